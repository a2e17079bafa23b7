"""A finger that does not hold joins the grasp: from where it rests to a new contact Q.

A finger whose contacts run out of its workspace (the object has turned away from it)
lets go (:mod:`.release`); a finger that did not take part so far, or one that let go
earlier and whose contacts are back within reach, can take its place.
The joining finger moves in joint space (minimum jerk) from its configuration at
``t_start`` to a pre-landing configuration whose fingertip is ``clearance`` above Q
along Q's normal, then approaches Q along that normal (the target moves with the
object, the offset shrinks by minimum jerk) and touches it at ``t_end``. The motion is
verified with Coal like every regrasp
(:func:`~regrasp_pin.verify.finger_motion.verify_finger_motion`: the fingertip and the
other links clear of the object, the other fingers clear, joints within limits) and
its joint speeds are checked against the velocity limits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..exceptions import FailureKind, InputError, PlanningError
from ..model.clearance import LinkClearance
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from .release import verify_or_raise
from .timing import check_joint_speed, durations_for_moves, minimum_jerk

__all__ = ["Join", "join_duration", "join_durations", "plan_join"]


@dataclass(frozen=True)
class Join:
    """A verified move of an idle ``finger`` onto contact Q.

    Attributes:
        finger: Finger name.
        t_start: When the finger starts to move [s].
        t_end: When its pad touches Q [s].
        Q_object: The new contact, object frame ``(3,)`` [m].
        n_Q_object: Its outward normal, object frame ``(3,)``.
        times_s: ``(S,)`` sample times [s].
        q: ``(S, k)`` the finger's configurations [rad].
        min_clearance_m: Smallest finger-object distance before the approach [m]
            (Coal).
    """

    finger: str
    t_start: float
    t_end: float
    Q_object: np.ndarray
    n_Q_object: np.ndarray
    times_s: np.ndarray
    q: np.ndarray
    min_clearance_m: float


def plan_join(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    finger: str,
    t_start_s: float,
    q_from: np.ndarray,
    Q: tuple[np.ndarray, np.ndarray],
    q_land: np.ndarray,
    q_hand: Callable[[np.ndarray], np.ndarray],
    *,
    duration_s: float,
    approach_s: float,
    clearance_m: float,
    dt_s: float,
    link_clearance_m: float,
    finger_clearance_m: float,
    ik_tol_m: float,
) -> Join:
    """Plan and verify ``finger``'s move onto ``Q`` from ``q_from`` at ``t_start_s``.

    Args:
        hand: The hand.
        obj: The object.
        motion: Its motion.
        finger: The joining finger.
        t_start_s: When it starts to move [s].
        q_from: ``(k,)`` its configuration then [rad].
        Q: The new contact ``(point, outward normal)``, object frame.
        q_land: ``(k,)`` a configuration near the landing one (IK seed) [rad].
        q_hand: Maps times ``(S,)`` to hand configurations ``(S, nq)`` with the other
            fingers where they are then.
        duration_s: From the start to the touch [s] (see :func:`join_duration`).
        approach_s: Duration of the final approach along Q's normal [s], shorter
            than ``duration_s``.
        clearance_m: The approach starts this far above Q [m].
        dt_s: Durations are multiples of this step [s].
        link_clearance_m: Clearance of the finger's other links from the object [m].
        finger_clearance_m: Clearance from the other fingers [m].
        ik_tol_m: IK tolerance of the approach [m].

    Returns:
        The verified :class:`Join`.

    Raises:
        InputError: ``approach_s`` not shorter than ``duration_s``.
        PlanningError: the approach is out of reach (``ik-unreachable``), a joint would
            exceed its velocity limit (``velocity``), the motion ends before the
            landing (``too-late``), or the Coal check fails (its kind and numbers).
    """
    f = hand.finger(finger)
    p, n = np.asarray(Q[0], float), np.asarray(Q[1], float)
    q_from = np.asarray(q_from, float)
    t0 = float(t_start_s)
    n_app = max(int(np.ceil(approach_s / dt_s * 4)), 4)
    tau = np.linspace(0.0, 1.0, n_app + 1)
    offset = f.tip_radius + clearance_m * (1.0 - minimum_jerk(tau))
    if not 0.0 < approach_s < duration_s:
        raise InputError("approach_s", f"{approach_s!r} is not allowed", f"in (0, {duration_s!r})")
    transfer = duration_s - approach_s
    t_land = t0 + duration_s
    if t_land > motion.t_end + 1e-9:
        raise PlanningError(
            f"joining would land at t={t_land:.3f} s, after the motion ends",
            finger=finger,
            time_s=t0,
            kind=FailureKind.TOO_LATE,
            measured=t_land,
            required=float(motion.t_end),
        )
    t_app = t_land - approach_s + approach_s * tau
    T = motion.pose(t_app)
    tips = np.einsum("sij,j->si", T[:, :3, :3], p) + T[:, :3, 3]
    tips += offset[:, None] * np.einsum("sij,j->si", T[:, :3, :3], n)
    q_app = np.empty((tau.size, f.k))
    seed = np.asarray(q_land, float)
    for i in range(tau.size - 1, -1, -1):  # from the landing back up, warm started
        res = f.ik(tips[i], seed, tol_m=ik_tol_m)
        if res.error_m[0] > ik_tol_m:
            raise PlanningError(
                f"cannot approach Q along its normal (residual {res.error_m[0] * 1e3:.2f} mm "
                f"at {offset[i] * 1e3 - f.tip_radius * 1e3:.1f} mm above it)",
                finger=finger,
                time_s=float(t_app[i]),
                kind=FailureKind.IK_UNREACHABLE,
                measured=float(res.error_m[0]),
                required=ik_tol_m,
            )
        q_app[i] = seed = res.q[0]
    n_move = max(int(np.ceil(transfer / dt_s * 4)), 2)
    t_move = t0 + transfer * np.linspace(0.0, 1.0, n_move + 1)
    s = minimum_jerk(np.linspace(0.0, 1.0, n_move + 1))
    q_move = q_from[None] + s[:, None] * (q_app[0] - q_from)[None]
    times = np.concatenate([t_move, t_app[1:]])
    q = np.vstack([q_move, q_app[1:]])
    check_joint_speed(finger, f.joint_names, f.velocity_limit, times, q)
    q_full = q_hand(times)
    q_full[:, f.q_indices] = q
    T_all = motion.pose(times)
    tip_req = np.where(times < t_app[0] - 1e-9, 0.5 * clearance_m, 0.0)
    verify_or_raise(
        "the join",
        hand,
        obj,
        finger,
        times,
        q_full,
        T_all,
        tip_clearance_m=tip_req,
        link_clearance_m=link_clearance_m,
        finger_clearance_m=finger_clearance_m,
    )
    before = times <= t_app[0] + 1e-9
    clear = LinkClearance(hand, finger, obj, include_tip=True)(q_full[before], T_all[before])
    return Join(
        finger=finger,
        t_start=t0,
        t_end=float(t_land),
        Q_object=p.copy(),
        n_Q_object=n.copy(),
        times_s=times,
        q=q,
        min_clearance_m=float(clear.min()),
    )


def join_duration(
    q_from: np.ndarray,
    q_land: np.ndarray,
    velocity_limit: np.ndarray,
    *,
    minimum_s: float,
    approach_s: float,
    dt_s: float,
) -> float:
    """The duration [s] of a join from ``q_from`` to about ``q_land`` [rad]: a transfer
    that keeps the joints under ``velocity_limit`` [rad/s]
    (:func:`~.timing.duration_for_move`), then the approach, at least ``minimum_s``."""
    q_land = np.asarray(q_land, float)
    return float(
        join_durations(
            q_from,
            q_land[None],
            velocity_limit,
            minimum_s=minimum_s,
            approach_s=approach_s,
            dt_s=dt_s,
        )[0]
    )


def join_durations(
    q_from: np.ndarray,
    q_land: np.ndarray,
    velocity_limit: np.ndarray,
    *,
    minimum_s: float,
    approach_s: float,
    dt_s: float,
) -> np.ndarray:
    """:func:`join_duration` [s] to each row of ``q_land`` ``(C, k)`` [rad]: ``(C,)``."""
    transfer = durations_for_moves(
        q_from, q_land, velocity_limit, minimum_s=max(minimum_s - approach_s, dt_s), dt_s=dt_s
    )
    return transfer + approach_s
