"""Leaving a contact (and coming down onto one): the direction the fingertip takes.

A fingertip that lets go of its contact P backs off from the surface; one that lands
on Q comes down onto it. Along the contact's outward normal is the natural way, but
the finger lets go *because* its contact has reached a joint limit, and there the
normal may be out of reach: the tip would have to move where only the joint at its
limit could take it (the IK stops millimetres short). Any direction that leaves the
surface does as well for the object, since the fingertip only has to rise above the
face before it travels. So the back-off is searched over directions:

1. the normal first (where it is within reach nothing changes);
2. then directions tilted from the normal by ``TILTS_DEG``, at ``AZIMUTHS`` azimuths
   about it (the first pointing, along the surface, towards where the finger goes
   next), ranked by how much of the move the finger can make to first order within
   its joint limits (a bounded least-squares step of the tip Jacobian at the contact,
   :func:`scipy.optimize.lsq_linear`); the ``MAX_TILTED`` best are tried.

A back-off along the normal can also take the finger towards a neighbour holding
beside it on the same face (the fingers' links converge as they curl). Where the
caller found that, :func:`directions_apart` gives the tilted directions whose top
stands further from the other fingers than the caller's back-off does, measured there.

Along a direction ``d`` the tip centre rises to the same height above the contact's
tangent plane as along the normal (it moves ``offset / (d . n)`` along ``d``): the
clearance reached is the same, only the tip slides sideways on the way. Every
direction is followed with warm-started IK at the object's poses, so the back-off moves
with the object; what the finger then does is verified by the Coal check of its caller.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.optimize import lsq_linear

from ..exceptions import FailureKind, PlanningError
from ..model.hand import Finger

__all__ = [
    "APART_GAIN_M",
    "AZIMUTHS",
    "GAP_TOL_M",
    "MAX_APART",
    "MAX_TILTED",
    "TILTS_DEG",
    "along",
    "back_off",
    "directions_apart",
    "tilted_directions",
]

#: Tilts from the contact normal of the directions tried when the normal is out of
#: reach [deg].
TILTS_DEG = (30.0, 60.0)
#: Azimuths about the normal per tilt.
AZIMUTHS = 8
#: Most tilted directions followed with IK (the best ranked at first order).
MAX_TILTED = 4
#: Most directions away from the other fingers returned by :func:`directions_apart`.
MAX_APART = 3
#: How much further from the other fingers than the caller's back-off a tilted
#: back-off's top must stand to be tried for that [m].
APART_GAIN_M = 2e-4
#: Gaps of directions apart closer than this are ties (broken by the smaller tilt) [m].
GAP_TOL_M = 1e-9
#: First-order shares of the move within the joint limits closer than this are ties,
#: broken by the smaller tilt, then the azimuth's order [-].
_SHARE_TOL = 1e-3


def tilted_directions(
    f: Finger,
    T: np.ndarray,
    contact: tuple[np.ndarray, np.ndarray],
    q: np.ndarray,
    height_m: float,
    toward: np.ndarray | None = None,
) -> np.ndarray:
    """Directions ``(D, 3)`` (object frame, unit) tilted from the contact's outward
    normal to back off along when the normal is out of reach, in the order to try them:
    the (at most ``MAX_TILTED``) ones the finger at ``q`` ``(k,)`` [rad] can follow
    furthest to first order within its joint limits (module docstring).

    Args:
        f: The finger.
        T: ``(4, 4)`` the object's pose in the palm frame.
        contact: ``(point, outward normal)``, object frame [m].
        q: ``(k,)`` the finger holding the contact [rad].
        height_m: How high above the tangent plane the back-off goes [m].
        toward: A point (object frame) the finger goes to next: the first azimuth
            points along the surface towards it (None, or right above the contact:
            a fixed basis).
    """
    dirs, tilt = _tilted_grid(contact, toward)
    _, J = f.jacobian(q)
    R = np.asarray(T, float)[:3, :3]
    lo = np.minimum(f.lower - q, 0.0)  # a joint at (or past) a limit moves only back
    hi = np.maximum(np.maximum(f.upper - q, 0.0), lo + 1e-12)
    share = np.empty(len(dirs))
    for i, d in enumerate(dirs):  # D = len(TILTS_DEG) * AZIMUTHS small solves
        move = (height_m / np.cos(tilt[i])) * (R @ d)
        step = lsq_linear(J, move, bounds=(lo, hi)).x
        share[i] = float(move @ (J @ step)) / float(move @ move)
    return dirs[_ranked(share, tilt)[:MAX_TILTED]]


def _tilted_grid(
    contact: tuple[np.ndarray, np.ndarray], toward: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The directions ``(D, 3)`` (object frame, unit) tilted from the contact's outward
    normal by each of ``TILTS_DEG`` at ``AZIMUTHS`` azimuths about it (the first along
    the surface towards ``toward``, see :func:`tilted_directions`), tilt by tilt, and
    their tilts ``(D,)`` [rad]."""
    n = np.asarray(contact[1], float)
    n = n / np.linalg.norm(n)
    e1 = _tangent_towards(n, None if toward is None else np.asarray(toward, float) - contact[0])
    e2 = np.cross(n, e1)
    azimuths = 2.0 * np.pi * np.arange(AZIMUTHS) / AZIMUTHS
    tilts = np.radians(np.asarray(TILTS_DEG, float))
    tilt, az = np.repeat(tilts, AZIMUTHS), np.tile(azimuths, tilts.size)
    dirs = np.cos(tilt)[:, None] * n + np.sin(tilt)[:, None] * (
        np.cos(az)[:, None] * e1 + np.sin(az)[:, None] * e2
    )
    return dirs, tilt


