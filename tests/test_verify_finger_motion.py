"""Tests of the dense Coal verification of a finger motion (regrasp_pin.verify.finger_motion).

Every distance the verifier reports is checked against a reason: analytic sphere/box
and cylinder/box distances, independent ``coal.distance`` calls on Pinocchio's own
geometry placements, and a brute-force all-pairs Coal check on the same dense samples.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close
from scipy.optimize import brentq, minimize_scalar
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import InputError, UnknownNameError, VerificationError
from regrasp_pin.model import distances
from regrasp_pin.model.distances import (
    PairDistances,
    _geometry,
    _placements,
    _segment_distance,
)
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box, Prism
from regrasp_pin.verify import finger_motion
from regrasp_pin.verify.finger_motion import (
    OBJECT_LEVER_M,
    Failure,
    VerificationReport,
    densify,
    failure_at_samples,
    verify_finger_motion,
)

TOL = 5e-5  # default penetration_tol_m
STRAIGHT = np.zeros(3)  # five-finger index straight: tip centre at (0.1345, 0.0285, -0.006)
TIP_R = 0.008


@pytest.fixture(scope="module")
def five() -> Hand:
    return Hand.five_finger()


@pytest.fixture(scope="module")
def allegro() -> Hand:
    return Hand.allegro()


# ---------------------------------------------------------------------- helpers
def pose(p, rotvec=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = p
    return T


def box_distance(size, T_palm_object, c_palm, radius) -> np.ndarray:
    """Analytic signed distance of spheres (N, 3) to a box (|c - box| - r outside)."""
    half = 0.5 * np.asarray(size)
    c = (np.asarray(c_palm) - T_palm_object[:3, 3]) @ T_palm_object[:3, :3]
    out = np.linalg.norm(c - np.clip(c, -half, half), axis=-1)
    inside = np.min(half - np.abs(c), axis=-1)
    return np.where(out > 0, out, -inside) - radius


def line(hand, finger, q_a, q_b, n, base=None):
    """n full configurations on the straight joint-space line q_a -> q_b."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    q_f = np.asarray(q_a) + s * (np.asarray(q_b) - np.asarray(q_a))
    base = hand.neutral() if base is None else base
    return hand.to_full(finger, q_f, np.tile(base, (n, 1)))


def brute_force(hand, obj, finger, t_d, q_d, T_d, tip_req, link_req, ff_req):
    """All-pairs Coal distances at the given dense samples, placements by Pinocchio.

    Returns the minima (as in the report) and, per failing check ``(kind, detail)``,
    the boolean array of the samples where it fails.
    """
    f = hand.finger(finger)
    others = sorted({g for n, o in hand.fingers.items() if n != finger for g in o.geometry_ids})
    model, gmodel = hand.model, hand.collision_model
    data, gdata = model.createData(), pin.GeometryData(gmodel)
    shape_obj = obj.coal_geometry()
    req = coal.DistanceRequest()
    req.gjk_tolerance = 1e-9
    mins = {"tip": np.inf, "link": np.inf, "ff": np.inf, "margin": np.inf}
    failing: dict = {}

    def check(kind, detail, d, dist, required):
        mins["margin"] = min(mins["margin"], dist - required)
        if dist < required:
            failing.setdefault((kind, detail), np.zeros(t_d.size, dtype=bool))[d] = True

    for d in range(t_d.size):
        pin.updateGeometryPlacements(model, data, gmodel, gdata, q_d[d])
        tf = {
            g: coal.Transform3s(gdata.oMg[g].rotation, gdata.oMg[g].translation)
            for g in list(f.geometry_ids) + others
        }
        tf_obj = coal.Transform3s(T_d[d, :3, :3], T_d[d, :3, 3])
        for g in f.geometry_ids:
            geom = gmodel.geometryObjects[g]
            dist = coal.distance(
                geom.geometry, tf[g], shape_obj, tf_obj, req, coal.DistanceResult()
            )  # a fresh result every call
            tip = g in f.tip_geometry_ids
            key = "tip" if tip else "link"
            mins[key] = min(mins[key], dist)
            check(
                "tip-object" if tip else "link-object",
                f"{geom.name} vs object",
                d,
                dist,
                tip_req[d] if tip else link_req,
            )
            for h in others:
                other = gmodel.geometryObjects[h]
                dist = coal.distance(
                    geom.geometry, tf[g], other.geometry, tf[h], req, coal.DistanceResult()
                )
                mins["ff"] = min(mins["ff"], dist)
                check("finger-finger", f"{geom.name} vs {other.name}", d, dist, ff_req)
    return mins, failing


def n_runs(mask: np.ndarray) -> int:
    return int(np.sum(np.diff(np.concatenate([[0], mask.astype(int)])) == 1))


def report_mins(r: VerificationReport) -> dict:
    return {
        "tip": r.min_tip_object_m,
        "link": r.min_link_object_m,
        "ff": r.min_finger_finger_m,
        "margin": r.min_clearance_margin_m,
    }


