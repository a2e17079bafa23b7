"""Distances of every (sample, geometry pair) check of one finger motion.

Internal to :mod:`regrasp_pin.verify.finger_motion`, which documents what is checked. This module
holds the machinery: batched geometry placements, the numpy broad phase (lower bounds
on the signed distance for all samples at once), the exact Coal queries where the
bounds do not settle a check, and the branch and bound that makes the reported
minima exact.
"""

from __future__ import annotations

import itertools
import logging
import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, cast

import coal
import numpy as np

from ..exceptions import InputError
from . import bounds_numba, capsules_numba, placements_numba
from .hand import Finger, Hand
from .ik import ik_backend
from .kinematics import FingerChain, attached_placements, attached_points_soa
from .objects import ConvexObject
from .support import support, support_parameters

#: Pairs of geometries whose bounding spheres are within this of the requirement get
#: the tighter capsule and separating-axis bounds [m].
BROAD_PHASE_MARGIN_M = 0.005
#: Extra Coal queries allowed per reported minimum (beyond the mandatory ones).
MAX_MINIMUM_QUERIES = 256
#: The mandatory queries measure every this-many-th sample of a column first; the sweep
#: bound from those values spares the samples it lifts above their requirement.
QUERY_STRIDE = 8
#: A sample is spared only when the sweep bound lifts it this far above its requirement:
#: Coal's own tolerances (GJK 1e-9 m, EPA 1e-6 m) on the values the bound comes from [m].
_LIFT_MARGIN_M = 2e-6

_MAX_DEPTH_M = 1.0  # a Coal distance below -this is an EPA failure, not a depth
TIP, LINK, FF = 0, 1, 2  # kinds of check (columns)

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class _Geometry:
    """One collision geometry: how to place it in batch, and two convex bounds of it.

    The capsule ``(seg_a, seg_b, radius)`` contains the shape. The support function
    of the shape about ``centre`` in a unit direction ``u`` (geometry frame) is
    ``sum_i half_i |u_i| + axial |u_z| + radial sqrt(1 - u_z^2) + round``: a box
    (``half``), a cylinder (``axial`` = half length, ``radial`` = radius), a capsule
    (``axial``, ``round``), a sphere (``round``); any other shape gets the sphere of
    its local AABB.
    """

    gid: int
    name: str
    shape: Any  # coal.CollisionGeometry
    chain: FingerChain
    R_frame_geom: np.ndarray  # (3, 3)
    p_frame_geom: np.ndarray  # (3,)
    seg_a: np.ndarray  # (3,) capsule segment start, geometry frame [m]
    seg_b: np.ndarray  # (3,) capsule segment end
    radius: float  # capsule radius [m]
    centre: np.ndarray  # (3,) centre of symmetry, geometry frame [m]
    support: np.ndarray  # (6,) half_x, half_y, half_z, axial, radial, round [m]


_TABLES: weakref.WeakKeyDictionary[Hand, dict[Any, Any]] = weakref.WeakKeyDictionary()


def _geometry(hand: Hand, gid: int) -> _Geometry:
    """The (cached) batch description of collision geometry ``gid`` of the hand."""
    table = _TABLES.setdefault(hand, {})
    if gid not in table:
        model = hand.model
        gobj = hand.collision_model.geometryObjects[gid]
        frame_name = model.frames[int(gobj.parentFrame)].name
        fid = model.getFrameId(frame_name)
        if int(model.frames[fid].parentJoint) != int(gobj.parentJoint):  # ambiguous name
            frame_name = model.names[int(gobj.parentJoint)]
            fid = model.getFrameId(frame_name)
        chain = table.get(("chain", frame_name))
        if chain is None:
            chain = table[("chain", frame_name)] = FingerChain(model, frame_name)
        M = model.frames[fid].placement.inverse() * gobj.placement  # frame -> geometry
        a, b, r = _capsule(gobj.geometry)
        centre, params = support_parameters(gobj.geometry)
        table[gid] = _Geometry(
            gid=gid,
            name=gobj.name,
            shape=gobj.geometry,
            chain=chain,
            R_frame_geom=M.rotation.copy(),
            p_frame_geom=M.translation.copy(),
            seg_a=a,
            seg_b=b,
            radius=r,
            centre=centre,
            support=params,
        )
    return table[gid]


def _capsule(shape: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """A capsule ``(a, b, r)`` that contains the shape, in the shape's frame."""
    zero = np.zeros(3)
    if isinstance(shape, coal.Sphere):
        return zero, zero, float(shape.radius)
    if isinstance(shape, (coal.Cylinder, coal.Capsule)):
        h = np.array([0.0, 0.0, float(shape.halfLength)])
        return -h, h, float(shape.radius)
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide, dtype=float)
        i = int(np.argmax(half))
        h = np.zeros(3)
        h[i] = half[i]
        return -h, h, float(np.linalg.norm(np.delete(half, i)))
    shape.computeLocalAABB()
    c = np.asarray(shape.aabb_center, dtype=float)
    return c, c.copy(), float(shape.aabb_radius)


