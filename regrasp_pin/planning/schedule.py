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

from ..grasp.contact import ContactModel
from ..grasp.tracking import ContactTrack

__all__ = ["LiftOffWindow", "held_until", "lift_off_window", "start_times"]

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
    (margin >= 0), reached, pad facing, with the links clear and the fingertip link
    not sunk in, without a break."""
    ok = (
        (track.error_m <= contact.ik_tol_m)
        & (track.margin_rad >= 0.0)
        & (track.pad_cos >= contact.cos_cone)
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
