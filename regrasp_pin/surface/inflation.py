"""The "virtual inflation" of the object surface along the path (section 2.1, Fig. 3).

The paper inflates the mesh of the region holding P and Q so that the finger travels
over the inflated surface and never touches the object, while "the sections
containing the initial and final position [are] not affected" (Fig. 3). Here the
inflation is a height field over the surface:

    h(d_P, d_Q) = clearance_m * smoothstep(min(d_P, d_Q) / taper_m),
    smoothstep(x) = 3 x^2 - 2 x^3 for x in [0, 1] (0 below, 1 above),

zero at P and at Q, so the finger lifts off and lands on the surface, and the full
clearance once it is ``taper_m`` away from both. The fingertip (a sphere of radius
``tip_radius_m``) travels with its centre at ``surface point + (tip_radius_m + h) n``;
where the path crosses an edge of the object, the offset direction turns from one
face normal to the next about the edge (an arc), so the centre stays exactly
``tip_radius_m + h`` from the convex object everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import frozen, positive
from ..exceptions import InputError
from ..model.objects import ConvexObject
from .grid import SurfaceGrid
from .path import GridPath

__all__ = ["TipPath", "grid_inflation", "inflate_path", "inflation_height"]

_MAX_SLOPE = 1.5  # max of d smoothstep / dx


def inflation_height(
    dist_from_P_m: np.ndarray | float,
    dist_from_Q_m: np.ndarray | float,
    *,
    clearance_m: float,
    taper_m: float,
) -> np.ndarray:
    """Inflation height ``clearance_m * smoothstep(min(d_P, d_Q) / taper_m)``.

    Args:
        dist_from_P_m: Distance from P along the surface [m], any shape.
        dist_from_Q_m: Distance from Q along the surface [m], broadcastable to it.
        clearance_m: Full inflation height [m], > 0.
        taper_m: Distance from P and Q over which the height rises from 0 [m], > 0.

    Returns:
        Heights [m], the broadcast shape: 0 at P and Q, ``clearance_m`` beyond
        ``taper_m`` from both.

    Raises:
        InputError: if ``clearance_m`` or ``taper_m`` is not > 0.
    """
    c = positive(clearance_m, "clearance_m")
    t = positive(taper_m, "taper_m")
    d = np.minimum(np.asarray(dist_from_P_m, dtype=float), np.asarray(dist_from_Q_m, float))
    x = np.clip(d / t, 0.0, 1.0)
    return c * np.clip(x * x * (3.0 - 2.0 * x), 0.0, 1.0)  # clip rounding near x = 1


def grid_inflation(grid: SurfaceGrid, clearance_m: float, taper_m: float) -> np.ndarray:
    """Inflation height of every grid node, from its unfolded distances to P and Q.

    Args:
        grid: The surface grid.
        clearance_m: Full inflation height [m], > 0.
        taper_m: Taper distance [m], > 0.

    Returns:
        Heights [m], shape (M,).

    Raises:
        InputError: if ``clearance_m`` or ``taper_m`` is not > 0.
    """
    d_p = np.linalg.norm(grid.uv - grid.uv[grid.p_index], axis=1)
    d_q = np.linalg.norm(grid.uv - grid.uv[grid.q_index], axis=1)
    return inflation_height(d_p, d_q, clearance_m=clearance_m, taper_m=taper_m)


@dataclass(frozen=True, eq=False)
class TipPath:
    """The fingertip-centre curve over the inflated surface, in the object frame.

    Attributes:
        points_object: Tip centres [m], shape (K, 3); first ``P + r n_P``, last
            ``Q + r n_Q``.
        surface_points_object: Surface point under each tip centre [m], shape (K, 3).
        normals_object: Unit offset direction of each tip centre from its surface
            point, shape (K, 3): the face normal, turning about the edge on an arc.
        height_m: Inflation height ``h`` [m], shape (K,) (the tip centre is
            ``tip_radius_m + h`` from the object).
        arc_length_m: Length along the surface path from P [m], shape (K,)
            (constant along an arc about an edge).
        face_ids: Face of each surface point, shape (K,) int; -1 inside an arc about
            an edge (the offset direction lies between two face normals there).
        uv: Surface points in the unfolded plane of the grid [m], shape (K, 2).
        tip_radius_m: Fingertip radius [m].
        clearance_m: Full inflation height [m].
        taper_m: Taper distance [m].
        length_m: Length of the surface path [m].
    """

    points_object: np.ndarray
    surface_points_object: np.ndarray
    normals_object: np.ndarray
    height_m: np.ndarray
    arc_length_m: np.ndarray
    face_ids: np.ndarray
    uv: np.ndarray
    tip_radius_m: float
    clearance_m: float
    taper_m: float
    length_m: float

    def __len__(self) -> int:
        return int(self.points_object.shape[0])

    @property
    def offset_m(self) -> np.ndarray:
        """Distance of each tip centre from the object, ``tip_radius_m + height_m`` [m], (K,)."""
        return self.tip_radius_m + self.height_m


def inflate_path(
    obj: ConvexObject,
    path: GridPath,
    *,
    tip_radius_m: float,
    clearance_m: float,
    taper_m: float | None = None,
    step_m: float = 0.001,
) -> TipPath:
    """The fingertip-centre curve over the virtually inflated surface (Fig. 3).

    The grid path is split where it crosses an edge between faces and resampled by
    arc length ``s`` so that consecutive tip centres are at most ``step_m`` apart (the
    surface step is ``step_m / sqrt(1 + (1.5 clearance_m / taper_m)^2)``, which bounds
    the height change too). Each tip centre is ``x + (tip_radius_m + h(s)) n`` with
    ``h = inflation_height(s, length - s)``; at an edge crossing ``x_e`` the direction
    ``n`` turns from the normal of the face left to the normal of the face entered
    about the edge, at radius ``tip_radius_m + h(s_e)``, in steps of at most ``step_m``.
    On a convex object every such point is exactly ``tip_radius_m + h`` from the
    object (its offset direction lies in the normal cone at ``x``).

    Args:
        obj: The object the path's grid was built on.
        path: The grid path.
        tip_radius_m: Fingertip sphere radius [m], > 0.
        clearance_m: Full inflation height [m], > 0 (the margin between the fingertip
            and the object away from P and Q).
        taper_m: Distance from P and Q over which the inflation rises [m], > 0;
            default ``clearance_m``.
        step_m: Largest step between consecutive tip centres [m], > 0.

    Returns:
        The tip path (see :class:`TipPath`).

    Raises:
        InputError: if a length is not > 0 (naming the argument), or ``path`` does not
            lie on ``obj``.
    """
    r = positive(tip_radius_m, "tip_radius_m")
    c = positive(clearance_m, "clearance_m")
    taper = c if taper_m is None else positive(taper_m, "taper_m")
    step = positive(step_m, "step_m")
    off = float(np.max(np.abs(obj.signed_distance(path.points_object))))
    if off > 1e-6:
        raise InputError("path", f"does not lie on obj (a node is {off:.3g} m from it)")
    grid = path.grid
    total = path.length_m
    start, end, s0, piece = _split_at_hinges(grid, path.uv, path.arc_length_m)
    # Zero-length pieces at P and Q carry the faces P and Q were assigned to.
    first = _piece_index(grid, int(grid.face_ids[grid.p_index]))
    last = _piece_index(grid, int(grid.face_ids[grid.q_index]))
    start = np.vstack([path.uv[:1], start, path.uv[-1:]])
    end = np.vstack([path.uv[:1], end, path.uv[-1:]])
    s0 = np.concatenate([[0.0], s0, [total]])
    piece = np.concatenate([[first], piece, [last]])
    length = np.linalg.norm(end - start, axis=1)

    ds = step / np.sqrt(1.0 + (_MAX_SLOPE * c / taper) ** 2)
    n = np.where(length > 0, np.ceil(length / ds), 0).astype(np.int64)
    offsets = np.concatenate([[0], np.cumsum(n)])
    idx = np.repeat(np.arange(n.size), n)
    t = (np.arange(offsets[-1]) - offsets[idx]) / np.maximum(n[idx], 1)
    uv = np.vstack([start[idx] + t[:, None] * (end - start)[idx], end[-1:]])
    s = np.concatenate([s0[idx] + t * length[idx], [total]])
    pc = np.concatenate([piece[idx], piece[-1:]])
    x, nrm, fid = grid.to_object(uv, np.array([u.face_id for u in grid.unfoldings])[pc])

    # Arcs about edges where consecutive pieces lie on different faces.
    blocks = []
    for j in np.flatnonzero(piece[:-1] != piece[1:]):  # per edge crossing (a few)
        x_e, n_a, _ = grid.to_object(start[j + 1][None], np.array([_face(grid, piece[j])]))
        n_b = grid.unfoldings[piece[j + 1]].normal_object
        h_e = inflation_height(s0[j + 1], total - s0[j + 1], clearance_m=c, taper_m=taper)
        dirs = _arc_directions(n_a[0], n_b, (r + float(h_e)) / step)
        k = dirs.shape[0]
        face = np.full(k, -1)
        face[0] = _face(grid, piece[j])
        blocks.append(
            (
                offsets[j + 1],
                np.repeat(x_e, k, axis=0),
                dirs,
                np.full(k, s0[j + 1]),
                face,
                np.repeat(start[j + 1][None], k, axis=0),
            )
        )
    x, nrm, s, fid, uv = _insert(blocks, x, nrm, s, fid, uv)

    h = inflation_height(s, total - s, clearance_m=c, taper_m=taper)
    tips = x + (r + h)[:, None] * nrm
    return TipPath(
        points_object=frozen(tips),
        surface_points_object=frozen(x),
        normals_object=frozen(nrm),
        height_m=frozen(h),
        arc_length_m=frozen(s),
        face_ids=frozen(fid),
        uv=frozen(uv),
        tip_radius_m=r,
        clearance_m=c,
        taper_m=taper,
        length_m=total,
    )


def _piece_index(grid: SurfaceGrid, face_id: int) -> int:
    return next(i for i, u in enumerate(grid.unfoldings) if u.face_id == face_id)


def _face(grid: SurfaceGrid, piece: int) -> int:
    return grid.unfoldings[int(piece)].face_id


def _split_at_hinges(
    grid: SurfaceGrid, uv: np.ndarray, arc: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Split the path's segments where they cross a hinge (an edge between faces).

    Returns:
        ``(start (J, 2), end (J, 2), s0 (J,), piece (J,))``: non-empty sub-segments in
        order, the arc length at each start [m] and the unfolded face each lies in.
    """
    a, d = uv[:-1], np.diff(uv, axis=0)  # (S, 2)
    hinges = grid.hinges_uv
    seg = [np.arange(a.shape[0])]
    ts = [np.zeros(a.shape[0])]
    if hinges:
        h0 = np.stack([h[0] for h in hinges])  # (H, 2)
        g = np.stack([h[1] - h[0] for h in hinges])
        denom = d[:, None, 0] * g[None, :, 1] - d[:, None, 1] * g[None, :, 0]  # (S, H)
        w = h0[None] - a[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[..., 0] * g[None, :, 1] - w[..., 1] * g[None, :, 0]) / denom
            u = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / denom
        scale = np.linalg.norm(d, axis=1)[:, None] * np.linalg.norm(g, axis=1)[None]
        hit = (
            (np.abs(denom) > 1e-12 * scale)
            & (t > 1e-12)
            & (t < 1 - 1e-12)
            & (u >= -1e-9)
            & (u <= 1 + 1e-9)
        )
        si, _ = np.nonzero(hit)
        seg.append(si)
        ts.append(t[hit])
    seg_all, t_all = np.concatenate(seg), np.concatenate(ts)
    order = np.lexsort((t_all, seg_all))
    seg_all, t_all = seg_all[order], t_all[order]
    t_end = np.append(t_all[1:], 1.0)
    t_end = np.where(np.append(seg_all[1:] == seg_all[:-1], False), t_end, 1.0)
    start = a[seg_all] + t_all[:, None] * d[seg_all]
    end = a[seg_all] + t_end[:, None] * d[seg_all]
    keep = np.linalg.norm(end - start, axis=1) > 1e-12
    start, end, seg_all, t_all = start[keep], end[keep], seg_all[keep], t_all[keep]
    s0 = arc[seg_all] + t_all * np.linalg.norm(d[seg_all], axis=1)
    piece = grid.piece_of(0.5 * (start + end))
    return start, end, s0, piece


