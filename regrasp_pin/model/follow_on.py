"""Keeping a batched IK along a trajectory on one branch of the finger's solutions.

A trajectory's samples are solved in batches, every sample of a batch warm-started
from one configuration (the last of the batch before). A finger with a spare joint
(the Allegro's four joints for a 3-D tip centre, the Shadow Hand's thumb) has a curve of
solutions per target, and a sample several steps from the warm start may converge
elsewhere on that curve than its neighbours: the joints jump between two samples
although the tip moves little, a motion no finger makes, which a velocity test then
takes for the limit of the trajectory (a contact's hold "lost" on a joint that "cannot
follow it"). :func:`follow_on` solves such samples again from the sample before.
"""

from __future__ import annotations

import numpy as np

from .hand import Finger, speed_shares

__all__ = ["fastest_share", "follow_on"]


def follow_on(
    finger: Finger,
    q: np.ndarray,
    error_m: np.ndarray,
    targets_palm: np.ndarray,
    q_before: np.ndarray,
    step_s: np.ndarray,
    ik_tol_m: float,
    reached_m: float | np.ndarray | None = None,
) -> int:
    """Solve again, each from the sample before, the samples of a batched IK that did not
    reach their target or that a joint reaches from the sample before only over its
    velocity limit; in place.

    From the first such sample on, the samples are taken one after another: a sample
    that fails or jumps is solved from the one before (no restarts, so that the
    solution stays near it) and the new solution is kept where it reaches the target
    and, for a sample that had reached it, moves less than the batch's did. A sample
    that neither reached nor jumped is left as it is.

    Args:
        finger: The finger.
        q: ``(S, k)`` the batch's configurations [rad], changed in place.
        error_m: ``(S,)`` their tip-centre residuals [m], changed in place.
        targets_palm: ``(S, 3)`` the tip-centre targets, palm frame [m].
        q_before: ``(k,)`` the configuration of the sample before the first [rad].
        step_s: ``(S,)`` the time from the sample before to each [s]; a step of 0 (the
            trajectory's first sample, where ``q_before`` is that very configuration)
            tests no speed.
        ik_tol_m: Tolerance of the new solves [m].
        reached_m: What counts as reaching the target [m], one for all samples or
            ``(S,)``; default ``ik_tol_m``.

    Returns:
        How many samples were solved again and kept.
    """
    reached = np.broadcast_to(ik_tol_m if reached_m is None else reached_m, error_m.shape)
    share = fastest_share(finger, q, q_before, step_s)
    bad = np.flatnonzero((error_m > reached) | (share > 1.0))
    if bad.size == 0:
        return 0
    kept = 0
    last = q[bad[0] - 1] if bad[0] > 0 else q_before
    for i in range(int(bad[0]), q.shape[0]):
        failed = bool(error_m[i] > reached[i])
        step = float(fastest_share(finger, q[i][None], last, step_s[i : i + 1])[0])
        if failed or step > 1.0:
            res = finger.ik(targets_palm[i][None], last, tol_m=ik_tol_m, restarts=False)
            moved = float(fastest_share(finger, res.q, last, step_s[i : i + 1])[0])
            if res.error_m[0] <= reached[i] and (failed or moved < step):
                q[i], error_m[i] = res.q[0], res.error_m[0]
                kept += 1
        last = q[i]
    return kept


def fastest_share(
    finger: Finger, q: np.ndarray, q_before: np.ndarray, step_s: np.ndarray
) -> np.ndarray:
    """``(S,)``: how fast the fastest joint moves into each of the configurations ``q``
    ``(S, k)`` from the one before (``q_before`` ``(k,)`` ahead of the first) over
    ``step_s`` ``(S,)`` [s], as a share of its velocity limit
    (:func:`~regrasp_pin.model.hand.speed_shares`; 0 for a step of no time)."""
    before = np.vstack([q_before[None], q[:-1]])
    return speed_shares(q - before, step_s, finger.velocity_limit).max(axis=1)
