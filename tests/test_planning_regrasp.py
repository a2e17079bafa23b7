"""Tests of one verified regrasp (regrasp_pin.planning.regrasp).

Every trajectory the planner returns is re-checked here, independently of
:mod:`regrasp_pin.verify.finger_motion`: the returned samples are interpolated linearly at
joint steps of at most 1 mrad, the object poses come from ``motion.pose``, the finger is placed with
Pinocchio (``forwardKinematics`` / ``updateGeometryPlacements``) and every distance is a
``coal.distance`` call on a ``coal.Box`` built here from the box's size.

Scenes (palm frame: x toward the fingers, z out of the palm), five-finger hand, box
40 x 60 x 40 mm, index finger regrasping:

* "upright": the box at (65, 0, 60) mm, axes aligned with the palm. The index reaches
  around it and touches its +x face; its usable contacts fill y in [23, 29] mm,
  z in [-19, -3] mm of that face (object frame).
* "edge": the box turned -45 deg about z, centre at (60, 20, 50) mm, so that a vertical
  edge points away from the palm; the index has contacts on the two faces around it
  (+x and +y). The chord between two tip centres on either side of a convex edge passes
  through the box, so a straight joint-space move cuts it (asserted below).

Each scene is used static and turning about the palm y axis through the box centre at
10 deg/s. Other fingers sit at the middle of their limits unless a test moves one.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

import regrasp_pin.planning.regrasp as regrasp_module
from regrasp_pin.exceptions import FailureKind, InputError, PlanningError, VerificationError
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box
from regrasp_pin.planning.regrasp import RegraspParams, RegraspResult, minimum_jerk, plan_regrasp

FINGER = "index"
BOX_SIZE = (0.04, 0.06, 0.04)
T_MANIFOLD_S = np.array([0.0, 0.5])  # lift-off and landing times of a default regrasp
MAX_JOINT_STEP_RAD = 1e-3  # re-check resolution
OBJECT_LEVER_M = 0.1  # object translation per step bounded by the joint step times this
PENETRATION_TOL_M = 1e-4  # the re-check tolerates 0.1 mm (the verifier itself uses 0.05 mm)
FINGER_GAP_M = 5e-4  # another finger must stay at least this far away
# The verifier proves FINGER_GAP_M at its own dense samples (<= 1 mrad apart on the same
# linear interpolation); one of ours lies at most half a step (0.5 mrad per joint) from
# one of them, where no point of the index moves more than 0.5 mrad x the sum of its
# lever arms (abd, mcp, pip, mimic dip: < 0.1 + 0.1 + 0.065 + 0.03 m) < 0.15 mm.
FINGER_GAP_SLACK_M = 1.5e-4


# ---------------------------------------------------------------------- helpers
def box_pose(p_m, rotvec=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = p_m
    return T


class Scene:
    """Hand, box, motion and the index finger's feasible contacts at t = 0 and 0.5 s."""

    def __init__(
        self,
        hand: Hand,
        T0: np.ndarray,
        rate_deg_s: float,
        margin_rad: float = 0.15,
        link_clearance_m: float = 0.003,
    ) -> None:
        self.hand = hand
        self.obj = Box(BOX_SIZE)
        self.T0 = T0
        self.motion = ObjectMotion.constant_twist(
            T0,
            axis_palm=[0.0, 1.0, 0.0],
            point_palm=T0[:3, 3],
            rate_rad_s=math.radians(rate_deg_s),
            duration_s=1.0,
            dt_s=0.01,
        )
        self.sample = self.obj.sample_surface(0.002)
        f = hand.finger(FINGER)
        M = build_manifold(f, self.sample, self.motion, T_MANIFOLD_S)
        self.manifold = M
        idx = np.nonzero(M.usable(margin_rad)[0] & M.usable(margin_rad)[1])[0]
        lc = LinkClearance(hand, FINGER, self.obj)
        for k in range(2):
            keep = lc(hand.to_full(FINGER, M.q[k, idx]), M.T_palm_object[k]) > link_clearance_m
            idx = idx[keep]
        self.feasible = idx

    def contact(self, p_object) -> int:
        """Index of the sample point nearest to ``p_object``; it must be feasible."""
        i = int(np.argmin(np.linalg.norm(self.sample.points - np.asarray(p_object), axis=1)))
        assert i in self.feasible, f"{p_object} is not a feasible index contact"
        return i

    def plan(self, i_p: int, i_q: int, q_hand=None, **kwargs) -> RegraspResult:
        S, M = self.sample, self.manifold
        return plan_regrasp(
            self.hand,
            self.obj,
            self.motion,
            FINGER,
            0.0,
            S.points[i_p],
            S.normals[i_p],
            S.points[i_q],
            S.normals[i_q],
            M.q[0, i_p],
            q_hand or self.q_neutral,
            **kwargs,
        )

    def q_neutral(self, times: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.hand.neutral(), (len(times), self.hand.model.nq)).copy()


