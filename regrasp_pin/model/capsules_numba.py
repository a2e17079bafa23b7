"""The capsule bounds' pair loop, compiled with numba (an optional accelerator).

:func:`~regrasp_pin.model.distances.capsule_gaps` tests every (geometry a, geometry b,
row) by the capsules' bounding spheres and measures the kept pairs' segments in numpy
batches. :func:`gaps_python` does the same one pair at a time, with the same operations
in the same order (no fused multiply-adds: numba's default), so that its numbers are
the numpy path's to the bit; numba compiles it to a loop without temporaries. It runs
when the IK backend is numba (:func:`~regrasp_pin.model.ik.set_ik_backend`), which
already compiles with numba; numpy remains the reference and the tests compare both,
bit for bit. The function is plain Python too, which lets the tests run it uncompiled.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .numba_jit import compile_together

__all__ = ["available", "gaps", "gaps_python"]

_compiled: Callable[..., Any] | None = None
_failed = False
_EPS = 1e-18  # squared segment lengths at or below this are points [m^2]


def _clip01(x):
    """``x`` clipped to ``[0, 1]`` (as ``np.clip``)."""
    return min(max(x, 0.0), 1.0)


def _segment_distance(a1, b1, a2, b2, n, i, nb, j):
    """Distance between segment ``i`` of ``(a1, b1)`` at row ``n`` and segment ``j`` of
    ``(a2, b2)`` at row ``nb``: the operations of
    :func:`~regrasp_pin.model.distances._segment_distance_soa`, one pair."""
    d10 = b1[0, i, n] - a1[0, i, n]
    d11 = b1[1, i, n] - a1[1, i, n]
    d12 = b1[2, i, n] - a1[2, i, n]
    d20 = b2[0, j, nb] - a2[0, j, nb]
    d21 = b2[1, j, nb] - a2[1, j, nb]
    d22 = b2[2, j, nb] - a2[2, j, nb]
    r0 = a1[0, i, n] - a2[0, j, nb]
    r1 = a1[1, i, n] - a2[1, j, nb]
    r2 = a1[2, i, n] - a2[2, j, nb]
    a = d10 * d10 + d11 * d11 + d12 * d12
    e = d20 * d20 + d21 * d21 + d22 * d22
    b = d10 * d20 + d11 * d21 + d12 * d22
    c = d10 * r0 + d11 * r1 + d12 * r2
    f = d20 * r0 + d21 * r1 + d22 * r2
    a_ok, e_ok = a > _EPS, e > _EPS
    a_safe = a if a_ok else 1.0
    e_safe = e if e_ok else 1.0
    denom = a * e - b * b
    s = _clip01((b * f - c * e) / denom) if denom > _EPS else 0.0
    if not a_ok:
        s = 0.0
    t = (b * s + f) / e_safe if e_ok else 0.0
    redo = t < 0.0 or t > 1.0 or not e_ok
    t = _clip01(t)
    if redo:
        s = _clip01((t * b - c) / a_safe) if a_ok else 0.0
    x0 = r0 + s * d10 - t * d20
    x1 = r1 + s * d11 - t * d21
    x2 = r2 + s * d12 - t * d22
    return math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)


def gaps_python(a1, b1, a2, b2, rows_b, rad_a, rad_b, reach_a, reach_b, group_of, gap, cap):
    """Fill ``gap`` ``(G, N)`` (inf on entry) with the smallest capsule bound of each row
    ``n`` against each group: segments ``(a1, b1)`` ``(3, A, N)`` of the first
    geometries, ``(a2, b2)`` ``(3, B, M)`` of the second ones at row ``rows_b[n]``,
    radii ``rad_*``, bounding-sphere reaches ``reach_*``, group of each second geometry
    ``group_of`` ``(B,)``; a pair whose bounding spheres are ``cap`` [m] (less 1 nm)
    apart is not measured. The caller caps the result."""
    n_a, n_rows = a1.shape[1], a1.shape[2]
    n_b = a2.shape[1]
    limit = cap + 1e-9
    for n in range(n_rows):
        nb = rows_b[n]
        for i in range(n_a):
            m0 = 0.5 * (a1[0, i, n] + b1[0, i, n])
            m1 = 0.5 * (a1[1, i, n] + b1[1, i, n])
            m2 = 0.5 * (a1[2, i, n] + b1[2, i, n])
            for j in range(n_b):
                x0 = m0 - 0.5 * (a2[0, j, nb] + b2[0, j, nb])
                x1 = m1 - 0.5 * (a2[1, j, nb] + b2[1, j, nb])
                x2 = m2 - 0.5 * (a2[2, j, nb] + b2[2, j, nb])
                far = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
                if not far - reach_a[i] - reach_b[j] < limit:
                    continue
                d = _segment_distance(a1, b1, a2, b2, n, i, nb, j) - rad_a[i] - rad_b[j]
                g = group_of[j]
                if d < gap[g, n]:
                    gap[g, n] = d


def _compile() -> Callable[..., Any] | None:
    """The compiled :func:`gaps_python` (cached on disk), or None without numba."""
    global _compiled, _failed
    if _compiled is None and not _failed:
        compiled = compile_together((_clip01, _segment_distance), (gaps_python,))
        if compiled is None:
            _failed = True
            return None
        _compiled = compiled["gaps_python"]
    return _compiled


def available() -> bool:
    """True when numba is installed (the compiled loop can be used)."""
    return _compile() is not None


def gaps(a1, b1, a2, b2, rows_b, rad_a, rad_b, reach_a, reach_b, group_of, gap, cap):
    """The compiled :func:`gaps_python` (same arguments; fills ``gap``).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    kernel = _compile()
    if kernel is None:
        raise ImportError("the compiled capsule loop needs numba: pip install regrasp-pin[fast]")
    f64 = [np.ascontiguousarray(x, dtype=np.float64) for x in (a1, b1, a2, b2)]
    kernel(
        *f64,
        np.ascontiguousarray(rows_b, dtype=np.int64),
        *(np.ascontiguousarray(x, dtype=np.float64) for x in (rad_a, rad_b, reach_a, reach_b)),
        np.ascontiguousarray(group_of, dtype=np.int64),
        gap,
        float(cap),
    )