# ---------------------------------------------------------------------- building blocks
@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_batched_placements_match_pinocchio(hand_name):
    hand = getattr(Hand, hand_name)()
    rng = np.random.default_rng(0)
    lo, hi = hand.model.lowerPositionLimit, hand.model.upperPositionLimit
    q = lo + rng.random((7, hand.model.nq)) * (hi - lo)
    gids = [g for f in hand.fingers.values() for g in f.geometry_ids]
    R, p = _placements([_geometry(hand, g) for g in gids], q)
    data, gdata = hand.model.createData(), pin.GeometryData(hand.collision_model)
    for d in range(q.shape[0]):
        pin.updateGeometryPlacements(hand.model, data, hand.collision_model, gdata, q[d])
        for j, g in enumerate(gids):
            assert_close(R[d, j], gdata.oMg[g].rotation, atol=1e-12, what=f"R of {g}")
            assert_close(p[d, j], gdata.oMg[g].translation, atol=1e-12, what=f"p of {g}")


def test_segment_distance_matches_coal_capsules():
    rng = np.random.default_rng(1)
    a1, b1, a2, b2 = (rng.normal(size=(300, 3)) * 0.03 for _ in range(4))
    b2[:20] = a2[:20]  # degenerate segments (points)
    b1[20:40] = a1[20:40]
    b2[40:60] = a2[40:60] + (b1[40:60] - a1[40:60]) * 0.5  # parallel segments
    got, v = _segment_distance(a1, b1, a2, b2)
    assert_close(np.linalg.norm(v, axis=1), got, atol=1e-15, what="nearest-point vector")
    req = coal.DistanceRequest()
    expected = []
    for i in range(300):
        tfs, caps = [], []
        for a, b in ((a1[i], b1[i]), (a2[i], b2[i])):
            axis = b - a
            length = float(np.linalg.norm(axis))
            if length < 1e-12:
                caps.append(coal.Sphere(1e-3))
                tfs.append(coal.Transform3s(np.eye(3), a))
                continue
            z = axis / length
            R = Rotation.align_vectors([z], [[0.0, 0.0, 1.0]])[0].as_matrix()
            caps.append(coal.Capsule(1e-3, length))
            tfs.append(coal.Transform3s(R, 0.5 * (a + b)))
        res = coal.DistanceResult()
        expected.append(coal.distance(caps[0], tfs[0], caps[1], tfs[1], req, res) + 2e-3)
    expected = np.array(expected)
    touching = expected <= 2e-3 + 1e-9  # capsules overlapping: distance only known >= 0
    assert_close(got[~touching], expected[~touching], atol=1e-8, what="segment distance")
    assert np.all(got[touching] <= 2e-3 + 1e-9)


@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_lower_bounds_never_exceed_coal_distances(hand_name):
    """The broad phase is sound: every bound is <= the exact Coal distance."""
    hand = getattr(Hand, hand_name)()
    rng = np.random.default_rng(3)
    lo, hi = hand.model.lowerPositionLimit, hand.model.upperPositionLimit
    D = 60
    q = lo + rng.random((D, hand.model.nq)) * (hi - lo)
    centre = [0.07, 0.0, 0.06] if hand_name == "five_finger" else [0.08, 0.0, 0.08]
    T = np.stack(
        [pose(np.asarray(centre) + rng.normal(0, 0.02, 3), rng.normal(0, 1.0, 3)) for _ in range(D)]
    )
    for obj in (Box((0.06, 0.04, 0.03)), Prism(5, 0.03, 0.05)):
        for finger in ("thumb", "index"):
            checker = PairDistances(
                hand, obj, hand.finger(finger), q, T, np.zeros(D), 0.0, 1.0
            )  # 1 m: every pair gets the fine bound
            checker._query(*np.nonzero(np.ones(checker.lb.shape, dtype=bool)))
            assert np.all(checker.exact >= checker.lb - 1e-9)
            assert np.mean(checker.lb > 0) > 0.3  # and they are not trivial


def _dense_motion_near_object(five, allegro, case: int, seed: int) -> tuple:
    """:class:`PairDistances` arguments for a smooth dense motion of ``CASES[case]``'s
    finger (four random configurations about the middle of its limits) with the object
    near it, held still at one random pose; tip and link clearance 2 mm, fingers 4 mm."""
    hand_name, finger, obj, centre, _ = CASES[case]
    hand = five if hand_name == "five_finger" else allegro
    f = hand.finger(finger)
    rng = np.random.default_rng(seed)
    n = 4
    t = np.arange(n, dtype=float)
    q_f = f.q_mid + rng.uniform(-0.3, 0.3, (n, f.k)) * (f.upper - f.lower)
    q = hand.to_full(finger, q_f, np.tile(hand.neutral(), (n, 1)))
    T = np.stack([pose(np.asarray(centre) + rng.normal(0, 0.01, 3), rng.normal(0, 0.2, 3))] * n)
    _, q_d, T_d = densify(t, q, T, 0.005)
    return (hand, obj, f, q_d, T_d, np.full(q_d.shape[0], 0.002), 0.002, 0.004)


