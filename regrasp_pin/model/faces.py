"""Planar faces of a convex polytope and the edges they share, in the object frame.

:class:`Face` carries a 2-D frame ``(origin, u, v)`` in its plane (``u x v = normal``);
:class:`FaceAdjacency` records an edge shared by two faces, so that later stages can unfold
adjacent faces about it. Both are built by :class:`regrasp_pin.model.objects.ConvexObject`
(and re-exported from :mod:`regrasp_pin.model.objects`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix

from .._validate import frozen
from ._polyhedra import cross, newell_normal

__all__ = ["Face", "FaceAdjacency"]


@dataclass(frozen=True, eq=False)
class Face:
    """One planar polygonal face of a convex object, in the object frame.

    Attributes:
        id: Index of the face in :attr:`ConvexObject.faces`.
        normal: Outward unit normal, shape (3,).
        offset: Plane offset [m]: points x of the plane satisfy ``normal . x = offset``.
        polygon: Vertices [m], shape (k, 3), counter-clockwise seen from outside.
        vertex_ids: Indices of ``polygon`` in :attr:`ConvexObject.vertices`, shape (k,).
        origin: Area centroid of the polygon [m], shape (3,): origin of the face frame.
        u: First in-plane unit axis, shape (3,), along the face's longest edge.
        v: Second in-plane unit axis, shape (3,), ``v = normal x u`` (so ``u x v = normal``).
        polygon_uv: ``polygon`` in face coordinates [m], shape (k, 2), counter-clockwise.
        area: Area of the face [m^2].
    """

    id: int
    normal: np.ndarray
    offset: float
    polygon: np.ndarray
    vertex_ids: np.ndarray
    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    polygon_uv: np.ndarray
    area: float

    def to_uv(self, p_object: np.ndarray) -> np.ndarray:
        """Face coordinates of points (projected onto the face plane).

        Args:
            p_object: Points in the object frame [m], shape (N, 3).

        Returns:
            Coordinates ``(u, v)`` [m] in the face frame, shape (N, 2).
        """
        d = np.asarray(p_object, dtype=float) - self.origin
        return np.stack([d @ self.u, d @ self.v], axis=-1)

    def from_uv(self, uv: np.ndarray) -> np.ndarray:
        """Points of the face plane from face coordinates.

        Args:
            uv: Face coordinates [m], shape (N, 2).

        Returns:
            Points in the object frame [m], shape (N, 3).
        """
        uv = np.asarray(uv, dtype=float)
        return self.origin + uv[..., :1] * self.u + uv[..., 1:2] * self.v

    def contains_uv(self, uv: np.ndarray, inset_m: float = 0.0) -> np.ndarray:
        """Whether face coordinates lie in the polygon shrunk by ``inset_m``.

        Args:
            uv: Face coordinates [m], shape (N, 2).
            inset_m: Minimum distance from every edge [m] (0: closed polygon).

        Returns:
            Boolean mask, shape (N,).
        """
        a = self.polygon_uv
        e = np.roll(a, -1, axis=0) - a
        m = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None]
        depth = (np.asarray(uv, dtype=float) @ m.T) - np.sum(a * m, axis=1)  # (N, k)
        return np.all(depth >= inset_m, axis=1)


@dataclass(frozen=True, eq=False)
class FaceAdjacency:
    """Two faces that share an edge.

    Attributes:
        face_a: Id of the first face (the smaller id).
        face_b: Id of the second face.
        edge: Endpoints of the shared edge [m], shape (2, 3), ordered so that
            ``edge[0] -> edge[1]`` runs counter-clockwise around ``face_a`` seen from
            outside (and so clockwise around ``face_b``).
        vertex_ids: Indices of the endpoints in :attr:`ConvexObject.vertices`, shape (2,).
    """

    face_a: int
    face_b: int
    edge: np.ndarray
    vertex_ids: np.ndarray


def make_face(face_id: int, verts: np.ndarray, ids: np.ndarray) -> Face:
    poly = verts[ids]
    normal = newell_normal(poly)
    offset = float(np.mean(poly @ normal))
    # Area centroid by a fan from vertex 0.
    a, b, c = poly[0], poly[1:-1], poly[2:]
    tri_area = 0.5 * np.linalg.norm(cross(b - a, c - a), axis=1)
    area = float(tri_area.sum())
    origin = (tri_area[:, None] * (a + b + c) / 3.0).sum(axis=0) / area
    origin = origin - (origin @ normal - offset) * normal
    edges = np.roll(poly, -1, axis=0) - poly
    lengths = np.linalg.norm(edges, axis=1)
    u = edges[int(np.argmax(lengths >= lengths.max() * (1.0 - 1e-9)))]  # first longest edge
    u = u - (u @ normal) * normal
    u /= np.linalg.norm(u)
    v = cross(normal, u)
    uv = np.stack([(poly - origin) @ u, (poly - origin) @ v], axis=1)
    return Face(
        id=face_id,
        normal=frozen(normal),
        offset=offset,
        polygon=frozen(poly),
        vertex_ids=frozen(ids.astype(np.int64)),
        origin=frozen(origin),
        u=frozen(u),
        v=frozen(v),
        polygon_uv=frozen(uv),
        area=area,
    )


def face_adjacency(faces: tuple[Face, ...], verts: np.ndarray) -> tuple[FaceAdjacency, ...]:
    """Faces sharing at least two vertices share an edge (convex polytope)."""
    rows = np.concatenate([np.full(len(f.vertex_ids), f.id) for f in faces])
    cols = np.concatenate([f.vertex_ids for f in faces])
    inc = csr_matrix(
        (np.ones(rows.size, dtype=np.int64), (rows, cols)), shape=(len(faces), verts.shape[0])
    )
    shared = (inc @ inc.T).tocoo()
    pairs = (shared.row < shared.col) & (shared.data >= 2)
    fa_all, fb_all = shared.row[pairs], shared.col[pairs]
    order = np.lexsort((fb_all, fa_all))
    out = []
    for fa, fb in zip(fa_all[order], fb_all[order], strict=True):
        common = np.intersect1d(faces[fa].vertex_ids, faces[fb].vertex_ids)
        pts = verts[common]
        d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        i, j = np.unravel_index(int(np.argmax(d)), d.shape)
        a, b = common[i], common[j]
        face = faces[fa]
        if cross(face.normal, verts[b] - verts[a]) @ (face.origin - verts[a]) < 0:
            a, b = b, a
        out.append(
            FaceAdjacency(
                face_a=int(fa),
                face_b=int(fb),
                edge=frozen(verts[[a, b]]),
                vertex_ids=frozen(np.array([a, b], dtype=np.int64)),
            )
        )
    return tuple(out)
