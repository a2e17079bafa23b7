"""Lower bounds of Coal's signed distance for the plan re-check's exact minima
(:func:`~regrasp_pin.verify.plan_check.recheck_plan`; numpy and Coal's shapes only,
nothing of the planner's).

Each collision geometry lies in a capsule (a sphere or a capsule in itself, a cylinder
about its axis, a box about its longest axis; any other shape in the sphere of Coal's
local AABB), hence in the sphere around that capsule, and the object in a sphere around
its vertices: :func:`sphere_bound` bounds every entry cheaply. Tighter, for the entries
that need it: :func:`pair_bound` for two geometries (the larger of their capsules'
signed distance, exact for spheres and capsules, and their separation along the line
through the capsules' nearest points, exact for boxes face to face) and
:func:`object_bound` for a geometry against the object (its separation from the face
plane of the object's convex hull its centre is farthest in front of). Every bound is
put :data:`BOUND_MARGIN_M` below its value, penetration included.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "BOUND_MARGIN_M",
    "Bodies",
    "Shapes",
    "hull_planes",
    "object_bound",
    "pair_bound",
    "segment_gap",
    "shape_bounds",
    "sphere_bound",
]

#: Coal's distances are precise to its GJK and EPA tolerances (1e-6 m each by default,
#: ``coal.DistanceRequest``), above or below; every lower bound is put twice that below
#: its geometric value, so that it stays below whatever Coal answers [m].
BOUND_MARGIN_M = 2e-6


@dataclass(frozen=True)
class Shapes:
    """Convex shapes in their own frames: a capsule around each, and its support function.

    A shape lies in its capsule, the points within ``r`` of the segment from ``c - u`` to
    ``c + u``. Its support function about ``c`` in a unit direction ``v`` of its frame
    (the largest ``v . (p - c)`` over its points ``p``) is ``sum_i half_i |v_i| + axial
    |v_z| + radial sqrt(v_x^2 + v_y^2) + round``: a box (``half``), a cylinder
    (``axial`` its half length, ``radial`` its radius), a capsule (``axial``,
    ``round``), a sphere (``round``); every shape is symmetric about ``c``.

    Attributes:
        c: Centres ``(G, 3)`` [m].
        u: Half segments ``(G, 3)`` [m] (zero: the capsule is a sphere).
        r: Capsule radii ``(G,)`` [m].
        s: Support parameters ``(G, 6)`` [m]: ``half`` (3), ``axial``, ``radial``,
            ``round``.
    """

    c: np.ndarray
    u: np.ndarray
    r: np.ndarray
    s: np.ndarray

    @classmethod
    def of(cls, shapes: list[Any]) -> Shapes:
        """The capsules and support functions of Coal shapes (:func:`shape_bounds`)."""
        rows = [shape_bounds(shape) for shape in shapes]
        c, u, r, s = (np.array([row[i] for row in rows], float) for i in range(4))
        return cls(c.reshape(-1, 3), u.reshape(-1, 3), r, s.reshape(-1, 6))

    def __getitem__(self, index: Any) -> Shapes:
        """The shapes at ``index``."""
        return Shapes(self.c[index], self.u[index], self.r[index], self.s[index])

    def placed(self, R: np.ndarray, x: np.ndarray) -> Bodies:
        """The shapes placed by rotations ``R (..., G, 3, 3)`` and translations ``x (...,
        G, 3)`` [m] (their frames in the frame of reference)."""
        return Bodies(
            _rotate(R, self.c) + x,
            _rotate(R, self.u),
            np.broadcast_to(self.r, x.shape[:-1]),
            R,
            np.broadcast_to(self.s, (*x.shape[:-1], 6)),
        )


@dataclass(frozen=True)
class Bodies:
    """:class:`Shapes` placed in a frame of reference (the palm's).

    Attributes:
        c: Centres ``(..., 3)`` [m].
        u: Half segments ``(..., 3)`` [m].
        r: Capsule radii ``(...)`` [m].
        R: Rotations ``(..., 3, 3)`` of the shapes' frames (columns: their axes).
        s: Support parameters ``(..., 6)`` [m] (:class:`Shapes`).
    """

    c: np.ndarray
    u: np.ndarray
    r: np.ndarray
    R: np.ndarray
    s: np.ndarray

    def __getitem__(self, index: Any) -> Bodies:
        """The bodies at ``index`` of the leading axes (slices and arrays, no ellipsis)."""
        return Bodies(self.c[index], self.u[index], self.r[index], self.R[index], self.s[index])

    def take(self, k: np.ndarray, g: np.ndarray) -> Bodies:
        """The bodies ``(N,)`` at samples ``k`` and columns ``g`` ``(N,)`` of bodies ``(K,
        G)`` (``self[k, g]``, gathered faster)."""
        i = k * self.c.shape[1] + g

        def rows(a: np.ndarray) -> np.ndarray:
            return np.take(a.reshape(-1, *a.shape[2:]), i, axis=0)

        return Bodies(rows(self.c), rows(self.u), self.r[k, g], rows(self.R), self.s[k, g])

    @property
    def rho(self) -> np.ndarray:
        """Radii ``(...)`` [m] of the spheres about the centres around the capsules."""
        return np.sqrt(_dot(self.u, self.u)) + self.r

    def support(self, w: np.ndarray) -> np.ndarray:
        """The support function ``(...)`` [m] about the centres in the unit directions
        ``w`` ``(..., 3)`` (the frame of reference), broadcast."""
        return _local_support(np.einsum("...ji,...j->...i", self.R, w), self.s)


def _rotate(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R @ v`` ``(..., G, 3)`` for rotations ``R`` ``(..., G, 3, 3)`` and vectors ``v``
    ``(G, 3)``, column by column (faster than einsum on a broadcast operand)."""
    return R[..., 0] * v[:, 0, None] + R[..., 1] * v[:, 1, None] + R[..., 2] * v[:, 2, None]


def _local_support(v: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The support function ``(...)`` [m] of bodies with support parameters ``s``
    ``(..., 6)`` (:class:`Shapes`) in the unit directions ``v`` ``(..., 3)`` of their
    own frames, broadcast."""
    ax, ay, az = np.abs(v[..., 0]), np.abs(v[..., 1]), np.abs(v[..., 2])
    return (
        s[..., 0] * ax
        + s[..., 1] * ay
        + (s[..., 2] + s[..., 3]) * az
        + s[..., 4] * np.hypot(ax, ay)
        + s[..., 5]
    )


def shape_bounds(shape: Any) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The capsule ``(c, u, r)`` [m] around a Coal shape and its support parameters
    (:class:`Shapes`), in the shape's frame.

    A sphere or a capsule is its own capsule; a cylinder (axis z) gets its axis and
    radius; a box the segment along its longest side and the half diagonal of the other
    two. Any other shape is taken as the sphere of its local AABB.
    """
    import coal

    zero, z = np.zeros(3), np.array([0.0, 0.0, 1.0])
    if isinstance(shape, coal.Sphere):
        r = float(shape.radius)
        return zero, zero, r, np.array([0.0, 0.0, 0.0, 0.0, 0.0, r])
    if isinstance(shape, coal.Capsule):
        r, a = float(shape.radius), float(shape.halfLength)
        return zero, a * z, r, np.array([0.0, 0.0, 0.0, a, 0.0, r])
    if isinstance(shape, coal.Cylinder):
        r, a = float(shape.radius), float(shape.halfLength)
        return zero, a * z, r, np.array([0.0, 0.0, 0.0, a, r, 0.0])
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide, float)
        i = int(np.argmax(half))
        u = np.zeros(3)
        u[i] = half[i]
        return zero, u, float(np.linalg.norm(np.delete(half, i))), np.append(half, [0.0] * 3)
    shape.computeLocalAABB()
    r = float(shape.aabb_radius)
    return np.array(shape.aabb_center, float), zero, r, np.array([0.0, 0.0, 0.0, 0.0, 0.0, r])


def hull_planes(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Planes around the points ``(N, 3)`` [m], in their frame: outward unit normals
    ``(F, 3)`` and offsets ``(F,)`` [m] with ``n . p <= o`` for every point ``p`` (hence
    for their convex hull), the normals of the hull's faces (those of the bounding box
    when the points are flat)."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        n = np.unique(np.round(ConvexHull(points).equations[:, :3], 12), axis=0)
    except QhullError:
        n = np.vstack([np.eye(3), -np.eye(3)])
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return n, np.max(points @ n.T, axis=0)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (broadcast)."""
    return np.einsum("...i,...i->...", a, b)


def segment_gap(c1: np.ndarray, u1: np.ndarray, c2: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """The vector ``(..., 3)`` [m] from the nearest point of the segment ``c2 -/+ u2`` to
    that of the segment ``c1 -/+ u1`` (``(..., 3)`` [m], broadcast).

    Closed form of Ericson, *Real-Time Collision Detection*, 5.1.9, vectorized
    (segments reduced to a point included): the nearest points' parameters, clamped to
    the segments, and the vector between those two points.
    """
    d1, d2, r = 2.0 * u1, 2.0 * u2, (c1 - u1) - (c2 - u2)
    a, e, b = _dot(d1, d1), _dot(d2, d2), _dot(d1, d2)
    c, f = _dot(d1, r), _dot(d2, r)
    denom = a * e - b * b  # 0 for parallel segments (or a point)
    with np.errstate(divide="ignore", invalid="ignore"):  # the branches np.where drops
        s = np.where(denom > 0.0, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = np.where(e > 0.0, (b * s + f) / e, 0.0)
        redo = (t < 0.0) | (t > 1.0) | (e <= 0.0)  # t clamped: s again, for that t
        t = np.clip(t, 0.0, 1.0)
        s = np.where(redo, np.where(a > 0.0, np.clip((b * t - c) / a, 0.0, 1.0), 0.0), s)
    return r + s[..., None] * d1 - t[..., None] * d2


def sphere_bound(
    c_a: np.ndarray, rho_a: np.ndarray | float, c_b: np.ndarray, rho_b: np.ndarray | float
) -> np.ndarray:
    """Lower bounds ``(...)`` [m] of Coal's signed distance between bodies inside the
    spheres ``(c_a, rho_a)`` and ``(c_b, rho_b)`` (centres ``(..., 3)``, radii ``(...)``
    [m], broadcast): ``|c_a - c_b| - rho_a - rho_b``, less :data:`BOUND_MARGIN_M`."""
    d = c_a - c_b
    return np.sqrt(_dot(d, d)) - rho_a - rho_b - BOUND_MARGIN_M


def pair_bound(a: Bodies, b: Bodies) -> np.ndarray:
    """Lower bounds ``(...)`` [m] of Coal's signed distance between the bodies ``a`` and
    ``b`` (placed in one frame, broadcast), penetration included.

    The larger of two: the capsules' signed distance (their segments' distance less
    both radii: a body inside another is no farther from a third, and penetrates it no
    deeper), exact for two spheres or capsules; and the bodies' separation along the
    unit ``w`` joining the capsules' nearest points, ``w . (c_a - c_b) - h_a(w) -
    h_b(w)`` with their support functions ``h`` (the gap between two slabs, one around
    each), exact for two boxes face to face. Less :data:`BOUND_MARGIN_M`, for Coal's
    tolerance.
    """
    gap = segment_gap(a.c, a.u, b.c, b.u)
    dist = np.sqrt(_dot(gap, gap))
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(dist[..., None] > 0.0, gap / dist[..., None], [1.0, 0.0, 0.0])
    apart = _dot(w, a.c - b.c) - a.support(w) - b.support(w)
    return np.maximum(dist - a.r - b.r, apart) - BOUND_MARGIN_M


def object_bound(
    bodies: Bodies, R_obj: np.ndarray, x_obj: np.ndarray, planes: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Lower bounds ``(N,)`` [m] of Coal's signed distance between the bodies ``(N,)`` and
    the object at ``R_obj (N, 3, 3)``, ``x_obj (N, 3)`` (the bodies' frame of
    reference), penetration included.

    ``planes``: the object's face planes in its frame (:func:`hull_planes`), each
    holding the object behind it. The bound is ``n . c - o - h(n)`` with ``c`` a
    body's centre, ``h`` its support function and ``n . x = o`` the plane its centre is
    farthest in front of: the body lies that far in front of the plane (or at most
    that far behind it). Less :data:`BOUND_MARGIN_M`, for Coal's tolerance.
    """
    normals, offsets = planes
    c = np.einsum("nji,nj->ni", R_obj, bodies.c - x_obj)  # (N, 3) object frame
    ahead = c @ normals.T - offsets  # (N, F)
    f = np.argmax(ahead, axis=1)
    n = np.einsum("nij,nj->ni", R_obj, normals[f])  # (N, 3) palm frame
    return ahead[np.arange(f.size), f] - bodies.support(n) - BOUND_MARGIN_M
