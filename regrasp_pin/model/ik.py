"""Batched damped-least-squares position IK for one finger.

Solves ``p_tip(q) = target`` for ``N`` targets at once, with the finger's joint limits
respected at every iterate (projected steps with an active set: a joint at a limit
whose step points outward is frozen for that step, and the step is recomputed for the
others). Damping follows the error (lambda^2 = lambda0^2 + w |e|^2, Sugihara's
Levenberg-Marquardt rule), so far targets take cautious steps and the last steps are
nearly Gauss-Newton. Inner iterations run to half the tolerance, and a final pass
finishes the points just above it. Cos and sin come from :func:`~.trig.cos_sin`, the
same bits in numpy, in the compiled loop and on any CPU. Points that have not
converged after ``max_iter`` iterations are restarted from a fixed set of seeds spread
over the joint box (deterministic); the
first seed (in their fixed order) that converges is kept, else the smallest residual
(not the smallest residual below the tolerance: between converged seeds that choice
follows rounding noise). An unreachable target is not an error: it comes back with
``success=False`` and its residual.

The work is done on component-major arrays ``(k, N)`` and only on the points that
have not converged yet (compacted with ``take``); consecutive points with the same start,
bit for bit, share its first evaluation, and few points take the step in fewer numpy
calls. Every point's result depends on that point alone, bit for bit, whatever the batch.
The iterations run in numpy (the reference) or in the same loop compiled per point by
numba (:mod:`.ik_numba`, ``pip install regrasp-pin[fast]``), the default where numba
is installed; :func:`set_ik_backend` or the environment variable
``REGRASP_PIN_IK_BACKEND`` (``numpy`` or ``numba``) choose. The two give the same bits,
since they do the same float64 operations in the same order, cos and sin included, so
a plan does not depend on whether numba is installed (when their cos/sin were the
libraries' own, in single precision, the iterates differed by about 1e-7 rad, and 2 or
3 of the 30 neighbour scenarios ended differently).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import cast

import numpy as np

from ..exceptions import InputError
from . import ik_numba
from .kinematics import FingerChain

__all__ = [
    "IK_BACKENDS",
    "IK_BACKEND_ENV",
    "IKResult",
    "environment_backend",
    "ik_backend",
    "set_ik_backend",
    "solve_position_ik",
]

IK_BACKENDS = ("numpy", "numba")
#: the environment variable that chooses the backend of a new process
IK_BACKEND_ENV = "REGRASP_PIN_IK_BACKEND"

_LAMBDA0_SQ = 1e-8  # [m^2]
_LAMBDA_ERR = 1e-2  # [-], weight of |e|^2 in lambda^2
_MAX_STEP = 0.4  # [rad] largest joint change per iteration
_BLOCK = 32768  # points per block
_STALL_SQ = 0.995**2  # an iteration must shrink the error by 0.5 % ...
_STALL_TOL_FACTOR = 10.0  # ... unless it is already within 10 x tol
_CONSTS = (_LAMBDA0_SQ, _LAMBDA_ERR, _MAX_STEP, _STALL_SQ, _STALL_TOL_FACTOR)
#: Residuals [m] of restarts that did not converge, within this fraction of the
#: smallest, are ties, won by the first seed rather than by their last bits (which move
#: a residual by about 1e-13 of it: a flip needs two seeds' residuals that close).
RESIDUAL_RTOL = 1e-9
_backend: list[str] = []  # the chosen backend, once chosen


def environment_backend() -> str:
    """The backend a new process chooses (unchecked): ``REGRASP_PIN_IK_BACKEND`` if set,
    else ``"numba"`` where numba is installed, else ``"numpy"``."""
    return os.environ.get(IK_BACKEND_ENV) or ("numba" if ik_numba.available() else "numpy")


def ik_backend() -> str:
    """The backend the IK iterations run on: ``"numba"`` or ``"numpy"``.

    The environment variable ``REGRASP_PIN_IK_BACKEND`` chooses; without it, numba
    where it is installed (the same results, faster), else numpy.

    Raises:
        InputError: the variable names no backend, or numba without numba installed.
    """
    if not _backend:
        want = environment_backend()
        if want not in IK_BACKENDS:
            raise InputError(IK_BACKEND_ENV, f"is {want!r}", f"one of {IK_BACKENDS}")
        if want == "numba" and not ik_numba.available():
            raise InputError(
                IK_BACKEND_ENV,
                "is 'numba' but numba is not installed",
                "numpy, or pip install 'regrasp-pin[fast]'",
            )
        _backend.append(want)
    return _backend[0]


def set_ik_backend(name: str) -> str:
    """Run the IK iterations on ``name`` (one of :data:`IK_BACKENDS`); return the previous.

    Raises:
        InputError: an unknown name, or ``"numba"`` without numba installed.
    """
    if name not in IK_BACKENDS:
        raise InputError("name", f"is {name!r}", f"one of {IK_BACKENDS}")
    if name == "numba" and not ik_numba.available():
        raise InputError("name", "is 'numba' but numba is not installed", "numpy")
    previous = ik_backend()
    _backend[0] = name
    return previous


@dataclass(frozen=True)
class IKResult:
    """Result of a batched IK solve.

    Attributes:
        q: ``(N, k)`` joint solutions [rad], always within the joint limits.
        success: ``(N,)`` True where the residual is below the tolerance.
        error_m: ``(N,)`` residual distance between tip and target [m].
        iterations: Total number of damped least-squares iterations run (all passes).
    """

    q: np.ndarray
    success: np.ndarray
    error_m: np.ndarray
    iterations: int

    @property
    def success_rate(self) -> float:
        """Fraction of targets reached, in [0, 1]."""
        return float(np.mean(self.success)) if self.success.size else 1.0


def _rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sum_k a[k] * b[k] for (k, n) arrays (faster than einsum for small k)."""
    out = a[0] * b[0]
    for i in range(1, a.shape[0]):
        out += a[i] * b[i]
    return out