class CoalCheck:
    """Independent distances of one finger's geometries, computed with Pinocchio + Coal."""

    def __init__(self, hand: Hand, finger: str) -> None:
        self.hand = hand
        self.finger = hand.finger(finger)
        self.model, self.cm = hand.model, hand.collision_model
        self.data = self.model.createData()
        self.gdata = pin.GeometryData(self.cm)
        self.box = coal.Box(*BOX_SIZE)
        self.request = coal.DistanceRequest()
        mine = set(self.finger.geometry_ids)
        self.others = [
            g
            for name, other in hand.fingers.items()
            if name != finger
            for g in other.geometry_ids
            if g not in mine
        ]
        self.tip_frame = self.model.getFrameId(self.finger.tip_frame)
        self.bound_radius = {
            g: _bounding_radius(self.cm.geometryObjects[g].geometry)
            for g in (*self.finger.geometry_ids, *self.others)
        }

    def place(self, q_full: np.ndarray) -> None:
        pin.forwardKinematics(self.model, self.data, q_full)
        pin.updateGeometryPlacements(self.model, self.data, self.cm, self.gdata)

    def tip_palm(self, q_full: np.ndarray) -> np.ndarray:
        """Tip-centre positions (N, 3) in the palm frame [m] (Pinocchio frame placement)."""
        out = np.empty((len(q_full), 3))
        for i, q in enumerate(q_full):
            pin.forwardKinematics(self.model, self.data, q)
            out[i] = pin.updateFramePlacement(self.model, self.data, self.tip_frame).translation
        return out

    def run(self, q_full: np.ndarray, T_palm_object: np.ndarray, *, fingers: bool = True):
        """Object distances ``(N, G)`` of the finger's geometries, the smallest distance
        ``(N,)`` to another finger (inf where every pair is provably > 1 mm apart) and
        the tip centres ``(N, 3)`` in the palm frame."""
        objs = self.cm.geometryObjects
        G = self.finger.geometry_ids
        d_obj = np.empty((len(q_full), len(G)))
        d_ff = np.full(len(q_full), np.inf)
        tips = np.empty((len(q_full), 3))
        for i, (q, T) in enumerate(zip(q_full, T_palm_object, strict=True)):
            self.place(q)
            tips[i] = pin.updateFramePlacement(self.model, self.data, self.tip_frame).translation
            tf_box = coal.Transform3s(T[:3, :3], T[:3, 3])
            for j, g in enumerate(G):
                d_obj[i, j] = coal.distance(
                    objs[g].geometry,
                    self.gdata.oMg[g],
                    self.box,
                    tf_box,
                    self.request,
                    coal.DistanceResult(),
                )
                if not fingers:
                    continue
                c_g = self.gdata.oMg[g].translation
                for b in self.others:
                    gap = (
                        np.linalg.norm(c_g - self.gdata.oMg[b].translation)
                        - self.bound_radius[g]
                        - self.bound_radius[b]
                    )
                    if gap > 1e-3:  # bounding spheres: far more than FINGER_GAP_M apart
                        continue
                    d = coal.distance(
                        objs[g].geometry,
                        self.gdata.oMg[g],
                        objs[b].geometry,
                        self.gdata.oMg[b],
                        self.request,
                        coal.DistanceResult(),
                    )
                    d_ff[i] = min(d_ff[i], d)
        return d_obj, d_ff, tips


def _bounding_radius(shape) -> float:
    if isinstance(shape, coal.Sphere):
        return float(shape.radius)
    if isinstance(shape, coal.Cylinder):
        return float(math.hypot(shape.radius, shape.halfLength))
    if isinstance(shape, coal.Capsule):
        return float(shape.radius + shape.halfLength)
    if isinstance(shape, coal.Box):
        return float(np.linalg.norm(shape.halfSide))
    raise NotImplementedError(type(shape).__name__)


def full_trajectory(hand: Hand, result: RegraspResult, q_hand) -> np.ndarray:
    q_full = np.array(q_hand(result.times_s), dtype=float)
    q_full[:, hand.finger(result.finger).q_indices] = result.q
    return q_full


def dense(times_s: np.ndarray, q_full: np.ndarray, motion: ObjectMotion):
    """Linear interpolation of ``q_full`` (every joint) at steps <= 1 mrad; object poses
    from ``motion.pose``, with its rotation and translation per step bounded as well."""
    T = motion.pose(times_s)
    turn = Rotation.from_matrix(
        np.einsum("kji,kjl->kil", T[:-1, :3, :3], T[1:, :3, :3])
    ).magnitude()
    shift = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1) / OBJECT_LEVER_M
    step = np.maximum.reduce([np.abs(np.diff(q_full, axis=0)).max(axis=1), turn, shift])
    n = np.maximum(1, np.ceil(step / MAX_JOINT_STEP_RAD)).astype(int)
    t_d, q_d = [], []
    for k in range(len(times_s) - 1):
        s = np.arange(n[k]) / n[k]
        t_d.append(times_s[k] + s * (times_s[k + 1] - times_s[k]))
        q_d.append(q_full[k] + s[:, None] * (q_full[k + 1] - q_full[k]))
    t_d.append(times_s[-1:])
    q_d.append(q_full[-1:])
    t_d, q_d = np.concatenate(t_d), np.vstack(q_d)
    assert np.abs(np.diff(q_d, axis=0)).max() <= MAX_JOINT_STEP_RAD * (1 + 1e-9)
    return t_d, q_d, motion.pose(t_d)


