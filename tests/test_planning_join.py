"""An idle finger joining the grasp (regrasp_pin.planning.join), against FK and
computeDistances."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import assert_close, held_grasp
from test_planning_release import _distance_to_object

from regrasp_pin import make_scenario
from regrasp_pin.exceptions import FailureKind, InputError, PlanningError
from regrasp_pin.grasp.choice import choose_new_contact
from regrasp_pin.grasp.holding import holding_q, rest_configuration
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.planning.join import join_duration, join_durations, plan_join
from regrasp_pin.planning.timing import MJ_PEAK, PATH_FACTOR

T0_S = 0.3
APPROACH_S = 0.1
CLEARANCE_M = 0.003


@pytest.fixture(scope="module")
def scene():
    """The demo's first 1.2 s with the ring finger idle at rest: thumb, index and
    middle hold their initial contacts, and the ring finger joins from t=0.3 s onto the
    contact the paper's criterion picks at its arrival."""
    scen = make_scenario("five_finger", "hexagon")
    t = np.round(np.arange(0.0, 1.2 + 1e-9, 0.01), 9)
    scen = dataclasses.replace(scen, motion=ObjectMotion.from_poses(t, scen.motion.pose(t)))
    hand, p = scen.hand, scen.params
    _, _, holding = held_grasp(scen)
    holding.pop("ring")
    base = rest_configuration(hand, scen.obj, scen.motion, ["ring", "little"])

    def q_hand(times):
        q = np.broadcast_to(base, (times.size, base.size)).copy()
        for n, h in holding.items():
            q[:, hand.finger(n).q_indices] = holding_q(
                hand, scen.motion, n, h, times, p.contact.ik_tol_m
            )
        return q

    f = hand.finger("ring")
    sample = scen.obj.sample_surface(0.002)
    manifold = build_manifold(f, sample, scen.motion, np.linspace(0.0, 1.2, 13), contact=p.contact)
    q_from = base[f.q_indices]

    def choose(t_arrive):
        return choose_new_contact(
            hand,
            scen.obj,
            manifold,
            sample,
            t_arrive,
            P_object=sample.points[0],
            n_P_object=sample.normals[0],
            others={n: (h.p, h.n) for n, h in holding.items()},
            contact=p.contact,
            q_hand_arrive=q_hand(np.array([t_arrive]))[0],
        )

    first = choose(T0_S + 0.4)
    duration = join_duration(
        q_from, first.q_arrive, f.velocity_limit, minimum_s=0.4, approach_s=APPROACH_S, dt_s=0.01
    )
    return scen, q_hand, q_from, choose(T0_S + duration), duration


def _join(scene, Q=None, **kw):
    scen, q_hand, q_from, c, duration = scene
    args = dict(
        duration_s=duration,
        approach_s=APPROACH_S,
        clearance_m=CLEARANCE_M,
        dt_s=0.01,
        link_clearance_m=0.0,
        finger_clearance_m=0.0005,
        ik_tol_m=1e-5,
    )
    args.update(kw)
    Q = (c.p_object, c.n_object) if Q is None else Q
    return plan_join(
        scen.hand, scen.obj, scen.motion, "ring", T0_S, q_from, Q, c.q_arrive, q_hand, **args
    )


def test_the_finger_moves_from_rest_and_touches_q_along_its_normal(scene):
    scen, q_hand, q_from, c, duration = scene
    join = _join(scene)
    f = scen.hand.finger("ring")
    assert join.t_start == T0_S and join.t_end == pytest.approx(T0_S + duration)
    assert np.all(np.diff(join.times_s) > 0)
    assert_close(join.q[0], q_from, atol=1e-12, what="starts at rest")
    # FK of the planned configurations: the tip centre is r + clearance (1 - s) above Q
    # along its normal, in the moving object frame, over the approach
    app = join.times_s >= join.t_end - APPROACH_S - 1e-9
    T = scen.motion.pose(join.times_s[app])
    tip_obj = np.einsum("sji,sj->si", T[:, :3, :3], f.fk(join.q[app]) - T[:, :3, 3])
    height = (tip_obj - c.p_object) @ c.n_object - f.tip_radius
    lateral = np.linalg.norm(
        tip_obj - c.p_object - np.outer(height + f.tip_radius, c.n_object), axis=1
    )
    assert lateral.max() < 2e-5
    assert height[0] == pytest.approx(CLEARANCE_M, abs=2e-5)
    assert height[-1] == pytest.approx(0.0, abs=2e-5)
    assert np.all(np.diff(height) <= 2e-5)  # it only comes closer
    # joint speeds within the limits
    vel = np.abs(np.diff(join.q, axis=0)) / np.diff(join.times_s)[:, None]
    assert np.all(vel <= f.velocity_limit)


def test_its_clearance_is_the_smallest_compute_distances_before_the_approach(scene):
    scen, q_hand, _, _, _ = scene
    join = _join(scene)
    f = scen.hand.finger("ring")
    before = join.times_s <= join.t_end - APPROACH_S + 1e-9
    T = scen.motion.pose(join.times_s[before])
    q_full = q_hand(join.times_s[before])
    q_full[:, f.q_indices] = join.q[before]
    d = [
        _distance_to_object(scen.hand, scen.obj, "ring", q, Tk)
        for q, Tk in zip(q_full, T, strict=True)
    ]
    assert_close(join.min_clearance_m, min(d), atol=1e-6, what="clearance")
    assert join.min_clearance_m >= 0.5 * CLEARANCE_M - 5e-5


def test_failures_are_typed(scene):
    scen, _, _, c, duration = scene
    far = (c.p_object - 0.2 * c.n_object, c.n_object)  # 20 cm inside: out of reach
    with pytest.raises(PlanningError) as info:
        _join(scene, Q=far)
    assert info.value.kind == FailureKind.IK_UNREACHABLE and info.value.finger == "ring"
    with pytest.raises(PlanningError) as info:
        _join(scene, duration_s=APPROACH_S + 0.01)  # the transfer in 10 ms
    assert info.value.kind == FailureKind.VELOCITY
    assert info.value.measured > info.value.required
    with pytest.raises(PlanningError) as info:
        _join(scene, duration_s=2.0)  # lands after the motion's end
    assert info.value.kind == FailureKind.TOO_LATE
    with pytest.raises(InputError, match="approach_s"):
        _join(scene, approach_s=duration)


def test_join_durations_leave_the_approach_and_keep_the_transfer_under_the_limits():
    """Each join duration: the approach, plus a whole number of steps in which the
    transfer's largest joint move, allowed PATH_FACTOR for its detour, peaks at most at
    its limit (minimum jerk: MJ_PEAK times the mean speed), and one step less would not
    do unless the minimum decided."""
    rng = np.random.default_rng(5)
    q_from, q_land = rng.uniform(-1, 1, 4), rng.uniform(-1, 1, (8, 4))
    vmax = rng.uniform(1.0, 3.0, 4)
    approach, dt, minimum = 0.1, 0.01, 0.35
    D = join_durations(q_from, q_land, vmax, minimum_s=minimum, approach_s=approach, dt_s=dt)
    need = MJ_PEAK * PATH_FACTOR * np.max(np.abs(q_land - q_from) / vmax, axis=1)
    transfer = D - approach
    assert np.all(D >= minimum - 1e-12)
    assert np.all(transfer >= need - 1e-12)
    assert np.all((transfer - dt < need) | (transfer <= minimum - approach + 1e-9))
    assert join_duration(
        q_from, q_land[3], vmax, minimum_s=minimum, approach_s=approach, dt_s=dt
    ) == pytest.approx(D[3], abs=0.0)