@pytest.mark.parametrize("stride", [4, 8, 32])
@pytest.mark.parametrize("case", range(4))
def test_coarse_bounds_are_sound_and_query_the_same_samples(five, allegro, case, stride):
    """Bounds evaluated coarse to fine (a smooth dense motion, the object near the
    finger) stay below Coal's distances, and are below the requirement exactly where
    every bound evaluated is: the same mandatory queries."""
    args = _dense_motion_near_object(five, allegro, case, seed=7 + case)
    D = args[3].shape[0]
    every = PairDistances(*args)
    coarse = PairDistances(*args, coarse_stride=stride)
    assert D > 4 * stride
    assert np.array_equal(coarse.lb < coarse.required, every.lb < every.required)
    assert np.mean(coarse.lb != every.lb) > 0.3  # most bounds were carried, not evaluated
    coarse._query(*np.nonzero(np.ones(coarse.lb.shape, dtype=bool)))
    assert np.all(coarse.exact >= coarse.lb - 1e-9)


def test_strided_queries_find_every_failing_sample_with_fewer_queries(five, allegro, monkeypatch):
    """The mandatory queries measured every QUERY_STRIDE-th sample first and then only
    the samples the sweep bound leaves below their requirement: the same failing
    samples with the same Coal values as measuring every one, in fewer queries."""
    spared = failing = 0
    for case in range(len(CASES)):
        args = _dense_motion_near_object(five, allegro, case, seed=11 + case)
        runs = {}
        for stride in (1, distances.QUERY_STRIDE):
            monkeypatch.setattr(distances, "QUERY_STRIDE", stride)
            runs[stride] = PairDistances(*args)
            runs[stride].run(exact_minima=False)
        every, strided = runs[1], runs[distances.QUERY_STRIDE]
        fail = every.exact < every.required
        assert np.array_equal(strided.exact < strided.required, fail)
        assert np.array_equal(strided.exact[fail], every.exact[fail])
        assert strided.n_queries <= every.n_queries
        spared += every.n_queries - strided.n_queries
        failing += int(fail.sum())
    assert failing > 0 and spared > 0  # failures to find, and queries spared


def test_densify_bounds_steps_and_stays_on_the_interpolation():
    rng = np.random.default_rng(2)
    t = np.array([0.0, 0.4, 1.0, 1.3])
    q = rng.normal(size=(4, 5)) * 0.05
    T = np.stack([pose(rng.normal(size=3) * 0.01, rng.normal(size=3) * 0.02) for _ in t])
    step = 1e-3
    t_d, q_d, T_d = densify(t, q, T, step)
    assert np.all(np.abs(np.diff(q_d, axis=0)) <= step * (1 + 1e-9))
    assert np.all(np.isin(t, t_d)) and np.all(np.diff(t_d) > 0)
    assert_close(q_d[np.isin(t_d, t)], q, atol=1e-15, what="original samples kept")
    # the fewest steps: one step fewer per interval would exceed the bound somewhere
    counts = np.diff(np.searchsorted(t_d, t))
    rel = Rotation.from_matrix(T[:-1, :3, :3].transpose(0, 2, 1) @ T[1:, :3, :3])
    need = np.maximum.reduce(
        [
            np.max(np.abs(np.diff(q, axis=0)), axis=1) / step,
            rel.magnitude() / step,  # the object turns at most one step per sample
            np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1) / (step * OBJECT_LEVER_M),
        ]
    )
    assert np.all(counts == np.maximum(np.ceil(need), 1))
    assert_close(T_d, ObjectMotion.from_poses(t, T).pose(t_d), atol=1e-12, what="poses")
    assert_close(
        q_d,
        np.stack([np.interp(t_d, t, q[:, j]) for j in range(5)], axis=1),
        atol=1e-12,
        what="linear q",
    )


def test_densify_follows_object_rotation_when_joints_are_still():
    T = np.stack([pose([0, 0, 0]), pose([0, 0, 0], [0.0, 0.0, 0.05])])
    t_d, _, T_d = densify([0.0, 1.0], np.zeros((2, 3)), T, 1e-3)
    assert t_d.size == 51
    angles = Rotation.from_matrix(T_d[:-1, :3, :3].transpose(0, 2, 1) @ T_d[1:, :3, :3])
    assert np.all(angles.magnitude() <= 1e-3 + 1e-12)