def in_flight(result: RegraspResult, tip_object: np.ndarray) -> np.ndarray:
    """Where the tip is away from the lift-off and landing zones.

    Our choice: each tip centre (FK, moved to the object frame) is matched with the
    nearest point of ``result.tip_path`` (the fingertip-centre curve over the inflated
    surface) and is in flight when that point's surface arc length lies more than
    ``tip_path.taper_m`` from both ends of the path.
    """
    path = result.tip_path
    near = np.argmin(
        np.linalg.norm(tip_object[:, None, :] - path.points_object[None], axis=2), axis=1
    )
    arc = path.arc_length_m[near]
    return (arc > path.taper_m) & (arc < path.length_m - path.taper_m)


def recheck(checker: CoalCheck, scene: Scene, result: RegraspResult, q_hand=None) -> dict:
    """Dense, independent re-check of a returned regrasp; returns the measured minima.

    Stricter than the planner's own check in one respect: in flight (see
    :func:`in_flight`) *every* geometry of the finger must keep ``clearance_m`` (issue 5),
    while the planner requires it of the tip geometries only (``link_clearance_m`` for
    the others).
    """
    q_hand = q_hand or scene.q_neutral
    f = checker.finger
    params = result.params
    t_d, q_d, T_d = dense(
        result.times_s, full_trajectory(checker.hand, result, q_hand), scene.motion
    )
    d_obj, d_ff, tips = checker.run(q_d, T_d)
    tip_obj = np.einsum("dji,dj->di", T_d[:, :3, :3], tips - T_d[:, :3, 3])
    flight = in_flight(result, tip_obj)
    names = [checker.cm.geometryObjects[g].name for g in f.geometry_ids]

    worst = np.unravel_index(np.argmin(d_obj), d_obj.shape)
    assert d_obj.min() >= -PENETRATION_TOL_M, (
        f"{names[worst[1]]} penetrates the box by {-1e3 * d_obj.min():.3f} mm "
        f"at t={t_d[worst[0]]:.4f} s"
    )
    if flight.any():
        fl = d_obj[flight]
        worst = np.unravel_index(np.argmin(fl), fl.shape)
        assert fl.min() >= params.clearance_m - PENETRATION_TOL_M, (
            f"in flight {names[worst[1]]} is {1e3 * fl.min():.3f} mm from the box "
            f"(clearance {1e3 * params.clearance_m:.1f} mm) at t={t_d[flight][worst[0]]:.4f} s"
        )
    assert d_ff.min() >= FINGER_GAP_M - FINGER_GAP_SLACK_M, (
        f"another finger is {1e3 * d_ff.min():.3f} mm away at t={t_d[np.argmin(d_ff)]:.4f} s"
    )
    q_f = q_d[:, f.q_indices]
    assert np.all(q_f >= f.lower - 1e-9) and np.all(q_f <= f.upper + 1e-9), "joint limits"
    speed = np.abs(np.diff(result.q, axis=0)) / np.diff(result.times_s)[:, None]
    assert np.all(speed <= f.velocity_limit), "joint velocity limits"
    return {
        "n_dense": len(t_d),
        "min_object_m": float(d_obj.min()),
        "min_flight_m": float(d_obj[flight].min()) if flight.any() else math.inf,
        "n_flight": int(flight.sum()),
        "min_finger_m": float(d_ff.min()),
    }


def interp_q(result: RegraspResult, t_s: np.ndarray) -> np.ndarray:
    """The planned joint trajectory, linearly interpolated at times ``t_s``."""
    return np.stack(
        [np.interp(t_s, result.times_s, result.q[:, j]) for j in range(result.q.shape[1])], axis=1
    )


# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def hand() -> Hand:
    return Hand.five_finger()


@pytest.fixture(scope="module")
def checker(hand) -> CoalCheck:
    return CoalCheck(hand, FINGER)


UPRIGHT = box_pose((0.065, 0.0, 0.06))
EDGE = box_pose((0.06, 0.02, 0.05), (0.0, 0.0, -math.pi / 4))


@pytest.fixture(scope="module")
def scenes(hand) -> dict[str, Scene]:
    return {
        "upright-static": Scene(hand, UPRIGHT, 0.0),
        "upright-moving": Scene(hand, UPRIGHT, 10.0),
        # fewer contacts keep 0.15 rad and 3 mm around the edge: 0.1 rad and 1 mm
        "edge-static": Scene(hand, EDGE, 0.0, 0.1, 0.001),
        "edge-moving": Scene(hand, EDGE, 10.0, 0.1, 0.001),
    }


@pytest.fixture(scope="module")
def planned(scenes):
    """``planned(scene_name, P, Q) -> (scene, result)``, each plan made once per module."""
    cache: dict[tuple, RegraspResult] = {}

    def plan(scene_name: str, p_object, q_object) -> tuple[Scene, RegraspResult]:
        scene = scenes[scene_name]
        key = (scene_name, tuple(p_object), tuple(q_object))
        if key not in cache:
            cache[key] = scene.plan(scene.contact(p_object), scene.contact(q_object))
        return scene, cache[key]

    return plan


