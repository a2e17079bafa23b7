"""The unfolded surface region that holds P and Q, and a grid over it (section 2.2, Fig. 4).

Section 2.1 of the paper chooses "a limited object region containing points P and Q"
and builds a mesh over it; section 2.2 turns that mesh into "a grid in the plane"
(Fig. 4) on which the path from P to Q is planned. Here the region is a set of planar
faces of the convex object *unfolded* into the plane of P's face:

* if P and Q lie on one face, the region is that face, plus (by default) each
  neighbouring face rotated about their shared edge into the same plane, so a path
  may leave the face where node costs make that cheaper;
* otherwise it is the chain of adjacent faces (at most ``max_faces``) from P's face
  to Q's face whose unfolded region holds the shortest P -> Q route, each face
  rotated about the edge it shares with the previous one (a polyhedron net along the
  chain).

Unfolding is an isometry per face, so a straight segment in the unfolded plane that
stays inside the region is a surface path of the same length (it crosses from one face
to the next through their shared edge). The grid is a square lattice of step
``spacing_m`` anchored at P with its first axis along the unfolded P -> Q direction;
its nodes are joined by the 16-neighbour stencil (8 king and 8 knight moves) wherever
the straight segment stays inside the region. Build with :func:`build_surface_grid`,
solve with :func:`regrasp_pin.surface.path.shortest_grid_path`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .._validate import as_array, frozen, positive, positive_int
from ..exceptions import GeometryError, InputError
from ..model.objects import ConvexObject, FaceAdjacency

__all__ = ["FaceUnfolding", "SurfaceGrid", "build_surface_grid", "unfold_faces"]

log = logging.getLogger(__name__)

ON_SURFACE_TOL_M = 1e-6  # P and Q must lie this close to the surface [m]
_TOL_M = 1e-9  # geometric slack for containment and touching tests [m]
# Half of the 16-neighbour stencil in lattice steps (the other half is the reverse).
_STENCIL = np.array([(1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2)])


def _rot2(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s], [s, c]])


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@dataclass(frozen=True, eq=False)
class FaceUnfolding:
    """Where one face of the object lies in the unfolded plane.

    The map is the rigid motion ``x_unfolded = rotation @ uv_face + translation`` from
    the face's own ``(u, v)`` coordinates (:class:`regrasp_pin.model.objects.Face`) to the
    unfolded plane; it preserves lengths and orientation (seen from outside).

    Attributes:
        face_id: Id of the face in ``obj.faces``.
        rotation: 2-D rotation, shape (2, 2).
        translation: Translation [m], shape (2,).
        polygon_uv: The face polygon in the unfolded plane [m], shape (k, 2),
            counter-clockwise.
        parent: Face this one was unfolded about (None for the root face, P's face).
        hinge_uv: The edge shared with ``parent`` in the unfolded plane [m], shape (2, 2),
            ordered counter-clockwise around the parent (None for the root).
        origin_object: Face frame origin in the object frame [m], shape (3,).
        u_object: Face frame first axis, shape (3,).
        v_object: Face frame second axis, shape (3,).
        normal_object: Outward unit normal of the face, shape (3,).
    """

    face_id: int
    rotation: np.ndarray
    translation: np.ndarray
    polygon_uv: np.ndarray
    parent: int | None
    hinge_uv: np.ndarray | None
    origin_object: np.ndarray
    u_object: np.ndarray
    v_object: np.ndarray
    normal_object: np.ndarray

    def to_unfolded(self, uv_face: np.ndarray) -> np.ndarray:
        """Unfolded coordinates of face coordinates.

        Args:
            uv_face: Coordinates in the face's ``(u, v)`` frame [m], shape (N, 2).

        Returns:
            Unfolded coordinates [m], shape (N, 2).
        """
        return np.asarray(uv_face, dtype=float) @ self.rotation.T + self.translation

    def to_face(self, uv_unfolded: np.ndarray) -> np.ndarray:
        """Face coordinates of unfolded coordinates (inverse of :meth:`to_unfolded`).

        Args:
            uv_unfolded: Unfolded coordinates [m], shape (N, 2).

        Returns:
            Coordinates in the face's ``(u, v)`` frame [m], shape (N, 2).
        """
        return (np.asarray(uv_unfolded, dtype=float) - self.translation) @ self.rotation

    def to_object(self, uv_unfolded: np.ndarray) -> np.ndarray:
        """Points of the face plane, object frame, from unfolded coordinates.

        Args:
            uv_unfolded: Unfolded coordinates [m], shape (N, 2).

        Returns:
            Points in the object frame [m], shape (N, 3).
        """
        uv = self.to_face(uv_unfolded)
        return self.origin_object + uv[:, :1] * self.u_object + uv[:, 1:] * self.v_object


@dataclass(frozen=True, eq=False)
class SurfaceGrid:
    """A grid over the unfolded surface region holding P and Q (Fig. 4).

    Node ``p_index`` is P and node ``q_index`` is Q; all other nodes form a square
    lattice of step ``spacing_m`` anchored at P with its first axis along the unfolded
    P -> Q direction. Every edge is a straight segment of the unfolded plane inside the
    region, so its length is also the length of the surface path it stands for.

    Attributes:
        uv: Node coordinates in the unfolded plane [m], shape (M, 2).
        points_object: Node positions on the surface, object frame [m], shape (M, 3).
        normals_object: Outward unit normal of each node's face, shape (M, 3).
        face_ids: Face of each node, shape (M,) int (on a shared edge: one of the two).
        p_index: Index of P among the nodes.
        q_index: Index of Q among the nodes.
        edges: Node pairs joined by an edge, shape (E, 2) int, each pair once.
        edge_lengths_m: Edge lengths [m], shape (E,) (unfolded = surface length).
        face_chain: Faces from P's face to Q's face, in unfolding order.
        unfoldings: Map of every face of the region to the unfolded plane: first the
            faces of ``face_chain`` in order, then any neighbouring faces added.
        spacing_m: Lattice step [m].
        P_object: P projected onto its face, object frame [m], shape (3,).
        Q_object: Q projected onto its face, object frame [m], shape (3,).
        geodesic_m: Length of the shortest P -> Q route inside the unfolded region [m]
            (exact, from the region's reflex corners; the straight distance when the
            segment P -> Q stays inside).
    """

    uv: np.ndarray
    points_object: np.ndarray
    normals_object: np.ndarray
    face_ids: np.ndarray
    p_index: int
    q_index: int
    edges: np.ndarray
    edge_lengths_m: np.ndarray
    face_chain: tuple[int, ...]
    unfoldings: tuple[FaceUnfolding, ...]
    spacing_m: float
    P_object: np.ndarray
    Q_object: np.ndarray
    geodesic_m: float

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    @property
    def polygons_uv(self) -> tuple[np.ndarray, ...]:
        """The face polygons of the region in the unfolded plane [m], each (k, 2)."""
        return tuple(f.polygon_uv for f in self.unfoldings)

    @property
    def hinges_uv(self) -> tuple[np.ndarray, ...]:
        """The edges between unfolded faces in the unfolded plane [m], each (2, 2)."""
        return tuple(f.hinge_uv for f in self.unfoldings if f.hinge_uv is not None)

    def piece_of(self, uv_unfolded: np.ndarray) -> np.ndarray:
        """Index into :attr:`unfoldings` of the face each unfolded point lies deepest in.

        Args:
            uv_unfolded: Unfolded coordinates [m], shape (K, 2).

        Returns:
            Indices into :attr:`unfoldings`, shape (K,) int (ties: the first face).
        """
        uv = as_array(uv_unfolded, "uv_unfolded", (None, 2))
        return np.argmax(_depths(uv, self.unfoldings), axis=1)

    def contains(self, uv_unfolded: np.ndarray, tol_m: float = _TOL_M) -> np.ndarray:
        """Whether unfolded points lie in the region (within ``tol_m``).

        Args:
            uv_unfolded: Unfolded coordinates [m], shape (K, 2).
            tol_m: Slack [m].

        Returns:
            Boolean mask, shape (K,).
        """
        uv = as_array(uv_unfolded, "uv_unfolded", (None, 2))
        return np.max(_depths(uv, self.unfoldings), axis=1) >= -tol_m

    def segments_inside(self, a_uv: np.ndarray, b_uv: np.ndarray) -> np.ndarray:
        """Whether straight unfolded segments ``a -> b`` stay inside the region.

        Such a segment is a surface path of the same length (see module docstring).

        Args:
            a_uv: Segment starts [m], shape (K, 2).
            b_uv: Segment ends [m], shape (K, 2).

        Returns:
            Boolean mask, shape (K,).
        """
        a = as_array(a_uv, "a_uv", (None, 2))
        b = as_array(b_uv, "b_uv", (a.shape[0], 2))
        return _segments_inside(a, b, self.unfoldings)

    def to_object(
        self, uv_unfolded: np.ndarray, face_ids: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Map unfolded points back onto the object surface (vectorized).

        Args:
            uv_unfolded: Unfolded coordinates [m], shape (K, 2), inside the region.
            face_ids: Face to map each point with, shape (K,) int (faces of the
                region); default the face each point lies deepest in.

        Returns:
            ``(points (K, 3) [m], normals (K, 3), face_ids (K,))`` in the object frame.

        Raises:
            InputError: if a point lies outside the region by more than 1e-6 m, or a
                face id is not a face of the region.
        """
        uv = as_array(uv_unfolded, "uv_unfolded", (None, 2))
        depth = _depths(uv, self.unfoldings)
        if face_ids is None:
            piece = np.argmax(depth, axis=1)
        else:
            ids = np.asarray(face_ids, dtype=np.int64)
            if ids.shape != (uv.shape[0],):
                raise InputError("face_ids", f"has shape {ids.shape}", f"({uv.shape[0]},)")
            lookup = np.full(
                max(max(f.face_id for f in self.unfoldings), int(ids.max(initial=0))) + 1, -1
            )
            lookup[[f.face_id for f in self.unfoldings]] = np.arange(len(self.unfoldings))
            piece = lookup[np.clip(ids, 0, None)]
            if np.any(piece < 0) or np.any(ids < 0):
                raise InputError(
                    "face_ids",
                    "holds a face that is not in the region",
                    f"ids among {[f.face_id for f in self.unfoldings]}",
                )
        worst = -float(np.min(np.max(depth, axis=1), initial=0.0))
        if worst > ON_SURFACE_TOL_M:
            raise InputError("uv_unfolded", f"a point lies {worst:.3g} m outside the region")
        return _lift(self.unfoldings, uv, piece)


def _lift(
    pieces: Sequence[FaceUnfolding], uv: np.ndarray, piece: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Object-frame points, normals and face ids of unfolded points mapped by ``pieces[piece]``."""
    rot = np.stack([f.rotation for f in pieces])[piece]  # (K, 2, 2)
    tra = np.stack([f.translation for f in pieces])[piece]
    uv_face = np.einsum("kji,kj->ki", rot, uv - tra)  # rotation^T (x - t)
    origin = np.stack([f.origin_object for f in pieces])[piece]
    u = np.stack([f.u_object for f in pieces])[piece]
    v = np.stack([f.v_object for f in pieces])[piece]
    normal = np.stack([f.normal_object for f in pieces])[piece]
    points = origin + uv_face[:, :1] * u + uv_face[:, 1:] * v
    fid = np.array([f.face_id for f in pieces], dtype=np.int64)[piece]
    return points, normal, fid


# ---------------------------------------------------------------------- unfolding
def unfold_faces(
    obj: ConvexObject,
    face_ids: Sequence[int],
    parents: Sequence[int | None] | None = None,
) -> tuple[FaceUnfolding, ...]:
    """Unfold faces into the plane of the first one, each about the edge it shares with its parent.

    Args:
        obj: The convex object.
        face_ids: Faces to unfold; the first is the root (its ``(u, v)`` frame is the
            unfolded frame).
        parents: Parent face of each face (None for the root); every parent must come
            earlier in ``face_ids`` and share an edge with the face. Default: a chain,
            each face unfolded about the previous one.

    Returns:
        One :class:`FaceUnfolding` per face, in the order of ``face_ids``.

    Raises:
        InputError: if a face id is out of range or the lists do not fit.
        GeometryError: if a face and its parent share no edge.
    """
    ids = [int(i) for i in face_ids]
    if not ids:
        raise InputError("face_ids", "is empty", "at least one face id")
    n_faces = len(obj.faces)
    for i in ids:
        if not 0 <= i < n_faces:
            raise InputError("face_ids", f"{i} is not a face id", f"ids in [0, {n_faces})")
    if parents is None:
        parents = [None, *ids[:-1]]
    if len(parents) != len(ids) or parents[0] is not None:
        raise InputError("parents", "must hold one parent per face, None for the first")
    adjacency = _adjacency_map(obj)
    done: dict[int, FaceUnfolding] = {}
    out = []
    for fid, parent in zip(ids, parents, strict=True):  # per face (a handful)
        face = obj.faces[fid]
        if parent is None:
            rot, tra, hinge = np.eye(2), np.zeros(2), None
        else:
            if parent not in done:
                raise InputError("parents", f"parent {parent} of face {fid} comes later")
            adj = adjacency.get((min(fid, parent), max(fid, parent)))
            if adj is None:
                raise GeometryError(f"faces {parent} and {fid} share no edge: cannot unfold")
            rot, tra, hinge = _hinge_map(obj, done[parent], fid, adj)
        unf = FaceUnfolding(
            face_id=fid,
            rotation=frozen(rot),
            translation=frozen(tra),
            polygon_uv=frozen(face.polygon_uv @ rot.T + tra),
            parent=parent,
            hinge_uv=None if hinge is None else frozen(hinge),
            origin_object=face.origin,
            u_object=face.u,
            v_object=face.v,
            normal_object=face.normal,
        )
        done[fid] = unf
        out.append(unf)
    return tuple(out)


def _adjacency_map(obj: ConvexObject) -> dict[tuple[int, int], FaceAdjacency]:
    return {(a.face_a, a.face_b): a for a in obj.face_adjacency}


def _hinge_map(
    obj: ConvexObject, parent: FaceUnfolding, fid: int, adj: FaceAdjacency
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rigid map of face ``fid`` that lays its shared edge onto the parent's unfolded edge."""
    pface, face = obj.faces[parent.face_id], obj.faces[fid]
    e0, e1 = adj.edge if adj.face_a == parent.face_id else adj.edge[::-1]  # CCW around parent
    hinge = parent.to_unfolded(pface.to_uv(np.stack([e0, e1])))  # (2, 2)
    c = face.to_uv(np.stack([e0, e1]))
    dh, dc = hinge[1] - hinge[0], c[1] - c[0]
    rot = _rot2(math.atan2(dh[1], dh[0]) - math.atan2(dc[1], dc[0]))
    return rot, hinge[0] - rot @ c[0], hinge


# ---------------------------------------------------------------------- 2-D geometry
def _halfplanes(pieces: Sequence[FaceUnfolding]) -> tuple[np.ndarray, np.ndarray]:
    """Inward unit edge normals (F, k, 2) and biases (F, k), padded by repeating edge 0."""
    k = max(p.polygon_uv.shape[0] for p in pieces)
    normals = np.empty((len(pieces), k, 2))
    bias = np.empty((len(pieces), k))
    for i, p in enumerate(pieces):  # per face (a handful)
        a = p.polygon_uv
        e = np.roll(a, -1, axis=0) - a
        m = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None]
        c = np.sum(a * m, axis=1)
        pad = k - a.shape[0]
        normals[i] = np.concatenate([m, np.repeat(m[:1], pad, axis=0)])
        bias[i] = np.concatenate([c, np.repeat(c[:1], pad)])
    return normals, bias


def _depths(uv: np.ndarray, pieces: Sequence[FaceUnfolding]) -> np.ndarray:
    """Signed depth [m] of points inside each piece (min over its edges), shape (N, F)."""
    normals, bias = _halfplanes(pieces)
    return np.min(np.einsum("nd,fkd->nfk", uv, normals) - bias, axis=2)


def _segments_inside(
    a: np.ndarray, b: np.ndarray, pieces: Sequence[FaceUnfolding], tol_m: float = _TOL_M
) -> np.ndarray:
    """Whether each segment ``a -> b`` is covered by the union of the convex pieces.

    Each piece clips the segment to a parameter interval (Cyrus-Beck); the segment is
    inside when the intervals cover ``[0, 1]`` without a gap.
    """
    normals, bias = _halfplanes(pieces)
    d = b - a
    da = np.einsum("nd,fkd->nfk", a, normals) - bias + tol_m  # depth at a, with slack
    dd = np.einsum("nd,fkd->nfk", d, normals)  # rate of change along the segment
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = -da / dd
    enter = np.where(dd > 0, bound, -np.inf)
    leave = np.where(dd < 0, bound, np.inf)
    never = (dd == 0) & (da < 0)
    t0 = np.maximum(np.max(enter, axis=2), 0.0)
    t1 = np.minimum(np.min(leave, axis=2), 1.0)
    empty = (t0 > t1) | np.any(never, axis=2)
    t0 = np.where(empty, np.inf, t0)
    order = np.argsort(t0, axis=1)
    t0 = np.take_along_axis(t0, order, axis=1)
    t1 = np.take_along_axis(t1, order, axis=1)
    reach = np.zeros(a.shape[0])
    eps = 1e-12
    for j in range(t0.shape[1]):  # per piece (a handful), vectorized over segments
        ok = t0[:, j] <= reach + eps
        reach = np.where(ok, np.maximum(reach, t1[:, j]), reach)
    return reach >= 1.0 - eps


def _polygons_overlap(a: np.ndarray, b: np.ndarray, tol_m: float = _TOL_M) -> bool:
    """Separating-axis test: do two convex polygons share interior (more than touch)?"""
    for poly in (a, b):
        e = np.roll(poly, -1, axis=0) - poly
        axes = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None]
        pa, pb = a @ axes.T, b @ axes.T
        if np.any(
            (pa.max(axis=0) <= pb.min(axis=0) + tol_m) | (pb.max(axis=0) <= pa.min(axis=0) + tol_m)
        ):
            return False
    return True


