"""The whole-hand planner on several scenarios, re-checked from the plan file alone.

The scenarios are the canonical demo and two of its neighbours (other angles and
rates; regrasp_pin.suite.neighbour_specs lists all 30, bench/suite.py runs them).

The re-check (:func:`regrasp_pin.verify.plan_check.recheck_plan`) uses only the plan file
(URDF path, object mesh, q, poses, phases), Pinocchio and Coal: none of regrasp_pin's
own kinematics or verification.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import CONE_60
from scipy.spatial.transform import Rotation

from regrasp_pin import Plan, make_scenario, plan_manipulation, plan_scenario
from regrasp_pin.exceptions import FailureKind, InputError, PlanningError
from regrasp_pin.grasp.contact import ContactModel
from regrasp_pin.grasp.quality import is_force_closure
from regrasp_pin.grasp.tracking import track_contact
from regrasp_pin.plan import ContactPhase
from regrasp_pin.planning.planner import PlannerParams
from regrasp_pin.planning.schedule import held_until
from regrasp_pin.suite import build_scenario, generate_specs
from regrasp_pin.verify.plan_check import recheck_plan

# (angle [deg], rate [deg/s]): the demo and neighbours with other angles and rates
SCENARIOS = [(100, 20), (60, 10), (100, 10)]


@pytest.fixture(scope="module", params=SCENARIOS, ids=lambda p: f"{p[0]}deg-{p[1]}dps")
def demo(request, tmp_path_factory):
    angle, rate = request.param
    scen = make_scenario("five_finger", "hexagon", angle_deg=angle, rate_deg_s=rate)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    path = result.plan.save(tmp_path_factory.mktemp("plan") / "plan.json")
    return result, Plan.load(path), angle, scen


def test_demo_criteria(demo):
    result, plan, angle, _ = demo
    regrasps = plan.regrasps()
    assert len(regrasps) >= 3
    assert len({r.finger for r in regrasps}) >= 2
    assert all(r.report.ok for r in result.regrasps)
    total_turn = np.degrees(
        (
            Rotation.from_quat(plan.T_palm_object[-1, 3:])
            * Rotation.from_quat(plan.T_palm_object[0, 3:]).inv()
        ).magnitude()
    )
    assert total_turn == pytest.approx(abs(angle), abs=0.5)
    # every regrasp says, as data, what was tried before it (JSON-able kinds)
    for r in regrasps:
        for a in r.extra["attempts"]:
            assert a["kind"] in {k.value for k in FailureKind}


def _assert_new_contacts_held(result, scen):
    """Followed again from its landing configuration, each new contact is held inside
    the joint limits for at least the shortest regrasp duration, or to the end."""
    p = scen.params
    grid = np.asarray(result.plan.t)
    for r in result.regrasps:
        times = np.concatenate([[r.t_end], grid[grid > r.t_end + 1e-9]])
        track = track_contact(
            scen.hand,
            r.finger,
            scen.obj,
            scen.motion,
            times,
            r.Q_object,
            r.n_Q_object,
            r.q[-1],
            contact=p.contact,
        )
        need = min(r.t_end + p.regrasp.duration_s, grid[-1] - p.dt_s)
        assert held_until(track, p.contact) >= need - 1e-9, (r.finger, r.t_end)


def test_every_new_contact_is_held_at_least_as_long_as_a_regrasp(demo):
    # a regrasp that lands on a contact lost right after gains nothing
    result, _, _, scen = demo
    _assert_new_contacts_held(result, scen)


def test_no_regrasp_lands_where_the_pad_is_about_to_turn_away():
    """Allegro, 60 deg at 40 deg/s: the landing falls between two manifold times, and
    a Q that faces the pad at the later one only would be lost at once (the ring then
    had to lift off again while the index was in the air: finger-busy). Two guards,
    each enough here: Q is chosen usable at both times, and the search follows each
    landing and turns down a contact that would not be held as long as a regrasp takes.
    A full plan, every new contact held."""
    scen = make_scenario("allegro", "hexagon", angle_deg=60, rate_deg_s=40)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    _assert_new_contacts_held(result, scen)


def test_plan_round_trips(demo):
    _, plan, _, _ = demo
    assert Plan.from_dict(plan.to_dict()).to_dict() == plan.to_dict()


@pytest.fixture(scope="module")
def recheck(demo):
    _, plan, _, _ = demo
    return recheck_plan(plan, max_step_rad=1e-3, penetration_tol_m=1e-4, contact_tol_m=1e-4)


def test_the_plan_records_its_mu_and_holds_in_force_closure_at_every_instant(demo, recheck):
    """The plan file records the friction coefficient it was made for, and the
    re-check (its own wrench model) finds the contacts held at once in force closure
    at every instant, while a finger is in the air too."""
    _, plan, _, scen = demo
    assert plan.mu == scen.params.mu
    assert recheck.min_closure_epsilon is not None and recheck.min_closure_epsilon > 1e-9
    assert len(recheck.closure_fingers) >= 3


def test_every_finger_has_phases_over_the_whole_plan(demo, recheck):
    """The little finger takes no part: one idle phase over the whole plan, re-checked
    clear of the object; the others' phases start at 0 and end at the end."""
    _, plan, _, _ = demo
    assert set(plan.phases) == set(plan.load_hand().finger_names)
    (idle,) = plan.phases["little"]
    assert (idle.kind, idle.t_start, idle.t_end) == ("idle", plan.t[0], plan.t[-1])
    assert [c.finger for c in recheck.idles] == ["little"]
    assert recheck.idles[0].min_object_distance_m > 0.0
    for ps in plan.phases.values():
        assert ps[0].t_start == plan.t[0] and ps[-1].t_end == pytest.approx(plan.t[-1])


