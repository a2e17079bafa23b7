"""One finger's regrasp search (regrasp_pin.planning.search) on the demo's first trigger.

The demo's initial grasp is held; the index finger, whose contact triggers first,
searches a regrasp. The landing check is the caller's judgement of a verified regrasp
(the planner follows the new contact): a rejected landing must cost only its Q.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from conftest import held_grasp

from regrasp_pin import make_scenario
from regrasp_pin.exceptions import Attempt, FailureKind, PlanningError
from regrasp_pin.grasp import choice as choice_module
from regrasp_pin.grasp.holding import holding_q
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.model.scene import Scene
from regrasp_pin.planning import search as search_module
from regrasp_pin.planning.search import RegraspSearch, SearchBudget

FINGER = "index"


@pytest.fixture(scope="module")
def problem():
    scen = make_scenario("five_finger", "hexagon")
    hand, p, motion = scen.hand, scen.params, scen.motion
    _, base, holding = held_grasp(scen)
    sample = scen.obj.sample_surface(p.sample_spacing_m)
    times = np.linspace(motion.t_start, motion.t_end, 101)
    manifolds = {
        n: build_manifold(hand.finger(n), sample, motion, times, contact=p.contact)
        for n in p.fingers
    }

    def new_search(time_law="minimum-jerk"):
        return RegraspSearch(
            Scene(hand, scen.obj, motion),
            manifolds,
            sample,
            regrasp=dataclasses.replace(p.regrasp, time_law=time_law),
            contact=p.contact,
        )

    kept = new_search()  # one search for every test: what it measured stays with it
    h = holding[FINGER]
    t_trig, _ = h.track.trigger()
    assert t_trig is not None  # the demo's index contact nears its limits
    stay = [n for n in p.fingers if n != FINGER]

    def q_hand(t):
        q = np.broadcast_to(base, (t.size, base.size)).copy()
        for n in stay:
            q[:, hand.finger(n).q_indices] = holding_q(
                hand, motion, n, holding[n], t, p.contact.ik_tol_m
            )
        return q

    def find(fresh=False, time_law="minimum-jerk", search=None, hand_motion=None, **kwargs):
        if search is None:
            search = new_search(time_law) if fresh or time_law != "minimum-jerk" else kept
        return search.find(
            FINGER,
            (h.p, h.n),
            [t_trig - p.lead_s],
            lambda t: holding_q(hand, motion, FINGER, h, np.array([t]), p.contact.ik_tol_m)[0],
            {n: (holding[n].p, holding[n].n) for n in stay},
            q_hand if hand_motion is None else hand_motion,
            SearchBudget(),
            **kwargs,
        )

    # what the tests of the search's own caches read
    find.new_search, find.q_hand, find.stay, find.t_trig = new_search, q_hand, stay, t_trig
    return find


def _reject(result):
    return Attempt(FailureKind.SHORT_HOLD, FINGER, result.t_start, measured=0.0, required=0.4)


def test_a_rejected_landing_costs_only_its_q(problem):
    first = problem()
    assert first.result.report.ok

    def not_first(result):
        same = np.allclose(result.Q_object, first.result.Q_object, atol=1e-12)
        return _reject(result) if same else None

    second = problem(landing_check=not_first)
    assert second.result.report.ok
    assert not np.allclose(second.result.Q_object, first.result.Q_object, atol=1e-12)
    # the rejection is recorded as data, after the attempts that preceded the first
    assert second.attempts[: len(first.attempts)] == first.attempts
    assert second.attempts[len(first.attempts)].kind == FailureKind.SHORT_HOLD


def test_a_search_that_keeps_what_it_measured_finds_the_same(problem):
    """The search keeps the link distances, the epsilons and the finger clearances it
    measured between its choices of Q: asked again (and after other searches), it finds
    the same regrasp after the same failed attempts as a search that starts afresh."""

    def second_only(result):
        second_only.seen += 1
        return _reject(result) if second_only.seen == 1 else None

    found = []
    for fresh in (True, False, False):
        second_only.seen = 0
        found.append(problem(fresh=fresh, landing_check=second_only))
    for again in found[1:]:
        assert again.attempts == found[0].attempts
        assert again.result.t_start == found[0].result.t_start
        assert again.result.Q_object.tolist() == found[0].result.Q_object.tolist()
        mine, first = again.choice, found[0].choice
        assert (mine.index, mine.rank, mine.epsilon, mine.exit_time_s) == (
            first.index,
            first.rank,
            first.epsilon,
            first.exit_time_s,
        )


def test_every_landing_rejected_ends_typed_with_every_attempt(problem):
    with pytest.raises(PlanningError) as err:
        problem(landing_check=_reject)
    exc = err.value
    assert exc.kind == FailureKind.SHORT_HOLD and exc.finger == FINGER
    rejected = [a for a in exc.attempts if a.kind == FailureKind.SHORT_HOLD]
    # each verified landing was judged once, and each took another Q
    assert len(rejected) >= 2
    assert exc.required == pytest.approx(0.4)


def test_a_distance_failure_reports_the_attempt_nearest_to_passing(problem):
    """Every landing refused for its distance to the object, by varying amounts: the
    error's numbers are those of the refusal nearest to passing, as its message says."""
    count = iter(range(10**6))

    def too_close(result):
        k = next(count)
        miss = -0.001 * (1 + (7 * k) % 5)  # -1 .. -5 mm, in a scrambled order
        return Attempt(FailureKind.OBJECT_CLEARANCE, FINGER, result.t_start, miss, 0.002)

    with pytest.raises(PlanningError) as err:
        problem(landing_check=too_close)
    exc = err.value
    mine = [a for a in exc.attempts if a.kind == FailureKind.OBJECT_CLEARANCE]
    assert exc.kind == FailureKind.OBJECT_CLEARANCE and len(mine) >= 2
    assert exc.measured == max(a.measured for a in mine) and exc.required == 0.002
    assert f"the nearest {exc.measured * 1e3:.2f} mm, need 2.00 mm" in str(exc)


