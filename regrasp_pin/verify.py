"""Dense, exact verification of one finger's motion with Coal (section 2.3 of the issue).

The check every planned regrasp must pass before it is returned. The motion between
two consecutive samples of a plan is linear interpolation of the full hand
configuration ``q`` and, for the object pose ``T_palm_object``, linear interpolation of
the position and slerp of the rotation (exactly what :class:`~regrasp_pin.motion.ObjectMotion`
does). :func:`verify_finger_motion` re-samples that motion densely (:func:`densify`)
and, at every dense sample, checks with Coal's exact distances:

* every collision geometry of the moving finger against the object: the fingertip
  geometries (``finger.tip_geometry_ids``) at least ``tip_clearance_m(t) -
  penetration_tol_m`` away, the other geometries at least ``link_clearance_m -
  penetration_tol_m``;
* every geometry of the moving finger against every geometry of every other finger
  (the palm excluded) at least ``finger_clearance_m``;
* the moving finger's joints within their limits (to :data:`JOINT_LIMIT_TOL_RAD`).

Broad phase. Every geometry is enclosed in a capsule (a segment and a radius: the axis
of a cylinder, the longest axis of a box, a point for a sphere). Two lower bounds on
the true distance are evaluated for all samples at once with numpy:

* geometry vs object: ``max_f min(n_f . a - o_f, n_f . b - o_f) - r`` for the capsule
  ``(a, b, r)`` in the object frame, with the object's face planes ``n_f . x = o_f``
  (the distance to a convex polytope is at least the distance to any of its face
  planes, and a segment is at least as far from a plane as the nearer endpoint);
* geometry vs geometry: segment-to-segment distance minus both radii.

Coal is called only where a bound does not prove the requirement with
:data:`BROAD_PHASE_MARGIN_M` to spare, so every pass/fail decision near the threshold
is made on an exact Coal distance. The reported minima are exact too: after the
mandatory queries, the remaining candidates are queried in increasing order of their
lower bound until the bound exceeds the smallest exact distance found
(branch and bound, capped at :data:`MAX_MINIMUM_QUERIES` extra queries per minimum).
"""

from __future__ import annotations

import logging
import math
import time
import weakref
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
from scipy.spatial.transform import Rotation

from ._validate import as_array, positive
from .exceptions import InputError, VerificationError
from .hand import Finger, Hand
from .kinematics import FingerChain
from .motion import ObjectMotion
from .objects import ConvexObject

__all__ = [
    "BROAD_PHASE_MARGIN_M",
    "Failure",
    "VerificationReport",
    "densify",
    "verify_finger_motion",
]

#: Coal is called wherever a lower bound is below the requirement plus this [m].
BROAD_PHASE_MARGIN_M = 0.005
#: Tolerance on the joint limits [rad].
JOINT_LIMIT_TOL_RAD = 1e-9
#: At most this many failures are kept in a report (all are counted).
MAX_REPORTED_FAILURES = 20
#: Extra Coal queries allowed per reported minimum (beyond the mandatory ones).
MAX_MINIMUM_QUERIES = 256
#: Densification bounds the object's translation per step by max_joint_step_rad x this [m].
OBJECT_LEVER_M = 0.1
#: Refuse to verify more dense samples than this (a bad step size or a huge motion).
MAX_DENSE_SAMPLES = 2_000_000

_MAX_DEPTH_M = 1.0  # a Coal distance below -this is an EPA failure, not a depth
logger = logging.getLogger(__name__)

_KINDS = ("tip-object", "link-object", "finger-finger")
_TIP, _LINK, _FF = 0, 1, 2


@dataclass(frozen=True)
class Failure:
    """One failed check: a run of consecutive dense samples where one check fails.

    Attributes:
        time_s: Time of the worst sample of the run [s].
        kind: ``"tip-object"``, ``"link-object"``, ``"finger-finger"`` or ``"joint-limit"``.
        detail: What failed: ``"<geometry> vs object"``, ``"<geometry> vs <geometry>"``
            or the joint name.
        value: The worst value of the run: a distance [m] (negative = penetration
            depth) or a joint angle [rad].
        required: The requirement it violates: the minimum distance [m] or the joint
            limit that was crossed [rad].
        t_first_s: First time of the run [s].
        t_last_s: Last time of the run [s].
        n_samples: Number of dense samples in the run.
    """

    time_s: float
    kind: str
    detail: str
    value: float
    required: float
    t_first_s: float = math.nan
    t_last_s: float = math.nan
    n_samples: int = 1

    def describe(self) -> str:
        """One line: kind, detail, value vs requirement and the time span."""
        if self.kind == "joint-limit":
            what = f"{self.value:.6f} rad beyond the limit {self.required:.6f} rad"
        else:
            what = f"distance {self.value * 1e3:.4f} mm < required {self.required * 1e3:.4f} mm"
        return (f"{self.kind} {self.detail}: {what} at t={self.time_s:.4f} s "
                f"(failing from {self.t_first_s:.4f} to {self.t_last_s:.4f} s)")


