"""Faces of a convex object unfolded into one plane (a polyhedron net).

A face is laid into the plane of its parent by the rigid map that puts their shared
edge onto the parent's unfolded edge; unfolding is an isometry per face, so a straight
segment in the unfolded plane that stays inside the unfolded faces is a surface path of
the same length. :func:`unfold_faces` unfolds a tree of faces; :func:`depths`,
:func:`segments_inside` and :func:`polygons_overlap` answer containment questions in
the plane; :func:`lift` maps unfolded points back onto the surface (object frame).
"""

from __future__ import annotations

import collections
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .._validate import frozen
from ..exceptions import GeometryError, InputError
from ..model.objects import ConvexObject, FaceAdjacency

__all__ = [
    "UNFOLD_TOL_M",
    "FaceUnfolding",
    "depths",
    "lift",
    "polygons_overlap",
    "segments_inside",
    "unfold_faces",
]

UNFOLD_TOL_M = 1e-9  # geometric slack for containment and touching tests [m]


def _rot2(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s], [s, c]])


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

    @cached_property
    def edge_halfplanes(self) -> tuple[np.ndarray, np.ndarray]:
        """Inward unit edge normals ``m`` (k, 2) and offsets ``c`` (k,) [m] of
        ``polygon_uv``: a point ``x`` is inside where ``m @ x - c >= 0`` for every edge."""
        a = self.polygon_uv
        e = np.roll(a, -1, axis=0) - a
        m = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.linalg.norm(e, axis=1)[:, None]
        return m, np.sum(a * m, axis=1)

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


def lift(
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


#: The last regions' padded half-planes, keyed by their pieces' identities (each entry
#: holds its pieces, so an identity cannot be reused while the entry lives).
_HALFPLANES: collections.OrderedDict[
    tuple[int, ...], tuple[tuple[FaceUnfolding, ...], np.ndarray, np.ndarray]
] = collections.OrderedDict()
_HALFPLANES_KEEP = 8
_HALFPLANES_LOCK = threading.Lock()


def _halfplanes(pieces: Sequence[FaceUnfolding]) -> tuple[np.ndarray, np.ndarray]:
    """Inward unit edge normals (F, k, 2) and biases (F, k), padded by repeating edge 0
    (read-only; remembered for the last few regions: a grid's construction and its
    queries ask for the same pieces many times)."""
    key = tuple(id(p) for p in pieces)
    with _HALFPLANES_LOCK:
        hit = _HALFPLANES.get(key)
        if hit is None:
            normals, bias = _pad_halfplanes(pieces)
            normals.flags.writeable = bias.flags.writeable = False
            hit = _HALFPLANES[key] = (tuple(pieces), normals, bias)
            while len(_HALFPLANES) > _HALFPLANES_KEEP:
                _HALFPLANES.popitem(last=False)
        else:
            _HALFPLANES.move_to_end(key)
    return hit[1], hit[2]


def _pad_halfplanes(pieces: Sequence[FaceUnfolding]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_halfplanes` computed."""
    k = max(p.polygon_uv.shape[0] for p in pieces)
    normals = np.empty((len(pieces), k, 2))
    bias = np.empty((len(pieces), k))
    for i, p in enumerate(pieces):  # per face (a handful)
        m, c = p.edge_halfplanes
        pad = k - m.shape[0]
        normals[i] = np.concatenate([m, np.repeat(m[:1], pad, axis=0)])
        bias[i] = np.concatenate([c, np.repeat(c[:1], pad)])
    return normals, bias


def depths(uv: np.ndarray, pieces: Sequence[FaceUnfolding]) -> np.ndarray:
    """Signed depth [m] of points inside each piece (min over its edges), shape (N, F)."""
    normals, bias = _halfplanes(pieces)
    return np.min(np.einsum("nd,fkd->nfk", uv, normals) - bias, axis=2)


def segments_inside(
    a: np.ndarray, b: np.ndarray, pieces: Sequence[FaceUnfolding], tol_m: float = UNFOLD_TOL_M
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


def polygons_overlap(a: np.ndarray, b: np.ndarray, tol_m: float = UNFOLD_TOL_M) -> bool:
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
