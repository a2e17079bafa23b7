"""Joint-space manifolds of the object surface (the paper's Fig. 2).

For one finger, every sampled surface point ``s`` (normal ``n``) is mapped into the
finger's joint space by IK of the tip-centre target ``T_palm_object(t) (s + r n)``,
at every time of a grid. As the object moves, this point cloud (the manifold) moves
through joint space; the joint limits are the boundary planes of a box.

IK runs in a box *extended* beyond the joint limits by ``extend_rad`` so that the part
of the manifold just outside the limits is mapped too (that is what the paper draws:
the manifold crossing the boundary planes). A point is

- ``reachable`` when IK reaches it within tolerance in the extended box,
- ``inside`` when, in addition, its joint coordinates are within the real limits,
- ``pad_ok`` when the finger pad faces the surface there (see :mod:`.contact`),

and its ``margin`` is the signed distance [rad] of its joint coordinates to the nearest
boundary plane (negative outside). Times are processed in order, each warm-started
from the previous solution. Two repairs keep the entries equal to a per-point IK: a
point whose warm start fails is re-solved cold when its target may have come into
reach (a warm start can stay in a local minimum), and a solution outside the limits
is re-solved in the real box from its reflection about the violated planes (the
extended box admits a second branch, e.g. a hyperextended one mirroring a flexed one,
where the real box has a solution inside).

Points that provably cannot be feasible are not sent to IK: points whose tip target
lies outside a conservative voxel cover of the finger's workspace, and points on a face
whose normal no pad direction of the finger can oppose within the cone (checked per
face and time against pad directions sampled over the joint box, with a slack that
bounds the sampling error). They are reported unreachable, with NaN coordinates.

A manifold built for the initial grasp only (``track``, :class:`StartTracking`) maps
only what that choice reads: every point at the first time, then only the points
feasible there, each through the first ``all_until_s`` and after that only while it
stays usable (:func:`~regrasp_pin.grasp.choice.exit_times` reads no further). The
other entries are reported not reachable. Each point's entries depend on that point
alone (the IK runs point by point in a batch, warm starts and repairs are per point),
so the entries it maps equal the full manifold's.

The link-vs-object Coal test of the contact model is not part of the manifold (it
would cost a Coal query per point and time); it is applied where contacts are chosen
(:mod:`.choice`, :mod:`.initial`) and followed (:mod:`.tracking`).
"""

from __future__ import annotations

import collections
import functools
import hashlib
import logging
import os
import struct
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, frozen, positive, positive_int
from ..exceptions import InputError
from ..model.hand import Finger, Hand
from ..model.ik import IKResult, ik_backend, solve_position_ik
from ..model.motion import ObjectMotion
from ..model.objects import SurfaceSample
from .contact import ContactModel, pad_cosines_and_overshoot, tip_targets

__all__ = [
    "THREADS_ENV",
    "Manifold",
    "StartTracking",
    "WorkspaceVoxels",
    "build_manifold",
    "build_manifolds",
    "default_threads",
    "forget_first_times",
    "manifold_threads",
    "workspace_voxels",
]

log = logging.getLogger(__name__)


_ALL = slice(None)  # every row or column of a manifold array


def _block(rows: slice | np.ndarray, points: slice | np.ndarray) -> tuple:
    """The index of the block ``rows`` x ``points`` of a ``(T, N)`` array (an outer
    product when both are index arrays)."""
    if isinstance(rows, slice) or isinstance(points, slice):
        return rows, points
    return np.ix_(np.asarray(rows), np.asarray(points))