@dataclass(frozen=True)
class VerificationReport:
    """Result of :func:`verify_finger_motion`.

    Attributes:
        ok: True when every check passed at every dense sample.
        n_samples: Number of dense samples checked.
        n_distance_queries: Number of Coal distance calls made.
        min_tip_object_m: Smallest fingertip-object distance [m] (inf if none checked).
        min_link_object_m: Smallest distance of the finger's other geometries to the
            object [m] (inf if the finger has none).
        min_finger_finger_m: Smallest distance to another finger's geometry [m] (inf
            if there is no other finger).
        min_clearance_margin_m: Smallest ``distance - required`` over all distance
            checks [m] (negative when a check failed), where ``required`` is the
            threshold applied (clearance minus ``penetration_tol_m`` for object checks).
        joint_limits_ok: True when the finger's joints stayed within their limits.
        failures: The first :data:`MAX_REPORTED_FAILURES` failures, by start time.
        n_failures: Number of failures (runs of failing samples per check), all counted.
        time_s: Time of the worst failure [s] (the most negative distance margin, else
            the largest joint-limit excess); None when ``ok``.
        max_tip_step_m: Largest step of the fingertip centre relative to the object
            between consecutive dense samples [m].
        minima_exact: True when the four minima above are exact Coal distances. A
            minimum below its requirement plus :data:`BROAD_PHASE_MARGIN_M` is always
            exact; a larger one may be a lower bound (False here) when
            :data:`MAX_MINIMUM_QUERIES` extra queries did not settle it.
        finger: Name of the finger verified.
        elapsed_s: Wall-clock time of the verification [s].
    """

    ok: bool
    n_samples: int
    n_distance_queries: int
    min_tip_object_m: float
    min_link_object_m: float
    min_finger_finger_m: float
    min_clearance_margin_m: float
    joint_limits_ok: bool
    failures: tuple[Failure, ...]
    n_failures: int = 0
    time_s: float | None = None
    max_tip_step_m: float = 0.0
    minima_exact: bool = True
    finger: str | None = None
    elapsed_s: float = 0.0

    @property
    def worst_failure(self) -> Failure | None:
        """The kept failure at :attr:`time_s` with the smallest margin, or None."""
        if not self.failures:
            return None
        return min(self.failures, key=_severity)

    def raise_if_failed(self, finger: str | None = None) -> None:
        """Raise if the verification failed.

        Args:
            finger: Finger name for the message; default :attr:`finger`.

        Raises:
            VerificationError: naming the finger, the time of the worst failure and
                what failed (kind, geometries or joint, value vs requirement); its
                ``partial`` attribute holds this report.
        """
        if self.ok:
            return
        worst = self.worst_failure
        name = finger if finger is not None else self.finger
        lines = [worst.describe()] if worst is not None else []
        lines += [f.describe() for f in self.failures if f is not worst][:4]
        extra = self.n_failures - min(len(lines), self.n_failures)
        reason = f"{self.n_failures} failed check(s) in {self.n_samples} dense samples: "
        reason += "; ".join(lines) + (f"; and {extra} more" if extra > 0 else "")
        raise VerificationError(reason, finger=name, time_s=self.time_s, partial=self)


