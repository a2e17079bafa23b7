"""The verification's broad phase, compiled with numba (an optional accelerator).

:class:`~regrasp_pin.model.distances.PairDistances` bounds the signed distance of every
(dense sample, geometry pair) check of a finger motion from below, in numpy batches:
the face-plane support bound against the object, and between two geometries their
bounding spheres, then, where those come near, the capsule bound and the separating-axis
bound. On the thousand samples and eighty pairs of one check, those batches cost more
in temporaries than in arithmetic. :func:`bounds_python` computes the same bounds one
(sample, column) at a time, with the same formulas; numba compiles it to a loop without
temporaries. It runs when the IK backend is numba
(:func:`~regrasp_pin.model.ik.set_ik_backend`), which already compiles with numba; numpy
remains the reference and the tests compare both.

The numbers agree with numpy's to rounding, not to the bit: numpy's matrix products of
the object frame go through BLAS, whose kernels differ between machines. No decision
reads those last bits: a bound decides which samples Coal measures (one below its
requirement is measured, or cleared by the sweep bound from measured ones; a failing
distance is always measured), so the pass/fail decisions and the failures are the same.
What may differ in the last bits: how many queries were made, the minima of the
planner's check (``exact_minima=False``, read partly from bounds; nothing decides on
them), and the value of a failure where Coal's EPA fails and the bound stands in.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .numba_jit import compile_together

__all__ = [
    "available",
    "bounds",
    "bounds_python",
    "interpolate",
    "interpolate_python",
    "object_bounds",
    "object_bounds_python",
    "sweep",
    "sweep_python",
    "wanted",
]

_compiled: dict[str, Callable[..., Any]] | None = None
_failed = False
_EPS = 1e-18  # squared segment lengths at or below this are points [m^2]


def _clip01(x):
    """``x`` clipped to ``[0, 1]`` (as ``np.clip``)."""
    return min(max(x, 0.0), 1.0)


def _place(R, p, local, r, g, out):
    """``out = R[r, g] @ local[g] + p[r, g]``, column by column (as
    :func:`~regrasp_pin.model.distances._place`)."""
    for i in range(3):
        out[i] = R[r, g, i, 0] * local[g, 0]
        out[i] = out[i] + R[r, g, i, 1] * local[g, 1]
        out[i] = out[i] + R[r, g, i, 2] * local[g, 2]
        out[i] = out[i] + p[r, g, i]


def _support(u0, u1, u2, params, g):
    """The support function of geometry ``g`` in the unit direction ``u`` (its frame),
    as :func:`~regrasp_pin.model.support.support`."""
    uz = abs(u2)
    h = params[g, 0] * abs(u0) + params[g, 1] * abs(u1) + params[g, 2] * uz
    h = h + params[g, 3] * uz
    h = h + params[g, 4] * math.sqrt(max(0.0, 1.0 - uz * uz))
    return h + params[g, 5]


def _object_bound(R, T, c, params, normals, offsets, r, g, Rog):
    """The face-plane support bound of geometry ``g`` at sample ``r`` against the object
    (:func:`~regrasp_pin.model.distances._object_lower_bound`): ``max_f (n_f . c - o_f -
    h(R^T n_f))``, ``c`` and ``R`` in the object frame; ``Rog`` a scratch ``(3, 3)``."""
    c0 = c[r, g, 0] - T[r, 0, 3]
    c1 = c[r, g, 1] - T[r, 1, 3]
    c2 = c[r, g, 2] - T[r, 2, 3]
    # the centre and the orientation in the object frame: T^T (c - t), T^T R
    co0 = c0 * T[r, 0, 0] + c1 * T[r, 1, 0] + c2 * T[r, 2, 0]
    co1 = c0 * T[r, 0, 1] + c1 * T[r, 1, 1] + c2 * T[r, 2, 1]
    co2 = c0 * T[r, 0, 2] + c1 * T[r, 1, 2] + c2 * T[r, 2, 2]
    for i in range(3):
        for col in range(3):
            Rog[i, col] = (
                T[r, 0, i] * R[r, g, 0, col]
                + T[r, 1, i] * R[r, g, 1, col]
                + T[r, 2, i] * R[r, g, 2, col]
            )
    best = -math.inf
    for f in range(normals.shape[0]):
        n0, n1, n2 = normals[f, 0], normals[f, 1], normals[f, 2]
        u0 = n0 * Rog[0, 0] + n1 * Rog[1, 0] + n2 * Rog[2, 0]
        u1 = n0 * Rog[0, 1] + n1 * Rog[1, 1] + n2 * Rog[2, 1]
        u2 = n0 * Rog[0, 2] + n1 * Rog[1, 2] + n2 * Rog[2, 2]
        v = co0 * n0 + co1 * n1 + co2 * n2 - offsets[f] - _support(u0, u1, u2, params, g)
        if v > best:
            best = v
    return best


def _near_pair_bound(R, p, c, a_loc, b_loc, params, rad, r, g1, g2, w):
    """The capsule bound and the separating-axis bound along the capsules' nearest-point
    direction, the larger, of geometries ``g1`` and ``g2`` at sample ``r``
    (:meth:`~regrasp_pin.model.distances.PairDistances._near_pair_bounds`); ``w`` a
    scratch array ``(4, 3)``."""
    a1, b1, a2, b2 = w[0], w[1], w[2], w[3]
    _place(R, p, a_loc, r, g1, a1)
    _place(R, p, b_loc, r, g1, b1)
    _place(R, p, a_loc, r, g2, a2)
    _place(R, p, b_loc, r, g2, b2)
    # Ericson 5.1.9, as distances._segment_distance_soa
    d10, d11, d12 = b1[0] - a1[0], b1[1] - a1[1], b1[2] - a1[2]
    d20, d21, d22 = b2[0] - a2[0], b2[1] - a2[1], b2[2] - a2[2]
    r0, r1, r2 = a1[0] - a2[0], a1[1] - a2[1], a1[2] - a2[2]
    a = d10 * d10 + d11 * d11 + d12 * d12
    e = d20 * d20 + d21 * d21 + d22 * d22
    b = d10 * d20 + d11 * d21 + d12 * d22
    cc = d10 * r0 + d11 * r1 + d12 * r2
    f = d20 * r0 + d21 * r1 + d22 * r2
    a_ok, e_ok = a > _EPS, e > _EPS
    a_safe = a if a_ok else 1.0
    e_safe = e if e_ok else 1.0
    denom = a * e - b * b
    s = _clip01((b * f - cc * e) / denom) if denom > _EPS else 0.0
    if not a_ok:
        s = 0.0
    t = (b * s + f) / e_safe if e_ok else 0.0
    redo = t < 0.0 or t > 1.0 or not e_ok
    t = _clip01(t)
    if redo:
        s = _clip01((t * b - cc) / a_safe) if a_ok else 0.0
    x0 = r0 + s * d10 - t * d20
    x1 = r1 + s * d11 - t * d21
    x2 = r2 + s * d12 - t * d22
    seg = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    lb = seg - rad[g1] - rad[g2]
    if not seg > 1e-12:
        return lb
    u0, u1, u2 = x0 / seg, x1 / seg, x2 / seg  # from geometry 2 towards 1
    gap = (
        u0 * (c[r, g1, 0] - c[r, g2, 0])
        + u1 * (c[r, g1, 1] - c[r, g2, 1])
        + u2 * (c[r, g1, 2] - c[r, g2, 2])
    )
    for g in (g1, g2):  # R^T u in each geometry's frame
        v0 = u0 * R[r, g, 0, 0] + u1 * R[r, g, 1, 0] + u2 * R[r, g, 2, 0]
        v1 = u0 * R[r, g, 0, 1] + u1 * R[r, g, 1, 1] + u2 * R[r, g, 2, 1]
        v2 = u0 * R[r, g, 0, 2] + u1 * R[r, g, 1, 2] + u2 * R[r, g, 2, 2]
        gap = gap - _support(v0, v1, v2, params, g)
    return max(lb, gap)


def bounds_python(
    R, p, T, c, a_loc, b_loc, mid_loc, params, rad, reach, normals, offsets, first, second,
    near_m, rows, cols, out,
):  # fmt: skip
    """Fill ``out`` ``(K,)`` with the lower bound of each (sample ``rows[k]``, column
    ``cols[k]``) of :class:`~regrasp_pin.model.distances.PairDistances`: geometry
    placements ``R`` ``(D, G, 3, 3)``, ``p`` ``(D, G, 3)`` and centres ``c`` ``(D, G,
    3)`` (palm frame), object poses ``T`` ``(D, 4, 4)``; per geometry its capsule
    segment's ends ``a_loc``, ``b_loc`` and middle ``mid_loc`` ``(G, 3)``, support
    parameters ``(G, 6)``, capsule radius and bounding-sphere reach ``(G,)``; the
    object's face planes ``normals`` ``(F, 3)``, ``offsets`` ``(F,)``; per column its
    geometries ``first``, ``second`` (-1: the object); pairs whose bounding spheres are
    ``near_m`` apart or less get the capsule and separating-axis bounds."""
    w = np.empty((4, 3))
    mid = np.empty((2, 3))
    Rog = np.empty((3, 3))
    for k in range(rows.shape[0]):
        r, col = rows[k], cols[k]
        g1, g2 = first[col], second[col]
        if g2 < 0:
            out[k] = _object_bound(R, T, c, params, normals, offsets, r, g1, Rog)
            continue
        _place(R, p, mid_loc, r, g1, mid[0])
        _place(R, p, mid_loc, r, g2, mid[1])
        x0 = mid[0, 0] - mid[1, 0]
        x1 = mid[0, 1] - mid[1, 1]
        x2 = mid[0, 2] - mid[1, 2]
        lb = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2) - reach[g1] - reach[g2]
        if lb < near_m:
            lb = _near_pair_bound(R, p, c, a_loc, b_loc, params, rad, r, g1, g2, w)
        out[k] = lb


def object_bounds_python(R, T, c, params, normals, offsets, out):
    """Fill ``out`` ``(N, G)`` with the face-plane support bound of every geometry at
    every sample against the object (:func:`~regrasp_pin.model.distances.
    object_gap_bounds`'s, before the minimum over a group): placements ``R`` ``(N, G, 3,
    3)`` and centres ``c`` ``(N, G, 3)`` (palm frame), object poses ``T`` ``(N, 4, 4)``,
    support parameters ``(G, 6)``, the object's face planes ``normals`` ``(F, 3)``,
    ``offsets`` ``(F,)``."""
    Rog = np.empty((3, 3))
    for r in range(out.shape[0]):
        for g in range(out.shape[1]):
            out[r, g] = _object_bound(R, T, c, params, normals, offsets, r, g, Rog)


def _body_step(c1, c0, R1, R0, rho):
    """How far any point within ``rho`` of a body's centre moves between two samples,
    ``|dc| + rho |dR|_F / sqrt(2)`` (as :func:`~regrasp_pin.model.distances._step_bound`,
    its sums in the same order)."""
    d0, d1, d2 = c1[0] - c0[0], c1[1] - c0[1], c1[2] - c0[2]
    dc = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    f = 0.0
    for i in range(3):
        for j in range(3):
            d = R1[i, j] - R0[i, j]
            f = f + d * d
    return dc + rho * math.sqrt(f / 2.0)


def sweep_python(c, R, T, rho, obj_radius, first, second, S):
    """Fill ``S`` ``(D, P)`` with the sweep parameter of each column (the cumulative sum
    of its two bodies' per-step bounds, 0 at the first sample) and return the largest
    step, as :meth:`~regrasp_pin.model.distances.PairDistances._sweep_steps` does:
    geometry centres ``c`` ``(D, G, 3)`` and orientations ``R`` ``(D, G, 3, 3)``, their
    reaches ``rho`` ``(G,)`` [m], object poses ``T`` ``(D, 4, 4)`` and its radius, the
    columns' geometries ``first``, ``second`` ``(P,)`` (-1: the object)."""
    n_d, n_g = c.shape[0], c.shape[1]
    n_p = first.shape[0]
    step_g = np.empty(n_g)
    most = 0.0
    for col in range(n_p):
        S[0, col] = 0.0
    for k in range(n_d - 1):
        for g in range(n_g):
            step_g[g] = _body_step(c[k + 1, g], c[k, g], R[k + 1, g], R[k, g], rho[g])
        step_o = _body_step(
            T[k + 1, :3, 3], T[k, :3, 3], T[k + 1, :3, :3], T[k, :3, :3], obj_radius
        )
        for col in range(n_p):
            other = step_o if second[col] < 0 else step_g[second[col]]
            step = step_g[first[col]] + other
            if step > most:
                most = step
            S[k + 1, col] = S[k, col] + step
    return most


def interpolate_python(lb_c, coarse, S, out):
    """Fill ``out`` ``(D, P)`` with the bounds between the coarse samples ``coarse``
    ``(C,)`` (increasing, the first and last sample among them) from theirs, ``lb_c``
    ``(C, P)``: the better of the two neighbours' bounds less the sweep ``S`` ``(D, P)``
    to them, less 1e-12 for its rounding; a coarse sample's own bound as it is (as
    :meth:`~regrasp_pin.model.distances.PairDistances._bounds_coarse_to_fine`)."""
    n_d, n_p = S.shape
    hi = 0
    for s in range(n_d):
        while coarse[hi] < s:
            hi += 1
        if coarse[hi] == s:
            for col in range(n_p):
                out[s, col] = lb_c[hi, col]
            continue
        lo = hi - 1
        a, b = coarse[lo], coarse[hi]
        for col in range(n_p):
            from_lo = lb_c[lo, col] - (S[s, col] - S[a, col])
            from_hi = lb_c[hi, col] - (S[b, col] - S[s, col])
            out[s, col] = max(from_lo, from_hi) - 1e-12


def _compile() -> dict[str, Callable[..., Any]] | None:
    """The compiled kernels (cached on disk) by name, or None without numba."""
    global _compiled, _failed
    if _compiled is None and not _failed:
        compiled = compile_together(
            (_clip01, _place, _support, _object_bound, _near_pair_bound, _body_step),
            (bounds_python, sweep_python, interpolate_python, object_bounds_python),
        )
        if compiled is None:
            _failed = True
            return None
        _compiled = compiled
    return _compiled


def _kernel(name: str) -> Callable[..., Any]:
    """The compiled kernel ``name``.

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    kernels = _compile()
    if kernels is None:
        raise ImportError("the compiled broad phase needs numba: pip install regrasp-pin[fast]")
    return kernels[name]


def available() -> bool:
    """True when numba is installed (the compiled loop can be used)."""
    return _compile() is not None


def wanted(backend: str) -> bool:
    """Whether to bound by the compiled loop on the IK backend ``backend``
    (:func:`~regrasp_pin.model.ik.ik_backend`): on ``"numba"`` when it compiles."""
    return backend == "numba" and available()


def bounds(*args: Any) -> None:
    """The compiled :func:`bounds_python` (same arguments; fills ``out``).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    _kernel("bounds_python")(*args)


def sweep(*args: Any) -> float:
    """The compiled :func:`sweep_python` (same arguments; fills ``S``, returns the
    largest step [m]).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    return float(_kernel("sweep_python")(*args))


def interpolate(*args: Any) -> None:
    """The compiled :func:`interpolate_python` (same arguments; fills ``out``).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    _kernel("interpolate_python")(*args)


def object_bounds(*args: Any) -> None:
    """The compiled :func:`object_bounds_python` (same arguments; fills ``out``).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    _kernel("object_bounds_python")(*args)
