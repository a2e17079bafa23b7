"""The batched IK's iteration loop, compiled with numba (an optional accelerator).

The same damped-least-squares iteration as :mod:`regrasp_pin.model.ik` (the same
damping rule, active set at the limits, step cap, clipping, stop and stall tests, and
cos/sin: :func:`~.trig.cos_sin_scalar`), written one point at a time so that numba
compiles it to a loop without temporaries, with every float64 operation of numpy's
in numpy's order. numpy remains the reference: the numpy path is kept and the tests
check that both give the same joint coordinates, residuals and flags, bit for bit.
numba is imported only when the kernel is first needed
(``pip install regrasp-pin[fast]``); without it :func:`available` is False and
:mod:`.ik` uses numpy.

The functions below are plain Python too (numba compiles them unchanged), which lets the
tests run the same code uncompiled on a few points.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .numba_jit import compile_together
from .trig import cos_sin_scalar

__all__ = ["available", "iterate", "iterate_python"]

_compiled: Callable[..., Any] | None = None
_failed = False


def _fk_jacobian(chain, q, n, work):
    """Tip position of point ``n`` into ``o`` and its Jacobian into ``J`` (3, k).

    Mirrors :meth:`FingerChain.forward_soa`: ``W' <- W' C_j Rz(theta_j)`` and
    ``o <- o + W' t_j`` per joint, ``J[:, col_j] += s_j z_j x (p - o_j)``.
    ``work`` is ``(W, o, axes, origins, J)``, scratch arrays that receive the results.
    """
    C, t, column, scaling, offset, tip_t = chain
    W, o, axes, origins, J = work
    for jt in range(C.shape[0]):
        for i in range(3):
            if jt == 0:  # W' = I before the first joint: o = t, W' = C exactly
                o[i] = t[0, i]
                for j in range(3):
                    W[i, j] = C[0, i, j]
                continue
            o[i] = o[i] + (W[i, 0] * t[jt, 0] + W[i, 1] * t[jt, 1] + W[i, 2] * t[jt, 2])
            w0, w1, w2 = W[i, 0], W[i, 1], W[i, 2]
            for j in range(3):
                W[i, j] = w0 * C[jt, 0, j] + w1 * C[jt, 1, j] + w2 * C[jt, 2, j]
        theta = q[column[jt], n]
        if scaling[jt] != 1.0:
            theta = theta * scaling[jt]
        if offset[jt] != 0.0:
            theta = theta + offset[jt]
        c, s = cos_sin_scalar(theta)
        for i in range(3):
            m0 = W[i, 0]
            m1 = W[i, 1]
            W[i, 0] = c * m0 + s * m1
            W[i, 1] = c * m1 - s * m0
            axes[jt, i] = W[i, 2]
            origins[jt, i] = o[i]
    for i in range(3):
        o[i] = o[i] + (W[i, 0] * tip_t[0] + W[i, 1] * tip_t[1] + W[i, 2] * tip_t[2])
    _jacobian(chain, work)


def _jacobian(chain, work):
    """``J[:, col_j] += s_j z_j x (p - o_j)`` from the axes and origins of :func:`_fk_jacobian`."""
    C, t, column, scaling, offset, tip_t = chain
    W, o, axes, origins, J = work
    for i in range(3):
        for c in range(J.shape[1]):
            J[i, c] = 0.0
    for jt in range(C.shape[0]):
        r0 = o[0] - origins[jt, 0]
        r1 = o[1] - origins[jt, 1]
        r2 = o[2] - origins[jt, 2]
        z0, z1, z2 = axes[jt, 0], axes[jt, 1], axes[jt, 2]
        f = scaling[jt]
        col = column[jt]
        J[0, col] += f * (z1 * r2 - z2 * r1)
        J[1, col] += f * (z2 * r0 - z0 * r2)
        J[2, col] += f * (z0 * r1 - z1 * r0)


def _dls_step(J, free, e0, e1, e2, err_sq, lam0_sq, lam_err, dq):
    """``dq = J^T (J J^T + lambda^2 I)^-1 e`` over the ``free`` columns (others 0)."""
    k = J.shape[1]
    a00 = a11 = a22 = a01 = a02 = a12 = 0.0
    for c in range(k):
        if free[c]:
            a00 += J[0, c] * J[0, c]
            a11 += J[1, c] * J[1, c]
            a22 += J[2, c] * J[2, c]
            a01 += J[0, c] * J[1, c]
            a02 += J[0, c] * J[2, c]
            a12 += J[1, c] * J[2, c]
    lam = lam0_sq + lam_err * err_sq
    a00 += lam
    a11 += lam
    a22 += lam
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    x0 = (c00 * e0 + c01 * e1 + c02 * e2) / det
    x1 = (c01 * e0 + c11 * e1 + c12 * e2) / det
    x2 = (c02 * e0 + c12 * e1 + c22 * e2) / det
    for c in range(k):
        dq[c] = J[0, c] * x0 + J[1, c] * x1 + J[2, c] * x2 if free[c] else 0.0


def iterate_python(chain_arrays, lower, upper, targets, q, tol_m, max_iter, consts):
    """DLS iterations on component-major ``targets`` (3, n) and ``q`` (k, n), in place.

    Args:
        chain_arrays: :meth:`FingerChain.packed` ``(C, t, column, scaling, offset, tip_t)``.
        lower, upper: ``(k,)`` joint limits [rad].
        targets: ``(3, n)`` tip targets (palm frame) [m].
        q: ``(k, n)`` initial configurations [rad]; overwritten with the results.
        tol_m: Stop tolerance [m].
        max_iter: Iteration cap per point.
        consts: ``(lambda0^2, lambda_err, max_step, stall_sq, stall_tol_factor)``.

    Returns:
        ``(err, iterations)``: the ``(n,)`` residuals [m] at the returned ``q`` (computed
        with the iteration's trig) and the largest number of steps any point took.
    """
    lam0_sq, lam_err, max_step, stall_sq, stall_factor = consts
    k, n = q.shape
    nj = chain_arrays[0].shape[0]
    o = np.empty(3)
    J = np.empty((3, k))
    work = (np.empty((3, 3)), o, np.empty((nj, 3)), np.empty((nj, 3)), J)
    dq = np.empty(k)
    free = np.empty(k, dtype=np.bool_)
    err = np.empty(n)
    tol_sq = tol_m * tol_m
    near_sq = (stall_factor * tol_m) ** 2
    most = 0
    for p in range(n):
        prev_sq = np.inf
        steps = 0
        while True:
            _fk_jacobian(chain_arrays, q, p, work)
            e0 = targets[0, p] - o[0]
            e1 = targets[1, p] - o[1]
            e2 = targets[2, p] - o[2]
            err_sq = e0 * e0 + e1 * e1 + e2 * e2
            err[p] = math.sqrt(err_sq)
            if err_sq <= tol_sq or not (err_sq < stall_sq * prev_sq or err_sq < near_sq):
                break
            prev_sq = err_sq
            if steps == max_iter:
                break
            steps += 1
            for c in range(k):
                free[c] = True
            _dls_step(J, free, e0, e1, e2, err_sq, lam0_sq, lam_err, dq)
            any_blocked = False
            for c in range(k):
                if (q[c, p] <= lower[c] and dq[c] < 0) or (q[c, p] >= upper[c] and dq[c] > 0):
                    free[c] = False
                    any_blocked = True
            if any_blocked:
                _dls_step(J, free, e0, e1, e2, err_sq, lam0_sq, lam_err, dq)
            big = 0.0
            for c in range(k):
                big = max(big, abs(dq[c]))
            scale = max_step / big if big > max_step else 1.0
            for c in range(k):
                q[c, p] = min(max(q[c, p] + dq[c] * scale, lower[c]), upper[c])
        most = max(most, steps)
    return err, most


def _compile() -> Callable[..., Any] | None:
    """The compiled :func:`iterate_python` (cached on disk), or None without numba."""
    global _compiled, _failed
    if _compiled is None and not _failed:
        compiled = compile_together(
            (cos_sin_scalar, _jacobian, _fk_jacobian, _dls_step),
            (iterate_python,),
        )
        if compiled is None:
            _failed = True
            return None
        _compiled = compiled["iterate_python"]
    return _compiled


def available() -> bool:
    """True when numba is installed (the compiled kernel can be used)."""
    return _compile() is not None


def iterate(chain_arrays, lower, upper, targets, q, tol_m, max_iter, consts):
    """The compiled :func:`iterate_python` (same arguments and results).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    kernel = _compile()
    if kernel is None:
        raise ImportError("the compiled IK kernel needs numba: pip install regrasp-pin[fast]")
    return kernel(
        chain_arrays,
        np.ascontiguousarray(lower, dtype=np.float64),
        np.ascontiguousarray(upper, dtype=np.float64),
        np.ascontiguousarray(targets, dtype=np.float64),
        q,
        float(tol_m),
        int(max_iter),
        consts,
    )