@dataclass(frozen=True)
class Manifold:
    """One finger's manifold over a time grid.

    Attributes:
        finger: Finger name.
        times_s: ``(T,)`` times [s].
        q: ``(T, N, k)`` joint coordinates of the N surface points [rad] (the IK
            result; meaningful where ``reachable``).
        reachable: ``(T, N)`` IK reached the point (extended box).
        inside: ``(T, N)`` reachable and within the joint limits.
        margin_rad: ``(T, N)`` signed distance to the nearest boundary plane [rad]
            (``-inf`` where not reachable).
        pad_ok: ``(T, N)`` the pad faces the surface.
        lower: ``(k,)`` joint limits [rad].
        upper: ``(k,)`` joint limits [rad].
        T_palm_object: ``(T, 4, 4)`` object poses at the grid times.
        tip_clear: ``(T, N)`` reachable, and the fingertip link does not reach past the
            plane on which the tip sphere rests by more than
            ``ContactModel.tip_penetration_m`` (:class:`~regrasp_pin.model.tip_reach.
            TipReach`): inside a face, where it is False the link sinks in. Not part of
            :attr:`feasible` (near an edge the object may not be under the link);
            :meth:`holdable` uses it. None: not computed (every entry counts as clear).
    """

    finger: str
    times_s: np.ndarray
    q: np.ndarray
    reachable: np.ndarray
    inside: np.ndarray
    margin_rad: np.ndarray
    pad_ok: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    T_palm_object: np.ndarray
    tip_clear: np.ndarray | None = None

    @property
    def feasible(self) -> np.ndarray:
        """``(T, N)`` inside the limits and the pad facing the surface."""
        return self.inside & self.pad_ok

    def usable(
        self,
        margin_rad: float,
        *,
        rows: slice | np.ndarray = _ALL,
        points: slice | np.ndarray = _ALL,
    ) -> np.ndarray:
        """``(T, N)`` feasible with at least ``margin_rad`` to every boundary plane; with
        ``rows`` (time indices) and ``points`` (sample indices), only that block."""
        block = _block(rows, points)
        return self.inside[block] & self.pad_ok[block] & (self.margin_rad[block] >= margin_rad)

    def holdable(
        self,
        margin_rad: float,
        *,
        rows: slice | np.ndarray = _ALL,
        points: slice | np.ndarray = _ALL,
    ) -> np.ndarray:
        """``(T, N)`` :meth:`usable` and, as far as the fingertip link's shape tells
        (:attr:`tip_clear`), held there without the link sinking into the face: what
        a held contact's exit time is read from (a ranking; Coal decides). ``rows``,
        ``points``: as in :meth:`usable`."""
        usable = self.usable(margin_rad, rows=rows, points=points)
        return usable if self.tip_clear is None else usable & self.tip_clear[_block(rows, points)]

    def time_index(self, t_s: float) -> int:
        """Index of the first grid time >= ``t_s`` (clamped to the last)."""
        return min(int(np.searchsorted(self.times_s, t_s - 1e-12)), self.times_s.size - 1)


@dataclass(frozen=True)
class StartTracking:
    """Which entries of a manifold the choice of a grasp at its first time reads.

    With it, :func:`build_manifold` maps every point at the first time and after that
    only the points feasible there (inside the limits, pad facing): each at every time
    up to ``all_until_s`` (where the grasp search reads its joint coordinates), and
    after that at a time only if it was usable with ``margin_rad`` at every earlier
    time (so that :func:`~regrasp_pin.grasp.choice.exit_times` from the first time,
    over ``usable(margin_rad)``, is the full manifold's). Every other entry is reported
    not reachable (NaN coordinates).

    Attributes:
        margin_rad: The margin of the usability that the lasting times are read with
            [rad] (``ContactModel.limit_margin_rad`` for the initial grasp).
        all_until_s: Every point feasible at the first time is mapped at all times up
            to this one [s] (within 1e-9 s).
    """

    margin_rad: float
    all_until_s: float


@dataclass(frozen=True)
class WorkspaceVoxels:
    """A conservative voxel cover of a finger's tip-centre workspace (palm frame).

    Attributes:
        origin: ``(3,)`` corner of voxel (0, 0, 0) [m].
        voxel_m: Voxel edge [m].
        occupied: ``(nx, ny, nz)`` True where some configuration may put the tip.
    """

    origin: np.ndarray
    voxel_m: float
    occupied: np.ndarray

    def contains(self, p_palm: np.ndarray) -> np.ndarray:
        """``(...,)`` True where the points may be reachable (False = provably not)."""
        # component by component (a broadcast along a short last axis is slow)
        ix, iy, iz = (
            np.floor((p_palm[..., a] - self.origin[a]) / self.voxel_m).astype(np.int64)
            for a in range(3)
        )
        nx, ny, nz = self.occupied.shape
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & (iz >= 0) & (iz < nz)
        flat = np.where(ok, (ix * ny + iy) * nz + iz, 0)  # C order of `occupied`
        return ok & self.occupied.ravel()[flat]


