"""Our verified regrasp against OMPL RRTConnect + path simplification, one finger around a box.

Scene (``--scene``): the Allegro hand's index finger and a box in front of it; the
other fingers are bent back, out of the way. ``upright`` (default): a 50 mm cube, its
top face under the index pad. ``tilted``: a 40 x 50 x 40 mm box tilted 45 deg, whose
feasible contacts lie along one edge. ``--pairs`` pairs of contacts (P, Q), at least
``--min-distance-mm`` apart, are drawn (seeded) among the contacts that are feasible
for the index at the box's start pose and at its landing pose in the moving case: IK
inside the joint limits with 0.1 rad to spare, the pad facing the face, the non-tip
links >= 2 mm from the box, and valid by the rule below. Both planners get the same
start and goal joint configurations ``q_P`` and ``q_Q`` (IK at P and at Q).

* ours: :func:`regrasp_pin.planning.regrasp.plan_regrasp` (surface grid, grid path, Hopfield
  waypoints, IK, Coal verification) with the default
  :class:`~regrasp_pin.planning.regrasp.RegraspParams`; static box (two equal poses).
* OMPL: ``RRTConnect`` in the finger's joint space (``RealVectorStateSpace`` bounded by
  the joint limits) from ``q_P`` to ``q_Q``, then ``SimpleSetup.simplifySolution()``
  (the ``PathSimplifier``); OMPL's default state validity resolution; ``--time-limit``.

Validity rule, the same for both (OMPL's state validity checker, and the dense re-check
of every path of both planners): with Pinocchio placements and Coal, a configuration is
valid when no collision geometry of the finger penetrates the box by more than 0.1 mm
(signed distance >= -0.1 mm: the fingertip touches the box at P and Q) and none touches
a geometry of another finger (the palm, to which the finger is jointed, is not checked).
OMPL's checker evaluates it with ``pinocchio.computeCollisions`` (C++ loop over the
pairs, Coal security margin -0.1 mm for the box); the re-check with Coal distances. The
two are compared on random configurations at start-up.

Re-check: every path is re-sampled on its own interpolation (piecewise linear in joint
space; the object pose slerped in the moving case) at <= 1 mrad per joint and per
object rotation step. Reported: success count; median planning time (OMPL: solve,
simplify, both; ours: the whole ``plan_regrasp`` call, verification included); the
joint-space path length ``sum |dq|`` [rad] (median and range; ``|q_Q - q_P|`` bounds it
from below); the smallest Coal distance of the whole finger to the box away from the
endpoints (samples whose fingertip centre is more than ``--end-zone-mm`` from its
position at P and at Q, object frame); "touch": paths closer than 0.1 mm there; "pen":
paths that break the validity rule anywhere. OMPL's quality columns count every run
(``pairs x repeats`` paths); ours is deterministic, one path per pair.

Moving box: the box turns at ``--rate-deg-s`` about the palm y axis through its centre
during the regrasp (``RegraspParams.duration_s``). Ours plans with the motion. OMPL's
paths from the static case (planned with the box frozen at its start pose, i.e.
ignoring the motion) are executed with the same timing as ours (same duration,
minimum-jerk progress along the joint-space length) and re-checked against the moving
box.

Usage: ``python bench/regrasp_vs_ompl.py [--pairs 20] [--seed 0] [--repeats 3]
[--scene upright|tilted] [--verbose]``. OMPL is a benchmark-only dependency:
``pip install -e '.[bench]'``.
"""

from __future__ import annotations

import argparse
import gc
import itertools
import logging
import re
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from machine import machine_line
from scipy.spatial.transform import Rotation

from regrasp_pin import Box, Hand, ObjectMotion, RegraspError
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.ik import IK_BACKENDS, ik_backend, set_ik_backend
from regrasp_pin.model.ik_numba import available as numba_available
from regrasp_pin.planning.regrasp import RegraspParams, RegraspResult, minimum_jerk, plan_regrasp

try:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou
except ImportError:  # the 'bench' extra is not installed
    ob = og = ou = None

FINGER = "index"
#: scene name -> (box size [m], box centre in the palm frame [m], tilt about palm y [deg])
SCENES = {
    "upright": ((0.05, 0.05, 0.05), (0.07, 0.05, 0.04), 0.0),
    "tilted": ((0.04, 0.05, 0.04), (0.06, 0.05, 0.06), 45.0),
}
PENETRATION_TOL_M = 1e-4  # validity: no geometry deeper than this into the box [m]
TOUCH_M = 1e-4  # a re-checked path "touches" closer than this away from the ends [m]
CHECK_STEP_RAD = 1e-3  # re-check: largest joint step and object rotation step [rad]
CONTACT_MARGIN_RAD = 0.1  # P and Q at least this far inside the joint limits [rad]
CONTACT_LINK_CLEARANCE_M = 0.002  # non-tip links this far from the box at P and Q [m]
SAMPLE_SPACING_M = 0.003  # surface sample for the contact candidates [m]


