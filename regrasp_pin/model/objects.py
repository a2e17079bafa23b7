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

from .._validate import as_array, frozen, hand_scale, positive, positive_int
from ..exceptions import InputError
from ._polyhedra import (
    convex_hull,
    convex_polygon_ccw,
    cross,
    extrude,
    fan_triangles,
    hull_polygons,
    polygon_centroid,
    volume_centroid,
)
from .faces import Face, FaceAdjacency, face_adjacency, make_face

__all__ = [
    "OBJECT_KINDS",
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

#: Every object kind (:attr:`ConvexObject.kind`; what a plan file may hold).
OBJECT_KINDS = ("box", "prism", "extrusion", "convex_mesh")
_CHUNK_ELEMENTS = 2_000_000  # bound on (points x candidates) arrays in distance queries


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
        if kind not in OBJECT_KINDS:
            raise InputError("kind", f"{kind!r} is not known", f"one of {OBJECT_KINDS}")
        pts = as_array(vertices_object, "vertices", (None, 3))
        if pts.size:
            hand_scale(float(np.ptp(pts, axis=0).max()), "vertices")
        tol = positive(coplanar_tol, "coplanar_tol")
        verts, polys = hull_polygons(pts, tol)
        self.kind = kind
        self.vertices = frozen(verts)
        self.faces = tuple(make_face(i, verts, ids) for i, ids in enumerate(polys))
        self.triangles = frozen(
            np.concatenate([fan_triangles(f.vertex_ids) for f in self.faces]).astype(np.int64)
        )
        self.face_adjacency = face_adjacency(self.faces, verts)
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
            points=frozen(self.surface_points(face_ids, uv)),
            normals=frozen(self._normals[face_ids]),
            face_ids=frozen(face_ids),
            uv=frozen(uv),
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
        self._normals = frozen(np.array([f.normal for f in faces]))
        self._offsets = frozen(np.array([f.offset for f in faces]))
        self._origins = frozen(np.array([f.origin for f in faces]))
        self._us = frozen(np.array([f.u for f in faces]))
        self._vs = frozen(np.array([f.v for f in faces]))
        k = max(len(f.vertex_ids) for f in faces)
        # Per face, padded to k edges (padding repeats edge 0: a duplicate constraint).
        starts = np.empty((len(faces), k, 3))
        inward = np.empty((len(faces), k, 3))
        edges: set[tuple[int, ...]] = set()
        for i, f in enumerate(faces):
            a = f.polygon
            e = np.roll(a, -1, axis=0) - a
            m = cross(f.normal, e)
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
        hand_scale(float(s.max()), "size")
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
        poly = convex_polygon_ccw(polygon_xy)
        h = hand_scale(positive(height_m, "height_m"), "height_m")
        hand_scale(float(np.ptp(poly, axis=0).max()), "polygon_xy")
        poly = poly - polygon_centroid(poly)
        super().__init__(
            extrude(poly, h),
            kind="extrusion",
            params={"polygon_xy": poly.tolist(), "height_m": h},
        )
        self.polygon_xy = frozen(poly)


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
        r = hand_scale(positive(circumradius_m, "circumradius_m"), "circumradius_m")
        h = hand_scale(positive(height_m, "height_m"), "height_m")
        ang = (2 * np.arange(n) + 1) * math.pi / n
        super().__init__(r * np.stack([np.cos(ang), np.sin(ang)], axis=1), h)
        self.kind = "prism"
        self.params = {"n_sides": n, "circumradius_m": r, "height_m": h}


#: A point set whose volume centroid lies within this many times its extent of the
#: origin is centred already (rounding): :class:`ConvexMesh` keeps it as it is, so that
#: a mesh rebuilt from its own vertices (a plan file's) has the same vertices, bit for bit.
CENTRED_RTOL = 1e-12


class ConvexMesh(ConvexObject):
    """The convex hull of a point set, re-centred at its volume centroid.

    Hull triangles that are coplanar within ``coplanar_tol`` are merged into polygonal
    faces. :attr:`input_centroid` holds the centre of mass in the input coordinates,
    so ``p_object = p_input - input_centroid`` (zero for points centred already, to
    :data:`CENTRED_RTOL`).
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
        hull = convex_hull(pts)
        c = volume_centroid(pts[hull.vertices], hull)
        spread = float(np.max(np.abs(pts[hull.vertices] - c)))
        if float(np.max(np.abs(c))) <= CENTRED_RTOL * spread:
            c = np.zeros(3)  # centred already, to rounding: kept as they are
        centred = pts[hull.vertices] - c
        super().__init__(centred, kind="convex_mesh", coplanar_tol=coplanar_tol)
        self.input_centroid = frozen(c)


_OBJECT_CLASSES: dict[str, type[ConvexObject]] = {
    "box": Box,
    "prism": Prism,
    "extrusion": ExtrudedPolygon,
    "convex_mesh": ConvexMesh,
}


def object_from_params(kind: str, params: dict[str, Any]) -> ConvexObject:
    """Rebuild an object from its :attr:`ConvexObject.kind` and :attr:`ConvexObject.params`.

    Raises:
        InputError: if ``kind`` is unknown or ``params`` do not fit it.
    """
    classes = _OBJECT_CLASSES
    if kind not in classes:
        raise InputError("kind", f"{kind!r} is not known", f"one of {tuple(classes)}")
    try:
        return classes[kind](**params)
    except TypeError as exc:
        raise InputError("params", f"do not fit kind {kind!r} ({exc})") from None
