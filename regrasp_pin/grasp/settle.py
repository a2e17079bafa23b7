"""A redundant finger's spare joints: keeping the fingertip link off the face it holds.

Position IK fixes the fingertip centre: three coordinates. A finger with more joints
(the Allegro's four, the Shadow Hand's thumb) can still turn its fingertip about the
tip centre without moving it, and where warm-started IK leaves that turn is an accident
of the seed. The turn decides whether the fingertip link reaches past the plane on
which the tip sphere rests (:meth:`~regrasp_pin.model.tip_reach.TipReach.overshoot`):
the Allegro's distal box lets the pad tilt only about 5 deg towards the palm, so a
contact followed through the object's motion sinks the box into the face after a few
degrees, although a small move of the spare joint (a few hundredths of a radian) would
tilt the fingertip back.

:func:`settle_tip_link` makes that move where the link would reach past the plane (by
at most ``SETTLE_WITHIN_M``: further, a small turn does not lift it off): a
step in the null space of the tip's position Jacobian along the overshoot's descent
(forward differences), sized to bring the overshoot to ``SETTLE_TO_M`` below the plane
to first order (shortened to stay within the allowance), then the tip put back on its
target by IK (warm-started, no restarts).
A step is kept only where the IK reaches the target within its tolerance, the joints
stay within their limits and within ``max_change_rad`` of a given configuration (the
time before, when a contact is followed), the overshoot fell, and neither the pad
turned beyond its cone nor a joint came nearer a limit than the trigger's margin
(unless they already had); at most ``MAX_STEPS`` steps. A finger without spare joints,
or without fingertip geometries the overshoot reads, is returned unchanged.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_array
from ..model.hand import Finger
from .contact import pad_cosines_and_overshoot

__all__ = [
    "MAX_STEPS",
    "SETTLE_TO_M",
    "SETTLE_WITHIN_M",
    "TURN_SPEED_SHARE",
    "settle_tip_link",
    "sinking",
]

#: The overshoot a settle aims at: this far below the plane the tip sphere rests on [m].
SETTLE_TO_M = 1e-4
#: Configurations whose link reaches further than this past the plane are left as they
#: are [m]: a turn within a time step's allowance rarely lifts them off (over the
#: Allegro's manifolds of its demo: 3 % of those reaching 1-2 mm past, 0.1 % beyond,
#: against 39 % of those up to 1 mm; most that sink reach 2-40 mm past).
SETTLE_WITHIN_M = 1e-3
#: Most null-space steps per configuration.
MAX_STEPS = 6
#: A turn held over time (:func:`~regrasp_pin.grasp.tracking.track_contact`) keeps each
#: joint's whole step from the time before (the motion that follows the object and the
#: turn together) within this share of its velocity limit; a time whose following
#: motion alone moves a joint further is not turned. The rest of the limit is left to
#: the IK's corrections where a plan samples the hold between the track's times (with
#: the whole limit those reached 1 % over it).
TURN_SPEED_SHARE = 0.5
_FD_RAD = 1e-6  # finite-difference step of the overshoot's gradient [rad]


def settle_tip_link(
    finger: Finger,
    q: np.ndarray,
    targets_palm: np.ndarray,
    normals_palm: np.ndarray,
    *,
    ik_tol_m: float,
    around: np.ndarray | None = None,
    max_change_rad: float | np.ndarray = 0.2,
    cos_cone: float | None = None,
    margin_rad: float | None = None,
    above_m: float = 0.0,
) -> np.ndarray:
    """Configurations ``(N, k)`` holding the same tip centres with the fingertip link
    turned off the face where it reached past the tip sphere's tangent plane (module
    docstring).

    Args:
        finger: The finger.
        q: ``(N, k)`` configurations reaching ``targets_palm`` [rad].
        targets_palm: ``(N, 3)`` their tip-centre targets, palm frame [m].
        normals_palm: ``(N, 3)`` the outward surface normals at the contacts, palm frame.
        ik_tol_m: IK tolerance a settled configuration must meet [m].
        around: ``(N, k)`` configurations a settled row must stay within
            ``max_change_rad`` of (default ``q``: the move itself is bounded); a row
            already farther from it is left as it is [rad].
        max_change_rad: Most any joint may differ from ``around`` [rad] (scalar or
            ``(k,)``).
        cos_cone: A step may not turn the pad beyond this cone (cosine of the angle
            between the pad and the inward normal), unless it already was.
        margin_rad: A step may not bring a joint nearer than this to a limit than it
            already was [rad].
        above_m: Configurations whose overshoot is above this (and at most
            ``SETTLE_WITHIN_M``) are settled [m].

    Returns:
        ``(N, k)``: a copy of ``q`` with the rows that could be settled replaced.

    Raises:
        InputError: arrays of the wrong shape (naming the argument).
    """
    q = np.array(as_array(q, "q", (None, finger.k)), dtype=float, copy=True)
    targets = as_array(targets_palm, "targets_palm", (q.shape[0], 3))
    normals = as_array(normals_palm, "normals_palm", (q.shape[0], 3))
    base = q.copy() if around is None else as_array(around, "around", q.shape)
    if not _has_spare_joints(finger) or q.shape[0] == 0:
        return q
    cos, over = pad_cosines_and_overshoot(finger, q, normals)
    lo = np.maximum(finger.lower, base - max_change_rad)
    hi = np.minimum(finger.upper, base + max_change_rad)
    in_box = np.all((q >= lo - 1e-12) & (q <= hi + 1e-12), axis=1)
    todo = np.flatnonzero((over > above_m) & (over <= SETTLE_WITHIN_M) & in_box)
    lo, hi = lo[todo], hi[todo]
    margin = finger.limit_margin(q)
    least_cos = np.minimum(-np.inf if cos_cone is None else cos_cone, cos[todo])
    least_margin = np.minimum(-np.inf if margin_rad is None else margin_rad, margin[todo])
    for _ in range(MAX_STEPS):
        if todo.size == 0:
            break
        qa, n = q[todo], normals[todo]
        q_new = _step(finger, qa, targets[todo], n, over[todo], lo, hi, ik_tol_m)
        ok = ~np.isnan(q_new[:, 0])
        q_new[~ok] = qa[~ok]
        new_cos, new_over = pad_cosines_and_overshoot(finger, q_new, n)
        new_margin = finger.limit_margin(q_new)
        better = ok & (new_over < over[todo] - 1e-9)
        better &= (new_cos >= least_cos) & (new_margin >= least_margin)
        q[todo[better]] = q_new[better]
        over[todo[better]] = new_over[better]
        keep = better & (new_over > above_m)
        todo, lo, hi = todo[keep], lo[keep], hi[keep]
        least_cos, least_margin = least_cos[keep], least_margin[keep]
    return q


def sinking(finger: Finger, q: np.ndarray, normals_palm: np.ndarray) -> np.ndarray:
    """``(N,)`` True where :func:`settle_tip_link` would try to settle ``q`` ``(N, k)``:
    a finger with spare joints whose fingertip link reaches past the plane by at most
    ``SETTLE_WITHIN_M``."""
    if not _has_spare_joints(finger) or len(q) == 0:
        return np.zeros(len(q), bool)
    _, over = pad_cosines_and_overshoot(
        finger, np.asarray(q, float), np.asarray(normals_palm, float)
    )
    return (over > 0.0) & (over <= SETTLE_WITHIN_M)


def _has_spare_joints(finger: Finger) -> bool:
    """More joints than the tip centre's three coordinates, and fingertip geometries
    whose overshoot can be read."""
    reach = finger.tip_reach
    return finger.k > 3 and reach is not None and reach.params.shape[0] > 0


def _step(
    finger: Finger,
    q: np.ndarray,
    targets: np.ndarray,
    normals: np.ndarray,
    over: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    ik_tol_m: float,
) -> np.ndarray:
    """One null-space step of each row ``q`` ``(m, k)`` and IK back onto its target,
    within ``[lo, hi]``: ``(m, k)``, NaN rows where the IK missed or left the box."""
    g = _gradient(finger, q, normals, over)
    _, J = finger.jacobian(q)
    # the projector onto the null space of J (rank 3 away from singularities)
    JJt = J @ np.swapaxes(J, 1, 2) + 1e-12 * np.eye(3)
    null = np.eye(finger.k)[None] - np.swapaxes(J, 1, 2) @ np.linalg.solve(JJt, J)
    d = -np.einsum("mij,mj->mi", null, g)
    slope = np.einsum("mi,mi->m", g, d)  # <= 0 along the descent
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where(slope < -1e-12, (over + SETTLE_TO_M) / -slope, 0.0)
        # no further than the allowance left (90 %: the IK's correction is second order)
        room = np.where(d > 0.0, hi - q, q - lo)
        fit = np.where(np.abs(d) > 1e-15, 0.9 * room / np.abs(d), np.inf).min(axis=1)
    q_try = np.clip(q + np.minimum(alpha, fit)[:, None] * d, lo, hi)
    res = finger.ik(targets, q_try, tol_m=ik_tol_m, restarts=False)
    inside = np.all((res.q >= lo - 1e-12) & (res.q <= hi + 1e-12), axis=1)
    return np.where((res.success & inside)[:, None], res.q, np.nan)


def _gradient(
    finger: Finger, q: np.ndarray, normals_palm: np.ndarray, over: np.ndarray
) -> np.ndarray:
    """``(N, k)`` the overshoot's gradient in the joints (forward differences from the
    overshoot ``over`` ``(N,)`` at ``q``)."""
    m, k = q.shape
    qq = q[:, None, :] + _FD_RAD * np.eye(k)[None]
    nn = np.repeat(normals_palm[:, None, :], k, axis=1)
    _, o = pad_cosines_and_overshoot(finger, qq.reshape(-1, k), nn.reshape(-1, 3))
    o = o.reshape(m, k)
    return (o - over[:, None]) / _FD_RAD
