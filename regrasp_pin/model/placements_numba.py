"""The placements of frames attached to finger chains, compiled with numba (an optional
accelerator).

:func:`~regrasp_pin.model.kinematics.attached_placements` runs each finger's kernel in
numpy batches, a few dozen numpy calls per joint and per attached frame (a link's
collision geometry, a capsule's end); on the few hundred configurations of one check,
those calls cost more than their arithmetic. :func:`placements_python` does the same
per configuration: the same products with the same nonzero constants, in the same
order (no fused multiply-adds: numba does not ask LLVM to contract a multiply and an
add, on any CPU), on the cosines and sines of :func:`~.trig.cos_sin_scalar` (the
numpy kernel's :func:`~.trig.cos_sin`, one angle at a time), so that its numbers are
the numpy path's to the bit. It runs when the IK backend is numba
(:func:`~regrasp_pin.model.ik.set_ik_backend`), which already compiles with numba;
numpy remains the reference and the tests compare both, bit for bit. The function is
plain Python too, which lets the tests run it uncompiled.

A chain's constants are packed once (:func:`chain_plan`): per joint the nonzero terms
of ``W' t_j`` and of ``W' C_j`` (columns; none where ``C_j`` is the identity), per
attached frame the terms of its origin and of its rotation's columns in the last
``W'`` frame of its link.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .numba_jit import compile_together
from .trig import cos_sin_scalar

__all__ = ["available", "frame_terms", "placements", "placements_python", "wanted"]

_compiled: Callable[..., Any] | None = None
_failed = False


def _linear(idx, coef, n_terms, cols, r, out):
    """``out[n] = sum_k coef[k] * cols[idx[k], r, n]`` over the first ``n_terms`` terms
    in their order, a unit coefficient multiplying by nothing (the operations of
    :func:`~regrasp_pin.model.kinematics._linear`, point by point); 0 without terms."""
    n_points = out.shape[0]
    if n_terms == 0:
        for n in range(n_points):
            out[n] = 0.0
        return
    b, c = idx[0], coef[0]
    if c == 1.0:
        for n in range(n_points):
            out[n] = cols[b, r, n]
    else:
        for n in range(n_points):
            out[n] = cols[b, r, n] * c
    for k in range(1, n_terms):
        b, c = idx[k], coef[k]
        if c == 1.0:
            for n in range(n_points):
                out[n] = out[n] + cols[b, r, n]
        else:
            for n in range(n_points):
                out[n] = out[n] + cols[b, r, n] * c


def placements_python(
    theta,
    o0,
    C0,
    t_idx,
    t_coef,
    t_n,
    C_has,
    C_idx,
    C_coef,
    C_n,
    joint_of,
    out_of,
    p_idx,
    p_coef,
    p_n,
    R_idx,
    R_coef,
    R_n,
    want_R,
    R_out,
    p_out,
):
    """Fill ``p_out[n, out_of[j]]`` ``(3,)`` [m] (and ``R_out[n, out_of[j]]`` ``(3, 3)``
    when ``want_R``) with the palm-frame placement of the attached frame ``j`` at each
    configuration ``n``.

    One chain (the host of the frames): ``theta`` ``(m, N)`` its joint angles [rad],
    whose cosines and sines are :func:`~.trig.cos_sin_scalar`'s (the numpy kernel's);
    ``o0`` ``(3,)`` and ``C0`` ``(3, 3)`` the first joint's ``t`` and ``C``; per joint
    ``i`` the terms of ``W' t_i`` (``t_idx``, ``t_coef`` ``(m, 3)``, ``t_n`` ``(m,)``) and,
    where ``C_has[i]``, of column ``a`` of ``W' C_i`` (``C_idx``, ``C_coef`` ``(m, 3, 3)``,
    ``C_n`` ``(m, 3)``). Per frame ``j``: the joint after which it is read ``joint_of``,
    its output column ``out_of``, the terms of its origin (``p_*``, ``(J, 3)``, ``(J,)``)
    and of its rotation's columns (``R_*``, ``(J, 3, 3)``, ``(J, 3)``).

    The points are the innermost loop, as numpy's batches (each point's numbers its
    own): ``cols[b, r, n]`` is coordinate ``r`` of column ``b`` of ``W'`` at point ``n``.
    """
    m, n_points = theta.shape
    cos = np.empty((m, n_points))
    sin = np.empty((m, n_points))
    for i in range(m):
        for n in range(n_points):
            cos[i, n], sin[i, n] = cos_sin_scalar(theta[i, n])
    cols = np.empty((3, 3, n_points))
    new = np.empty((3, 3, n_points))
    o = np.empty((3, n_points))
    d = np.empty(n_points)
    for r in range(3):
        o[r, :] = o0[r]
        for b in range(3):
            cols[b, r, :] = C0[r, b]
    for i in range(m):
        if i > 0:
            _through_joint(
                t_idx[i], t_coef[i], t_n[i], C_has[i], C_idx[i], C_coef[i], C_n[i], cols, new, o, d
            )
        _rotate(cos[i], sin[i], cols)
        for j in range(joint_of.shape[0]):
            if joint_of[j] == i:
                _frame(
                    out_of[j],
                    p_idx[j],
                    p_coef[j],
                    p_n[j],
                    R_idx[j],
                    R_coef[j],
                    R_n[j],
                    want_R,
                    cols,
                    o,
                    d,
                    R_out,
                    p_out,
                )


def _through_joint(t_idx, t_coef, t_n, C_has, C_idx, C_coef, C_n, cols, new, o, d):
    """``o <- o + W' t`` and, unless ``C`` is the identity, ``W' <- W' C`` (one joint's
    constants), point by point."""
    for r in range(3):
        _linear(t_idx, t_coef, t_n, cols, r, d)
        for n in range(d.shape[0]):
            o[r, n] = o[r, n] + d[n]
    if C_has:
        for a in range(3):
            for r in range(3):
                _linear(C_idx[a], C_coef[a], C_n[a], cols, r, new[a, r])
        cols[:, :, :] = new


def _rotate(cos, sin, cols):
    """``W' <- W' Rz(theta)`` point by point: column 0 ``c m0 + s m1``, column 1
    ``c m1 - s m0``."""
    for r in range(3):
        for n in range(cos.shape[0]):
            c = cos[n]
            s = sin[n]
            m0 = cols[0, r, n]
            m1 = cols[1, r, n]
            w0 = c * m0
            w0 = w0 + s * m1
            w1 = c * m1
            w1 = w1 - s * m0
            cols[0, r, n] = w0
            cols[1, r, n] = w1


def _frame(g, p_idx, p_coef, p_n, R_idx, R_coef, R_n, want_R, cols, o, d, R_out, p_out):
    """One attached frame's placement at every point into output column ``g``."""
    for r in range(3):
        _linear(p_idx, p_coef, p_n, cols, r, d)
        for n in range(d.shape[0]):
            p_out[n, g, r] = o[r, n] + d[n]
    if want_R:
        for a in range(3):
            for r in range(3):
                _linear(R_idx[a], R_coef[a], R_n[a], cols, r, d)
                for n in range(d.shape[0]):
                    R_out[n, g, r, a] = d[n]


