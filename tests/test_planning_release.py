"""Letting a finger go (regrasp_pin.planning.release), against FK and computeDistances."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from conftest import CONE_60, assert_close, held_grasp
from test_planning_lift import contacts_past_a_limit

from regrasp_pin import make_scenario
from regrasp_pin.exceptions import FailureKind, PlanningError
from regrasp_pin.grasp.holding import holding_q, rest_configuration
from regrasp_pin.model.clearance import FingerClearance
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box
from regrasp_pin.planning.release import check_failure, plan_release
from regrasp_pin.planning.timing import duration_for_move
from regrasp_pin.verify.finger_motion import verify_finger_motion

T_RELEASE_S = 0.3
CLEARANCE_M = 0.003


@pytest.fixture(scope="module")
def scene():
    """The demo's initial grasp (with 60 deg pad cones: CONE_60) held over the first
    0.8 s of the turn; the index finger lets go at 0.3 s, while it still holds."""
    scen = make_scenario("five_finger", "hexagon", contact=CONE_60)
    t = np.round(np.arange(0.0, 0.8 + 1e-9, 0.01), 9)
    scen = dataclasses.replace(scen, motion=ObjectMotion.from_poses(t, scen.motion.pose(t)))
    hand, p = scen.hand, scen.params
    _, base, holding = held_grasp(scen)

    def q_hand(times):
        q = np.broadcast_to(base, (times.size, base.size)).copy()
        for n, h in holding.items():
            if n != "index":
                q[:, hand.finger(n).q_indices] = holding_q(
                    hand, scen.motion, n, h, times, p.contact.ik_tol_m
                )
        return q

    h = holding["index"]
    q_r = holding_q(hand, scen.motion, "index", h, np.array([T_RELEASE_S]), 1e-5)[0]
    return scen, q_hand, h, q_r


def _release(scene, **kw):
    scen, q_hand, h, q_r = scene
    args = dict(
        clearance_m=CLEARANCE_M,
        back_off_s=0.1,
        dt_s=0.01,
        link_clearance_m=0.0,
        finger_clearance_m=0.0005,
        ik_tol_m=1e-5,
    )
    args.update(kw)
    return plan_release(
        scen.hand,
        scen.obj,
        scen.motion,
        "index",
        T_RELEASE_S,
        (h.p, h.n),
        q_r,
        q_hand,
        **args,
    )


def _distance_to_object(hand, obj, finger, q_full, T):
    """computeDistances: every geometry of the finger against the object."""
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    placement = pin.SE3(T[:3, :3], T[:3, 3])
    oid = gm.addGeometryObject(pin.GeometryObject("obj", 0, placement, obj.coal_geometry()))
    for g in hand.finger(finger).geometry_ids:
        gm.addCollisionPair(pin.CollisionPair(int(g), oid))
    gdata = pin.GeometryData(gm)
    pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, q_full)
    return min(r.min_distance for r in gdata.distanceResults)


def test_the_finger_backs_off_along_the_normal_and_stays(scene):
    scen, q_hand, h, q_r = scene
    rel = _release(scene)
    f = scen.hand.finger("index")
    assert rel.t_start == T_RELEASE_S and rel.t_end == scen.motion.t_end
    assert rel.times_s[0] == T_RELEASE_S and rel.times_s[-1] == pytest.approx(rel.t_end)
    assert np.all(np.diff(rel.times_s) > 0)
    assert_close(rel.q[0], q_r, atol=1e-12, what="starts where it held")
    # after the back-off the tip centre is `clearance` further out along the normal,
    # fixed in the palm frame (FK of the planned configurations)
    T_r = scen.motion.pose(np.array([T_RELEASE_S]))[0]
    c_touch = T_r[:3, :3] @ (h.p + f.tip_radius * h.n) + T_r[:3, 3]
    c_off = c_touch + CLEARANCE_M * (T_r[:3, :3] @ h.n)
    still = rel.times_s >= T_RELEASE_S + 0.1 - 1e-9
    assert still.sum() > 10
    assert_close(f.fk(rel.q[still]), np.tile(c_off, (still.sum(), 1)), atol=2e-5, what="tip")
    # its clearance is the smallest computeDistances over the still samples
    T = scen.motion.pose(rel.times_s[still])
    q_full = q_hand(rel.times_s[still])
    q_full[:, f.q_indices] = rel.q[still]
    d = [
        _distance_to_object(scen.hand, scen.obj, "index", q, Tk)
        for q, Tk in zip(q_full, T, strict=True)
    ]
    assert_close(rel.min_clearance_m, min(d), atol=1e-6, what="clearance")
    assert rel.min_clearance_m > 0.0


def test_the_samples_reach_the_end_when_the_back_off_ends_within_a_step_of_it(scene):
    # the back-off ends 5 ms before the motion (0.3 + 0.495 s of 0.8 s): no still sample
    # fits after it, and the release must still be sampled to its end (the plan's
    # phases end there; a plan whose samples stop 5 ms short fails its re-check)
    scen, _, _, _ = scene
    rel = _release(scene, back_off_s=0.495)
    assert rel.t_end == scen.motion.t_end
    assert rel.times_s[-1] == rel.t_end
    assert np.all(np.diff(rel.times_s) > 0)
    assert rel.times_s[-2] == pytest.approx(T_RELEASE_S + 0.495)


def test_a_release_planned_until_a_time_is_the_full_release_up_to_then(scene):
    """A release planned to 0.6 s (a finger that joins again by then) ends there: the
    full release's samples up to 0.6 s and one at 0.6 s, the same configurations."""
    full = _release(scene)
    until = _release(scene, until_s=0.6)
    assert until.t_end == 0.6 and until.times_s[-1] == pytest.approx(0.6, abs=1e-9)
    upto = full.times_s <= 0.6 + 1e-9
    np.testing.assert_array_equal(until.times_s, full.times_s[upto])
    np.testing.assert_array_equal(until.q, full.q[upto])
    assert until.t_backed_off == full.t_backed_off
    with pytest.raises(PlanningError) as info:
        _release(scene, until_s=T_RELEASE_S)  # no time to back off by then
    assert info.value.kind == FailureKind.TOO_LATE


