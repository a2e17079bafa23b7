"""Dense, exact verification of one finger's motion with Coal.

The check every planned regrasp must pass before it is returned. The motion between
two consecutive samples of a plan is linear interpolation of the full hand
configuration ``q`` and, for the object pose ``T_palm_object``, linear interpolation of
the position and slerp of the rotation (exactly what :class:`~regrasp_pin.model.motion.ObjectMotion`
does). :func:`verify_finger_motion` re-samples that motion densely (:func:`densify`)
and, at every dense sample, checks with Coal's exact distances:

* every collision geometry of the moving finger against the object: the fingertip
  geometries (``finger.tip_geometry_ids``) at least ``tip_clearance_m(t) -
  penetration_tol_m`` away, the other geometries at least ``link_clearance_m -
  penetration_tol_m``;
* every geometry of the moving finger against every geometry of every other finger
  (the palm excluded) at least ``finger_clearance_m``;
* the moving finger's joints within their limits (to :data:`JOINT_LIMIT_TOL_RAD`).

Broad phase (all samples at once, numpy). Each geometry carries two convex bounds:
a capsule that contains it (the axis of a cylinder, the longest axis of a box, a point
for a sphere) and its support function ``h(u)`` (exact for boxes, cylinders, capsules
and spheres). Lower bounds on the signed distance:

* geometry vs object: ``max_f (n_f . c - o_f - h(n_f))`` over the object's face
  planes ``n_f . x = o_f`` (``c`` the geometry's centre): the geometry lies at least
  that far in front of a face plane, the object behind it;
* geometry vs geometry: bounding spheres first; where they are within reach, the
  larger of the capsule bound (segment distance minus both radii) and the
  separating-axis bound ``u . (c1 - c2) - h1(u) - h2(u)`` along the direction ``u``
  joining the capsules' nearest points.

Both stay valid under penetration (they bound minus the penetration depth). Wherever a
bound is below the requirement the sample is settled by Coal: every
:data:`~regrasp_pin.model.distances.QUERY_STRIDE`-th such sample is measured first, and
then every one that the sweep bound (below) from those values does not lift clear of
the requirement, so every pass/fail decision near a threshold is an exact Coal
distance. Without exact minima (``exact_minima=False``, the
planner's check) the bounds are evaluated coarse to fine: at every
:data:`COARSE_STRIDE`-th sample, and between two of them from theirs less the sweep
bound (below); a sample's own bound is evaluated only where that is below the
requirement. The same samples get a Coal query, so the same pass/fail and failures.

Reported minima. A minimum below its requirement is already exact. Otherwise a branch and
bound queries, per pair, the sample with the lowest bound until no bound is below the
smallest exact value found. Its bounds are also raised by a sweep bound: between
samples no point of a body moves more than ``|dc| + rho |dR|_2`` per step, so an exact
distance ``d(k)`` gives ``d(s) >= d(k) - sum of the two bodies' steps between k and s``.
It stops after :data:`MAX_MINIMUM_QUERIES` extra queries per minimum, reporting a
lower bound (:attr:`VerificationReport.minima_exact` is then False). The same step
bounds give :attr:`VerificationReport.interpolation_slack_m`, how much lower a
distance can be between two samples than at them.

See ``docs/verification.md``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .._validate import as_array, positive
from ..exceptions import FailureKind, InputError, VerificationError
from ..model.distances import BROAD_PHASE_MARGIN_M, MAX_MINIMUM_QUERIES, PairDistances
from ..model.hand import Finger, Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject

__all__ = [
    "BROAD_PHASE_MARGIN_M",
    "MAX_MINIMUM_QUERIES",
    "PENETRATION_TOL_M",
    "Failure",
    "VerificationReport",
    "densify",
    "failure_at_samples",
    "verify_finger_motion",
]

#: Tolerance on the joint limits [rad].
JOINT_LIMIT_TOL_RAD = 1e-9
#: How far a geometry may enter the object where it is required to touch it (0
#: clearance) before the check fails, by default [m].
PENETRATION_TOL_M = 5e-5
#: At most this many failures are kept in a report (all are counted).
MAX_REPORTED_FAILURES = 20
#: Densification bounds the object's translation per step by max_joint_step_rad x this [m].
OBJECT_LEVER_M = 0.1
#: Refuse to verify more dense samples than this (a bad step size or a huge motion).
MAX_DENSE_SAMPLES = 2_000_000
#: :func:`failure_at_samples` calls a motion failed where a Coal distance at one of its
#: samples is this far below its requirement [m]: far above the rounding by which the
#: dense check's copy of a sample can differ from it (its object pose is interpolated
#: again), so that the dense check fails there too.
SURE_FAILURE_M = 1e-9
#: Without exact minima, the broad phase's bounds are evaluated at every this many
#: samples, and elsewhere only where those carried by the sweep bound do not settle it.
COARSE_STRIDE = 8

_KINDS = ("tip-object", "link-object", "finger-finger")  # by PairDistances.kind
_FAILURE_KIND = {
    "tip-object": FailureKind.OBJECT_CLEARANCE,
    "link-object": FailureKind.OBJECT_CLEARANCE,
    "finger-finger": FailureKind.FINGER_COLLISION,
    "joint-limit": FailureKind.JOINT_LIMIT,
}


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
        other: For ``"finger-finger"``, the finger whose geometry the finger came too
            near (of a geometry that several fingers carry, the first in the hand's
            order); None for the other kinds.
    """

    time_s: float
    kind: str
    detail: str
    value: float
    required: float
    t_first_s: float = math.nan
    t_last_s: float = math.nan
    n_samples: int = 1
    other: str | None = None

    @property
    def failure_kind(self) -> FailureKind:
        """The planner's kind of this failure (object clearance, finger collision or
        joint limit)."""
        return _FAILURE_KIND[self.kind]

    def describe(self) -> str:
        """One line: kind, detail, value vs requirement and the time span."""
        if self.kind == "joint-limit":
            side = "upper" if self.value > self.required else "lower"
            what = f"{self.value:.6f} rad beyond the {side} limit {self.required:.6f} rad"
        else:
            what = f"distance {self.value * 1e3:.4f} mm < required {self.required * 1e3:.4f} mm"
        return (
            f"{self.kind} {self.detail}: {what} at t={self.time_s:.4f} s "
            f"(failing from {self.t_first_s:.4f} to {self.t_last_s:.4f} s)"
        )


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
        interpolation_slack_m: Half the largest bound on how far a point of one
            checked body moves relative to the other between consecutive dense samples
            [m]: between two samples a distance is at most this much below the smaller
            of its two sampled values (to first order in the step).
        minima_exact: True when the four minima above are exact Coal distances. A
            minimum below its requirement is always exact; a larger one may be a lower
            bound (False here) when
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
    interpolation_slack_m: float = 0.0
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
        raise InputError(
            "max_joint_step_rad",
            f"{step:g} rad needs {counts.sum() + 1} samples",
            f"at most {MAX_DENSE_SAMPLES} dense samples (a larger step)",
        )
    return counts