# ---------------------------------------------------------------------- static checks
@pytest.mark.parametrize("gap", [0.002, 0.03])
def test_static_configuration_reports_exact_minima(five, gap):
    size = (0.06, 0.04, 0.04)
    obj = Box(size)
    f = five.finger("index")
    tip = f.fk(STRAIGHT)
    # box face perpendicular to the straight finger, `gap` beyond the tip sphere; the box
    # turned about the finger axis (x) so the rotation matters
    T = pose(tip + [TIP_R + gap + 0.03, 0.0, 0.0], [0.4, 0.0, 0.0])
    q = line(five, "index", STRAIGHT, STRAIGHT, 3, base=np.zeros(five.model.nq))
    t = np.array([0.0, 0.5, 1.0])
    Ts = np.tile(T, (3, 1, 1))
    r = verify_finger_motion(five, obj, "index", t, q, Ts, tip_clearance_m=0.0)
    assert r.ok and r.joint_limits_ok and not r.failures and r.time_s is None
    assert r.n_samples == 3  # nothing moves: no extra samples
    # analytic: the sphere is the nearest tip geometry
    assert_close(
        r.min_tip_object_m, box_distance(size, T, tip, TIP_R), atol=1e-9, what="sphere-box"
    )
    assert_close(r.min_tip_object_m, gap, atol=1e-9, what="gap")
    # independent Coal calls on Pinocchio's placements
    mins, failing = brute_force(five, obj, "index", t, q, Ts, np.full(3, -TOL), -TOL, 5e-4)
    assert not failing
    for key, value in mins.items():
        assert_close(report_mins(r)[key], value, atol=1e-8, what=key)


def test_single_sample_is_checked_as_is(five):
    obj = Box((0.04, 0.04, 0.04))
    tip = five.finger("index").fk(STRAIGHT)
    T = pose(tip + [TIP_R + 0.001 + 0.02, 0.0, 0.0])  # 1 mm gap
    q = five.to_full("index", STRAIGHT, np.zeros(five.model.nq))
    r = verify_finger_motion(five, obj, "index", [0.0], q[None], T[None], tip_clearance_m=0.0)
    assert r.ok and r.n_samples == 1 and r.max_tip_step_m == 0.0
    assert_close(r.min_tip_object_m, 0.001, atol=1e-9, what="gap")
    r = verify_finger_motion(five, obj, "index", [0.0], q[None], T[None], tip_clearance_m=0.002)
    assert [x.kind for x in r.failures] == ["tip-object"] and r.time_s == 0.0


def test_touching_tip_passes_with_zero_clearance_only(five):
    size = (0.04, 0.04, 0.04)
    obj = Box(size)
    tip = five.finger("index").fk(STRAIGHT)
    T = pose(tip + [TIP_R + 0.02, 0.0, 0.0])  # face exactly at the sphere surface
    q = line(five, "index", STRAIGHT, STRAIGHT, 2, base=np.zeros(five.model.nq))
    Ts = np.tile(T, (2, 1, 1))
    touching = verify_finger_motion(five, obj, "index", [0.0, 1.0], q, Ts, tip_clearance_m=0.0)
    assert touching.ok
    assert abs(touching.min_tip_object_m) < 1e-9
    clear = verify_finger_motion(five, obj, "index", [0.0, 1.0], q, Ts, tip_clearance_m=0.005)
    assert not clear.ok
    fail = clear.failures[0]
    assert fail.kind == "tip-object" and fail.detail == "index_distal_1 vs object"
    assert abs(fail.value) < 1e-9
    assert_close(fail.required, 0.005 - TOL, atol=1e-15, what="required")
    assert (fail.t_first_s, fail.t_last_s) == (0.0, 1.0)


def test_tip_clearance_is_interpolated_in_time(five):
    obj = Box((0.04, 0.04, 0.04))
    tip = five.finger("index").fk(STRAIGHT)
    Ts = np.tile(pose(tip + [TIP_R + 0.002 + 0.02, 0.0, 0.0]), (5, 1, 1))  # 2 mm gap
    q = line(five, "index", STRAIGHT, STRAIGHT, 5, base=np.zeros(five.model.nq))
    t = np.linspace(0.0, 1.0, 5)
    r = verify_finger_motion(
        five, obj, "index", t, q, Ts, tip_clearance_m=np.array([0.0, 0.001, 0.002, 0.003, 0.004])
    )
    # required = clearance - tol: 0.002 - tol passes, 0.003 - tol does not
    assert [f.kind for f in r.failures] == ["tip-object"]
    assert (r.failures[0].t_first_s, r.failures[0].t_last_s) == (0.75, 1.0)
    assert r.time_s == 1.0
    assert_close(r.min_clearance_margin_m, 0.002 - (0.004 - TOL), atol=1e-9, what="margin")


def test_link_penetration_is_a_link_failure_with_the_analytic_depth(five):
    # a box resting 2 mm deep on the straight proximal phalanx (a cylinder of radius r
    # along x from the MCP joint), read from the model
    model, data = five.model, five.model.createData()
    pin.forwardKinematics(model, data, np.zeros(model.nq))
    mcp = data.oMi[model.getJointId("index_mcp")].translation
    gid = five.fingers["index"].geometry_ids[0]
    r = five.collision_model.geometryObjects[gid].geometry.radius
    obj = Box((0.02, 0.02, 0.02))
    T = pose([mcp[0] + 0.0225, mcp[1], mcp[2] + r - 0.002 + 0.01])
    q = line(five, "index", STRAIGHT, STRAIGHT, 2, base=np.zeros(five.model.nq))
    r = verify_finger_motion(
        five, obj, "index", [0.0, 1.0], q, np.tile(T, (2, 1, 1)), tip_clearance_m=0.0
    )
    assert [(f.kind, f.detail) for f in r.failures] == [
        ("link-object", "index_proximal_0 vs object")
    ]
    assert_close(r.failures[0].value, -0.002, atol=1e-6, what="penetration depth")
    assert_close(r.min_link_object_m, -0.002, atol=1e-6, what="min link distance")