def _clamp_into(uv: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Nearest point of a closed convex polygon to a 2-D point (the point if inside)."""
    a = poly
    e = np.roll(a, -1, axis=0) - a
    m = np.stack([-e[:, 1], e[:, 0]], axis=1)
    if np.all(np.sum((uv - a) * m, axis=1) >= 0):
        return uv
    t = np.clip(np.sum((uv - a) * e, axis=1) / np.sum(e * e, axis=1), 0.0, 1.0)
    foot = a + t[:, None] * e
    return foot[int(np.argmin(np.linalg.norm(foot - uv, axis=1)))]


def _region_geodesic(p_uv: np.ndarray, q_uv: np.ndarray, pieces: Sequence[FaceUnfolding]) -> float:
    """Shortest P -> Q route inside the region: Dijkstra over the visibility graph of
    P, Q and the endpoints of the hinges (the only possible reflex corners)."""
    if _segments_inside(p_uv[None], q_uv[None], pieces)[0]:
        return float(np.linalg.norm(q_uv - p_uv))
    hinge_ends = [h for p in pieces if p.hinge_uv is not None for h in p.hinge_uv]
    pts = np.vstack([p_uv, q_uv, *hinge_ends]) if hinge_ends else np.vstack([p_uv, q_uv])
    i, j = np.triu_indices(pts.shape[0], k=1)
    ok = _segments_inside(pts[i], pts[j], pieces)
    length = np.linalg.norm(pts[j] - pts[i], axis=1)
    ok &= length > 0
    graph = csr_matrix((length[ok], (i[ok], j[ok])), shape=(pts.shape[0],) * 2)
    return float(dijkstra(graph, directed=False, indices=0)[1])


# ---------------------------------------------------------------------- region choice
def _faces_holding(obj: ConvexObject, p: np.ndarray, argument: str) -> list[int]:
    """Faces that hold a surface point (several on an edge or a vertex), sorted by id."""
    dist = float(obj.signed_distance(p[None])[0])
    if abs(dist) > ON_SURFACE_TOL_M:
        raise InputError(
            argument,
            f"is not on the object surface (distance {dist:.3g} m)",
            f"a point within {ON_SURFACE_TOL_M:g} m of the surface",
        )
    tol = 2 * ON_SURFACE_TOL_M
    plane = np.abs(obj.normals @ p - obj.offsets)
    ids = [
        f.id
        for f in obj.faces
        if plane[f.id] <= tol and bool(f.contains_uv(f.to_uv(p[None]), -tol)[0])
    ]
    return ids or [int(obj.supporting_face(p[None])[0])]


def _chains(
    obj: ConvexObject, starts: list[int], goals: list[int], max_faces: int
) -> list[tuple[int, ...]]:
    """All simple chains of adjacent faces from a start face to a goal face (depth-first)."""
    neighbours: dict[int, list[int]] = {f.id: [] for f in obj.faces}
    for adj in obj.face_adjacency:
        neighbours[adj.face_a].append(adj.face_b)
        neighbours[adj.face_b].append(adj.face_a)
    goal_set = set(goals)
    out: list[tuple[int, ...]] = []
    stack: list[tuple[int, ...]] = [(s,) for s in reversed(starts)]
    while stack:
        chain = stack.pop()
        if chain[-1] in goal_set:
            out.append(chain)
            continue
        if len(chain) < max_faces:
            stack.extend(
                chain + (n,) for n in sorted(neighbours[chain[-1]], reverse=True) if n not in chain
            )
    return out


def _chain_overlaps(pieces: Sequence[FaceUnfolding]) -> bool:
    """Whether two faces that are not consecutive in the chain overlap once unfolded."""
    return any(
        _polygons_overlap(pieces[i].polygon_uv, pieces[j].polygon_uv)
        for i in range(len(pieces))
        for j in range(i + 2, len(pieces))
    )


def _face_uv(obj: ConvexObject, fid: int, p: np.ndarray) -> np.ndarray:
    face = obj.faces[fid]
    return _clamp_into(face.to_uv(p[None]), face.polygon_uv).reshape(2)


# ---------------------------------------------------------------------- grid
def build_surface_grid(
    obj: ConvexObject,
    P_object: np.ndarray,
    Q_object: np.ndarray,
    *,
    spacing_m: float = 0.002,
    max_faces: int = 4,
    include_neighbours: bool = True,
) -> SurfaceGrid:
    """Unfold the surface region holding P and Q into a plane and build a grid over it.

    Region: if P and Q share a face, that face (and with ``include_neighbours`` every
    adjacent face that does not overlap the others once unfolded); otherwise, among
    the chains of adjacent faces from P's face to Q's face with at most ``max_faces``
    faces whose unfolded faces do not overlap, the one with the shortest P -> Q route
    inside its unfolded region (the straight unfolded distance when that segment
    stays inside: the geodesic candidate). A point on an edge belongs to each face
    that holds it; the choice of chain decides (ties: fewer faces, then lower ids).

    Grid: the lattice ``P + spacing_m * (i e1 + j e2)`` (``e1`` along the unfolded
    P -> Q direction) inside the region, plus Q; 16-neighbour edges (king and knight
    moves) whose straight segment stays inside; Q joined to the lattice nodes within
    two steps whose segment stays inside.

    Args:
        obj: The convex object.
        P_object: Start point on the surface, object frame [m], shape (3,).
        Q_object: Goal point on the surface, object frame [m], shape (3,).
        spacing_m: Lattice step [m], > 0.
        max_faces: Longest face chain considered, >= 1.
        include_neighbours: When P and Q share a face, also unfold its neighbours.

    Returns:
        The grid (see :class:`SurfaceGrid`).

    Raises:
        InputError: if P or Q is not within 1e-6 m of the surface (the message gives
            the distance), if P and Q are closer than ``spacing_m / 2``, or if
            ``spacing_m`` or ``max_faces`` is not valid.
        GeometryError: if no chain of at most ``max_faces`` faces joins P's face to
            Q's face without overlapping once unfolded (the region cannot be unfolded).
    """
    s = positive(spacing_m, "spacing_m")
    n_max = positive_int(max_faces, "max_faces", minimum=1)
    p = as_array(P_object, "P_object", (3,))
    q = as_array(Q_object, "Q_object", (3,))
    p_faces = _faces_holding(obj, p, "P_object")
    q_faces = _faces_holding(obj, q, "Q_object")
    gap = float(np.linalg.norm(q - p))
    if gap < 0.5 * s:
        raise InputError(
            "Q_object",
            f"is {gap:.3g} m from P_object: P and Q coincide",
            f"a point at least spacing_m / 2 = {0.5 * s:g} m from P",
        )

    # Candidates by their straight unfolded distance, a lower bound of their route.
    candidates = []
    for chain in _chains(obj, p_faces, q_faces, n_max):  # few chains of few faces
        pieces = unfold_faces(obj, chain)
        p_uv = _face_uv(obj, chain[0], p)
        q_uv = pieces[-1].to_unfolded(_face_uv(obj, chain[-1], q)[None])[0]
        bound = float(np.linalg.norm(q_uv - p_uv))
        candidates.append(((bound, len(chain), chain), pieces, p_uv, q_uv))
    candidates.sort(key=lambda c: c[0])
    best: tuple[float, int, tuple[int, ...]] | None = None
    best_pieces: tuple[FaceUnfolding, ...] = ()
    for (bound, n_chain, chain), pieces, p_uv, q_uv in candidates:
        if best is not None and (bound, n_chain, chain) >= best:
            break  # no later chain can beat the best route
        if _chain_overlaps(pieces):
            continue
        key = (_region_geodesic(p_uv, q_uv, pieces), n_chain, chain)
        if np.isfinite(key[0]) and (best is None or key < best):
            best, best_pieces = key, pieces
    if best is None:
        raise GeometryError(
            f"the region cannot be unfolded: no chain of at most {n_max} adjacent faces "
            f"joins P's face {p_faces} to Q's face {q_faces} without overlapping"
        )
    geodesic, _, chain = best
    pieces = best_pieces
    if len(chain) == 1 and include_neighbours:
        pieces = _with_neighbours(obj, pieces)

    p_uv = _face_uv(obj, chain[0], p)
    q_uv = pieces[len(chain) - 1].to_unfolded(_face_uv(obj, chain[-1], q)[None])[0]
    uv, edges = _lattice(p_uv, q_uv, s, pieces)
    lengths = np.linalg.norm(uv[edges[:, 1]] - uv[edges[:, 0]], axis=1)
    m = uv.shape[0]
    piece = np.argmax(_depths(uv, pieces), axis=1)
    piece[0], piece[m - 1] = 0, len(chain) - 1  # P on its face, Q on its face
    points, normals, face_ids = _lift(pieces, uv, piece)
    log.debug("surface grid: faces %s, %d nodes, %d edges", chain, m, edges.shape[0])
    return SurfaceGrid(
        uv=frozen(uv),
        points_object=frozen(points),
        normals_object=frozen(normals),
        face_ids=frozen(face_ids),
        p_index=0,
        q_index=m - 1,
        edges=frozen(edges),
        edge_lengths_m=frozen(lengths),
        face_chain=tuple(chain),
        unfoldings=pieces,
        spacing_m=s,
        P_object=frozen(points[0].copy()),
        Q_object=frozen(points[m - 1].copy()),
        geodesic_m=float(geodesic),
    )


def _with_neighbours(
    obj: ConvexObject, pieces: tuple[FaceUnfolding, ...]
) -> tuple[FaceUnfolding, ...]:
    """Add the faces adjacent to the single root face that do not overlap the others."""
    root = pieces[0].face_id
    others = sorted(
        a.face_b if a.face_a == root else a.face_a
        for a in obj.face_adjacency
        if root in (a.face_a, a.face_b)
    )
    star = unfold_faces(obj, [root, *others], [None] * 1 + [root] * len(others))
    kept = [pieces[0]]
    for cand in star[1:]:  # per neighbour (a handful)
        if not any(_polygons_overlap(cand.polygon_uv, k.polygon_uv) for k in kept[1:]):
            kept.append(cand)
    return tuple(kept)


def _lattice(
    p_uv: np.ndarray, q_uv: np.ndarray, s: float, pieces: Sequence[FaceUnfolding]
) -> tuple[np.ndarray, np.ndarray]:
    """Lattice nodes inside the region (node 0 = P, last = Q) and their edges (E, 2)."""
    e1 = (q_uv - p_uv) / np.linalg.norm(q_uv - p_uv)
    axes = np.stack([e1, [-e1[1], e1[0]]])  # rows e1, e2
    corners = (np.vstack([pc.polygon_uv for pc in pieces]) - p_uv) @ axes.T / s
    lo = np.floor(corners.min(axis=0) - 1e-9).astype(int)
    hi = np.ceil(corners.max(axis=0) + 1e-9).astype(int)
    ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    ij = np.stack([ii.ravel(), jj.ravel()], axis=1)
    uv = p_uv + s * (ij @ axes)
    depth = _depths(uv, pieces)  # (N, F)
    member = depth >= -_TOL_M
    keep = np.any(member, axis=1)
    keep &= np.linalg.norm(uv - q_uv, axis=1) > 1e-6 * s  # Q is added as its own node
    p_cell = (0 - lo[0]) * ii.shape[1] + (0 - lo[1])
    keep[p_cell] = True  # P (inside its face, up to rounding)
    # Number the nodes: P first, then the lattice, then Q.
    order = np.flatnonzero(keep)
    order = np.concatenate([[p_cell], order[order != p_cell]])
    index = np.full(ij.shape[0], -1)
    index[order] = np.arange(order.size)
    index = index.reshape(ii.shape)
    uv_nodes = uv[order]
    member = member[order]
    member[0, 0] = True  # P lies in the root face (clamped into it)
    padded = np.pad(index, 2, constant_values=-1)
    ni, nj = (int(n) for n in np.shape(index))
    pairs = []
    for di, dj in _STENCIL:  # 8 offsets, each vectorized over the lattice
        b = padded[2 + di : 2 + di + ni, 2 + dj : 2 + dj + nj]
        ok = (index >= 0) & (b >= 0)
        pairs.append(np.stack([index[ok], b[ok]], axis=1))
    edges = np.concatenate(pairs)
    # Q: joined to lattice nodes within two steps.
    q_id = uv_nodes.shape[0]
    near = np.flatnonzero(np.linalg.norm(uv_nodes - q_uv, axis=1) <= 2 * s * (1 + 1e-9))
    edges = np.concatenate([edges, np.stack([near, np.full(near.size, q_id)], axis=1)])
    uv_nodes = np.vstack([uv_nodes, q_uv])
    q_member = _depths(q_uv[None], pieces) >= -_TOL_M
    member = np.vstack([member, q_member])
    # An edge is valid if one piece holds both ends (pieces are convex) or, failing
    # that, if its segment is covered by the union of the pieces.
    same = np.any(member[edges[:, 0]] & member[edges[:, 1]], axis=1)
    cross = np.flatnonzero(~same)
    ok = same.copy()
    if cross.size:
        ok[cross] = _segments_inside(uv_nodes[edges[cross, 0]], uv_nodes[edges[cross, 1]], pieces)
    return uv_nodes, edges[ok].astype(np.int64)