def test_a_surface_path_too_fast_at_every_duration_falls_back_to_joint_space(problem, monkeypatch):
    import regrasp_pin.planning.regrasp as regrasp_module

    def too_fast(task, p):
        raise PlanningError(
            "too fast (test)", finger=FINGER, kind=FailureKind.VELOCITY, measured=2.0, required=1.0
        )

    monkeypatch.setattr(regrasp_module, "surface_path", too_fast)
    try:
        found = problem()
    except PlanningError as exc:
        attempts, result = exc.attempts, None
    else:
        attempts, result = list(found.attempts), found.result
    # for the first candidate: the surface path at longer and longer durations (the
    # Q re-chosen for each arrival time), then the fallback once, at the last of them
    # with the last Q
    tried = [re.search(r"Q=\[(.*?)\], ([0-9.]+) s( \(joint-space\))?$", a.what) for a in attempts]
    group = []
    for a, m in zip(attempts, tried, strict=True):
        group.append((a, m))
        if m is None or m.group(3):
            break
    last_a, last_m = group[-1]
    fell_back = last_m is not None and last_m.group(3) is not None
    surface = group[:-1] if fell_back else group
    assert len(surface) >= 2 and all(a.kind == FailureKind.VELOCITY for a, _ in surface)
    durations = [float(m.group(2)) for _, m in surface]
    assert durations == sorted(durations) and durations[-1] > durations[0]
    if fell_back:  # the fallback failed: it was tried
        assert float(last_m.group(2)) == durations[-1]
        assert last_m.group(1) == surface[-1][1].group(1)
    else:  # the first candidate's fallback passed
        assert result is not None and result.route == "joint-space" and result.report.ok
        assert result.t_end - result.t_start == pytest.approx(durations[-1], abs=1e-9)


