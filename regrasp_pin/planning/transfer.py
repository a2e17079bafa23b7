"""The joint-space fallback of a regrasp: lift off P, move, come down onto Q.

The paper's regrasp follows a path over the virtually inflated surface
(:mod:`.planning.regrasp`). Where no variant of that path passes -- the finger's
other links sweep an edge on the way down to Q, a joint flips to follow the curve, the
path crowds another finger -- the finger can still get there another way, the one a
release and a join take (:mod:`.release`, :mod:`.join`):

1. *lift*: over the first ``LIFT_FRACTION`` of the duration the fingertip backs off
   to ``clearance_m`` above P's tangent plane, which turns with the object (minimum
   jerk): along P's outward normal, or, where a joint limit keeps the finger from
   that, along a direction tilted from it (:func:`~.lift.back_off`);
2. *transfer*: a move in the finger's joint space to the configuration above Q, through
   a via configuration whose fingertip is raised away from the object (none: a straight
   move), shape-preserving (PCHIP) through the three configurations, by the regrasp's
   time law (:mod:`.timing`: minimum jerk, or the faster cruise), plus a drift that
   fades in and out (zero at both ends) so that the joint velocities are continuous
   with the lift's and the approach's, which follow the moving object;
3. *approach*: over the last ``LIFT_FRACTION`` the fingertip comes down onto Q the same
   way (along its normal, or tilted) and touches Q at the landing time.

Where that even split fails with a velocity failure, the three parts are paced and
the vias tried again: each part gets the time its fastest joint needs at its limit (a
tilted back-off at a joint limit may need much more than a quarter of a short regrasp
while the move between needs less), when their needs fit in the duration
(:func:`_paced_shares`); if the paced transfer fails too, the even split's velocity
failure stands (a longer duration is its to ask for).

The vias tried are the straight move and the midpoint of the two backed-off fingertips
raised along the mean of the two normals by ``VIA_HEIGHTS`` times the clearance plus
the tip radius; where one of those fails its Coal check (the move crosses another
finger or the object), vias sampled in the finger's joint box (a fixed seed: the same
every call), the shortest detours first, that are clear of the object and the other
fingers at the transfer's middle with ``VIA_MARGIN_M`` to spare: a one-via roadmap
searched in order, the rest of the motion judged by the Coal check. Each candidate
is checked against the joint velocity limits and verified with Coal exactly as a surface path is
(:func:`~regrasp_pin.verify.finger_motion.verify_finger_motion`: the fingertip and the
other links clear of the object by ``clearance_m`` during the transfer, allowed to touch
only at lift-off and landing, the other fingers clear, joints within their limits).

Where the transfer fails for another finger (``finger-collision``, the kind of its
last Coal failure), the lift may be what took the finger towards it (a neighbour
holding beside it on the same face: the fingers' links converge as they curl): the
transfer is tried again, with the even split, lifted off along the tilted directions
whose lift ends further from the other fingers (:func:`~.lift.directions_apart`), the
first failure standing if none passes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from ..exceptions import FailureKind, PlanningError
from ..model.clearance import FingerClearance, LinkClearance
from ..model.hand import Finger, Hand, speed_shares
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from ..verify.finger_motion import VerificationReport, failure_at_samples
from .lift import along, back_off, directions_apart
from .release import check_failure, verify_or_raise
from .timing import check_joint_speed, minimum_jerk, peak_ratio, progress, velocity_blend

__all__ = ["LIFT_FRACTION", "VIA_HEIGHTS", "Transfer", "plan_transfer"]

#: Share of the duration taken by the lift, and by the approach [-].
LIFT_FRACTION = 0.25
#: Heights of the via above the two backed-off tips' midpoint, in units of
#: (clearance + tip radius); 0 is the straight joint-space move.
VIA_HEIGHTS = (0.0, 1.0, 2.0)
#: Vias sampled in the finger's joint box when none of ``VIA_HEIGHTS`` passes; the
#: ``SAMPLED_SCREENED`` shortest detours are screened at the transfer's middle and the
#: first ``SAMPLED_VERIFIED`` clear ones within the velocity limits are given the Coal
#: check (a too fast one asks for no longer duration: the fixed vias do).
SAMPLED_VIAS = 256
SAMPLED_SCREENED = 48
SAMPLED_VERIFIED = 3
#: What a sampled via keeps to spare, beyond the clearances, at the transfer's middle [m].
VIA_MARGIN_M = 0.002
#: Where the even split is too fast, what the paced parts keep to spare below the
#: velocity limits [-] (the back-off at the paced times differs a little).
PACE_MARGIN = 0.05
#: The smallest share of the duration a paced part gets [-].
MIN_SHARE = 0.1


@dataclass(frozen=True)
class Transfer:
    """A verified joint-space regrasp (module docstring).

    Attributes:
        times_s: ``(S,)`` sample times [s].
        q: ``(S, k)`` the finger's joint trajectory [rad].
        tip_object: ``(S, 3)`` the fingertip centre as executed, object frame [m].
        keyframes_object: ``(K, 3)`` the fingertip at lift-off, after the lift, at the
            via (when there is one), before the approach and at landing, object frame
            [m].
        keyframe_times_s: ``(K,)`` when each keyframe is passed [s].
        report: The Coal verification report (``report.ok`` is True; its minima are
            lower bounds, see ``min_clearance_m``).
        min_clearance_m: Smallest Coal distance between the finger and the object
            during the transfer [m].
        via_height: The ``VIA_HEIGHTS`` entry that passed (NaN: a sampled via).
    """

    times_s: np.ndarray
    q: np.ndarray
    tip_object: np.ndarray
    keyframes_object: np.ndarray
    keyframe_times_s: np.ndarray
    report: VerificationReport
    min_clearance_m: float
    via_height: float


def plan_transfer(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    finger: str,
    t_start: float,
    duration_s: float,
    P: tuple[np.ndarray, np.ndarray],
    Q: tuple[np.ndarray, np.ndarray],
    q_start: np.ndarray,
    q_land: np.ndarray,
    q_hand: Callable[[np.ndarray], np.ndarray],
    *,
    clearance_m: float,
    link_clearance_m: float,
    finger_clearance_m: float,
    ik_tol_m: float,
    sample_dt_s: float,
    time_law: str = "minimum-jerk",
) -> Transfer:
    """Plan and verify ``finger``'s joint-space regrasp from P to Q (module docstring).

    Args:
        hand: The hand.
        obj: The object.
        motion: Its motion; ``[t_start, t_start + duration_s]`` lies within it.
        finger: The regrasping finger.
        t_start: Lift-off time [s].
        duration_s: From lift-off to landing [s].
        P: The contact let go ``(point, outward normal)``, object frame [m].
        Q: The new contact ``(point, outward normal)``, object frame [m].
        q_start: ``(k,)`` the finger holding P at ``t_start`` [rad].
        q_land: ``(k,)`` a configuration near the one holding Q at landing (IK seed)
            [rad].
        q_hand: Maps times ``(S,)`` to hand configurations ``(S, nq)`` with the other
            fingers holding.
        clearance_m: How far the fingertip backs off, and the clearance it keeps from
            the object during the transfer [m].
        link_clearance_m: Clearance of the finger's other links from the object [m].
        finger_clearance_m: Clearance from the other fingers [m].
        ik_tol_m: IK tolerance along the lift and the approach [m].
        sample_dt_s: Time step of the trajectory [s].
        time_law: The move's time law (:data:`~.timing.TIME_LAWS`). Through a via the
            joints turn unevenly, and the cruise law, faster near the move's ends, may
            move them faster than minimum jerk does.

    Returns:
        The verified :class:`Transfer`.

    Raises:
        PlanningError: the lift or the approach is out of reach (``ik-unreachable``),
            or no via passes the Coal check within the velocity limits: ``velocity`` if
            one that is too fast passes its geometry (the least too fast: a longer
            duration may let it pass), else the kind, measured and required values
            of the last Coal failure; a ``finger-collision`` only once no lift apart
            passes either (module docstring).
    """
    f = hand.finger(finger)
    n_t = max(int(np.ceil(duration_s / sample_dt_s)), 8) + 1
    times = t_start + np.linspace(0.0, duration_s, n_t)
    moving = _Moving(
        hand,
        obj,
        f,
        times,
        motion.pose(times),
        (np.asarray(P[0], float), np.asarray(P[1], float)),
        (np.asarray(Q[0], float), np.asarray(Q[1], float)),
        np.array(q_hand(times), dtype=float),  # the same for every via
        clearance_m,
        link_clearance_m,
        finger_clearance_m,
        time_law,
    )
    tau = np.linspace(0.0, 1.0, n_t)
    even = (LIFT_FRACTION, LIFT_FRACTION)
    ends = _lift_and_approach(moving, tau, q_start, q_land, ik_tol_m, even)
    try:
        return _even_or_paced(moving, tau, q_start, q_land, ik_tol_m, ends)
    except PlanningError as exc:
        if exc.kind != FailureKind.FINGER_COLLISION:
            raise
        failure = exc
    # the finger's way crosses another finger's: lifted off P away from the others
    # (their failures aside, the first one's stands)
    for d in _lifts_apart(moving, ik_tol_m, ends):
        try:
            apart = _lift_and_approach(moving, tau, q_start, q_land, ik_tol_m, even, d)
            return _through_vias(moving, apart, reported=False)
        except PlanningError:
            continue
    raise failure


def _even_or_paced(
    m: _Moving,
    tau: np.ndarray,
    q_start: np.ndarray,
    q_land: np.ndarray,
    ik_tol_m: float,
    ends: _Ends,
) -> Transfer:
    """The transfer through the vias between the even split's ``ends``, or, where that
    is too fast, between the parts paced by their joints' needs, the even split's
    failure standing if that fails too (a longer duration is its to ask for)."""
    try:
        return _through_vias(m, ends)
    except PlanningError as exc:
        paced = (
            _paced_shares(m.f, m.times, ends, peak_ratio(m.time_law))
            if exc.kind == FailureKind.VELOCITY
            else None
        )
        if paced is None:
            raise
        failure = exc
    try:
        paced_ends = _lift_and_approach(m, tau, q_start, q_land, ik_tol_m, paced)
        return _through_vias(m, paced_ends, reported=False)
    except PlanningError:
        raise failure from None


def _lifts_apart(m: _Moving, ik_tol_m: float, ends: _Ends) -> np.ndarray:
    """Unit directions ``(D, 3)`` (object frame) to back off from P along, whose lift
    ends further from the other fingers than ``ends``' lift does (along the normal, or
    the tilted direction :func:`~.lift.back_off` took): :func:`~.lift.directions_apart`,
    judged where the lift ends, the others holding."""
    i_a = int(np.flatnonzero(ends.lift)[-1])
    fingers = FingerClearance.shared(m.hand, m.f.name)
    q_full = np.array(m.q_others[i_a], float)

    def gap(q: np.ndarray) -> float:
        q_full[m.f.q_indices] = q
        return float(fingers(q_full))

    q_top = ends.q_lift[-1]
    return directions_apart(
        m.f, m.T[i_a], m.P, q_top, m.clearance_m, gap, ik_tol_m, m.Q[0], gap(q_top)
    )


@dataclass(frozen=True)
class _Moving:
    """What a transfer's trajectories are judged by: the finger, its sample times
    ``(S,)`` [s], the object's poses ``(S, 4, 4)``, the contacts P and Q (object frame
    [m]), the hand ``(S, nq)`` [rad] with the other fingers holding, the clearances
    [m], and the move's time law."""

    hand: Hand
    obj: ConvexObject
    f: Finger
    times: np.ndarray
    T: np.ndarray
    P: tuple[np.ndarray, np.ndarray]
    Q: tuple[np.ndarray, np.ndarray]
    q_others: np.ndarray
    clearance_m: float
    link_clearance_m: float
    finger_clearance_m: float
    time_law: str = "minimum-jerk"


