"""Holding fingers that come near each other.

Each holding finger follows its own contact; nothing in that keeps two holding
fingers apart while the object turns. Two fingers that close in on each other must
not both keep holding: one of them regrasps. For every pair of holding fingers (and
every holding finger and a still one: idle, or let go and parked) this finds the first
time their Coal distance falls below the trigger distance (a regrasp should start) and
below the lost distance (the hold must have ended: a regrasp that lifts off later
fails its finger-clearance check at once).

Conservative capsule bounds screen all times at once; Coal is called only where the
bound is below the trigger distance, first on every ``COARSE``-th such time and then
on the times before the first coarse hit.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..grasp.holding import Holding
from ..model.clearance import FingerClearance
from ..model.distances import capsule_gap, capsule_gaps
from ..model.hand import Hand

__all__ = ["Proximity", "clear_of_fingers", "holding_proximity"]

COARSE = 5  # Coal on every COARSE-th screened time first


@dataclass(frozen=True)
class Proximity:
    """When a holding finger comes near another holding finger.

    Attributes:
        finger: The finger.
        other: The finger it comes near.
        trigger_s: First time the distance is below the trigger distance [s].
        lost_s: First time the distance is below the lost distance [s] (inf: never).
        distance_m: The Coal distance at ``trigger_s`` [m].
    """

    finger: str
    other: str
    trigger_s: float
    lost_s: float
    distance_m: float

    @property
    def reason(self) -> str:
        """Why the hold ends, in words."""
        return f"{self.distance_m * 1e3:.2f} mm from the {self.other} finger"


class _PairDistance:
    """Exact Coal distance between two fingers' geometries at full configurations."""

    def __init__(self, hand: Hand) -> None:
        self.checks: dict[tuple[str, str], FingerClearance] = {}
        self.hand = hand

    def __call__(self, a: str, b: str, q: np.ndarray) -> float:
        fc = self.checks.get((a, b))
        if fc is None:
            fc = self.checks[(a, b)] = FingerClearance.shared(self.hand, a, others=[b])
        return fc(q)


def _first_below(
    dist: _PairDistance,
    pair: tuple[str, str],
    q: np.ndarray,
    cand: np.ndarray,
    limit_m: float,
) -> tuple[int | None, float]:
    """First index of ``cand`` (increasing rows of q) whose distance is below
    ``limit_m``, and that distance; coarse to fine."""
    prev = -1
    for c in range(0, cand.size + COARSE - 1, COARSE):
        c = min(c, cand.size - 1)
        d = dist(*pair, q[cand[c]])
        if d < limit_m:
            for f in range(prev + 1, c):
                df = dist(*pair, q[cand[f]])
                if df < limit_m:
                    return int(cand[f]), df
            return int(cand[c]), d
        prev = c
        if c == cand.size - 1:
            break
    return None, math.inf