# (scene, P, Q): P and Q on the +x face of the upright box (object frame [m]); on
# the edge scene P on the +x face and Q on the +y face, around the vertical edge
CASES = [
    ("upright-static", (0.02, 0.025, -0.019), (0.02, 0.029, -0.003)),
    ("upright-static", (0.02, 0.027, -0.003), (0.02, 0.027, -0.019)),
    ("upright-moving", (0.02, 0.029, -0.019), (0.02, 0.025, -0.003)),
    ("upright-moving", (0.02, 0.025, -0.019), (0.02, 0.025, -0.003)),
    ("edge-static", (0.02, 0.027, -0.007), (0.009, 0.03, -0.019)),
    ("edge-moving", (0.02, 0.029, -0.017), (0.009, 0.03, -0.005)),
]


# ---------------------------------------------------------------------- 1. re-check
@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), CASES)
def test_every_returned_path_passes_an_independent_dense_coal_recheck(
    planned, checker, scene_name, p_object, q_object
):
    scene, result = planned(scene_name, p_object, q_object)
    assert result.report.ok
    stats = recheck(checker, scene, result)
    # the re-check is dense: at least one sample per mrad of the largest joint travel
    travel = np.abs(np.diff(result.q, axis=0)).max(axis=1).sum()
    assert stats["n_dense"] >= travel / MAX_JOINT_STEP_RAD
    # the tip touches at P and Q (IK tolerance), so the smallest distance is ~0
    assert stats["min_object_m"] <= 1e-4


# ---------------------------------------------------------------------- 2. synchronization
@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), CASES)
def test_waypoints_are_passed_in_step_with_the_object(
    planned, checker, scene_name, p_object, q_object
):
    scene, result = planned(scene_name, p_object, q_object)
    t_i = result.waypoint_times_s
    assert np.all(np.diff(t_i) > 0)
    assert_close(t_i[[0, -1]], [result.t_start, result.t_end], atol=1e-9, what="first/last")
    q_full = np.tile(scene.hand.neutral(), (len(t_i), 1))
    q_full[:, checker.finger.q_indices] = interp_q(result, t_i)
    tip_palm = checker.tip_palm(q_full)
    T = scene.motion.pose(t_i)
    expected = np.einsum("nij,nj->ni", T[:, :3, :3], result.waypoints_object) + T[:, :3, 3]
    assert_close(tip_palm, expected, atol=1e-4, what="tip at T(t_i) waypoint_i")


# ---------------------------------------------------------------------- 3. end points
@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), CASES)
def test_tip_starts_on_p_and_ends_on_q(planned, checker, scene_name, p_object, q_object):
    scene, result = planned(scene_name, p_object, q_object)
    S = scene.sample
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    r = checker.finger.tip_radius
    q_full = full_trajectory(scene.hand, result, scene.q_neutral)[[0, -1]]
    tip_palm = checker.tip_palm(q_full)
    T = scene.motion.pose(np.array([result.t_start, result.t_end]))
    targets = np.stack([S.points[i_p] + r * S.normals[i_p], S.points[i_q] + r * S.normals[i_q]])
    expected = np.einsum("nij,nj->ni", T[:, :3, :3], targets) + T[:, :3, 3]
    assert_close(tip_palm, expected, atol=2e-5, what="tip at P (t0) and Q (t1)")
    assert_close(result.P_object, S.points[i_p], atol=0.0, what="recorded P")
    assert_close(result.Q_object, S.points[i_q], atol=0.0, what="recorded Q")


# ---------------------------------------------------------------------- 4. straight move
@pytest.mark.parametrize(("scene_name", "p_object", "q_object"), CASES[4:])
def test_a_move_that_a_straight_joint_line_would_cut_through_the_box_is_solved(
    planned, checker, scene_name, p_object, q_object
):
    scene, result = planned(scene_name, p_object, q_object)
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    # the straight joint-space move from q_P (t = 0) to q_Q (t = 0.5 s), object moving
    q_P, q_Q = scene.manifold.q[0, i_p], scene.manifold.q[1, i_q]
    q_full = np.tile(scene.hand.neutral(), (2, 1))
    q_full[:, checker.finger.q_indices] = [q_P, q_Q]
    t_d, q_d, T_d = dense(T_MANIFOLD_S, q_full, scene.motion)
    d_obj, _, _ = checker.run(q_d, T_d, fingers=False)
    assert d_obj.min() < -1e-3, "the straight move should cut more than 1 mm into the box"
    # ... and the re-check below rejects it, timed like the plan
    s = (result.times_s - result.t_start) / (result.t_end - result.t_start)
    straight = dataclasses.replace(result, q=q_P + s[:, None] * (q_Q - q_P))
    with pytest.raises(AssertionError, match="penetrates the box"):
        recheck(checker, scene, straight)
    # the planned path goes around the edge: from the +x face to the +y face
    assert {0, 1} <= set(result.grid_path.face_ids.tolist())
    stats = recheck(checker, scene, result)
    assert stats["n_flight"] > 0, "the path should leave the lift-off and landing zones"
    assert stats["min_flight_m"] >= result.params.clearance_m - PENETRATION_TOL_M


# ---------------------------------------------------------------------- 5. neighbour
BLOCK_MARGIN_M = 1e-3  # a blocker keeps this from the box and from the finger at P and Q


