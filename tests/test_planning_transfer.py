"""Tests of the joint-space fallback of a regrasp (regrasp_pin.planning.transfer).

The scenes are those of tests/test_planning_regrasp.py (five-finger hand, a 40 x 60 x
40 mm box, the index finger): "edge" puts P and Q on the two faces around a vertical
edge that points away from the palm, so that the straight joint-space move from P to Q
cuts into the box (asserted there). Every returned trajectory is re-checked here with
the independent Pinocchio + Coal distances of that module, densified to 1 mrad joint
steps.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_planning_regrasp import (
    CASES,
    EDGE,
    FINGER,
    PENETRATION_TOL_M,
    UPRIGHT,
    CoalCheck,
    Scene,
    dense,
)

import regrasp_pin.planning.regrasp as regrasp_module
import regrasp_pin.planning.transfer as transfer_module
from regrasp_pin.exceptions import FailureKind, InputError, PlanningError, UnfoldError
from regrasp_pin.model.clearance import FingerClearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.planning.regrasp import RegraspParams
from regrasp_pin.planning.timing import MJ_PEAK, minimum_jerk
from regrasp_pin.planning.transfer import LIFT_FRACTION, Transfer, plan_transfer

PARAMS = RegraspParams()
IK_TOL_M = PARAMS.ik_tol_m


@pytest.fixture(scope="module")
def hand() -> Hand:
    return Hand.five_finger()


@pytest.fixture(scope="module")
def checker(hand) -> CoalCheck:
    return CoalCheck(hand, FINGER)


@pytest.fixture(scope="module")
def scenes(hand) -> dict[str, Scene]:
    return {
        "upright-moving": Scene(hand, UPRIGHT, 10.0),
        "edge-static": Scene(hand, EDGE, 0.0, 0.1, 0.001),
        "edge-moving": Scene(hand, EDGE, 10.0, 0.1, 0.001),
    }


def transfer(
    scene: Scene, p_object, q_object, duration_s: float = 0.8, time_law: str = "minimum-jerk"
) -> Transfer:
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    S, M = scene.sample, scene.manifold
    return plan_transfer(
        scene.hand,
        scene.obj,
        scene.motion,
        FINGER,
        0.0,
        duration_s,
        (S.points[i_p], S.normals[i_p]),
        (S.points[i_q], S.normals[i_q]),
        M.q[0, i_p],
        M.q[1, i_q],
        scene.q_neutral,
        clearance_m=PARAMS.clearance_m,
        link_clearance_m=PARAMS.link_clearance_m,
        finger_clearance_m=PARAMS.finger_clearance_m,
        ik_tol_m=IK_TOL_M,
        sample_dt_s=PARAMS.sample_dt_s,
        time_law=time_law,
    )


def recheck_transfer(
    checker: CoalCheck,
    scene: Scene,
    times,
    q,
    t0: float,
    D: float,
    shares: tuple[float, float] = (LIFT_FRACTION, LIFT_FRACTION),
) -> dict:
    """Dense independent re-check: no geometry of the finger in the box; between the
    lift and the approach (``shares`` of ``D``) every geometry keeps the clearance;
    joints and speeds within limits."""
    f = checker.finger
    q_full = scene.q_neutral(times)
    q_full[:, f.q_indices] = q
    t_d, q_d, T_d = dense(times, q_full, scene.motion)
    d_obj, d_ff, _ = checker.run(q_d, T_d)
    tau = (t_d - t0) / D
    flight = (tau > shares[0] + 1e-9) & (tau < 1.0 - shares[1] - 1e-9)
    assert d_obj.min() >= -PENETRATION_TOL_M, f"penetrates by {-1e3 * d_obj.min():.3f} mm"
    assert d_obj[flight].min() >= PARAMS.clearance_m - PENETRATION_TOL_M
    assert d_ff.min() > 0.0
    q_f = q_d[:, f.q_indices]
    assert np.all(q_f >= f.lower - 1e-9) and np.all(q_f <= f.upper + 1e-9)
    speed = np.abs(np.diff(q, axis=0)) / np.diff(times)[:, None]
    assert np.all(speed <= f.velocity_limit)
    return {"min_flight_m": float(d_obj[flight].min()), "n_flight": int(flight.sum())}


@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), [CASES[3], *CASES[4:]])
def test_a_transfer_lands_on_q_and_passes_an_independent_recheck(
    scenes, checker, scene_name, p_object, q_object
):
    scene = scenes[scene_name]
    moved = transfer(scene, p_object, q_object)
    assert moved.report.ok
    stats = recheck_transfer(checker, scene, moved.times_s, moved.q, 0.0, 0.8)
    assert stats["n_flight"] > 0
    # FK round trip: the tip centre touches P at lift-off and Q at landing, and backs
    # off along the normals by the clearance at the ends of the lift and the approach
    S, f = scene.sample, checker.finger
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    T = scene.motion.pose(moved.times_s)
    tip_obj = np.einsum("nji,nj->ni", T[:, :3, :3], f.fk(moved.q) - T[:, :3, 3])
    r = f.tip_radius
    assert np.linalg.norm(tip_obj[0] - (S.points[i_p] + r * S.normals[i_p])) <= IK_TOL_M
    assert np.linalg.norm(tip_obj[-1] - (S.points[i_q] + r * S.normals[i_q])) <= IK_TOL_M
    lifted = moved.keyframes_object[1]
    above_p = S.points[i_p] + (r + PARAMS.clearance_m) * S.normals[i_p]
    assert np.linalg.norm(lifted - above_p) <= IK_TOL_M
    np.testing.assert_allclose(moved.tip_object, tip_obj, atol=1e-9)
    # the smallest clearance it reports is what the re-check finds in the transfer
    assert moved.min_clearance_m >= PARAMS.clearance_m - PENETRATION_TOL_M


@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), CASES[4:])
def test_around_an_edge_the_transfer_goes_through_a_raised_via(
    scenes, checker, scene_name, p_object, q_object
):
    # the straight move between the backed-off configurations cuts the edge region,
    # so the first via height that passes is above zero
    moved = transfer(scenes[scene_name], p_object, q_object)
    assert moved.via_height > 0.0
    assert len(moved.keyframes_object) == 5


def test_too_short_a_transfer_is_a_velocity_failure_with_its_numbers(scenes):
    with pytest.raises(PlanningError) as info:
        transfer(scenes["edge-static"], *CASES[4][1:], duration_s=0.04)
    exc = info.value
    assert exc.kind == FailureKind.VELOCITY and exc.finger == FINGER
    assert exc.measured > exc.required > 0.0


def test_a_failure_the_caller_drops_skips_the_too_fast_vias_coal_checks(scenes, monkeypatch):
    # 0.04 s: every via is too fast; the reported failure Coal-checks them to decide
    # between their velocity failure and their geometry's; a dropped one (a retry's)
    # is a too fast via's velocity failure, without a Coal check
    real_vias, real_verify = transfer_module._through_vias, transfer_module.verify_or_raise
    checks: list[int] = []
    outcomes: dict[bool, PlanningError] = {}

    def counted(*args, **kwargs):
        checks[-1] += 1
        return real_verify(*args, **kwargs)

    def both(m, ends, reported=True):
        for flag in (True, False):
            checks.append(0)
            with pytest.raises(PlanningError) as info:
                real_vias(m, ends, flag)
            outcomes[flag] = info.value
        raise outcomes[True]

    monkeypatch.setattr(transfer_module, "verify_or_raise", counted)
    monkeypatch.setattr(transfer_module, "_through_vias", both)
    with pytest.raises(PlanningError):
        transfer(scenes["edge-static"], *CASES[4][1:], duration_s=0.04)
    assert checks[0] > 0 and checks[1] == 0
    assert outcomes[False].kind == FailureKind.VELOCITY
    assert outcomes[False].measured > outcomes[False].required > 0.0


@pytest.mark.parametrize(
    ("scene_name", "case", "duration_s"),
    [("upright-moving", CASES[3], 0.2), ("edge-moving", CASES[5], 0.25)],
)
def test_where_the_even_split_is_too_fast_the_parts_are_paced_within_the_limits(
    scenes, checker, monkeypatch, scene_name, case, duration_s
):
    # a quarter of the duration each for the lift and the approach moves a joint too
    # fast in these short transfers; paced by the joints' needs, the same transfer
    # stays within the limits and passes the independent re-check
    scene = scenes[scene_name]
    monkeypatch.setattr(transfer_module, "_paced_shares", lambda *args: None)
    with pytest.raises(PlanningError) as info:
        transfer(scene, *case[1:], duration_s=duration_s)
    assert info.value.kind == FailureKind.VELOCITY
    monkeypatch.undo()
    real_vias, flags = transfer_module._through_vias, []

    def recorded(m, ends, reported=True):
        flags.append(reported)
        return real_vias(m, ends, reported)

    monkeypatch.setattr(transfer_module, "_through_vias", recorded)
    moved = transfer(scene, *case[1:], duration_s=duration_s)
    assert flags == [True, False]  # the paced retry's failure would be dropped
    t_lift, t_land = moved.keyframe_times_s[1], moved.keyframe_times_s[-2]
    shares = (t_lift / duration_s, 1.0 - t_land / duration_s)
    assert shares != pytest.approx((LIFT_FRACTION, LIFT_FRACTION))
    assert min(shares) >= transfer_module.MIN_SHARE - 1e-9
    stats = recheck_transfer(checker, scene, moved.times_s, moved.q, 0.0, duration_s, shares)
    assert stats["n_flight"] > 0
    # the lift still ends at the clearance above P (FK round trip)
    S, f = scene.sample, checker.finger
    i_p = scene.contact(case[1])
    above_p = S.points[i_p] + (f.tip_radius + PARAMS.clearance_m) * S.normals[i_p]
    assert np.linalg.norm(moved.keyframes_object[1] - above_p) <= IK_TOL_M


def _ends_moving_joint(f, times, lift_rad: float):
    """An even split of ``times`` whose lift moves the finger's first joint by
    ``lift_rad`` (minimum jerk), the rest still."""
    tau = np.linspace(0.0, 1.0, len(times))
    lift = tau <= LIFT_FRACTION + 1e-12
    land = tau >= 1.0 - LIFT_FRACTION - 1e-12
    q_lift = np.zeros((int(lift.sum()), f.k))
    q_lift[:, 0] = lift_rad * minimum_jerk(tau[lift] / LIFT_FRACTION)
    q_app = np.repeat(q_lift[-1:], int(land.sum()), axis=0)
    return transfer_module._Ends(lift, land, q_lift, q_app)


def test_paced_shares_give_a_too_fast_part_the_time_its_joints_need(hand):
    f = hand.fingers[FINGER]
    times = np.linspace(0.0, 0.4, 41)  # 40 steps: 10 each for the lift and the approach
    # a lift at 1.5 times the limit: it needs 1.5 x (1 + margin) of its quarter, the
    # still parts their least; the rest of the time is shared as the split shares it
    lift_rad = 1.5 * f.velocity_limit[0] * 0.1 / 1.875
    ends = _ends_moving_joint(f, times, lift_rad)
    peak = transfer_module._peak_share(f, times[ends.lift], ends.q_lift)
    assert 1.4 < peak < 1.5  # sampled: a little under the continuous peak
    s_lift, s_land = transfer_module._paced_shares(f, times, ends, MJ_PEAK)
    need = 0.25 * peak * (1.0 + transfer_module.PACE_MARGIN)
    assert need <= s_lift < need + 0.25 * (1.0 - need - 0.2) + 1.0 / 40 + 1e-12
    assert s_land >= transfer_module.MIN_SHARE
    assert (s_lift * 40) == pytest.approx(round(s_lift * 40)) and s_lift + s_land < 1.0
    # within the limits, or too fast for any split of the duration: None
    assert (
        transfer_module._paced_shares(
            f, times, _ends_moving_joint(f, times, 0.5 * lift_rad), MJ_PEAK
        )
        is None
    )
    assert (
        transfer_module._paced_shares(f, times, _ends_moving_joint(f, times, 4 * lift_rad), MJ_PEAK)
        is None
    )


def test_by_the_cruise_law_a_transfer_too_fast_by_minimum_jerk_passes(scenes, checker):
    """In 0.17 s the index's transfer on the moving box turns a joint too fast by
    minimum jerk; its move by the cruise law (peak 1.43 instead of 1.875 times the mean
    speed) passes the independent re-check, joint speeds included. Through a via the
    joints turn unevenly, so it is not always so: on the moving edge (CASES[5]) the
    cruise law needs 0.32 s where minimum jerk needs 0.22 s."""
    case = CASES[3]
    scene = scenes[case[0]]
    with pytest.raises(PlanningError) as info:
        transfer(scene, *case[1:], duration_s=0.17)
    assert info.value.kind == FailureKind.VELOCITY
    moved = transfer(scene, *case[1:], duration_s=0.17, time_law="cruise")
    assert moved.report.ok
    recheck_transfer(checker, scene, moved.times_s, moved.q, 0.0, 0.17)


def test_a_transfer_within_the_limits_keeps_the_even_split(scenes):
    moved = transfer(scenes["edge-moving"], *CASES[5][1:], duration_s=0.4)
    assert moved.keyframe_times_s[1] == pytest.approx(LIFT_FRACTION * 0.4)
    assert moved.keyframe_times_s[-2] == pytest.approx((1.0 - LIFT_FRACTION) * 0.4)


def test_of_the_vias_too_fast_the_least_too_fast_whose_geometry_passes_is_reported(
    scenes, monkeypatch
):
    # at 0.5 s no fixed via passes (the sampled ones left out): alone, each raises
    # either its velocity failure (its geometry passes the Coal check) or its Coal
    # failure; together, the velocity failure reported is the smallest over-speed among
    # those whose geometry passes, the one a stretch of the duration fixes soonest
    scene, case = scenes["edge-static"], CASES[4][1:]
    heights = transfer_module.VIA_HEIGHTS
    monkeypatch.setattr(transfer_module, "_clear_vias", lambda *args: iter([]))
    alone = {}
    for height in heights:
        monkeypatch.setattr(transfer_module, "VIA_HEIGHTS", (height,))
        with pytest.raises(PlanningError) as info:
            transfer(scene, *case, duration_s=0.5)
        alone[height] = info.value
    monkeypatch.setattr(transfer_module, "VIA_HEIGHTS", heights)
    fixable = [e.measured / e.required for e in alone.values() if e.kind == FailureKind.VELOCITY]
    assert any(e.kind != FailureKind.VELOCITY for e in alone.values())  # the straight move
    with pytest.raises(PlanningError) as info:
        transfer(scene, *case, duration_s=0.5)
    if fixable:
        assert info.value.kind == FailureKind.VELOCITY
        assert info.value.measured / info.value.required == pytest.approx(min(fixable))
    else:
        assert info.value.kind != FailureKind.VELOCITY


def test_plan_regrasp_falls_back_to_the_transfer_when_no_surface_variant_passes(
    scenes, checker, monkeypatch
):
    scene = scenes["edge-moving"]
    p_object, q_object = CASES[5][1:]

    def no_surface_path(task, p):
        raise PlanningError(
            "no surface path (test)",
            finger=FINGER,
            time_s=0.1,
            kind=FailureKind.OBJECT_CLEARANCE,
            measured=-1e-3,
            required=0.0,
        )

    monkeypatch.setattr(regrasp_module, "surface_path", no_surface_path)
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    result = scene.plan(i_p, i_q, q_land=scene.manifold.q[1, i_q])
    assert result.route == "joint-space" and result.grid_path is None
    assert result.report.ok
    kinds = [a.kind for a in result.attempts]
    assert kinds and all(k == FailureKind.OBJECT_CLEARANCE for k in kinds)
    recheck_transfer(checker, scene, result.times_s, result.q, 0.0, result.params.duration_s)
    np.testing.assert_array_equal(result.Q_object, scene.sample.points[i_q])
    # the surface path is taken whenever it passes: the same call without the patch
    monkeypatch.undo()
    plain = scene.plan(i_p, i_q, q_land=scene.manifold.q[1, i_q])
    assert plain.route == "surface" and plain.grid_path is not None


def test_where_no_region_can_be_unfolded_the_transfer_is_the_route(scenes, checker, monkeypatch):
    """P and Q too many faces apart (a mesh with many small faces) leave no region to
    grid: that is a ``grid-unreachable`` attempt of the surface route, and the transfer
    goes instead; with the surface route alone it is the failure."""
    scene = scenes["edge-moving"]
    i_p, i_q = (scene.contact(c) for c in CASES[5][1:])
    q_land = scene.manifold.q[1, i_q]

    def too_far(obj, P, Q, **kwargs):
        raise UnfoldError("the region cannot be unfolded (test)")

    monkeypatch.setattr(regrasp_module, "build_surface_grid", too_far)
    result = scene.plan(i_p, i_q, q_land=q_land)
    assert result.route == "joint-space" and result.report.ok
    assert [(a.kind, a.what) for a in result.attempts] == [
        (FailureKind.GRID_UNREACHABLE, "surface grid")
    ]
    recheck_transfer(checker, scene, result.times_s, result.q, 0.0, result.params.duration_s)
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, q_land=q_land, route="surface")
    assert info.value.kind == FailureKind.GRID_UNREACHABLE
    # where the transfer fails too, its failure is the one reported, whatever its kind

    def blocked(*args, **kwargs):
        raise PlanningError("blocked (test)", finger=FINGER, kind=FailureKind.OBJECT_CLEARANCE)

    monkeypatch.setattr(regrasp_module, "plan_transfer", blocked)
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, q_land=q_land)
    assert info.value.kind == FailureKind.OBJECT_CLEARANCE
    assert [a.what for a in info.value.attempts] == ["surface grid", "joint-space transfer"]


def test_when_the_transfer_fails_too_the_error_keeps_every_attempt(scenes, monkeypatch):
    scene = scenes["edge-static"]
    p_object, q_object = CASES[4][1:]

    def no_surface_path(task, p):
        raise PlanningError(
            "no surface path (test)", finger=FINGER, kind=FailureKind.FINGER_COLLISION
        )

    monkeypatch.setattr(regrasp_module, "surface_path", no_surface_path)
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    short = dataclasses.replace(PARAMS, duration_s=0.04)
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, params=short, q_land=scene.manifold.q[1, i_q])
    exc = info.value
    # the transfer was too fast: its velocity failure is what a longer duration fixes
    assert exc.kind == FailureKind.VELOCITY
    assert [a.what for a in exc.attempts][-1] == "joint-space transfer"


def _fails_with(kind: FailureKind):
    def no_surface_path(task, p):
        raise PlanningError(
            "no surface path (test)", finger=FINGER, kind=kind, measured=2.0, required=1.0
        )

    return no_surface_path


def test_route_selects_the_surface_path_the_fallback_or_both(scenes, monkeypatch):
    scene = scenes["edge-moving"]
    i_p, i_q = (scene.contact(c) for c in CASES[5][1:])
    q_land = scene.manifold.q[1, i_q]
    # the fallback alone, even where the surface path passes
    only = scene.plan(i_p, i_q, q_land=q_land, route="joint-space")
    assert only.route == "joint-space" and not only.attempts
    monkeypatch.setattr(regrasp_module, "surface_path", _fails_with(FailureKind.OBJECT_CLEARANCE))
    # the surface path alone: its failure, and no transfer tried
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, q_land=q_land, route="surface")
    assert info.value.kind == FailureKind.OBJECT_CLEARANCE
    assert all(a.what != "joint-space transfer" for a in info.value.attempts)
    # a surface path too fast for its duration: the caller tries a longer one first
    monkeypatch.setattr(regrasp_module, "surface_path", _fails_with(FailureKind.VELOCITY))
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, q_land=q_land)
    assert info.value.kind == FailureKind.VELOCITY
    assert [a.what for a in info.value.attempts] != [] and all(
        a.what != "joint-space transfer" for a in info.value.attempts
    )


def test_an_unknown_route_is_an_input_error_naming_it(scenes):
    scene = scenes["edge-moving"]
    i_p, i_q = (scene.contact(c) for c in CASES[5][1:])
    with pytest.raises(InputError) as info:
        scene.plan(i_p, i_q, route="air")
    assert info.value.argument == "route" and "joint-space" in str(info.value)


@pytest.mark.parametrize(
    ("scene_name", "case"), [("edge-moving", CASES[5]), ("upright-moving", CASES[3])]
)
def test_joint_velocities_are_continuous_where_the_transfer_meets_the_lift_and_approach(
    scenes, scene_name, case
):
    # the lift and the approach follow the turning object, so the finger moves there;
    # the transfer must leave and arrive at those velocities, not at rest: the
    # finite-difference velocity changes across each junction by no more than
    # one step's worth of the smooth motion's change (a step would be ~100 %)
    moved = transfer(scenes[scene_name], case[1], case[2])
    t, q = moved.times_s, moved.q
    tau = (t - t[0]) / (t[-1] - t[0])
    i_a = int(np.flatnonzero(tau <= LIFT_FRACTION + 1e-12)[-1])
    i_b = int(np.flatnonzero(tau >= 1.0 - LIFT_FRACTION - 1e-12)[0])
    v = np.diff(q, axis=0) / np.diff(t)[:, None]
    for i in (i_a, i_b):
        following = np.linalg.norm(v[i - 1])
        assert following > 0.05  # the object turns at 10 deg/s: the finger moves
        assert np.linalg.norm(v[i] - v[i - 1]) <= 0.2 * following


def test_a_landing_seed_of_the_wrong_shape_is_an_input_error_naming_it(scenes):
    scene = scenes["edge-moving"]
    i_p, i_q = (scene.contact(c) for c in CASES[5][1:])
    with pytest.raises(InputError) as info:
        scene.plan(i_p, i_q, q_land=np.zeros(7), route="surface")
    assert info.value.argument == "q_land"


@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), CASES[4:])
def test_where_no_fixed_via_passes_a_sampled_via_does(
    scenes, checker, scene_name, p_object, q_object, monkeypatch
):
    """Around the edge the straight move cuts the box; with the raised vias taken
    away, the transfer searches vias sampled clear of the box (and of the other
    fingers) at its middle, and one passes the independent dense re-check. The vias
    it was given are clear there by the margin (independent Coal distances)."""
    monkeypatch.setattr(transfer_module, "VIA_HEIGHTS", (0.0,))
    real, given = transfer_module._clear_vias, []

    def spy(hand, obj, f, q_mid, T_mid, *rest):
        vias = list(real(hand, obj, f, q_mid, T_mid, *rest))
        given.append((q_mid, T_mid, vias))
        return iter(vias)

    monkeypatch.setattr(transfer_module, "_clear_vias", spy)
    scene = scenes[scene_name]
    moved = transfer(scene, p_object, q_object)
    assert np.isnan(moved.via_height) and len(moved.keyframes_object) == 5
    recheck_transfer(checker, scene, moved.times_s, moved.q, 0.0, 0.8)
    [(q_mid, T_mid, vias)] = given
    assert 0 < len(vias) <= transfer_module.SAMPLED_SCREENED
    q_full = np.tile(q_mid, (len(vias), 1))
    q_full[:, checker.finger.q_indices] = np.array(vias)
    d_obj, d_ff, _ = checker.run(q_full, np.repeat(T_mid[None], len(vias), axis=0))
    assert d_obj.min() >= PARAMS.clearance_m + transfer_module.VIA_MARGIN_M - 1e-9
    assert d_ff.min() >= PARAMS.finger_clearance_m + transfer_module.VIA_MARGIN_M - 1e-9


def test_sampled_vias_that_fail_leave_the_fixed_vias_failure_as_it_was(scenes, monkeypatch):
    """Sampled vias are tried only for a passing motion: when none passes (here one
    through the middle of the box), the failure reported is the fixed vias' own."""
    scene, case = scenes["edge-static"], CASES[4][1:]
    monkeypatch.setattr(transfer_module, "VIA_HEIGHTS", (0.0,))
    monkeypatch.setattr(transfer_module, "_clear_vias", lambda *args: iter([]))
    with pytest.raises(PlanningError) as without:
        transfer(scene, *case)
    f = scene.hand.finger(FINGER)
    inside = f.ik(np.zeros((1, 3)) + scene.motion.pose(np.array([0.4]))[0, :3, 3], f.q_mid).q[0]
    monkeypatch.setattr(transfer_module, "_clear_vias", lambda *args: iter([inside, f.q_mid]))
    with pytest.raises(PlanningError) as through_bad:
        transfer(scene, *case)
    a, b = without.value, through_bad.value
    assert (a.kind, a.measured, a.required, a.time_s) == (b.kind, b.measured, b.required, b.time_s)


