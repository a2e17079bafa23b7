"""Following a held contact through the object's motion, and the regrasp trigger.

While a finger holds a contact, the contact point ``P`` is fixed in the object frame;
its tip-centre target ``T_palm_object(t) (P + r n)`` moves with the object, and the
finger follows it by IK (warm-started from one time to the next). The *trigger* is the
first time P comes within ``limit_margin_rad`` of a boundary plane of the joint box,
or stops being feasible (IK fails, the pad turns away beyond the cone, or another link
of the finger comes within ``link_clearance_m`` of the object) -- the moment the
paper's contact point "meets one of the boundary planes".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array
from ..exceptions import InputError
from ..model.clearance import LinkClearance
from ..model.follow_on import fastest_share, follow_on
from ..model.hand import Finger, Hand, speed_shares
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from .contact import ContactModel, pad_cosines, tip_targets
from .settle import TURN_SPEED_SHARE, settle_tip_link, sinking

__all__ = ["ContactTrack", "track_contact"]


@dataclass(frozen=True)
class ContactTrack:
    """A contact followed over a time grid.

    Attributes:
        finger: Finger name.
        times_s: ``(T,)`` times [s].
        p_object: Contact point, object frame ``(3,)`` [m].
        n_object: Outward normal at the contact, object frame ``(3,)``.
        q: ``(T, k)`` finger configurations [rad] (always within the limits).
        error_m: ``(T,)`` IK residual [m].
        margin_rad: ``(T,)`` distance to the nearest boundary plane [rad].
        pad_cos: ``(T,)`` cosine between the pad direction and the inward normal.
        cos_cone: The cosine of the finger's pad cone the contact was followed with
            (:meth:`~regrasp_pin.grasp.contact.ContactModel.cos_cone_of`): below it,
            the pad has turned away.
        link_clearance_m: ``(T,)`` Coal distance of the finger's non-tip links to the
            object [m] (``inf`` where not computed).
        tip_clearance_m: ``(T,)`` Coal distance of the fingertip link's geometries to
            the object [m] (about 0 at a contact; ``inf`` where not computed).
        reasons: ``(T,)`` why each time is not holdable ("" where it is).
        n_followed: How many of the times were followed (None: all).
        speed_share: ``(T,)`` how fast the fastest joint moves into each time's
            configuration from the time before's, as a share of its velocity limit
            (0 at the first time and after the contact is lost; above 1 the finger
            cannot follow); None: not measured.

    The contact is followed until it is lost (not reached, a joint that cannot follow it
    within its velocity limit, outside the joint limits, or the pad turned away beyond
    the cone): after that time, ``q`` repeats its last
    configuration, ``error_m`` is ``inf``, ``margin_rad`` and ``pad_cos`` are ``-inf``,
    the clearances ``inf`` (not computed), and every time is not holdable.
    """

    finger: str
    times_s: np.ndarray
    p_object: np.ndarray
    n_object: np.ndarray
    q: np.ndarray
    error_m: np.ndarray
    margin_rad: np.ndarray
    pad_cos: np.ndarray
    cos_cone: float
    link_clearance_m: np.ndarray
    reasons: tuple[str, ...]
    tip_clearance_m: np.ndarray | None = None
    n_followed: int | None = None
    speed_share: np.ndarray | None = None

    @property
    def followed_until_s(self) -> float:
        """The last time [s] followed: where the contact is lost, or the last time."""
        n = len(self.times_s) if self.n_followed is None else self.n_followed
        return float(self.times_s[n - 1])

    @property
    def cannot_follow(self) -> np.ndarray:
        """``(T,)`` True where a joint would have to move faster than its velocity limit
        to follow the contact from the time before (:attr:`speed_share` above 1)."""
        if self.speed_share is None:
            return np.zeros(len(self.times_s), bool)
        return np.asarray(self.speed_share) > 1.0

    def lost(self, contact: ContactModel) -> np.ndarray:
        """``(T,)`` True where the contact is lost under ``contact``'s IK tolerance: not
        reached, a joint that cannot follow it, outside the joint limits or the pad
        turned away (the conditions that end every hold; not the links nor the trigger
        margin)."""
        speed = np.zeros(len(self.times_s)) if self.speed_share is None else self.speed_share
        return _lost(self.error_m, speed, self.margin_rad, self.pad_cos, contact, self.cos_cone)

    @property
    def holdable(self) -> np.ndarray:
        """``(T,)`` True where the contact can be held (no trigger condition)."""
        return np.array([r == "" for r in self.reasons])

    def trigger_index(self) -> int | None:
        """Index of the first time the contact cannot be held, or None."""
        bad = np.flatnonzero(~self.holdable)
        return int(bad[0]) if bad.size else None

    def trigger(self) -> tuple[float | None, str]:
        """``(time [s], reason)`` of the first trigger, or ``(None, "")``."""
        i = self.trigger_index()
        return (None, "") if i is None else (float(self.times_s[i]), self.reasons[i])


def track_contact(
    hand: Hand,
    finger: str,
    obj: ConvexObject,
    motion: ObjectMotion,
    times_s: np.ndarray,
    p_object: np.ndarray,
    n_object: np.ndarray,
    q_start: np.ndarray,
    *,
    contact: ContactModel | None = None,
    check_links: bool = True,
    chunk: int = 8,
) -> ContactTrack:
    """Follow a contact fixed in the object frame and find when it must be let go.

    Args:
        hand: The hand.
        finger: Finger name.
        obj: The object.
        motion: Object motion ``T_palm_object(t)``.
        times_s: ``(T,)`` increasing times [s].
        p_object: Contact point, object frame ``(3,)`` [m].
        n_object: Outward unit normal there, object frame ``(3,)``.
        q_start: ``(k,)`` finger configuration near the solution at ``times_s[0]``.
        contact: Contact model (tolerances, cone, trigger margin).
        check_links: Measure link-object clearance with Coal at every time.
        chunk: Times solved per IK batch, each chunk warm-started from the last
            solution of the previous one.

    Returns:
        The :class:`ContactTrack`, followed until the contact is lost (see there).
    """
    contact = contact or ContactModel()
    f = hand.finger(finger)
    times = as_array(times_s, "times_s", (None,))
    if times.size == 0 or np.any(np.diff(times) <= 0):
        raise InputError("times_s", "is empty or not strictly increasing", "increasing times [s]")
    p = as_array(p_object, "p_object", (3,))
    n = as_array(n_object, "n_object", (3,))
    q0 = as_array(q_start, "q_start", (f.k,))
    T_all = motion.pose(times)
    targets = tip_targets(p[None], n[None], f.tip_radius, T_all)[:, 0]  # (T, 3)
    n_palm = T_all[:, :3, :3] @ n
    q = np.empty((times.size, f.k))
    err = np.empty(times.size)
    margin = np.empty(times.size)
    pad_cos = np.empty(times.size)
    speed = np.zeros(times.size)  # the fastest joint's share of its velocity limit
    cos_cone = contact.cos_cone_of(f)
    lost_at = times.size - 1  # the last time followed
    prev = q0
    # a joint moves at most as far as its velocity limit takes it in one time step
    # (at the first time none: q_start is the configuration at that very time)
    step_s = np.diff(times, prepend=times[0])
    for s0 in range(0, times.size, chunk):
        s1 = min(s0 + chunk, times.size)
        res = f.ik(targets[s0:s1], prev, tol_m=contact.ik_tol_m)
        q[s0:s1], err[s0:s1] = res.q, res.error_m
        # a joint that jumps (another branch of a spare joint's solutions) is solved
        # again from the time before: the jump is the batch's, not the hold's limit
        follow_on(f, q[s0:s1], err[s0:s1], targets[s0:s1], prev, step_s[s0:s1], contact.ik_tol_m)
        _settle_chunk(f, q, err, targets, n_palm, s0, s1, prev, step_s, contact)  # grasp.settle
        margin[s0:s1] = f.limit_margin(q[s0:s1])
        pad_cos[s0:s1] = pad_cosines(f, q[s0:s1], n_palm[s0:s1])
        # the first time is where the track starts (its own configuration): no speed
        speed[s0:s1] = fastest_share(f, q[s0:s1], q[s0 - 1] if s0 else q[0], step_s[s0:s1])
        prev = q[s1 - 1]
        lost = _lost(err[s0:s1], speed[s0:s1], margin[s0:s1], pad_cos[s0:s1], contact, cos_cone)
        if lost.any():
            lost_at = s0 + int(np.argmax(lost))
            break
    # not followed after the contact is lost: no IK (a restart at every later time
    # would cost most of the track) and no Coal
    after = slice(lost_at + 1, None)
    q[after], err[after], margin[after], pad_cos[after] = q[lost_at], np.inf, -np.inf, -np.inf
    speed[after] = 0.0
    clearance = np.full(times.size, np.inf)
    tip_clear = np.full(times.size, np.inf)
    if check_links:
        q_full = hand.to_full(finger, q[: lost_at + 1])
        T_held = T_all[: lost_at + 1]
        clearance[: lost_at + 1] = LinkClearance(hand, finger, obj)(q_full, T_held)
        tip_clear[: lost_at + 1] = LinkClearance(hand, finger, obj, tip_only=True)(q_full, T_held)
    reasons = _reasons(
        f, times, lost_at, q, (err, speed, margin, pad_cos, clearance, tip_clear), contact
    )
    return ContactTrack(
        finger=finger,
        times_s=times,
        p_object=p,
        n_object=n,
        q=q,
        error_m=err,
        margin_rad=margin,
        pad_cos=pad_cos,
        cos_cone=cos_cone,
        link_clearance_m=clearance,
        reasons=tuple(reasons),
        tip_clearance_m=tip_clear,
        n_followed=lost_at + 1,
        speed_share=speed,
    )


def _reasons(
    f: Finger,
    times: np.ndarray,
    lost_at: int,
    q: np.ndarray,
    measured: tuple[np.ndarray, ...],
    contact: ContactModel,
) -> list[str]:
    """Why each time of a track is not holdable ("" where it is), from what was
    ``measured`` there: ``(error_m, speed share, margin_rad, pad_cos, link clearance,
    tip clearance)`` ``(T,)`` each."""
    reasons = []
    err, speed, margin, pad_cos, clearance, tip_clear = measured
    cos_cone = contact.cos_cone_of(f)
    for i in range(times.size):
        if i > lost_at:
            reasons.append(f"not followed after the contact is lost at t={times[lost_at]:.3f} s")
        elif err[i] > contact.ik_tol_m:
            reasons.append(f"IK cannot reach the contact (residual {err[i] * 1e3:.2f} mm)")
        elif speed[i] > 1.0:  # never at i = 0
            step = speed_shares(
                (q[i] - q[i - 1])[None], times[i : i + 1] - times[i - 1], f.velocity_limit
            )
            j = int(np.argmax(step[0]))
            reasons.append(
                f"joint {f.joint_names[j]} cannot follow it "
                f"({speed[i]:.2f}x its velocity limit {f.velocity_limit[j]:.2f} rad/s)"
            )
        elif margin[i] < contact.limit_margin_rad:
            j = int(np.argmin(np.minimum(q[i] - f.lower, f.upper - q[i])))
            side = "lower" if q[i, j] - f.lower[j] < f.upper[j] - q[i, j] else "upper"
            reasons.append(
                f"joint {f.joint_names[j]} within {margin[i]:.3f} rad of its {side} limit"
            )
        elif pad_cos[i] < cos_cone:
            ang = np.degrees(np.arccos(np.clip(pad_cos[i], -1, 1)))
            reasons.append(f"pad turned {ang:.0f} deg from the surface normal")
        elif clearance[i] < contact.link_clearance_m:
            reasons.append(
                f"a link of the finger comes within {contact.link_clearance_m * 1e3:.2f} mm "
                f"of the object ({clearance[i] * 1e3:.2f} mm)"
            )
        elif tip_clear[i] < -contact.tip_penetration_m:
            reasons.append(
                f"the fingertip link sinks into the object ({-tip_clear[i] * 1e3:.2f} mm)"
            )
        else:
            reasons.append("")
    return reasons


def _settle_chunk(
    f: Finger,
    q: np.ndarray,
    err: np.ndarray,
    targets: np.ndarray,
    n_palm: np.ndarray,
    s0: int,
    s1: int,
    prev: np.ndarray,
    step_s: np.ndarray,
    contact: ContactModel,
) -> None:
    """Turn the fingertip link off the face at times ``s0:s1`` with the finger's spare
    joints (:func:`~.settle.settle_tip_link`), in place, time by time: each time's
    configuration within :data:`~.settle.TURN_SPEED_SHARE` of what the velocity limits
    allow over ``step_s[i]`` [s] (the time since the time before) of the time before's
    (``prev`` before ``s0``), and re-solved from it by IK once a time before was turned,
    so that the turn carries on; the pad kept within its cone and the joints off the
    trigger's margin where they were."""
    sink = sinking(f, q[s0:s1], n_palm[s0:s1])
    if not sink.any():
        return
    last = prev
    turned = False
    cos_cone = contact.cos_cone_of(f)
    for i in range(s0, s1):
        if err[i] > contact.ik_tol_m:
            break  # lost here; the caller stops
        if turned:  # follow on from the turned configuration
            res = f.ik(targets[i][None], last, tol_m=contact.ik_tol_m, restarts=False)
            if res.success[0]:
                q[i], err[i] = res.q[0], res.error_m[0]
        elif not sink[i - s0]:  # as the IK left it, not sinking: nothing to turn
            last = q[i]
            continue
        row = settle_tip_link(
            f,
            q[i][None],
            targets[i][None],
            n_palm[i][None],
            ik_tol_m=contact.ik_tol_m,
            around=last[None],
            max_change_rad=TURN_SPEED_SHARE * f.velocity_limit * step_s[i],
            cos_cone=cos_cone,
            margin_rad=contact.limit_margin_rad,
        )[0]
        if not np.array_equal(row, q[i]):
            q[i], err[i] = row, float(np.linalg.norm(f.fk(row) - targets[i]))
            turned = True
        last = q[i]


def _lost(
    err: np.ndarray,
    speed: np.ndarray,
    margin: np.ndarray,
    pad_cos: np.ndarray,
    contact: ContactModel,
    cos_cone: float,
) -> np.ndarray:
    """Where the contact is lost: not reached, a joint that cannot follow it within its
    velocity limit (``speed``: :func:`~regrasp_pin.model.follow_on.fastest_share`),
    outside the joint limits, or the pad turned away beyond the cone (the conditions
    that end every hold; the links and the trigger margin come on top of them)."""
    return (err > contact.ik_tol_m) | (speed > 1.0) | (margin < 0.0) | (pad_cos < cos_cone)