class Placer:
    """Geometries of the hand placed with Pinocchio, and Coal distances between them."""

    def __init__(self, hand: Hand) -> None:
        self.hand, self.model, self.cm = hand, hand.model, hand.collision_model
        self.data, self.gdata = self.model.createData(), pin.GeometryData(self.cm)
        self.request = coal.DistanceRequest()

    def place(self, q_full: np.ndarray, finger: str) -> list[tuple]:
        """``(shape, placement)`` of each geometry of ``finger`` at ``q_full``."""
        pin.forwardKinematics(self.model, self.data, q_full)
        pin.updateGeometryPlacements(self.model, self.data, self.cm, self.gdata)
        return [
            (self.cm.geometryObjects[g].geometry, pin.SE3(self.gdata.oMg[g]))
            for g in self.hand.finger(finger).geometry_ids
        ]

    def distance(self, a: list[tuple], b: list[tuple]) -> float:
        """Smallest distance between two sets of placed geometries [m]."""
        return min(
            coal.distance(g1, M1, g2, M2, self.request, coal.DistanceResult())
            for g1, M1 in a
            for g2, M2 in b
        )

    def finger_gap(self, q_full: np.ndarray, finger: str, other: str) -> float:
        return self.distance(self.place(q_full, finger), self.place(q_full, other))


def blocking_configuration(hand: Hand, scene: Scene, path: RegraspResult, other: str):
    """A configuration of ``other`` (held still) that keeps ``BLOCK_MARGIN_M`` from the
    box and from the regrasping finger at P and Q, but cuts into the finger along
    ``path`` (13 samples). None if there is none.

    Deterministic search: every constraint is a margin (distance to the box minus
    ``BLOCK_MARGIN_M``, gaps at P and Q minus ``BLOCK_MARGIN_M``, depth of the cut in
    flight); their minimum is maximised over a 9 x 9 x 9 grid of the joint box, then by
    a compass search (halving steps, inside the limits) from the three best grid points.
    A configuration blocks when that minimum is positive.
    """
    o = hand.finger(other)
    placer = Placer(hand)
    T = scene.motion.pose(path.times_s[[0, -1]])
    box = coal.Box(*BOX_SIZE)
    box_at = [[(box, pin.SE3(Ti[:3, :3], Ti[:3, 3]))] for Ti in T]
    sel = np.linspace(0, len(path.times_s) - 1, 13).round().astype(int)
    finger_at = [placer.place(q, FINGER) for q in full_trajectory(hand, path, scene.q_neutral)[sel]]

    def full(q_other: np.ndarray) -> np.ndarray:
        base = hand.neutral()
        base[o.q_indices] = q_other
        return base

    def margin(q_other: np.ndarray) -> float:
        geoms = placer.place(full(q_other), other)
        to_box = min(placer.distance(geoms, b) for b in box_at)
        gap = [placer.distance(geoms, sample) for sample in finger_at]
        return min(
            to_box - BLOCK_MARGIN_M,
            gap[0] - BLOCK_MARGIN_M,
            gap[-1] - BLOCK_MARGIN_M,
            -min(gap[1:-1]),
        )

    axes = [np.linspace(lo, hi, 9) for lo, hi in zip(o.lower, o.upper, strict=True)]
    grid = [np.array(q) for q in itertools.product(*axes)]
    scores = np.array([margin(q) for q in grid])
    best, best_score = None, -math.inf
    for k in np.argsort(-scores, kind="stable")[:3]:
        x, s = grid[k], scores[k]
        step = (o.upper - o.lower) / 16  # half a grid cell
        for _ in range(6):
            while True:
                moves = [
                    np.clip(x + sign * step[j] * np.eye(len(x))[j], o.lower, o.upper)
                    for j in range(len(x))
                    for sign in (1.0, -1.0)
                ]
                m = [margin(y) for y in moves]
                j = int(np.argmax(m))
                if m[j] <= s:
                    break
                x, s = moves[j], m[j]
            step = step / 2
        if s > best_score:
            best, best_score = x, s
    return full(best) if best_score > 0.0 else None


def landing_next_to(scene: Scene, placer: Placer, other: str):
    """Lift-off P and landing Q among the feasible contacts (searched): at Q the index
    comes within ``FINGER_GAP_M`` of ``other`` (and of no other finger), as little
    inside as possible; P is the contact farthest from Q whose lift-off keeps 2 mm from
    every other finger. None if there is no such pair."""
    hand, M, S = scene.hand, scene.manifold, scene.sample
    rest = [name for name in hand.fingers if name not in (FINGER, other)]

    def gaps(k: int, i: int) -> tuple[float, float]:
        q = hand.to_full(FINGER, M.q[k, i])
        return placer.finger_gap(q, FINGER, other), min(
            placer.finger_gap(q, FINGER, name) for name in rest
        )

    landing, lift_off = [], []
    for i in scene.feasible:
        g_other, g_rest = gaps(1, i)
        if g_other < FINGER_GAP_M <= g_rest:
            landing.append((g_other, -i))
        if min(gaps(0, i)) >= 2e-3:
            lift_off.append(i)
    if not landing or not lift_off:
        return None
    i_q = -max(landing)[1]
    d = np.linalg.norm(S.points[lift_off] - S.points[i_q], axis=1)
    return int(lift_off[int(np.argmax(d))]), int(i_q)