def _pack(terms_list):
    """Terms ``[((b, c), ...), ...]`` as ``(idx, coef, n)`` arrays ``(L, 3)``, ``(L, 3)``,
    ``(L,)`` (at most three terms each: coordinates of a 3-vector)."""
    size = len(terms_list)
    idx = np.zeros((size, 3), np.int64)
    coef = np.zeros((size, 3))
    n = np.zeros(size, np.int64)
    for row, terms in enumerate(terms_list):
        n[row] = len(terms)
        for k, (b, c) in enumerate(terms):
            idx[row, k] = b
            coef[row, k] = c
    return idx, coef, n


def chain_plan(joints, t_terms, C_terms) -> tuple[np.ndarray, ...]:
    """A chain's constants for :func:`placements_python`: ``(o0, C0, t_idx, t_coef, t_n,
    C_has, C_idx, C_coef, C_n)`` from its joints (``t``, ``C``), the terms of each
    joint's ``t`` and of the columns of its ``C`` (None: the identity)."""
    m = len(joints)
    t_idx, t_coef, t_n = _pack(t_terms)
    C_has = np.array([terms is not None for terms in C_terms], bool)
    C_idx = np.zeros((m, 3, 3), np.int64)
    C_coef = np.zeros((m, 3, 3))
    C_n = np.zeros((m, 3), np.int64)
    for i, terms in enumerate(C_terms):
        if terms is not None:
            C_idx[i], C_coef[i], C_n[i] = _pack(terms)
    o0 = np.array(joints[0].t, float)
    C0 = np.array(joints[0].C, float)
    return o0, C0, t_idx, t_coef, t_n, C_has, C_idx, C_coef, C_n


def frame_terms(p_terms: list, R_terms: list | None) -> tuple[np.ndarray, ...]:
    """Attached frames' terms for :func:`placements_python`: ``(p_idx, p_coef, p_n,
    R_idx, R_coef, R_n)`` from each frame's origin terms and its rotation columns'
    terms (None: no rotations)."""
    p_idx, p_coef, p_n = _pack(p_terms)
    size = len(p_terms)
    R_idx = np.zeros((size, 3, 3), np.int64)
    R_coef = np.zeros((size, 3, 3))
    R_n = np.zeros((size, 3), np.int64)
    for j, columns in enumerate(R_terms or ()):
        R_idx[j], R_coef[j], R_n[j] = _pack(columns)
    return p_idx, p_coef, p_n, R_idx, R_coef, R_n


def _compile() -> Callable[..., Any] | None:
    """The compiled :func:`placements_python` (cached on disk), or None without numba."""
    global _compiled, _failed
    if _compiled is None and not _failed:
        compiled = compile_together(
            (cos_sin_scalar, _linear, _through_joint, _rotate, _frame), (placements_python,)
        )
        if compiled is None:
            _failed = True
            return None
        _compiled = compiled["placements_python"]
    return _compiled


def available() -> bool:
    """True when numba is installed (the compiled loop can be used)."""
    return _compile() is not None


def wanted(backend: str) -> bool:
    """Whether to place by the compiled loop on the IK backend ``backend``
    (:func:`~regrasp_pin.model.ik.ik_backend`): on ``"numba"`` when it compiles (the
    same bits as numpy either way)."""
    return backend == "numba" and available()


def placements(*args: Any) -> None:
    """The compiled :func:`placements_python` (same arguments; fills the outputs).

    Raises:
        ImportError: numba is not installed (check :func:`available` first).
    """
    kernel = _compile()
    if kernel is None:
        raise ImportError("the compiled placements need numba: pip install regrasp-pin[fast]")
    kernel(*args)