def holding_proximity(
    hand: Hand,
    holding: Mapping[str, Holding],
    times_s: np.ndarray,
    base_q: np.ndarray,
    *,
    trigger_m: float,
    lost_m: float,
    still: Sequence[str] = (),
) -> dict[str, Proximity]:
    """The earliest proximity of each holding finger to another one over ``times_s``.

    Args:
        hand: The hand.
        holding: The fingers that hold, and their holds.
        times_s: ``(T,)`` increasing times to check [s].
        base_q: ``(nq,)`` configuration of the fingers that do not hold, or ``(T, nq)``
            one per time (a finger that let go moves while it backs off and parks).
        trigger_m: A regrasp should start below this distance [m].
        lost_m: The hold is lost below this distance [m] (< ``trigger_m``).
        still: Fingers that do not hold and are at ``base_q`` (idle, or let go):
            a holding finger that comes near one of them must regrasp too.

    Returns:
        finger -> its earliest :class:`Proximity` (fingers that stay apart are absent),
        over the times at which both fingers hold (up to where each hold's contact is
        lost, :attr:`~regrasp_pin.grasp.tracking.ContactTrack.followed_until_s`).
    """
    times = np.asarray(times_s, float)
    out: dict[str, Proximity] = {}
    if times.size == 0:
        return out
    q = np.broadcast_to(base_q, (times.size, hand.model.nq)).copy()
    for n, h in holding.items():
        q[:, hand.fingers[n].q_indices] = h.q_at(times)
    dist = _PairDistance(hand)
    pairs = list(itertools.combinations(sorted(holding), 2)) + [
        (a, b) for a in sorted(holding) for b in sorted(set(still) - set(holding))
    ]
    # a pair is checked while both hold: a hold ends where its contact is lost (its
    # track is not followed further)
    until = {n: h.track.followed_until_s for n, h in holding.items()}
    for a, b in pairs:
        ids = (list(hand.fingers[a].geometry_ids), list(hand.fingers[b].geometry_ids))
        held = np.flatnonzero(times <= min(until[a], until.get(b, math.inf)) + 1e-9)
        cand = held[capsule_gap(hand, *ids, q[held], cap_m=trigger_m) < trigger_m]
        if cand.size == 0:
            continue
        i_trig, d_trig = _first_below(dist, (a, b), q, cand, trigger_m)
        if i_trig is None:
            continue
        later = cand[cand >= i_trig]
        i_lost, _ = _first_below(dist, (a, b), q, later, lost_m)
        lost = math.inf if i_lost is None else float(times[i_lost])
        for me, other in ((a, b), (b, a)) if b in holding else ((a, b),):
            p = Proximity(me, other, float(times[i_trig]), lost, d_trig)
            if me not in out or (p.trigger_s, p.other) < (out[me].trigger_s, out[me].other):
                out[me] = p
    return out


def clear_of_fingers(
    hand: Hand,
    finger: str,
    q_finger: np.ndarray,
    q_hand: np.ndarray,
    others: list[str],
    limit_m: float,
    horizon: np.ndarray | None = None,
) -> np.ndarray:
    """Where a finger's candidate contacts stay clear of the other fingers over time.

    Args:
        hand: The hand.
        finger: The finger.
        q_finger: ``(K, C, k)`` the finger's configurations at ``K`` times for ``C``
            candidates [rad] (NaN rows count as clear: they are not usable anyway).
        q_hand: ``(K, nq)`` the hand at those times (the others holding).
        others: The fingers to keep clear of.
        limit_m: Smallest distance [m].
        horizon: Optional ``(C,)`` how many of the first times to check per candidate
            (the caller reads nothing later); the times from there on are not
            measured and come out True. None: all ``K``.

    Returns:
        ``(K, C)`` bool: False from the first time (per candidate) at which the finger
        comes closer than ``limit_m`` to one of ``others`` (capsule screen, then Coal).
    """
    K, C, _ = q_finger.shape
    h = np.full(C, K) if horizon is None else np.clip(np.asarray(horizon, int), 0, K)
    f = hand.fingers[finger]
    q = np.repeat(q_hand[None], C, axis=0)  # (C, K, nq)
    qf = np.transpose(q_finger, (1, 0, 2))
    q[..., f.q_indices] = np.where(np.isfinite(qf), qf, f.q_mid)
    # the (candidate, time) rows to measure: each candidate's first h[c] times
    c_of = np.repeat(np.arange(C), h)
    k_of = np.arange(c_of.size) - np.repeat(np.cumsum(h) - h, h)
    # the finger is placed once for all the others, and the other fingers once per
    # time, not once per (candidate, time) (the same bounds, bit for bit)
    gaps = capsule_gaps(
        hand,
        list(f.geometry_ids),
        [list(hand.fingers[o].geometry_ids) for o in others],
        q[c_of, k_of],
        cap_m=limit_m,
        q_b=q_hand,
        rows_b=k_of,
    )
    ok = np.ones((C, K), bool)
    dist = _PairDistance(hand)
    for o, gap in zip(others, gaps, strict=True):
        near = np.zeros((C, K), bool)
        near[c_of, k_of] = gap < limit_m
        for c in np.flatnonzero(near.any(axis=1)):
            cand = np.flatnonzero(near[c] & ok[c])
            if cand.size == 0:
                continue
            i, _ = _first_below(dist, (finger, o), q[c], cand, limit_m)
            if i is not None:
                ok[c, i:] = False
    return ok.T
