"""Fingers that hold: a contact fixed in the object frame, followed by IK.

While a finger holds, its contact is fixed in the object frame and the finger follows
it through the object's motion (:func:`~.tracking.track_contact`). This module keeps
one such hold per finger and phase, places a holding finger exactly at any time (the
configurations the verification and the plan file use), builds the ``q_hand``
callables that :func:`~.regrasp.plan_regrasp` needs, and parks idle fingers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model.clearance import LinkClearance
from ..model.distances import object_gap_bound
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from .contact import ContactModel, tip_targets
from .initial import Grasp
from .tracking import ContactTrack, track_contact

__all__ = [
    "Holding",
    "holding_hand",
    "holding_q",
    "holds_to_end",
    "rest_configuration",
    "start_holding",
]


_SOLVED_KEPT = 64  # holding_q answers kept per hold
#: A face-plane lower bound may exceed Coal's distance by Coal's tolerance (about
#: 1e-6 m): a pose whose bound is this far above a measured distance cannot be nearer.
_BOUND_SLACK_M = 1e-5


@dataclass
class Holding:
    """A finger holding a contact from ``t_from`` (to ``t_to``, None while held).

    Attributes:
        p: Contact point, object frame ``(3,)`` [m].
        n: Outward normal at the contact, object frame ``(3,)``.
        t_from: Start of the hold [s].
        track: The contact followed over the rest of the motion.
        t_to: End of the hold [s] (the lift-off of the next regrasp), or None.
        solved: The configurations :func:`holding_q` solved for this hold, by its
            arguments (shared by copies of the hold; bounded).
    """

    p: np.ndarray
    n: np.ndarray
    t_from: float
    track: ContactTrack
    t_to: float | None = None
    solved: dict[tuple, tuple[Any, Any, np.ndarray]] = field(
        default_factory=dict, repr=False, compare=False
    )

    def q_at(self, times: np.ndarray) -> np.ndarray:
        """The track's configurations ``(S, k)`` interpolated at ``times`` [rad]."""
        tr = self.track
        return np.stack(
            [np.interp(times, tr.times_s, tr.q[:, j]) for j in range(tr.q.shape[1])], axis=1
        )


def start_holding(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    grid: np.ndarray,
    name: str,
    p: np.ndarray,
    n: np.ndarray,
    q_start: np.ndarray,
    t_from: float,
    contact: ContactModel,
) -> Holding:
    """Follow a new contact from ``t_from`` over the later times of ``grid``."""
    times = np.concatenate([[t_from], grid[grid > t_from + 1e-9]])
    if times.size < 2:
        # a hold that starts at (or within float noise of) the motion's end: a two-sample
        # track that stays inside the motion
        t_from = min(t_from, motion.t_end)
        times = (
            np.array([t_from, motion.t_end])
            if motion.t_end > t_from + 1e-9
            else np.array([t_from - 1e-6, t_from])
        )
    track = track_contact(hand, name, obj, motion, times, p, n, q_start, contact=contact)
    return Holding(p=np.asarray(p, float), n=np.asarray(n, float), t_from=t_from, track=track)


def holds_to_end(track: ContactTrack, t_from: float, contact: ContactModel) -> bool:
    """Whether a contact stays reached, inside the joint limits (margin >= 0), pad facing
    and links clear from ``t_from`` to the end of its track."""
    sel = track.times_s >= t_from - 1e-9
    return bool(
        np.all(track.error_m[sel] <= contact.ik_tol_m)
        and np.all(track.margin_rad[sel] >= 0.0)
        and np.all(track.pad_cos[sel] >= track.cos_cone)
        and np.all(track.link_clearance_m[sel] >= 0.0)
    )