@functools.lru_cache(maxsize=64)
def workspace_voxels(
    finger: Finger, extend_rad: float = 0.0, voxel_m: float = 0.003, max_samples: int = 120_000
) -> WorkspaceVoxels:
    """Voxels that hold every tip-centre position reachable in the (extended) joint box.

    Joint ``j`` is sampled on a regular grid of step ``h_j`` [rad]; any configuration is
    within ``h_j / 2`` of a grid sample in each joint, so its tip is within
    ``L = sum_j c_j h_j / 2`` of that sample's tip, where ``c_j`` [m/rad] bounds the norm
    of the Jacobian's column ``j`` at every configuration (:func:`_column_norm_bounds`).
    The steps make the ``c_j h_j`` equal (a joint that swings the tip far is sampled
    densest), which minimises ``L`` for about ``max_samples`` samples (at least: each
    joint's count rounds up; :func:`_cover_grid`). A voxel is marked when its centre
    lies within ``L + sqrt(3) voxel_m`` of the centre of a voxel that holds a sampled tip
    (a Euclidean distance transform): a reachable tip and its nearest sample each lie
    within half a voxel diagonal of their voxels' centres, which makes the cover
    conservative.
    """
    axes, reach = _cover_grid(finger, extend_rad, max_samples)
    q = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, finger.k)
    p = finger.fk(q)
    radius = reach + np.sqrt(3.0) * voxel_m
    pad = int(np.ceil(radius / voxel_m)) + 1
    origin = p.min(0) - (pad + 1) * voxel_m
    idx = np.floor((p - origin) / voxel_m).astype(np.int64)
    occ = np.zeros(tuple(idx.max(0) + pad + 2), bool)
    occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    from scipy.ndimage import distance_transform_edt

    near = distance_transform_edt(~occ, sampling=voxel_m) <= radius + 1e-9
    return WorkspaceVoxels(origin=origin, voxel_m=voxel_m, occupied=near)


def _cover_grid(
    finger: Finger, extend_rad: float, max_samples: int
) -> tuple[list[np.ndarray], float]:
    """The joint values that :func:`workspace_voxels` samples, per joint, and ``L`` [m]:
    every configuration of the (extended) box has its tip within ``L`` of the tip of the
    grid sample nearest to it in every joint.

    A joint on the grid of ``n`` values spaced ``h`` is within ``h / 2`` of one; a joint
    whose range is no wider than its step would be (a locked or nearly locked joint,
    or one that barely moves the tip) takes only the middle of its range, within half
    its range, and leaves the samples to the others (found again until none is).
    """
    lo, hi = finger.lower - extend_rad, finger.upper + extend_rad
    span = hi - lo
    c = _column_norm_bounds(finger)
    c_pos = np.maximum(c, 1e-3 * c.max() + 1e-9)  # a joint that barely moves the tip
    grid = span > 0.0
    while grid.any():
        size = float(np.prod(span[grid] * c_pos[grid]) / max_samples)
        step = size ** (1.0 / int(grid.sum())) / c_pos[grid]
        thin = span[grid] <= step
        if not thin.any():
            break
        grid[np.flatnonzero(grid)[thin]] = False
    counts = np.ones(finger.k, np.int64)
    if grid.any():
        counts[grid] = np.ceil(span[grid] / step).astype(np.int64) + 1
    axes = [
        np.linspace(a, b, int(n)) if g else np.array([0.5 * (a + b)])
        for a, b, n, g in zip(lo, hi, counts, grid, strict=True)
    ]
    h = np.where(grid, span / np.maximum(counts - 1, 1), span)
    return axes, float(c @ h) / 2