def assert_refused_or_verified(scene, checker, i_p, i_q, q_hand, blocker: str):
    """The planner either returns a path that passes the re-check, or raises the typed
    error naming the finger, the time (within the regrasp) and the blocking finger."""
    try:
        result = scene.plan(i_p, i_q, q_hand)
    except (VerificationError, PlanningError) as exc:
        assert exc.finger == FINGER
        assert exc.time_s is not None and 0.0 <= exc.time_s <= 0.5
        text = str(exc)
        assert text.startswith(f"finger '{FINGER}', t={exc.time_s:.3f} s:"), text
        assert blocker in text, text  # what failed: the other finger is named
        return exc
    recheck(checker, scene, result, q_hand)
    return result


def test_a_finger_in_the_way_in_flight_is_avoided_or_refused(hand, scenes, planned, checker):
    """The thumb, held still (configuration searched), sits where the unobstructed path
    of the index passes, clear of it at lift-off and landing."""
    scene = scenes["edge-static"]
    p_object, q_object = CASES[4][1:]
    i_p, i_q = scene.contact(p_object), scene.contact(q_object)
    free = planned("edge-static", p_object, q_object)[1]
    base = blocking_configuration(hand, scene, free, "thumb")
    assert base is not None, "no thumb configuration blocks the path: the scene changed"

    def q_hand(times):
        return np.tile(base, (len(times), 1))

    # the thumb is in the way: the free path, re-checked with it, fails in flight only
    _, q_d, T_d = dense(free.times_s, full_trajectory(hand, free, q_hand), scene.motion)
    _, d_ff, _ = checker.run(q_d, T_d)
    assert d_ff[0] > FINGER_GAP_M and d_ff[-1] > FINGER_GAP_M and d_ff.min() < 0.0
    assert_refused_or_verified(scene, checker, i_p, i_q, q_hand, "thumb")


def test_a_landing_next_to_the_middle_finger_is_refused(hand, scenes, checker):
    """A landing spot (searched) where the index comes within 0.5 mm of the middle
    finger (at the middle of its limits): no path can end there, so the planner must
    refuse, naming the middle finger."""
    scene = scenes["upright-static"]
    placer = Placer(hand)
    pair = landing_next_to(scene, placer, "middle")
    assert pair is not None, "no feasible landing next to the middle finger: the scene changed"
    i_p, i_q = pair
    q_land = hand.to_full(FINGER, scene.manifold.q[1, i_q])
    assert placer.finger_gap(q_land, FINGER, "middle") < FINGER_GAP_M
    _, d_ff, _ = checker.run(q_land[None], scene.motion.pose(np.array([0.5])))
    assert d_ff[0] < FINGER_GAP_M  # the independent check agrees
    outcome = assert_refused_or_verified(scene, checker, i_p, i_q, scene.q_neutral, "middle")
    assert isinstance(outcome, VerificationError)


def test_a_failure_before_verification_reports_when_it_happened(scenes):
    """0.03 s is far too short for this move: every attempt exceeds a joint velocity
    limit. Minimum-jerk timing starts and ends at rest, so the violation lies strictly
    inside the regrasp, and the error must say when (not just when the regrasp began)."""
    scene = scenes["upright-static"]
    i_p = scene.contact((0.02, 0.025, -0.019))
    i_q = scene.contact((0.02, 0.029, -0.003))
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, params=RegraspParams(duration_s=0.03))
    exc = info.value
    assert not isinstance(exc, VerificationError)
    assert exc.finger == FINGER
    assert 0.0 < exc.time_s < 0.03
    assert str(exc).startswith(f"finger '{FINGER}', t={exc.time_s:.3f} s:")
    assert "rad/s" in exc.reason and "index_" in exc.reason  # the joint and its speed
    # as data: the kind, and the speed over the joint's limit (what time scaling needs)
    assert exc.kind == FailureKind.VELOCITY
    assert exc.measured is not None and exc.required is not None
    assert exc.measured > exc.required > 0.0
    assert all(a.kind == FailureKind.VELOCITY for a in exc.attempts)


def test_a_regrasp_too_fast_when_paced_by_its_length_passes_paced_by_its_joints(
    scenes, checker, monkeypatch
):
    """At 0.18 s the index outruns a joint's limit when its tip moves along the curve
    with minimum-jerk progress in length (the joints turn unevenly along it); paced by
    the joints' motion (:func:`~regrasp_pin.planning.timing.joint_paced`) the same
    regrasp passes: the independent re-check, the joint velocity limits, and each
    waypoint still reached at its own time."""
    scene = scenes["upright-moving"]
    i_p = scene.contact((0.02, 0.025, -0.019))
    i_q = scene.contact((0.02, 0.025, -0.003))
    params = RegraspParams(duration_s=0.18)
    result = scene.plan(i_p, i_q, params=params, route="surface")
    recheck(checker, scene, result)  # includes the joint velocity limits
    t_i = result.waypoint_times_s
    assert np.all(np.diff(t_i) > 0)
    q_full = np.tile(scene.hand.neutral(), (len(t_i), 1))
    q_full[:, checker.finger.q_indices] = interp_q(result, t_i)
    T = scene.motion.pose(t_i)
    expected = np.einsum("nij,nj->ni", T[:, :3, :3], result.waypoints_object) + T[:, :3, 3]
    assert_close(checker.tip_palm(q_full), expected, atol=1e-4, what="tip at T(t_i) waypoint_i")

    monkeypatch.setattr(regrasp_module, "joint_paced", lambda u, q, vlim, progress: u)
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, params=params, route="surface")
    assert info.value.kind == FailureKind.VELOCITY