def _dls_step(J: np.ndarray, e: np.ndarray, err_sq: np.ndarray) -> np.ndarray:
    """Damped least-squares step ``dq = J^T (J J^T + lambda^2 I)^-1 e``.

    ``J`` is component-major ``(3, k, n)``, ``e`` is ``(3, n)``. Few points: in one batch
    (:func:`_dls_step_few`, fewer numpy calls); many: :func:`_dls_step_loop` (fewer
    operations). The two do the same operations on each point's numbers.
    """
    if e.shape[1] <= _FEW_POINTS:
        return _dls_step_few(J, e, err_sq)
    return _dls_step_loop(J, e, err_sq)


def _dls_step_few(J: np.ndarray, e: np.ndarray, err_sq: np.ndarray) -> np.ndarray:
    """:func:`_dls_step_loop` in a handful of numpy calls: ``A = J J^T`` from all
    products ``J[a, k] J[b, k]`` summed in the order of ``k``; the adjugate from ``A``
    extended cyclically (rows and columns 3, 4 = 0, 1), cofactor ``ab`` =
    ``A[a+1, b+1] A[a+2, b+2] - A[a+1, b+2] A[a+2, b+1]``, which is the hand-written
    one's products in commuted order (the same bits: ``A`` is symmetric bit for bit and
    a product does not depend on its operands' order)."""
    prod = J[:, None] * J[None, :]  # (3, 3, k, n)
    A = prod[:, :, 0].copy()
    for i in range(1, J.shape[1]):
        A += prod[:, :, i]
    A.reshape(9, -1)[::4] += _LAMBDA0_SQ + _LAMBDA_ERR * err_sq  # the diagonal
    Ae = A[_CYCLIC][:, _CYCLIC]  # (5, 5, n)
    C = Ae[1:4, 1:4] * Ae[2:5, 2:5]
    C -= Ae[1:4, 2:5] * Ae[2:5, 1:4]
    d = A[0] * C[0]  # det = a00 c00 + a01 c01 + a02 c02
    det = d[0] + d[1]
    det += d[2]
    y = C * e[None]  # x_a = (c_a0 e0 + c_a1 e1 + c_a2 e2) / det
    x = y[:, 0] + y[:, 1]
    x += y[:, 2]
    x /= det
    s = J * x[:, None]  # dq = J[0] x0 + J[1] x1 + J[2] x2
    dq = s[0] + s[1]
    dq += s[2]
    return dq  # (k, n)


