"""Convex objects in their own frame: faces, surface sampling, exact distances, Coal geometry.

The object frame has its origin at the centre of mass of the solid (uniform density),
as in section 2.1 of the paper ("a Cartesian system with the origin on the object
center of gravity"). Every object is a convex polytope described by its planar
polygonal faces:

* :class:`Box`, :class:`Prism` (regular n-gon extruded along z) and
  :class:`ExtrudedPolygon` (any convex polygon extruded along z) are the paper's
  prismatic objects (Fig. 1);
* :class:`ConvexMesh` (the convex hull of any point set) goes beyond the paper.

Each face carries a 2-D frame ``(origin, u, v)`` in its plane (``u x v = normal``) so
that later stages can work in face coordinates and unfold adjacent faces about their
shared edge (:attr:`ConvexObject.face_adjacency`). All arrays are read-only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from ._validate import as_array, positive, positive_int
from .exceptions import GeometryError, InputError

__all__ = [
    "Box",
    "ConvexMesh",
    "ConvexObject",
    "ExtrudedPolygon",
    "Face",
    "FaceAdjacency",
    "Prism",
    "SurfaceSample",
    "object_from_params",
]

_KINDS = ("box", "prism", "extrusion", "convex_mesh")
_CHUNK_ELEMENTS = 2_000_000  # bound on (points x candidates) arrays in distance queries


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(arr)
    arr.setflags(write=False)
    return arr


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


@dataclass(frozen=True, eq=False)
class SurfaceSample:
    """Points sampled on an object's surface, in the object frame.

    Attributes:
        points: Surface points [m], shape (N, 3).
        normals: Outward unit normals, shape (N, 3).
        face_ids: Face of each point, shape (N,) int.
        uv: Coordinates [m] of each point in its face's ``(origin, u, v)`` frame, shape (N, 2).
        spacing_m: Grid spacing used [m].
    """

    points: np.ndarray
    normals: np.ndarray
    face_ids: np.ndarray
    uv: np.ndarray
    spacing_m: float

    def __len__(self) -> int:
        return int(self.points.shape[0])


class ConvexObject:
    """A convex polytope with its frame at the centre of mass.

    Build one with :class:`Box`, :class:`Prism`, :class:`ExtrudedPolygon` or
    :class:`ConvexMesh`; the base constructor takes vertices already expressed in the
    object frame.

    Attributes:
        kind: ``"box"``, ``"prism"``, ``"extrusion"`` or ``"convex_mesh"``.
        params: JSON-able constructor arguments; ``object_from_params(kind, params)``
            rebuilds the object.
        vertices: Polytope vertices in the object frame [m], shape (V, 3).
        triangles: Outward counter-clockwise triangle mesh, shape (F, 3) int into
            ``vertices``.
        faces: The planar polygonal faces.
        face_adjacency: One entry per edge of the polytope: the two faces sharing it.
    """

    def __init__(
        self,
        vertices_object: np.ndarray,
        *,
        kind: str = "convex_mesh",
        params: dict[str, Any] | None = None,
        coplanar_tol: float = 1e-6,
    ) -> None:
        """Build the faces of the convex hull of ``vertices_object``.

        Args:
            vertices_object: Points in the object frame [m], shape (V, 3); their hull is
                the object. They are not re-centred (see :class:`ConvexMesh`).
            kind: Object kind recorded in plan files.
            params: JSON-able parameters; default ``{"vertices": ...}``.
            coplanar_tol: Hull triangles whose normals differ by less than this [rad]
                and whose plane offsets differ by less than this times the object
                radius are merged into one polygonal face.

        Raises:
            InputError: if the vertices are not a finite (V, 3) array.
            GeometryError: if the points are fewer than 4 or span no volume.
        """
        if kind not in _KINDS:
            raise InputError("kind", f"{kind!r} is not known", f"one of {_KINDS}")
        pts = as_array(vertices_object, "vertices", (None, 3))
        tol = positive(coplanar_tol, "coplanar_tol")
        verts, polys = _hull_polygons(pts, tol)
        self.kind = kind
        self.vertices = _frozen(verts)
        self.faces = tuple(_make_face(i, verts, ids) for i, ids in enumerate(polys))
        self.triangles = _frozen(
            np.concatenate([_fan(f.vertex_ids) for f in self.faces]).astype(np.int64)
        )
        self.face_adjacency = _adjacency(self.faces, verts)
        if params is None:
            params = {"vertices": verts.tolist()}
        self.params = params
        self._coal: Any = None
        self._samples: dict[float, SurfaceSample] = {}
        self._build_distance_tables()

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(kind={self.kind!r}, {len(self.vertices)} vertices, "
            f"{len(self.faces)} faces)"
        )

    # ------------------------------------------------------------------ geometry
    @property
    def normals(self) -> np.ndarray:
        """Outward unit face normals, shape (n_faces, 3)."""
        return self._normals

    @property
    def offsets(self) -> np.ndarray:
        """Face plane offsets [m], shape (n_faces,): ``normals @ x <= offsets`` inside."""
        return self._offsets

    @property
    def radius_m(self) -> float:
        """Largest distance of a vertex from the centre of mass [m]."""
        return float(np.max(np.linalg.norm(self.vertices, axis=1)))

    @property
    def volume_m3(self) -> float:
        """Volume of the solid [m^3]."""
        return float(sum(f.area * f.offset for f in self.faces) / 3.0)

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """The outward triangle mesh.

        Returns:
            ``(vertices (V, 3) [m], triangles (F, 3) int)`` in the object frame.
        """
        return self.vertices, self.triangles

    def to_dict(self) -> dict[str, Any]:
        """JSON-able description: kind, params, mesh ``vertices`` and ``faces`` (triangles)."""
        return {
            "kind": self.kind,
            "params": self.params,
            "vertices": self.vertices.tolist(),
            "faces": self.triangles.tolist(),
        }

    def surface_points(self, face_ids: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Points from face ids and face coordinates (vectorized :meth:`Face.from_uv`).

        Args:
            face_ids: Face of each point, shape (N,) int.
            uv: Face coordinates [m], shape (N, 2).

        Returns:
            Points in the object frame [m], shape (N, 3).
        """
        ids = np.asarray(face_ids, dtype=np.int64)
        uv = as_array(uv, "uv", (ids.shape[0], 2))
        return self._origins[ids] + uv[:, :1] * self._us[ids] + uv[:, 1:] * self._vs[ids]

    def coal_geometry(self) -> Any:
        """The Coal collision geometry in the object frame (built once, then cached).

        Returns:
            ``coal.Box`` for a box, otherwise a ``coal.Convex`` of :attr:`vertices`.
        """
        if self._coal is None:
            import coal

            if self.kind == "box" and "size" in self.params:
                self._coal = coal.Box(*[float(s) for s in self.params["size"]])
            else:
                pts = coal.StdVec_Vec3s()
                pts.extend([np.asarray(p, dtype=float) for p in self.vertices])
                self._coal = coal.Convex.convexHull(pts, False, None)
        return self._coal

    # ------------------------------------------------------------------ sampling
    def sample_surface(self, spacing_m: float) -> SurfaceSample:
        """Sample the surface on a regular grid per face.

        Each face gets a square grid of step ``spacing_m`` along its ``(u, v)`` axes,
        centred on the face's bounding box and kept where it is at least
        ``spacing_m / 2`` inside the polygon, so no point lies on an edge (where its
        face would be ambiguous). A face too small for any grid point gets its centroid.
        A face of area A therefore holds about ``A / spacing_m**2`` points.

        Args:
            spacing_m: Grid step [m], > 0.

        Returns:
            The sample (cached per spacing).

        Raises:
            InputError: if ``spacing_m`` is not a finite positive number.
        """
        s = positive(spacing_m, "spacing_m")
        if s in self._samples:
            return self._samples[s]
        uvs, ids = [], []
        for face in self.faces:  # per face (few); all points of a face at once
            lo, hi = face.polygon_uv.min(axis=0), face.polygon_uv.max(axis=0)
            n = np.maximum(np.floor((hi - lo) / s + 1e-9).astype(int), 1)
            axes = [
                0.5 * (lo[i] + hi[i]) + (np.arange(n[i]) - 0.5 * (n[i] - 1)) * s for i in range(2)
            ]
            gu, gv = np.meshgrid(axes[0], axes[1], indexing="ij")
            grid = np.stack([gu.ravel(), gv.ravel()], axis=1)
            keep = grid[face.contains_uv(grid, 0.5 * s * (1.0 - 1e-9))]
            if keep.shape[0] == 0:
                keep = np.zeros((1, 2))  # the area centroid, strictly inside
            uvs.append(keep)
            ids.append(np.full(keep.shape[0], face.id, dtype=np.int64))
        uv = np.concatenate(uvs)
        face_ids = np.concatenate(ids)
        sample = SurfaceSample(
            points=_frozen(self.surface_points(face_ids, uv)),
            normals=_frozen(self._normals[face_ids]),
            face_ids=_frozen(face_ids),
            uv=_frozen(uv),
            spacing_m=s,
        )
        self._samples[s] = sample
        return sample

    # ------------------------------------------------------------------ distances
    def contains(self, p_object: np.ndarray, tol_m: float = 0.0) -> np.ndarray:
        """Whether points lie in the closed solid (within ``tol_m`` of it along normals).

        Args:
            p_object: Points in the object frame [m], shape (N, 3).
            tol_m: Tolerance [m]; points at most this far outside every face plane count.

        Returns:
            Boolean mask, shape (N,).
        """
        p = as_array(p_object, "p_object", (None, 3))
        return np.max(p @ self._normals.T - self._offsets, axis=1) <= tol_m

    def signed_distance(self, p_object: np.ndarray) -> np.ndarray:
        """Exact Euclidean signed distance to the surface (negative inside).

        Inside, the distance is ``-min_f (offset_f - n_f . p)``; outside it is the
        distance to the nearest point of the polytope, found among the feet on the
        faces (where the foot lies in the face polygon) and the nearest points of all
        edges, so it is exact also in the regions of edges and vertices.

        Args:
            p_object: Points in the object frame [m], shape (N, 3).

        Returns:
            Signed distances [m], shape (N,).
        """
        p = as_array(p_object, "p_object", (None, 3))
        dist, _ = self._closest(p)
        plane = np.max(p @ self._normals.T - self._offsets, axis=1)
        return np.where(plane <= 0.0, plane, dist)

    def project_to_surface(self, p_object: np.ndarray) -> np.ndarray:
        """Nearest surface points (exact, for points inside or outside).

        Args:
            p_object: Points in the object frame [m], shape (N, 3).

        Returns:
            Nearest points on the surface [m], shape (N, 3).
        """
        p = as_array(p_object, "p_object", (None, 3))
        return self._closest(p)[1]

    def supporting_face(self, p_object: np.ndarray) -> np.ndarray:
        """Face whose plane lies most below each point: for surface points, their face.

        Args:
            p_object: Points in the object frame [m], shape (N, 3).

        Returns:
            Face ids, shape (N,) int.
        """
        p = as_array(p_object, "p_object", (None, 3))
        return np.argmax(p @ self._normals.T - self._offsets, axis=1)

    def _build_distance_tables(self) -> None:
        faces = self.faces
        self._normals = _frozen(np.array([f.normal for f in faces]))
        self._offsets = _frozen(np.array([f.offset for f in faces]))
        self._origins = _frozen(np.array([f.origin for f in faces]))
        self._us = _frozen(np.array([f.u for f in faces]))
        self._vs = _frozen(np.array([f.v for f in faces]))
        k = max(len(f.vertex_ids) for f in faces)
        # Per face, padded to k edges (padding repeats edge 0: a duplicate constraint).
        starts = np.empty((len(faces), k, 3))
        inward = np.empty((len(faces), k, 3))
        edges: set[tuple[int, ...]] = set()
        for i, f in enumerate(faces):
            a = f.polygon
            e = np.roll(a, -1, axis=0) - a
            m = _cross(f.normal, e)
            m /= np.linalg.norm(m, axis=1, keepdims=True)
            pad = k - len(a)
            starts[i] = np.concatenate([a, np.repeat(a[:1], pad, axis=0)])
            inward[i] = np.concatenate([m, np.repeat(m[:1], pad, axis=0)])
            ids = f.vertex_ids
            ring = np.sort(np.stack([ids, np.roll(ids, -1)], axis=1), axis=1)
            edges.update(map(tuple, ring.tolist()))
        self._edge_starts = starts
        self._edge_inward = inward
        self._edge_bias = np.einsum("fkd,fkd->fk", starts, inward)  # (F, k)
        seg = np.array(sorted(edges), dtype=np.int64)
        self._seg_a = self.vertices[seg[:, 0]]
        self._seg_d = self.vertices[seg[:, 1]] - self._seg_a

    def _closest(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unsigned distance to the surface and the nearest surface point, vectorized."""
        n_f, k = self._edge_bias.shape
        n_e = self._seg_a.shape[0]
        chunk = max(1, _CHUNK_ELEMENTS // max(n_f * k, n_e))
        dist = np.empty(p.shape[0])
        near = np.empty_like(p)
        eps = 1e-12 * max(self.radius_m, 1.0)
        for lo in range(0, p.shape[0], chunk):
            q = p[lo : lo + chunk]
            # Feet on face planes, valid where inside the face polygon.
            h = q @ self._normals.T - self._offsets  # (n, F)
            depth = np.einsum("nd,fkd->nfk", q, self._edge_inward) - self._edge_bias
            inside = np.all(depth >= -eps, axis=2)
            d_face = np.where(inside, np.abs(h), np.inf)
            jf = np.argmin(d_face, axis=1)
            # Nearest points on every edge segment.
            t = np.einsum("ned,ed->ne", q[:, None, :] - self._seg_a, self._seg_d)
            t = np.clip(t / np.sum(self._seg_d**2, axis=1), 0.0, 1.0)
            foot = self._seg_a + t[..., None] * self._seg_d  # (n, E, 3)
            d_edge = np.linalg.norm(q[:, None, :] - foot, axis=2)
            je = np.argmin(d_edge, axis=1)
            rows = np.arange(q.shape[0])
            df, de = d_face[rows, jf], d_edge[rows, je]
            use_face = df <= de
            dist[lo : lo + chunk] = np.where(use_face, df, de)
            p_face = q - h[rows, jf][:, None] * self._normals[jf]
            near[lo : lo + chunk] = np.where(use_face[:, None], p_face, foot[rows, je])
        return dist, near


# ---------------------------------------------------------------------- constructors
class Box(ConvexObject):
    """A rectangular box centred at its centre of mass, edges along the object axes."""

    def __init__(self, size: tuple[float, float, float] | np.ndarray) -> None:
        """Args:
            size: Full side lengths ``(sx, sy, sz)`` [m], each > 0.

        Raises:
            InputError: if ``size`` is not three finite positive numbers.
        """
        s = as_array(size, "size", (3,))
        if np.any(s <= 0):
            raise InputError("size", f"{s.tolist()} has a side <= 0", "three sides > 0 [m]")
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T
        super().__init__(0.5 * corners * s, kind="box", params={"size": s.tolist()})


class ExtrudedPolygon(ConvexObject):
    """A convex polygon in the xy plane extruded along z, centred at its centre of mass.

    The polygon is shifted so that its area centroid is the origin, and the extrusion
    spans ``z in [-height_m / 2, height_m / 2]``.
    """

    def __init__(self, polygon_xy: np.ndarray, height_m: float) -> None:
        """Args:
            polygon_xy: Convex polygon [m], shape (k, 2), k >= 3, either orientation
                (clockwise input is reversed). Collinear vertices are allowed.
            height_m: Extrusion height [m], > 0.

        Raises:
            InputError: if the arrays are malformed or ``height_m`` is not > 0.
            GeometryError: if the polygon is degenerate (repeated vertices, zero area)
                or not convex.
        """
        poly = _convex_polygon_ccw(polygon_xy)
        h = positive(height_m, "height_m")
        poly = poly - _polygon_centroid(poly)
        super().__init__(
            _extrude(poly, h),
            kind="extrusion",
            params={"polygon_xy": poly.tolist(), "height_m": h},
        )
        self.polygon_xy = _frozen(poly)


class Prism(ExtrudedPolygon):
    """A regular n-gon prism along z, centred at its centre of mass.

    The polygon's vertices are at angles ``(2 i + 1) pi / n_sides`` (so a 4-gon is an
    axis-aligned square).
    """

    def __init__(self, n_sides: int, circumradius_m: float, height_m: float) -> None:
        """Args:
            n_sides: Number of sides, >= 3.
            circumradius_m: Distance from the axis to the polygon's vertices [m], > 0.
            height_m: Height along z [m], > 0.

        Raises:
            InputError: for ``n_sides < 3`` or non-positive sizes.
        """
        n = positive_int(n_sides, "n_sides", minimum=3)
        r = positive(circumradius_m, "circumradius_m")
        h = positive(height_m, "height_m")
        ang = (2 * np.arange(n) + 1) * math.pi / n
        super().__init__(r * np.stack([np.cos(ang), np.sin(ang)], axis=1), h)
        self.kind = "prism"
        self.params = {"n_sides": n, "circumradius_m": r, "height_m": h}


class ConvexMesh(ConvexObject):
    """The convex hull of a point set, re-centred at its volume centroid.

    Hull triangles that are coplanar within ``coplanar_tol`` are merged into polygonal
    faces. :attr:`input_centroid` holds the centre of mass in the input coordinates,
    so ``p_object = p_input - input_centroid``.
    """

    def __init__(self, vertices: np.ndarray, *, coplanar_tol: float = 1e-6) -> None:
        """Args:
            vertices: Points [m], shape (V, 3), V >= 4, spanning a volume.
            coplanar_tol: See :class:`ConvexObject`.

        Raises:
            InputError: if ``vertices`` is not a finite (V, 3) array.
            GeometryError: if the points are fewer than 4 or flat.
        """
        pts = as_array(vertices, "vertices", (None, 3))
        hull = _hull(pts)
        c = _volume_centroid(pts[hull.vertices], hull)
        centred = pts[hull.vertices] - c
        super().__init__(centred, kind="convex_mesh", coplanar_tol=coplanar_tol)
        self.input_centroid = _frozen(c)


def object_from_params(kind: str, params: dict[str, Any]) -> ConvexObject:
    """Rebuild an object from its :attr:`ConvexObject.kind` and :attr:`ConvexObject.params`.

    Raises:
        InputError: if ``kind`` is unknown or ``params`` do not fit it.
    """
    classes = {"box": Box, "prism": Prism, "extrusion": ExtrudedPolygon, "convex_mesh": ConvexMesh}
    if kind not in classes:
        raise InputError("kind", f"{kind!r} is not known", f"one of {tuple(classes)}")
    try:
        return classes[kind](**params)
    except TypeError as exc:
        raise InputError("params", f"do not fit kind {kind!r} ({exc})") from None


# ---------------------------------------------------------------------- construction
def _hull(pts: np.ndarray) -> ConvexHull:
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


def _volume_centroid(pts: np.ndarray, hull: ConvexHull) -> np.ndarray:
    """Centroid of the solid hull: tetrahedra from an interior point to each triangle."""
    c0 = pts.mean(axis=0)
    tri = hull.points[hull.simplices]  # (T, 3, 3)
    vol = np.abs(np.linalg.det(tri - c0)) / 6.0
    cent = (c0 + tri.sum(axis=1)) / 4.0
    return (vol[:, None] * cent).sum(axis=0) / vol.sum()


def _hull_polygons(pts: np.ndarray, tol: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Canonical hull vertices (lexicographic) and CCW polygon index lists (sorted faces).

    Neighbouring hull triangles whose planes agree within ``tol`` are merged into one
    polygonal face (connected components over the triangle adjacency).
    """
    hull = _hull(pts)
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
    normals = np.array([_newell_normal(verts[ring]) for ring in polys])
    keys = np.round(normals, 9)
    face_order = np.lexsort((-keys[:, 2], -keys[:, 1], -keys[:, 0]))
    kept = np.unique(np.concatenate(polys))
    remap = np.full(verts.shape[0], -1, dtype=np.int64)
    remap[kept] = np.arange(kept.size)
    return verts[kept], [remap[polys[i]] for i in face_order]


