"""One verified regrasp: inflated surface, grid path, Hopfield waypoints, joint trajectory.

Sections 2.1-2.3 of the paper. The finger lets go of P at ``t_start`` and lands on Q
at ``t_start + duration`` while the object keeps moving:

1. In the object frame, the surface region holding P and Q is unfolded into a plane
   and gridded (:mod:`regrasp_pin.surface.grid`); grid nodes cost more where the finger's IK, at
   the time the tip would pass over them, comes near a boundary plane, and nodes
   under another fingertip are forbidden. The cheapest grid path (Dijkstra) is lifted
   onto the virtually inflated surface: the fingertip-centre curve
   (:mod:`.surface_route`).
2. The competitive Hopfield network reduces that curve to m waypoints (Eqs. 5-10).
3. The waypoints are joined by a shape-preserving C1 curve (PCHIP, no overshoot)
   traversed by the regrasp's time law (minimum jerk by default, or the faster
   cruise: :mod:`.timing`), so the tip leaves P and reaches Q at rest relative to the
   object; waypoint i is passed at time t_i, in step with the object's motion
   (section 2.3). The progress is spent along the curve's length, or, where that
   outruns a joint's velocity limit, along the joints' motion
   (:func:`~.timing.joint_paced`). Each sample is moved to the palm frame with
   ``T_palm_object(t)`` and turned into joint angles by warm-started batched IK
   (:mod:`.follow`).
4. Coal checks the whole trajectory densely (:mod:`.verify`): the finger against the
   object (no penetration; at least ``clearance_m`` away from the lift-off and
   landing zones) and against the other fingers, which keep holding and move with
   the object; joint limits and velocity limits are checked too.

A failed candidate is changed by what failed (its :class:`~.exceptions.FailureKind`):
a curve that cuts into the clearance gets more waypoints, then more inflation; a motion
whose Coal check finds the finger nearer the object than required while its curve keeps
the clearance (the fingertip's link or sphere, another link) gets more inflation at
once; a finger that comes near another finger keeps a wider gap from it on the grid
(and a grid with no route keeps a narrower one); a finger near its joint limits is
rerouted more strongly. A failure that only another duration can fix (velocity) ends
the variants at once, for the caller
(:mod:`.planning.search`). When no variant passes for another reason, the joint-space
fallback (:mod:`.transfer`: lift off P, a joint-space move through a raised via, come
down onto Q; not in the paper) is tried, verified by the same
check; its velocity failure is the one reported then (a longer duration may let it
pass), and any failure of it where the region holding P and Q could not be unfolded
(too many faces apart: no surface route to try). ``route`` restricts a call to one of
the two.
It never returns a path that has not passed the check;
when nothing passes it raises :class:`~.exceptions.PlanningError` (or
:class:`~.exceptions.VerificationError`) with the finger, the time, the kind of the
failure, its numbers and every attempt.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace

import numpy as np
from scipy.interpolate import PchipInterpolator

from .._validate import as_array, positive
from ..exceptions import (
    Attempt,
    FailureKind,
    InputError,
    PlanningError,
    UnfoldError,
    VerificationError,
)
from ..model.clearance import LinkClearance
from ..model.hand import Finger, Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from ..model.scene import Scene
from ..polygon.approximate import PolygonResult, approximate_polygon
from ..surface.grid import SurfaceGrid, build_surface_grid
from ..surface.inflation import TipPath
from ..surface.path import GridPath
from ..verify.finger_motion import VerificationReport, verify_finger_motion
from .follow import CurveSamples, follow_curve
from .surface_route import RegraspTask, surface_path
from .timing import check_joint_speed, checked_time_law, joint_paced, minimum_jerk, progress
from .transfer import Transfer, plan_transfer

__all__ = ["RegraspParams", "RegraspResult", "minimum_jerk", "plan_regrasp"]

log = logging.getLogger(__name__)

#: The grid path's nodes: on paths at most twice as long as the straight unfolded P -> Q
#: segment plus 1 cm (an ellipse with foci P and Q; see ``build_surface_grid``).
_DETOUR = (2.0, 0.01)
_OTHERS_TIMES = 21  # the other fingers are placed at this many times over the regrasp
_MAX_LIMIT_WEIGHT_FACTOR = 16.0  # the joint-limit weight grows up to this x its start
_MAX_INFLATION_FACTOR = 2.25  # the inflation grows up to this x its start
_MAX_FINGER_GAP_M = 0.008  # the hard gap kept from the other fingers grows up to this
#: failures that no path variant fixes: the caller changes Q or the duration
CALLER_KINDS = frozenset({FailureKind.VELOCITY})
#: the routes :func:`plan_regrasp` may take
ROUTES = ("auto", "surface", "joint-space")


@dataclass(frozen=True)
class RegraspParams:
    """Parameters of one regrasp.

    Attributes:
        duration_s: Time from lift-off to landing [s].
        clearance_m: Clearance the fingertip must keep from the object away from the
            lift-off and landing zones (verified with Coal) [m].
        inflation_factor: The surface is inflated by ``inflation_factor * clearance_m``
            so that the waypoint curve, which cuts corners, still keeps ``clearance_m``.
        taper_m: Length of the lift-off and landing zones along the surface path [m]
            (default: the inflation height).
        grid_spacing_m: Grid spacing on the unfolded surface [m].
        m: Number of Hopfield waypoints (P, Q and m - 2 intermediate points).
        max_m: Largest m tried when the waypoint curve loses clearance.
        deviation: Hopfield deviation measure ("max" as in Eq. 7, "sum", "ise").
        method: "hopfield" (the paper) or "exact" (dynamic programming).
        limit_margin_rad: Nodes whose IK margin is below this cost extra [rad].
        limit_weight: Weight of the joint-limit cost in the grid path.
        contact_keepout_m: Extra distance kept from the other fingertips [m].
        link_clearance_m: Clearance of the finger's other links from the object [m].
        finger_clearance_m: Clearance from the other fingers [m].
        finger_gap_m: Grid nodes where the finger's links (conservative capsules)
            come closer than this to another finger, at the time the tip passes
            there, are forbidden [m]; grows when the Coal check finds the fingers
            too close.
        sample_dt_s: Time step of the returned trajectory [s] (the verifier
            densifies further, to 1 mrad joint steps).
        ik_tol_m: IK tolerance at lift-off and landing (and in their zones) [m].
        flight_ik_tol_m: IK tolerance in flight [m]: the executed motion, not the
            planned curve, is what the Coal check verifies.
        max_variants: Most path variants tried for one P, Q and duration.
        time_law: How the fingertip's progress along the path (or the joint-space
            fallback's move) is spread over the duration (:data:`~.timing.TIME_LAWS`):
            ``"minimum-jerk"`` (the smoothest), or ``"cruise"``, which peaks at 1.43
            instead of 1.875 times its mean speed (a velocity-bound regrasp in 0.76 of
            the time, with larger accelerations; the planner's search computes the
            durations by the same law).
    """

    duration_s: float = 0.5
    clearance_m: float = 0.005
    inflation_factor: float = 1.6
    taper_m: float | None = None
    grid_spacing_m: float = 0.002
    m: int = 7
    max_m: int = 13
    deviation: str = "ise"
    method: str = "hopfield"
    limit_margin_rad: float = 0.25
    limit_weight: float = 3.0
    contact_keepout_m: float = 0.003
    link_clearance_m: float = 0.0
    finger_clearance_m: float = 0.0005
    finger_gap_m: float = 0.001
    sample_dt_s: float = 0.005
    ik_tol_m: float = 1e-5
    flight_ik_tol_m: float = 5e-4
    max_variants: int = 8
    time_law: str = "minimum-jerk"

    def validate(self) -> RegraspParams:
        """Return ``self`` after checking every field (raises InputError naming it)."""
        positive(self.duration_s, "duration_s")
        positive(self.clearance_m, "clearance_m")
        positive(self.grid_spacing_m, "grid_spacing_m")
        positive(self.sample_dt_s, "sample_dt_s")
        if self.inflation_factor < 1.0:
            raise InputError("inflation_factor", f"{self.inflation_factor} < 1", "a number >= 1")
        if not isinstance(self.m, int) or self.m < 2:
            raise InputError("m", f"{self.m!r} is not allowed", "an integer >= 2")
        if self.taper_m is not None:
            positive(self.taper_m, "taper_m")
        positive(self.limit_margin_rad, "limit_margin_rad")
        positive(self.ik_tol_m, "ik_tol_m")
        if self.flight_ik_tol_m < self.ik_tol_m:
            raise InputError(
                "flight_ik_tol_m", f"{self.flight_ik_tol_m} < ik_tol_m", "a tolerance >= ik_tol_m"
            )
        if not isinstance(self.max_variants, int) or self.max_variants < 1:
            raise InputError("max_variants", f"{self.max_variants!r}", "an integer >= 1")
        checked_time_law(self.time_law)
        return self


@dataclass(frozen=True)
class RegraspResult:
    """A verified regrasp.

    Attributes:
        finger: Finger name.
        t_start: Lift-off time [s].
        t_end: Landing time [s].
        P_object: Released contact, object frame ``(3,)`` [m].
        n_P_object: Its outward normal.
        Q_object: New contact, object frame ``(3,)`` [m].
        n_Q_object: Its outward normal.
        grid: The unfolded surface grid (None for a joint-space transfer).
        grid_path: The grid path from P to Q (None for a joint-space transfer).
        tip_path: The fingertip-centre curve over the inflated surface (None for a
            joint-space transfer).
        polygon: The Hopfield (or exact) polygonal approximation of ``tip_path`` (None
            for a joint-space transfer).
        waypoints_object: ``(m, 3)`` waypoints (tip centres), object frame [m]; for a
            joint-space transfer its keyframes (:mod:`.transfer`).
        waypoint_times_s: ``(m,)`` when each waypoint is passed [s].
        times_s: ``(S,)`` trajectory times [s].
        q: ``(S, k)`` finger joint trajectory [rad].
        tip_object: ``(S, 3)`` planned tip centres in the object frame [m].
        report: The Coal verification report (``report.ok`` is always True; its minima
            are lower bounds, ``report.minima_exact`` False: see ``min_clearance_m``).
        min_clearance_m: Smallest Coal distance between the finger and the object
            away from the lift-off and landing zones (the middle half of the motion when
            the path is too short to leave them) [m].
        params: The parameters that succeeded.
        stage_ms: Time spent in each stage [ms].
        attempts: The variants that failed before success, as data.
        route: ``"surface"`` (the paper's path over the inflated surface) or
            ``"joint-space"`` (the fallback of :mod:`.transfer`).
    """

    finger: str
    t_start: float
    t_end: float
    P_object: np.ndarray
    n_P_object: np.ndarray
    Q_object: np.ndarray
    n_Q_object: np.ndarray
    grid: SurfaceGrid | None
    grid_path: GridPath | None
    tip_path: TipPath | None
    polygon: PolygonResult | None
    waypoints_object: np.ndarray
    waypoint_times_s: np.ndarray
    times_s: np.ndarray
    q: np.ndarray
    tip_object: np.ndarray
    report: VerificationReport
    min_clearance_m: float
    params: RegraspParams
    stage_ms: dict[str, float] = field(default_factory=dict)
    attempts: tuple[Attempt, ...] = ()
    route: str = "surface"

    @property
    def planning_ms(self) -> float:
        """Total planning and verification time [ms]."""
        return float(sum(self.stage_ms.values()))

    @property
    def path_length_m(self) -> float:
        """Length of the fingertip-centre trajectory in the object frame [m]."""
        return float(np.linalg.norm(np.diff(self.tip_object, axis=0), axis=1).sum())


class _Stages:
    def __init__(self) -> None:
        self.ms: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.ms[name] = self.ms.get(name, 0.0) + 1e3 * (now - self._t)
        self._t = now


def plan_regrasp(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    finger: str,
    t_start: float,
    P_object: np.ndarray,
    n_P_object: np.ndarray,
    Q_object: np.ndarray,
    n_Q_object: np.ndarray,
    q_start: np.ndarray,
    q_hand: Callable[[np.ndarray], np.ndarray],
    *,
    others_tips_object: np.ndarray | None = None,
    params: RegraspParams | None = None,
    q_land: np.ndarray | None = None,
    route: str = "auto",
) -> RegraspResult:
    """Plan and verify one finger's regrasp from P to Q while the object moves.

    Args:
        hand: The hand.
        obj: The object.
        motion: Object motion ``T_palm_object(t)``; ``[t_start, t_start + duration]``
            must lie within it.
        finger: The regrasping finger.
        t_start: Lift-off time [s].
        P_object: Current contact, object frame ``(3,)`` [m]; on the surface.
        n_P_object: Outward normal at P.
        Q_object: New contact, object frame ``(3,)`` [m]; on the surface.
        n_Q_object: Outward normal at Q.
        q_start: ``(k,)`` finger configuration at lift-off (tip at P) [rad].
        q_hand: Maps times ``(S,)`` to full hand configurations ``(S, nq)`` of the other
            fingers (holding their contacts); the regrasping finger's entries are
            overwritten.
        others_tips_object: ``(F, 3)`` tip centres of the other fingers in the object
            frame (they are fixed there while holding) [m]; grid nodes under them are
            forbidden.
        params: :class:`RegraspParams`.
        q_land: ``(k,)`` a configuration near the one holding Q at landing [rad], the
            IK seed of the joint-space fallback (default ``q_start``).
        route: ``"auto"``: the paper's surface path, and if no variant of it passes,
            the joint-space fallback (:mod:`.transfer`), except after a velocity
            failure (the caller tries a longer duration first); ``"surface"``: the
            surface path only; ``"joint-space"``: the fallback only.

    Returns:
        A :class:`RegraspResult` whose trajectory passed the Coal verification.

    Raises:
        InputError: bad parameters, P or Q not on the object, P == Q.
        VerificationError: no candidate passed the verification (finger, time, why).
        PlanningError: the path or the IK failed for every candidate.
    """
    scene = Scene(hand, obj, motion)  # types and scale, before any work
    params = (params or RegraspParams()).validate()
    if route not in ROUTES:
        raise InputError("route", f"{route!r} is not a route", f"one of {ROUTES}")
    f = hand.finger(finger)
    P = as_array(P_object, "P_object", (3,))
    Q = as_array(Q_object, "Q_object", (3,))
    nP = as_array(n_P_object, "n_P_object", (3,))
    nQ = as_array(n_Q_object, "n_Q_object", (3,))
    q0 = as_array(q_start, "q_start", (f.k,))
    q_seed = q0 if q_land is None else as_array(q_land, "q_land", (f.k,))
    if not np.isfinite(t_start):
        raise InputError("t_start", f"{t_start!r} is not finite", "a time within the motion [s]")
    t_end = float(t_start) + params.duration_s
    if t_start < motion.t_start - 1e-9 or t_end > motion.t_end + 1e-9:
        raise InputError(
            "t_start",
            f"regrasp [{t_start:.3f}, {t_end:.3f}] s leaves the motion",
            f"within [{motion.t_start:.3f}, {motion.t_end:.3f}] s",
        )
    others = (
        np.zeros((0, 3))
        if others_tips_object is None
        else as_array(others_tips_object, "others_tips_object", (None, 3))
    )
    stages = _Stages()
    attempts: list[Attempt] = []
    last: PlanningError | None = None
    unfoldable: bool | None = None  # whether the region holding P and Q unfolds
    if route != "joint-space":
        task = _surface_route(scene, f, float(t_start), q0, P, Q, others, q_hand, params, stages)
        unfoldable = not isinstance(task, PlanningError)
        if isinstance(task, PlanningError):
            attempts.append(task.as_attempt("surface grid"))
            found: RegraspResult | PlanningError = task
        else:
            found = _surface_variants(task, params, stages, attempts)
        if isinstance(found, RegraspResult):
            return replace(
                found,
                P_object=P,
                n_P_object=nP,
                Q_object=Q,
                n_Q_object=nQ,
                stage_ms=dict(stages.ms),
                attempts=tuple(attempts),
            )
        last = found
    if route == "joint-space" or (
        route == "auto" and last is not None and last.kind not in CALLER_KINDS
    ):
        try:
            moved = plan_transfer(
                hand,
                obj,
                motion,
                f.name,
                float(t_start),
                params.duration_s,
                (P, nP),
                (Q, nQ),
                q0,
                q_seed,
                q_hand,
                clearance_m=params.clearance_m,
                link_clearance_m=params.link_clearance_m,
                finger_clearance_m=params.finger_clearance_m,
                ik_tol_m=params.ik_tol_m,
                sample_dt_s=params.sample_dt_s,
                time_law=params.time_law,
            )
        except PlanningError as exc:
            attempts.append(exc.as_attempt("joint-space transfer"))
            log.debug("regrasp %s joint-space transfer failed: %s", f.name, exc)
            if last is None or unfoldable is False or exc.kind == FailureKind.VELOCITY:
                # the only route that could be tried, or a failure a longer duration fixes
                last = exc
        else:
            stages.lap("transfer")
            log.info(
                "regrasp %s at t=%.3f s verified in joint space (via %g, clearance %.2f mm)",
                f.name,
                t_start,
                moved.via_height,
                1e3 * moved.min_clearance_m,
            )
            return _transferred(
                f.name, P, nP, Q, nQ, float(t_start), moved, params, stages, attempts
            )
    assert last is not None  # a surface variant or the transfer was tried
    cls = VerificationError if isinstance(last, VerificationError) else PlanningError
    raise cls(
        f"no path variant passed ({len(attempts)} tried); the last: {last.reason}",
        finger=f.name,
        time_s=last.time_s if last.time_s is not None else float(t_start),
        kind=last.kind,
        measured=last.measured,
        required=last.required,
        attempts=attempts,
        other=last.other,
    )


def _surface_route(
    scene: Scene,
    f: Finger,
    t_start: float,
    q0: np.ndarray,
    P: np.ndarray,
    Q: np.ndarray,
    others: np.ndarray,
    q_hand: Callable[[np.ndarray], np.ndarray],
    params: RegraspParams,
    stages: _Stages,
) -> RegraspTask | PlanningError:
    """The surface route's task (its grid, the other fingers over the regrasp, which
    hold and move with the object), or a ``grid-unreachable`` failure where the region
    holding P and Q cannot be unfolded."""
    try:
        grid = build_surface_grid(
            scene.obj, P, Q, spacing_m=params.grid_spacing_m, max_detour=_DETOUR
        )
    except UnfoldError as exc:
        return PlanningError(
            f"no surface route: {exc}",
            finger=f.name,
            time_s=t_start,
            kind=FailureKind.GRID_UNREACHABLE,
        )
    stages.lap("grid")
    t_others = t_start + np.linspace(0.0, params.duration_s, _OTHERS_TIMES)
    q_others = np.asarray(q_hand(t_others), float)
    stages.lap("others")
    return RegraspTask(scene, f, t_start, q0, grid, q_hand, others, t_others, q_others)


def _surface_variants(
    task: RegraspTask, params: RegraspParams, stages: _Stages, attempts: list[Attempt]
) -> RegraspResult | PlanningError:
    """The first surface-path variant that verifies, or the last failure (each failure
    appended to ``attempts``): variants follow the failures' kinds (:func:`_next_variant`)
    until none is left, or at once after one that only the caller can fix."""
    last: PlanningError | None = None
    tried: set[tuple] = set()
    paths: dict[tuple, tuple[GridPath, TipPath]] = {}
    failed: dict[tuple, PlanningError] = {}  # an attempt's failure, by what it depends on
    p_try = params
    for _ in range(params.max_variants):
        tried.add(_variant_key(p_try))
        try:
            key = (p_try.inflation_factor, p_try.limit_weight, p_try.finger_gap_m)
            if key not in paths:
                paths[key] = surface_path(task, p_try)
            gpath, tip_path = paths[key]
            stages.lap("path")
            same = (_path_key(tip_path), min(p_try.m, len(tip_path)))
            if same in failed:  # a variant that left the path as it was fails as it did
                raise failed[same]
            try:
                result = _attempt(task, gpath, tip_path, p_try, stages)
            except PlanningError as exc:
                failed[same] = exc
                raise
        except PlanningError as exc:
            attempts.append(exc.as_attempt(_describe(p_try)))
            last = exc
            log.debug("regrasp %s variant failed: %s", task.finger.name, exc)
            if exc.kind in CALLER_KINDS:
                break
            nxt = _next_variant(p_try, exc, params)
            if nxt is None or _variant_key(nxt) in tried:
                break
            p_try = nxt
            continue
        log.info(
            "regrasp %s at t=%.3f s verified (m=%d, min clearance %.2f mm, %.0f ms)",
            task.finger.name,
            task.t_start,
            p_try.m,
            1e3 * result.min_clearance_m,
            sum(stages.ms.values()),
        )
        return result
    assert last is not None  # max_variants >= 1
    return last


def _transferred(
    finger: str,
    P: np.ndarray,
    nP: np.ndarray,
    Q: np.ndarray,
    nQ: np.ndarray,
    t_start: float,
    moved: Transfer,
    params: RegraspParams,
    stages: _Stages,
    attempts: list[Attempt],
) -> RegraspResult:
    """The :class:`RegraspResult` of a verified joint-space transfer."""
    return RegraspResult(
        finger=finger,
        t_start=t_start,
        t_end=float(moved.times_s[-1]),
        P_object=P,
        n_P_object=nP,
        Q_object=Q,
        n_Q_object=nQ,
        grid=None,
        grid_path=None,
        tip_path=None,
        polygon=None,
        waypoints_object=moved.keyframes_object,
        waypoint_times_s=moved.keyframe_times_s,
        times_s=moved.times_s,
        q=moved.q,
        tip_object=moved.tip_object,
        report=moved.report,
        min_clearance_m=moved.min_clearance_m,
        params=params,
        stage_ms=dict(stages.ms),
        attempts=tuple(attempts),
        route="joint-space",
    )


_POLYGONS: OrderedDict[tuple, PolygonResult] = OrderedDict()
_POLYGONS_KEPT = 256  # the polygons remembered (the searches of a plan ask again)
_POLYGONS_LOCK = threading.Lock()


def _polygon(pts: np.ndarray, m: int, deviation: str, method: str) -> PolygonResult:
    """``approximate_polygon`` of an open tip path (stopping at the optimum), the
    result of an earlier call with the same points and settings when it is one of the
    last ``_POLYGONS_KEPT`` (recovery plans the same regrasp again from other
    branches; the function is deterministic, so the answer is the same)."""
    key = (pts.dtype.str, pts.shape, pts.tobytes(), m, deviation, method)
    with _POLYGONS_LOCK:
        poly = _POLYGONS.get(key)
        if poly is not None:
            _POLYGONS.move_to_end(key)
    if poly is None:
        poly = approximate_polygon(
            pts, m, closed=False, deviation=deviation, method=method, stop_at_optimum=True
        )
        with _POLYGONS_LOCK:
            _POLYGONS[key] = poly
            if len(_POLYGONS) > _POLYGONS_KEPT:
                _POLYGONS.popitem(last=False)
    # the caller's own arrays: what it does with them cannot reach the kept result
    return replace(
        poly,
        indices=poly.indices.copy(),
        vertices=poly.vertices.copy(),
        energy_history=np.array(poly.energy_history, copy=True),
        timings_ms=dict(poly.timings_ms),
    )


def _path_key(path: TipPath) -> tuple:
    """What an attempt along ``path`` depends on of it: every field, arrays by their
    bytes (two variants of the grid path may lift to the same tip path)."""
    return tuple(
        (v.dtype.str, v.shape, v.tobytes()) if isinstance(v, np.ndarray) else v
        for v in (getattr(path, f.name) for f in fields(path))
    )


def _variant_key(p: RegraspParams) -> tuple:
    return (p.m, p.inflation_factor, p.limit_weight, p.finger_gap_m)


def _describe(p: RegraspParams) -> str:
    return (
        f"m={p.m}, inflation x{p.inflation_factor:g}, limit weight {p.limit_weight:g}, "
        f"finger gap {1e3 * p.finger_gap_m:g} mm"
    )


def _next_variant(
    p: RegraspParams, failure: PlanningError, base: RegraspParams
) -> RegraspParams | None:
    """The path variant that addresses ``failure`` (by its kind), or None if none is
    left.

    Too little clearance from the object in the planned waypoint curve itself (it cuts
    the inflated surface's corners): more waypoints. Too little in the Coal check of
    the motion while the curve keeps its clearance (a
    :class:`~regrasp_pin.exceptions.VerificationError`: the fingertip's link or sphere,
    or another link, nearer the object than required): more inflation, the waypoints as
    at first (more waypoints only make the fingertip follow the inflated surface more
    closely; they do not lift a link, nor the tip where the IK's flight tolerance lets
    it off the curve). Too close to another finger: a wider forbidden gap around the
    other fingers on the grid. Near a joint limit or out of reach: a stronger
    joint-limit cost. No route on the grid: only the other fingers' capsules themselves
    stay forbidden.
    """
    kind = failure.kind
    if kind == FailureKind.OBJECT_CLEARANCE:
        if not isinstance(failure, VerificationError) and p.m + 2 <= p.max_m:
            return replace(p, m=p.m + 2)
        infl = p.inflation_factor * 1.5
        if infl <= base.inflation_factor * _MAX_INFLATION_FACTOR + 1e-9:
            return replace(p, inflation_factor=infl, m=base.m)
        return None
    if kind == FailureKind.FINGER_COLLISION:
        gap = max(2.0 * p.finger_gap_m, 0.002)
        return replace(p, finger_gap_m=gap) if gap <= _MAX_FINGER_GAP_M + 1e-12 else None
    if kind == FailureKind.GRID_UNREACHABLE:
        # the forbidden gap around the other fingers may close every route: keep only
        # the capsules' overlap forbidden (the soft cost and Coal still keep them apart)
        return replace(p, finger_gap_m=0.0) if p.finger_gap_m > 0.0 else None
    if kind in (FailureKind.JOINT_LIMIT, FailureKind.IK_UNREACHABLE):
        weight = p.limit_weight * 4.0
        if weight <= base.limit_weight * _MAX_LIMIT_WEIGHT_FACTOR + 1e-9:
            return replace(p, limit_weight=weight)
        return None
    return None


def _attempt(
    task: RegraspTask, gpath: GridPath, tip_path: TipPath, p: RegraspParams, stages: _Stages
) -> RegraspResult:
    hand, obj, motion = task.scene.hand, task.scene.obj, task.scene.motion
    f, t_start = task.finger, task.t_start
    finger = f.name
    pts = tip_path.points_object
    m = min(p.m, len(tip_path))
    poly = _polygon(pts, m, p.deviation, p.method)
    W = poly.vertices
    stages.lap("hopfield")

    # C1 shape-preserving curve through the waypoints, by chord length
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(W, axis=0), axis=1))])
    curve = PchipInterpolator(chord, W, axis=0)
    u_fine = np.linspace(0.0, chord[-1], 2001)
    c_fine = curve(u_fine)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c_fine, axis=0), axis=1))])
    n_t = max(int(np.ceil(p.duration_s / p.sample_dt_s)), 8) + 1
    times = t_start + np.linspace(0.0, p.duration_s, n_t)
    s_t = progress(np.linspace(0.0, 1.0, n_t), p.time_law)
    u = np.interp(s_t * arc[-1], arc, u_fine)
    # where along the surface path each waypoint is (for the lift-off/landing zones)
    a_way = tip_path.arc_length_m[poly.indices]
    samples = CurveSamples(curve, chord, a_way, tip_path, pts, p.clearance_m)
    tip_obj, required, in_flight = samples.at(u, obj, f, times)
    waypoint_times = (
        np.interp(np.interp(chord, u_fine, arc) / arc[-1], s_t, times - t_start) + t_start
    )
    stages.lap("timing")

    T = motion.pose(times)
    tol = np.where(in_flight, p.flight_ik_tol_m, p.ik_tol_m)
    q = follow_curve(f, times, T, tip_obj, task.q0, tol, p.ik_tol_m)
    try:
        check_joint_speed(finger, f.joint_names, f.velocity_limit, times, q)
    except PlanningError as too_fast:
        # paced along the path by the joints' motion instead of its length; if that
        # fails for another reason, the velocity failure stands (a longer duration)
        u = joint_paced(u, q, f.velocity_limit, s_t)
        try:
            tip_obj, required, in_flight = samples.at(u, obj, f, times)
            tol = np.where(in_flight, p.flight_ik_tol_m, p.ik_tol_m)
            q = follow_curve(f, times, T, tip_obj, task.q0, tol, p.ik_tol_m)
        except PlanningError as exc:
            raise too_fast from exc
        check_joint_speed(finger, f.joint_names, f.velocity_limit, times, q)
        waypoint_times = np.interp(chord, u, times)
    stages.lap("ik")

    q_full = np.array(task.q_hand(times), dtype=float)
    q_full[:, f.q_indices] = q
    report = verify_finger_motion(
        hand,
        obj,
        finger,
        times,
        q_full,
        T,
        tip_clearance_m=required,
        link_clearance_m=np.maximum(required, p.link_clearance_m),
        finger_clearance_m=p.finger_clearance_m,
        exact_minima=False,  # pass/fail and failures are exact; the minima are not read
    )
    stages.lap("verify")
    if not report.ok:
        worst = report.worst_failure
        if worst is None:  # the report is not ok only with a failure
            raise AssertionError("verification failed without a failure")
        raise VerificationError(
            f"Coal check failed ({worst.describe()})",
            finger=finger,
            time_s=report.time_s,
            kind=worst.failure_kind,
            measured=worst.value,
            required=worst.required,
            other=worst.other,
        )
    # smallest Coal distance of the whole finger to the object in flight (between the
    # lift-off and landing zones; the middle half of the motion if the path is short)
    flight = in_flight if in_flight.any() else (np.abs(s_t - 0.5) <= 0.25)
    lc = LinkClearance(hand, finger, obj, include_tip=True)
    min_clear = float(lc(q_full[flight], T[flight]).min())
    # the tip as executed (within the flight tolerance of the planned curve)
    tip_palm = f.fk(q)
    tip_exec = np.einsum("nji,nj->ni", T[:, :3, :3], tip_palm - T[:, :3, 3])
    return RegraspResult(
        finger=finger,
        t_start=float(t_start),
        t_end=float(times[-1]),
        P_object=np.zeros(3),
        n_P_object=np.zeros(3),
        Q_object=np.zeros(3),
        n_Q_object=np.zeros(3),
        grid=task.grid,
        grid_path=gpath,
        tip_path=tip_path,
        polygon=poly,
        waypoints_object=W,
        waypoint_times_s=waypoint_times,
        times_s=times,
        q=q,
        tip_object=tip_exec,
        report=report,
        min_clearance_m=min_clear,
        params=p,
    )