_CYCLIC = np.array([0, 1, 2, 0, 1])
_FEW_POINTS = 256  # up to this many points, the DLS step in one batch


def _dls_step_loop(J: np.ndarray, e: np.ndarray, err_sq: np.ndarray) -> np.ndarray:
    """Damped least-squares step ``dq = J^T (J J^T + lambda^2 I)^-1 e``.

    ``J`` is component-major ``(3, k, n)``, ``e`` is ``(3, n)``.
    """
    a00 = _rowdot(J[0], J[0])
    a11 = _rowdot(J[1], J[1])
    a22 = _rowdot(J[2], J[2])
    a01 = _rowdot(J[0], J[1])
    a02 = _rowdot(J[0], J[2])
    a12 = _rowdot(J[1], J[2])
    lam = _LAMBDA0_SQ + _LAMBDA_ERR * err_sq
    a00 += lam
    a11 += lam
    a22 += lam
    # adjugate of the symmetric 3x3 matrix
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    x0 = (c00 * e[0] + c01 * e[1] + c02 * e[2]) / det
    x1 = (c01 * e[0] + c11 * e[1] + c12 * e[2]) / det
    x2 = (c02 * e[0] + c12 * e[1] + c22 * e[2]) / det
    return J[0] * x0 + J[1] * x1 + J[2] * x2  # (k, n)