def _fan(ids: np.ndarray) -> np.ndarray:
    """Fan triangulation (k - 2, 3) of a convex polygon's vertex ids, same orientation."""
    return np.stack([np.full(len(ids) - 2, ids[0]), ids[1:-1], ids[2:]], axis=1)


def _plane_axes(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = _cross(normal, a)
    u /= np.linalg.norm(u)
    return u, _cross(normal, u)


def _newell_normal(poly: np.ndarray) -> np.ndarray:
    nrm = np.sum(_cross(poly, np.roll(poly, -1, axis=0)), axis=0)
    return nrm / np.linalg.norm(nrm)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product on the last axis (cheaper than np.cross for small arrays)."""
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def _make_face(face_id: int, verts: np.ndarray, ids: np.ndarray) -> Face:
    poly = verts[ids]
    normal = _newell_normal(poly)
    offset = float(np.mean(poly @ normal))
    # Area centroid by a fan from vertex 0.
    a, b, c = poly[0], poly[1:-1], poly[2:]
    tri_area = 0.5 * np.linalg.norm(_cross(b - a, c - a), axis=1)
    area = float(tri_area.sum())
    origin = (tri_area[:, None] * (a + b + c) / 3.0).sum(axis=0) / area
    origin = origin - (origin @ normal - offset) * normal
    edges = np.roll(poly, -1, axis=0) - poly
    lengths = np.linalg.norm(edges, axis=1)
    u = edges[int(np.argmax(lengths >= lengths.max() * (1.0 - 1e-9)))]  # first longest edge
    u = u - (u @ normal) * normal
    u /= np.linalg.norm(u)
    v = _cross(normal, u)
    uv = np.stack([(poly - origin) @ u, (poly - origin) @ v], axis=1)
    return Face(
        id=face_id,
        normal=_frozen(normal),
        offset=offset,
        polygon=_frozen(poly),
        vertex_ids=_frozen(ids.astype(np.int64)),
        origin=_frozen(origin),
        u=_frozen(u),
        v=_frozen(v),
        polygon_uv=_frozen(uv),
        area=area,
    )


def _adjacency(faces: tuple[Face, ...], verts: np.ndarray) -> tuple[FaceAdjacency, ...]:
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
        if _cross(face.normal, verts[b] - verts[a]) @ (face.origin - verts[a]) < 0:
            a, b = b, a
        out.append(
            FaceAdjacency(
                face_a=int(fa),
                face_b=int(fb),
                edge=_frozen(verts[[a, b]]),
                vertex_ids=_frozen(np.array([a, b], dtype=np.int64)),
            )
        )
    return tuple(out)


def _convex_polygon_ccw(polygon_xy: np.ndarray) -> np.ndarray:
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


def _polygon_centroid(poly: np.ndarray) -> np.ndarray:
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


def _extrude(poly: np.ndarray, height_m: float) -> np.ndarray:
    k = poly.shape[0]
    z = np.repeat([-0.5 * height_m, 0.5 * height_m], k)[:, None]
    return np.hstack([np.tile(poly, (2, 1)), z])