def _interpolate(
    t: np.ndarray,
    q: np.ndarray,
    T: np.ndarray,
    motion: ObjectMotion | None,
    counts: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plan's interpolation at ``counts[i]`` equal steps per interval."""
    if t.size < 2 or motion is None:
        return t.copy(), q.copy(), T.copy()
    idx = np.repeat(np.arange(t.size - 1), counts)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    frac = (np.arange(idx.size) - start) / np.repeat(counts, counts)
    t_d = np.append(t[idx] + frac * (t[idx + 1] - t[idx]), t[-1])
    q_d = np.vstack([q[idx] + frac[:, None] * (q[idx + 1] - q[idx]), q[-1:]])
    T_d = motion.pose(t_d)
    T_d[0], T_d[-1] = T[0], T[-1]
    return t_d, q_d, T_d


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
    link_clearance_m: float | np.ndarray = 0.0,
    finger_clearance_m: float = 0.0005,
    penetration_tol_m: float = PENETRATION_TOL_M,
    max_joint_step_rad: float = 1e-3,
    max_tip_step_m: float | None = None,
    exact_minima: bool = True,
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
        link_clearance_m: Required clearance of the finger's other geometries [m], >= 0,
            a number or shape (S,) (interpolated like ``tip_clearance_m``).
        finger_clearance_m: Required distance to the other fingers [m], >= 0.
        penetration_tol_m: Tolerance on the object checks [m], >= 0.
        max_joint_step_rad: Largest joint step between dense samples [rad], > 0.
        max_tip_step_m: Optional largest fingertip step relative to the object [m], > 0.
        exact_minima: Find the report's minima exactly (a branch and bound, module
            docstring); False: only the pass/fail decisions and the failures, which are
            exact either way, and the minima as lower bounds (``minima_exact`` False
            unless every one is an exact distance).

    Returns:
        The :class:`VerificationReport`; call :meth:`VerificationReport.raise_if_failed`
        to turn a failure into a :class:`~regrasp_pin.exceptions.VerificationError`.

    Raises:
        InputError: wrong shapes, NaN/inf, times not strictly increasing, poses that
            are not rigid, negative clearances or tolerances, non-positive steps.
        UnknownNameError: ``finger`` is not a finger of the hand.
    """
    start = time.perf_counter()
    f, (t, q, T, motion), clr, link_clr, ff_clr, tol = _checked(
        hand,
        obj,
        finger,
        (times_s, q_full, T_palm_object),
        tip_clearance_m,
        link_clearance_m,
        finger_clearance_m,
        penetration_tol_m,
    )
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
                raise InputError(
                    "max_tip_step_m",
                    f"{tip_step:g} m needs {counts.sum() + 1} samples",
                    "a larger step",
                )
            t_d, q_d, T_d = _interpolate(t, q, T, motion, counts)
            tip_obj = _tip_in_object(f, q_d, T_d)
    clr_d = np.interp(t_d, t, clr) if t.size > 1 else clr.copy()
    link_d = np.interp(t_d, t, link_clr) if t.size > 1 else link_clr.copy()
    max_step = (
        float(np.max(np.linalg.norm(np.diff(tip_obj, axis=0), axis=1))) if t_d.size > 1 else 0.0
    )

    stride = 1 if exact_minima else COARSE_STRIDE
    pairs = PairDistances(
        hand, obj, f, q_d, T_d, clr_d - tol, link_d - tol, ff_clr, coarse_stride=stride
    )
    dist, minima_exact = pairs.run(exact_minima)
    joint_fail = _joint_limit_failures(f, t_d, q_d)
    dist_fail = _distance_failures(pairs, t_d, hand)
    all_fail = sorted(dist_fail + joint_fail, key=lambda x: (x.t_first_s, x.kind, x.detail))
    worst = min(all_fail, key=_severity) if all_fail else None
    return VerificationReport(
        ok=not all_fail,
        n_samples=int(t_d.size),
        n_distance_queries=pairs.n_queries,
        min_tip_object_m=dist["tip"],
        min_link_object_m=dist["link"],
        min_finger_finger_m=dist["ff"],
        min_clearance_margin_m=dist["margin"],
        joint_limits_ok=not joint_fail,
        failures=tuple(all_fail[:MAX_REPORTED_FAILURES]),
        n_failures=len(all_fail),
        time_s=None if worst is None else worst.time_s,
        max_tip_step_m=max_step,
        interpolation_slack_m=0.5 * pairs.max_step_m,
        minima_exact=minima_exact,
        finger=f.name,
        elapsed_s=time.perf_counter() - start,
    )


def failure_at_samples(
    hand: Hand,
    obj: ConvexObject,
    finger: str,
    times_s: np.ndarray,
    q_full: np.ndarray,
    T_palm_object: np.ndarray,
    *,
    tip_clearance_m: float | np.ndarray,
    link_clearance_m: float | np.ndarray = 0.0,
    finger_clearance_m: float = 0.0005,
    penetration_tol_m: float = PENETRATION_TOL_M,
) -> Failure | None:
    """A failure that :func:`verify_finger_motion` finds in this motion too, told from
    its given samples alone (arguments as there): the worst, as there, of the samples
    where a joint of the finger is beyond a limit or a Coal distance is below its
    requirement by more than :data:`SURE_FAILURE_M` (Coal's own, not a bound kept where
    it could not measure a penetration). The dense check keeps these samples
    (:func:`densify`) and settles every distance below its requirement with Coal, so it
    fails there too, if not worse. None says nothing: the given samples pass, and what
    lies between them is the dense check's to decide.

    For a caller that needs only whether a motion passes and checks many that fail:
    the broad phase and Coal at the S given samples instead of the dense ones, often
    20-40 times as many.

    Raises:
        InputError, UnknownNameError: as :func:`verify_finger_motion`.
    """
    f, (t, q, T, _), clr, link_clr, ff_clr, tol = _checked(
        hand,
        obj,
        finger,
        (times_s, q_full, T_palm_object),
        tip_clearance_m,
        link_clearance_m,
        finger_clearance_m,
        penetration_tol_m,
    )
    pairs = PairDistances(hand, obj, f, q, T, clr - tol, link_clr - tol, ff_clr)
    pairs.run(exact_minima=False)
    # NaN (not queried) is no failure; nor is a bound where Coal could not measure
    # (the dense check's own bound there may prove the requirement)
    sure = (pairs.exact < pairs.required - SURE_FAILURE_M) & ~pairs.unmeasured
    found = _distance_failures(pairs, t, hand, sure) + _joint_limit_failures(f, t, q)
    return min(found, key=_severity) if found else None


def _checked(
    hand: Hand,
    obj: ConvexObject,
    finger: str,
    motion: tuple[np.ndarray, np.ndarray, np.ndarray],
    tip_clearance_m: float | np.ndarray,
    link_clearance_m: float | np.ndarray,
    finger_clearance_m: float,
    penetration_tol_m: float,
) -> tuple[
    Finger,
    tuple[np.ndarray, np.ndarray, np.ndarray, ObjectMotion | None],
    np.ndarray,
    np.ndarray,
    float,
    float,
]:
    """The checks' arguments, checked (:func:`verify_finger_motion`'s): the finger, the
    trajectory ``(times_s, q_full, T_palm_object)`` as :func:`_check_trajectory`
    gives it, the tip and link clearances per sample [m], the finger clearance and the
    penetration tolerance [m]."""
    if not isinstance(hand, Hand):
        raise InputError("hand", f"is a {type(hand).__name__}", "a regrasp_pin.Hand")
    if not isinstance(obj, ConvexObject):
        raise InputError("obj", f"is a {type(obj).__name__}", "a regrasp_pin.ConvexObject")
    f = hand.finger(finger)
    trajectory = _check_trajectory(*motion, hand.model.nq)
    n = trajectory[0].size
    return (
        f,
        trajectory,
        _per_sample(tip_clearance_m, "tip_clearance_m", n),
        _per_sample(link_clearance_m, "link_clearance_m", n),
        positive(finger_clearance_m, "finger_clearance_m", allow_zero=True),
        positive(penetration_tol_m, "penetration_tol_m", allow_zero=True),
    )


def _per_sample(value: float | np.ndarray, name: str, n: int) -> np.ndarray:
    """A clearance [m] given as a number or per sample, as ``(n,)``; a negative one is
    an input error naming ``name``."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(positive(float(arr), name, allow_zero=True)))
    arr = as_array(arr, name, (n,))
    if np.any(arr < 0):
        raise InputError(name, f"has a negative value {arr.min():g}", "clearances >= 0 [m]")
    return arr