def test_three_fingers_hold_at_every_instant(recheck):
    assert recheck.min_holding >= 3, recheck.t_min_holding_s


def test_every_regrasp_passes_an_independent_dense_recheck(demo, recheck):
    _, plan, _, _ = demo
    assert [(r.finger, r.t_start) for r in recheck.regrasps] == [
        (r.finger, r.t_start) for r in plan.regrasps()
    ]
    assert not recheck.joint_limit_violations, recheck.joint_limit_violations
    for r in recheck.regrasps:
        assert r.min_object_distance_m >= -1e-4, (
            f"{r.finger} at {r.t_start:.2f} s penetrates the object by "
            f"{r.penetration_m * 1e3:.3f} mm"
        )
        assert r.min_finger_distance_m > 0.0, (
            f"{r.finger} at {r.t_start:.2f} s touches another finger"
        )


def test_fingers_never_touch_each_other_even_while_holding(recheck):
    # holding fingers close in on each other as the object turns: the planner must
    # regrasp one of them before they touch (the paper's fingers hold independently)
    assert recheck.min_finger_distance_samples_m > 0.0, (
        recheck.finger_pair_samples,
        recheck.t_min_finger_samples_s,
    )
    assert recheck.ok, recheck.problems


def test_fingertips_stay_on_their_contacts(recheck):
    assert recheck.max_contact_error_m <= 1e-4, (
        recheck.contact_error_finger,
        recheck.t_max_contact_error_s,
    )


def test_unachievable_motion_raises_with_partial_plan():
    scen = make_scenario("five_finger", "hexagon", angle_deg=-100)
    from dataclasses import replace

    from regrasp_pin.grasp.contact import ContactModel

    # a trigger margin larger than any new contact can offer: the first regrasp fails
    params = replace(
        scen.params, contact=ContactModel(choice_margin_rad=2.0), max_starts=1, max_backtracks=0
    )
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params)
    exc = err.value
    assert exc.finger is not None and exc.time_s is not None
    assert exc.partial is not None and exc.partial.t[-1] <= exc.time_s + 1e-6
    # as data: no new contact offers the margin, and every attempt says so
    assert exc.kind == FailureKind.NO_CANDIDATE
    assert exc.attempts and all(a.kind == FailureKind.NO_CANDIDATE for a in exc.attempts)
    assert all(a.finger == exc.finger for a in exc.attempts)