def _through_vias(m: _Moving, ends: _Ends, reported: bool = True) -> Transfer:
    """The first trajectory through a via, between the lift and the approach ``ends``,
    that is within the velocity limits and passes its Coal check (module docstring);
    else the failure :func:`plan_transfer` raises (``reported`` False, for a caller
    that drops the failure: the last Coal failure, else a too fast via's, without the
    Coal checks of the too fast vias that :func:`_reported_failure` would make; each
    via's as :class:`_CoalCheck` makes them)."""
    hand, obj, f, times, T, P, Q = m.hand, m.obj, m.f, m.times, m.T, m.P, m.Q
    finger, clearance_m, finger_clearance_m = f.name, m.clearance_m, m.finger_clearance_m
    lift, land, q_lift, q_app = ends.lift, ends.land, ends.q_lift, ends.q_app
    i_a, i_b = int(np.flatnonzero(lift)[-1]), int(np.flatnonzero(land)[0])
    i_m = (i_a + i_b) // 2  # the via's sample
    q_a, q_b = q_lift[-1], q_app[0]
    mid = times[i_a : i_b + 1]
    s = progress((mid - mid[0]) / (mid[-1] - mid[0]), m.time_law)
    v_lift = (q_lift[-1] - q_lift[-2]) / (times[i_a] - times[i_a - 1])
    v_approach = (q_app[1] - q_app[0]) / (times[i_b + 1] - times[i_b])
    drift = velocity_blend(mid, v_lift, v_approach)
    required = np.where(lift | land, 0.0, clearance_m)
    required[[i_a, i_b]] = 0.0  # the backed-off tip sits at clearance_m

    def through(via: np.ndarray | None) -> np.ndarray:
        """The finger's trajectory ``(S, k)`` through ``via`` (None: straight)."""
        knots = np.stack([q_a, q_b]) if via is None else np.stack([q_a, via, q_b])
        path = PchipInterpolator(np.linspace(0.0, 1.0, len(knots)), knots, axis=0)
        return np.vstack([q_lift[:-1], path(s) + drift, q_app[1:]])

    fixed = [
        (h, through(_via(f, T[i_m], P, Q, q_a, q_b, h * (clearance_m + f.tip_radius))))
        for h in VIA_HEIGHTS
    ]
    q_others = m.q_others
    coal = _CoalCheck(m, required)

    # the fixed vias within the velocity limits first, then vias sampled clear of the
    # object and the other fingers; the fixed ones that are too fast only if none of
    # those passes, and then only their geometry decides whether a velocity failure
    # is reported
    too_fast: list[tuple[float, np.ndarray, PlanningError]] = []
    failures: list[tuple[np.ndarray, PlanningError]] = []  # fixed vias failing Coal

    def sampled() -> Iterator[np.ndarray]:  # asked for only when a fixed via fails
        return _clear_vias(
            hand, obj, f, q_others[i_m], T[i_m], q_a, q_b, clearance_m, finger_clearance_m
        )

    checked: list[np.ndarray] = []  # the sampled vias' trajectories given the Coal check
    for height, q in _candidates(fixed, sampled, through, failures, checked):
        try:
            check_joint_speed(finger, f.joint_names, f.velocity_limit, times, q)
        except PlanningError as exc:
            if not math.isnan(height):  # a longer duration is the fixed vias' to ask for
                too_fast.append((height, q, exc))
            continue
        if math.isnan(height):
            checked.append(q)
        failure, report, q_full = coal.failure(q)
        if report is not None:
            return _transfer(hand, obj, finger, times, T, q, q_full, report, height, (i_a, i_b))
        if failure is not None and not math.isnan(height):
            failures.append((q, failure))
    if not reported:
        raise failures[-1][1] if failures else too_fast[0][2]
    raise _reported_failure(too_fast, [q for q, _ in failures], coal)