def _arc_directions(n_a: np.ndarray, n_b: np.ndarray, radius_over_step: float) -> np.ndarray:
    """Directions from ``n_a`` towards ``n_b`` on their great circle, ``n_b`` excluded.

    The number of pieces keeps the chord at ``radius`` below ``step``.
    """
    cos = float(np.clip(n_a @ n_b, -1.0, 1.0))
    w = n_b - cos * n_a
    sin = float(np.linalg.norm(w))
    if sin < 1e-12:
        return n_a[None].copy()
    theta = float(np.arctan2(sin, cos))
    k = max(1, int(np.ceil(theta * radius_over_step)))
    phi = theta * np.arange(k) / k
    return np.cos(phi)[:, None] * n_a + np.sin(phi)[:, None] * (w / sin)


def _insert(
    blocks: list,
    x: np.ndarray,
    nrm: np.ndarray,
    s: np.ndarray,
    fid: np.ndarray,
    uv: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """Insert the arc blocks ``(position, x, n, s, face, uv)`` before the given samples."""
    if not blocks:
        return x, nrm, s, fid, uv
    cols: list[list[np.ndarray]] = [[], [], [], [], []]
    prev = 0
    for pos, *block in blocks:  # per edge crossing
        for col, full, part in zip(cols, (x, nrm, s, fid, uv), block, strict=True):
            col.extend([full[prev:pos], part])
        prev = pos
    for col, full in zip(cols, (x, nrm, s, fid, uv), strict=True):
        col.append(full[prev:])
    return tuple(np.concatenate(col) for col in cols)
