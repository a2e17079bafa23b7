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
solve with :func:`regrasp_pin.surface.path.shortest_grid_path`. The region is chosen in
:mod:`.region` and unfolded in :mod:`.unfolding`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, frozen, positive, positive_int
from ..exceptions import InputError
from ..model.objects import ConvexObject
from .region import ON_SURFACE_TOL_M, choose_region
from .unfolding import UNFOLD_TOL_M, FaceUnfolding, depths, lift, segments_inside, unfold_faces

__all__ = ["FaceUnfolding", "SurfaceGrid", "build_surface_grid", "unfold_faces"]

log = logging.getLogger(__name__)

# Half of the 16-neighbour stencil in lattice steps (the other half is the reverse).
_STENCIL = np.array([(1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2)])


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
        return np.argmax(depths(uv, self.unfoldings), axis=1)

    def contains(self, uv_unfolded: np.ndarray, tol_m: float = UNFOLD_TOL_M) -> np.ndarray:
        """Whether unfolded points lie in the region (within ``tol_m``).

        Args:
            uv_unfolded: Unfolded coordinates [m], shape (K, 2).
            tol_m: Slack [m].

        Returns:
            Boolean mask, shape (K,).
        """
        uv = as_array(uv_unfolded, "uv_unfolded", (None, 2))
        return np.max(depths(uv, self.unfoldings), axis=1) >= -tol_m

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
        return segments_inside(a, b, self.unfoldings)

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
        depth = depths(uv, self.unfoldings)
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
        return lift(self.unfoldings, uv, piece)


