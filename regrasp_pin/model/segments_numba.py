"""The nearest points of two segments, one pair at a time: the scalar helper of the
compiled loops (:mod:`.capsules_numba`, :mod:`.bounds_numba`).

:func:`segment_offset` makes the operations of
:func:`~regrasp_pin.model.distances._segment_distance_soa` in the same order (Ericson,
*Real-Time Collision Detection*, 5.1.9), so that a loop calling it gives numpy's numbers
to the bit. It is plain Python: a kernel module imports these names, and
:func:`~regrasp_pin.model.numba_jit.compile_together` compiles them inlined into its
kernels (``EPS`` a compile-time constant).
"""

from __future__ import annotations

__all__ = ["EPS", "clip01", "segment_offset"]

EPS = 1e-18  # squared segment lengths at or below this are points [m^2]


def clip01(x):
    """``x`` clipped to ``[0, 1]`` (as ``np.clip``)."""
    return min(max(x, 0.0), 1.0)


def segment_offset(d10, d11, d12, d20, d21, d22, r0, r1, r2):
    """The vector from the nearest point of segment 2 to that of segment 1 [m].

    Segment 1 runs from ``a1`` along ``d1 = b1 - a1``, segment 2 from ``a2`` along
    ``d2 = b2 - a2``, and ``r = a1 - a2``; its norm is the segments' distance.
    """
    a = d10 * d10 + d11 * d11 + d12 * d12
    e = d20 * d20 + d21 * d21 + d22 * d22
    b = d10 * d20 + d11 * d21 + d12 * d22
    c = d10 * r0 + d11 * r1 + d12 * r2
    f = d20 * r0 + d21 * r1 + d22 * r2
    a_ok, e_ok = a > EPS, e > EPS
    a_safe = a if a_ok else 1.0
    e_safe = e if e_ok else 1.0
    denom = a * e - b * b
    s = clip01((b * f - c * e) / denom) if denom > EPS else 0.0
    if not a_ok:
        s = 0.0
    t = (b * s + f) / e_safe if e_ok else 0.0
    redo = t < 0.0 or t > 1.0 or not e_ok
    t = clip01(t)
    if redo:
        s = clip01((t * b - c) / a_safe) if a_ok else 0.0
    return r0 + s * d10 - t * d20, r1 + s * d11 - t * d21, r2 + s * d12 - t * d22