def test_a_regrasp_that_failed_is_not_planned_again(problem, monkeypatch):
    """Every regrasp fails by its joint speeds: each Q is tried at longer durations,
    and the Q chosen for a later arrival takes over; a Q given up that way comes back
    as the best of the next round, at the duration that failed already. No regrasp (the
    same lift-off, Q, duration and route) is planned or recorded twice."""
    import regrasp_pin.planning.search as search_module

    planned = []

    def too_fast(hand, obj, motion, finger, t_start, P, n_P, Q, n_Q, q_start, q_hand, **kw):
        planned.append(
            (round(t_start, 9), tuple(Q), round(kw["params"].duration_s, 9), kw["route"])
        )
        raise PlanningError(
            "too fast (test)", finger=finger, kind=FailureKind.VELOCITY, measured=2.0, required=1.0
        )

    monkeypatch.setattr(search_module, "plan_regrasp", too_fast)
    with pytest.raises(PlanningError) as err:
        problem(fresh=True)
    assert err.value.kind == FailureKind.VELOCITY
    assert len(planned) >= 6
    assert len(set(planned)) == len(planned)
    recorded = [a.what for a in err.value.attempts if a.kind == FailureKind.VELOCITY]
    assert len(recorded) == len(planned) and len(set(recorded)) == len(recorded)


def test_a_q_that_cannot_land_in_time_is_not_chosen(problem):
    """The demo's first index regrasp lands 0.25 s after lift-off; allowed 0.12 s (and
    regrasps as short as 0.1 s), the Q's whose move needs longer within the joint
    velocity limits are passed over when Q is chosen, instead of being chosen, found
    too late and excluded with their neighbourhood one by one (which used up the
    candidates of this lift-off: a too-late failure). A regrasp that lands in time is
    found, and no attempt was a Q too late to land."""
    first = problem()
    start = first.result.t_start
    found = problem(end_by_s=start + 0.12, shortest_s=0.1)
    assert found.result.report.ok
    assert found.result.t_end <= start + 0.12 + 1e-9
    assert all(a.kind != FailureKind.TOO_LATE for a in found.attempts)


def test_a_q_is_kept_clear_of_the_others_where_they_are_when_it_is_judged(problem, monkeypatch):
    """The choice judges a candidate by the finger's joint coordinates at the
    manifold's first time at or after the arrival; the other fingers it must clear are
    taken where they hold at that same time, not at the arrival (which the grid rounds
    up by up to a manifold step: the hand moves on with the object meanwhile). Read in
    the screen itself: the row of the finger's coordinates and the hand it is paired
    with."""
    real_choose, real_screen = search_module.choose_new_contact, choice_module._Screen
    calls, screens = [], []

    class Screen(real_screen):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            screens.append(self.clearances[0][1:])  # (hand, row) of the arrival test

    def spy(hand, obj, manifold, sample, t_arrive_s, **kwargs):
        calls.append((manifold, t_arrive_s, kwargs["lasting"].args[2], len(screens)))
        return real_choose(hand, obj, manifold, sample, t_arrive_s, **kwargs)

    monkeypatch.setattr(search_module, "choose_new_contact", spy)
    monkeypatch.setattr(choice_module, "_Screen", Screen)
    problem(fresh=True)
    off_grid = 0
    for manifold, t_arrive, q_hand, n_before in calls:
        if n_before == len(screens):
            continue  # no screen was built: nothing to judge
        q_arrive, row = screens[n_before]
        t_row = manifold.times_s[row]
        assert t_row >= t_arrive - 1e-9 and (row == 0 or manifold.times_s[row - 1] < t_arrive)
        np.testing.assert_array_equal(q_arrive, q_hand(np.array([t_row]))[0])
        if t_row - t_arrive > 1e-6:
            off_grid += 1
            assert not np.allclose(q_arrive, q_hand(np.array([t_arrive]))[0], atol=1e-6)
    assert off_grid  # the arrivals the test is about


def test_by_the_cruise_law_a_regrasp_lands_sooner_within_the_same_limits(problem):
    """Allowed 0.12 s to land (and regrasps as short as 0.1 s), the demo's first index
    regrasp by the cruise law (``RegraspParams.time_law``) lands sooner than by minimum
    jerk, its joints within their velocity limits and its motion verified by Coal."""
    start = problem().result.t_start
    kw = dict(end_by_s=start + 0.12, shortest_s=0.1, fresh=True)
    smooth = problem(**kw)
    fast = problem(time_law="cruise", **kw)
    assert smooth.result.params.time_law == "minimum-jerk"
    assert fast.result.params.time_law == "cruise" and fast.result.report.ok
    assert fast.result.t_end < smooth.result.t_end - 1e-9  # here 0.10 s against 0.11 s
    assert fast.result.t_end <= start + 0.12 + 1e-9
    r = fast.result
    speeds = np.abs(np.diff(r.q, axis=0)) / np.diff(r.times_s)[:, None]
    limit = make_scenario("five_finger", "hexagon").hand.finger(FINGER).velocity_limit
    assert np.all(speeds <= limit * (1 + 1e-9))