def test_a_neighbour_that_cannot_be_planned_ends_typed_with_a_verified_partial_plan():
    """Turned the other way (-100 deg), the fingers cannot follow the whole turn (the
    index soon has no contact inside its limits): a typed failure within the budget,
    and what was planned before it passes the independent re-check."""
    scen = make_scenario("five_finger", "hexagon", angle_deg=-100, rate_deg_s=20, contact=CONE_60)
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    exc = err.value
    assert exc.kind in set(FailureKind) and exc.finger is not None
    # a failed search carries what it tried; a scheduling failure (no time, no force
    # closure without the finger) is decided before any attempt
    scheduling = {FailureKind.FINGER_BUSY, FailureKind.FORCE_CLOSURE, FailureKind.TOO_LATE}
    assert exc.attempts or exc.kind in scheduling
    assert exc.partial is not None
    check = recheck_plan(exc.partial, max_step_rad=1e-3)
    assert not check.joint_limit_violations
    assert all(r.min_object_distance_m >= -1e-4 for r in check.regrasps)


def _spec_6():
    """Suite spec 6 (five-finger hand, pentagonal prism, -175 deg about the thumb's
    contact) with regrasps of at least 0.8 s (none faster: no rush), searched although
    it is proven to have no plan (the ring finger cannot let go from 1.8 s on:
    tests/test_grasp_necessity.py has such cases), to test how the search ends."""
    scen = build_scenario(generate_specs(7, seed=0)[6], contact=CONE_60)
    slow = replace(scen.params.regrasp, duration_s=0.8)
    params = replace(scen.params, regrasp=slow, prove_infeasible=False, rush_duration_s=None)
    return replace(scen, params=params)


def test_a_grasp_that_loses_two_holds_at_once_fails_at_once():
    """Suite spec 6 with regrasps of at least 0.8 s: the fingers' holds end within
    about a second of the start, closer together than one regrasp, so that whichever
    finger goes first another loses its hold in the meantime (the ring's at 0.69 s
    when the index could land at 0.8 s): a finger-busy failure at the start that names
    the hold and the landing, not a search that plans on into a state with a finger
    already lost."""
    scen = _spec_6()
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    exc = err.value
    assert exc.kind == FailureKind.FINGER_BUSY
    assert exc.required < exc.measured  # the hold is lost before the landing
    assert exc.time_s <= exc.required  # decided before that hold is lost
    assert exc.partial is not None and not exc.partial.regrasps()


def test_an_exhausted_budget_ends_typed_with_the_partial_plan():
    scen = make_scenario("five_finger", "hexagon")
    params = replace(scen.params, budget_s=0.0)
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params)
    exc = err.value
    assert exc.kind == FailureKind.BUDGET
    assert exc.partial is not None and not exc.partial.regrasps()


@pytest.mark.parametrize("max_steps", [4, 7])  # the full plans need more (9 at 60 deg)
def test_the_step_budget_stops_the_same_plan_at_the_same_step(demo, max_steps):
    """The budget counts search steps, not seconds: a plan cut short by it is the start
    of the full plan (the same regrasps, at the same times, onto the same Q), and a
    regrasp takes at least two steps (its Q chosen, its path planned)."""
    result, _, _, scen = demo
    params = replace(scen.params, max_steps=max_steps)
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params)
    exc = err.value
    assert exc.kind == FailureKind.BUDGET
    cut = exc.partial.regrasps()
    full = result.plan.regrasps()
    assert 1 <= len(cut) <= (max_steps + 1) // 2 < len(full)
    for a, b in zip(cut, full, strict=False):
        assert (a.finger, a.t_start) == (b.finger, b.t_start)
        np.testing.assert_allclose(a.Q_object, b.Q_object, atol=1e-9)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("max_steps", 0),
        ("budget_s", -1.0),
        ("dt_s", 0.0),
        ("candidates", 2.5),
        ("prove_infeasible", "yes"),
        ("release", 1),
        ("rush_duration_s", 0.0),
        ("threads", 0),
        ("min_holding", 0),
        ("min_holding", 2.0),
    ],
)
def test_planner_params_name_a_bad_value(field, value):
    with pytest.raises(InputError, match=f"PlannerParams.{field}"):
        PlannerParams(**{field: value})


