"""Letting a finger go for the rest of the motion.

Near the end of a motion a contact may be lost with no time left for a regrasp
(lift-off, flight and landing take at least ``RegraspParams.duration_s``). If the
other fingers hold the object in force closure to the end, the finger can simply let
go: from the release time ``t_r`` its fingertip backs off along the contact normal
or, where a joint limit puts that out of reach, along a direction tilted from it
(:func:`~.lift.back_off`; fixed in the palm frame: ``clearance`` above the tangent
plane where the pad touched) over a short
minimum-jerk move (straight in joint space, as long as the joint velocity limits
need: near a joint limit, backing off may swing another joint far); the finger then
stays still or, given a parking configuration, moves there (minimum jerk, joint
space, as slowly as its velocity limits need) and stays. The joint speeds are checked
against the limits and the motion is verified with Coal like every regrasp
(:func:`~regrasp_pin.verify.finger_motion.verify_finger_motion`: the fingertip
clear of the object, allowed to touch only at the release, the other links and the
other fingers clear, joints within their limits).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import FailureKind, PlanningError
from ..grasp.contact import tip_targets
from ..model.clearance import LinkClearance
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from ..verify.finger_motion import Failure, VerificationReport, verify_finger_motion
from .lift import back_off
from .timing import check_joint_speed, duration_for_move, minimum_jerk

__all__ = ["Release", "check_failure", "plan_release", "verify_or_raise"]


@dataclass(frozen=True)
class Release:
    """A verified release of ``finger`` at ``t_start`` to the end of the motion.

    Attributes:
        finger: Finger name.
        t_start: Release time [s] (the pad touches its contact there).
        t_backed_off: When the back-off ends [s].
        t_end: End of the release [s]: the motion's end, or the earlier time it was
            planned to (``until_s`` of :func:`plan_release`).
        P_object: The contact let go, object frame ``(3,)`` [m].
        times_s: ``(S,)`` sample times [s].
        q: ``(S, k)`` the finger's configurations [rad].
        min_clearance_m: Smallest distance of the finger to the object after the
            back-off [m] (Coal).
    """

    finger: str
    t_start: float
    t_backed_off: float
    t_end: float
    P_object: np.ndarray
    times_s: np.ndarray
    q: np.ndarray
    min_clearance_m: float


def plan_release(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    finger: str,
    t_release_s: float,
    P: tuple[np.ndarray, np.ndarray],
    q_release: np.ndarray,
    q_hand: Callable[[np.ndarray], np.ndarray],
    *,
    clearance_m: float,
    back_off_s: float,
    dt_s: float,
    link_clearance_m: float,
    finger_clearance_m: float,
    ik_tol_m: float,
    q_park: np.ndarray | None = None,
    park_s: float = 0.4,
    until_s: float | None = None,
) -> Release:
    """Plan and verify the release of ``finger`` at ``t_release_s`` (module docstring).

    Args:
        hand: The hand.
        obj: The object.
        motion: Its motion.
        finger: The finger that lets go.
        t_release_s: Release time [s] (before the end of the motion).
        P: Its contact ``(point, outward normal)``, object frame.
        q_release: ``(k,)`` the finger's configuration holding P at ``t_release_s``.
        q_hand: Maps times ``(S,)`` to hand configurations ``(S, nq)`` with the other
            fingers holding.
        clearance_m: How high the fingertip rises above the contact's tangent plane
            (along the normal, or tilted from it where that is out of reach) [m].
        back_off_s: Shortest duration of the back-off [s] (longer when the joint
            velocity limits need it; cut short if the motion ends first).
        dt_s: Sampling step after the back-off [s].
        link_clearance_m: Clearance of the finger's other links from the object [m].
        finger_clearance_m: Clearance from the other fingers [m].
        ik_tol_m: IK tolerance of the backed-off configuration [m].
        q_park: ``(k,)`` where the finger goes after the back-off (None: it stays).
        park_s: Shortest duration of the move to ``q_park`` [s] (longer when the joint
            velocity limits need it; cut short, unfinished, if the motion ends).
        until_s: Plan and verify the release to this time [s] (None: to the motion's
            end), for a finger that joins again by then.

    Returns:
        The verified :class:`Release`.

    Raises:
        PlanningError: the release is at the end of the motion (``too-late``), the
            backed-off position is out of reach (``ik-unreachable``), a joint would
            move faster than its limit (``velocity``) or the motion fails the Coal
            check (its kind, measured and required value).
    """
    f = hand.finger(finger)
    t_r, t_end = float(t_release_s), float(motion.t_end)
    if until_s is not None:
        t_end = min(t_end, float(until_s))
    if t_r >= t_end - 1e-9:
        raise PlanningError(
            f"a release at t={t_r:.3f} s leaves no time to back off before the motion ends",
            finger=finger,
            time_s=t_r,
            kind=FailureKind.TOO_LATE,
            measured=t_r,
            required=t_end,
        )
    T_r = motion.pose(np.array([t_r]))[0]
    p, n = np.asarray(P[0], float), np.asarray(P[1], float)
    target = tip_targets(p[None], n[None], f.tip_radius + clearance_m, T_r[None])[0, 0]
    res = f.ik(target[None], q_release, tol_m=ik_tol_m)
    if res.error_m[0] <= ik_tol_m:
        q_off = res.q[0]
    else:  # the normal is out of reach at a joint limit: a direction tilted from it
        try:
            q_off = back_off(f, T_r[None], (p, n), np.array([clearance_m]), q_release, ik_tol_m)[0]
        except PlanningError:
            raise PlanningError(
                f"cannot back off {clearance_m * 1e3:.1f} mm from the contact, along its "
                f"normal (residual {res.error_m[0] * 1e3:.2f} mm) or tilted from it",
                finger=finger,
                time_s=t_r,
                kind=FailureKind.IK_UNREACHABLE,
                measured=float(res.error_m[0]),
                required=ik_tol_m,
            ) from None
    need = duration_for_move(
        q_release,
        q_off,
        f.velocity_limit,
        minimum_s=dt_s,
        dt_s=dt_s,
        path_factor=1.0,  # a straight joint-space move
    )
    d = min(max(back_off_s, need), t_end - t_r)
    n_move = max(int(np.ceil(d / dt_s * 4)), 2)
    t_move = t_r + d * np.linspace(0.0, 1.0, n_move + 1)
    t_still = np.arange(t_move[-1] + dt_s, t_end + 1e-9, dt_s)
    times = np.concatenate([t_move, t_still])
    if times[-1] < t_end - 1e-9:  # sampled to the end, even when no still step fits
        times = np.append(times, t_end)
    s = minimum_jerk((times - t_r) / max(d, 1e-9))
    q = q_release[None] + s[:, None] * (q_off - q_release)[None]
    if q_park is not None and t_move[-1] < t_end - 1e-9:
        # as long as the joint velocity limits need (a motion that ends first ends it)
        d_park = duration_for_move(
            q_off,
            np.asarray(q_park, float),
            f.velocity_limit,
            minimum_s=park_s,
            dt_s=dt_s,
            path_factor=1.0,  # a straight joint-space move
        )
        s_park = minimum_jerk((times - t_move[-1]) / d_park)
        q = q + s_park[:, None] * (np.asarray(q_park, float) - q_off)[None]
    check_joint_speed(finger, f.joint_names, f.velocity_limit, times, q)
    q_full = q_hand(times)
    q_full[:, f.q_indices] = q
    T = motion.pose(times)
    verify_or_raise(
        "the release",
        hand,
        obj,
        finger,
        times,
        q_full,
        T,
        tip_clearance_m=0.0,
        link_clearance_m=link_clearance_m,
        finger_clearance_m=finger_clearance_m,
    )
    after = times >= t_move[-1] - 1e-9
    clear = LinkClearance(hand, finger, obj, include_tip=True)(q_full[after], T[after])
    return Release(
        finger=finger,
        t_start=t_r,
        t_backed_off=float(t_move[-1]),
        t_end=t_end,
        P_object=p.copy(),
        times_s=times,
        q=q,
        min_clearance_m=float(clear.min()),
    )


def verify_or_raise(
    what: str,
    hand: Hand,
    obj: ConvexObject,
    finger: str,
    times: np.ndarray,
    q_full: np.ndarray,
    T_palm_object: np.ndarray,
    **clearances: Any,
) -> VerificationReport:
    """Check a finger's motion with :func:`~regrasp_pin.verify.finger_motion.
    verify_finger_motion` (``clearances``: its clearance keywords) and return the
    report if it passes; else raise a PlanningError of the worst failure's kind
    (``joint-limit`` if only a joint left its limits), with its distance and the
    required one [m]; ``what`` names the motion in the message. The report's minima are
    lower bounds (``exact_minima=False``: nothing here reads them)."""
    report = verify_finger_motion(
        hand, obj, finger, times, q_full, T_palm_object, exact_minima=False, **clearances
    )
    if report.ok:
        return report
    raise check_failure(what, finger, report.worst_failure, report.time_s)


def check_failure(
    what: str, finger: str, worst: Failure | None, time_s: float | None
) -> PlanningError:
    """The PlanningError of a motion (``what``) that fails its Coal check with ``worst``
    (None: only a joint left its limits, ``joint-limit``) at ``time_s`` [s]: its kind,
    distance and the required one [m]."""
    return PlanningError(
        f"{what} fails the Coal check"
        + ("" if worst is None else f" ({worst.kind}, {worst.value * 1e3:.2f} mm)"),
        finger=finger,
        time_s=time_s,
        kind=FailureKind.JOINT_LIMIT if worst is None else worst.failure_kind,
        measured=None if worst is None else worst.value,
        required=None if worst is None else worst.required,
        other=None if worst is None else worst.other,
    )