def _first_evaluation(chain: FingerChain, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions ``(3, n)`` and Jacobians ``(3, k, n)`` at ``q`` ``(k, n)``, each run of
    consecutive equal starts (bit for bit) evaluated once: warm starts shared by a
    point's times, a common cold start. Each point's kernel result depends on that
    point alone, so the copies are the same bits as evaluating every column."""
    n = q.shape[1]
    if n < 2:
        return chain.tip_soa(q, True)  # type: ignore[return-value]
    bits = q.view(np.int64)
    new = np.empty(n, bool)
    new[0] = True
    np.any(bits[:, 1:] != bits[:, :-1], axis=0, out=new[1:])
    first = np.flatnonzero(new)
    if first.size > 0.8 * n:  # few repeats: not worth the copies
        return chain.tip_soa(q, True)  # type: ignore[return-value]
    p, J = chain.tip_soa(q.take(first, axis=1), True)
    counts = np.diff(np.append(first, n))
    return np.repeat(p, counts, axis=1), np.repeat(J, counts, axis=2)  # type: ignore[arg-type]


def _iterate(
    chain: FingerChain,
    lower: np.ndarray,
    upper: np.ndarray,
    targets: np.ndarray,
    q: np.ndarray,
    tol_m: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Run DLS on component-major ``targets`` (3,n), ``q`` (k,n); return q, err, iters.

    Only the points that have not converged are carried from one iteration to the next.
    """
    if ik_backend() == "numba":
        q = np.ascontiguousarray(q, dtype=np.float64)
        err, iters = ik_numba.iterate(
            chain.packed(), lower, upper, targets, q, tol_m, max_iter, _CONSTS
        )
        return q, err, int(iters)
    n = q.shape[1]
    err = np.empty(n)
    active = np.arange(n)
    qa = q
    ta = targets
    lo = lower[:, None]
    hi = upper[:, None]
    iters = 0
    prev_sq = np.full(n, np.inf)
    while True:
        if iters == 0:
            p, J = _first_evaluation(chain, qa)
        else:  # the last evaluation only checks: no Jacobian (p is the same bits)
            p, J_or_none = chain.tip_soa(qa, iters < max_iter)
            J = cast(np.ndarray, J_or_none)  # None only when this is the last evaluation
        e = ta - p
        e2 = e * e
        err_sq = e2[0] + e2[1]  # the order of _rowdot(e, e)
        err_sq += e2[2]
        # done: converged, or stalled far from the target (an unreachable target whose
        # error no longer drops by 0.5 % per iteration)
        keep = (err_sq > tol_m * tol_m) & (
            (err_sq < _STALL_SQ * prev_sq) | (err_sq < (_STALL_TOL_FACTOR * tol_m) ** 2)
        )
        n_keep = int(np.count_nonzero(keep))
        last = n_keep == 0 or iters == max_iter
        if n_keep < keep.size:
            kept, done = np.flatnonzero(keep), np.flatnonzero(~keep)
            q[:, active[done]] = qa.take(done, axis=1)  # write back finished points
            err[active[done]] = np.sqrt(err_sq[done])
            active, err_sq = active[kept], err_sq[kept]
            qa, ta = qa.take(kept, axis=1), ta.take(kept, axis=1)
            if not last:
                J, e = J.take(kept, axis=2), e.take(kept, axis=1)
        if last:
            err[active] = np.sqrt(err_sq)
            break
        prev_sq = err_sq
        iters += 1
        dq = _dls_step(J, e, err_sq)
        blocked = ((qa <= lo) & (dq < 0)) | ((qa >= hi) & (dq > 0))
        rows = np.flatnonzero(blocked.any(axis=0))
        if rows.size:  # (take: boolean or fancy indexing of a last axis is slow)
            free = ~blocked.take(rows, axis=1)
            Jb = J.take(rows, axis=2) * free[None]
            dq[:, rows] = _dls_step(Jb, e.take(rows, axis=1), err_sq[rows]) * free
        size = np.abs(dq)
        if size.max() > _MAX_STEP:
            big = size.max(axis=0)
            dq *= np.minimum(1.0, _MAX_STEP / np.maximum(big, 1e-300))
        qa = (qa + dq).clip(lo, hi)
    q[:, active] = qa
    return q, err, iters


def _finish(
    chain: FingerChain,
    lower: np.ndarray,
    upper: np.ndarray,
    targets: np.ndarray,
    q: np.ndarray,
    err: np.ndarray,
    tol_m: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Finish the points of a first pass (to half the tolerance) whose residuals ``err``
    [m] at ``q`` are just above ``tol_m``.

    The first pass's residuals are the exact ones: its tip positions are computed the
    same way at every evaluation, so measuring them again would give the same bits.
    Points far above the tolerance have stalled (unreachable) or run out of
    iterations; more iterations would not help them (restarts might).
    """
    bad = np.flatnonzero((err > tol_m) & (err <= _STALL_TOL_FACTOR * tol_m))
    iters = 0
    if bad.size:
        qb, eb, iters = _iterate(
            chain, lower, upper, targets.take(bad, axis=1), q.take(bad, axis=1), tol_m, max_iter
        )
        q[:, bad] = qb
        err[bad] = eb
    return q, err, iters


def _seeds(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Deterministic restart seeds ``(s, k)``: the box centre's neighbours and corners."""
    k = lower.size
    fr = np.array([0.2, 0.8])
    grid = np.stack(np.meshgrid(*[fr] * k, indexing="ij"), -1).reshape(-1, k)
    return lower + grid * (upper - lower)


def solve_position_ik(
    chain: FingerChain,
    lower: np.ndarray,
    upper: np.ndarray,
    targets_palm: np.ndarray,
    q_init: np.ndarray,
    *,
    tol_m: float = 1e-5,
    max_iter: int = 40,
    restarts: bool = True,
) -> IKResult:
    """Batched damped-least-squares position IK (inputs already validated).

    Prefer :meth:`regrasp_pin.model.hand.Finger.ik`, which validates its arguments.

    Args:
        chain: The finger's kinematic kernel.
        lower: ``(k,)`` lower joint limits [rad].
        upper: ``(k,)`` upper joint limits [rad].
        targets_palm: ``(N, 3)`` tip-centre targets in the palm frame [m].
        q_init: ``(N, k)`` initial guesses [rad] (clipped into the limits).
        tol_m: Convergence tolerance on the tip position error [m].
        max_iter: Iteration cap per pass.
        restarts: Restart points that did not converge from deterministic seeds: the
            first seed that converges, else the first of those that end nearest the
            target (within :data:`RESIDUAL_RTOL` of the nearest), if nearer than the
            first solve by more than that.

    Returns:
        An :class:`IKResult`; ``q`` is always within ``[lower, upper]``.
    """
    n = targets_palm.shape[0]
    if n > _BLOCK:  # blocks small enough for the working set to stay in cache
        parts = [
            solve_position_ik(
                chain,
                lower,
                upper,
                targets_palm[i : i + _BLOCK],
                q_init[i : i + _BLOCK],
                tol_m=tol_m,
                max_iter=max_iter,
                restarts=restarts,
            )
            for i in range(0, n, _BLOCK)
        ]
        return IKResult(
            q=np.concatenate([r.q for r in parts]),
            success=np.concatenate([r.success for r in parts]),
            error_m=np.concatenate([r.error_m for r in parts]),
            iterations=max(r.iterations for r in parts),
        )
    targets = np.ascontiguousarray(targets_palm.T)
    q = np.clip(np.ascontiguousarray(q_init.T, dtype=float), lower[:, None], upper[:, None])
    # iterations to half the tolerance, then a pass that finishes the few points just
    # above it (their residuals are the first pass's: exact)
    q, err, iters = _iterate(chain, lower, upper, targets, q, 0.5 * tol_m, max_iter)
    q, err, it = _finish(chain, lower, upper, targets, q, err, tol_m, max_iter)
    iters += it
    if restarts:
        bad = np.flatnonzero(err > tol_m)
        if bad.size:
            # every seed for every failed point, in one batch, seed by seed (a seed's
            # entries share its first evaluation); keep the best per point
            seeds = _seeds(lower, upper)
            ns = seeds.shape[0]
            k = q.shape[0]
            q_try = np.repeat(seeds.T[:, :, None], bad.size, axis=2).reshape(k, -1)
            t_try = np.tile(targets.take(bad, axis=1), (1, ns))
            q_try, e_try, it = _iterate(chain, lower, upper, t_try, q_try, 0.5 * tol_m, max_iter)
            q_try, e_try, it2 = _finish(chain, lower, upper, t_try, q_try, e_try, tol_m, max_iter)
            iters += it + it2
            e_try = e_try.reshape(ns, bad.size).T  # (point, seed)
            # the first seed that converged (not the smallest residual below the
            # tolerance: that one follows rounding noise), else the first of the smallest
            # residuals: seeds that stall where the target is out of reach end at the
            # same distance, on other branches of a spare joint, and the last bits of
            # that distance must not choose the branch
            conv = e_try <= tol_m
            least = e_try.min(axis=1, keepdims=True)
            tied = e_try <= least * (1.0 + RESIDUAL_RTOL)
            best = np.where(conv.any(axis=1), np.argmax(conv, axis=1), np.argmax(tied, axis=1))
            rows = np.arange(bad.size)
            e_best = e_try[rows, best]
            # a seed that converged replaces the first solve (which did not); one that
            # stalled, only where it ends nearer by more than the tie tolerance
            better = conv.any(axis=1) | (e_best < err[bad] * (1.0 - RESIDUAL_RTOL))
            q_best = q_try.reshape(k, ns, bad.size)[:, best, rows]
            q[:, bad[better]] = q_best[:, better]
            err[bad[better]] = e_best[better]
    return IKResult(
        q=np.ascontiguousarray(q.T), success=err <= tol_m, error_m=err, iterations=iters
    )