def test_the_fewest_holding_fingers_follow_the_contact_model_unless_given():
    """Point contacts need three fingers in the hand while one is in the air, soft ones
    (torsional friction) two: ``fewest_holding`` reads the contact model, also after a
    ``replace`` of it; a ``min_holding`` given is kept."""
    soft = ContactModel(torsion_m=0.001)
    assert PlannerParams().fewest_holding == 3
    assert PlannerParams(contact=soft).fewest_holding == 2
    assert replace(PlannerParams(), contact=soft).fewest_holding == 2
    assert PlannerParams(contact=soft, min_holding=3).fewest_holding == 3
    assert PlannerParams(min_holding=4).fewest_holding == 4


def test_a_budget_that_runs_out_while_backing_up_is_the_failure(monkeypatch):
    """Suite spec 6 fails at t=0 (finger-busy, see above) and the planner would back up;
    with the budget gone at that moment the failure is ``budget``, not the finger-busy
    it could not back out of, and the message still names that failure."""
    from regrasp_pin.planning import recovery

    def out_of_time(ctx, *args, **kwargs):
        ctx.budget.deadline = float("-inf")  # the budget runs out here
        return None

    monkeypatch.setattr(recovery, "_another_first", out_of_time)
    scen = _spec_6()
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    exc = err.value
    assert exc.kind == FailureKind.BUDGET
    assert "while backing up from a finger-busy failure" in exc.reason
    assert exc.partial is not None


def test_a_finger_lets_go_when_no_regrasp_can_land_before_the_end(tmp_path):
    """60 deg at 20 deg/s: a contact is lost too close to the end for any regrasp; the
    others hold to the end, so the finger lets go. The release is in the plan file and
    passes the same independent re-check as the regrasps. (60 deg at 40 deg/s showed
    it until the grasp search's spacing ties were decided on every machine alike.)"""
    scen = make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=20)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    plan = Plan.load(result.plan.save(tmp_path / "plan.json"))
    releases = plan.releases()
    assert len(releases) == 1
    rel = releases[0]
    phases = plan.phases[rel.finger]
    # it held until it let go, and stays off to the end
    assert phases[-1].kind == "release"
    assert phases[-2].kind == "contact" and phases[-2].t_end == pytest.approx(rel.t_start)
    assert rel.t_end == pytest.approx(plan.t[-1])
    # nobody regrasps after it: every other finger holds from before the release to the end
    for name, ps in plan.phases.items():
        if name != rel.finger and ps[-1].kind != "idle":  # idle: it takes no part
            assert ps[-1].kind == "contact" and ps[-1].t_start <= rel.t_start + 1e-9
    check = recheck_plan(plan, max_step_rad=1e-3)
    assert check.ok, check.problems
    assert check.min_holding >= 3
    (after,) = [r for r in check.regrasps if r.t_start == pytest.approx(rel.t_start)]
    assert after.finger == rel.finger and after.min_object_distance_m >= -1e-4
    assert Plan.from_dict(plan.to_dict()).to_dict() == plan.to_dict()


