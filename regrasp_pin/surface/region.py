"""Which faces hold the path from P to Q: the region that is unfolded and gridded.

If P and Q lie on one face, the region is that face, plus (by default) each
neighbouring face rotated about their shared edge into the same plane; otherwise it is
the chain of adjacent faces from P's face to Q's face whose unfolded region holds the
shortest P -> Q route (:func:`choose_region`).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ..exceptions import InputError, UnfoldError
from ..model.objects import ConvexObject
from .unfolding import FaceUnfolding, polygons_overlap, segments_inside, unfold_faces

__all__ = ["ON_SURFACE_TOL_M", "Region", "choose_region"]

ON_SURFACE_TOL_M = 1e-6  # P and Q must lie this close to the surface [m]

#: Per object, its unfolded chains and single faces with their neighbours: they depend on
#: the object and the faces alone, and every regrasp on the object asks for a few of them.
_UNFOLDED: weakref.WeakKeyDictionary[ConvexObject, dict[Any, tuple[FaceUnfolding, ...]]] = (
    weakref.WeakKeyDictionary()
)


@dataclass(frozen=True)
class Region:
    """The unfolded region that holds P and Q.

    Attributes:
        chain: Face ids from P's face to Q's face.
        pieces: The unfolded faces (the chain first, then any added neighbours).
        p_uv: P in the unfolded plane [m].
        q_uv: Q in the unfolded plane [m].
        geodesic_m: Length of the shortest P -> Q route inside the region [m].
    """

    chain: tuple[int, ...]
    pieces: tuple[FaceUnfolding, ...]
    p_uv: np.ndarray
    q_uv: np.ndarray
    geodesic_m: float


def choose_region(
    obj: ConvexObject,
    p: np.ndarray,
    q: np.ndarray,
    max_faces: int,
    include_neighbours: bool,
) -> Region:
    """The region for P and Q (object frame, on the surface; see
    :func:`~regrasp_pin.surface.grid.build_surface_grid` for the rule and the errors)."""
    p_faces = _faces_holding(obj, p, "P_object")
    q_faces = _faces_holding(obj, q, "Q_object")
    # Candidates by their straight unfolded distance, a lower bound of their route.
    candidates = []
    for chain in _chains(obj, p_faces, q_faces, max_faces):  # few chains of few faces
        pieces = _unfolded(obj, chain)
        p_uv = _face_uv(obj, chain[0], p)
        q_uv = pieces[-1].to_unfolded(_face_uv(obj, chain[-1], q)[None])[0]
        bound = float(np.linalg.norm(q_uv - p_uv))
        candidates.append(((bound, len(chain), chain), pieces, p_uv, q_uv))
    candidates.sort(key=lambda c: c[0])
    best: tuple[float, int, tuple[int, ...]] | None = None
    best_uv: tuple[tuple[FaceUnfolding, ...], np.ndarray, np.ndarray] | None = None
    for (bound, n_chain, chain), pieces, p_uv, q_uv in candidates:
        if best is not None and (bound, n_chain, chain) >= best:
            break  # no later chain can beat the best route
        if _chain_overlaps(pieces):
            continue
        key = (_region_geodesic(p_uv, q_uv, pieces), n_chain, chain)
        if np.isfinite(key[0]) and (best is None or key < best):
            best, best_uv = key, (pieces, p_uv, q_uv)
    if best is None or best_uv is None:
        raise UnfoldError(
            f"the region cannot be unfolded: no chain of at most {max_faces} adjacent faces "
            f"joins P's face {p_faces} to Q's face {q_faces} without overlapping"
        )
    geodesic, _, chain = best
    pieces, p_uv, q_uv = best_uv
    if len(chain) == 1 and include_neighbours:
        pieces = _with_neighbours(obj, pieces)  # the root piece stays first: same P, Q
    return Region(tuple(chain), pieces, p_uv, q_uv, float(geodesic))


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
    if segments_inside(p_uv[None], q_uv[None], pieces)[0]:
        return float(np.linalg.norm(q_uv - p_uv))
    hinge_ends = [h for p in pieces if p.hinge_uv is not None for h in p.hinge_uv]
    pts = np.vstack([p_uv, q_uv, *hinge_ends]) if hinge_ends else np.vstack([p_uv, q_uv])
    i, j = np.triu_indices(pts.shape[0], k=1)
    ok = segments_inside(pts[i], pts[j], pieces)
    length = np.linalg.norm(pts[j] - pts[i], axis=1)
    ok &= length > 0
    graph = csr_matrix((length[ok], (i[ok], j[ok])), shape=(pts.shape[0],) * 2)
    return float(dijkstra(graph, directed=False, indices=0)[1])


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
        polygons_overlap(pieces[i].polygon_uv, pieces[j].polygon_uv)
        for i in range(len(pieces))
        for j in range(i + 2, len(pieces))
    )


def _face_uv(obj: ConvexObject, fid: int, p: np.ndarray) -> np.ndarray:
    face = obj.faces[fid]
    return _clamp_into(face.to_uv(p[None]), face.polygon_uv).reshape(2)


def _remembered(
    obj: ConvexObject, key: Any, compute: Callable[[], tuple[FaceUnfolding, ...]]
) -> tuple[FaceUnfolding, ...]:
    """``compute()``, remembered per object under ``key``."""
    known = _UNFOLDED.setdefault(obj, {})
    if key not in known:
        known[key] = compute()
    return known[key]


def _unfolded(obj: ConvexObject, chain: tuple[int, ...]) -> tuple[FaceUnfolding, ...]:
    """:func:`~.unfolding.unfold_faces` of a chain, remembered per object."""
    return _remembered(obj, chain, lambda: unfold_faces(obj, chain))


def _with_neighbours(
    obj: ConvexObject, pieces: tuple[FaceUnfolding, ...]
) -> tuple[FaceUnfolding, ...]:
    """Add the faces adjacent to the single root face that do not overlap the others
    (remembered per object and root face: the root's unfolding is the identity)."""
    key = ("with neighbours", pieces[0].face_id)
    return _remembered(obj, key, lambda: _add_neighbours(obj, pieces))


def _add_neighbours(
    obj: ConvexObject, pieces: tuple[FaceUnfolding, ...]
) -> tuple[FaceUnfolding, ...]:
    """:func:`_with_neighbours` computed."""
    root = pieces[0].face_id
    others = sorted(
        a.face_b if a.face_a == root else a.face_a
        for a in obj.face_adjacency
        if root in (a.face_a, a.face_b)
    )
    star = unfold_faces(obj, [root, *others], [None] * 1 + [root] * len(others))
    kept = [pieces[0]]
    for cand in star[1:]:  # per neighbour (a handful)
        if not any(polygons_overlap(cand.polygon_uv, k.polygon_uv) for k in kept[1:]):
            kept.append(cand)
    return tuple(kept)