# ---------------------------------------------------------------------- moving checks
def _sweep_case(five, n_coarse):
    """Straight index abducting 0.3 -> 0 rad across a small box in the tip's path."""
    f = five.finger("index")
    size = (0.01, 0.01, 0.01)
    T = pose(f.fk(np.array([0.15, 0.0, 0.0])))
    q = line(
        five, "index", [0.3, 0.0, 0.0], [0.0, 0.0, 0.0], n_coarse, base=np.zeros(five.model.nq)
    )
    t = np.linspace(0.0, 1.0, n_coarse)
    return size, T, q, t


def test_tip_through_box_fails_at_the_analytic_time(five):
    size, T, q, t = _sweep_case(five, 5)
    f = five.finger("index")
    r = verify_finger_motion(
        five, Box(size), "index", t, q, np.tile(T, (t.size, 1, 1)), tip_clearance_m=0.0
    )
    assert not r.ok

    def depth(s):  # analytic sphere-box distance at time s (q linear in time here)
        return float(box_distance(size, T, f.fk(np.array([0.3 * (1 - s), 0, 0])), TIP_R))

    t_in = brentq(lambda s: depth(s) + TOL, 0.0, 0.5)
    t_out = brentq(lambda s: depth(s) + TOL, 0.5, 1.0)
    dt = 1.0 / (r.n_samples - 1)  # the dense samples are uniform here
    run = [x for x in r.failures if x.detail == "index_distal_1 vs object"]
    assert len(run) == 1 and run[0].kind == "tip-object"
    assert t_in <= run[0].t_first_s <= t_in + dt + 1e-12
    assert t_out - dt - 1e-12 <= run[0].t_last_s <= t_out
    assert_close(run[0].value, depth(run[0].time_s), atol=1e-7, what="depth at worst sample")
    t_worst = minimize_scalar(depth, bounds=(t_in, t_out), method="bounded").x
    assert abs(run[0].time_s - t_worst) <= 2 * dt
    assert r.failures[0].kind == "tip-object" and r.failures[0].t_first_s <= run[0].t_first_s


def test_sweep_between_two_clear_samples_is_caught_by_densification(five):
    size, T, q, t = _sweep_case(five, 2)
    obj = Box(size)
    Ts = np.tile(T, (2, 1, 1))
    coarse = verify_finger_motion(
        five, obj, "index", t, q, Ts, tip_clearance_m=0.0, max_joint_step_rad=10.0
    )
    assert coarse.ok and coarse.n_samples == 2  # both samples are clear of the box
    dense = verify_finger_motion(five, obj, "index", t, q, Ts, tip_clearance_m=0.0)
    assert not dense.ok and dense.n_samples == 301
    assert {x.kind for x in dense.failures} == {"tip-object"}


def test_interpolation_slack_bounds_what_happens_between_samples(five):
    """Ten times denser sampling never finds a distance below min - slack."""
    size, _, q, t = _sweep_case(five, 2)
    # a box face 0.5 mm outside the tip's arc, touching it at abduction 0.155 rad,
    # between the coarse samples (0.01 rad apart, 0.15 and 0.16)
    f = five.finger("index")
    mcp = five.model.jointPlacements[five.model.getJointId("index_abd")].translation
    tip = f.fk(np.array([0.155, 0.0, 0.0]))
    radial = (tip - mcp) / np.linalg.norm(tip - mcp)
    T = pose(tip + radial * (TIP_R + 0.0005 + 0.005), [0.0, 0.0, np.arctan2(radial[1], radial[0])])
    Ts = np.tile(T, (2, 1, 1))
    coarse = verify_finger_motion(
        five, Box(size), "index", t, q, Ts, tip_clearance_m=0.0, max_joint_step_rad=0.01
    )
    fine = verify_finger_motion(
        five, Box(size), "index", t, q, Ts, tip_clearance_m=0.0, max_joint_step_rad=0.001
    )
    assert 0 < fine.interpolation_slack_m < 1e-4  # 1 mrad: under 0.1 mm here
    assert coarse.min_tip_object_m > 0  # a near miss
    assert fine.min_tip_object_m <= coarse.min_tip_object_m
    assert fine.min_tip_object_m >= coarse.min_tip_object_m - coarse.interpolation_slack_m
    assert fine.interpolation_slack_m <= 0.1 * coarse.interpolation_slack_m * 1.01


def test_max_tip_step_refines_the_sampling(five):
    size, T, q, t = _sweep_case(five, 2)
    r = verify_finger_motion(
        five,
        Box(size),
        "index",
        t,
        q,
        np.tile(T, (2, 1, 1)),
        tip_clearance_m=0.0,
        max_joint_step_rad=0.05,
        max_tip_step_m=2e-4,
    )
    assert r.max_tip_step_m <= 2e-4
    assert r.n_samples > 7  # 0.3 rad / 0.05 rad alone would give 7