class _CoalCheck:
    """The Coal checks of a transfer's trajectories through its vias: the finger
    ``(S, k)`` [rad] at the transfer's times among the other fingers holding, its
    fingertip ``required`` ``(S,)`` [m] from the object (its other links at least
    that or their own clearance), clear of the other fingers.

    A trajectory is first checked at its own samples
    (:func:`~regrasp_pin.verify.finger_motion.failure_at_samples`): a failure there is
    one of the dense check's, and most trajectories that fail show it there; the dense
    check runs for the others, and for the failure a transfer reports, for its numbers
    (:meth:`dense_failure`)."""

    what = "the joint-space transfer"

    def __init__(self, m: _Moving, required: np.ndarray) -> None:
        self.m = m
        self.clear = {
            "tip_clearance_m": required,
            "link_clearance_m": np.maximum(required, m.link_clearance_m),
            "finger_clearance_m": m.finger_clearance_m,
        }
        self._dense: dict[bytes, PlanningError] = {}  # the dense checks' failures

    def failure(
        self, q: np.ndarray, at_samples: bool = True
    ) -> tuple[PlanningError | None, VerificationReport | None, np.ndarray]:
        """The check of the finger's trajectory ``q``: its failure or its report, and the
        hand's trajectory ``(S, nq)``. With ``at_samples``, a failure found at the
        trajectory's own samples comes without the dense check (its numbers those
        samples')."""
        m, f = self.m, self.m.f
        q_full = m.q_others.copy()
        q_full[:, f.q_indices] = q
        args = (m.hand, m.obj, f.name, m.times, q_full, m.T)
        if at_samples:
            sure = failure_at_samples(*args, **self.clear)
            if sure is not None:
                return check_failure(self.what, f.name, sure, sure.time_s), None, q_full
        try:
            report = verify_or_raise(self.what, *args, **self.clear)
        except PlanningError as exc:
            self._dense[q.tobytes()] = exc
            return exc, None, q_full
        return None, report, q_full

    def dense_failure(self, q: np.ndarray) -> PlanningError:
        """The dense check's failure of ``q``, a trajectory known to fail."""
        known = self._dense.get(q.tobytes())
        if known is None:
            known, _, _ = self.failure(q, at_samples=False)
        assert known is not None  # failure_at_samples finds only the dense check's
        return known


