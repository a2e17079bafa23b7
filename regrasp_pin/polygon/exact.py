"""Exact optimum of the polygonal-approximation energy by dynamic programming.

It minimizes the same energy as the competitive network (Eq. 8 halved: the sum of the
chord deviations ``H[s_i, s_{i+1}]``) over all ordered vertex sets, and is the yardstick for
:mod:`regrasp_pin.polygon.hopfield`.

Open curves: the vertices start at point 0 and end at point ``n - 1``; ``C_j[y]``, the
cheapest path from 0 to ``y`` with ``j`` chords, obeys
``C_j[y] = min_L C_{j-1}[y - L] + H[y - L, y]``, O(m n^2) in general.

Closed curves: the optimum is the best over start points ``t`` of the open problem from
``t`` around to ``t + n`` with ``m`` chords. Trying every start costs n times more, so only
the starts of a window that every better polygon must hit are tried: a polygon with no
vertex in ``[a, a + w)`` has a chord covering the window, and chords whose deviation plus a
lower bound of the cheapest cover of the rest of the curve (:func:`rest_lower_bound`)
exceeds the incumbent energy cannot be in a better polygon. The window is chosen as small
as these chords allow; the result is exact.

All layers are vectorized over the end point, the chord span and the start point; spans
whose chords are all unavailable (``inf``) are skipped, and states whose cost plus the
rest bound exceed the incumbent are pruned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided

from .._validate import positive_int
from ..exceptions import InputError
from .deviation import rest_lower_bound
from .hopfield import check_deviation_matrix, check_state, polygon_energy

# Cap on the number of candidate values evaluated at once (memory) [elements].
_CHUNK = 1 << 22
# Consecutive start points solved together on closed curves.
_RUN = 16
_RTOL = 1e-12


@dataclass(frozen=True)
class ExactResult:
    """Result of :func:`exact_polygon`.

    Attributes:
        indices: Optimal vertex indices, shape ``(m,)``, ordered.
        energy: Optimal energy (sum of chord deviations).
        starts: Number of start points solved (1 for open curves).
    """

    indices: np.ndarray
    energy: float
    starts: int


def exact_polygon(
    H: object, m: int, *, closed: bool = False, incumbent: object = None
) -> ExactResult:
    """Globally optimal polygon for deviation matrix ``H`` by dynamic programming.

    Args:
        H: Deviation matrix, shape ``(n, n)``; ``inf`` marks chords that may not be used.
        m: Number of vertices (``2 <= m <= n`` open, ``3 <= m <= n`` closed).
        closed: Closed curve.
        incumbent: Optional feasible state ``(m,)`` (e.g. from the network); its energy
            bounds the search. The result is never worse than it.

    Returns:
        The optimal vertex indices and energy.

    Raises:
        InputError: invalid ``H``, ``m`` or ``incumbent``, or no polygon with finite energy
            exists in ``H``.
    """
    H = check_deviation_matrix(H)
    n = H.shape[0]
    m = positive_int(m, "m", 3 if closed else 2)
    if m > n:
        raise InputError("m", f"{m} exceeds the number of points n={n}", f"m <= {n}")
    ub, inc = np.inf, None
    if incumbent is not None:
        inc = check_state(incumbent, n, closed, "incumbent")
        if inc.shape[0] != m:
            raise InputError("incumbent", f"has {inc.shape[0]} vertices", f"{m} vertices")
        ub = polygon_energy(H, inc, closed=closed)
    solver = _Solver(H, closed)
    if closed:
        best, starts = _solve_closed(solver, m, ub)
    else:
        best, starts = solver.solve(np.array([0]), n - 1, m - 1, ub), 1
    if best is not None:
        s = best[0]
    elif inc is not None and np.isfinite(ub):
        s = inc  # nothing beats the incumbent: it is optimal
    else:
        raise InputError("H", "admits no polygon with finite energy", "available chords")
    s = np.sort(np.asarray(s) % n)
    return ExactResult(s, polygon_energy(H, s, closed=closed), starts)


def _solve_closed(
    solver: _Solver, m: int, ub: float
) -> tuple[tuple[np.ndarray, float] | None, int]:
    """Best closed polygon better than ``ub``; returns ((positions, energy) or None, starts).

    Starts are solved in runs of consecutive points; after each run the window of starts
    that a better polygon must hit is recomputed with the improved bound, and chords that
    can no longer be in a better polygon are dropped.
    """
    n = solver.n
    best: tuple[np.ndarray, float] | None = None
    if not np.isfinite(ub):  # no incumbent: the best polygon through point 0 first
        best = solver.solve(np.array([0]), n, m, np.inf)
        if best is None:
            return None, 1
        ub = best[1]
    tried = np.zeros(n, dtype=bool)
    tried[0] = best is not None
    count = int(tried.sum())
    togo: tuple[int, np.ndarray] | None = None
    pruned_at = np.inf
    while True:
        if ub < pruned_at * (1 - 1e-3):
            try:
                solver = _Solver(solver.pruned(m, ub), True)
            except InputError:  # nothing can beat ub
                break
            pruned_at, togo = ub, None
        window = solver.start_window(m, ub)
        todo = window[~tried[window % n]]
        if todo.size == 0:
            break
        if togo is None:  # bounds for every start of this window (valid for any subset)
            togo = (int(window[0]), solver.cost_to_go(int(window[0]), window.size, m))
        breaks = np.flatnonzero(np.diff(todo) > 1)
        end = int(breaks[0]) + 1 if breaks.size else todo.size
        run = todo[: min(end, _RUN)]
        if togo[0] > run[0] or togo[0] + togo[1].shape[1] - n < run[-1] + 1:
            togo = (int(run[0]), solver.cost_to_go(int(run[0]), run.size, m))
        res = solver.solve(run, n, m, ub, togo)
        tried[run % n] = True
        count += int(run.size)
        if res is not None and res[1] < ub:
            best, ub = res, res[1]
    return best, count


class _Solver:
    """Banded DP over chord spans, vectorized over start points."""

    def __init__(self, H: np.ndarray, closed: bool) -> None:
        n = H.shape[0]
        self.n, self.closed = n, closed
        # B[y, L] = H[(y - L) mod n, y]: the chord of span L ending at y (inf if unavailable)
        if closed:
            stack = np.concatenate([H, H])
        else:
            stack = np.concatenate([np.full((n, n), np.inf), H])
        rs, cs = stack.strides
        view = as_strided(stack[n:], shape=(n, n), strides=(rs + cs, -rs), writeable=False)
        spans = np.flatnonzero(np.isfinite(view).any(axis=0))
        spans = spans[spans >= 1]
        if spans.size == 0:
            raise InputError("H", "has no available chord", "finite off-diagonal entries")
        self.Lmin, self.Lmax = int(spans[0]), int(spans[-1])
        B = np.ascontiguousarray(view[:, self.Lmin : self.Lmax + 1])
        # rows t + r for unrolled starts t < 2n and offsets r <= n
        self.B2 = np.concatenate([B, B, B]) if closed else B
        if closed:
            # F[x, L] = H[x, (x + L) mod n]: the chord of span L starting at x
            wide = np.concatenate([H, H], axis=1)
            rs2, cs2 = wide.strides
            fwd = as_strided(wide, shape=(n, n), strides=(rs2 + cs2, cs2), writeable=False)
            F = np.ascontiguousarray(fwd[:, self.Lmin : self.Lmax + 1])
            self.F3 = np.concatenate([F, F, F])
        self.min_by_length = np.full(n, np.inf)
        self.min_by_length[self.Lmin : self.Lmax + 1] = B.min(axis=0)
        self._rest: dict[int, np.ndarray] = {}

    def rest(self, chords: int) -> np.ndarray:
        """Lower bound of covering ``l`` steps with ``chords`` chords, for l = 0 .. n."""
        if chords not in self._rest:
            self._rest[chords] = rest_lower_bound(self.min_by_length, chords, np.arange(self.n + 1))
        return self._rest[chords]

    def start_window(self, m: int, ub: float) -> np.ndarray:
        """Smallest window of start points that every polygon better than ``ub`` must hit."""
        n = self.n
        L = np.arange(self.Lmin, self.Lmax + 1)
        fwd = self.F3[:n]  # chord (x, L) starting at x
        limit = ub * (1 + _RTOL) + 1e-300
        feasible = fwd + self.rest(m - 1)[n - L][None, :] <= limit
        reach = np.where(feasible, L[None, :], 0).max(axis=1)  # longest useful chord from x
        has = feasible.any(axis=1)
        # a polygon missing [a, a + w) has a chord (x, x + L) with x < a and x + L >= a + w
        end2 = np.concatenate([np.arange(n) - n + reach, np.arange(n) + reach])  # x in [-n, n)
        G = self.Lmax
        win = as_strided(
            end2[n - G :], shape=(n, G), strides=(end2.strides[0],) * 2, writeable=False
        )  # win[a, k] = end of chord from x = a - G + k
        need = np.maximum(win.max(axis=1) - np.arange(n) + 1, 1)
        a = int(np.argmin(need))
        w = int(min(need[a], n))
        starts = a + np.arange(w)  # unrolled, consecutive
        useful = np.flatnonzero(has[starts % n])
        if useful.size == 0:
            return starts[:0]
        return starts[useful[0] : useful[-1] + 1]

    def pruned(self, m: int, ub: float) -> np.ndarray:
        """H without the chords that cannot be in a closed polygon better than ``ub``."""
        n = self.n
        L = np.arange(self.Lmin, self.Lmax + 1)
        fwd = self.F3[:n]
        limit = ub * (1 + _RTOL) + 1e-300
        keep = np.isfinite(fwd) & (fwd + self.rest(m - 1)[n - L][None, :] <= limit)
        xs, ls = np.nonzero(keep)
        H = np.full((n, n), np.inf)
        H[xs, (xs + L[ls]) % n] = fwd[xs, ls]
        return H

    def cost_to_go(self, t0: int, count: int, chords: int) -> np.ndarray:
        """Lower bounds ``G[k, u]`` of ``k`` chords from ``t0 + u`` to any end in
        ``[t0 + n, t0 + n + count)`` (a DP backwards from all those ends at once)."""
        n = self.n
        Lmin, Lmax = self.Lmin, self.Lmax
        W = Lmax - Lmin + 1
        size = n + count
        G = np.full((chords + 1, size + Lmax), np.inf)
        G[0, n:size] = 0.0
        F3 = self.F3
        rf0, rf1 = F3.strides
        costs = as_strided(F3[t0:], shape=(size, W), strides=(rf0, rf1), writeable=False)
        for k in range(1, chords + 1):
            prev = G[k - 1]
            nxt = as_strided(
                prev[Lmin:], shape=(size, W), strides=(prev.strides[0],) * 2, writeable=False
            )  # nxt[u, l] = G[k-1, u + Lmin + l]
            G[k, :size] = (costs + nxt).min(axis=1)
        return G[:, :size]

    def solve(
        self,
        starts: np.ndarray,
        total: int,
        chords: int,
        ub: float,
        togo: tuple[int, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, float] | None:
        """Best path of ``chords`` chords from each start ``t`` to ``t + total``.

        ``starts`` must be consecutive (unrolled) integers. ``togo = (t0, G)`` are
        cost-to-go bounds from :meth:`cost_to_go` for a window of starts from ``t0`` that
        contains ``starts``.

        Returns (vertex positions as absolute unrolled indices, energy) of the best start,
        or None if no path beats ``ub``.
        """
        best: tuple[np.ndarray, float] | None = None
        W = self.Lmax - self.Lmin + 1
        per_start = (total + 1) * W
        chunk = max(1, _CHUNK // max(per_start, 1))
        for c0 in range(0, starts.shape[0], chunk):
            res = self._solve_chunk(starts[c0 : c0 + chunk], total, chords, ub, togo)
            if res is not None and res[1] < ub:
                best, ub = res, res[1]
        return best

    def _solve_chunk(
        self,
        starts: np.ndarray,
        total: int,
        chords: int,
        ub: float,
        togo: tuple[int, np.ndarray] | None,
    ) -> tuple[np.ndarray, float] | None:
        T = starts.shape[0]
        Lmin, Lmax = self.Lmin, self.Lmax
        W = Lmax - Lmin + 1
        limit = ub * (1 + _RTOL) + 1e-300 if np.isfinite(ub) else np.inf
        pad = Lmax
        C = np.full((T, pad + total + 1), np.inf)
        C[:, pad] = 0.0
        bound_rows = None
        if togo is not None and np.isfinite(limit):
            t0, G = togo
            bound_rows = G  # G[k, u]: from position t0 + u with k chords left
            shift = (starts - t0)[:, None]
        lo = hi = 0
        args: list[tuple[int, np.ndarray]] = []
        B2 = self.B2
        rb0, rb1 = B2.strides
        for j in range(1, chords + 1):
            remaining = chords - j
            r_lo = max(lo + Lmin, total - remaining * Lmax)
            r_hi = min(hi + Lmax, total - remaining * Lmin)
            if j == chords:
                r_lo = r_hi = total
            if r_lo > r_hi:
                return None
            R = r_hi - r_lo + 1
            cs = C.strides
            base = pad + r_lo - Lmin
            prev = as_strided(
                C[:, base:], shape=(T, R, W), strides=(cs[0], cs[1], -cs[1]), writeable=False
            )
            # chord costs B2[t + r, L]: starts are consecutive, so one strided view
            costs = as_strided(
                B2[int(starts[0]) + r_lo :],
                shape=(T, R, W),
                strides=(rb0, rb0, rb1),
                writeable=False,
            )
            cand = costs + prev
            arg = cand.argmin(axis=2)
            val = np.take_along_axis(cand, arg[..., None], axis=2)[..., 0]
            if np.isfinite(limit):
                r_all = np.arange(r_lo, r_hi + 1)
                bound = self.rest(remaining)[total - r_all][None, :]
                if bound_rows is not None:
                    bound = np.maximum(bound, bound_rows[remaining][shift + r_all[None, :]])
                val[val + bound > limit] = np.inf
            C = np.full((T, pad + total + 1), np.inf)
            C[:, pad + r_lo : pad + r_hi + 1] = val
            args.append((r_lo, arg))
            fin = np.isfinite(val)
            if not fin.any():
                return None
            cols = np.flatnonzero(fin.any(axis=0))
            lo, hi = r_lo + int(cols[0]), r_lo + int(cols[-1])
        final = C[:, pad + total]
        k = int(np.argmin(final))
        energy = float(final[k])
        if not np.isfinite(energy):
            return None
        # backtrack
        t = int(starts[k])
        r = total
        pos = [r]
        for r_lo, arg in reversed(args):
            L = Lmin + int(arg[k, r - r_lo])
            r -= L
            pos.append(r)
        pos = pos[::-1]
        verts = t + np.asarray(pos[:-1] if self.closed else pos)
        return verts, energy