def test_a_back_off_lasts_as_long_as_the_joint_velocity_limits_need(scene):
    """Asked to back off 8 mm in 10 ms, the finger takes the time its joints need: the
    straight joint-space move's minimum-jerk duration at the velocity limits
    (``duration_for_move``, path factor 1), its speeds within the limits, then still."""
    scen, _, _, q_r = scene
    f = scen.hand.finger("index")
    rel = _release(scene, clearance_m=0.008, back_off_s=0.01)
    k = int(np.flatnonzero(np.isclose(rel.times_s, rel.t_backed_off, atol=1e-12))[0])
    need = duration_for_move(
        q_r, rel.q[k], f.velocity_limit, minimum_s=0.01, dt_s=0.01, path_factor=1.0
    )
    assert need >= 0.05 - 1e-12  # five times what was asked for
    assert rel.t_backed_off == pytest.approx(T_RELEASE_S + need, abs=1e-12)
    speed = np.abs(np.diff(rel.q, axis=0)) / np.diff(rel.times_s)[:, None]
    assert (speed <= f.velocity_limit + 1e-9).all()
    assert speed.max() > 0.5 * f.velocity_limit.max()  # not slower than it needs either
    assert_close(rel.q[k:], np.tile(rel.q[k], (rel.q.shape[0] - k, 1)), atol=0, what="still")


def test_a_parking_configuration_is_reached(scene):
    scen, _, _, _ = scene
    f = scen.hand.finger("index")
    park = rest_configuration(scen.hand, scen.obj, scen.motion, ["index"])[f.q_indices]
    rel = _release(scene, q_park=park, park_s=0.2)
    # the move takes 0.2 s, or longer if the velocity limits need it: never faster
    k_off = int(np.argmin(np.abs(rel.times_s - (T_RELEASE_S + 0.1))))
    d = duration_for_move(
        rel.q[k_off], park, f.velocity_limit, minimum_s=0.2, dt_s=0.01, path_factor=1.0
    )
    assert d > 0.2  # this park needs more than 0.2 s at the velocity limits
    speed = np.abs(np.diff(rel.q, axis=0)) / np.diff(rel.times_s)[:, None]
    assert (speed <= f.velocity_limit + 1e-9).all()
    done = rel.times_s >= T_RELEASE_S + 0.1 + d - 1e-9
    assert done.any() and not done[k_off + 1]
    assert_close(rel.q[done], np.tile(park, (done.sum(), 1)), atol=1e-9, what="parked")