@dataclass(frozen=True)
class _Ends:
    """The lift and the approach of a transfer: their sample masks ``(S,)`` and the
    finger's configurations ``(L, k)``, ``(A, k)`` along them [rad]."""

    lift: np.ndarray
    land: np.ndarray
    q_lift: np.ndarray
    q_app: np.ndarray


def _lift_and_approach(
    m: _Moving,
    tau: np.ndarray,
    q_start: np.ndarray,
    q_land: np.ndarray,
    ik_tol_m: float,
    shares: tuple[float, float],
    lift_dir: np.ndarray | None = None,
) -> _Ends:
    """The lift over the first ``shares[0]`` of the normalized time ``tau`` ``(S,)`` and
    the approach over the last ``shares[1]``: the fingertip backs off ``clearance_m``
    from P, and comes down onto Q, minimum jerk, with the object moving
    (:func:`~.lift.back_off`, from ``q_start`` and towards ``q_land`` ``(k,)`` [rad];
    the lift along ``lift_dir``, object frame, when given); ``ik-unreachable`` if
    either is out of reach."""
    f, T, P, Q = m.f, m.T, m.P, m.Q
    s_lift, s_land = shares
    lift = tau <= s_lift + 1e-12
    land = tau >= 1.0 - s_land - 1e-12
    off_lift = m.clearance_m * minimum_jerk(tau[lift] / s_lift)
    off_land = m.clearance_m * minimum_jerk((1.0 - tau[land]) / s_land)
    q0 = np.asarray(q_start, float)
    q_lift = (
        back_off(f, T[lift], P, off_lift, q0, ik_tol_m, Q[0])
        if lift_dir is None
        else along(f, T[lift], P, lift_dir, off_lift, q0, ik_tol_m)
    )
    q_app = back_off(f, T[land][::-1], Q, off_land[::-1], np.asarray(q_land, float), ik_tol_m, P[0])
    return _Ends(lift, land, q_lift, q_app[::-1])