# ----------------------------------------------------------------------- scene
@dataclass(frozen=True)
class Pair:
    """A regrasp problem: contacts (object frame) and start/goal joint configurations."""

    P: np.ndarray
    n_P: np.ndarray
    Q: np.ndarray
    n_Q: np.ndarray
    q_P: np.ndarray  # (k,) IK at P, box at its start pose [rad]
    q_Q: np.ndarray  # (k,) IK at Q, box at its start pose [rad]


@dataclass(frozen=True)
class Scene:
    hand: Hand
    box: Box
    q_hand: np.ndarray  # (nq,) the other fingers, out of the way
    T0: np.ndarray  # (4, 4) T_palm_object at the start
    static: ObjectMotion
    moving: ObjectMotion
    params: RegraspParams


def make_scene(name: str, rate_deg_s: float) -> Scene:
    size, centre, tilt_deg = SCENES[name]
    hand = Hand.allegro()
    q_hand = hand.neutral()
    for other, f in hand.fingers.items():
        if other != FINGER:  # bent back, away from the box, no abduction
            q_hand[f.q_indices] = f.lower
            if other != "thumb":
                q_hand[f.q_indices[0]] = 0.0
    T0 = np.eye(4)
    T0[:3, :3] = Rotation.from_euler("y", tilt_deg, degrees=True).as_matrix()
    T0[:3, 3] = centre
    params = RegraspParams()
    d = params.duration_s
    static = ObjectMotion.from_poses(np.array([0.0, d]), np.stack([T0, T0]))
    moving = ObjectMotion.constant_twist(
        T0,
        axis_palm=np.array([0.0, 1.0, 0.0]),
        point_palm=np.array(centre),
        rate_rad_s=np.radians(rate_deg_s),
        duration_s=d,
        dt_s=0.01,
    )
    return Scene(hand, Box(size), q_hand, T0, static, moving, params)