def test_an_unreachable_back_off_is_a_typed_failure(scene):
    with pytest.raises(PlanningError) as info:
        _release(scene, clearance_m=0.5)
    err = info.value
    assert err.kind == FailureKind.IK_UNREACHABLE and err.finger == "index"
    assert err.measured > err.required == 1e-5


def test_a_release_at_the_end_of_the_motion_is_too_late(scene):
    scen, q_hand, h, q_r = scene
    with pytest.raises(PlanningError) as info:
        plan_release(
            scen.hand,
            scen.obj,
            scen.motion,
            "index",
            scen.motion.t_end,
            (h.p, h.n),
            q_r,
            q_hand,
            clearance_m=CLEARANCE_M,
            back_off_s=0.1,
            dt_s=0.01,
            link_clearance_m=0.0,
            finger_clearance_m=0.0005,
            ik_tol_m=1e-5,
        )
    assert info.value.kind == FailureKind.TOO_LATE and info.value.required == scen.motion.t_end


def test_where_the_normal_is_out_of_reach_the_finger_backs_off_tilted(scene):
    """At a contact whose normal only a joint past its limit could follow (the object
    kept 1 m away, at rest), the normal back-off is out of reach; the release backs off
    along a tilted direction instead: the tip centre ends ``clearance`` above the
    contact's tangent plane (FK), the joints within their limits."""
    scen, _, _, _ = scene
    hand, f = scen.hand, scen.hand.finger("index")
    t = np.round(np.arange(0.0, 0.8 + 1e-9, 0.01), 9)
    T = np.repeat(np.eye(4)[None], t.size, axis=0)
    T[:, :3, 3] = [0.0, 0.0, 1.0]
    far = ObjectMotion.from_poses(t, T)
    base = rest_configuration(hand, scen.obj, scen.motion, list(hand.finger_names))

    def q_hand(times):
        return np.broadcast_to(base, (times.size, base.size)).copy()

    clear_of_others = FingerClearance(hand, "index")
    rescued = 0
    for q, (p, n) in contacts_past_a_limit(f, seed=3):
        p_obj = p - T[0, :3, 3]  # the object frame is the palm frame shifted
        target = p + (f.tip_radius + CLEARANCE_M) * n
        if f.ik(target[None], q, tol_m=1e-5).error_m[0] <= 1e-5:
            continue  # the normal is within reach here
        q_all = base.copy()
        q_all[f.q_indices] = q
        if clear_of_others(q_all) < 0.005:
            continue  # a finger holding there would be in its neighbour
        try:
            rel = plan_release(
                hand, scen.obj, far, "index", T_RELEASE_S, (p_obj, n), q, q_hand,
                clearance_m=CLEARANCE_M, back_off_s=0.1, dt_s=0.01,
                link_clearance_m=0.0, finger_clearance_m=0.0005, ik_tol_m=1e-5,
            )  # fmt: skip
        except PlanningError as exc:
            if exc.kind == FailureKind.IK_UNREACHABLE:  # no tilted direction either
                assert exc.measured > exc.required == 1e-5
                continue
            raise
        rescued += 1
        tip = f.fk(rel.q[-1][None])[0]
        assert (tip - p) @ n - f.tip_radius == pytest.approx(CLEARANCE_M, abs=2e-5)
        assert np.linalg.norm(tip - target) > 1e-4  # not along the normal
        assert np.all(f.within_limits(rel.q, 1e-9))
        if rescued == 3:
            break
    assert rescued == 3


def test_a_motion_into_another_finger_fails_naming_that_finger():
    """The failure of a motion that fails its Coal check by coming too near another
    finger names that finger (the verification's, from the hand's geometries), and so
    does its attempt record."""
    hand = make_scenario().hand
    q = np.tile(hand.neutral(), (3, 1))
    f = hand.finger("index")
    q[:, f.q_indices] = np.linspace([0.0, 0.65, 0.87], [-0.349, 0.65, 0.87], 3)  # into middle
    T = np.tile(np.eye(4), (3, 1, 1))
    T[:, 2, 3] = 0.3  # the object far away
    report = verify_finger_motion(
        hand, Box((0.04, 0.04, 0.04)), "index", [0.0, 0.5, 1.0], q, T, tip_clearance_m=0.0
    )
    error = check_failure("the move", "index", report.worst_failure, report.time_s)
    assert error.kind is FailureKind.FINGER_COLLISION and error.other == "middle"
    assert error.measured < 0.0 and error.as_attempt("the move").other == "middle"