def heights_above_plane(f, q: np.ndarray, T: np.ndarray, contact) -> float:
    """The fingertip centre's height above the contact's tangent plane minus the tip
    radius, object pose ``T`` (forward kinematics) [m]."""
    tip = T[:3, :3].T @ (f.fk(q[None])[0] - T[:3, 3])
    return float((tip - contact[0]) @ contact[1]) - f.tip_radius


def _tilted(n: np.ndarray, deg: float) -> np.ndarray:
    """A unit direction ``deg`` from ``n`` (object frame)."""
    side = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    return np.cos(np.radians(deg)) * n + np.sin(np.radians(deg)) * side


def _crossing(time_s: float = 0.05) -> PlanningError:
    return PlanningError(
        "crosses another finger", finger=FINGER, time_s=time_s,
        kind=FailureKind.FINGER_COLLISION, measured=-0.001, required=0.0005,
    )  # fmt: skip


def test_a_way_into_another_finger_is_tried_again_lifted_apart(scenes, checker, monkeypatch):
    """Every via of the lift along the normal "crosses another finger" (a stand-in
    failure): the transfer is tried again lifted off along the directions apart, and
    the one that passes leaves P along that direction, to the clearance above the
    tangent plane where the lift ends (forward kinematics), and passes the independent
    re-check."""
    scene, (p_object, q_object) = scenes["upright-moving"], CASES[3][1:]
    real_vias, real_ends = transfer_module._through_vias, transfer_module._lift_and_approach
    lifted: list = []
    asked: list = []
    flags: list = []

    def crossed_unless_apart(m, ends, reported=True):
        flags.append(reported)
        if lifted[-1] is None:
            raise _crossing()
        return real_vias(m, ends, reported)

    def ends_of(m, tau, q_start, q_land, tol, shares, lift_dir=None):
        lifted.append(lift_dir)
        return real_ends(m, tau, q_start, q_land, tol, shares, lift_dir)

    def directions(f, T, contact, q, height, gap, tol, toward=None, baseline_m=None):
        asked.append((contact[0], height, T, q, gap(q), baseline_m))
        return np.array([_tilted(contact[1], 30.0)])

    monkeypatch.setattr(transfer_module, "_through_vias", crossed_unless_apart)
    monkeypatch.setattr(transfer_module, "_lift_and_approach", ends_of)
    monkeypatch.setattr(transfer_module, "directions_apart", directions)
    moved = transfer(scene, p_object, q_object)
    assert flags == [True, False]  # the lift apart's failure would be dropped
    S = scene.sample
    i = scene.contact(p_object)
    p, n = S.points[i], S.normals[i]
    [(at, height, T_top, q_top, gap, baseline)] = asked
    assert np.array_equal(at, p) and height == PARAMS.clearance_m
    recheck_transfer(checker, scene, moved.times_s, moved.q, 0.0, 0.8)
    f = checker.finger
    k = int(np.floor(LIFT_FRACTION * (len(moved.times_s) - 1) + 1e-9))  # where the lift ends
    T = scene.motion.pose(moved.times_s[k : k + 1])[0]
    # judged where the lift along the normal ends, the others where they hold then,
    # against that lift's own gap (an independent FingerClearance)
    np.testing.assert_allclose(T_top, T, atol=1e-12)
    fc = FingerClearance(scene.hand, FINGER)
    q_full = scene.q_neutral(moved.times_s[k : k + 1])[0]
    q_full[f.q_indices] = q_top
    assert gap == pytest.approx(fc(q_full), abs=1e-12) and baseline == gap
    assert np.linalg.norm(heights_above_plane(f, q_top, T, (p, n)) - PARAMS.clearance_m) < 1e-4
    tip = T[:3, :3].T @ (f.fk(moved.q[k : k + 1])[0] - T[:3, 3])
    d = _tilted(n, 30.0)
    want = p + f.tip_radius * n + PARAMS.clearance_m / float(d @ n) * d
    assert np.linalg.norm(tip - want) <= IK_TOL_M + 1e-9


