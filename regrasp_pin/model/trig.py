"""Cosine and sine that come out the same bits in numpy, in numba and on any CPU.

The batched IK (:mod:`.ik`) evaluates the fingers' joint cosines and sines millions of
times, in numpy or in numba's compiled loop (:mod:`.ik_numba`). The libraries' own
cos/sin differ in their last bits, and in single precision by about 1e-7: numpy's
vectorized loops differ from the C library that compiled code calls, and numpy picks
its loops by the CPU's instruction sets. The IK's iterates follow those bits, so the
same inputs gave other manifolds on the two backends, and a plan depended on which
one ran.

Here both are computed the way fdlibm does (Sun Microsystems' freely distributable
libm, the reference of most C libraries), from float64 additions and multiplications
in one fixed order, which IEEE 754 rounds the same way everywhere (numba compiles them
without fused multiply-adds):

1. reduction by pi/2 (Cody-Waite): ``k = floor(theta 2/pi + 1/2)``,
   ``r = (theta - k P1) - k P2`` with ``P1`` pi/2's first 33 bits (so that ``k P1`` is
   exact) and ``P2`` the rest; ``|r| <= pi/4`` up to rounding;
2. fdlibm's minimax polynomials of ``sin r`` and ``cos r`` on ``[-pi/4, pi/4]``
   (``__kernel_sin``, ``__kernel_cos`` without its tail correction);
3. the quadrant ``k mod 4`` swaps and negates them (exact).

They agree with the C library's within about 2e-16 for ``|theta| < 1e5`` rad (joint
angles are a few rad). :func:`cos_sin` is the numpy version, :func:`cos_sin_scalar`
the scalar one that numba compiles into the IK's loop; both do the same operations.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cos_sin", "cos_sin_scalar"]

_TWO_OVER_PI = 6.36619772367581382433e-01
_PIO2_HI = 1.57079632673412561417e00  # the first 33 bits of pi/2 (0x3FF921FB54400000)
_PIO2_LO = 6.07710050650619224932e-11  # pi/2 - _PIO2_HI (0x3DD0B4611A626331)
# fdlibm's __kernel_sin: sin r = r + r^3 (S1 + r^2 S2 + ... + r^10 S6)
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
# fdlibm's __kernel_cos: cos r = 1 - r^2 / 2 + r^4 (C1 + r^2 C2 + ... + r^10 C6)
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11


def cos_sin(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``cos(theta)``, ``sin(theta)`` (module docstring), element-wise.

    Args:
        theta: Angles [rad], any shape (``|theta| < 1e5`` for the stated accuracy).

    Returns:
        The cosines and sines, float64 arrays of ``theta``'s shape (NaN where it is).
    """
    x = np.asarray(theta, dtype=np.float64)
    k = np.floor(x * _TWO_OVER_PI + 0.5)
    r = (x - k * _PIO2_HI) - k * _PIO2_LO
    z = r * r
    s = r + (z * r) * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - (0.5 * z - z * (z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))))
    quadrant = k - 4.0 * np.floor(0.25 * k)  # 0, 1, 2 or 3, exactly
    odd = (quadrant == 1.0) | (quadrant == 3.0)
    cos = np.where(odd, s, c)
    sin = np.where(odd, c, s)
    cos = np.where((quadrant == 1.0) | (quadrant == 2.0), -cos, cos)
    sin = np.where(quadrant >= 2.0, -sin, sin)
    return cos, sin


def cos_sin_scalar(theta: float) -> tuple[float, float]:
    """:func:`cos_sin` of one angle [rad], by the same operations (plain Python that
    numba compiles; :mod:`.ik_numba` calls it in its loop)."""
    k = np.floor(theta * _TWO_OVER_PI + 0.5)
    r = (theta - k * _PIO2_HI) - k * _PIO2_LO
    z = r * r
    s = r + (z * r) * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - (0.5 * z - z * (z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))))
    quadrant = k - 4.0 * np.floor(0.25 * k)
    if quadrant == 1.0:
        return -s, c
    if quadrant == 2.0:
        return -c, -s
    if quadrant == 3.0:
        return s, -c
    return c, s