def directions_apart(
    f: Finger,
    T: np.ndarray,
    contact: tuple[np.ndarray, np.ndarray],
    q: np.ndarray,
    height_m: float,
    gap: Callable[[np.ndarray], float],
    ik_tol_m: float,
    toward: np.ndarray | None = None,
    baseline_m: float | None = None,
) -> np.ndarray:
    """Directions ``(D, 3)`` (object frame, unit) tilted from the contact's outward
    normal along which the back-off ends further from the other fingers than the
    back-off the caller has, the furthest first: where backing off took the finger
    towards a neighbour (fingers side by side on one face).

    Each direction of ``TILTS_DEG`` x ``AZIMUTHS`` (:func:`tilted_directions`'
    directions, unranked) is judged at the back-off's top, the tip centre ``height_m``
    above the tangent plane at the object pose ``T``, by one IK solve from ``q`` (the
    back-off itself follows the direction sample by sample, and a redundant finger may
    end elsewhere; its Coal check judges it): its ``gap`` must exceed ``baseline_m`` by
    ``APART_GAIN_M``, and an unreachable top has none. At most ``MAX_APART`` are
    returned; gaps within ``GAP_TOL_M`` of the furthest left are ties, broken by the
    smaller tilt, then the azimuth's order.

    Args:
        f: The finger.
        T: ``(4, 4)`` the object's pose in the palm frame at the back-off's top.
        contact: ``(point, outward normal)``, object frame [m].
        q: ``(k,)`` the finger's configuration to solve from [rad].
        height_m: How high above the tangent plane the back-off goes [m].
        gap: The finger's distance from the other fingers at a configuration ``(k,)``
            [m].
        ik_tol_m: IK tolerance of the tops [m].
        toward: As :func:`tilted_directions`': the first azimuth's direction.
        baseline_m: The gap to beat [m]; None: the normal's top's (-inf where it is
            out of reach).
    """
    p, n = np.asarray(contact[0], float), np.asarray(contact[1], float)
    n = n / np.linalg.norm(n)
    tilted, tilts = _tilted_grid(contact, toward)
    dirs, tilt = np.vstack([n, tilted]), np.r_[0.0, tilts]  # the normal first
    local = p + f.tip_radius * n + (height_m / (dirs @ n))[:, None] * dirs
    T = np.asarray(T, float)
    res = f.ik(local @ T[:3, :3].T + T[:3, 3], np.asarray(q, float), tol_m=ik_tol_m, restarts=False)
    gaps = np.array(
        [gap(res.q[i]) if res.error_m[i] <= ik_tol_m else -np.inf for i in range(len(dirs))]
    )
    base = gaps[0] if baseline_m is None else float(baseline_m)
    better = np.flatnonzero(np.isfinite(gaps[1:]) & (gaps[1:] >= base + APART_GAIN_M)) + 1
    order = _ranked(gaps[better], tilt[better], GAP_TOL_M)
    return dirs[better[order][:MAX_APART]]