# ---------------------------------------------------------------------- densification
def densify(
    times_s: np.ndarray,
    q_full: np.ndarray,
    T_palm_object: np.ndarray,
    max_joint_step_rad: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Insert samples so that the interpolated motion moves little between samples.

    Each interval ``[t_i, t_i+1]`` is cut into ``n_i`` equal time steps, the smallest
    ``n_i`` such that per step every joint of the hand moves at most
    ``max_joint_step_rad``, the object turns at most ``max_joint_step_rad`` and
    translates at most ``max_joint_step_rad * OBJECT_LEVER_M``. The new samples lie on
    the plan's own interpolation: ``q`` linear, the object position linear and its
    rotation slerped.

    Args:
        times_s: Sample times [s], shape (S,), strictly increasing, S >= 1.
        q_full: Hand configurations [rad], shape (S, nq).
        T_palm_object: Object poses in the palm frame, shape (S, 4, 4).
        max_joint_step_rad: Largest step per joint [rad], > 0.

    Returns:
        ``(times_s (D,), q_full (D, nq), T_palm_object (D, 4, 4))`` with D >= S; the
        original samples are kept.

    Raises:
        InputError: wrong shapes, NaN/inf, times not increasing, poses that are not
            rigid, a non-positive step, or more than :data:`MAX_DENSE_SAMPLES` samples.
    """
    t, q, T, motion = _check_trajectory(times_s, q_full, T_palm_object, None)
    step = positive(max_joint_step_rad, "max_joint_step_rad")
    counts = _step_counts(t, q, T, step)
    return _interpolate(t, q, T, motion, counts)


def _check_trajectory(
    times_s: object, q_full: object, T_palm_object: object, nq: int | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, ObjectMotion | None]:
    t = as_array(times_s, "times_s", (None,))
    if t.size < 1:
        raise InputError("times_s", "is empty", "at least one sample")
    q = as_array(q_full, "q_full", (t.size, nq))
    T = as_array(T_palm_object, "T_palm_object", (t.size, 4, 4))
    if t.size == 1:  # validate the single pose with the same rules as a motion
        ObjectMotion.from_poses(np.array([t[0], t[0] + 1.0]), np.concatenate([T, T]))
        return t, q, T, None
    motion = ObjectMotion.from_poses(t, T)  # checks times and rigid poses
    return t, q, T, motion


def _step_counts(t: np.ndarray, q: np.ndarray, T: np.ndarray, step: float) -> np.ndarray:
    """Number of equal steps per interval, shape (S - 1,) int >= 1."""
    if t.size < 2:
        return np.zeros(0, dtype=np.int64)
    dq = np.max(np.abs(np.diff(q, axis=0)), axis=1) if q.shape[1] else np.zeros(t.size - 1)
    R = T[:, :3, :3]
    angle = Rotation.from_matrix(np.einsum("kji,kjl->kil", R[:-1], R[1:])).magnitude()
    dp = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)
    need = np.maximum.reduce([dq / step, angle / step, dp / (step * OBJECT_LEVER_M)])
    counts = np.maximum(1, np.ceil(need * (1.0 - 1e-12))).astype(np.int64)
    if counts.sum() + 1 > MAX_DENSE_SAMPLES:
        raise InputError("max_joint_step_rad", f"{step:g} rad needs {counts.sum() + 1} samples",
                         f"at most {MAX_DENSE_SAMPLES} dense samples (a larger step)")
    return counts


def _interpolate(
    t: np.ndarray, q: np.ndarray, T: np.ndarray, motion: ObjectMotion | None,
    counts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plan's interpolation at ``counts[i]`` equal steps per interval."""
    if t.size < 2:
        return t.copy(), q.copy(), T.copy()
    idx = np.repeat(np.arange(t.size - 1), counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    frac = (np.arange(idx.size) - start) / np.repeat(counts, counts)
    t_d = np.append(t[idx] + frac * (t[idx + 1] - t[idx]), t[-1])
    q_d = np.vstack([q[idx] + frac[:, None] * (q[idx + 1] - q[idx]), q[-1:]])
    T_d = motion.pose(t_d)
    T_d[0], T_d[-1] = T[0], T[-1]
    return t_d, q_d, T_d


# ---------------------------------------------------------------------- geometry tables
@dataclass(frozen=True, eq=False)
class _Geometry:
    """One collision geometry: how to place it in batch, and two convex bounds of it.

    The capsule ``(seg_a, seg_b, radius)`` contains the shape. The support function
    of the shape about ``centre`` in a unit direction ``u`` (geometry frame) is
    ``sum_i half_i |u_i| + axial |u_z| + radial sqrt(1 - u_z^2) + round``: a box
    (``half``), a cylinder (``axial`` = half length, ``radial`` = radius), a capsule
    (``axial``, ``round``), a sphere (``round``); any other shape gets the sphere of
    its local AABB.
    """

    gid: int
    name: str
    shape: Any  # coal.CollisionGeometry
    chain: FingerChain
    R_frame_geom: np.ndarray  # (3, 3)
    p_frame_geom: np.ndarray  # (3,)
    seg_a: np.ndarray  # (3,) capsule segment start, geometry frame [m]
    seg_b: np.ndarray  # (3,) capsule segment end
    radius: float  # capsule radius [m]
    centre: np.ndarray  # (3,) centre of symmetry, geometry frame [m]
    support: np.ndarray  # (6,) half_x, half_y, half_z, axial, radial, round [m]


_TABLES: weakref.WeakKeyDictionary[Hand, dict[Any, Any]] = weakref.WeakKeyDictionary()


def _geometry(hand: Hand, gid: int) -> _Geometry:
    """The (cached) batch description of collision geometry ``gid`` of the hand."""
    table = _TABLES.setdefault(hand, {})
    if gid not in table:
        model = hand.model
        gobj = hand.collision_model.geometryObjects[gid]
        frame_name = model.frames[int(gobj.parentFrame)].name
        fid = model.getFrameId(frame_name)
        if int(model.frames[fid].parentJoint) != int(gobj.parentJoint):  # ambiguous name
            frame_name = model.names[int(gobj.parentJoint)]
            fid = model.getFrameId(frame_name)
        chain = table.get(("chain", frame_name))
        if chain is None:
            chain = table[("chain", frame_name)] = FingerChain(model, frame_name)
        M = model.frames[fid].placement.inverse() * gobj.placement  # frame -> geometry
        a, b, r = _capsule(gobj.geometry)
        centre, support = _support_parameters(gobj.geometry)
        table[gid] = _Geometry(
            gid=gid, name=gobj.name, shape=gobj.geometry, chain=chain,
            R_frame_geom=M.rotation.copy(), p_frame_geom=M.translation.copy(),
            seg_a=a, seg_b=b, radius=r, centre=centre, support=support,
        )
    return table[gid]


def _capsule(shape: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """A capsule ``(a, b, r)`` that contains the shape, in the shape's frame."""
    zero = np.zeros(3)
    if isinstance(shape, coal.Sphere):
        return zero, zero, float(shape.radius)
    if isinstance(shape, (coal.Cylinder, coal.Capsule)):
        h = np.array([0.0, 0.0, float(shape.halfLength)])
        return -h, h, float(shape.radius)
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide, dtype=float)
        i = int(np.argmax(half))
        h = np.zeros(3)
        h[i] = half[i]
        return -h, h, float(np.linalg.norm(np.delete(half, i)))
    shape.computeLocalAABB()
    c = np.asarray(shape.aabb_center, dtype=float)
    return c, c.copy(), float(shape.aabb_radius)


def _support_parameters(shape: Any) -> tuple[np.ndarray, np.ndarray]:
    """Centre and support parameters (see :class:`_Geometry`) of a Coal shape."""
    out = np.zeros(6)
    centre = np.zeros(3)
    if isinstance(shape, coal.Box):
        out[:3] = np.asarray(shape.halfSide, dtype=float)
    elif isinstance(shape, coal.Cylinder):
        out[3], out[4] = float(shape.halfLength), float(shape.radius)
    elif isinstance(shape, coal.Capsule):
        out[3], out[5] = float(shape.halfLength), float(shape.radius)
    elif isinstance(shape, coal.Sphere):
        out[5] = float(shape.radius)
    else:
        shape.computeLocalAABB()
        centre = np.asarray(shape.aabb_center, dtype=float).copy()
        out[5] = float(shape.aabb_radius)
    return centre, out


def _support(u_local: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Support function values ``(...)`` for unit directions ``(..., 3)`` in the geometry
    frames and support parameters ``(..., 6)`` (broadcast)."""
    uz = np.abs(u_local[..., 2])
    return (np.sum(params[..., :3] * np.abs(u_local), axis=-1) + params[..., 3] * uz
            + params[..., 4] * np.sqrt(np.maximum(0.0, 1.0 - uz * uz)) + params[..., 5])


def _placements(
    geoms: list[_Geometry], q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Geometry placements in the palm frame: ``R (D, G, 3, 3)``, ``p (D, G, 3)``."""
    D, G = q.shape[0], len(geoms)
    R = np.empty((D, G, 3, 3))
    p = np.empty((D, G, 3))
    poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for j, g in enumerate(geoms):
        key = id(g.chain)
        if key not in poses:
            poses[key] = g.chain.poses(q[:, g.chain.q_indices])
        R_f, p_f = poses[key]
        R[:, j] = R_f @ g.R_frame_geom
        p[:, j] = p_f + R_f @ g.p_frame_geom
    return R, p


# ---------------------------------------------------------------------- lower bounds
def _segment_distance(a1: np.ndarray, b1: np.ndarray, a2: np.ndarray, b2: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Distance between segments ``[a1, b1]`` and ``[a2, b2]``, shapes (N, 3).

    Returns:
        The distances (N,) and the vectors from the nearest point of the second
        segment to that of the first (N, 3).

    Closed form of Ericson, *Real-Time Collision Detection*, 5.1.9 (degenerate
    segments included), vectorized.
    """
    d1, d2, r = (b1 - a1).T, (b2 - a2).T, (a1 - a2).T  # (3, N) rows for speed

    def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    a, e, b = dot(d1, d1), dot(d2, d2), dot(d1, d2)
    c, f = dot(d1, r), dot(d2, r)
    eps = 1e-18
    a_ok, e_ok = a > eps, e > eps
    a_safe, e_safe = np.where(a_ok, a, 1.0), np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.where(denom > eps, denom, 1.0),
                                      0.0, 1.0), 0.0)
    s = np.where(a_ok, s, 0.0)
    t = np.where(e_ok, (b * s + f) / e_safe, 0.0)
    # t outside [0, 1] (or the second segment is a point): clamp t and recompute s
    redo = (t < 0.0) | (t > 1.0) | ~e_ok
    t = np.clip(t, 0.0, 1.0)
    s = np.where(redo, np.where(a_ok, np.clip((t * b - c) / a_safe, 0.0, 1.0), 0.0), s)
    diff = r + s * d1 - t * d2
    return np.sqrt(dot(diff, diff)), diff.T


def _object_lower_bound(
    obj: ConvexObject, c_obj: np.ndarray, R_obj_geom: np.ndarray, params: np.ndarray
) -> np.ndarray:
    """Lower bound on the signed distance from geometries to the object.

    ``max_f (n_f . c - o_f - h(n_f))`` over the object's face planes ``n_f . x = o_f``,
    with ``c`` the geometry's centre and ``h`` its support function: the geometry lies
    entirely beyond that far in front of each face plane, and the object entirely
    behind it. Valid under penetration too (moving the geometry by the bound's
    opposite along ``n_f`` separates them).

    Args:
        obj: The object.
        c_obj: Geometry centres in the object frame, (D, G, 3) [m].
        R_obj_geom: Geometry orientations in the object frame, (D, G, 3, 3).
        params: Support parameters, (G, 6).

    Returns:
        Lower bounds (D, G) [m].
    """
    n_local = np.matmul(obj.normals, R_obj_geom)  # rows R^T n_f: (D, G, F, 3)
    h = _support(n_local, params[None, :, None, :])
    return np.max(c_obj @ obj.normals.T - obj.offsets - h, axis=-1)


# ---------------------------------------------------------------------- verification
def verify_finger_motion(
    hand: Hand,
    obj: ConvexObject,
    finger: str,
    times_s: np.ndarray,
    q_full: np.ndarray,
    T_palm_object: np.ndarray,
    *,
    tip_clearance_m: float | np.ndarray,
    link_clearance_m: float = 0.0,
    finger_clearance_m: float = 0.0005,
    penetration_tol_m: float = 5e-5,
    max_joint_step_rad: float = 1e-3,
    max_tip_step_m: float | None = None,
) -> VerificationReport:
    """Check one finger's motion against the object, the other fingers and its limits.

    The motion is the plan's interpolation of the samples (``q`` linear, object pose
    linear + slerp), re-sampled by :func:`densify` with ``max_joint_step_rad`` (and,
    if ``max_tip_step_m`` is given, further until the fingertip centre moves at most
    that far relative to the object between samples, measured on chords).
    ``tip_clearance_m`` is interpolated linearly in time. At every dense sample, with
    exact Coal distances where the broad phase does not prove the requirement (see
    the module docstring):

    * fingertip geometries vs object >= ``tip_clearance_m(t) - penetration_tol_m``;
    * the finger's other geometries vs object >= ``link_clearance_m - penetration_tol_m``;
    * the finger's geometries vs every other finger's geometries >= ``finger_clearance_m``;
    * the finger's joints within ``[lower, upper]`` to :data:`JOINT_LIMIT_TOL_RAD`.

    Args:
        hand: The hand.
        obj: The object (its frame at the centre of mass).
        finger: Name of the moving finger.
        times_s: Sample times [s], shape (S,), strictly increasing.
        q_full: Full hand configurations [rad], shape (S, nq); the other fingers
            follow the object in them.
        T_palm_object: Object poses in the palm frame, shape (S, 4, 4).
        tip_clearance_m: Required fingertip clearance [m], a number or shape (S,), >= 0
            (0 in the lift-off and landing zones, where the tip touches).
        link_clearance_m: Required clearance of the finger's other geometries [m], >= 0.
        finger_clearance_m: Required distance to the other fingers [m], >= 0.
        penetration_tol_m: Tolerance on the object checks [m], >= 0.
        max_joint_step_rad: Largest joint step between dense samples [rad], > 0.
        max_tip_step_m: Optional largest fingertip step relative to the object [m], > 0.

    Returns:
        The :class:`VerificationReport`; call :meth:`VerificationReport.raise_if_failed`
        to turn a failure into a :class:`~regrasp_pin.exceptions.VerificationError`.

    Raises:
        InputError: wrong shapes, NaN/inf, times not strictly increasing, poses that
            are not rigid, negative clearances or tolerances, non-positive steps.
        UnknownNameError: ``finger`` is not a finger of the hand.
    """
    start = time.perf_counter()
    f = hand.finger(finger)
    t, q, T, motion = _check_trajectory(times_s, q_full, T_palm_object, hand.model.nq)
    clr = np.asarray(tip_clearance_m, dtype=float)
    if clr.ndim == 0:
        clr = np.full(t.size, float(positive(float(clr), "tip_clearance_m", allow_zero=True)))
    else:
        clr = as_array(clr, "tip_clearance_m", (t.size,))
        if np.any(clr < 0):
            raise InputError("tip_clearance_m", f"has a negative value {clr.min():g}",
                             "clearances >= 0 [m]")
    link_clr = positive(link_clearance_m, "link_clearance_m", allow_zero=True)
    ff_clr = positive(finger_clearance_m, "finger_clearance_m", allow_zero=True)
    tol = positive(penetration_tol_m, "penetration_tol_m", allow_zero=True)
    step = positive(max_joint_step_rad, "max_joint_step_rad")
    tip_step = None if max_tip_step_m is None else positive(max_tip_step_m, "max_tip_step_m")

    counts = _step_counts(t, q, T, step)
    t_d, q_d, T_d = _interpolate(t, q, T, motion, counts)
    tip_obj = _tip_in_object(f, q_d, T_d)
    if tip_step is not None and t.size > 1:
        for _ in range(4):  # refine on chords until every step is short enough
            steps = np.linalg.norm(np.diff(tip_obj, axis=0), axis=1)
            per = np.maximum.reduceat(steps, np.cumsum(counts) - counts)
            if np.all(per <= tip_step):
                break
            counts = np.maximum(counts, np.ceil(counts * per / tip_step)).astype(np.int64)
            if counts.sum() + 1 > MAX_DENSE_SAMPLES:
                raise InputError("max_tip_step_m", f"{tip_step:g} m needs {counts.sum() + 1} "
                                 "samples", "a larger step")
            t_d, q_d, T_d = _interpolate(t, q, T, motion, counts)
            tip_obj = _tip_in_object(f, q_d, T_d)
    clr_d = np.interp(t_d, t, clr) if t.size > 1 else clr.copy()
    max_step = float(np.max(np.linalg.norm(np.diff(tip_obj, axis=0), axis=1))) \
        if t_d.size > 1 else 0.0

    checker = _PairChecker(hand, obj, f, q_d, T_d, clr_d - tol, link_clr - tol, ff_clr)
    required = checker.required
    dist, minima_exact = checker.run()
    joint_fail = _joint_limit_failures(hand, f, t_d, q_d)
    dist_fail = checker.failures(t_d, required)
    all_fail = sorted(dist_fail + joint_fail, key=lambda x: (x.t_first_s, x.kind, x.detail))
    worst = min(all_fail, key=_severity) if all_fail else None
    return VerificationReport(
        ok=not all_fail,
        n_samples=int(t_d.size),
        n_distance_queries=checker.n_queries,
        min_tip_object_m=dist["tip"],
        min_link_object_m=dist["link"],
        min_finger_finger_m=dist["ff"],
        min_clearance_margin_m=dist["margin"],
        joint_limits_ok=not joint_fail,
        failures=tuple(all_fail[:MAX_REPORTED_FAILURES]),
        n_failures=len(all_fail),
        time_s=None if worst is None else worst.time_s,
        max_tip_step_m=max_step,
        minima_exact=minima_exact,
        finger=f.name,
        elapsed_s=time.perf_counter() - start,
    )


def _severity(failure: Failure) -> tuple[int, float]:
    """Sort key: distance failures by margin first, then joint-limit excess."""
    if failure.kind == "joint-limit":
        return (1, -abs(failure.value - failure.required))
    return (0, failure.value - failure.required)


def _tip_in_object(f: Finger, q_d: np.ndarray, T_d: np.ndarray) -> np.ndarray:
    """Fingertip centres in the object frame, (D, 3) [m]."""
    p = f.chain.positions(q_d[:, f.q_indices])
    return np.einsum("dji,dj->di", T_d[:, :3, :3], p - T_d[:, :3, 3])


def _joint_limit_failures(hand: Hand, f: Finger, t_d: np.ndarray, q_d: np.ndarray
                          ) -> list[Failure]:
    qf = q_d[:, f.q_indices]
    out = []
    for j, name in enumerate(f.joint_names):
        for bound, sign in ((f.lower[j], -1.0), (f.upper[j], 1.0)):
            excess = sign * (qf[:, j] - bound)
            for lo, hi in _runs(excess > JOINT_LIMIT_TOL_RAD):
                w = lo + int(np.argmax(excess[lo:hi]))
                out.append(Failure(float(t_d[w]), "joint-limit", name, float(qf[w, j]),
                                   float(bound), float(t_d[lo]), float(t_d[hi - 1]), hi - lo))
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges ``[lo, hi)`` of the True runs of a boolean array."""
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist(),
                    strict=True))


def _step_bound(c: np.ndarray, R: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Bound on how far any point of a body moves between consecutive samples.

    A point ``c + R v`` with ``|v| <= rho`` moves by at most ``|dc| + rho |dR|_2``, and
    for rotations ``|dR|_2 = |dR|_F / sqrt(2)`` (= 2 sin(angle / 2)).

    Args:
        c: Body centres (D, G, 3) [m].
        R: Body orientations (D, G, 3, 3).
        rho: Largest distance of a point of each body from its centre (G,) [m].

    Returns:
        Step bounds (D - 1, G) [m].
    """
    dc = np.linalg.norm(np.diff(c, axis=0), axis=-1)
    dR = R[1:] - R[:-1]
    dR = np.sqrt(np.einsum("...ij,...ij->...", dR, dR) / 2.0)
    return dc + rho * dR


class _PairChecker:
    """Lower bounds and exact Coal distances for all (sample, pair) checks of one motion.

    Pairs are the columns: first the finger's geometries vs the object, then every
    (finger geometry, other finger's geometry) pair.
    """

    def __init__(self, hand: Hand, obj: ConvexObject, f: Finger, q_d: np.ndarray,
                 T_d: np.ndarray, tip_req: np.ndarray, link_req: float, ff_req: float
                 ) -> None:
        """Place the geometries and evaluate every lower bound.

        Args:
            hand, obj, f: The hand, the object and the moving finger.
            q_d: Dense configurations (D, nq) [rad].
            T_d: Dense object poses (D, 4, 4).
            tip_req: Required fingertip distance per sample (D,) [m].
            link_req: Required distance of the other finger geometries to the object [m].
            ff_req: Required distance to the other fingers [m].
        """
        moving = [_geometry(hand, g) for g in f.geometry_ids]
        own = set(f.geometry_ids)
        other_ids = sorted({g for name, o in hand.fingers.items() if name != f.name
                            for g in o.geometry_ids} - own)
        others = [_geometry(hand, g) for g in other_ids]
        geoms = moving + others
        R, p = _placements(geoms, q_d)
        self._R, self._p, self._T = R, p, T_d
        self._geoms = geoms
        self._obj_shape = obj.coal_geometry()
        nm, no = len(moving), len(others)
        tip = set(f.tip_geometry_ids)
        # columns
        self.first = np.concatenate([np.arange(nm), np.repeat(np.arange(nm), no)]).astype(int)
        self.second = np.concatenate([np.full(nm, -1), nm + np.tile(np.arange(no), nm)])
        self.second = self.second.astype(int)
        self.kind = np.concatenate([[_TIP if g.gid in tip else _LINK for g in moving],
                                    np.full(nm * no, _FF)]).astype(int)
        # capsule endpoints and centres in the palm frame, (D, G, 3)
        a_loc = np.array([g.seg_a for g in geoms]).reshape(-1, 3)
        b_loc = np.array([g.seg_b for g in geoms]).reshape(-1, 3)
        c_loc = np.array([g.centre for g in geoms]).reshape(-1, 3)
        params = np.array([g.support for g in geoms]).reshape(-1, 6)
        rad = np.array([g.radius for g in geoms])
        abc = np.matmul(R, np.stack([a_loc, b_loc, c_loc], axis=2)) + p[..., None]
        a, b, c = abc[..., 0], abc[..., 1], abc[..., 2]
        # geometry vs object: the face-plane support bound, in the object frame
        R_po = T_d[:, None, :3, :3]
        c_o = np.matmul(c[:, :nm] - T_d[:, None, :3, 3], T_d[:, :3, :3])  # R^T (x - p)
        lb_obj = _object_lower_bound(obj, c_o, np.matmul(np.swapaxes(R_po, 2, 3), R[:, :nm]),
                                     params[:nm])
        # geometry vs geometry: bounding spheres first; near pairs get the capsule bound
        # and the separating-axis bound along the capsules' nearest-point direction
        i1, i2 = self.first[nm:], self.second[nm:]
        mid = 0.5 * (a + b)
        reach = 0.5 * np.linalg.norm(b - a, axis=2) + rad  # (D, G)
        diff = mid[:, i1] - mid[:, i2]
        lb_ff = np.sqrt(np.einsum("dpi,dpi->dp", diff, diff)) - reach[:, i1] - reach[:, i2]
        d, k = np.nonzero(lb_ff < ff_req + BROAD_PHASE_MARGIN_M)
        g1, g2 = i1[k], i2[k]
        seg, v = _segment_distance(a[d, g1], b[d, g1], a[d, g2], b[d, g2])
        lb = seg - rad[g1] - rad[g2]
        u = v / np.where(seg > 1e-12, seg, 1.0)[:, None]  # from geometry 2 towards 1
        gap = np.einsum("ni,ni->n", u, c[d, g1] - c[d, g2]) \
            - _support(np.matmul(u[:, None, :], R[d, g1])[:, 0], params[g1]) \
            - _support(np.matmul(u[:, None, :], R[d, g2])[:, 0], params[g2])
        lb_ff[d, k] = np.where(seg > 1e-12, np.maximum(lb, gap), lb)
        self.lb = np.concatenate([lb_obj, lb_ff], axis=1)
        # sweep bound: between samples s and s', no point of a geometry moves by more
        # than the sum of its per-step bounds |dc| + rho |dR|_2, so a distance is
        # 1-Lipschitz in the cumulative sum of the two bodies' steps (see _update_sweep)
        rho = np.array([np.linalg.norm(g.support[:3]) + math.hypot(g.support[3], g.support[4])
                        + g.support[5] for g in geoms])
        step_g = _step_bound(c, R, rho)  # (D - 1, G)
        step_o = _step_bound(T_d[:, None, :3, 3], T_d[:, None, :3, :3],
                             np.array([obj.radius_m]))[:, 0]
        second = np.where(self.second < 0, 0, self.second)
        step = step_g[:, self.first] + np.where(self.second < 0, step_o[:, None],
                                                step_g[:, second])
        self._sweep = np.vstack([np.zeros((1, step.shape[1])), np.cumsum(step, axis=0)])
        self.swept = np.full(self.lb.shape, -np.inf)
        self.required = np.empty(self.lb.shape)
        self.required[:, self.kind == _TIP] = tip_req[:, None]
        self.required[:, self.kind == _LINK] = link_req
        self.required[:, self.kind == _FF] = ff_req
        self.exact = np.full(self.lb.shape, np.nan)
        self.n_queries = 0
        self._request = coal.DistanceRequest()
        self._request.gjk_tolerance = 1e-9  # separation distances to ~1e-9 m
        # penetration depths (EPA) to 1e-6 m: tighter tolerances make EPA fail on
        # deep cylinder/convex penetrations (Coal then returns -DBL_MAX)
        self._request.epa_tolerance = 1e-6
        self._result = coal.DistanceResult()
        self._functors: dict[int, Any] = {}

    def run(self) -> tuple[dict[str, float], bool]:
        """Mandatory queries, then the minima.

        Returns:
            The minima ``{"tip", "link", "ff", "margin"}`` [m] and whether all are exact.
        """
        rows, cols = np.nonzero(self.lb < self.required + BROAD_PHASE_MARGIN_M)
        self._query(rows, cols)
        self._update_sweep(np.unique(cols))
        out, exact = {}, True
        zero = np.zeros(self.lb.shape)
        for key, kind in (("tip", _TIP), ("link", _LINK), ("ff", _FF)):
            out[key], ok = self._minimum(zero, self.kind == kind)
            exact &= ok
        out["margin"], ok = self._minimum(-self.required, np.ones(self.kind.size, dtype=bool))
        return out, exact and ok

    def failures(self, t_d: np.ndarray, required: np.ndarray) -> list[Failure]:
        """Runs of samples where an exact distance is below its requirement."""
        fail = self.exact < required  # NaN (not queried: proven by the bound) -> False
        out = []
        for col in np.nonzero(fail.any(axis=0))[0]:
            g1 = self._geoms[self.first[col]].name
            g2 = "object" if self.second[col] < 0 else self._geoms[self.second[col]].name
            margin = self.exact[:, col] - required[:, col]
            for lo, hi in _runs(fail[:, col]):
                w = lo + int(np.argmin(margin[lo:hi]))
                out.append(Failure(float(t_d[w]), _KINDS[self.kind[col]], f"{g1} vs {g2}",
                                   float(self.exact[w, col]), float(required[w, col]),
                                   float(t_d[lo]), float(t_d[hi - 1]), hi - lo))
        return out

    def _minimum(self, offset: np.ndarray, columns: np.ndarray) -> tuple[float, bool]:
        """``min(distance + offset)`` over the given columns, by branch and bound.

        The bound of a sample not queried is the larger of its broad-phase bound and
        the sweep bound from the exact values of its column. Each round queries, in
        every column whose bound is still below the best exact value, the sample with
        the lowest bound, until no bound is below it. A minimum within the mandatory
        zone (below requirement + margin) needs no extra query.

        Args:
            offset: Added to every distance, shape (D, P) [m].
            columns: Columns taking part, boolean shape (P,).

        Returns:
            The minimum and True, or, when :data:`MAX_MINIMUM_QUERIES` did not settle it,
            a lower bound on it and False.
        """
        cols = np.nonzero(columns)[0]
        if cols.size == 0:
            return math.inf, True
        off = offset[:, cols]
        ex = self.exact[:, cols] + off
        done = ~np.isnan(ex)
        best = float(np.min(ex[done])) if done.any() else math.inf
        bound = np.where(done, np.inf, np.maximum(self.lb[:, cols], self.swept[:, cols]) + off)
        rows = np.argmin(bound, axis=0)  # per column, the sample with the lowest bound
        low = bound[rows, np.arange(cols.size)]
        n_extra = 0
        while True:
            open_ = np.nonzero(low < best)[0]
            if open_.size == 0:
                return best, True
            if n_extra >= MAX_MINIMUM_QUERIES:
                return float(np.min(low)), False  # bounds every distance left
            pick = open_[np.argsort(low[open_])[:MAX_MINIMUM_QUERIES - n_extra]]
            sub = cols[pick]
            self._query(rows[pick], sub)
            self._update_sweep(sub)
            n_extra += pick.size
            # only the picked columns changed
            ex = self.exact[:, sub] + off[:, pick]
            done = ~np.isnan(ex)
            best = min(best, float(np.min(ex[done])))
            bound = np.where(done, np.inf,
                             np.maximum(self.lb[:, sub], self.swept[:, sub]) + off[:, pick])
            rows[pick] = np.argmin(bound, axis=0)
            low[pick] = bound[rows[pick], np.arange(pick.size)]

    def _update_sweep(self, cols: np.ndarray) -> None:
        """Sweep bounds of the given columns from their exact values.

        ``swept(s) = max_k exact(k) - |S(s) - S(k)|`` with ``S`` the cumulative step
        bound, in two running maxima: ``max_{k<=s} (exact(k) + S(k)) - S(s)`` and
        ``max_{k>=s} (exact(k) - S(k)) + S(s)``.
        """
        if cols.size == 0:
            return
        S = self._sweep[:, cols]
        e = self.exact[:, cols]
        e = np.where(np.isnan(e), -np.inf, e)
        forward = np.maximum.accumulate(e + S, axis=0) - S
        backward = np.maximum.accumulate((e - S)[::-1], axis=0)[::-1] + S
        self.swept[:, cols] = np.maximum(forward, backward) - 1e-12  # rounding of S

    def _query(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Exact Coal distances for the (sample, column) pairs not yet computed."""
        todo = np.isnan(self.exact[rows, cols])
        rows, cols = rows[todo], cols[todo]
        if rows.size == 0:
            return
        g1 = self.first[cols]
        g2 = self.second[cols]
        # relative placement of geometry g1 in the frame of the second body (object or g2)
        R1, p1 = self._R[rows, g1], self._p[rows, g1]
        is_obj = g2 < 0
        R2 = np.where(is_obj[:, None, None], self._T[rows, :3, :3],
                      self._R[rows, np.maximum(g2, 0)])
        p2 = np.where(is_obj[:, None], self._T[rows, :3, 3], self._p[rows, np.maximum(g2, 0)])
        R_rel = np.matmul(np.swapaxes(R2, 1, 2), R1)
        p_rel = np.matmul((p1 - p2)[:, None, :], R2)[:, 0]
        identity = coal.Transform3s()
        request, result = self._request, self._result
        values = np.empty(rows.size)
        for n in range(rows.size):
            key = int(cols[n])
            fn = self._functors.get(key)
            if fn is None:
                second = self._obj_shape if is_obj[n] else self._geoms[g2[n]].shape
                fn = self._functors[key] = coal.ComputeDistance(second, self._geoms[g1[n]].shape)
            result.clear()  # Coal keeps the smaller of the old and new distances otherwise
            values[n] = fn(identity, coal.Transform3s(R_rel[n], p_rel[n]), request, result)
        bad = np.nonzero(~(values > -_MAX_DEPTH_M))[0]  # NaN or EPA failure (-DBL_MAX)
        if bad.size:
            retry = coal.DistanceRequest()
            retry.epa_tolerance = 1e-4
            for n in bad.tolist():
                values[n] = coal.distance(
                    self._obj_shape if is_obj[n] else self._geoms[g2[n]].shape, identity,
                    self._geoms[g1[n]].shape, coal.Transform3s(R_rel[n], p_rel[n]), retry,
                    coal.DistanceResult())
                if not values[n] > -_MAX_DEPTH_M:  # keep the (negative) lower bound
                    values[n] = min(self.lb[rows[n], cols[n]], 0.0)
                    logger.warning("Coal could not measure a penetration depth; using the "
                                   "broad-phase bound %.6f m", values[n])
        self.exact[rows, cols] = values
        self.n_queries += int(rows.size)