def test_when_no_lift_apart_passes_the_first_failure_stands(scenes, monkeypatch):
    scene, case = scenes["upright-moving"], CASES[3][1:]
    first, tried = _crossing(), []

    def crossed(m, ends, reported=True):
        tried.append(reported)
        if len(tried) == 1:
            raise first
        raise PlanningError("other", finger=FINGER, kind=FailureKind.OBJECT_CLEARANCE)

    monkeypatch.setattr(transfer_module, "_through_vias", crossed)
    with pytest.raises(PlanningError) as info:
        transfer(scene, *case)
    # directions apart were tried, their failures dropped unreported
    assert info.value is first and tried[0] and len(tried) > 1 and not any(tried[1:])


@pytest.mark.parametrize("duration_s", [0.04, 0.8])
def test_the_failure_reported_is_the_dense_checks_whatever_the_samples_showed(
    scenes, monkeypatch, duration_s
):
    """A via that fails at its own samples is given up without the dense check; the
    failure a transfer reports is still the dense check's, the same numbers as with
    every via checked densely (0.04 s: every via too fast, their geometry decides the
    kind; 0.8 s, one via through the box's middle: a Coal failure)."""
    scene, case = scenes["edge-static"], CASES[4][1:]
    monkeypatch.setattr(transfer_module, "VIA_HEIGHTS", (0.0,))
    monkeypatch.setattr(transfer_module, "_clear_vias", lambda *args: iter([]))
    real_sure, found = transfer_module.failure_at_samples, []

    def recorded(*args, **kwargs):
        found.append(real_sure(*args, **kwargs))
        return found[-1]

    monkeypatch.setattr(transfer_module, "failure_at_samples", recorded)
    with pytest.raises(PlanningError) as by_samples:
        transfer(scene, *case, duration_s=duration_s)
    assert found and all(x is not None for x in found)  # decided at the samples
    monkeypatch.setattr(transfer_module, "failure_at_samples", lambda *args, **kwargs: None)
    with pytest.raises(PlanningError) as dense:
        transfer(scene, *case, duration_s=duration_s)
    a, b = by_samples.value, dense.value
    assert (a.kind, a.measured, a.required, a.time_s) == (b.kind, b.measured, b.required, b.time_s)