def test_the_candidates_clearance_of_the_others_is_measured_once_per_postures(problem, monkeypatch):
    """The columns of the candidates' clearance of the holding fingers
    (clear_of_fingers) are what clear_of_fingers gives, and are measured once for the
    same postures of the others, whatever function gives them (the planner makes a new
    one for every state); other postures are measured again."""
    search = problem.new_search()
    hand, contact = search.scene.hand, search.contact
    m = search.manifolds[FINGER]
    ka = int(np.searchsorted(m.times_s, problem.t_trig))
    points = np.flatnonzero(m.reachable[ka])[::7][:60]
    horizon = np.full(points.size, m.times_s.size - ka)
    calls = []
    real = search_module.clear_of_fingers

    def counted(*args, **kwargs):
        calls.append(args[2].shape[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(search_module, "clear_of_fingers", counted)
    first = search._clear_of_others(FINGER, problem.stay, problem.q_hand, points, ka, horizon)
    same = search._clear_of_others(
        FINGER, problem.stay, lambda t: problem.q_hand(t), points[::-1], ka, horizon
    )
    assert calls == [points.size]
    assert np.array_equal(same, first[:, ::-1])
    postures = problem.q_hand(m.times_s[ka:])
    direct = real(hand, FINGER, m.q[ka:, points], postures, problem.stay, contact.finger_trigger_m)
    assert np.array_equal(first, direct)
    assert not direct.all() and direct.any(), "some candidates must come near the others"
    closer = search._clear_of_others(
        FINGER, problem.stay, lambda t: problem.q_hand(t) * 1.05, points, ka, horizon
    )
    assert calls == [points.size, points.size] and closer.shape == first.shape


class _Keyed:
    """The other fingers' motion with a key, as :class:`~regrasp_pin.planning.state.
    HandMotion` has: the search keeps the regrasps planned under it."""

    def __init__(self, q_hand, key):
        self.q_hand, self.key = q_hand, key

    def __call__(self, t):
        return self.q_hand(t)


def test_a_regrasp_planned_before_under_the_same_motion_is_not_planned_again(problem, monkeypatch):
    """A second search of the same plan (another call, as a recovery makes) under the
    other fingers' same motion gets every regrasp it planned before, verified or
    failed, without planning it: the same attempts and the same regrasp as a search
    that starts afresh. Under another motion (another key), or one without a key, it
    plans them again."""

    def second_only(result):
        second_only.seen += 1
        return _reject(result) if second_only.seen == 1 else None

    planned = []
    real = search_module.plan_regrasp
    monkeypatch.setattr(
        search_module, "plan_regrasp", lambda *a, **k: planned.append(a[5]) or real(*a, **k)
    )

    def run(search, hand_motion):
        second_only.seen, planned[:] = 0, []
        found = problem(search=search, hand_motion=hand_motion, landing_check=second_only)
        return found, len(planned)

    reference, n_reference = run(problem.new_search(), problem.q_hand)
    assert n_reference >= 2  # the first landing rejected: at least two regrasps planned
    search = problem.new_search()
    first, n_first = run(search, _Keyed(problem.q_hand, b"the others' motion"))
    again, n_again = run(search, _Keyed(problem.q_hand, b"the others' motion"))
    assert n_first == n_reference and n_again == 0
    assert again.result is first.result
    for found in (first, again):
        assert found.attempts == reference.attempts
        assert found.result.Q_object.tolist() == reference.result.Q_object.tolist()
        assert found.result.q.tolist() == reference.result.q.tolist()
    assert run(search, _Keyed(problem.q_hand, b"another motion"))[1] == n_reference
    assert run(search, problem.q_hand)[1] == n_reference