def build_surface_grid(
    obj: ConvexObject,
    P_object: np.ndarray,
    Q_object: np.ndarray,
    *,
    spacing_m: float = 0.002,
    max_faces: int = 4,
    include_neighbours: bool = True,
    max_detour: tuple[float, float] | None = None,
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
    two steps whose segment stays inside. With ``max_detour = (ratio, slack_m)``, only the
    lattice nodes ``x`` with ``|x - P| + |x - Q| <= ratio |PQ| + slack_m`` (unfolded
    plane) are kept: the ellipse with foci P and Q that holds every path up to that long.

    Args:
        obj: The convex object.
        P_object: Start point on the surface, object frame [m], shape (3,).
        Q_object: Goal point on the surface, object frame [m], shape (3,).
        spacing_m: Lattice step [m], > 0.
        max_faces: Longest face chain considered, >= 1.
        include_neighbours: When P and Q share a face, also unfold its neighbours.
        max_detour: ``(ratio >= 1, slack_m >= 0)`` bounding the paths kept (above), or
            None for the whole region.

    Returns:
        The grid (see :class:`SurfaceGrid`).

    Raises:
        InputError: if P or Q is not within 1e-6 m of the surface (the message gives
            the distance), if P and Q are closer than ``spacing_m / 2``, or if
            ``spacing_m`` or ``max_faces`` is not valid.
        UnfoldError: if no chain of at most ``max_faces`` faces joins P's face to
            Q's face without overlapping once unfolded (the region cannot be unfolded;
            a :class:`~regrasp_pin.exceptions.GeometryError`).
    """
    s = positive(spacing_m, "spacing_m")
    n_max = positive_int(max_faces, "max_faces", minimum=1)
    p = as_array(P_object, "P_object", (3,))
    q = as_array(Q_object, "Q_object", (3,))
    detour = _check_detour(max_detour)
    gap = float(np.linalg.norm(q - p))
    if gap < 0.5 * s:
        raise InputError(
            "Q_object",
            f"is {gap:.3g} m from P_object: P and Q coincide",
            f"a point at least spacing_m / 2 = {0.5 * s:g} m from P",
        )

    region = choose_region(obj, p, q, n_max, include_neighbours)
    chain, pieces, p_uv, q_uv = region.chain, region.pieces, region.p_uv, region.q_uv
    uv, edges, depth = _lattice(p_uv, q_uv, s, pieces, detour)
    lengths = np.linalg.norm(uv[edges[:, 1]] - uv[edges[:, 0]], axis=1)
    m = uv.shape[0]
    piece = np.argmax(depth, axis=1)
    piece[0], piece[m - 1] = 0, len(chain) - 1  # P on its face, Q on its face
    points, normals, face_ids = lift(pieces, uv, piece)
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
        geodesic_m=region.geodesic_m,
    )


def _check_detour(max_detour: object) -> tuple[float, float] | None:
    if max_detour is None:
        return None
    try:
        ratio, slack = (float(v) for v in max_detour)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise InputError(
            "max_detour", f"is {max_detour!r}", "None or (ratio >= 1, slack_m >= 0)"
        ) from None
    if not (ratio >= 1.0 and slack >= 0.0 and math.isfinite(ratio) and math.isfinite(slack)):
        raise InputError(
            "max_detour", f"is ({ratio:g}, {slack:g})", "None or (ratio >= 1, slack_m >= 0)"
        )
    return ratio, slack


def _lattice(
    p_uv: np.ndarray,
    q_uv: np.ndarray,
    s: float,
    pieces: Sequence[FaceUnfolding],
    detour: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lattice nodes inside the region (node 0 = P, last = Q), their edges (E, 2) and
    their depths in the pieces (N, F) (see :func:`depths`)."""
    e1 = (q_uv - p_uv) / np.linalg.norm(q_uv - p_uv)
    axes = np.stack([e1, [-e1[1], e1[0]]])  # rows e1, e2
    corners = (np.vstack([pc.polygon_uv for pc in pieces]) - p_uv) @ axes.T / s
    lo = np.floor(corners.min(axis=0) - 1e-9).astype(int)
    hi = np.ceil(corners.max(axis=0) + 1e-9).astype(int)
    ii, jj = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij")
    ij = np.stack([ii.ravel(), jj.ravel()], axis=1)
    uv = p_uv + s * (ij @ axes)
    p_cell = (0 - lo[0]) * ii.shape[1] + (0 - lo[1])
    to_q = np.linalg.norm(uv - q_uv, axis=1)
    near = np.ones(uv.shape[0], dtype=bool)
    if detour is not None:
        reach = detour[0] * float(np.linalg.norm(q_uv - p_uv)) + detour[1]
        near = np.linalg.norm(uv - p_uv, axis=1) + to_q <= reach
    near[p_cell] = True
    cand = np.flatnonzero(near)
    depth = depths(uv[cand], pieces)  # (C, F), each row its point's own
    member = depth >= -UNFOLD_TOL_M
    keep = np.any(member, axis=1)
    keep &= to_q[cand] > 1e-6 * s  # Q is added as its own node
    keep[cand == p_cell] = True  # P (inside its face, up to rounding)
    # Number the nodes: P first, then the lattice, then Q.
    p_row = int(np.flatnonzero(cand == p_cell)[0])
    rows = np.flatnonzero(keep)
    rows = np.concatenate([[p_row], rows[rows != p_row]])
    order = cand[rows]
    index = np.full(ij.shape[0], -1)
    index[order] = np.arange(order.size)
    index = index.reshape(ii.shape)
    uv_nodes = uv[order]
    member = member[rows]
    depth = depth[rows]
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
    q_depth = depths(q_uv[None], pieces)
    member = np.vstack([member, q_depth >= -UNFOLD_TOL_M])
    depth = np.vstack([depth, q_depth])
    # An edge is valid if one piece holds both ends (pieces are convex) or, failing
    # that, if its segment is covered by the union of the pieces.
    same = np.any(member[edges[:, 0]] & member[edges[:, 1]], axis=1)
    cross = np.flatnonzero(~same)
    ok = same.copy()
    if cross.size:
        ok[cross] = segments_inside(uv_nodes[edges[cross, 0]], uv_nodes[edges[cross, 1]], pieces)
    return uv_nodes, edges[ok].astype(np.int64), depth
