"""The pad cosines and the fingertip link's overshoot, compiled with numba (an optional
accelerator).

:func:`~regrasp_pin.grasp.contact.pad_cosines_and_overshoot` judges every entry of a
finger's manifold and every step of a tracked hold: how far the pad turns from the
inward normal, and how far the fingertip link's geometries reach past the plane the tip
sphere rests on (:meth:`~regrasp_pin.model.tip_reach.TipReach.overshoot`). In numpy
that is a dozen temporaries per batch. :func:`pad_overshoot_python` computes both per
configuration with the same operations in the same written order as the numpy path
(no ``einsum`` or matrix product, whose order numpy picks by the CPU; no fused
multiply-adds), so the two give the same bits on any CPU. It runs when the IK backend
is numba; numpy remains the reference and the tests compare both, bit for bit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from .numba_jit import compile_together

__all__ = ["available", "pad_overshoot", "pad_overshoot_python", "wanted"]

_compiled: Callable[..., Any] | None = None
_failed = False


def pad_overshoot_python(
    R, normals, pad_axis, centres, rotations, params, radius, cos_out, over_out
):  # fmt: skip
    """Fill ``cos_out`` ``(N,)`` with the cosine between each pad and the inward normal,
    and ``over_out`` ``(N,)`` with how far the fingertip link's geometries reach past
    the tip sphere's tangent plane [m] (``-inf`` without geometries): tip rotations
    ``R`` ``(N, 3, 3)`` and outward normals ``normals`` ``(N, 3)`` in the palm frame,
    the pad axis ``(3,)`` in the tip frame, the geometries' centres ``(G, 3)``,
    rotations ``(G, 3, 3)`` and support parameters ``(G, 6)`` in the tip frame, the tip
    radius [m]."""
    n_geoms = centres.shape[0]
    for k in range(R.shape[0]):
        n0, n1, n2 = normals[k, 0], normals[k, 1], normals[k, 2]
        p0 = R[k, 0, 0] * pad_axis[0] + R[k, 0, 1] * pad_axis[1] + R[k, 0, 2] * pad_axis[2]
        p1 = R[k, 1, 0] * pad_axis[0] + R[k, 1, 1] * pad_axis[1] + R[k, 1, 2] * pad_axis[2]
        p2 = R[k, 2, 0] * pad_axis[0] + R[k, 2, 1] * pad_axis[1] + R[k, 2, 2] * pad_axis[2]
        cos_out[k] = -(p0 * n0 + p1 * n1 + p2 * n2)
        if n_geoms == 0:
            over_out[k] = -math.inf
            continue
        # R^T (-n): into the object, in the tip frame
        u0 = -(R[k, 0, 0] * n0 + R[k, 1, 0] * n1 + R[k, 2, 0] * n2)
        u1 = -(R[k, 0, 1] * n0 + R[k, 1, 1] * n1 + R[k, 2, 1] * n2)
        u2 = -(R[k, 0, 2] * n0 + R[k, 1, 2] * n1 + R[k, 2, 2] * n2)
        best = -math.inf
        for g in range(n_geoms):
            l0 = u0 * rotations[g, 0, 0] + u1 * rotations[g, 1, 0] + u2 * rotations[g, 2, 0]
            l1 = u0 * rotations[g, 0, 1] + u1 * rotations[g, 1, 1] + u2 * rotations[g, 2, 1]
            l2 = u0 * rotations[g, 0, 2] + u1 * rotations[g, 1, 2] + u2 * rotations[g, 2, 2]
            uz = abs(l2)
            h = params[g, 0] * abs(l0) + params[g, 1] * abs(l1) + params[g, 2] * uz
            h = h + params[g, 3] * uz
            h = h + params[g, 4] * math.sqrt(max(0.0, 1.0 - uz * uz))
            h = h + params[g, 5]
            reach = (u0 * centres[g, 0] + u1 * centres[g, 1] + u2 * centres[g, 2]) + h
            if g == 0 or reach > best:
                best = reach
        over_out[k] = best - radius


def _compile() -> Callable[..., Any] | None:
    """The compiled :func:`pad_overshoot_python` (cached on disk), or None without
    numba."""
    global _compiled, _failed
    if _compiled is None and not _failed:
        compiled = compile_together((), (pad_overshoot_python,))
        if compiled is None:
            _failed = True
            return None
        _compiled = compiled["pad_overshoot_python"]
    return _compiled


def available() -> bool:
    """True when numba is installed (the compiled loop can be used)."""
    return _compile() is not None


def wanted(backend: str) -> bool:
    """Whether to use the compiled loop on the IK backend ``backend``
    (:func:`~regrasp_pin.model.ik.ik_backend`): on ``"numba"`` when it compiles."""
    return backend == "numba" and available()


def pad_overshoot(*args: Any) -> None:
    """The compiled :func:`pad_overshoot_python` (same arguments; fills the outputs).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    kernel = _compile()
    if kernel is None:
        raise ImportError("the compiled pad cosines need numba: pip install regrasp-pin[fast]")
    kernel(*args)