def holding_q(
    hand: Hand, motion: ObjectMotion, name: str, h: Holding, times: np.ndarray, tol_m: float
) -> np.ndarray:
    """Exact IK of a holding finger at arbitrary times (warm from its track); after its
    contact is lost (where the track stops, :attr:`.ContactTrack.followed_until_s`), the
    finger stays where it lost it.

    The planner asks for the same hold at the same times again and again (each choice
    of a new contact, each path variant): the answer to the same arguments is kept in
    :attr:`Holding.solved` and returned again (a copy), the same bits."""
    times = np.asarray(times, float)
    key = (id(hand), id(motion), name, float(tol_m), times.shape, times.tobytes())
    known = h.solved.get(key)
    if known is not None and known[0] is hand and known[1] is motion:
        return known[2].copy()
    f = hand.fingers[name]
    q = h.q_at(times)
    held = np.flatnonzero(times <= h.track.followed_until_s + 1e-9)
    if held.size:
        T = motion.pose(times[held])
        targets = tip_targets(h.p[None], h.n[None], f.tip_radius, T)[:, 0]
        q[held] = f.ik(targets, q[held], tol_m=tol_m).q
    if len(h.solved) >= _SOLVED_KEPT:
        h.solved.pop(next(iter(h.solved)), None)  # the oldest
    h.solved[key] = (hand, motion, q.copy())  # hand and motion alive: their ids stay theirs
    return q


def rest_configuration(
    hand: Hand, obj: ConvexObject, motion: ObjectMotion, idle: list[str]
) -> np.ndarray:
    """Full configuration ``(nq,)`` with the idle fingers where they stay clearest of
    the object over the motion (Coal), chosen among a few fixed postures; the other
    fingers at the middle of their limits.
    """
    q = hand.neutral()
    if not idle:
        return q
    T = motion.pose(np.linspace(motion.t_start, motion.t_end, 7))
    for name in idle:
        f = hand.fingers[name]
        fr = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
        grid = np.stack(np.meshgrid(*[fr] * f.k, indexing="ij"), -1).reshape(-1, f.k)
        postures = f.lower + grid * (f.upper - f.lower)
        lc = LinkClearance(hand, name, obj, include_tip=True)
        best = _clearest(hand, obj, lc, hand.to_full(name, postures, q), T)
        q[f.q_indices] = f.q_mid if best is None else postures[best]
    return q


def _clearest(
    hand: Hand, obj: ConvexObject, clearance: LinkClearance, full: np.ndarray, T: np.ndarray
) -> int | None:
    """Index of the first posture (full configurations ``full`` ``(M, nq)``) whose
    smallest ``clearance`` distance [m] to ``obj`` over the poses ``T`` ``(P, 4, 4)``
    exceeds every earlier one's by more than 1e-6 m (None: no posture).

    The lower bounds of every (posture, pose) come in one batch; Coal measures a
    posture's poses lowest bound first, only until no pose left can be nearer or the
    posture can no longer beat the best: the same answer as measuring them all."""
    lb = object_gap_bound(
        hand,
        clearance.geometry_ids,
        obj,
        np.repeat(full, len(T), axis=0),
        np.tile(T, (len(full), 1, 1)),
    ).reshape(len(full), len(T))
    best, best_d = None, -np.inf
    for m, (row, bounds) in enumerate(zip(full, lb, strict=True)):
        d = np.inf
        for t in np.argsort(bounds, kind="stable"):
            if bounds[t] >= d + _BOUND_SLACK_M or d <= best_d + 1e-6:
                break
            d = min(d, float(clearance(row[None], T[t])[0]))
        if d > best_d + 1e-6:
            best, best_d = m, d
    return best


def holding_hand(
    hand: Hand,
    motion: ObjectMotion,
    grasp: Grasp,
    fingers: tuple[str, ...] | list[str],
    moving: str,
) -> Callable[[np.ndarray], np.ndarray]:
    """A ``q_hand(times) -> (S, nq)`` for :func:`~.regrasp.plan_regrasp`: every finger of
    ``fingers`` but ``moving`` holds its ``grasp`` contact (exact IK at every time, warm
    from the grasp configuration); the others stay at the middle of their limits."""

    def q_hand(times: np.ndarray) -> np.ndarray:
        times = np.atleast_1d(np.asarray(times, float))
        q = np.broadcast_to(hand.neutral(), (times.size, hand.model.nq)).copy()
        T = motion.pose(times)
        for n in fingers:
            if n == moving:
                continue
            f = hand.fingers[n]
            p, nrm = grasp.points_object[n][None], grasp.normals_object[n][None]
            q[:, f.q_indices] = f.ik(tip_targets(p, nrm, f.tip_radius, T)[:, 0], grasp.q[n]).q
        return q

    return q_hand