def _paced_shares(
    f: Finger, times: np.ndarray, ends: _Ends, peak: float
) -> tuple[float, float] | None:
    """Shares of the duration for the lift and the approach that keep the joints within
    their velocity limits, after the split of ``ends`` (sampled at ``times`` ``(S,)``
    [s]) was too fast; None where no split is (or this one is not).

    Each part needs the time its fastest joint takes at its limit: its share times its
    peak speed share (the lift and the approach as backed off, the move between as a
    straight move by the time law, whose peak speed is ``peak`` times its mean). When
    the parts' needs, with ``PACE_MARGIN`` to spare, add up to at most the whole
    duration, each part gets its need (at least ``MIN_SHARE`` and two steps) and the
    time left is shared as the split shares it, rounded up to whole steps for the lift
    and the approach; a back-off that only a joint jump could follow stays too fast."""
    lift, land = ends.lift, ends.land
    steps = len(times) - 1
    i_a, i_b = int(np.flatnonzero(lift)[-1]), int(np.flatnonzero(land)[0])
    split = np.diff([0, i_a, i_b, steps]) / steps  # the shares the parts have
    peak_lift = _peak_share(f, times[lift], ends.q_lift)
    peak_land = _peak_share(f, times[land], ends.q_app)
    step = np.abs(ends.q_app[0] - ends.q_lift[-1])
    limit = np.where(f.velocity_limit > 0.0, f.velocity_limit, np.inf)
    t_mid = float(times[i_b] - times[i_a])
    peak_mid = peak * float(np.max(step / limit)) / max(t_mid, 1e-12)
    if max(peak_lift, peak_land, peak_mid) <= 1.0:
        return None  # within the limits as far as this tells: not the split's fault
    need = split * np.array([peak_lift, peak_mid, peak_land]) * (1.0 + PACE_MARGIN)
    need = np.maximum(need, max(MIN_SHARE, 2.0 / steps))  # two steps at least
    if need.sum() > 1.0:
        return None
    share = need + (1.0 - need.sum()) * split
    # whole steps: the lift ends, and the approach begins, on a sample
    k_lift, k_land = (int(np.ceil(share[i] * steps - 1e-9)) for i in (0, 2))
    if (steps - k_lift - k_land) < need[1] * steps:
        return None
    return k_lift / steps, k_land / steps