def _placements(geoms: list[_Geometry], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Geometry placements in the palm frame: ``R (D, G, 3, 3)``, ``p (D, G, 3)``."""
    return attached_placements(
        [g.chain for g in geoms],
        np.array([g.R_frame_geom for g in geoms]).reshape(-1, 3, 3),
        np.array([g.p_frame_geom for g in geoms]).reshape(-1, 3),
        q,
        compiled=placements_numba.wanted(ik_backend()),  # the same loop compiled, the same bits
    )


def _place(R: np.ndarray, p: np.ndarray, local: np.ndarray) -> np.ndarray:
    """``R @ local + p`` ``(D, G, 3)`` for placements ``R`` ``(D, G, 3, 3)``, ``p`` ``(D, G,
    3)`` and points ``local`` ``(G, 3)`` in the geometries' frames, column by column (a
    stack of 3 x 3 products costs a call per matrix in ``matmul``)."""
    out = R[..., 0] * local[:, 0, None]
    out += R[..., 1] * local[:, 1, None]
    out += R[..., 2] * local[:, 2, None]
    out += p
    return out


def _segment_ends(geoms: list[_Geometry], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The capsule segments' ends of the geometries in the palm frame, ``(G, D, 3)``
    each."""
    a, b = _segment_ends_soa(geoms, q)
    return np.moveaxis(a, 0, -1), np.moveaxis(b, 0, -1)


def _segment_ends_soa(geoms: list[_Geometry], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_segment_ends` coordinate first, ``(3, G, D)`` each (the same bits)."""
    ends = [g.p_frame_geom + g.R_frame_geom @ g.seg_a for g in geoms]
    ends += [g.p_frame_geom + g.R_frame_geom @ g.seg_b for g in geoms]
    p = attached_points_soa(
        [g.chain for g in geoms] * 2,
        np.array(ends),
        q,
        compiled=placements_numba.wanted(ik_backend()),
    )
    return p[:, : len(geoms)], p[:, len(geoms) :]


def _norm3(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the vectors ``v`` ``(3, ...)``, coordinate first, written out."""
    return np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


# ---------------------------------------------------------------------- lower bounds
def _segment_distance(
    a1: np.ndarray, b1: np.ndarray, a2: np.ndarray, b2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Distance between segments ``[a1, b1]`` and ``[a2, b2]``, shapes (N, 3).

    Returns:
        The distances (N,) and the vectors from the nearest point of the second
        segment to that of the first (N, 3).

    Closed form of Ericson, *Real-Time Collision Detection*, 5.1.9 (degenerate
    segments included), vectorized.
    """
    d, diff = _segment_distance_soa(a1.T, b1.T, a2.T, b2.T)
    return d, diff.T


def _segment_distance_soa(
    a1: np.ndarray, b1: np.ndarray, a2: np.ndarray, b2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_segment_distance` coordinate first: ends ``(3, N)``, the distances
    ``(N,)`` and the vectors ``(3, N)`` (the same bits)."""
    d1, d2, r = b1 - a1, b2 - a2, a1 - a2  # (3, N) rows for speed

    def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]

    a, e, b = dot(d1, d1), dot(d2, d2), dot(d1, d2)
    c, f = dot(d1, r), dot(d2, r)
    eps = 1e-18
    a_ok, e_ok = a > eps, e > eps
    a_safe, e_safe = np.where(a_ok, a, 1.0), np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    s = np.where(
        denom > eps, np.clip((b * f - c * e) / np.where(denom > eps, denom, 1.0), 0.0, 1.0), 0.0
    )
    s = np.where(a_ok, s, 0.0)
    t = np.where(e_ok, (b * s + f) / e_safe, 0.0)
    # t outside [0, 1] (or the second segment is a point): clamp t and recompute s
    redo = (t < 0.0) | (t > 1.0) | ~e_ok
    t = np.clip(t, 0.0, 1.0)
    s = np.where(redo, np.where(a_ok, np.clip((t * b - c) / a_safe, 0.0, 1.0), 0.0), s)
    diff = r + s * d1 - t * d2
    return np.sqrt(dot(diff, diff)), diff


def _object_lower_bound(
    obj: ConvexObject, c_obj: np.ndarray, R_obj_geom: np.ndarray, params: np.ndarray
) -> np.ndarray:
    """Lower bound on the signed distance from geometries to the object.

    ``max_f (n_f . c - o_f - h(n_f))`` over the object's face planes ``n_f . x = o_f``,
    with ``c`` the geometry's centre and ``h`` its support function: the geometry lies
    entirely beyond that far in front of each face plane, and the object entirely
    behind it. Valid under penetration too (moving the geometry by the bound's
    opposite along ``n_f`` separates them).

    Args:
        obj: The object.
        c_obj: Geometry centres in the object frame, (D, G, 3) [m].
        R_obj_geom: Geometry orientations in the object frame, (D, G, 3, 3).
        params: Support parameters, (G, 6), or broadcast against the leading axes.

    Returns:
        Lower bounds (D, G) [m] (the leading axes).
    """
    # rows R^T n_f: (D, G, F, 3), term by term (matmul costs a call per 3 x 3 matrix)
    N = obj.normals
    n_local = N[:, 0, None] * R_obj_geom[..., None, 0, :]
    n_local += N[:, 1, None] * R_obj_geom[..., None, 1, :]
    n_local += N[:, 2, None] * R_obj_geom[..., None, 2, :]
    h = support(n_local, params[..., None, :])
    return np.max(c_obj @ obj.normals.T - obj.offsets - h, axis=-1)


def _placed_object_bound(
    obj: ConvexObject, c: np.ndarray, R: np.ndarray, T: np.ndarray, params: np.ndarray
) -> np.ndarray:
    """:func:`_object_lower_bound` ``(D, G)`` [m] of geometries centred at ``c``
    ``(D, G, 3)`` with orientations ``R`` ``(D, G, 3, 3)`` in the palm frame, the object
    at ``T`` ``(D, 4, 4)``; ``params`` ``(G, 6)``."""
    R_po = T[:, None, :3, :3]
    c_o = np.matmul(c - T[:, None, :3, 3], T[:, :3, :3])  # R^T (x - p), object frame
    R_og = R_po[..., 0, :, None] * R[..., 0, None, :]  # R_po^T R, term by term
    R_og += R_po[..., 1, :, None] * R[..., 1, None, :]
    R_og += R_po[..., 2, :, None] * R[..., 2, None, :]
    return _object_lower_bound(obj, c_o, R_og, params[None])


def _step_bound(c: np.ndarray, R: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Bound on how far any point of a body moves between consecutive samples.

    A point ``c + R v`` with ``|v| <= rho`` moves by at most ``|dc| + rho |dR|_2``, and
    for rotations ``|dR|_2 = |dR|_F / sqrt(2)`` (= 2 sin(angle / 2)).

    Args:
        c: Body centres (D, G, 3) [m].
        R: Body orientations (D, G, 3, 3).
        rho: Largest distance of a point of each body from its centre (G,) [m].

    Returns:
        Step bounds (D - 1, G) [m].
    """
    d = np.diff(c, axis=0)
    dc = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])
    dR = R[1:] - R[:-1]
    f = dR[..., 0, 0] * dR[..., 0, 0]  # the squares summed in order, on any CPU
    for i, j in itertools.product(range(3), range(3)):
        if i or j:
            f = f + dR[..., i, j] * dR[..., i, j]
    return dc + rho * np.sqrt(f / 2.0)