def test_the_cruise_law_lands_a_regrasp_sooner_within_the_same_velocity_limits(scenes, checker):
    """In 0.12 s the index's regrasp outruns a joint's limit by minimum jerk, paced by
    its joints or not; by the cruise law (its peak speed 1.43 instead of 1.875 times the
    mean) the same regrasp passes: the independent re-check, joint velocity limits
    included, and each waypoint reached at its own time (within the IK's flight
    tolerance: the executed motion, not the curve, is what the Coal check verifies)."""
    scene = scenes["upright-moving"]
    i_p = scene.contact((0.02, 0.025, -0.019))
    i_q = scene.contact((0.02, 0.025, -0.003))
    with pytest.raises(PlanningError) as info:
        scene.plan(i_p, i_q, params=RegraspParams(duration_s=0.12), route="surface")
    assert info.value.kind == FailureKind.VELOCITY
    params = RegraspParams(duration_s=0.12, time_law="cruise")
    result = scene.plan(i_p, i_q, params=params, route="surface")
    assert result.params.time_law == "cruise"
    assert result.t_end - result.t_start == pytest.approx(0.12, abs=1e-12)
    recheck(checker, scene, result)  # includes the joint velocity limits
    t_i = result.waypoint_times_s
    q_full = np.tile(scene.hand.neutral(), (len(t_i), 1))
    q_full[:, checker.finger.q_indices] = interp_q(result, t_i)
    T = scene.motion.pose(t_i)
    expected = np.einsum("nij,nj->ni", T[:, :3, :3], result.waypoints_object) + T[:, :3, 3]
    tip = checker.tip_palm(q_full)
    assert_close(tip, expected, atol=params.flight_ik_tol_m, what="tip at T(t_i) waypoint_i")
    assert_close(tip[[0, -1]], expected[[0, -1]], atol=params.ik_tol_m, what="tip at P and Q")


# ---------------------------------------------------------------------- 6. minimum jerk
def test_minimum_jerk_is_0_to_1_monotone_with_zero_velocity_and_acceleration_at_the_ends():
    assert_close(minimum_jerk(np.array([0.0, 0.5, 1.0])), [0.0, 0.5, 1.0], atol=1e-15)
    assert_close(minimum_jerk(np.array([-0.3, 1.4])), [0.0, 1.0], atol=0.0, what="clipped")
    tau = np.linspace(0.0, 1.0, 10001)
    s = minimum_jerk(tau)
    assert np.all(np.diff(s) > 0), "strictly increasing"
    assert_close(s + s[::-1], 1.0, atol=1e-14, what="symmetric about (1/2, 1/2)")
    # central differences against s' = 30 tau^2 (1 - tau)^2
    h = 1e-5
    mid = tau[1:-1]
    ds = (minimum_jerk(mid + h) - minimum_jerk(mid - h)) / (2 * h)
    assert_close(ds, 30 * mid**2 * (1 - mid) ** 2, atol=1e-8, what="s'")
    # one-sided differences at the ends: s ~ 10 h^3 there, so the first difference is
    # 10 h^2 and the second 60 h to leading order, both -> 0 with h
    for h in (1e-2, 1e-3, 1e-4):
        for end, sign in ((0.0, 1.0), (1.0, -1.0)):
            s0, s1, s2 = minimum_jerk(np.array([end, end + sign * h, end + 2 * sign * h]))
            assert abs(s1 - s0) / h <= 10.0 * h**2 * 1.001
            assert abs(s2 - 2 * s1 + s0) / h**2 <= 60.0 * h * 1.001


# ---------------------------------------------------------------------- 7. bad input
def test_bad_input_raises_input_error_naming_the_argument(scenes):
    scene = scenes["upright-moving"]
    S = scene.sample
    i_p = scene.contact((0.02, 0.025, -0.019))
    i_q = scene.contact((0.02, 0.029, -0.003))
    P, nP, Q, nQ = S.points[i_p], S.normals[i_p], S.points[i_q], S.normals[i_q]
    q0 = scene.manifold.q[0, i_p]

    def call(P=P, Q=Q, t_start=0.0, params=None):
        return plan_regrasp(
            scene.hand,
            scene.obj,
            scene.motion,
            FINGER,
            t_start,
            P,
            nP,
            Q,
            nQ,
            q0,
            scene.q_neutral,
            params=params,
        )

    cases = [
        ("P_object", dict(P=P + 0.003 * nP)),  # 3 mm off the face
        ("P_object", dict(P=P - 0.003 * nP)),  # inside the box
        ("Q_object", dict(Q=Q + 0.003 * nQ)),
        ("Q_object", dict(Q=P.copy())),  # P == Q
        ("clearance_m", dict(params=RegraspParams(clearance_m=0.0))),
        ("clearance_m", dict(params=RegraspParams(clearance_m=-0.001))),
        ("m", dict(params=RegraspParams(m=1))),
        ("time_law", dict(params=RegraspParams(time_law="trapezoid"))),
        ("t_start", dict(t_start=0.6)),  # [0.6, 1.1] s leaves the 1 s motion
        ("t_start", dict(t_start=-0.1)),
    ]
    for argument, kwargs in cases:
        with pytest.raises(InputError) as info:
            call(**kwargs)
        assert info.value.argument == argument, (argument, str(info.value))
        assert str(info.value).startswith(argument + ":")
    with pytest.raises(InputError, match="coincide"):
        call(Q=P.copy())
    for bad in (RegraspParams(clearance_m=0.0), RegraspParams(m=1), RegraspParams(m=2.5)):
        with pytest.raises(InputError):
            bad.validate()
    assert RegraspParams(m=2).validate().m == 2