def _severity(failure: Failure) -> tuple[int, float]:
    """Sort key: distance failures by margin first, then joint-limit excess."""
    if failure.kind == "joint-limit":
        return (1, -abs(failure.value - failure.required))
    return (0, failure.value - failure.required)


def _tip_in_object(f: Finger, q_d: np.ndarray, T_d: np.ndarray) -> np.ndarray:
    """Fingertip centres in the object frame, (D, 3) [m]."""
    p = f.chain.positions(q_d[:, f.q_indices])
    return np.einsum("dji,dj->di", T_d[:, :3, :3], p - T_d[:, :3, 3])


def _joint_limit_failures(f: Finger, t_d: np.ndarray, q_d: np.ndarray) -> list[Failure]:
    """Runs of samples where a joint of the finger is beyond one of its limits."""
    qf = q_d[:, f.q_indices]
    out = []
    for j, name in enumerate(f.joint_names):
        for bound, sign in ((f.lower[j], -1.0), (f.upper[j], 1.0)):
            excess = sign * (qf[:, j] - bound)
            for lo, hi in _runs(excess > JOINT_LIMIT_TOL_RAD):
                w = lo + int(np.argmax(excess[lo:hi]))
                out.append(
                    Failure(
                        float(t_d[w]),
                        "joint-limit",
                        name,
                        float(qf[w, j]),
                        float(bound),
                        float(t_d[lo]),
                        float(t_d[hi - 1]),
                        hi - lo,
                    )
                )
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges ``[lo, hi)`` of the True runs of a boolean array."""
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(
        zip(np.nonzero(edges == 1)[0].tolist(), np.nonzero(edges == -1)[0].tolist(), strict=True)
    )


def _owners(hand: Hand) -> dict[int, str]:
    """Geometry id -> the finger that carries it (the first in the hand's order)."""
    return {g: name for name, f in reversed(list(hand.fingers.items())) for g in f.geometry_ids}


def _distance_failures(
    pairs: PairDistances,
    t_d: np.ndarray,
    hand: Hand,
    fail: np.ndarray | None = None,
) -> list[Failure]:
    """Runs of samples where an exact distance is below its requirement (or, given,
    where ``fail`` ``(D, columns)`` says so), each naming the ``hand``'s finger of a
    second geometry that belongs to one."""
    if fail is None:
        fail = pairs.exact < pairs.required  # NaN (not queried: proven by the bound) -> False
    failing = np.nonzero(fail.any(axis=0))[0]
    owners = _owners(hand) if failing.size else {}  # read only where something failed
    out = []
    for col in failing:
        g1 = pairs.geoms[pairs.first[col]].name
        second = None if pairs.second[col] < 0 else pairs.geoms[pairs.second[col]]
        g2 = "object" if second is None else second.name
        other = None if second is None else owners.get(second.gid)
        margin = pairs.exact[:, col] - pairs.required[:, col]
        for lo, hi in _runs(fail[:, col]):
            w = lo + int(np.argmin(margin[lo:hi]))
            out.append(
                Failure(
                    float(t_d[w]),
                    _KINDS[pairs.kind[col]],
                    f"{g1} vs {g2}",
                    float(pairs.exact[w, col]),
                    float(pairs.required[w, col]),
                    float(t_d[lo]),
                    float(t_d[hi - 1]),
                    hi - lo,
                    other,
                )
            )
    return out