class PairDistances:
    """Lower bounds and exact Coal distances for all (sample, pair) checks of one motion.

    Pairs are the columns: first the finger's geometries vs the object, then every
    (finger geometry, other finger's geometry) pair.
    """

    def __init__(
        self,
        hand: Hand,
        obj: ConvexObject,
        f: Finger,
        q_d: np.ndarray,
        T_d: np.ndarray,
        tip_req: np.ndarray,
        link_req: float | np.ndarray,
        ff_req: float,
        coarse_stride: int = 1,
    ) -> None:
        """Place the geometries and evaluate the lower bounds.

        Args:
            hand: The hand.
            obj: The object.
            f: The moving finger.
            q_d: Dense configurations (D, nq) [rad].
            T_d: Dense object poses (D, 4, 4).
            tip_req: Required fingertip distance per sample (D,) [m].
            link_req: Required distance of the other finger geometries to the object [m],
                one for all samples or one per dense sample (D,).
            ff_req: Required distance to the other fingers [m].
            coarse_stride: 1: every bound as it is. ``s > 1``: the bounds are evaluated
                at every ``s``-th sample (and the last); a sample between two of them
                gets the better of their bounds less the sweep bound to it, and only
                where that is below the requirement its own bound. The mandatory
                queries are the same (a bound below the requirement is the sample's
                own); the bounds above it are weaker, which only the minima read.
        """
        moving = [_geometry(hand, g) for g in f.geometry_ids]
        own = set(f.geometry_ids)
        other_ids = sorted(
            {g for name, o in hand.fingers.items() if name != f.name for g in o.geometry_ids} - own
        )
        geoms = moving + [_geometry(hand, g) for g in other_ids]
        self.geoms = geoms
        self._R, self._p = _placements(geoms, q_d)
        self._T = T_d
        self._obj, self._obj_shape = obj, obj.coal_geometry()
        self._nm = nm = len(moving)
        # columns: the moving geometries vs the object, then each vs each other geometry
        no = len(geoms) - nm
        tip = set(f.tip_geometry_ids)
        self.first = np.concatenate([np.arange(nm), np.repeat(np.arange(nm), no)]).astype(int)
        self.second = np.concatenate([np.full(nm, -1), nm + np.tile(np.arange(no), nm)])
        self.second = self.second.astype(int)
        self.kind = np.concatenate(
            [[TIP if g.gid in tip else LINK for g in moving], np.full(nm * no, FF)]
        ).astype(int)
        self.required = np.empty((q_d.shape[0], self.first.size))
        self.required[:, self.kind == TIP] = tip_req[:, None]
        link = np.asarray(link_req, dtype=float)
        self.required[:, self.kind == LINK] = link[:, None] if link.ndim else link
        self.required[:, self.kind == FF] = ff_req
        self._ff_req = float(ff_req)
        # the geometries' bounding shapes (see _Geometry), one row each
        self._params = np.array([g.support for g in geoms]).reshape(-1, 6)
        self._rad = np.array([g.radius for g in geoms])
        self._reach = 0.5 * np.array([np.linalg.norm(g.seg_b - g.seg_a) for g in geoms]) + self._rad
        self._local = [
            np.array([getattr(g, key) for g in geoms]).reshape(-1, 3)
            for key in ("seg_a", "seg_b", "centre")
        ]
        self._mid_local = 0.5 * (self._local[0] + self._local[1])  # capsule segments' middles
        self._c = _place(self._R, self._p, self._local[2])  # centres, palm frame (D, G, 3)
        self._compiled = bounds_numba.wanted(ik_backend())  # the same bounds to rounding
        #: Largest per-step bound on the relative motion of two checked bodies [m].
        self.max_step_m: float
        self._sweep, self.max_step_m = self._sweep_steps(obj.radius_m)
        self.lb = self._bounds_coarse_to_fine(coarse_stride)
        self.swept = np.full(self.lb.shape, -np.inf)
        self.exact = np.full(self.lb.shape, np.nan)
        self.n_queries = 0
        # where Coal could not measure a penetration and the value is the bound's
        self.unmeasured = np.zeros(self.lb.shape, bool)
        self._request = coal.DistanceRequest()
        self._request.gjk_tolerance = 1e-9  # separation distances to ~1e-9 m
        # penetration depths (EPA) to 1e-6 m: tighter tolerances make EPA fail on
        # deep cylinder/convex penetrations (Coal then returns -DBL_MAX)
        self._request.epa_tolerance = 1e-6
        self._result = coal.DistanceResult()
        self._functors: dict[int, Any] = {}

    def _sweep_steps(self, obj_radius_m: float) -> tuple[np.ndarray, float]:
        """The sweep parameter ``S`` ``(D, P)`` [m] of each column, 0 at the first
        sample, and the largest step of any column [m].

        Between samples s and s', no point of a geometry moves by more than the sum of
        its per-step bounds ``|dc| + rho |dR|_2``, so a distance is 1-Lipschitz in the
        cumulative sum of the two bodies' steps (the sweep bound, see
        :meth:`_update_sweep`). The compiled loop (:mod:`.bounds_numba`) gives the same
        bits."""
        rho = np.array(
            [
                np.linalg.norm(g.support[:3])
                + math.hypot(g.support[3], g.support[4])
                + g.support[5]
                for g in self.geoms
            ]
        )
        T = self._T
        if self._compiled:
            S = np.empty((T.shape[0], self.first.size))
            most = bounds_numba.sweep(
                self._c,
                self._R,
                np.ascontiguousarray(T, dtype=np.float64),
                rho,
                float(obj_radius_m),
                self.first,
                self.second,
                S,
            )
            return S, most
        step_g = _step_bound(self._c, self._R, rho)  # (D - 1, G)
        step_o = _step_bound(T[:, None, :3, 3], T[:, None, :3, :3], np.array([obj_radius_m]))
        second = np.where(self.second < 0, 0, self.second)
        other = np.where(self.second < 0, step_o[:, :1], step_g[:, second])
        step = step_g[:, self.first] + other
        S = np.vstack([np.zeros((1, step.shape[1])), np.cumsum(step, axis=0)])
        return S, float(step.max()) if step.size else 0.0

    def _bounds_coarse_to_fine(self, stride: int) -> np.ndarray:
        """Lower bounds ``(D, P)`` of every (sample, column), see ``coarse_stride``."""
        n_d = self._R.shape[0]
        if stride <= 1 or n_d <= 2 * stride:
            return self._bounds_rows(np.arange(n_d))
        coarse = np.unique(np.concatenate([np.arange(0, n_d, stride), [n_d - 1]]))
        lb_c = self._bounds_rows(coarse)
        # a distance is 1-Lipschitz in the sweep parameter S (see _update_sweep): from
        # the coarse samples c0 <= s <= c1 around s, d(s) >= lb(c) - |S(s) - S(c)|
        S = self._sweep
        if self._compiled:  # the same bits
            lb = np.empty(S.shape)
            bounds_numba.interpolate(lb_c, coarse, S, lb)
        else:
            s = np.arange(n_d)
            hi = np.searchsorted(coarse, s)
            lo = np.where(coarse[hi] == s, hi, hi - 1)
            lb = np.maximum(lb_c[lo] - (S - S[coarse[lo]]), lb_c[hi] - (S[coarse[hi]] - S))
            lb -= 1e-12  # rounding of S
            lb[coarse] = lb_c
        rows, cols = np.nonzero(lb < self.required)
        if rows.size:
            lb[rows, cols] = self._bounds(rows, cols)
        return lb

    def _bounds_rows(self, rows: np.ndarray) -> np.ndarray:
        """Lower bounds ``(R, P)`` of every column at the samples ``rows``."""
        if self._compiled:
            n_p = self.first.size
            lb = self._bounds_compiled(np.repeat(rows, n_p), np.tile(np.arange(n_p), rows.size))
            return lb.reshape(rows.size, n_p)
        nm, n_g = self._nm, len(self.geoms)
        R, p, T = self._R[rows], self._p[rows], self._T[rows]
        # geometry vs object: the face-plane support bound, in the object frame
        lb_obj = _placed_object_bound(
            self._obj, self._c[rows, :nm], R[:, :nm], T, self._params[:nm]
        )
        # geometry vs geometry: bounding spheres first; near pairs get the capsule bound
        # and the separating-axis bound along the capsules' nearest-point direction
        i1, i2 = self.first[nm:], self.second[nm:]
        mid = _place(R, p, self._mid_local)
        diff = mid[:, i1] - mid[:, i2]
        reach = self._reach
        lb_ff = np.sqrt(np.einsum("dpi,dpi->dp", diff, diff)) - reach[i1] - reach[i2]
        d, k = np.nonzero(lb_ff < self._ff_req + BROAD_PHASE_MARGIN_M)
        lb_ff[d, k] = self._near_pair_bounds(rows[d] * n_g + i1[k], rows[d] * n_g + i2[k])
        return np.concatenate([lb_obj, lb_ff], axis=1)

    def _bounds(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Lower bounds ``(K,)`` of the (sample, column) pairs ``rows``, ``cols``: the
        same numbers as :meth:`_bounds_rows`, pair by pair."""
        if self._compiled:
            return self._bounds_compiled(rows, cols)
        out = np.empty(rows.size)
        n_g = len(self.geoms)
        g1, g2 = self.first[cols], self.second[cols]
        obj = g2 < 0
        if obj.any():
            r, g = rows[obj], g1[obj]
            R, T = self._R[r, g], self._T[r]
            c = _place(R, self._p[r, g], self._local[2][g])
            c_o = np.einsum("ki,kij->kj", c - T[:, :3, 3], T[:, :3, :3])
            R_og = np.einsum("kji,kjl->kil", T[:, :3, :3], R)
            out[obj] = _object_lower_bound(self._obj, c_o, R_og, self._params[g])
        ff = np.flatnonzero(~obj)
        if ff.size:
            j1, j2 = rows[ff] * n_g + g1[ff], rows[ff] * n_g + g2[ff]
            R_, p_, mid = self._R.reshape(-1, 3, 3), self._p.reshape(-1, 3), self._mid_local
            diff = _place(R_[j1], p_[j1], mid[g1[ff]]) - _place(R_[j2], p_[j2], mid[g2[ff]])
            reach = self._reach[g1[ff]] + self._reach[g2[ff]]
            lb = np.sqrt(np.einsum("ki,ki->k", diff, diff)) - reach
            near = np.flatnonzero(lb < self._ff_req + BROAD_PHASE_MARGIN_M)
            lb[near] = self._near_pair_bounds(j1[near], j2[near])
            out[ff] = lb
        return out

    def _bounds_compiled(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """:meth:`_bounds` by the compiled loop (:mod:`.bounds_numba`): the same
        bounds to rounding, ``(K,)`` [m] of the samples ``rows`` ``(K,)`` and columns
        ``cols`` ``(K,)``."""
        out = np.empty(rows.size)
        if rows.size == 0:
            return out
        obj = self._obj
        bounds_numba.bounds(
            self._R,
            self._p,
            np.ascontiguousarray(self._T, dtype=np.float64),
            self._c,
            self._local[0],
            self._local[1],
            self._mid_local,
            self._params,
            self._rad,
            self._reach,
            np.ascontiguousarray(obj.normals, dtype=np.float64),
            np.ascontiguousarray(obj.offsets, dtype=np.float64),
            self.first,
            self.second,
            self._ff_req + BROAD_PHASE_MARGIN_M,
            np.ascontiguousarray(rows, dtype=np.int64),
            np.ascontiguousarray(cols, dtype=np.int64),
            out,
        )
        return out

    def _near_pair_bounds(self, j1: np.ndarray, j2: np.ndarray) -> np.ndarray:
        """The capsule bound and the separating-axis bound along the capsules'
        nearest-point direction, the larger, of the geometry pairs at flat (sample,
        geometry) indices ``j1``, ``j2`` (K,)."""
        n_g = len(self.geoms)
        g1, g2 = j1 % n_g, j2 % n_g
        R_, p_ = self._R.reshape(-1, 3, 3), self._p.reshape(-1, 3)
        R1, p1, R2, p2 = R_[j1], p_[j1], R_[j2], p_[j2]
        a_loc, b_loc, c_loc = self._local
        seg, v = _segment_distance(
            _place(R1, p1, a_loc[g1]),
            _place(R1, p1, b_loc[g1]),
            _place(R2, p2, a_loc[g2]),
            _place(R2, p2, b_loc[g2]),
        )
        lb = seg - self._rad[g1] - self._rad[g2]
        u = v / np.where(seg > 1e-12, seg, 1.0)[:, None]  # from geometry 2 towards 1
        gap = (
            np.einsum("ni,ni->n", u, _place(R1, p1, c_loc[g1]) - _place(R2, p2, c_loc[g2]))
            - support(np.einsum("ni,nij->nj", u, R1), self._params[g1])
            - support(np.einsum("ni,nij->nj", u, R2), self._params[g2])
        )
        return np.where(seg > 1e-12, np.maximum(lb, gap), lb)

    def run(self, exact_minima: bool = True) -> tuple[dict[str, float], bool]:
        """Mandatory queries, then the minima.

        Args:
            exact_minima: Settle the minima by branch and bound; False: the smallest
                of the exact distances and the bounds of the samples not queried.

        Returns:
            The minima ``{"tip", "link", "ff", "margin"}`` [m] and whether all are exact.
        """
        self._mandatory_queries()
        if not exact_minima:
            return self._lowest_all()
        minimum = self._minimum
        out, exact = {}, True
        zero = np.zeros(self.lb.shape)
        for key, kind in (("tip", TIP), ("link", LINK), ("ff", FF)):
            out[key], ok = minimum(zero, self.kind == kind)
            exact &= ok
        out["margin"], ok = minimum(-self.required, np.ones(self.kind.size, dtype=bool))
        return out, exact and ok

    def _mandatory_queries(self) -> None:
        """Every (sample, column) whose bound is below its requirement, settled: first
        every :data:`QUERY_STRIDE`-th such sample of each column is measured, then only
        those that the sweep bound from these Coal values does not lift above the
        requirement by :data:`_LIFT_MARGIN_M`. A distance below its requirement is
        never lifted by a lower bound, so every failing sample is measured either way
        (the same failures and values), up to one case: a sample where Coal's EPA fails
        keeps the broad-phase bound as its value, which measuring it would report as a
        failure, while the sweep bound from its neighbours may spare it."""
        cols, rows = np.nonzero((self.lb < self.required).T)  # column by column, in time
        if QUERY_STRIDE > 1 and rows.size:
            starts = np.flatnonzero(np.r_[True, cols[1:] != cols[:-1]])
            rank = np.arange(rows.size) - np.repeat(starts, np.diff(np.r_[starts, rows.size]))
            first = rank % QUERY_STRIDE == 0
            self._query(rows[first], cols[first])
            self._update_sweep(np.unique(cols[first]))
            lifted = self.swept[rows, cols] >= self.required[rows, cols] + _LIFT_MARGIN_M
            rows, cols = rows[~lifted], cols[~lifted]
        self._query(rows, cols)
        self._update_sweep(np.unique(cols))

    def _lowest_all(self) -> tuple[dict[str, float], bool]:
        """:meth:`run`'s minima without further queries: of each kind, and of the
        distances less their requirements, the smallest of the exact distances and of
        the bounds (broad phase or sweep) of the samples not queried; exact where no
        such bound is below the smallest exact distance."""
        done = ~np.isnan(self.exact)
        ex = np.where(done, self.exact, np.inf)
        bound = np.where(done, np.inf, np.maximum(self.lb, self.swept))
        ex_col, bound_col = ex.min(axis=0, initial=np.inf), bound.min(axis=0, initial=np.inf)
        out, exact = {}, True
        for key, kind in (("tip", TIP), ("link", LINK), ("ff", FF)):
            cols = self.kind == kind
            best = float(ex_col[cols].min(initial=np.inf))
            low = float(bound_col[cols].min(initial=np.inf))
            out[key] = min(best, low)
            exact &= best <= low
        best = float((ex - self.required).min(initial=np.inf))
        low = float((bound - self.required).min(initial=np.inf))
        out["margin"] = min(best, low)
        return out, exact and best <= low

    def _minimum(self, offset: np.ndarray, columns: np.ndarray) -> tuple[float, bool]:
        """``min(distance + offset)`` over the given columns, by branch and bound.

        The bound of a sample not queried is the larger of its broad-phase bound and
        the sweep bound from the exact values of its column. Each round queries, in
        every column whose bound is still below the best exact value, the sample with
        the lowest bound, until no bound is below it. A minimum below the requirement
        needs no extra query (every sample whose bound is below it was queried).

        Args:
            offset: Added to every distance, shape (D, P) [m].
            columns: Columns taking part, boolean shape (P,).

        Returns:
            The minimum and True, or, when :data:`MAX_MINIMUM_QUERIES` did not settle it,
            a lower bound on it and False.
        """
        cols = np.nonzero(columns)[0]
        if cols.size == 0:
            return math.inf, True
        off = offset[:, cols]
        ex = self.exact[:, cols] + off
        done = ~np.isnan(ex)
        best = float(np.min(ex[done])) if done.any() else math.inf
        bound = np.where(done, np.inf, np.maximum(self.lb[:, cols], self.swept[:, cols]) + off)
        rows = np.argmin(bound, axis=0)  # per column, the sample with the lowest bound
        low = bound[rows, np.arange(cols.size)]
        n_extra = 0
        while True:
            open_ = np.nonzero(low < best)[0]
            if open_.size == 0:
                return best, True
            if n_extra >= MAX_MINIMUM_QUERIES:
                return float(np.min(low)), False  # bounds every distance left
            pick = open_[np.argsort(low[open_])[: MAX_MINIMUM_QUERIES - n_extra]]
            sub = cols[pick]
            self._query(rows[pick], sub)
            self._update_sweep(sub)
            n_extra += pick.size
            # only the picked columns changed
            ex = self.exact[:, sub] + off[:, pick]
            done = ~np.isnan(ex)
            best = min(best, float(np.min(ex[done])))
            bound = np.where(
                done, np.inf, np.maximum(self.lb[:, sub], self.swept[:, sub]) + off[:, pick]
            )
            rows[pick] = np.argmin(bound, axis=0)
            low[pick] = bound[rows[pick], np.arange(pick.size)]

    def _update_sweep(self, cols: np.ndarray) -> None:
        """Sweep bounds of the given columns from their exact values.

        ``swept(s) = max_k exact(k) - |S(s) - S(k)|`` with ``S`` the cumulative step
        bound, in two running maxima: ``max_{k<=s} (exact(k) + S(k)) - S(s)`` and
        ``max_{k>=s} (exact(k) - S(k)) + S(s)``.
        """
        if cols.size == 0:
            return
        S = self._sweep[:, cols]
        e = self.exact[:, cols]
        e = np.where(np.isnan(e), -np.inf, e)
        forward = np.maximum.accumulate(e + S, axis=0) - S
        backward = np.maximum.accumulate((e - S)[::-1], axis=0)[::-1] + S
        self.swept[:, cols] = np.maximum(forward, backward) - 1e-12  # rounding of S

    def _query(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Exact Coal distances for the (sample, column) pairs not yet computed."""
        todo = np.isnan(self.exact[rows, cols])
        rows, cols = rows[todo], cols[todo]
        if rows.size == 0:
            return
        g1 = self.first[cols]
        g2 = self.second[cols]
        # relative placement of geometry g1 in the frame of the second body (object or g2)
        R1, p1 = self._R[rows, g1], self._p[rows, g1]
        is_obj = g2 < 0
        R2 = np.where(
            is_obj[:, None, None], self._T[rows, :3, :3], self._R[rows, np.maximum(g2, 0)]
        )
        p2 = np.where(is_obj[:, None], self._T[rows, :3, 3], self._p[rows, np.maximum(g2, 0)])
        R_rel = np.matmul(np.swapaxes(R2, 1, 2), R1)
        p_rel = np.matmul((p1 - p2)[:, None, :], R2)[:, 0]
        identity = coal.Transform3s()
        request, result = self._request, self._result
        values = np.empty(rows.size)
        for n in range(rows.size):
            key = int(cols[n])
            fn = self._functors.get(key)
            if fn is None:
                second = self._obj_shape if is_obj[n] else self.geoms[g2[n]].shape
                fn = self._functors[key] = coal.ComputeDistance(second, self.geoms[g1[n]].shape)
            result.clear()  # Coal keeps the smaller of the old and new distances otherwise
            values[n] = fn(identity, coal.Transform3s(R_rel[n], p_rel[n]), request, result)
        bad = np.nonzero(~(values > -_MAX_DEPTH_M))[0]  # NaN or EPA failure (-DBL_MAX)
        if bad.size:
            retry = coal.DistanceRequest()
            retry.epa_tolerance = 1e-4
            for n in bad.tolist():
                values[n] = coal.distance(
                    self._obj_shape if is_obj[n] else self.geoms[g2[n]].shape,
                    identity,
                    self.geoms[g1[n]].shape,
                    coal.Transform3s(R_rel[n], p_rel[n]),
                    retry,
                    coal.DistanceResult(),
                )
                if not values[n] > -_MAX_DEPTH_M:  # keep the (negative) lower bound
                    values[n] = min(self.lb[rows[n], cols[n]], 0.0)
                    self.unmeasured[rows[n], cols[n]] = True
                    logger.warning(
                        "Coal could not measure a penetration depth; using the "
                        "broad-phase bound %.6f m",
                        values[n],
                    )
        self.exact[rows, cols] = values
        self.n_queries += int(rows.size)


def object_gap_bound(
    hand: Hand, ids: Sequence[int], obj: ConvexObject, q: np.ndarray, T_palm_object: np.ndarray
) -> np.ndarray:
    """Lower bound ``(N,)`` [m] on the signed distance from the hand's geometries ``ids``
    (the smallest over them; inf when empty) to the object, at each configuration row of
    ``q`` ``(N, nq)`` and object pose ``T_palm_object`` ``(N, 4, 4)`` (palm frame): the
    face-plane support bound of the broad phase, valid under penetration too. A bound at
    or above a requirement proves Coal's distance meets it (to Coal's tolerances)."""
    return object_gap_bounds(hand, [ids], obj, q, T_palm_object)[0]


def object_gap_bounds(
    hand: Hand,
    groups: Sequence[Sequence[int]],
    obj: ConvexObject,
    q: np.ndarray,
    T_palm_object: np.ndarray,
) -> np.ndarray:
    """:func:`object_gap_bound` of each group of geometry ids (e.g. a finger's links and
    its fingertip link), ``(len(groups), N)`` [m]: the same bits as one call per group,
    with the geometries placed in one pass."""
    q = np.atleast_2d(np.asarray(q, float))
    T = np.broadcast_to(np.asarray(T_palm_object, float), (q.shape[0], 4, 4))
    out = np.full((len(groups), q.shape[0]), np.inf)
    ids = [g for group in groups for g in group]
    if not ids or q.shape[0] == 0:
        return out
    geoms = [_geometry(hand, g) for g in ids]
    R, p = _placements(geoms, q)  # (N, G, 3, 3), (N, G, 3)
    c = _place(R, p, np.array([g.centre for g in geoms]).reshape(-1, 3))
    params = np.array([g.support for g in geoms]).reshape(-1, 6)
    if bounds_numba.wanted(ik_backend()):  # the same bounds to rounding, in one loop
        bound = np.empty((q.shape[0], len(geoms)))
        bounds_numba.object_bounds(
            np.ascontiguousarray(R),
            np.ascontiguousarray(T),
            c,
            params,
            np.ascontiguousarray(obj.normals, dtype=np.float64),
            np.ascontiguousarray(obj.offsets, dtype=np.float64),
            bound,
        )
    else:
        bound = _placed_object_bound(obj, c, R, T, params)  # (N, G)
    start = 0
    for k, group in enumerate(groups):
        if group:
            out[k] = bound[:, start : start + len(group)].min(axis=1)
        start += len(group)
    return out


def capsule_gap(
    hand: Hand,
    ids_a: list[int],
    ids_b: list[int],
    q: np.ndarray,
    *,
    cap_m: float = np.inf,
    q_b: np.ndarray | None = None,
    rows_b: np.ndarray | None = None,
) -> np.ndarray:
    """Lower bound ``(N,)`` [m] on the distance between geometries ``ids_a`` and ``ids_b``
    of the hand at each configuration row of ``q`` ``(N, nq)``, from capsules that
    contain the geometries (inf when either list is empty); ``min(bound, cap_m)``: pairs
    whose bounding spheres are ``cap_m`` apart are not measured (a bound below ``cap_m``
    is the same, to the bit, as without the cap).

    With ``q_b`` ``(M, nq)`` and ``rows_b`` ``(N,)``, the geometries ``ids_b`` are
    placed at ``q_b[rows_b[n]]`` for row ``n`` instead (e.g. each distinct configuration
    of the other fingers once; a geometry's placement depends on its own chain's joints
    alone, so the bound is the same, to the bit, as with those rows in ``q``)."""
    return capsule_gaps(hand, ids_a, [ids_b], q, cap_m=cap_m, q_b=q_b, rows_b=rows_b)[0]


def capsule_gaps(
    hand: Hand,
    ids_a: list[int],
    groups_b: Sequence[Sequence[int]],
    q: np.ndarray,
    *,
    cap_m: float = np.inf,
    q_b: np.ndarray | None = None,
    rows_b: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`capsule_gap` of ``ids_a`` against each group of ``groups_b`` (e.g. each
    other finger's geometries), ``(G, N)`` [m]: the same bits as one call per group,
    with ``ids_a`` placed once for all groups."""
    n_rows = q.shape[0]
    gap = np.full((len(groups_b), n_rows), np.inf)
    ids_b = [g for group in groups_b for g in group]
    if not ids_a or not ids_b:
        return gap
    group_of = np.repeat(np.arange(len(groups_b)), [len(group) for group in groups_b])
    ga = [_geometry(hand, g) for g in ids_a]
    gb = [_geometry(hand, g) for g in ids_b]
    # capsule segments' ends, coordinate first: (3, A, N) and (3, B, M), ids_b's at
    # their own M rows (row n reads row rows_b[n])
    A1, B1 = _segment_ends_soa(ga, q)
    if q_b is None or rows_b is None:
        A2, B2 = _segment_ends_soa(gb, q)
        rows_b = np.arange(n_rows)
    else:
        A2, B2 = _segment_ends_soa(gb, np.asarray(q_b, float))
        rows_b = np.asarray(rows_b, dtype=np.intp)
    n_b_rows = A2.shape[2]
    rad_a = np.array([g.radius for g in ga])
    rad_b = np.array([h.radius for h in gb])
    # broad phase: the capsules' bounding spheres (centre: the segment's middle); every
    # test keeps 1 nm to spare over rounding, so that it keeps every (a, b, row) whose
    # capsule bound can be below the cap
    reach_a = np.array([0.5 * np.linalg.norm(g.seg_b - g.seg_a) for g in ga]) + rad_a
    reach_b = np.array([0.5 * np.linalg.norm(h.seg_b - h.seg_a) for h in gb]) + rad_b
    if ik_backend() == "numba":  # the same loop compiled, the same bits
        capsules_numba.gaps(
            A1, B1, A2, B2, rows_b, rad_a, rad_b, reach_a, reach_b, group_of, gap, cap_m
        )
        return np.minimum(gap, cap_m)
    mid_a, mid_b = 0.5 * (A1 + B1), 0.5 * (A2 + B2)
    # every (a, b, row) at once, (A, B, N)
    far = _norm3(mid_a[:, :, None] - mid_b[:, None][..., rows_b])
    i, j, n = np.nonzero(far - reach_a[:, None, None] - reach_b[:, None] < cap_m + 1e-9)
    if i.size:  # each pair's distances as computed alone (elementwise)
        ia, ib = i * n_rows + n, j * n_b_rows + rows_b[n]
        ends = [e.reshape(3, -1)[:, ia] for e in (A1, B1)]
        ends += [e.reshape(3, -1)[:, ib] for e in (A2, B2)]
        d, _ = _segment_distance_soa(*ends)
        np.minimum.at(gap, (group_of[j], n), d - rad_a[i] - rad_b[j])
    return np.minimum(gap, cap_m)


def capsule_ends(hand: Hand, ids: list[int], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ends of the capsule segments of the geometries ``ids`` (the capsules that
    :func:`capsule_pair_gaps` bounds them with) at configurations ``q`` ``(N, nq)``,
    palm frame: ``(G, N, 3)`` each [m]. A geometry's ends depend on its own chain's
    joints alone, row by row."""
    return _segment_ends([_geometry(hand, g) for g in ids], np.asarray(q, float))


def capsule_pair_gaps(
    hand: Hand,
    ids_a: list[int],
    ids_b: list[int],
    q: np.ndarray | None = None,
    *,
    ends_a: tuple[np.ndarray, np.ndarray] | None = None,
    ends_b: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Lower bounds ``(A, B, N)`` [m] on the distance between each geometry of ``ids_a``
    and each of ``ids_b`` at each configuration row of ``q`` ``(N, nq)``, from capsules
    that contain the geometries: :func:`capsule_gap`'s pairs one by one (its bound is their
    minimum, to the bit), for a caller that measures the close pairs exactly.

    ``ends_a``, ``ends_b``: the geometries' :func:`capsule_ends`, if known, instead of
    ``q`` (the same bits); ``ends_b`` may hold one row, for ``ids_b`` held still at
    every row."""
    ga = [_geometry(hand, g) for g in ids_a]
    gb = [_geometry(hand, g) for g in ids_b]
    rows = None if q is None else np.asarray(q, float)
    if rows is None and (ends_a is None or ends_b is None):
        raise InputError("q", "is None and ends_a or ends_b not given", "(N, nq) rows")
    A1, B1 = ends_a if ends_a is not None else _segment_ends(ga, cast(np.ndarray, rows))
    A2, B2 = ends_b if ends_b is not None else _segment_ends(gb, cast(np.ndarray, rows))
    shape = (len(ga), len(gb), A1.shape[1])  # the rows are ids_a's
    if not ga or not gb:
        return np.full(shape, np.inf)
    # every (pair, row) in one batch: each computed elementwise, as alone
    ends = [np.broadcast_to(e, (*shape, 3)).reshape(-1, 3) for e in (A1[:, None], B1[:, None])]
    ends += [np.broadcast_to(e, (*shape, 3)).reshape(-1, 3) for e in (A2[None], B2[None])]
    d = _segment_distance(*ends)[0].reshape(shape)
    rad_a = np.array([g.radius for g in ga])
    rad_b = np.array([h.radius for h in gb])
    return d - rad_a[:, None, None] - rad_b[None, :, None]
