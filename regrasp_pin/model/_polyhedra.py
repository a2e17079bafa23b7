"""Convex hull and polygon geometry behind :mod:`regrasp_pin.model.objects` (private helpers).

Hull computation and coplanar-face merging, volume centroid, convex-polygon checks and
extrusion, plus small vector helpers. Plain numpy arrays in, plain numpy arrays out.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from .._validate import as_array
from ..exceptions import GeometryError


def convex_hull(pts: np.ndarray) -> ConvexHull:
    if pts.shape[0] < 4:
        raise GeometryError(f"a convex object needs at least 4 points, got {pts.shape[0]}")
    try:
        hull = ConvexHull(pts)
    except QhullError:
        raise GeometryError("the points are flat or degenerate: they span no volume") from None
    scale = np.max(np.ptp(pts, axis=0))
    if hull.volume <= 1e-12 * scale**3:
        raise GeometryError(f"the convex hull has no volume ({hull.volume:.3g} m^3)")
    return hull


def volume_centroid(pts: np.ndarray, hull: ConvexHull) -> np.ndarray:
    """Centroid of the solid hull: tetrahedra from an interior point to each triangle.

    The same bits on every machine: each determinant is written out (LAPACK's follow
    the CPU's kernels) and every sum is correctly rounded (``math.fsum``), so the
    object's vertices, re-centred by it, do not differ in their last bits between
    machines."""
    c0 = np.array([math.fsum(column) for column in pts.T]) / pts.shape[0]
    tri = hull.points[hull.simplices]  # (T, 3, 3)
    a, b, c = (tri[:, k] - c0 for k in range(3))
    det = (
        a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
        - a[:, 1] * (b[:, 0] * c[:, 2] - b[:, 2] * c[:, 0])
        + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0])
    )
    vol = np.abs(det) / 6.0
    cent = (c0 + (tri[:, 0] + tri[:, 1] + tri[:, 2])) / 4.0
    total = math.fsum(vol)
    return np.array([math.fsum(vol * cent[:, k]) for k in range(3)]) / total


def hull_polygons(pts: np.ndarray, tol: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Canonical hull vertices (lexicographic) and CCW polygon index lists (sorted faces).

    Neighbouring hull triangles whose planes agree within ``tol`` are merged into one
    polygonal face (connected components over the triangle adjacency).
    """
    hull = convex_hull(pts)
    scale = float(np.max(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))
    n, off = hull.equations[:, :3], -hull.equations[:, 3]
    a = np.repeat(np.arange(len(n)), 3)
    b = hull.neighbors.ravel()
    same = (np.einsum("ij,ij->i", n[a], n[b]) > math.cos(tol)) & (
        np.abs(off[a] - off[b]) <= tol * scale
    )
    graph = csr_matrix((np.ones(int(same.sum())), (a[same], b[same])), shape=(len(n), len(n)))
    n_groups, label = connected_components(graph, directed=False)
    used = np.unique(hull.simplices)
    order = used[np.lexsort(pts[used].T[::-1])]
    verts = pts[order]
    new_id = np.full(pts.shape[0], -1, dtype=np.int64)
    new_id[order] = np.arange(order.size)
    tri = new_id[hull.simplices]
    # Orient every triangle counter-clockwise about its outward normal.
    flip = (
        np.einsum(
            "ij,ij->i",
            np.cross(verts[tri[:, 1]] - verts[tri[:, 0]], verts[tri[:, 2]] - verts[tri[:, 0]]),
            n,
        )
        < 0
    )
    tri[flip] = tri[flip][:, ::-1]
    by_group = np.argsort(label, kind="stable")
    bounds = np.searchsorted(label[by_group], np.arange(n_groups + 1))
    polys: list[np.ndarray] = []
    for g in range(n_groups):  # per face
        members = by_group[bounds[g] : bounds[g + 1]]
        if members.size == 1:
            ring = tri[members[0]]
        else:
            ids = np.unique(tri[members])
            nrm = n[members].mean(axis=0)
            u, v = _plane_axes(nrm / np.linalg.norm(nrm))
            xy = (verts[ids] - verts[ids].mean(axis=0)) @ np.stack([u, v], axis=1)
            ring = ids[ConvexHull(xy).vertices]  # counter-clockwise about nrm
        polys.append(np.roll(ring, -int(np.argmin(ring))))
    normals = np.array([newell_normal(verts[ring]) for ring in polys])
    keys = np.round(normals, 9)
    face_order = np.lexsort((-keys[:, 2], -keys[:, 1], -keys[:, 0]))
    kept = np.unique(np.concatenate(polys))
    remap = np.full(verts.shape[0], -1, dtype=np.int64)
    remap[kept] = np.arange(kept.size)
    return verts[kept], [remap[polys[i]] for i in face_order]


def fan_triangles(ids: np.ndarray) -> np.ndarray:
    """Fan triangulation (k - 2, 3) of a convex polygon's vertex ids, same orientation."""
    return np.stack([np.full(len(ids) - 2, ids[0]), ids[1:-1], ids[2:]], axis=1)


def _plane_axes(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = cross(normal, a)
    u /= np.linalg.norm(u)
    return u, cross(normal, u)


def newell_normal(poly: np.ndarray) -> np.ndarray:
    nrm = np.sum(cross(poly, np.roll(poly, -1, axis=0)), axis=0)
    return nrm / np.linalg.norm(nrm)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product on the last axis (cheaper than np.cross for small arrays)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def convex_polygon_ccw(polygon_xy: np.ndarray) -> np.ndarray:
    poly = as_array(polygon_xy, "polygon_xy", (None, 2))
    if poly.shape[0] < 3:
        raise GeometryError(f"polygon_xy needs at least 3 vertices, got {poly.shape[0]}")
    edges = np.roll(poly, -1, axis=0) - poly
    lengths = np.linalg.norm(edges, axis=1)
    scale = float(np.max(np.ptp(poly, axis=0)))
    if scale <= 0 or np.any(lengths <= 1e-12 * scale):
        raise GeometryError("polygon_xy is degenerate: repeated consecutive vertices")
    x, y = poly[:, 0], poly[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    if abs(area2) <= 1e-12 * scale**2:
        raise GeometryError("polygon_xy is degenerate: zero area")
    if area2 < 0:
        poly = poly[::-1].copy()
        edges = np.roll(poly, -1, axis=0) - poly
    turn = edges[:, 0] * np.roll(edges[:, 1], -1) - edges[:, 1] * np.roll(edges[:, 0], -1)
    if np.any(turn < -1e-9 * scale**2):
        bad = int(np.argmin(turn))
        raise GeometryError(f"polygon_xy is not convex (reflex turn after edge {bad})")
    winding = np.sum(np.arctan2(turn, np.sum(edges * np.roll(edges, -1, axis=0), axis=1)))
    if abs(winding - 2 * math.pi) > 1e-6:
        raise GeometryError("polygon_xy is not a simple convex polygon (it winds more than once)")
    return poly


def polygon_centroid(poly: np.ndarray) -> np.ndarray:
    """Area centroid of a simple polygon ``(k, 2)``; sums correctly rounded
    (``math.fsum``), the same bits on every machine (see :func:`volume_centroid`)."""
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * math.fsum(cross)
    sums = [math.fsum((x + xn) * cross), math.fsum((y + yn) * cross)]
    return np.array(sums) / (6.0 * area)


def extrude(poly: np.ndarray, height_m: float) -> np.ndarray:
    k = poly.shape[0]
    z = np.repeat([-0.5 * height_m, 0.5 * height_m], k)[:, None]
    return np.hstack([np.tile(poly, (2, 1)), z])
