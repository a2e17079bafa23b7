"""Competitive (winner-take-all) Hopfield network for polygonal approximation (section 2.2.2).

The network has ``n x m`` binary neurons ``V[x, i]``: row ``x`` is a curve point, column
``i`` a polygon vertex, and exactly one neuron per column is active (Eq. 6), so a state is
simply the vertex index of every column, ``indices[i]``. With the connection matrix ``H``
of arc-to-chord deviations (Eq. 7, :mod:`regrasp_pin.polygon.deviation`) the energy (Eq. 8) is

    E_8 = sum_i sum_x sum_y (h[y, x] V[x, i] V[y, i-1] + h[x, y] V[x, i] V[y, i+1])
        = 2 * sum_i h[indices[i], indices[i+1]],

i.e. every chord is counted once from each end. We report ``E = E_8 / 2``, the sum of the
polygon's chord deviations. The input of neuron ``(x, i)`` (Eq. 10, from the weights of
Eq. 9 and ``I = 0``) is

    U[x, i] = -(h[indices[i-1], x] + h[x, indices[i+1]]),

and the winner-take-all rule (Eq. 6) activates, in column ``i``, the row with the largest
input, i.e. the point that minimizes the two chords it closes with its neighbours.

Why the energy never rises: columns are updated sequentially (Gauss-Seidel), and a
column's input only depends on its two neighbour columns. Given the neighbours, the
column's contribution to ``E`` is exactly ``-U[x, i]``, so the winner minimizes ``E`` over
that column; we move the winner only when it is *strictly* better than the current row
(ties keep the current one). Each update therefore lowers ``E`` or leaves the state
unchanged, and since there are finitely many states the network stops. Columns that are not
neighbours do not interact, so all even columns (then all odd ones) are updated at once;
this is the same sequence of energies as updating them one after the other.

Vertices stay ordered: column ``i`` only competes over the points strictly between its
neighbours (on a closed curve, the cyclic interval). For open curves (a path from P to Q)
the first and last columns are pinned to the end points.

The restarts, perturbations and local search that improve on the plain network
(:func:`competitive_hopfield`) live in :mod:`regrasp_pin.polygon.hopfield_search`; they are
re-exported here.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, positive_int
from ..exceptions import InputError

#: Safety limit on sweeps of one network run (the run always terminates; see module doc).
MAX_SWEEPS = 100_000

_ARANGE = np.arange(1 << 12)  # offsets within a column window (reused)
#: Relative tolerance of the winner-take-all: costs this close are ties, won by the
#: first row, so that the winners do not follow last-bit noise of the inputs.
TIE_RTOL = 1e-9


def tie_tolerance(cost: np.ndarray) -> np.ndarray:
    """Per-row tolerance ``(R, 1)`` within which costs are ties (inf rows: 0)."""
    return _tolerance_of(cost.min(axis=1, keepdims=True))


def _tolerance_of(best: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(best), TIE_RTOL * np.maximum(np.abs(best), 1e-12), 0.0)


def improves(new: float, old: float) -> bool:
    """Whether energy ``new`` is lower than ``old`` by more than the tie tolerance
    (``TIE_RTOL`` times ``old``): the one test by which a search keeps a state, so that no
    state is taken on last-bit noise (and a search cannot cycle among equal energies)."""
    if not np.isfinite(old):  # any finite energy beats an unavailable chord
        return bool(new < old)
    return bool(new < old - TIE_RTOL * max(abs(old), 1e-12))


def winners(cost: np.ndarray) -> np.ndarray:
    """Per row, the first column whose cost is within :func:`tie_tolerance` of the
    row's minimum (the winner-take-all of Eq. 6, with deterministic ties)."""
    return _winners_and_tolerance(cost)[0]