def test_a_plan_whose_samples_stop_short_of_the_end_is_never_returned(monkeypatch):
    """The assembled plan must span the motion (its samples and every finger's phases):
    one that stopped a sample short (as a release sampled short of the end once did)
    would leave the motion's last step unverified. The planner refuses it."""
    from regrasp_pin.planning import planner

    assemble = planner.plan_until

    def short(ctx, state, until, *, final=False):
        plan = assemble(ctx, state, until, final=final)
        if not final:
            return plan
        return replace(plan, t=plan.t[:-1], q=plan.q[:-1], T_palm_object=plan.T_palm_object[:-1])

    monkeypatch.setattr(planner, "plan_until", short)
    scen = make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40)
    with pytest.raises(AssertionError, match="last phase ends at"):
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)


def _failure_of_final_plan(monkeypatch, alter):
    """The PlanningError of the five-finger hexagon turned 60 deg at 40 deg/s when its
    assembled whole plan is replaced by ``alter(ctx, plan)`` (the partial plans are
    left as they are)."""
    from regrasp_pin.planning import planner

    assemble = planner.plan_until

    def altered(ctx, state, until, *, final=False):
        plan = assemble(ctx, state, until, final=final)
        return alter(ctx, plan) if final else plan

    monkeypatch.setattr(planner, "plan_until", altered)
    scen = make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40)
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    return err.value


def test_a_plan_too_fast_between_its_samples_is_never_returned(monkeypatch):
    """The holds are placed by IK at every sample of the assembled plan, so the planner
    checks the assembled plan's joint speeds: a held finger's joint made to jump (2x its
    velocity limit) between two samples is a velocity failure of that finger, there,
    with the plan before it."""
    jumped = {}

    def jump(ctx, plan):
        f = ctx.scene.hand.fingers["middle"]
        k = plan.t.size // 2
        q = plan.q.copy()
        step = 2.0 * f.velocity_limit[1] * (plan.t[k + 1] - plan.t[k])
        q[k + 1 :, f.q_indices[1]] += step if q[k, f.q_indices[1]] + step <= f.upper[1] else -step
        j, dt = f.q_indices[1], plan.t[k + 1] - plan.t[k]
        jumped.update(
            t=float(plan.t[k]),
            limit=float(f.velocity_limit[1]),
            speed=float(abs(q[k + 1, j] - q[k, j]) / dt),  # the jump and the hold's own
        )
        return replace(plan, q=q)

    exc = _failure_of_final_plan(monkeypatch, jump)
    assert exc.kind == FailureKind.VELOCITY and exc.finger == "middle"
    assert exc.time_s == jumped["t"]
    assert exc.measured == pytest.approx(jumped["speed"], rel=1e-9)
    assert exc.measured > 1.5 * jumped["limit"]
    assert exc.required == jumped["limit"]
    assert exc.partial is not None and exc.partial.t[-1] <= jumped["t"] + 1e-9


def test_a_plan_whose_finger_enters_the_object_is_never_returned(monkeypatch):
    """Every move is verified and every hold tracked, but the assembled plan is
    measured against the object once more before it is returned: the object moved 10 mm
    towards the index's fingertip at one sample of the assembled plan is an
    object-clearance failure of the index, there, with the plan before it."""
    moved = {}

    def shift(ctx, plan):
        f = ctx.scene.hand.fingers["index"]
        k = plan.t.size // 2
        x = plan.T_palm_object.copy()
        towards = f.fk(plan.q[k, f.q_indices]) - x[k, :3]
        x[k, :3] += 0.010 * towards / np.linalg.norm(towards)
        moved.update(t=float(plan.t[k]))
        return replace(plan, T_palm_object=x)

    exc = _failure_of_final_plan(monkeypatch, shift)
    assert exc.kind == FailureKind.OBJECT_CLEARANCE and exc.finger == "index"
    assert exc.time_s == moved["t"]
    assert exc.measured < -0.004 and exc.required < 0.0  # millimetres in; microns allowed
    assert exc.partial is not None and exc.partial.t[-1] <= moved["t"] + 1e-9