# ---------------------------------------------------------------------- 8. determinism
def test_the_same_call_gives_the_same_trajectory(scenes):
    scene = scenes["upright-moving"]
    i_p = scene.contact((0.02, 0.029, -0.019))
    i_q = scene.contact((0.02, 0.025, -0.003))
    a = scene.plan(i_p, i_q)
    b = scene.plan(i_p, i_q)
    assert np.array_equal(a.q, b.q)
    assert np.array_equal(a.times_s, b.times_s)
    assert np.array_equal(a.waypoints_object, b.waypoints_object)
    assert a.attempts == b.attempts


def test_a_variant_that_leaves_the_path_as_it_was_is_not_attempted_again(hand, scenes, monkeypatch):
    """Next to the middle finger every variant fails; the wider gaps that leave the tip
    path as it was (the same points, the same m) fail as that path did, without being
    attempted again: the attempts and the error are those of attempting every one."""
    scene = scenes["upright-static"]
    i_p, i_q = landing_next_to(scene, Placer(hand), "middle")
    real = regrasp_module._attempt
    calls = []

    def counted(task, gpath, tip_path, p, stages):
        calls.append((tip_path.points_object.tobytes(), min(p.m, len(tip_path))))
        return real(task, gpath, tip_path, p, stages)

    monkeypatch.setattr(regrasp_module, "_attempt", counted)

    def outcome():
        calls.clear()
        with pytest.raises(PlanningError) as info:
            scene.plan(i_p, i_q, q_hand=scene.q_neutral, route="surface")
        return info.value, list(calls)

    reused, reused_calls = outcome()
    monkeypatch.setattr(regrasp_module, "_path_key", lambda path: object())  # never equal
    every, every_calls = outcome()
    assert reused.attempts == every.attempts and reused.kind == every.kind
    assert len(every_calls) == len(every.attempts) > len(reused_calls)
    assert len(set(reused_calls)) == len(reused_calls) == len(set(every_calls))


def test_a_polygon_asked_for_again_is_the_one_computed_before(monkeypatch):
    """The regrasp's polygons: the same points and settings give the answer of
    ``approximate_polygon`` itself, computed once; what a caller does to its arrays
    does not reach the next caller."""
    monkeypatch.setattr(regrasp_module, "_POLYGONS", type(regrasp_module._POLYGONS)())
    real = regrasp_module.approximate_polygon
    calls = []

    def counted(*args, **kwargs):
        calls.append(args[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(regrasp_module, "approximate_polygon", counted)
    rng = np.random.default_rng(5)
    pts = np.cumsum(rng.normal(size=(60, 3)) * 1e-3, axis=0)
    first = regrasp_module._polygon(pts, 7, "max", "hopfield")
    direct = real(pts, 7, closed=False, deviation="max", method="hopfield", stop_at_optimum=True)
    assert np.array_equal(first.indices, direct.indices) and first.energy == direct.energy
    assert np.array_equal(first.vertices, direct.vertices)
    first.vertices[:] = 0.0  # a caller writing into its result
    again = regrasp_module._polygon(pts.copy(), 7, "max", "hopfield")
    assert calls == [7]  # not computed again
    assert np.array_equal(again.vertices, direct.vertices)
    regrasp_module._polygon(pts, 8, "max", "hopfield")
    assert calls == [7, 8]  # another m is another polygon


def test_object_clearance_variants_follow_where_the_clearance_was_lost():
    """The planned curve that cuts the inflated surface's corners gets more waypoints
    (then more inflation once ``max_m`` is reached); a motion whose Coal check finds the
    finger nearer the object than the curve gets more inflation at once, with the
    waypoints as at first, up to the largest inflation, and then no variant."""
    base = RegraspParams()
    curve = PlanningError("the waypoint curve", kind=FailureKind.OBJECT_CLEARANCE)
    coal = VerificationError("Coal check failed", kind=FailureKind.OBJECT_CLEARANCE)
    nxt = regrasp_module._next_variant
    assert nxt(base, curve, base) == dataclasses.replace(base, m=base.m + 2)
    at_max = dataclasses.replace(base, m=base.max_m)
    inflated = dataclasses.replace(base, inflation_factor=1.5 * base.inflation_factor)
    assert nxt(at_max, curve, base) == inflated
    assert nxt(base, coal, base) == inflated
    assert nxt(dataclasses.replace(base, m=base.m + 2), coal, base) == inflated
    factors, p = [base.inflation_factor], base
    while (p := nxt(p, coal, base)) is not None:
        assert p.m == base.m
        factors.append(p.inflation_factor)
    top = base.inflation_factor * regrasp_module._MAX_INFLATION_FACTOR
    assert factors[-1] <= top + 1e-9 < 1.5 * factors[-1]
    assert len(factors) == 3  # 1.6, 2.4 and 3.6 with the defaults