def _column_norm_bounds(finger: Finger) -> np.ndarray:
    """``(k,)`` bounds on the norm of each column of the tip's position Jacobian
    [m/rad], for every configuration: a unit turn of a joint moves the tip by at most
    its distance from the joint's origin, at most the lengths of the links after it
    (the chain's offsets, :meth:`~regrasp_pin.model.kinematics.FingerChain.packed`),
    times the joint's mimic scaling, summed over the joints it drives."""
    _, t, column, scaling, _, tip_t = finger.chain.packed()
    links = np.linalg.norm(t, axis=1)
    after = np.cumsum(links[::-1])[::-1] - links + float(np.linalg.norm(tip_t))
    bound = np.zeros(finger.k)
    np.add.at(bound, column, np.abs(scaling) * after)
    return bound


@functools.lru_cache(maxsize=64)
def pad_directions(
    finger: Finger, extend_rad: float = 0.0, n: int = 20000
) -> tuple[np.ndarray, float]:
    """Pad directions ``(M, 3)`` (palm frame, read-only) sampled over the joint box, and
    a slack; cached per finger (the sample is seeded, the same every time).

    The slack [cos units] bounds how much the best pad direction for any normal can
    exceed the best sampled one (the angular sampling step), so that
    ``max(P @ -n) + slack < cos(cone)`` proves no configuration faces ``n``.
    """
    lo, hi = finger.lower - extend_rad, finger.upper + extend_rad
    rng = np.random.default_rng(54321)
    q = rng.uniform(lo, hi, (n, finger.k))
    R, _ = finger.chain.poses(q)
    pads = R @ finger.pad_axis_tip
    # the pad turns at most sqrt(k) * step [rad] between a configuration and its
    # nearest sample; 1 - cos(x) <= x and the cosine moves by at most that angle
    step = float(np.prod(hi - lo) / n) ** (1.0 / finger.k)
    return frozen(pads), float(min(1.0, np.sqrt(finger.k) * step))