def test_holds_that_end_together_are_regrasped_in_turn(tmp_path):
    """100 deg at 40 deg/s: the holds of the three regrasping fingers end within about
    one second of each other, again and again, so waiting for each finger's own trigger
    leaves the last one no time (a finger-busy failure before the chain rule). The
    first finger of the chain goes early enough for every one to follow in turn: a full
    plan, one finger in the air at a time, that passes the independent re-check."""
    scen = make_scenario("five_finger", "hexagon", angle_deg=100, rate_deg_s=40, contact=CONE_60)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    plan = Plan.load(result.plan.save(tmp_path / "plan.json"))
    moves = sorted([*plan.regrasps(), *plan.releases()], key=lambda r: r.t_start)
    assert len(plan.regrasps()) >= 4
    for a, b in zip(moves, moves[1:], strict=False):  # one finger in the air at a time
        assert b.t_start >= a.t_end - 1e-9 or a.kind == "release"
    check = recheck_plan(plan, max_step_rad=1e-3)
    assert check.ok, check.problems
    assert check.min_holding >= 3


def test_a_neighbour_makes_room_for_a_crowded_finger(tmp_path):
    """Suite spec 31 (the Allegro hand turning a box by -94 deg about its own axis): at
    2.22 s the index finger's new contacts put its links into the middle finger's. The
    middle regrasps first, out of that room (its contact away from the index's, its
    finger clear of the index standing there), and the index's next regrasp lands in
    the room the middle left: a full plan that passes the independent re-check. (Spec
    5 showed this until a backtrack let another finger due then go first, and spec 80
    until two fingertips were kept apart by their spheres instead of their contact
    points.)"""
    spec = generate_specs(32, seed=0)[31]
    scen = build_scenario(spec)
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    plan = Plan.load(result.plan.save(tmp_path / "plan.json"))
    moves = plan.regrasps()
    made = [i for i, r in enumerate(moves) if r.reason.startswith("makes room for index")]
    assert made, [r.reason for r in moves]
    # the index's first regrasp after a neighbour made room, and the last room made
    # before it (the neighbour's contact then is its new one)
    then_i = next(i for i in range(made[0] + 1, len(moves)) if moves[i].finger == "index")
    k = max(i for i in made if i < then_i)
    first = moves[k]
    assert first.finger != "index"
    assert all(m.finger != first.finger for m in moves[k + 1 : then_i])
    then = moves[then_i]
    assert then.t_start >= first.t_end - 1e-9
    # the index lands within the separation of the contact the neighbour left
    sep = 2 * scen.hand.finger("index").tip_radius + 0.001
    assert np.linalg.norm(then.Q_object - first.P_object) < sep
    # ... and the neighbour's new contact is out of the index's way
    assert np.linalg.norm(then.Q_object - first.Q_object) >= sep
    check = recheck_plan(plan, max_step_rad=1e-3)
    assert check.ok, check.problems


def test_the_planner_backs_up_again_each_time_it_gets_further():
    """Suite spec 95 (the Allegro hand turning a random convex mesh by -141 deg while
    it moves): with ``max_backtracks`` 8, the planner backs up more often in all, each
    time it gets further in time it may back up as often again, and the plan is full."""
    spec = generate_specs(96, seed=0)[95]
    scen = build_scenario(spec)
    params = replace(scen.params, max_backtracks=8)
    result = plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params)
    assert result.plan.summary["backtracks"] > params.max_backtracks
    assert result.plan.t[-1] == pytest.approx(scen.motion.t_end)