def tf_of(T: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(T[:3, :3].copy(), T[:3, 3].copy())


# ---------------------------------------------------------------- Coal checks
class FingerCollision:
    """The validity rule for one finger against the box and the other (static) fingers.

    :meth:`valid_static` (OMPL's checker) runs ``pinocchio.computeCollisions`` over the
    finger-box pairs (security margin ``-PENETRATION_TOL_M``) and finger-finger pairs,
    box at ``T_box``. :meth:`along` measures Coal distances for the re-check; finger
    pairs whose bounding spheres are apart are not sent to Coal.
    """

    def __init__(self, hand: Hand, finger: str, box: Box, q_hand: np.ndarray, T_box: np.ndarray):
        f = hand.finger(finger)
        cm = hand.collision_model
        self.f = f
        self.model = hand.model
        self.data = hand.model.createData()
        self.q_full = q_hand.astype(float).copy()
        self.box_geom = box.coal_geometry()
        self.req = coal.DistanceRequest()
        self.res = coal.DistanceResult()
        # distances: the whole hand's geometry data, other fingers placed once
        self.cm = cm
        self.gdata = pin.GeometryData(cm)
        pin.updateGeometryPlacements(self.model, self.data, cm, self.gdata, self.q_full)
        self.ids = list(f.geometry_ids)
        self.geoms = [cm.geometryObjects[g].geometry for g in self.ids]
        other_ids = [g for n, o in hand.fingers.items() if n != finger for g in o.geometry_ids]
        self.others = [
            (cm.geometryObjects[g].geometry, pin.SE3(self.gdata.oMg[g])) for g in other_ids
        ]
        for geom in self.geoms + [g for g, _ in self.others]:
            geom.computeLocalAABB()
        self.others_c = np.array(
            [M.act(np.asarray(g.aabb_center, float)) for g, M in self.others]
        ).reshape(-1, 3)
        self.others_r = np.array([g.aabb_radius for g, _ in self.others])
        self.own_c = [np.asarray(g.aabb_center, float) for g in self.geoms]
        self.own_r = np.array([g.aabb_radius for g in self.geoms])
        # validity: a geometry model with the finger, the other fingers and the box
        gm = pin.GeometryModel()
        own = [gm.addGeometryObject(cm.geometryObjects[g].copy()) for g in self.ids]
        oth = [gm.addGeometryObject(cm.geometryObjects[g].copy()) for g in other_ids]
        box_id = gm.addGeometryObject(
            pin.GeometryObject(
                "box", 0, 0, pin.SE3(T_box[:3, :3].copy(), T_box[:3, 3].copy()), self.box_geom
            )
        )
        for a in own:
            gm.addCollisionPair(pin.CollisionPair(a, box_id))
            for b in oth:
                gm.addCollisionPair(pin.CollisionPair(a, b))
        self.vgm = gm
        self.vgd = pin.GeometryData(gm)
        for k, cp in enumerate(gm.collisionPairs):
            if box_id in (cp.first, cp.second):
                self.vgd.collisionRequests[k].security_margin = -PENETRATION_TOL_M
        self.vdata = hand.model.createData()
        self.vq = self.q_full.copy()
        self.qi = f.q_indices

    def valid_static(self, q_finger: np.ndarray) -> bool:
        """The validity rule with the box at ``T_box``."""
        self.vq[self.qi] = q_finger
        return not pin.computeCollisions(self.model, self.vdata, self.vgm, self.vgd, self.vq, True)

    def _distances(self, q_finger: np.ndarray, tf_box: coal.Transform3s) -> tuple[float, float]:
        """Smallest box distance and smallest finger distance [m] at one configuration."""
        self.q_full[self.qi] = q_finger
        pin.updateGeometryPlacements(self.model, self.data, self.cm, self.gdata, self.q_full)
        oMg = self.gdata.oMg
        d_box = np.inf
        for g, geom in zip(self.ids, self.geoms, strict=True):
            self.res.clear()
            d_box = min(
                d_box, coal.distance(geom, oMg[g], self.box_geom, tf_box, self.req, self.res)
            )
        c = np.array([oMg[g].act(c0) for g, c0 in zip(self.ids, self.own_c, strict=True)])
        gap = (
            np.linalg.norm(c[:, None, :] - self.others_c[None], axis=2)
            - self.own_r[:, None]
            - self.others_r[None]
        )
        d_ff = np.inf
        for a, b in zip(*np.nonzero(gap < 0.0), strict=True):
            other, M2 = self.others[b]
            self.res.clear()
            d_ff = min(
                d_ff, coal.distance(self.geoms[a], oMg[self.ids[a]], other, M2, self.req, self.res)
            )
        return float(d_box), float(d_ff)

    def valid_at(self, q_finger: np.ndarray, T_box: np.ndarray) -> bool:
        """The validity rule by Coal distances, box at any pose."""
        d_box, d_ff = self._distances(q_finger, tf_of(T_box))
        return d_box >= -PENETRATION_TOL_M and d_ff >= 0.0

    def along(self, q: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Smallest box distance and finger distance [m] per sample, shapes (N,), (N,)."""
        out = np.empty((len(q), 2))
        tf = tf_of(T[0])
        for i in range(len(q)):
            if i and not np.array_equal(T[i], T[i - 1]):
                tf = tf_of(T[i])
            out[i] = self._distances(q[i], tf)
        return out[:, 0], out[:, 1]


# ------------------------------------------------------------------- contacts
def choose_pairs(
    scene: Scene, checker: FingerCollision, n_pairs: int, min_dist_m: float, seed: int
) -> list[Pair]:
    """Contacts feasible at the start pose and at the moving box's landing pose."""
    hand, box = scene.hand, scene.box
    f = hand.finger(FINGER)
    sample = box.sample_surface(SAMPLE_SPACING_M)
    links = LinkClearance(hand, FINGER, box)
    ok = np.ones(len(sample), bool)
    q_start = np.full((len(sample), f.k), np.nan)
    for motion, t in ((scene.static, 0.0), (scene.moving, scene.params.duration_s)):
        man = build_manifold(f, sample, motion, np.array([t]))
        idx = np.nonzero(man.usable(CONTACT_MARGIN_RAD)[0])[0]
        T = motion.pose(np.array([t]))[0]
        c_obj = sample.points[idx] + f.tip_radius * sample.normals[idx]
        res = f.ik(c_obj @ T[:3, :3].T + T[:3, 3], man.q[0, idx], tol_m=1e-7)
        clear = links(hand.to_full(FINGER, res.q, scene.q_hand), T) >= CONTACT_LINK_CLEARANCE_M
        good = np.zeros(len(sample), bool)
        good[idx] = res.success & clear
        good[idx] &= np.array([checker.valid_at(q, T) for q in res.q], bool)
        ok &= good
        if t == 0.0:
            q_start[idx] = res.q
    cand = np.nonzero(ok)[0].tolist()
    combos = [
        (i, j)
        for i, j in itertools.permutations(cand, 2)
        if np.linalg.norm(sample.points[i] - sample.points[j]) >= min_dist_m
    ]
    if len(combos) < n_pairs:
        raise SystemExit(f"only {len(combos)} contact pairs in this scene, {n_pairs} wanted")
    rng = np.random.default_rng(seed)
    picks = [combos[c] for c in rng.choice(len(combos), size=n_pairs, replace=False)]
    return [
        Pair(
            sample.points[i],
            sample.normals[i],
            sample.points[j],
            sample.normals[j],
            q_start[i].copy(),
            q_start[j].copy(),
        )
        for i, j in picks
    ]


def rule_agreement(scene: Scene, checker: FingerCollision, n: int, seed: int) -> float:
    """Fraction of random configurations on which both implementations of the rule agree."""
    f = scene.hand.finger(FINGER)
    qs = np.random.default_rng(seed).uniform(f.lower, f.upper, (n, f.k))
    return float(np.mean([checker.valid_static(q) == checker.valid_at(q, scene.T0) for q in qs]))


# ----------------------------------------------------------------- planners
def run_ours(
    scene: Scene, motion: ObjectMotion, pair: Pair
) -> tuple[float, RegraspResult | None, str]:
    """Wall time [ms], the result (None on failure) and the failure message."""

    def q_hand(times: np.ndarray) -> np.ndarray:
        return np.broadcast_to(scene.q_hand, (len(times), scene.q_hand.size)).copy()

    t0 = time.perf_counter()
    try:
        res = plan_regrasp(
            scene.hand,
            scene.box,
            motion,
            FINGER,
            0.0,
            pair.P,
            pair.n_P,
            pair.Q,
            pair.n_Q,
            pair.q_P,
            q_hand,
            params=scene.params,
        )
    except RegraspError as exc:
        return 1e3 * (time.perf_counter() - t0), None, str(exc)
    return 1e3 * (time.perf_counter() - t0), res, ""


class _AttemptLog(logging.Handler):
    """Collects the reasons plan_regrasp logs for each failed attempt."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.reasons: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        msg = record.getMessage()
        if "attempt failed" in msg:
            self.reasons.append(msg.split(": ", 1)[1])


def _cause(reason: str) -> str:
    """A short category for one failed attempt's reason."""
    why = reason.split(": ", 1)[-1]
    hit = re.search(r"Coal check failed \((\S+) (\S+) vs ([^\s:]+)", why)
    if hit:
        return f"Coal: {hit.group(2)} vs {hit.group(3)}"
    hit = re.search(r"joint (\S+) would move", why)
    if hit:
        return f"velocity limit {hit.group(1)}"
    if why.startswith("IK cannot follow"):
        return "IK cannot reach the path"
    if why.startswith("the waypoint curve keeps only"):
        return "waypoint curve under the surface"
    return why[:40]


def failure_causes(
    scene: Scene, motion: ObjectMotion, pairs: list[Pair]
) -> tuple[Counter[str], Counter[str]]:
    """Re-run failed pairs with plan_regrasp's debug log captured (not timed).

    Returns the causes of every failed attempt, and of the first attempt (the default
    parameters) alone.
    """
    logger = logging.getLogger("regrasp_pin.planning.regrasp")
    handler = _AttemptLog()
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    first: Counter[str] = Counter()
    all_causes: Counter[str] = Counter()
    try:
        for pair in pairs:
            handler.reasons.clear()
            run_ours(scene, motion, pair)
            if handler.reasons:
                first[_cause(handler.reasons[0])] += 1
            all_causes.update(_cause(r) for r in handler.reasons)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    return all_causes, first


def print_causes(label: str, n_failed: int, causes: tuple[Counter[str], Counter[str]]) -> None:
    every, first = causes
    print(
        f"ours failed on {n_failed} pairs ({label}); causes of all "
        f"{sum(every.values())} failed attempts: "
        + ", ".join(f"{k} {v}" for k, v in every.most_common())
    )
    print(
        "  first attempt (default parameters): "
        + ", ".join(f"{k} {v}" for k, v in first.most_common())
    )


@dataclass
class OmplRun:
    ok: bool
    plan_ms: float
    simplify_ms: float
    q: np.ndarray | None  # (S, k) simplified path [rad]


def run_ompl(
    scene: Scene, valid: Callable[[np.ndarray], bool], pair: Pair, time_limit_s: float
) -> OmplRun:
    f = scene.hand.finger(FINGER)
    space = ob.RealVectorStateSpace(f.k)
    bounds = ob.RealVectorBounds(f.k)
    for j in range(f.k):
        bounds.setLow(j, float(f.lower[j]))
        bounds.setHigh(j, float(f.upper[j]))
    space.setBounds(bounds)
    ss = og.SimpleSetup(space)
    q = np.empty(f.k)
    k = f.k

    def is_valid(state) -> bool:
        for j in range(k):
            q[j] = state[j]
        return valid(q)

    ss.setStateValidityChecker(is_valid)
    start, goal = space.allocState(), space.allocState()
    for j in range(k):
        start[j] = float(pair.q_P[j])
        goal[j] = float(pair.q_Q[j])
    ss.setStartAndGoalStates(start, goal)
    ss.setPlanner(og.RRTConnect(ss.getSpaceInformation()))
    ss.setup()
    t0 = time.perf_counter()
    solved = ss.solve(time_limit_s)
    t1 = time.perf_counter()
    if not (solved and ss.haveExactSolutionPath()):
        return OmplRun(False, 1e3 * (t1 - t0), 0.0, None)
    ss.simplifySolution()
    t2 = time.perf_counter()
    path = ss.getSolutionPath()
    qs = np.array([[path.getState(i)[j] for j in range(k)] for i in range(path.getStateCount())])
    return OmplRun(True, 1e3 * (t1 - t0), 1e3 * (t2 - t1), qs)


# ------------------------------------------------------------------ re-check
@dataclass
class Check:
    length_rad: float
    min_clearance_m: float  # away from the endpoints
    touches: bool  # closer than TOUCH_M away from the endpoints
    penetrates: bool  # breaks the validity rule somewhere
    worst_m: float  # smallest box distance anywhere [m]


def densify_linear(
    times: np.ndarray, q: np.ndarray, motion: ObjectMotion
) -> tuple[np.ndarray, np.ndarray]:
    """Piecewise-linear ``q`` at <= CHECK_STEP_RAD per joint and per object rotation."""
    R = Rotation.from_matrix(motion.pose(times)[:, :3, :3])
    turn = (R[:-1].inv() * R[1:]).magnitude()
    step = np.maximum(np.abs(np.diff(q, axis=0)).max(axis=1), turn)
    n = np.maximum(1, np.ceil(step / CHECK_STEP_RAD - 1e-12)).astype(int)
    seg = np.repeat(np.arange(len(n)), n)
    frac = np.concatenate([np.arange(m) / m for m in n])
    t_d = np.append(times[seg] + frac * (times[seg + 1] - times[seg]), times[-1])
    q_d = np.vstack([q[seg] + frac[:, None] * (q[seg + 1] - q[seg]), q[-1:]])
    return t_d, q_d


def timed_joint_path(
    q: np.ndarray, duration_s: float, rate_rad_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """A joint-space polyline traversed in ``duration_s`` with minimum-jerk progress.

    Uniform time samples, dense enough for <= CHECK_STEP_RAD per joint step (the
    minimum-jerk peak speed is 1.875 L / duration) and per object rotation step.
    """
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
    n = int(np.ceil(max(1.875 * arc[-1], abs(rate_rad_s) * duration_s) / CHECK_STEP_RAD)) + 1
    tau = np.linspace(0.0, 1.0, n + 1)
    s = minimum_jerk(tau) * arc[-1]
    return tau * duration_s, np.column_stack([np.interp(s, arc, qj) for qj in q.T])


def recheck(
    scene: Scene,
    checker: FingerCollision,
    motion: ObjectMotion,
    times: np.ndarray,
    q_dense: np.ndarray,
    pair: Pair,
    end_zone_m: float,
) -> Check:
    f = scene.hand.finger(FINGER)
    T = motion.pose(times)
    d_box, d_ff = checker.along(q_dense, T)
    tip_obj = np.einsum("nji,nj->ni", T[:, :3, :3], f.fk(q_dense) - T[:, :3, 3])
    away = np.ones(len(times), bool)
    for c, n in ((pair.P, pair.n_P), (pair.Q, pair.n_Q)):
        away &= np.linalg.norm(tip_obj - (c + f.tip_radius * n), axis=1) > end_zone_m
    mid = float(d_box[away].min()) if away.any() else np.inf
    return Check(
        length_rad=float(np.linalg.norm(np.diff(q_dense, axis=0), axis=1).sum()),
        min_clearance_m=mid,
        touches=mid < TOUCH_M,
        penetrates=bool((d_box < -PENETRATION_TOL_M).any() or (d_ff < 0.0).any()),
        worst_m=float(d_box.min()),
    )


# -------------------------------------------------------------------- report
def med(x: Sequence[float]) -> float:
    return float(np.median(x)) if len(x) else float("nan")


HEADER = (
    f"{'planner':<27}{'ok':>6}  {'median time [ms]':>28}  {'length [rad]':>19}"
    f"  {'min clr [mm]':>12}  {'touch':>6}  {'pen':>6}"
)


def row(label: str, n_ok: int, n: int, t_ms: str, checks: list[Check]) -> str:
    lengths = [c.length_rad for c in checks]
    rng = f"[{min(lengths):.2f}-{max(lengths):.2f}]" if lengths else ""
    clear = min((c.min_clearance_m for c in checks), default=np.nan)
    m = len(checks)
    touch = f"{sum(c.touches for c in checks)}/{m}"
    pen = f"{sum(c.penetrates for c in checks)}/{m}"
    return (
        f"{label:<27}{n_ok:>3}/{n:<2}  {t_ms:>28}  {med(lengths):>7.2f} {rng:>11}"
        f"  {1e3 * clear:>12.2f}  {touch:>6}  {pen:>6}"
    )


@dataclass
class OursRuns:
    """Our planner on every pair: timings, first-run results, determinism."""

    times_ms: list[float]
    results: list[RegraspResult | None]
    stages: dict[str, list[float]]
    deterministic: bool


def installed_backends() -> list[str]:
    """The IK backends to time: numpy, and numba when it is installed."""
    return [b for b in IK_BACKENDS if b == "numpy" or numba_available()]


def time_ours(
    scene: Scene, motion: ObjectMotion, pairs: list[Pair], reps: int
) -> dict[str, OursRuns]:
    """Our planner on every pair, ``reps`` timed runs, on each IK backend available
    (numpy, then numba when installed), the backends' runs interleaved run by run so
    that both see the same machine load."""
    backends = installed_backends()
    runs = {b: OursRuns([], [], {}, True) for b in backends}
    previous = ik_backend()
    try:
        for pair in pairs:
            for r in range(reps):
                for b in backends:
                    set_ik_backend(b)
                    t_ms, res, _ = run_ours(scene, motion, pair)
                    _record(runs[b], r, t_ms, res)
    finally:
        set_ik_backend(previous)
    return runs


def _record(runs: OursRuns, r: int, t_ms: float, res: RegraspResult | None) -> None:
    runs.times_ms.append(t_ms)
    if r == 0:
        runs.results.append(res)
        if res is not None:
            for k, v in res.stage_ms.items():
                runs.stages.setdefault(k, []).append(v)
        return
    first = runs.results[-1]
    if res is None or first is None:
        runs.deterministic &= res is None and first is None
    else:
        runs.deterministic &= bool(np.array_equal(res.q, first.q))


def backend_rows(all_runs: dict[str, OursRuns], label: str) -> None:
    """Our time on each backend against the 25 ms target, and how far the numba
    backend's plans are from numpy's (same pairs, same parameters)."""
    base = all_runs["numpy"]
    for b, runs in all_runs.items():
        line = f"ours, IK on {b:<6} median {med(runs.times_ms):5.1f} ms (target <= 25 ms)"
        if b != "numpy":
            both = [
                (x, y)
                for x, y in zip(base.results, runs.results, strict=True)
                if x is not None and y is not None
            ]
            same_ok = sum(
                (x is None) == (y is None) for x, y in zip(base.results, runs.results, strict=True)
            )
            dq = [
                float(np.abs(x.q - y.q).max()) if x.q.shape == y.q.shape else np.inf
                for x, y in both
            ]
            line += (
                f"; {med(runs.times_ms) / med(base.times_ms):.2f}x numpy's time; "
                f"same outcome on {same_ok}/{len(base.results)} pairs, joint paths within "
                f"{max(dq, default=0.0):.1e} rad of numpy's"
            )
        print(line)
    if len(all_runs) == 1:
        print(f"  ({label}: numba not installed, pip install -e '.[fast]' for its row)")


def print_ours_notes(
    scene: Scene, motion: ObjectMotion, label: str, pairs: list[Pair], ours: OursRuns
) -> None:
    tries = [len(r.attempts) + 1 for r in ours.results if r is not None]
    print(
        "ours median stage times [ms]: "
        + ", ".join(f"{k} {med(v):.1f}" for k, v in ours.stages.items())
        + f"; candidates tried per success: median {med(tries):.0f}, max "
        + (f"{max(tries)}" if tries else "-")
        + f"; identical over repeats: {ours.deterministic}"
    )
    failed = [p for p, r in zip(pairs, ours.results, strict=True) if r is None]
    if failed:
        print_causes(label, len(failed), failure_causes(scene, motion, failed))


def bench_static(
    scene: Scene, checker: FingerCollision, pairs: list[Pair], args: argparse.Namespace
) -> list[list[OmplRun]]:
    """Both planners on the static box; returns OMPL's runs (reused by the moving case)."""
    reps, end_zone = args.repeats, 1e-3 * args.end_zone_mm
    all_ours = time_ours(scene, scene.static, pairs, reps)
    ours = all_ours["numpy"]
    om_runs = [
        [run_ompl(scene, checker.valid_static, pair, args.time_limit) for _ in range(reps)]
        for pair in pairs
    ]
    ok_runs = [run for runs in om_runs for run in runs if run.ok]

    ours_checks: list[Check] = []
    om_checks: list[Check] = []
    straight = [float(np.linalg.norm(p.q_Q - p.q_P)) for p in pairs]
    for i, (pair, res, runs) in enumerate(zip(pairs, ours.results, om_runs, strict=True)):
        line = (
            f"  pair {i:2d} |PQ| {1e3 * np.linalg.norm(pair.Q - pair.P):4.1f} mm, "
            f"|q_Q-q_P| {straight[i]:.2f} rad"
        )
        if res is not None:
            c = recheck(
                scene,
                checker,
                scene.static,
                *densify_linear(res.times_s, res.q, scene.static),
                pair,
                end_zone,
            )
            ours_checks.append(c)
            m = res.params.m if res.params else "?"
            line += (
                f" | ours {c.length_rad:.2f} rad, clr {1e3 * c.min_clearance_m:.2f} mm, "
                f"m={m}, lands {np.abs(res.q[-1] - pair.q_Q).max():.0e} rad from q_Q"
            )
        else:
            line += " | ours FAILED"
        for r, run in enumerate(runs):
            if run.q is not None:
                t_path = np.linspace(0.0, scene.params.duration_s, len(run.q))
                c = recheck(
                    scene,
                    checker,
                    scene.static,
                    *densify_linear(t_path, run.q, scene.static),
                    pair,
                    end_zone,
                )
                om_checks.append(c)
                if r == 0:
                    line += (
                        f" | OMPL {c.length_rad:.2f} rad, clr "
                        f"{1e3 * c.min_clearance_m:.2f} mm, worst {1e3 * c.worst_m:.2f} mm"
                    )
        if args.verbose:
            print(line)

    plan = [r.plan_ms for r in ok_runs]
    simp = [r.simplify_ms for r in ok_runs]
    total = [r.plan_ms + r.simplify_ms for r in ok_runs]
    n = len(pairs)
    print(
        f"\nstatic box: same q_P -> q_Q for both; straight joint-space distance "
        f"|q_Q - q_P| median {med(straight):.2f} rad"
    )
    print(HEADER)
    print(row("ours (plan_regrasp)", len(ours_checks), n, f"{med(ours.times_ms):.1f}", ours_checks))
    print(
        row(
            "OMPL RRTConnect+simplify",
            len(ok_runs),
            n * reps,
            f"{med(plan):.1f} + {med(simp):.1f} = {med(total):.1f}",
            om_checks,
        )
    )
    ours_len = med([c.length_rad for c in ours_checks])
    om_len = med([c.length_rad for c in om_checks])
    print(
        f"ours / OMPL: time {med(ours.times_ms) / med(total):.2f}x (target <= 0.5), "
        f"length {ours_len / om_len:.2f}x (target <= 0.6)"
    )
    print_ours_notes(scene, scene.static, "static box", pairs, ours)
    backend_rows(all_ours, "static box")
    return om_runs


def bench_moving(
    scene: Scene,
    checker: FingerCollision,
    pairs: list[Pair],
    om_runs: list[list[OmplRun]],
    args: argparse.Namespace,
) -> None:
    """Ours plans with the motion; OMPL's static-box paths are replayed on the moving box."""
    duration = scene.params.duration_s
    rate = np.radians(args.rate_deg_s)
    end_zone = 1e-3 * args.end_zone_mm
    all_ours = time_ours(scene, scene.moving, pairs, args.repeats)
    ours = all_ours["numpy"]
    ours_checks = [
        recheck(
            scene,
            checker,
            scene.moving,
            *densify_linear(res.times_s, res.q, scene.moving),
            pair,
            end_zone,
        )
        for pair, res in zip(pairs, ours.results, strict=True)
        if res is not None
    ]
    om_checks = [
        recheck(
            scene, checker, scene.moving, *timed_joint_path(run.q, duration, rate), pair, end_zone
        )
        for pair, runs in zip(pairs, om_runs, strict=True)
        for run in runs
        if run.q is not None
    ]
    n = len(pairs)
    print(
        f"\nmoving box: {args.rate_deg_s:g} deg/s about the palm y axis through its centre "
        f"for the {duration:g} s regrasp; OMPL = its static-box paths with ours' timing"
    )
    print(HEADER)
    print(row("ours (plan_regrasp)", len(ours_checks), n, f"{med(ours.times_ms):.1f}", ours_checks))
    print(
        row(
            "OMPL (ignores the motion)",
            len(om_checks),
            n * args.repeats,
            "(static plans)",
            om_checks,
        )
    )
    print_ours_notes(scene, scene.moving, "moving box", pairs, ours)
    backend_rows(all_ours, "moving box")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=tuple(SCENES), default="upright")
    parser.add_argument("--pairs", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="seeds the pairs and OMPL")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per pair")
    parser.add_argument("--time-limit", type=float, default=1.0, help="OMPL solve limit [s]")
    parser.add_argument("--min-distance-mm", type=float, default=20.0, help="|PQ| at least")
    parser.add_argument("--end-zone-mm", type=float, default=5.0)
    parser.add_argument("--rate-deg-s", type=float, default=20.0, help="moving box")
    parser.add_argument("--verbose", action="store_true", help="one line per pair")
    args = parser.parse_args()
    print(machine_line())
    if ob is None:
        print(
            "OMPL is not installed: this benchmark compares against it. Install the "
            "'bench' extra (pip install -e '.[bench]', PyPI 'ompl' >= 2.0). Skipping."
        )
        return
    ou.setLogLevel(ou.LOG_ERROR)
    ou.RNG.setSeed(args.seed + 1)  # OMPL wants a seed > 0; set once, before any planner

    scene = make_scene(args.scene, args.rate_deg_s)
    checker = FingerCollision(scene.hand, FINGER, scene.box, scene.q_hand, scene.T0)
    pairs = choose_pairs(scene, checker, args.pairs, 1e-3 * args.min_distance_mm, args.seed)
    size, centre, tilt = SCENES[args.scene]
    dist = [1e3 * np.linalg.norm(p.Q - p.P) for p in pairs]
    print(
        f"Allegro {FINGER}; box {' x '.join(f'{1e3 * s:g}' for s in size)} mm, centre "
        f"({', '.join(f'{1e3 * c:g}' for c in centre)}) mm in the palm frame, tilted "
        f"{tilt:g} deg; {len(pairs)} pairs (seed {args.seed}), |PQ| {min(dist):.0f}-"
        f"{max(dist):.0f} mm; {args.repeats} timed runs per pair and planner"
    )
    print(
        f"validity (both): finger geometries >= -{1e3 * PENETRATION_TOL_M:g} mm from the box, "
        f"not touching another finger; OMPL checker and re-check agree on "
        f"{100 * rule_agreement(scene, checker, 2000, args.seed):.1f}% of 2000 random q"
    )
    print(
        f"re-check at {1e3 * CHECK_STEP_RAD:g} mrad; min clr / touch (< {1e3 * TOUCH_M:g} mm) "
        f"with the tip > {args.end_zone_mm:g} mm from P and Q; pen = rule broken anywhere"
    )

    # warm-up (caches, first calls, numba's compiled kernels), not timed
    previous = ik_backend()
    for b in installed_backends():
        set_ik_backend(b)
        run_ours(scene, scene.static, pairs[0])
    set_ik_backend(previous)
    run_ompl(scene, checker.valid_static, pairs[0], args.time_limit)

    om_runs = bench_static(scene, checker, pairs, args)
    bench_moving(scene, checker, pairs, om_runs, args)
    # nanobind reports OMPL objects still alive at interpreter exit as leaks
    del om_runs
    gc.collect()


if __name__ == "__main__":
    main()