def build_manifold(
    finger: Finger,
    sample: SurfaceSample,
    motion: ObjectMotion,
    times_s: np.ndarray,
    *,
    contact: ContactModel | None = None,
    extend_rad: float = 0.3,
    max_iter: int = 30,
    max_iter_warm: int = 5,
    chunk: int = 5,
    track: StartTracking | None = None,
) -> Manifold:
    """Map the sampled surface into the finger's joint space at every time.

    Args:
        finger: The finger.
        sample: Surface sample (object frame): points and outward normals.
        motion: The object's motion ``T_palm_object(t)``.
        times_s: ``(T,)`` increasing times within the motion [s].
        contact: Contact model (IK tolerance, pad cone); default :class:`ContactModel`.
        extend_rad: How far beyond the limits IK may go to map the manifold [rad].
        max_iter: IK iteration cap at the first time (cold start, with restarts).
        max_iter_warm: IK iteration cap at later times, each warm-started from the
            previous time's iterate; a point still converging continues at the next
            time, so slow points cost no long tails.
        chunk: Number of consecutive times solved in one IK batch (warm-started from
            the last time of the previous chunk).
        track: Map only the entries that the choice of a grasp at the first time reads
            (:class:`StartTracking`); None: every entry.

    Returns:
        The :class:`Manifold` (with ``track``, the entries not mapped are not
        reachable; the others equal the full manifold's).

    Raises:
        InputError: NaN or non-increasing times, times outside the motion.
    """
    contact = contact or ContactModel()
    if not isinstance(finger, Finger):
        raise InputError(
            "finger", f"is a {type(finger).__name__}", "a Finger, e.g. hand.finger('index')"
        )
    times = as_array(times_s, "times_s", (None,))
    if times.size == 0 or np.any(np.diff(times) <= 0):
        raise InputError("times_s", "is empty or not strictly increasing", "increasing times [s]")
    positive(extend_rad, "extend_rad", allow_zero=True)
    T_all = motion.pose(times)
    targets = tip_targets(sample.points, sample.normals, finger.tip_radius, T_all)  # (T,N,3)
    normals_palm = sample.normals @ np.swapaxes(T_all[:, :3, :3], -1, -2)  # (T,N,3)
    lo, hi = finger.lower - extend_rad, finger.upper + extend_rad
    voxels = workspace_voxels(finger, float(extend_rad))
    pads, slack = pad_directions(finger)
    # per time and point: can any pad direction oppose the normal within the cone?
    face_ids = np.unique(sample.face_ids)
    face_normal = {int(f): sample.normals[np.argmax(sample.face_ids == f)] for f in face_ids}

    nt, n, k = times.size, len(sample), finger.k
    q_out = np.zeros((nt, n, k))
    reach = np.zeros((nt, n), bool)
    pad = np.zeros((nt, n), bool)
    tip_clear = np.zeros((nt, n), bool)
    q_prev = np.broadcast_to(finger.q_mid, (n, k)).copy()
    q_out[:] = np.nan
    # per point: target and IK residual at its last failed cold solve (see _retry_failed)
    anchor = targets[0].copy()
    resid = np.zeros(n)
    stays_out = np.zeros(n, bool)  # reached outside the limits, no inside solution found
    # which points are worth solving at each time (vectorized over times and faces)
    n_palm_faces = np.einsum("tij,fj->tfi", T_all[:, :3, :3], np.array(list(face_normal.values())))
    inward = -n_palm_faces.reshape(-1, 3)
    pads_T = np.ascontiguousarray(pads.T)
    # in blocks of 4 normals: each product (4, M) stays in cache, and small enough that
    # BLAS runs it on one thread (starting threads on a loaded machine cost 100 x)
    best_cos = np.concatenate(
        [(b @ pads_T).max(axis=1) for b in np.array_split(inward, -(-len(inward) // 4))]
    ).reshape(n_palm_faces.shape[:2])
    can_face = best_cos + slack >= contact.cos_cone_of(finger)
    face_index = np.searchsorted(np.array(list(face_normal)), sample.face_ids)
    solve = can_face[:, face_index] & voxels.contains(targets)

    # time 0 cold (with restarts); then chunks of `chunk` times, all warm-started from
    # the last solved time (small motions between grid times), in one IK batch each
    starts = [0, *range(1, nt, chunk)]
    stops = [1, *[min(s0 + chunk, nt) for s0 in range(1, nt, chunk)]]
    # with `track`: the points feasible at time 0, and those usable at every time so far
    tracked = np.zeros(n, bool)
    lasting = np.zeros(n, bool)
    k_all = (
        nt - 1
        if track is None
        else max(int(np.searchsorted(times, track.all_until_s + 1e-9, side="right")) - 1, 0)
    )
    for s0, s1 in zip(starts, stops, strict=True):
        if track is not None and s0 > 0:
            solve[s0:s1] &= (tracked if s0 <= k_all else lasting)[None, :]
        # point by point (each point's times in order): the entries of a point share
        # their warm start, so the IK evaluates it once (see solve_position_ik)
        pi, ti = np.nonzero(solve[s0:s1].T)
        if ti.size == 0:
            lasting[:] = False  # nothing reached in this chunk
            continue
        ti = ti + s0
        res = _chunk_solve(
            finger,
            lo,
            hi,
            targets[ti, pi],
            q_prev[pi],
            contact,
            max_iter if s0 == 0 else max_iter_warm,
            first=s0 == 0,
        )
        q_res, ok = res.q, res.success
        if s0 == 0:
            resid[pi[~ok]] = res.error_m[~ok]
            anchor[pi[~ok]] = targets[0, pi[~ok]]
        else:
            _retry_failed(
                finger,
                lo,
                hi,
                targets,
                ti,
                pi,
                q_res,
                ok,
                anchor,
                resid,
                contact,
                2 * max_iter_warm,
            )
        # the extended box admits other IK branches (e.g. a hyperextended one mirroring
        # a flexed one): a solution outside the limits is re-solved in the real box from
        # its reflection about the violated boundary planes, and replaced when that
        # finds a solution inside (once per stay outside: not while the same point's
        # re-solve failed at the previous chunk's last time)
        outside = ok & _outside(q_res, finger.lower, finger.upper)
        out = np.flatnonzero(outside & ~stays_out[pi])
        if out.size:
            q_o = q_res[out]
            q_refl = np.where(q_o < finger.lower, 2 * finger.lower - q_o, q_o)
            q_refl = np.where(q_o > finger.upper, 2 * finger.upper - q_o, q_refl)
            res_in = solve_position_ik(
                finger.chain,
                finger.lower,
                finger.upper,
                targets[ti[out], pi[out]],
                q_refl,
                tol_m=contact.ik_tol_m,
                max_iter=max_iter_warm,
                restarts=False,
            )
            q_res[out[res_in.success]] = res_in.q[res_in.success]
        q_out[ti, pi] = q_res
        reach[ti, pi] = ok
        last = ti == s1 - 1
        q_prev[pi[last]] = q_res[last]
        stays_out[pi[last]] = ok[last] & _outside(q_res[last], finger.lower, finger.upper)
        resid[pi[ok]] = 0.0  # reached: retry at once if it fails later
        if ok.any():
            cos, over = pad_cosines_and_overshoot(finger, q_res[ok], normals_palm[ti[ok], pi[ok]])
            pad[ti[ok], pi[ok]] = cos >= contact.cos_cone_of(finger)
            tip_clear[ti[ok], pi[ok]] = over <= contact.tip_penetration_m
        if track is not None:
            good = reach[s0:s1] & pad[s0:s1]
            m_chunk = _margins(q_out[s0:s1], finger.lower, finger.upper)
            usable = np.asarray((good & (m_chunk >= track.margin_rad)).all(axis=0))
            if s0 == 0:
                tracked = np.asarray(good[0] & (m_chunk[0] >= 0.0))
                lasting = usable
            else:
                lasting &= usable
    if track is not None:
        _forget_untracked(q_out, reach, pad, finger, track, k_all)
    margin = np.where(reach, _margins(q_out, finger.lower, finger.upper), -np.inf)
    inside = reach & (margin >= 0.0)
    log.debug(
        "manifold %s: %d times x %d points, %.1f%% reachable",
        finger.name,
        nt,
        n,
        100 * reach.mean(),
    )
    return Manifold(
        finger=finger.name,
        times_s=times,
        q=q_out,
        reachable=reach,
        inside=inside,
        margin_rad=margin,
        pad_ok=pad & reach,
        lower=finger.lower.copy(),
        upper=finger.upper.copy(),
        T_palm_object=T_all,
        tip_clear=tip_clear & reach,
    )


#: the environment variable that sets :func:`build_manifolds`' default thread count
THREADS_ENV = "REGRASP_PIN_THREADS"


def default_threads() -> int:
    """Threads that :func:`build_manifolds` uses when not told: ``REGRASP_PIN_THREADS``
    if set, else one per core with the numba IK backend and one with numpy.

    Raises:
        InputError: the variable is not a whole number >= 1.
    """
    text = os.environ.get(THREADS_ENV)
    if text is not None and text.strip():
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(THREADS_ENV, f"is {text!r}", "a whole number >= 1")
        return n
    return manifold_threads(1, os.cpu_count() or 1, ik_backend())


def manifold_threads(workers: int, cores: int, backend: str) -> int:
    """Threads per scenario for the manifolds when ``workers`` single-threaded workers
    share ``cores`` cores: with the numba IK backend, whose kernels release the GIL,
    the cores that one scenario per worker leaves idle, shared out; with numpy's
    (threads contend for the GIL), 1."""
    return max(1, cores // max(workers, 1)) if backend == "numba" else 1


def build_manifolds(
    hand: Hand,
    fingers: Sequence[str],
    sample: SurfaceSample,
    motion: ObjectMotion,
    times_s: np.ndarray,
    *,
    contact: ContactModel | None = None,
    track: StartTracking | None = None,
    threads: int | None = None,
) -> dict[str, Manifold]:
    """:func:`build_manifold` for each of ``fingers``, on up to ``threads`` threads.

    Each finger's manifold is its own computation, so the result is the same on any
    number of threads. Threads pay off with the numba IK backend, whose kernels release
    the GIL (about 1.6x on two cores); with numpy's they contend for it (small arrays),
    so ``threads=None`` means: the environment variable ``REGRASP_PIN_THREADS`` if set
    (the scenario suite's local workers set it to the cores their scenarios leave
    idle: :func:`manifold_threads`), else one thread per
    core with numba and one with numpy (at most one per finger either way).

    Args:
        hand: The hand.
        fingers: The fingers to map, in the order of the returned dict.
        sample, motion, times_s, contact, track: As :func:`build_manifold`.
        threads: Most threads (>= 1); None: as above.

    Returns:
        finger name -> :class:`Manifold`.
    """
    names = list(fingers)
    finger_objs = [hand.finger(n) for n in names]  # unknown names fail here, in order
    threads = default_threads() if threads is None else positive_int(threads, "threads")
    workers = max(1, min(threads, len(names)))

    def build(f: Finger) -> Manifold:
        return build_manifold(f, sample, motion, times_s, contact=contact, track=track)

    if workers == 1:
        return {n: build(f) for n, f in zip(names, finger_objs, strict=True)}
    with ThreadPoolExecutor(workers, thread_name_prefix="manifold") as pool:
        return dict(zip(names, pool.map(build, finger_objs), strict=True))


_FIRST_TIME: collections.OrderedDict[bytes, IKResult] = collections.OrderedDict()
_FIRST_TIME_KEEP = 16  # results kept (a hand's fingers, a few objects)
_FIRST_TIME_LOCK = threading.Lock()


def forget_first_times() -> None:
    """Forget the first-time IK solves that :func:`build_manifold` remembers (a
    benchmark that times repeated runs calls it before each)."""
    with _FIRST_TIME_LOCK:
        _FIRST_TIME.clear()


def _chunk_solve(
    finger: Finger,
    lo: np.ndarray,
    hi: np.ndarray,
    targets: np.ndarray,
    q_init: np.ndarray,
    contact: ContactModel,
    max_iter: int,
    *,
    first: bool,
) -> IKResult:
    """A chunk's IK: warm without restarts, or at the first time cold with restarts and
    remembered by its inputs' bytes (a scenario's grasp search and the planner map the
    same surface at the same start pose: the same numbers and IK backend give the same
    result; a remembered result comes back as a copy)."""
    key = _first_time_key(finger, lo, hi, targets, q_init, contact, max_iter) if first else b""
    with _FIRST_TIME_LOCK:
        res = _FIRST_TIME.get(key) if first else None
        if res is not None:
            _FIRST_TIME.move_to_end(key)
    if res is None:
        res = solve_position_ik(
            finger.chain,
            lo,
            hi,
            targets,
            q_init,
            tol_m=contact.ik_tol_m,
            max_iter=max_iter,
            restarts=first,
        )
        if not first:
            return res
        with _FIRST_TIME_LOCK:
            _FIRST_TIME[key] = res
            while len(_FIRST_TIME) > _FIRST_TIME_KEEP:
                _FIRST_TIME.popitem(last=False)
    return IKResult(
        q=res.q.copy(),
        success=res.success.copy(),
        error_m=res.error_m.copy(),
        iterations=res.iterations,
    )


def _first_time_key(
    finger: Finger,
    lo: np.ndarray,
    hi: np.ndarray,
    targets: np.ndarray,
    q_init: np.ndarray,
    contact: ContactModel,
    max_iter: int,
) -> bytes:
    """The digest of everything a first-time solve depends on."""
    digest = hashlib.sha1(ik_backend().encode())
    for a in (*finger.chain.packed(), lo, hi, targets, q_init):
        a = np.ascontiguousarray(a)
        digest.update(str(a.shape).encode())
        digest.update(a.tobytes())
    digest.update(struct.pack("<dq", contact.ik_tol_m, max_iter))
    return digest.digest()


def _margins(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``(...,)`` signed distance [rad] of ``q`` ``(..., k)`` to the nearest boundary
    plane (NaN where ``q`` is NaN): the minimum over the joints column by column, each
    joint's limits as scalars (a reduction over, or a broadcast along, a short last axis
    is slow in numpy; min is exact either way)."""
    m = np.minimum(q[..., 0] - lower[0], upper[0] - q[..., 0])
    for j in range(1, q.shape[-1]):
        qj = q[..., j]
        m = np.minimum(m, np.minimum(qj - lower[j], upper[j] - qj))
    return m


def _outside(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``(n,)`` whether ``q`` ``(n, k)`` is outside the limits, joint by joint."""
    out = np.zeros(q.shape[0], bool)
    for j in range(q.shape[1]):
        out |= (q[:, j] < lower[j]) | (q[:, j] > upper[j])
    return out


def _forget_untracked(
    q: np.ndarray,
    reach: np.ndarray,
    pad: np.ndarray,
    finger: Finger,
    track: StartTracking,
    k_all: int,
) -> None:
    """Report not reachable (in place) the entries that ``track`` does not ask for:
    after time 0, those of points not feasible at time 0, and after time ``k_all``
    those of points not usable with ``track.margin_rad`` at every earlier time (the
    chunks solve some of them past a point's exit; forgetting them makes the entries
    mapped follow from ``track`` alone)."""
    margin = np.where(reach, _margins(q, finger.lower, finger.upper), -np.inf)
    usable = reach & pad & (margin >= track.margin_rad)
    before = np.logical_and.accumulate(usable, axis=0)  # usable at every time <= k
    keep = np.ones_like(reach)
    keep[1:] = (reach[0] & pad[0] & (margin[0] >= 0.0))[None, :]
    keep[k_all + 1 :] &= before[k_all:-1]
    q[~keep] = np.nan
    reach &= keep
    pad &= keep


def _retry_failed(
    finger: Finger,
    lo: np.ndarray,
    hi: np.ndarray,
    targets: np.ndarray,
    ti: np.ndarray,
    pi: np.ndarray,
    q_res: np.ndarray,
    ok: np.ndarray,
    anchor: np.ndarray,
    resid: np.ndarray,
    contact: ContactModel,
    max_iter: int,
) -> None:
    """Retry cold, from the middle of the box, warm-started points that failed.

    A warm start that fails may sit in a local minimum (e.g. on an extended limit) that
    it would not leave as its target comes into reach, or may need more iterations
    than ``max_iter_warm`` after a fast move. A failed point is retried when it was
    reached since its last failed retry (``resid`` 0) or earlier in this chunk, or once its
    target has moved from ``anchor`` (where its last cold retry failed) by at least that
    retry's residual ``resid``: the distance from the target to the reachable set
    changes by no more than the target moves (the residual is that distance when the
    cold solve ended at the nearest reachable point: usual, not guaranteed). Updates
    ``q_res``, ``ok``, ``anchor`` and ``resid`` in place.
    """
    sel = np.flatnonzero(~ok)
    p = pi[sel]
    moved = np.linalg.norm(targets[ti[sel], p] - anchor[p], axis=1)
    first_ok = np.full(targets.shape[1], np.iinfo(np.int64).max)
    np.minimum.at(first_ok, pi[ok], ti[ok])
    keep = (moved >= resid[p] - contact.ik_tol_m) | (first_ok[p] < ti[sel])
    sel, p = sel[keep], p[keep]
    if sel.size == 0:
        return
    res = solve_position_ik(
        finger.chain,
        lo,
        hi,
        targets[ti[sel], p],
        np.broadcast_to(0.5 * (lo + hi), (sel.size, finger.k)),
        tol_m=contact.ik_tol_m,
        max_iter=max_iter,
        restarts=False,
    )
    q_res[sel], ok[sel] = res.q, res.success
    bad = ~res.success  # (ti is ascending: the latest time of a point is written last)
    resid[p[bad]] = res.error_m[bad]
    anchor[p[bad]] = targets[ti[sel[bad]], p[bad]]