def test_a_neighbour_regrasps_first_to_free_a_finger_that_must_let_go(tmp_path):
    """Suite spec 95 (the Allegro hand turning a random convex mesh by -141 deg while it
    moves): a finger whose hold is about to end cannot lift off, the others not being in
    force closure without it (the middle finger once failed so at t=5.36 s). Another
    finger regrasps first, onto a contact with which the others hold without it; when
    the freed finger lifts off, that contact is still held and the contacts held then
    are in force closure without it (the planner's test, recomputed from the plan file):
    a full plan that passes the independent re-check."""
    scen = build_scenario(generate_specs(96, seed=0)[95])
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    plan = Plan.load(result.plan.save(tmp_path / "plan.json"))
    moves = plan.regrasps()
    freeing = [r for r in moves if r.reason.startswith("moves so that ")]
    assert freeing, [r.reason for r in moves]
    for freed in {r.reason.split()[3] for r in freeing}:
        first = next(r for r in freeing if r.reason.split()[3] == freed)
        # the freed finger's next lift-off, and the last regrasp that freed it before
        lift = next(r for r in moves if r.finger == freed and r.t_start >= first.t_end - 1e-9)
        t = lift.t_start
        last = [r for r in freeing if r.reason.split()[3] == freed and r.t_end <= t + 1e-9][-1]
        held = {
            n: c
            for n, phases in plan.phases.items()
            if n != freed
            for c in phases
            if isinstance(c, ContactPhase) and c.t_start <= t + 1e-9 and t < c.t_end - 1e-9
        }
        assert np.allclose(held[last.finger].p_object, last.Q_object), (freed, t)
        p = np.array([c.p_object for c in held.values()])
        n = np.array([c.n_object for c in held.values()])
        assert len(held) >= 3
        assert is_force_closure(p, n, scen.params.mu, torque_scale_m=scen.obj.radius_m)
    check = recheck_plan(plan, max_step_rad=1e-3)
    assert check.ok, check.problems


def test_a_faster_regrasp_lands_before_another_hold_is_lost(tmp_path):
    """Suite spec 57 (the Allegro turning a hexagonal prism +205 deg at 41 deg/s about
    an axis through it): a finger must regrasp and land before another finger's hold
    is lost, sooner than a regrasp of the shortest duration (0.25 s) could. A faster
    one (as short as rush_duration_s, within the joint velocity limits) lands in time.
    The plan (full, or the part planned before a later failure) passes the independent
    re-check. Without faster regrasps, every regrasp takes the shortest duration at
    least. (Spec 51 showed this until a Coal failure of a finger nearer the object than
    its curve got more inflation at once, spec 81 until regrasps were paced by their
    joints, spec 54 with 60 deg pad cones until a finger that let go could join again,
    and spec 78 until the grasp search's spacing ties and the IK's restart ties were
    decided on every machine alike: their plans no longer need a faster regrasp.)"""
    scen = build_scenario(generate_specs(58, seed=0)[57])
    try:
        planned = plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
        ).plan
    except PlanningError as exc:
        planned = exc.partial
    plan = Plan.load(planned.save(tmp_path / "plan.json"))
    D = scen.params.regrasp.duration_s
    fast = [r for r in plan.regrasps() if r.t_end - r.t_start < D - 1e-9]
    assert fast, [(r.finger, r.t_end - r.t_start) for r in plan.regrasps()]
    t, q = np.asarray(plan.t), np.asarray(plan.q)
    for r in fast:
        assert "a faster regrasp" in r.reason
        # another finger's hold, held when this regrasp lands, ends before one of the
        # shortest duration could have landed
        ends = [
            ph.t_end
            for n, phases in plan.phases.items()
            if n != r.finger
            for ph in phases
            if isinstance(ph, ContactPhase)
            and ph.t_start <= r.t_end + 1e-9
            and r.t_end - 1e-9 <= ph.t_end < r.t_start + D - 1e-9
        ]
        assert ends, (r.finger, r.t_start, r.t_end)
        assert r.t_end - r.t_start >= scen.params.rush_duration_s - 1e-9
        # within the joint velocity limits (finite differences of the plan's samples)
        f = scen.hand.finger(r.finger)
        k = np.flatnonzero((t >= r.t_start - 1e-9) & (t <= r.t_end + 1e-9))
        speed = np.abs(np.diff(q[k][:, f.q_indices], axis=0)) / np.diff(t[k])[:, None]
        assert np.all(speed <= f.velocity_limit * (1 + 1e-6)), speed.max(axis=0)
    check = recheck_plan(plan, max_step_rad=1e-3)
    assert check.ok, check.problems
    # without faster regrasps (a full plan or not), every regrasp takes D at least
    slow = replace(scen.params, rush_duration_s=None)
    try:
        other = plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=slow
        ).plan
    except PlanningError as exc:
        other = exc.partial
    assert other.regrasps()
    assert all(r.t_end - r.t_start >= D - 1e-9 for r in other.regrasps())


