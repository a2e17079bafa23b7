"""Letting a finger go (regrasp_pin.planning.letgo) inside a whole plan.

A release or a hand-over moves the plan's time on (to the release, or to the joining
finger's landing); every other finger must still hold its contact then. Checked on the
neighbour scenario where a hand-over once landed after two other holds were lost: the
middle finger's IK could no longer reach its contact, yet the plan went on from there.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin import plan_manipulation
from regrasp_pin.exceptions import PlanningError
from regrasp_pin.plan import Plan
from regrasp_pin.planning import advance, letgo
from regrasp_pin.planning.join import plan_join
from regrasp_pin.planning.release import Release, plan_release
from regrasp_pin.suite import build_scenario, generate_specs
from regrasp_pin.suite.specs import neighbour_specs
from regrasp_pin.verify.plan_check import recheck_plan

#: a neighbour of the demo that lets fingers go, joins them again, and backs up over both
LETS_GO = "five_finger-hexagon--100deg-40dps"


@pytest.fixture(scope="module")
def lets_go_planned():
    """:func:`_plan_recording` of :data:`LETS_GO`, keeping what it planned: one planning
    that two tests read (each of them planned this same scenario in full before)."""
    with pytest.MonkeyPatch.context() as mp:
        return _plan_recording(mp, LETS_GO, forget=False)


def test_a_let_go_leaves_every_other_hold_unlost(lets_go_planned):
    # the outcome is not the point here: every let-go the plan tried, planned or not
    *_, let_gos, scen = lets_go_planned
    assert let_gos  # the scenario lets fingers go (or tries to)
    results = [after for _, after in let_gos if after is not None]
    c = scen.params.contact
    for after in results:
        for name, h in after.holding.items():
            if name in after.held_to_end:
                continue
            # every time of the hold up to the new time: the contact is still held
            # (reached, inside the joint limits, pad facing; a trigger, within the margin
            # of a limit, is not a loss), as its track measured it
            tr = h.track
            upto = (tr.times_s >= h.t_from - 1e-9) & (tr.times_s <= after.now + 1e-9)
            held = (tr.error_m <= c.ik_tol_m) & (tr.margin_rad >= 0.0) & (tr.pad_cos >= tr.cos_cone)
            assert np.all(held[upto]), (name, after.now)


class _Forgetful(dict):
    """A ``PlanContext.releases`` or ``joins`` that keeps nothing."""

    def __setitem__(self, key, value):
        pass


def _plan_recording(monkeypatch, name, forget):
    """The releases and joins a plan of the neighbour ``name`` plans, each as what it
    depends on, its outcome, every let-go it tried (the finger and the state after, None
    if none was planned) and the scenario; ``forget``: the plan keeps none it planned."""
    spec = next(s for s in neighbour_specs(("five_finger",)) if s.name == name)
    scen = build_scenario(spec)
    releases, joins, let_gos = [], [], []

    def recorded_release(hand, obj, motion, finger, t_r, P, q_r, q_hand, **kw):
        until = kw.get("until_s")  # a release planned to a join, or to the end
        times = np.linspace(t_r, motion.t_end if until is None else until, 20)
        releases.append(
            (
                finger,
                round(t_r, 9),
                kw["q_park"] is None,
                until,
                q_r.tobytes(),
                q_hand(times).tobytes(),
            )
        )
        return plan_release(hand, obj, motion, finger, t_r, P, q_r, q_hand, **kw)

    def recorded_join(hand, obj, motion, finger, t0, q_from, Q, q_arrive, q_hand, **kw):
        times = np.linspace(t0, t0 + kw["duration_s"], 9)
        joins.append(
            (
                finger,
                round(t0, 9),
                q_from.tobytes(),
                np.asarray(Q[0]).tobytes(),
                q_hand(times).tobytes(),
            )
        )
        return plan_join(hand, obj, motion, finger, t0, q_from, Q, q_arrive, q_hand, **kw)

    def let_go(ctx, state, trig, *args):
        if forget:
            ctx.releases, ctx.joins = _Forgetful(), _Forgetful()
        after = letgo.let_go(ctx, state, trig, *args)
        let_gos.append((trig.finger, after))
        return after

    monkeypatch.setattr(letgo, "plan_release", recorded_release)
    monkeypatch.setattr(letgo, "plan_join", recorded_join)
    monkeypatch.setattr(advance, "let_go", let_go)
    try:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    except PlanningError as exc:
        outcome = (exc.kind, exc.finger, exc.time_s, len(exc.partial.regrasps()))
    else:
        outcome = "full plan"
    return releases, joins, outcome, let_gos, scen


def test_a_release_or_a_join_is_planned_once_for_a_plan(lets_go_planned, monkeypatch):
    """Backing up asks for the same release (the finger, the time, its hold and the
    others' motion) or join (the finger, the time, where it starts, the others' holds
    and let-gos) again from other branches: each is planned once. A plan that forgets
    the ones it planned asks for some twice, and ends the same way."""
    released, joined, outcome, *_ = lets_go_planned
    released_again, joined_again, outcome_forgot, *_ = _plan_recording(monkeypatch, LETS_GO, True)
    for kept, forgot in ((released, released_again), (joined, joined_again)):
        assert kept and len(set(kept)) == len(kept)
        assert len(set(forgot)) < len(forgot)  # the repeats the plan no longer makes
        assert set(forgot) == set(kept)
    assert outcome == outcome_forgot


def _landing_by_choice(needs):
    """A choice is the duration it was made for; the duration it needs is read from a
    table."""
    made = []

    def choose(d):
        made.append(d)
        return d

    return made, choose, lambda c: needs[c]


def test_arrival_choice_lands_the_first_choice_when_it_needs_no_longer():
    made, choose, need = _landing_by_choice({0.25: 0.25})
    choice, chosen_s, needed_s = letgo.arrival_choice(choose, need, 0.25)
    assert made == [0.25] and (choice, chosen_s, needed_s) == (0.25, 0.25, 0.25)
    assert letgo.join_duration_of(chosen_s, needed_s) == 0.25


def test_arrival_choice_chooses_again_for_the_longer_duration_it_needs():
    # the first Q needs 0.55 s; the Q chosen for 0.55 s needs only 0.4 s, so the join
    # takes 0.55 s, the duration that Q was chosen for (the object's pose at landing)
    made, choose, need = _landing_by_choice({0.25: 0.55, 0.55: 0.4})
    choice, chosen_s, needed_s = letgo.arrival_choice(choose, need, 0.25)
    assert made == [0.25, 0.55]
    assert (choice, chosen_s, needed_s) == (0.55, 0.55, 0.4)
    assert letgo.join_duration_of(chosen_s, needed_s) == 0.55


def test_a_settled_join_takes_the_duration_its_choice_needs_not_a_time_difference():
    # within the tolerance the needed value (whole steps) is kept as it is
    assert letgo.join_duration_of(0.25, 0.25 + 1e-12) == 0.25 + 1e-12
    assert letgo.join_duration_of(0.25, 0.25 - 1e-12) == 0.25 - 1e-12


def test_arrival_choice_reports_a_choice_that_never_settles():
    # every longer duration needs longer still: after the rounds, the last choice needs
    # more than it was chosen for and the caller must not land it
    made, choose, need = _landing_by_choice({0.25: 0.5, 0.5: 0.75, 0.75: 1.0})
    choice, chosen_s, needed_s = letgo.arrival_choice(choose, need, 0.25)
    assert made == [0.25, 0.5, 0.75]
    assert choice == chosen_s == 0.75 and needed_s == 1.0


def _release(times, q):
    return Release(
        finger="index",
        t_start=float(times[0]),
        t_backed_off=float(times[2]),
        t_end=float(times[-1]),
        P_object=np.zeros(3),
        times_s=np.asarray(times, float),
        q=np.asarray(q, float),
        min_clearance_m=0.003,
    )


def test_a_let_go_finger_is_still_from_its_last_change_and_is_cut_there_or_later():
    times = np.array([1.0, 1.05, 1.1, 1.2, 1.3, 1.4])
    q = np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.1], [0.2, 0.3], [0.2, 0.3], [0.2, 0.3]])
    rel = _release(times, q)
    assert letgo.still_from(rel) == 1.2  # the last sample that differs from the one before
    assert letgo.still_from(_release(times, np.zeros((6, 2)))) == 1.0
    # a minimum-jerk move ends at 1 - 1e-16 of its way: rounding is no motion
    noisy = q.copy()
    noisy[3] = np.nextafter(noisy[3], 1.0)  # one ulp off the still configuration
    assert np.any(noisy[3] != noisy[4])
    assert letgo.still_from(_release(times, noisy)) == 1.2
    cut = letgo._cut(rel, 1.35)
    assert cut.t_end == 1.35
    np.testing.assert_array_equal(cut.times_s, [1.0, 1.05, 1.1, 1.2, 1.3, 1.35])
    np.testing.assert_array_equal(cut.q, np.vstack([q[:5], q[-1:]]))
    cut = letgo._cut(rel, 1.3)  # on a sample: that sample once
    np.testing.assert_array_equal(cut.times_s, [1.0, 1.05, 1.1, 1.2, 1.3])


def _planned(spec, tmp_path):
    """The scenario of a suite spec and its full plan, read back from its file."""
    scen = build_scenario(spec)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    return scen, Plan.load(result.plan.save(tmp_path / "plan.json"))


def _assert_rechecked(plan):
    """The plan passes the independent re-check, at least three fingers always holding."""
    check = recheck_plan(plan, max_step_rad=1e-3)
    assert check.ok, check.problems
    assert check.min_holding >= 3


def test_a_finger_that_let_go_joins_again_once_its_contacts_are_back(tmp_path):
    """Suite scenario s0-068 (five-finger hand, a mesh turned +124 deg about the thumb's
    contact): the index's contacts leave its joint limits at once, so it lets go and the
    idle little finger joins in its place; later the little finger's contacts leave its
    limits, and the index's are back. The index joins again in the little finger's
    place (a finger that let go may join: before, only one that took no part could, and
    the plan failed there, no-candidate at 1.45 s). From the plan file: the index's
    let-go ends where its join starts, it stands still before, and the whole plan
    passes the independent re-check."""
    spec = generate_specs(69, seed=0)[68]
    assert spec.name.startswith("s0-068-five_finger")
    scen, plan = _planned(spec, tmp_path)
    index = plan.phases["index"]
    assert [ph.kind for ph in index[:4]] == ["contact", "release", "join", "contact"]
    off, on = index[1], index[2]
    assert on.t_start == off.t_end and off.t_start < on.t_start
    assert on.reason.startswith("joins again")
    little = [ph for ph in plan.phases["little"] if ph.kind == "release"]
    assert little and little[0].t_start <= on.t_start
    assert on.reason == "joins again in place of little, which let go"
    # standing still the last 0.1 s before it starts to join
    f = scen.hand.fingers["index"]
    before = (plan.t >= on.t_start - 0.1 - 1e-9) & (plan.t <= on.t_start + 1e-9)
    q = plan.q[np.ix_(np.flatnonzero(before), f.q_indices)]
    assert len(q) >= 2 and np.all(q == q[0])
    _assert_rechecked(plan)


def test_a_finger_with_no_regrasp_lets_go_and_joins_again_on_its_own(tmp_path):
    """Suite scenario s0-113 (the Allegro hand, a mesh turned +216 deg while drifting):
    at 3.3 s no regrasp of the ring finger verifies, and the three others are too few to
    take turns without it. The ring lets go, the others hold alone, and it joins again
    on a new contact of its own (before, the plan failed there, force-closure of the
    thumb later). From the plan file: the let-go ends where the join starts, the join
    says why, and the whole plan passes the independent re-check with at least three
    fingers holding at every time."""
    spec = generate_specs(114, seed=0)[113]
    assert spec.name.startswith("s0-113-allegro")
    scen, plan = _planned(spec, tmp_path)
    ring = plan.phases["ring"]
    again = [
        k for k in range(1, len(ring)) if ring[k].kind == "join" and ring[k - 1].kind == "release"
    ]
    assert again
    off, on = ring[again[0] - 1], ring[again[0]]
    assert on.t_start == off.t_end and off.t_start < on.t_start
    assert on.reason == "joins again: its contacts are back within reach"
    assert ring[again[0] + 1].kind == "contact"
    _assert_rechecked(plan)