def test_finger_into_neighbour_is_a_finger_finger_failure(five):
    obj = Box((0.04, 0.04, 0.04))
    T = pose([0.0, 0.0, 0.3])  # far away
    q = line(five, "index", [0.0, 0.65, 0.87], [-0.349, 0.65, 0.87], 3)
    r = verify_finger_motion(
        five, obj, "index", [0.0, 0.5, 1.0], q, np.tile(T, (3, 1, 1)), tip_clearance_m=0.0
    )
    assert not r.ok and r.joint_limits_ok
    assert {x.kind for x in r.failures} == {"finger-finger"}
    assert all(x.detail.startswith("index_") and " vs middle_" in x.detail for x in r.failures)
    # the finger it came too near, from the hand's geometries (the names only say so)
    assert {x.other for x in r.failures} == {"middle"}
    assert r.min_finger_finger_m < 0


def test_joint_limit_violation(five):
    f = five.finger("index")
    obj = Box((0.04, 0.04, 0.04))
    T = pose([0.0, 0.0, 0.3])
    q_over = STRAIGHT.copy()
    q_over[2] = f.upper[2] + 0.01
    q = line(five, "index", STRAIGHT, q_over, 2, base=np.zeros(five.model.nq))
    r = verify_finger_motion(
        five, obj, "index", [0.0, 1.0], q, np.tile(T, (2, 1, 1)), tip_clearance_m=0.0
    )
    assert not r.ok and not r.joint_limits_ok
    lim = [x for x in r.failures if x.kind == "joint-limit"]
    assert len(lim) == 1 and lim[0].detail == "index_pip"
    assert lim[0].required == f.upper[2] and lim[0].time_s == 1.0
    assert_close(lim[0].value, f.upper[2] + 0.01, atol=1e-12, what="joint value")
    assert_close(lim[0].t_first_s, f.upper[2] / (f.upper[2] + 0.01), atol=2e-3, what="t")


# ---------------------------------------------------------------------- broad phase
CASES = [  # hand, moving finger, object, object centre in the palm frame, retreat direction
    ("five_finger", "index", Box((0.06, 0.04, 0.04)), [0.07, 0.0, 0.06], [0.0, 0.0, 1.0]),
    ("five_finger", "thumb", Prism(6, 0.03, 0.05), [0.07, 0.02, 0.05], [0.0, 0.0, 1.0]),
    ("allegro", "index", Box((0.05, 0.04, 0.04)), [0.08, 0.02, 0.08], [-0.45, 0.0, 0.9]),
    ("allegro", "thumb", Prism(5, 0.03, 0.05), [0.08, 0.03, 0.03], [-0.45, 0.0, 0.9]),
]


@pytest.mark.parametrize("retreat_m", [0.0, 0.04])
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("case", range(len(CASES)))
def test_broad_phase_never_changes_the_answer(five, allegro, case, seed, retreat_m):
    """Random motions (grazing, penetrating and clear) against an all-pairs Coal check."""
    hand_name, finger, obj, centre, away = CASES[case]
    hand = five if hand_name == "five_finger" else allegro
    rng = np.random.default_rng(100 * case + seed)
    f = hand.finger(finger)
    n = 4
    t = np.cumsum(rng.uniform(0.2, 1.0, n))
    # the finger: random points of its joint box (seed 0: a little beyond the limits;
    # others: the middle half of the box, which more often clears the other fingers)
    span = 1.06 if seed == 0 else 0.5
    q_f = f.q_mid + rng.uniform(-0.5, 0.5, (n, f.k)) * span * (f.upper - f.lower)
    # the other fingers drift around the middle of their limits
    base = (
        hand.neutral()
        + rng.normal(0.0, 0.1, (1, hand.model.nq))
        + np.linspace(0, 1, n)[:, None] * rng.normal(0.0, 0.05, hand.model.nq)
    )
    q = hand.to_full(finger, q_f, base)
    c = np.asarray(centre) + retreat_m * np.asarray(away)
    T = np.stack([pose(c + rng.normal(0, 0.01, 3), rng.normal(0, 0.2, 3)) for _ in range(n)])
    assert_matches_brute_force(hand, obj, finger, t, q, T, rng.uniform(0.0, 0.01, n))