def _peak_share(f: Finger, t: np.ndarray, q: np.ndarray) -> float:
    """The largest joint speed of ``q`` ``(S, k)`` over ``t`` ``(S,)`` as a share of its
    limit (0 for a single sample)."""
    if len(t) < 2:
        return 0.0
    return float(speed_shares(np.diff(q, axis=0), np.diff(t), f.velocity_limit).max())


def _candidates(
    fixed: list[tuple[float, np.ndarray]],
    sampled: Callable[[], Iterator[np.ndarray]],
    through: Callable[[np.ndarray], np.ndarray],
    failures: list[tuple[np.ndarray, PlanningError]],
    checked: list[np.ndarray],
) -> Iterator[tuple[float, np.ndarray]]:
    """``(via height, trajectory)`` to try: the fixed vias, then, if one of them failed
    its Coal check (``failures``), the sampled ones (height NaN) until
    ``SAMPLED_VERIFIED`` of them were given the Coal check (``checked``)."""
    yield from fixed
    if failures:
        for via in sampled():
            if len(checked) >= SAMPLED_VERIFIED:
                return
            yield math.nan, through(via)


def _reported_failure(
    too_fast: list[tuple[float, np.ndarray, PlanningError]],
    failed: list[np.ndarray],
    coal: _CoalCheck,
) -> PlanningError:
    """The failure of a transfer no via passed: the velocity failure a longer duration
    fixes soonest among the too fast fixed vias that pass their Coal check, else the
    last Coal failure (``failed``: the trajectories of the fixed vias that failed it, in
    order), as the dense check finds it."""
    last = failed[-1] if failed else None
    for _, q, speed_error in sorted(too_fast, key=lambda c: (_over_speed(c[2]), c[0])):
        failure, _, _ = coal.failure(q)
        if failure is None:
            return speed_error
        last = q
    assert last is not None  # VIA_HEIGHTS is not empty
    return coal.dense_failure(last)


