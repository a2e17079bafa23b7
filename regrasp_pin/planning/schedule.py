"""When a finger may lift off: its window, and the start times tried in it.

A held contact *triggers* when it comes within ``ContactModel.limit_margin_rad`` of a
boundary plane (or stops being feasible). The finger may lift off before that, but not
before it started holding nor while another finger is in the air; and it may lift off
*after* the trigger as long as the contact is still held inside the joint limits
themselves (margin >= 0, reached, pad facing, links clear). Start times are tried from
the preferred one outwards, earlier and later in turn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import positive
from ..grasp.contact import ContactModel
from ..grasp.tracking import ContactTrack

__all__ = [
    "Chain",
    "LiftOffWindow",
    "held_until",
    "lift_off_window",
    "regrasp_chain",
    "start_times",
]

TIME_TOL_S = 1e-9  # times closer than this are the same time


@dataclass(frozen=True)
class LiftOffWindow:
    """The times at which one finger may lift off [s].

    Attributes:
        finger: Finger name.
        trigger_s: When the contact comes within the trigger margin of a limit.
        earliest_s: No lift-off before this (hold start, or another finger in the air).
        latest_s: The contact is held inside the joint limits until this time.
        preferred_s: The first start time tried.
    """

    finger: str
    trigger_s: float
    earliest_s: float
    latest_s: float
    preferred_s: float

    @property
    def empty(self) -> bool:
        """True when no lift-off time fits (the latest is before the earliest)."""
        return self.latest_s < self.earliest_s - TIME_TOL_S


def held_until(track: ContactTrack, contact: ContactModel) -> float:
    """Last track time [s] up to which the contact is held inside the joint limits
    (margin >= 0), reached within the velocity limits, pad facing, with the links clear
    and the fingertip link not sunk in, without a break."""
    ok = (
        (track.error_m <= contact.ik_tol_m)
        & ~track.cannot_follow
        & (track.margin_rad >= 0.0)
        & (track.pad_cos >= track.cos_cone)
        & (track.link_clearance_m >= 0.0)
        & (
            True
            if track.tip_clearance_m is None
            else track.tip_clearance_m >= -contact.tip_penetration_m
        )
    )
    bad = np.flatnonzero(~ok)
    if bad.size == 0:
        return float(track.times_s[-1])
    return float(track.times_s[max(int(bad[0]) - 1, 0)])


def lift_off_window(
    finger: str,
    track: ContactTrack,
    trigger_s: float,
    *,
    earliest_s: float,
    lead_s: float,
    contact: ContactModel,
    lost_s: float = float("inf"),
) -> LiftOffWindow:
    """The lift-off window of a finger whose contact triggers at ``trigger_s`` [s];
    ``lost_s`` is a further end of the hold (e.g. another finger too near) [s]."""
    latest = max(min(held_until(track, contact), lost_s), float(track.times_s[0]))
    preferred = min(max(trigger_s - lead_s, earliest_s), latest)
    return LiftOffWindow(finger, float(trigger_s), float(earliest_s), latest, preferred)


@dataclass(frozen=True)
class Chain:
    """The regrasps that holds ending before the motion does force, one finger in the
    air at a time, earliest loss first.

    Attributes:
        order: The fingers, earliest loss first (ties by name).
        latest_start_s: The first of them must lift off by this time [s] so that each
            later one still holds when its turn comes (``-inf`` for no finger).
        land_by_s: The first must have landed by this time [s] for the same reason
            (``inf`` when it is alone).
        binding: The finger whose loss sets ``latest_start_s``.
    """

    order: tuple[str, ...]
    latest_start_s: float
    land_by_s: float
    binding: str | None


def regrasp_chain(lost: dict[str, float], duration_s: float) -> Chain:
    """The chain of regrasps forced by holds lost at ``lost`` (finger -> time [s]).

    With one finger in the air at a time and each regrasp taking at least
    ``duration_s``, the holds lost at ``L_1 <= L_2 <= ...`` can all be kept only if the
    regrasps go in that order (earliest deadline first; Jackson's rule) and the first
    lifts off by ``min_j (L_j - (j - 1) D)``: the ``j``-th finger must still hold when
    the ``j - 1`` regrasps before it have landed. The first must then land by
    ``min_{j >= 2} (L_j - (j - 2) D)``. Times are compared as given (ties by name), so
    the order does not follow last-bit noise of equal losses.

    Args:
        lost: When each hold that needs a regrasp is lost [s].
        duration_s: The shortest regrasp [s].

    Returns:
        The :class:`Chain`.
    """
    positive(duration_s, "duration_s")
    order = sorted(lost, key=lambda n: (round(lost[n], 9), n))
    starts = [lost[n] - j * duration_s for j, n in enumerate(order)]
    if not starts:
        return Chain((), -np.inf, np.inf, None)
    k = int(np.argmin(np.round(starts, 9)))  # first of equal minima
    land_by = min(starts[1:], default=np.inf) + duration_s
    return Chain(tuple(order), float(starts[k]), float(land_by), order[k])


def start_times(
    window: LiftOffWindow,
    *,
    latest_s: float | None = None,
    step_s: float = 0.1,
    max_starts: int = 5,
    min_step_s: float = 0.02,
) -> list[float]:
    """Start times to try [s]: the preferred one, then earlier and later in turn.

    Args:
        window: The finger's window.
        latest_s: A further upper bound (e.g. the motion's end minus the duration).
        step_s: Spacing of the tried times [s]; finer in a window shorter than
            ``(max_starts - 1) * step_s``, down to ``min_step_s``.
        max_starts: Most start times returned.
        min_step_s: Finest spacing [s].
    """
    lo = window.earliest_s
    hi = window.latest_s if latest_s is None else min(window.latest_s, latest_s)
    if hi < lo - TIME_TOL_S:
        return []
    first = min(max(window.preferred_s, lo), hi)
    # a short window is sampled more finely: max_starts times across it if it can be
    if max_starts > 1 and hi - lo < step_s * (max_starts - 1):
        step_s = max((hi - lo) / (max_starts - 1), min_step_s)
    out = [first]
    k = 1
    while len(out) < max_starts:
        added = False
        for t in (first - k * step_s, first + k * step_s):
            if lo - TIME_TOL_S <= t <= hi + TIME_TOL_S and len(out) < max_starts:
                out.append(float(min(max(t, lo), hi)))
                added = True
        if not added:
            break
        k += 1
    return out