@pytest.mark.parametrize("case", range(len(CASES)))
def test_a_failure_at_the_samples_is_one_the_dense_check_finds(five, allegro, case, monkeypatch):
    """Random motions of eight samples, grazing, penetrating and clear: a failure that
    :func:`failure_at_samples` finds is a failing run of the dense check's (same check,
    time within it, a margin no better than the dense minimum), and where it finds none
    the given samples alone pass (the dense check with one step per interval)."""
    hand_name, finger, obj, centre, away = CASES[case]
    hand = five if hand_name == "five_finger" else allegro
    f = hand.finger(finger)
    monkeypatch.setattr(finger_motion, "MAX_REPORTED_FAILURES", 10_000)  # every run kept
    outcomes = []
    for seed in range(6):
        rng = np.random.default_rng(1000 * case + seed)
        n = 8
        t = np.cumsum(rng.uniform(0.05, 0.2, n))
        span = 1.06 if seed == 0 else 0.5
        q_f = f.q_mid + rng.uniform(-0.5, 0.5, (n, f.k)) * span * (f.upper - f.lower)
        q = hand.to_full(finger, q_f, np.tile(hand.neutral(), (n, 1)))
        c = np.asarray(centre) + 0.02 * (seed % 3) * np.asarray(away)
        T = np.stack([pose(c + rng.normal(0, 0.005, 3), rng.normal(0, 0.1, 3)) for _ in range(n)])
        limits = {
            "tip_clearance_m": rng.uniform(0.0, 0.01, n),
            "link_clearance_m": 0.002,
            "finger_clearance_m": 0.001,
        }
        sure = failure_at_samples(hand, obj, finger, t, q, T, **limits)
        dense = verify_finger_motion(hand, obj, finger, t, q, T, **limits)
        outcomes.append(sure is not None)
        if sure is None:
            coarse = verify_finger_motion(
                hand, obj, finger, t, q, T, **limits, max_joint_step_rad=1e3
            )
            assert coarse.ok and coarse.n_samples == n
            continue
        assert not dense.ok
        if sure.kind == "joint-limit":
            assert not dense.joint_limits_ok
            continue
        assert sure.value < sure.required and sure.time_s in t
        assert dense.min_clearance_margin_m <= sure.value - sure.required + 1e-12
        assert any(
            (x.kind, x.detail) == (sure.kind, sure.detail)
            and x.t_first_s <= sure.time_s <= x.t_last_s
            for x in dense.failures
        )
    assert any(outcomes)  # the cases fail at their samples, some of them


def test_a_sweep_between_two_clear_samples_is_no_failure_at_the_samples(five):
    """None says nothing: both samples clear the box, the motion between them does not."""
    size, T, q, t = _sweep_case(five, 2)
    obj, Ts = Box(size), np.tile(T, (2, 1, 1))
    assert failure_at_samples(five, obj, "index", t, q, Ts, tip_clearance_m=0.0) is None
    assert not verify_finger_motion(five, obj, "index", t, q, Ts, tip_clearance_m=0.0).ok


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_near_misses_match_brute_force(five, allegro, hand_name, seed):
    """A box face 0-4 mm from the pad, wobbling: grazes and narrow passes."""
    hand = five if hand_name == "five_finger" else allegro
    finger = "index" if seed % 2 else "middle"
    rng = np.random.default_rng(1000 + seed)
    f = hand.finger(finger)
    q0 = f.q_mid
    tip, normal = f.fk(q0), f.pad_normals(q0)
    R = Rotation.align_vectors([normal], [[1.0, 0.0, 0.0]])[0]
    n = 4
    gap = rng.uniform(0.0, 0.004)
    contact = tip + normal * (f.tip_radius + gap)  # a point of the box face
    wobble = Rotation.from_rotvec(rng.normal(0.0, 0.04, (n, 3)))
    T = np.stack([np.eye(4)] * n)
    T[:, :3, :3] = (wobble * R).as_matrix()
    T[:, :3, 3] = contact + wobble.apply(R.apply([0.025, 0.0, 0.0]))
    q_f = q0 + rng.normal(0.0, 0.02, (n, f.k))
    q = hand.to_full(finger, q_f, np.tile(hand.neutral(), (n, 1)))
    t = np.cumsum(rng.uniform(0.2, 1.0, n))
    assert_matches_brute_force(
        hand,
        Box((0.05, 0.04, 0.04)),
        finger,
        t,
        q,
        T,
        rng.uniform(0.0, 0.0015, n),
        step=0.005,
        link=0.0,
    )


