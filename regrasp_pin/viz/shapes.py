"""Triangle meshes for what the viewer draws: tubes, spheres, arrows, box planes.

WebGL draws lines one pixel wide whatever the requested width, which is too thin to
read on a talk slide; paths are therefore drawn as tubes and points as small spheres.
Everything here is plain numpy (no meshcat), in whatever frame the input is given.
Each function returns ``(vertices (V, 3), triangles (F, 3) int)``.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_array, positive
from ..exceptions import InputError

__all__ = [
    "arrows_mesh",
    "box_edges",
    "box_planes_mesh",
    "icosphere",
    "merge_meshes",
    "spheres_mesh",
    "tube_mesh",
]

Mesh = tuple[np.ndarray, np.ndarray]


def merge_meshes(meshes: list[Mesh]) -> Mesh:
    """Concatenate meshes into one, re-indexing the triangles."""
    if not meshes:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes[:-1]])
    vertices = np.concatenate([v for v, _ in meshes])
    triangles = np.concatenate([f + o for (_, f), o in zip(meshes, offsets, strict=True)])
    return vertices, triangles


def icosphere(subdivisions: int = 1) -> Mesh:
    """A unit sphere: an icosahedron subdivided ``subdivisions`` times (outward triangles)."""
    phi = (1.0 + 5.0**0.5) / 2.0
    v = np.array(
        [
            [-1, phi, 0], [1, phi, 0], [-1, -phi, 0], [1, -phi, 0],
            [0, -1, phi], [0, 1, phi], [0, -1, -phi], [0, 1, -phi],
            [phi, 0, -1], [phi, 0, 1], [-phi, 0, -1], [-phi, 0, 1],
        ],
        dtype=float,
    )  # fmt: skip
    f = np.array(
        [
            [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
            [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
            [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
            [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
        ]
    )  # fmt: skip
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid_ids = len(v) + inverse.reshape(3, -1).T  # (F, 3): mids of edges 01, 12, 20
        v = np.concatenate([v, 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])])
        a, b, c = f.T
        ab, bc, ca = mid_ids.T
        f = np.concatenate(
            [np.stack(t, axis=1) for t in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))]
        )
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    return v, f


def spheres_mesh(centres: object, radius_m: float, subdivisions: int = 1) -> Mesh:
    """One sphere of radius ``radius_m`` [m] at each of ``centres (n, 3)``, as one mesh."""
    c = as_array(centres, "centres", (None, 3))
    r = positive(radius_m, "radius_m")
    v0, f0 = icosphere(subdivisions)
    vertices = (c[:, None, :] + r * v0[None]).reshape(-1, 3)
    triangles = (f0[None] + len(v0) * np.arange(len(c))[:, None, None]).reshape(-1, 3)
    return vertices, triangles


def _ring_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-vertex unit normals and binormals of a polyline, by parallel transport."""
    seg = np.diff(points, axis=0)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    tangents = np.concatenate([seg[:1], seg[:-1] + seg[1:], seg[-1:]])
    tangents /= np.maximum(np.linalg.norm(tangents, axis=1, keepdims=True), 1e-12)
    ref = np.eye(3)[int(np.argmin(np.abs(tangents[0])))]
    normals = np.empty_like(tangents)
    n = np.cross(tangents[0], ref)
    n /= np.linalg.norm(n)
    for i, t in enumerate(tangents):  # sequential by nature; polylines are short
        n = n - np.dot(n, t) * t
        norm = np.linalg.norm(n)
        if norm < 1e-9:  # the path reversed exactly: pick any perpendicular
            n = np.cross(t, np.eye(3)[int(np.argmin(np.abs(t)))])
            norm = np.linalg.norm(n)
        n = n / norm
        normals[i] = n
    return normals, np.cross(tangents, normals)