def _winners_and_tolerance(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`winners` and the rows' :func:`tie_tolerance` ``(R,)``, from one minimum."""
    best = cost.min(axis=1)
    tol = _tolerance_of(best)
    return np.argmax(cost <= (best + tol)[:, None], axis=1), tol


def tie_groups(values: np.ndarray, tol: float) -> np.ndarray:
    """Per value of ``values`` (1-D), the rank of its group of ties: the finite values
    ascending in groups, each the values within ``tol`` of its least (the next group
    starts at the first value above that); -inf one group first, +inf and NaN one
    group last."""
    v = np.asarray(values, dtype=float)
    order = np.argsort(v, kind="stable")  # -inf, finite, +inf, NaN
    sv = v[order]
    group = np.empty(v.shape[0], dtype=np.int64)
    start = int(np.isneginf(sv).sum())
    end = start + int(np.isfinite(sv).sum())
    group[order[:start]] = 0
    g = 1 if start else 0
    while start < end:
        stop = start + int(np.searchsorted(sv[start:end], sv[start] + tol, side="right"))
        group[order[start:stop]] = g
        g, start = g + 1, stop
    group[order[end:]] = g
    return group


def tolerant_order(values: np.ndarray, tol: float) -> np.ndarray:
    """Indices that sort ``values`` (1-D) ascending, values within ``tol`` of the first of
    their group counting as ties, ordered by index: an order that does not follow last-bit
    noise (inf and NaN last, by index; -inf among them)."""
    v = np.asarray(values, dtype=float)
    groups = tie_groups(np.where(np.isneginf(v), np.inf, v), tol)
    return np.lexsort((np.arange(v.shape[0]), groups))


@dataclass(frozen=True)
class NetworkRun:
    """One run of the network from a given state until it no longer changes.

    Attributes:
        indices: Final vertex index of every column, shape ``(m,)``, ordered.
        energy: Final energy ``E = E_8 / 2`` (sum of chord deviations).
        sweeps: Number of sweeps, including the last one that changed nothing.
        energy_history: Energy before the first sweep and after every sweep, shape
            ``(sweeps + 1,)``; never increasing.
        max_span: Widest interval (in curve steps between the two neighbours) any column
            competed over; chords spanning ``max_span`` steps or more were never read.
    """

    indices: np.ndarray
    energy: float
    sweeps: int
    energy_history: np.ndarray
    max_span: int


# ------------------------------------------------------------------------ basics
def initial_state(
    points: object, m: int, *, closed: bool = False, phase: float = 0.0
) -> np.ndarray:
    """The paper's initial state (step 2): ``m`` points as equidistant as possible.

    Targets are spaced evenly in arc length (cumulative chord length, including the closing
    segment of a closed curve) and snapped to the nearest point along the curve (a target
    midway between two, within :data:`TIE_RTOL` of the length: the later); the indices
    are then made strictly increasing. Open curves keep both end points.

    Args:
        points: Curve points, shape ``(n, d)`` [length unit].
        m: Number of vertices, ``2 <= m <= n`` (``3 <= m`` if closed).
        closed: Closed curve (targets at ``(i + phase) * length / m``).
        phase: Closed curves only: shift of the targets, as a fraction of their spacing.

    Returns:
        Vertex indices, shape ``(m,)``, strictly increasing.

    Raises:
        InputError: bad ``points`` or ``m``.
    """
    P = as_array(points, "points", (None, None))
    n = P.shape[0]
    m = positive_int(m, "m", 3 if closed else 2)
    if m > n:
        raise InputError("m", f"{m} exceeds the number of points n={n}", f"m <= {n}")
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    if closed:
        seg = np.append(seg, np.linalg.norm(P[0] - P[-1]))
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0:  # all points coincide: fall back to index spacing
        cum = np.arange(cum.shape[0], dtype=float)
    total = cum[-1]
    if closed:
        cum = cum[:n]
        targets = (np.arange(m) + phase) / m * total
    else:
        targets = np.arange(m) / (m - 1) * total
    after = np.clip(np.searchsorted(cum, targets), 1, n - 1)
    # a target midway between two points (within the rounding of the arc lengths) snaps
    # to the later one: on evenly spaced points the last bits would decide otherwise
    tie = TIE_RTOL * total
    nearer_before = (targets - cum[after - 1]) < (cum[after] - targets) - tie
    idx = np.where(nearer_before, after - 1, after)
    return make_increasing(idx, n, closed)


def make_increasing(idx: np.ndarray, n: int, closed: bool) -> np.ndarray:
    """Clip ``idx`` so that it is strictly increasing within ``[0, n)`` (ends pinned if open)."""
    m = idx.shape[0]
    i = np.arange(m)
    idx = np.clip(np.asarray(idx, dtype=np.int64), i, n - m + i)
    idx = np.maximum.accumulate(idx - i) + i
    if not closed:
        idx[0], idx[-1] = 0, n - 1
    return idx


def polygon_energy(H: np.ndarray, indices: np.ndarray, *, closed: bool = False) -> float:
    """Energy ``E = E_8 / 2`` of a state: the sum of its chord deviations (Eq. 8).

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        indices: Vertex indices, shape ``(m,)``, ordered.
        closed: Include the closing chord from the last vertex back to the first.

    Returns:
        The energy (``inf`` if a chord is not available in ``H``).
    """
    s = np.asarray(indices)
    if closed:
        return float(H[s, np.roll(s, -1)].sum())
    return float(H[s[:-1], s[1:]].sum())


def network_input(
    H: np.ndarray, indices: np.ndarray, column: int, *, closed: bool = False
) -> np.ndarray:
    """Input ``U[x, i]`` of every neuron of one column (Eq. 10).

    ``U[x, i] = -(h[indices[i-1], x] + h[x, indices[i+1]])``; rows outside the interval
    between the two neighbours (which would break the vertex order) get ``-inf``.

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        indices: Current state, shape ``(m,)``.
        column: Column ``i``; for open curves ``1 <= i <= m - 2``.
        closed: Closed curve (cyclic neighbours, Eq. 5).

    Returns:
        ``U[:, i]``, shape ``(n,)``.
    """
    s = np.asarray(indices)
    m = s.shape[0]
    p, q = s[(column - 1) % m], s[(column + 1) % m]
    cost = _local_costs(H, H.T, np.array([p]), np.array([q]))[0]
    return -cost


def _local_costs(H: np.ndarray, HT: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``h[p, x] + h[x, q]`` for x strictly inside the cyclic interval (p, q), else inf.

    Shapes: ``p``, ``q`` ``(k,)`` -> ``(k, n)``.
    """
    n = H.shape[0]
    cost = H[p] + HT[q]
    offset = (np.arange(n)[None, :] - p[:, None]) % n
    span = ((q - p) % n)[:, None]
    inside = (offset > 0) & (offset < span)
    return np.where(inside, cost, np.inf)


def window_costs(
    H: np.ndarray, HT: np.ndarray, p: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Like :func:`_local_costs` but only over the interval.

    Returns ``(points (k, w), costs (k, w), widest span)`` with
    ``points[r, c] = (p[r] + 1 + c) mod n``; costs beyond a row's own interval are inf.
    """
    n = H.shape[0]
    span = q - p
    span %= n
    widest = int(span.max())
    width = max(widest - 1, 1)
    c = _ARANGE[:width] if width <= _ARANGE.shape[0] else np.arange(width)
    x = p[:, None] + c
    x += 1
    x %= n
    cost = np.take(H.reshape(-1), x + (p * n)[:, None])
    cost += np.take(HT.reshape(-1), x + (q * n)[:, None])
    cost[c >= (span - 1)[:, None]] = np.inf
    return x, cost, widest


@functools.lru_cache(maxsize=64)
def column_groups(m: int, closed: bool) -> list[np.ndarray]:
    """Sets of mutually non-adjacent free columns (updated together, then the next set)."""
    cols = np.arange(m) if closed else np.arange(1, m - 1)
    evens = cols[cols % 2 == 0]
    odds = cols[cols % 2 == 1]
    groups = [evens, odds]
    if closed and m % 2 == 1:  # column m-1 is adjacent to column 0
        groups = [evens[:-1], odds, evens[-1:]]
    return [g for g in groups if g.size]


# ------------------------------------------------------------------- the network
def run_network(
    H: np.ndarray,
    indices: object,
    *,
    closed: bool = False,
    max_sweeps: int = MAX_SWEEPS,
) -> NetworkRun:
    """Run the competitive network (steps 3-5 of the paper) until the state stops changing.

    Each sweep updates every free column once with the winner-take-all rule (Eq. 6) on its
    input (Eq. 10); a column moves only to a strictly better row, so the energy never
    rises (see the module docstring).

    Args:
        H: Deviation matrix, shape ``(n, n)`` (``inf`` marks unavailable chords).
        indices: Initial state, shape ``(m,)``, strictly increasing vertex indices.
        closed: Closed curve (cyclic columns); otherwise columns 0 and m-1 stay pinned.
        max_sweeps: Safety limit on the number of sweeps.

    Returns:
        The converged state with its energy history.

    Raises:
        InputError: ``H`` is not square or ``indices`` is not a valid state.
    """
    H = check_deviation_matrix(H)
    s = check_state(indices, H.shape[0], closed)
    return run_from(H, np.ascontiguousarray(H.T), s, closed, max_sweeps)


def run_from(
    H: np.ndarray, HT: np.ndarray, s: np.ndarray, closed: bool, max_sweeps: int
) -> NetworkRun:
    """:func:`run_network` without input checks (``HT`` is ``H.T`` made contiguous)."""
    s = s.copy()
    groups = column_groups(s.shape[0], closed)
    history = [polygon_energy(H, s, closed=closed)]
    sweeps, max_span = 0, 0
    for _ in range(max_sweeps):
        changed, span = _sweep(H, HT, s, groups)
        sweeps += 1
        max_span = max(max_span, span)
        history.append(polygon_energy(H, s, closed=closed))
        if not changed:
            break
    if closed:  # a column may have moved past index 0: relabel the columns cyclically
        s = np.sort(s)
    return NetworkRun(s, history[-1], sweeps, np.asarray(history), max_span)


def update_columns(H: np.ndarray, HT: np.ndarray, s: np.ndarray, cols: np.ndarray) -> tuple:
    """Winner-take-all update of non-adjacent columns ``cols`` in place.

    Returns (columns that moved, widest span competed over).
    """
    m, n = s.shape[0], H.shape[0]
    p, q = s[(cols - 1) % m], s[(cols + 1) % m]
    x, cost, span = window_costs(H, HT, p, q)  # -U (Eq. 10) over the interval
    win, tol = _winners_and_tolerance(cost)  # winner-take-all (Eq. 6), ties to the first row
    r = np.arange(cols.shape[0])
    cur = (s[cols] - p - 1) % n  # current row's position in the window
    # better by more than the tie tolerance only: E never rises, and noise never moves
    better = cost[r, win] < cost[r, cur] - tol
    moved = cols[better]
    s[moved] = x[r, win][better]
    return moved, span


def _sweep(H: np.ndarray, HT: np.ndarray, s: np.ndarray, groups: list[np.ndarray]) -> tuple:
    """One sweep in place; returns (whether any column moved, widest span competed over)."""
    changed, max_span = False, 0
    for cols in groups:
        moved, span = update_columns(H, HT, s, cols)
        max_span = max(max_span, span)
        changed = changed or moved.size > 0
    return changed, max_span


def check_deviation_matrix(H: object) -> np.ndarray:
    """Return ``H`` as a square float matrix (``n >= 2``) that may hold +inf but no NaN.

    Raises:
        InputError: wrong shape or NaN entries.
    """
    arr = as_array(H, "H", (None, None), finite=False)
    if arr.shape[0] != arr.shape[1] or arr.shape[0] < 2:
        raise InputError("H", f"has shape {arr.shape}", "a square (n, n) matrix with n >= 2")
    if np.isnan(arr).any():
        raise InputError("H", "contains NaN", "finite values or +inf")
    return arr


def check_state(indices: object, n: int, closed: bool, argument: str = "indices") -> np.ndarray:
    """Return ``indices`` as a valid network state for ``n`` points.

    A state is a strictly increasing int array of ``m`` vertex indices in ``[0, n)``
    (``2 <= m`` open, ``3 <= m`` closed); open curves start at 0 and end at ``n - 1``.

    Raises:
        InputError: naming ``argument``, if the state is not valid.
    """
    try:
        s = np.array(indices, dtype=np.int64).ravel()
    except (TypeError, ValueError):
        raise InputError(
            argument, f"{indices!r} is not an integer array", "vertex indices"
        ) from None
    m = s.shape[0]
    low = 3 if closed else 2
    if m < low or m > n:
        raise InputError(argument, f"has {m} vertices", f"{low} <= m <= n={n}")
    if s.min() < 0 or s.max() >= n or np.any(np.diff(s) <= 0):
        raise InputError(
            argument, "is not strictly increasing within [0, n)", f"ordered indices in [0, {n})"
        )
    if not closed and (s[0] != 0 or s[-1] != n - 1):
        raise InputError(
            argument, "does not start at 0 and end at n-1", "an open path keeps both ends"
        )
    return s


__all__ = [
    "MAX_SWEEPS",
    "NetworkRun",
    "check_deviation_matrix",
    "check_state",
    "column_groups",
    "improves",
    "initial_state",
    "make_increasing",
    "network_input",
    "polygon_energy",
    "run_from",
    "run_network",
    "tie_groups",
    "tolerant_order",
    "update_columns",
    "window_costs",
    "winners",
]