def _ranked(share: np.ndarray, tilt: np.ndarray, tol: float = _SHARE_TOL) -> list[int]:
    """Indices by decreasing ``share``, shares within ``tol`` of the best left
    counting as ties, broken by the smaller tilt, then the index."""
    left = list(range(len(share)))
    order = []
    while left:
        best = max(share[i] for i in left)
        pick = min((i for i in left if share[i] >= best - tol), key=lambda i: (tilt[i], i))
        order.append(pick)
        left.remove(pick)
    return order


def back_off(
    f: Finger,
    T: np.ndarray,
    contact: tuple[np.ndarray, np.ndarray],
    offsets: np.ndarray,
    q_seed: np.ndarray,
    ik_tol_m: float,
    toward: np.ndarray | None = None,
) -> np.ndarray:
    """Configurations ``(S, k)`` whose fingertip rises ``offsets`` ``(S,)`` [m] above
    the contact's tangent plane at object poses ``T`` ``(S, 4, 4)``: along the outward
    normal or, when IK cannot follow it, along the first of :func:`tilted_directions`
    that it follows (each sample warm-started from the one before, the first from
    ``q_seed``, the configuration at the contact).

    Raises:
        PlanningError: ``ik-unreachable`` when no direction can be followed; its
            numbers are those of the normal.
    """
    n = np.asarray(contact[1], float)
    try:
        return along(f, T, contact, n / np.linalg.norm(n), offsets, q_seed, ik_tol_m)
    except PlanningError as exc:
        normal = exc
    height = float(np.max(offsets))
    for d in tilted_directions(f, T[0], contact, q_seed, height, toward):
        try:
            return along(f, T, contact, d, offsets, q_seed, ik_tol_m)
        except PlanningError:
            continue
    raise normal


def _tangent_towards(n: np.ndarray, v: np.ndarray | None) -> np.ndarray:
    """A unit tangent of the plane with normal ``n``: along ``v``'s tangential part when
    that is not negligible, else along the frame's x axis (its y axis where ``n`` is
    within 26 deg of x)."""
    if v is not None:
        t = v - (v @ n) * n
        if np.linalg.norm(t) > 1e-6:
            return t / np.linalg.norm(t)
    axis = np.eye(3)[0] if abs(n[0]) < 0.9 else np.eye(3)[1]
    t = axis - (axis @ n) * n
    return t / np.linalg.norm(t)


def along(
    f: Finger,
    T: np.ndarray,
    contact: tuple[np.ndarray, np.ndarray],
    d: np.ndarray,
    offsets: np.ndarray,
    q_seed: np.ndarray,
    ik_tol_m: float,
) -> np.ndarray:
    """The back-off of :func:`back_off` along the unit direction ``d`` (object frame),
    or ik-unreachable."""
    p, n = np.asarray(contact[0], float), np.asarray(contact[1], float)
    n = n / np.linalg.norm(n)
    local = p[None] + f.tip_radius * n[None] + (offsets / float(d @ n))[:, None] * d[None]
    targets = np.einsum("sij,sj->si", T[:, :3, :3], local) + T[:, :3, 3]
    q = np.empty((len(T), f.k))
    seed = q_seed
    for i, target in enumerate(targets):
        res = f.ik(target[None], seed, tol_m=ik_tol_m, restarts=False)
        if res.error_m[0] > ik_tol_m:
            raise PlanningError(
                f"cannot back off from the contact (residual {res.error_m[0] * 1e3:.2f} mm "
                f"at {offsets[i] * 1e3:.1f} mm above it)",
                finger=f.name,
                time_s=None,
                kind=FailureKind.IK_UNREACHABLE,
                measured=float(res.error_m[0]),
                required=ik_tol_m,
            )
        q[i] = seed = res.q[0]
    return q