def tube_mesh(points: object, radius_m: float, sides: int = 8) -> Mesh:
    """A tube of radius ``radius_m`` [m] along the polyline ``points (K, 3)``, K >= 2.

    Consecutive duplicate points are dropped; the ends are left open.

    Raises:
        InputError: fewer than two distinct points, or a non-positive radius.
    """
    p = as_array(points, "points", (None, 3))
    r = positive(radius_m, "radius_m")
    if len(p):
        keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-12])
        p = p[keep]
    if len(p) < 2:
        raise InputError("points", f"has {len(p)} distinct points", "at least 2")
    normals, binormals = _ring_frames(p)
    ang = 2.0 * np.pi * np.arange(sides) / sides
    ring = (
        np.cos(ang)[None, :, None] * normals[:, None]
        + np.sin(ang)[None, :, None] * binormals[:, None]
    )
    vertices = (p[:, None, :] + r * ring).reshape(-1, 3)
    i = np.arange(len(p) - 1)[:, None]
    j = np.arange(sides)[None, :]
    a = i * sides + j
    b = i * sides + (j + 1) % sides
    c = a + sides
    d = b + sides
    triangles = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    return vertices, triangles


def arrows_mesh(
    origins: object, directions: object, length_m: float, radius_m: float, sides: int = 10
) -> Mesh:
    """Arrows (shaft and cone) from ``origins (n, 3)`` along ``directions (n, 3)``.

    Args:
        origins: Arrow tails ``(n, 3)``.
        directions: Directions ``(n, 3)`` (normalized here; zero rows are dropped).
        length_m: Arrow length [m] (the cone takes the last quarter).
        radius_m: Shaft radius [m] (the cone base is 2.5 times it).
        sides: Facets around the axis.
    """
    o = as_array(origins, "origins", (None, 3))
    d = as_array(directions, "directions", (len(o), 3))
    length = positive(length_m, "length_m")
    r = positive(radius_m, "radius_m")
    norm = np.linalg.norm(d, axis=1)
    o, d = o[norm > 1e-12], d[norm > 1e-12] / norm[norm > 1e-12, None]
    if len(o) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    ref = np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(d, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(d, u)
    ang = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.cos(ang)[None, :, None] * u[:, None] + np.sin(ang)[None, :, None] * w[:, None]
    shaft_end = o + 0.75 * length * d
    # per arrow: shaft tail ring, shaft head ring, cone base ring, apex
    verts = np.concatenate(
        [
            o[:, None] + r * ring,
            shaft_end[:, None] + r * ring,
            shaft_end[:, None] + 2.5 * r * ring,
            (o + length * d)[:, None],
        ],
        axis=1,
    )  # (n, 3 sides + 1, 3)
    j = np.arange(sides)
    jn = (j + 1) % sides
    apex = 3 * sides
    tri = np.concatenate(
        [
            np.stack([j, jn, sides + jn], 1),
            np.stack([j, sides + jn, sides + j], 1),
            np.stack([sides + j, sides + jn, 2 * sides + jn], 1),
            np.stack([sides + j, 2 * sides + jn, 2 * sides + j], 1),
            np.stack([2 * sides + j, 2 * sides + jn, np.full(sides, apex)], 1),
        ]
    )
    n_v = verts.shape[1]
    triangles = (tri[None] + n_v * np.arange(len(o))[:, None, None]).reshape(-1, 3)
    return verts.reshape(-1, 3), triangles


def box_planes_mesh(lower: object, upper: object) -> Mesh:
    """The six boundary planes of the box ``[lower, upper]`` as 12 triangles."""
    lo = as_array(lower, "lower", (3,))
    hi = as_array(upper, "upper", (3,))
    if np.any(hi <= lo):
        raise InputError("upper", "is not above lower on every axis", "upper > lower")
    corners = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = np.array(
        [[0, 2, 6, 4], [1, 5, 7, 3], [0, 4, 5, 1], [2, 3, 7, 6], [0, 1, 3, 2], [4, 6, 7, 5]]
    )  # faces x=lo, x=hi, y=lo, y=hi, z=lo, z=hi
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return corners, triangles


def box_edges(lower: object, upper: object) -> np.ndarray:
    """The 12 edges of the box ``[lower, upper]`` as segment end points ``(24, 3)``."""
    corners, _ = box_planes_mesh(lower, upper)
    pairs = [(i, i | (1 << k)) for i in range(8) for k in range(3) if not (i >> k) & 1]
    return corners[np.array(pairs).reshape(-1)]