def assert_matches_brute_force(hand, obj, finger, t, q, T, clearance, step=0.02, link=0.002):
    """The report equals an all-pairs Coal check on the same dense samples."""
    f = hand.finger(finger)
    limits = dict(
        tip_clearance_m=clearance,
        link_clearance_m=link,
        finger_clearance_m=0.001,
        max_joint_step_rad=step,
    )
    r = verify_finger_motion(hand, obj, finger, t, q, T, **limits)
    t_d, q_d, T_d = densify(t, q, T, step)
    assert r.n_samples == t_d.size
    mins, failing = brute_force(
        hand, obj, finger, t_d, q_d, T_d, np.interp(t_d, t, clearance) - TOL, link - TOL, 0.001
    )
    for key, value in mins.items():
        if r.minima_exact:
            assert_close(report_mins(r)[key], value, atol=2e-6, what=key)
        else:  # far minima may be lower bounds
            assert report_mins(r)[key] <= value + 2e-6
    kept = [x for x in r.failures if x.kind != "joint-limit"]
    assert {(x.kind, x.detail) for x in kept} <= set(failing)
    for x in kept:  # each kept failure is a whole run of the brute-force failing samples
        mask = failing[(x.kind, x.detail)]
        lo, hi = np.searchsorted(t_d, [x.t_first_s, x.t_last_s])
        assert mask[lo : hi + 1].all() and hi - lo + 1 == x.n_samples
        assert (lo == 0 or not mask[lo - 1]) and (hi + 1 == t_d.size or not mask[hi + 1])
    q_f_d = q_d[:, f.q_indices]
    joint_runs = sum(
        n_runs(q_f_d[:, j] < f.lower[j] - 1e-9) + n_runs(q_f_d[:, j] > f.upper[j] + 1e-9)
        for j in range(f.k)
    )
    assert r.n_failures == sum(n_runs(m) for m in failing.values()) + joint_runs
    assert r.joint_limits_ok == (joint_runs == 0)
    assert r.ok == (not failing and r.joint_limits_ok)
    n_pairs = len(f.geometry_ids) * (
        1 + sum(len(o.geometry_ids) for name, o in hand.fingers.items() if name != finger)
    )
    assert r.n_distance_queries < 0.5 * t_d.size * n_pairs  # the broad phase prunes
    # without the minima's branch and bound: the same decisions and failures, fewer
    # queries, and minima that bound the exact ones from below
    fast = verify_finger_motion(hand, obj, finger, t, q, T, **limits, exact_minima=False)
    assert (fast.ok, fast.failures, fast.n_failures, fast.time_s, fast.joint_limits_ok) == (
        r.ok,
        r.failures,
        r.n_failures,
        r.time_s,
        r.joint_limits_ok,
    )
    assert fast.n_distance_queries <= r.n_distance_queries
    for key, value in report_mins(fast).items():  # to Coal's GJK tolerance (its warm
        # starts follow the order of the queries)
        if fast.minima_exact:
            assert_close(value, report_mins(r)[key], atol=1e-8, what=key)
        else:
            assert value <= report_mins(r)[key] + 1e-8
    return r


# ---------------------------------------------------------------------- errors
def test_raise_if_failed_names_finger_time_and_check(five):
    size, T, q, t = _sweep_case(five, 2)
    r = verify_finger_motion(
        five, Box(size), "index", t, q, np.tile(T, (2, 1, 1)), tip_clearance_m=0.0
    )
    with pytest.raises(VerificationError) as err:
        r.raise_if_failed("index")
    e = err.value
    assert e.finger == "index" and e.time_s == r.time_s and e.partial is r
    text = str(e)
    assert "finger 'index'" in text and "tip-object" in text and "vs object" in text
    assert f"t={r.time_s:.3f} s" in text
    ok = verify_finger_motion(
        five, Box(size), "index", t, q, np.tile(pose([0, 0, 0.3]), (2, 1, 1)), tip_clearance_m=0.0
    )
    ok.raise_if_failed("index")  # no error
    assert isinstance(r.failures[0], Failure)


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"times_s": [0.0, 0.0]}, "times_s"),
        ({"times_s": [1.0, 0.0]}, "times_s"),
        ({"times_s": [0.0, np.nan]}, "times_s"),
        ({"q_full": np.zeros((3, 15))}, "q_full"),
        ({"q_full": np.full((2, 15), np.nan)}, "q_full"),
        ({"T_palm_object": np.zeros((2, 4, 4))}, "T_palm_object"),
        ({"T_palm_object": np.ones((2, 3, 3))}, "T_palm_object"),
        ({"tip_clearance_m": -0.001}, "tip_clearance_m"),
        ({"tip_clearance_m": [0.0, -0.001]}, "tip_clearance_m"),
        ({"tip_clearance_m": [0.0, 0.0, 0.0]}, "tip_clearance_m"),
        ({"link_clearance_m": -1.0}, "link_clearance_m"),
        ({"finger_clearance_m": np.nan}, "finger_clearance_m"),
        ({"penetration_tol_m": -1e-5}, "penetration_tol_m"),
        ({"max_joint_step_rad": 0.0}, "max_joint_step_rad"),
        ({"max_tip_step_m": -1.0}, "max_tip_step_m"),
    ],
)
def test_bad_input_names_the_argument(five, kwargs, argument):
    """Both checks, verify_finger_motion and failure_at_samples, name it."""
    args = {
        "times_s": [0.0, 1.0],
        "q_full": np.tile(five.neutral(), (2, 1)),
        "T_palm_object": np.tile(pose([0, 0, 0.3]), (2, 1, 1)),
        "tip_clearance_m": 0.0,
    }
    args.update(kwargs)
    with pytest.raises(InputError) as err:
        verify_finger_motion(five, Box((0.04, 0.04, 0.04)), "index", **args)
    assert err.value.argument == argument
    if argument in ("max_joint_step_rad", "max_tip_step_m"):
        return  # the dense check's own; failure_at_samples takes the others
    with pytest.raises(InputError) as err:
        failure_at_samples(five, Box((0.04, 0.04, 0.04)), "index", **args)
    assert err.value.argument == argument


def test_unknown_finger(five):
    with pytest.raises(UnknownNameError, match="index"):
        verify_finger_motion(
            five,
            Box((0.04, 0.04, 0.04)),
            "pinky",
            [0.0],
            five.neutral()[None],
            pose([0, 0, 0.3])[None],
            tip_clearance_m=0.0,
        )