def test_a_neighbour_makes_room_for_a_hand_over(tmp_path):
    """The five-finger hand turning the hexagon -80 deg at 10 deg/s (60 deg friction
    cone): the index comes to have no contact inside its limits, and with three fingers
    left to take turns it can only let go if the idle little finger joins in its place;
    but the ring finger fills the room the little finger needs. The ring regrasps
    first, out of that room, then the index lets go and the little finger joins
    (verified release and join phases), and the plan is full.

    (The neighbour turning it -100 deg showed this until a candidate exactly a
    separation away was kept on every machine: its ring then makes room elsewhere and
    the little finger finds none.) What is asserted is the hand-over, from the plan or
    the partial plan of a failure; a full plan must pass the independent re-check."""
    scen = make_scenario("five_finger", "hexagon", angle_deg=-80, rate_deg_s=10, contact=CONE_60)
    try:
        plan = plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
        ).plan
        full = True
    except PlanningError as exc:
        assert exc.partial is not None
        plan, full = exc.partial, False
    plan = Plan.load(plan.save(tmp_path / "plan.json"))
    made = [r for r in plan.regrasps() if r.reason.startswith("makes room for little to join")]
    assert made and all(r.finger != "little" for r in made)
    released = [ph for ph in plan.phases["index"] if ph.kind == "release"]
    joined = [ph for ph in plan.phases["little"] if ph.kind == "join"]
    assert released and joined
    assert made[0].t_end <= released[0].t_start + 1e-9
    assert released[0].t_start <= joined[0].t_start + 1e-9
    if full:
        check = recheck_plan(plan, max_step_rad=1e-3)
        assert check.ok, check.problems
        assert check.min_holding >= 3


def test_soft_fingertips_let_two_fingers_hold_a_turn_point_contacts_cannot(tmp_path):
    """Suite spec 7 (the Allegro turning a box -160 deg while it drifts): with point
    contacts the plan fails (two holds end within one regrasp of each other, and three
    fingers must hold while one is in the air); with soft fingertips (1 mm of
    torsional friction, ``ContactModel.torsion_m``) the thumb and one finger may hold
    the box alone, and the plan is full. Its file records the torsion, and the
    re-check (its own wrench model, the torsion read from the file) finds every held
    set in force closure, two fingers at times."""
    spec = generate_specs(8, seed=0)[7]
    with pytest.raises(PlanningError) as point:
        plan_scenario(build_scenario(spec))
    assert point.value.kind is not None and point.value.partial is not None
    soft = ContactModel(torsion_m=0.001)
    scen = build_scenario(spec, contact=soft)
    assert scen.params.contact.torsion_m == 0.001 and scen.params.fewest_holding == 2
    plan = plan_scenario(scen).plan
    loaded = Plan.load(plan.save(tmp_path / "soft.json"))
    assert loaded.torsion_m == 0.001
    check = recheck_plan(loaded)
    assert check.ok, check.problems
    assert check.min_holding == 2 and check.min_closure_epsilon > 1e-9
    assert not recheck_plan(loaded, torsion_m=0.0).ok  # two point contacts never hold