def _transfer(
    hand: Hand,
    obj: ConvexObject,
    finger: str,
    times: np.ndarray,
    T: np.ndarray,
    q: np.ndarray,
    q_full: np.ndarray,
    report: VerificationReport,
    height: float,
    ends: tuple[int, int],
) -> Transfer:
    """The :class:`Transfer` of a verified trajectory (``ends``: the samples where the
    lift ends and the approach begins)."""
    f = hand.finger(finger)
    i_a, i_b = ends
    n_t = len(times)
    tip_obj = np.einsum("nji,nj->ni", T[:, :3, :3], f.fk(q) - T[:, :3, 3])
    keys = [0, i_a, i_b, n_t - 1] if height <= 0.0 else [0, i_a, (i_a + i_b) // 2, i_b, n_t - 1]
    flight = np.zeros(n_t, bool)
    flight[i_a + 1 : i_b] = True
    if not flight.any():
        flight[:] = True
    lc = LinkClearance(hand, finger, obj, include_tip=True)
    return Transfer(
        times_s=times,
        q=q,
        tip_object=tip_obj,
        keyframes_object=tip_obj[keys],
        keyframe_times_s=times[keys],
        report=report,
        min_clearance_m=float(lc(q_full[flight], T[flight]).min()),
        via_height=float(height),
    )


def _clear_vias(
    hand: Hand,
    obj: ConvexObject,
    f: Finger,
    q_mid: np.ndarray,
    T_mid: np.ndarray,
    q_a: np.ndarray,
    q_b: np.ndarray,
    clearance_m: float,
    finger_clearance_m: float,
) -> Iterator[np.ndarray]:
    """Via configurations ``(k,)`` of the finger, sampled in its joint box (the same
    ``SAMPLED_VIAS`` every call), the shortest detours from ``q_a`` to ``q_b`` first,
    that are clear at the middle of the transfer (hand ``q_mid``, object pose
    ``T_mid``): the whole finger ``clearance_m`` from the object and
    ``finger_clearance_m`` from the other fingers, each with ``VIA_MARGIN_M`` to spare
    (the object and the others move on while the finger passes), screened as they
    are asked for; the Coal check of the whole motion judges them."""
    rng = np.random.default_rng(0)
    vias = f.lower + rng.random((SAMPLED_VIAS, f.k)) * (f.upper - f.lower)
    detour = np.linalg.norm(vias - q_a, axis=1) + np.linalg.norm(vias - q_b, axis=1)
    # detours equal to 1e-9 rad go by index (ties broken the same way everywhere)
    order = np.lexsort((np.arange(SAMPLED_VIAS), np.round(detour, 9)))
    fingers = FingerClearance.shared(hand, f.name)
    links = LinkClearance(hand, f.name, obj, include_tip=True)
    for i in order[:SAMPLED_SCREENED]:
        q_full = np.array(q_mid, float)
        q_full[f.q_indices] = vias[i]
        if fingers(q_full) < finger_clearance_m + VIA_MARGIN_M:
            continue
        if links(q_full[None], T_mid[None])[0] < clearance_m + VIA_MARGIN_M:
            continue
        yield vias[i]


def _over_speed(exc: PlanningError) -> float:
    return float(exc.measured or np.inf) / float(exc.required or 1.0)


def _via(
    f: Finger,
    T: np.ndarray,
    P: tuple[np.ndarray, np.ndarray],
    Q: tuple[np.ndarray, np.ndarray],
    q_a: np.ndarray,
    q_b: np.ndarray,
    height_m: float,
) -> np.ndarray | None:
    """The via configuration ``(k,)``: the fingertip near the midpoint of the two
    backed-off tips (object pose ``T``) raised by ``height_m`` along the mean of the
    normals of P and Q (IK from the mean configuration, as near as it gets); None for
    a zero height (a straight move)."""
    if height_m <= 0.0:
        return None
    R, o = T[:3, :3], T[:3, 3]
    mid_palm = 0.5 * (f.fk(q_a) + f.fk(q_b))
    up_obj = np.asarray(P[1], float) + np.asarray(Q[1], float)
    norm = float(np.linalg.norm(up_obj))
    if norm < 1e-6:  # opposite normals: raise away from the object's centre instead
        up_obj = R.T @ (mid_palm - o)
        norm = float(np.linalg.norm(up_obj))
    target = mid_palm + height_m * (R @ (up_obj / norm))
    # a via need not be reached exactly: the Coal check judges the motion through it
    return f.ik(target[None], 0.5 * (q_a + q_b), tol_m=1e-4, restarts=False).q[0]
