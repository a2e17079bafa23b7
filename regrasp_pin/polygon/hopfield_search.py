"""Restarts, perturbations and local search around the competitive Hopfield network.

Closing the gap to the optimum (a departure from the paper): the plain network stops in a
local minimum. :func:`competitive_hopfield` keeps the plain run from the paper's initial
state and then tries more initial states (on closed curves the equidistant state shifted
by half a spacing, a greedy bottom-up merge, a greedy top-down split) and perturbations
(one or two columns' vertices relocated to other chords; several columns removed and
greedily re-inserted; blocks of consecutive columns competing jointly, runs of columns
moved together into other chords, and annealed runs of the winner-take-all,
:mod:`regrasp_pin.polygon.hopfield_moves`; on closed curves the best state turned along
the curve), each followed by re-convergence of the same network. A result is
accepted only if its energy is lower, so the answer is never worse than the plain network.

The network itself (states, input, energy, sweeps) is :mod:`regrasp_pin.polygon.hopfield`.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .._validate import positive_int
from ..exceptions import InputError
from .hopfield import (
    MAX_SWEEPS,
    TIE_RTOL,
    NetworkRun,
    check_deviation_matrix,
    check_state,
    column_groups,
    improves,
    initial_state,
    make_increasing,
    polygon_energy,
    run_from,
    tie_groups,
    update_columns,
    window_costs,
    winners,
)
from .hopfield_moves import annealed_sweeps, block_pass, group_relocations

logger = logging.getLogger(__name__)

# Annealed restarts: start temperature as a fraction of the mean chord energy, final
# temperature as a fraction of the start, and sweeps per anneal.
_ANNEAL_T0 = 1.0
_ANNEAL_T1 = 1e-3
_ANNEAL_SWEEPS = 40
# Largest block of consecutive columns that compete jointly, and the longest curve on
# which block moves are made by default.
_BLOCK_MAX = 8
_BLOCK_MAX_POINTS = 200
# Turned starts: the best state shifted along a closed curve by 1/_TURNS of its points,
# 2/_TURNS, ... (where block moves are made).
_TURNS = 4


@dataclass(frozen=True)
class HopfieldResult:
    """Result of :func:`competitive_hopfield`.

    Attributes:
        indices: Best vertex indices found, shape ``(m,)``, ordered.
        energy: Their energy (sum of chord deviations).
        sweeps: Total sweeps over all network runs.
        energy_history: The plain run's energies (before and after each sweep), followed by
            the best energy after each further initial state or perturbation round;
            never increasing.
        plain_indices: Result of the plain network from the paper's initial state, ``(m,)``.
        plain_energy: Its energy; ``energy <= plain_energy`` always.
        plain_sweeps: Sweeps of the plain run.
        plain_max_span: ``max_span`` of the plain run (see :class:`NetworkRun`).
    """

    indices: np.ndarray
    energy: float
    sweeps: int
    energy_history: np.ndarray
    plain_indices: np.ndarray
    plain_energy: float
    plain_sweeps: int
    plain_max_span: int


# ------------------------------------------------ improvement: starts and moves
def _gain_tolerance(H: np.ndarray, s: np.ndarray, closed: bool) -> float:
    """The tolerance within which energy changes of moves from state ``s`` are ties:
    :data:`~.hopfield.TIE_RTOL` times its energy (a change is a difference of chord
    costs, each at most the energy, so its rounding is relative to the energy, not to
    the change; a change of about 0 on a straight stretch is a tie, not noise's sign)."""
    energy = polygon_energy(H, s, closed=closed)
    return TIE_RTOL * (abs(energy) if np.isfinite(energy) else 0.0) + 1e-300


def _first_least(values: np.ndarray, tol: float) -> int:
    """The first index whose value is within ``tol`` of the least (:func:`_ranked`)."""
    return int(_ranked(values, tol)[0])


def _ranked(values: np.ndarray, tol: float) -> np.ndarray:
    """Indices of ``values`` (1-D), least first, values within ``tol`` of their group's
    least ties in index order (:func:`~.hopfield.tie_groups`): as
    :func:`~.hopfield.tolerant_order`, but -inf first (an unavailable chord's split,
    the best move), +inf and NaN last."""
    return np.lexsort((np.arange(len(values)), tie_groups(values, tol)))


def _best(values: np.ndarray, count: int, tol: float) -> np.ndarray:
    """The first ``count`` of :func:`_ranked`, ranking only the values that can be among
    them (those within ``tol`` of the ``count``-th least): the same indices."""
    v = np.asarray(values, dtype=float)
    if count < v.shape[0]:
        kth = np.partition(v, count - 1)[count - 1]
        near = np.flatnonzero(~(v > kth + tol))  # NaN kth: keep all
        return near[_ranked(v[near], tol)][:count]
    return _ranked(v, tol)[:count]


def _chords(s: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    return (s, np.append(s[1:], s[0])) if closed else (s[:-1], s[1:])


def _insertion(
    H: np.ndarray, HT: np.ndarray, s: np.ndarray, closed: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best point to insert into every chord: (point, new local cost, current chord cost)."""
    a, b = _chords(s, closed)
    pts, cost, _span = window_costs(H, HT, a, b)
    j = winners(cost)
    r = np.arange(a.shape[0])
    return pts[r, j], cost[r, j], H[a, b]


def _split_gain(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    """Energy change of splitting chords; unavailable (inf) chords are split first, no NaN."""
    gain = np.full(new.shape, np.inf)
    fin = np.isfinite(old) & np.isfinite(new)
    gain[fin] = new[fin] - old[fin]
    must = ~np.isfinite(old) & np.isfinite(new)
    gain[must] = -np.inf
    return gain


def _relocations(
    H: np.ndarray, HT: np.ndarray, s: np.ndarray, closed: bool, count: int
) -> list[tuple[float, np.ndarray]]:
    """The ``count`` best moves of one or two vertices into other chords: (energy change,
    state), best first.

    Removing vertex ``i`` and inserting the best point of a chord not adjacent to it changes
    the energy by the sum of the two exact local changes.
    """
    m = s.shape[0]
    x, new, old = _insertion(H, HT, s, closed)
    gain_ins = _split_gain(new, old)  # chord j = (s[j], s[j+1])
    i = np.arange(m)
    prev, nxt = s[i - 1], s[(i + 1) % m]
    with np.errstate(invalid="ignore"):
        gain_rem = H[prev, nxt] - H[prev, s] - H[s, nxt]
    gain_rem = np.where(np.isfinite(gain_rem), gain_rem, np.inf)
    if not closed:
        gain_rem[0] = gain_rem[-1] = np.inf
    with np.errstate(invalid="ignore"):  # inf + -inf: NaN, never among the best
        total = gain_rem[:, None] + gain_ins[None, :]
    # inserting into a chord adjacent to the removed vertex is a plain network move
    nc = total.shape[1]
    total[i, i % nc] = np.inf
    total[i, (i - 1) % nc] = np.inf
    flat = total.ravel()
    count = min(count, flat.shape[0])
    tol = _gain_tolerance(H, s, closed)
    moves = []
    for k in _best(flat, count, tol).tolist():
        if np.isfinite(flat[k]):
            ri, cj = divmod(k, nc)
            moves.append((float(flat[k]), np.sort(np.append(np.delete(s, ri), x[cj]))))
    moves += _pair_relocations(H, s, closed, x, gain_ins, count, tol)
    order = _best(np.array([g for g, _ in moves]), count, tol).tolist() if moves else []
    return [moves[k] for k in order]


def _pair_relocations(
    H: np.ndarray,
    s: np.ndarray,
    closed: bool,
    x: np.ndarray,
    gain_ins: np.ndarray,
    count: int,
    tol: float,
) -> list[tuple[float, np.ndarray]]:
    """The ``count`` best moves of two neighbouring vertices into two other chords
    (energy changes within ``tol`` are ties, taken in index order).

    Removing vertices ``i, i+1`` merges three chords into one; with ``"max"`` a long chord
    costs little more than a short one, so this is how spare vertices get parked.
    """
    m, nc = s.shape[0], gain_ins.shape[0]
    if m < (4 if closed else 5) or nc < 5:
        return []
    i = np.arange(m) if closed else np.arange(1, m - 2)
    a, b, c, d = s[(i - 1) % m], s[i], s[(i + 1) % m], s[(i + 2) % m]
    with np.errstate(invalid="ignore"):
        gain_rem = H[a, d] - H[a, b] - H[b, c] - H[c, d]
    order = _best(gain_ins, 5, tol)
    moves = []
    for k in _best(np.where(np.isfinite(gain_rem), gain_rem, np.inf), count, tol).tolist():
        if not np.isfinite(gain_rem[k]):
            break
        r = int(i[k])
        hit = {(r - 1) % nc, r % nc, (r + 1) % nc}  # chords replaced by the merge
        free = [j for j in order.tolist() if j not in hit][:2]
        if len(free) < 2:
            continue
        gain = float(gain_rem[k] + gain_ins[free[0]] + gain_ins[free[1]])
        if not np.isfinite(gain):
            continue
        kept = np.delete(s, [r, (r + 1) % m])
        moves.append((gain, np.sort(np.concatenate([kept, x[free]]))))
    return moves


def _insert_greedy(
    H: np.ndarray, HT: np.ndarray, s: np.ndarray, closed: bool, count: int
) -> np.ndarray | None:
    """Insert ``count`` vertices one by one, each at the best split; None if impossible."""
    for _ in range(count):
        x, new, old = _insertion(H, HT, s, closed)
        gain = _split_gain(new, old)
        if np.isneginf(gain).any():  # an unavailable chord: split it at its cheapest point
            cand = np.where(np.isneginf(gain), new, np.inf)
            j = _first_least(cand, TIE_RTOL * float(np.min(np.abs(cand))) + 1e-300)
        else:
            j = _first_least(gain, _gain_tolerance(H, s, closed))
            if not np.isfinite(gain[j]):
                return None
        s = np.sort(np.append(s, x[j]))
    return s


def _converge(
    H: np.ndarray,
    HT: np.ndarray,
    s: np.ndarray,
    groups: list[np.ndarray],
    closed: bool,
    dirty: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Run the network until no column moves (in place); returns (state, sweeps).

    Only columns whose neighbours moved since their last update (``dirty``) can change,
    so only those compete; a sweep visits each column group once.
    """
    m = s.shape[0]
    dirty = np.ones(m, dtype=bool) if dirty is None else dirty.copy()
    if not closed:
        dirty[0] = dirty[-1] = False
    sweeps = 0
    while dirty.any():
        sweeps += 1
        for g in groups:
            cols = g[dirty[g]]
            if cols.size == 0:
                continue
            moved, _span = update_columns(H, HT, s, cols)
            dirty[cols] = False
            if moved.size:
                dirty[(moved - 1) % m] = True
                dirty[(moved + 1) % m] = True
                if not closed:
                    dirty[0] = dirty[-1] = False
    return (np.sort(s) if closed else s), sweeps


def _changed_columns(old: np.ndarray, new: np.ndarray, n: int) -> np.ndarray:
    """Columns of ``new`` whose vertex or neighbours differ from ``old`` (cyclic)."""
    k, j = np.arange(old.shape[0]), np.arange(new.shape[0])
    prev_old = np.full(n, -1)
    next_old = np.full(n, -1)
    prev_old[old] = old[k - 1]
    next_old[old] = old[(k + 1) % k.shape[0]]
    return (prev_old[new] != new[j - 1]) | (next_old[new] != new[(j + 1) % j.shape[0]])


def _local_search(
    H: np.ndarray,
    HT: np.ndarray,
    s: np.ndarray,
    closed: bool,
    trials: int = 2,
    budget: int = 10_000,
    block: int = 0,
    memo: dict | None = None,
    blocks: dict | None = None,
) -> tuple[np.ndarray, float, int]:
    """Network convergence alternated with vertex relocations; returns (state, energy, sweeps).

    After the network has converged, the ``trials`` most promising relocations of one
    vertex to another chord are tried, each followed by re-convergence; the first that ends
    lower (by more than the tie tolerance, :func:`~.hopfield.improves`: no walk along
    plateaus of equal energy) is kept. When no relocation helps, blocks of ``block``
    consecutive columns compete jointly (:func:`~.hopfield_moves.block_pass`; 0 or 1: no
    block moves), and when that does not help either, the ``trials`` most promising moves
    of a run of up to ``block`` consecutive vertices into another chord are tried
    (:func:`~.hopfield_moves.group_relocations`).

    The search is a deterministic function of the converged state it stands on, so
    ``memo`` (one dict per ``H``) maps every such state already searched to where the
    search ended: reaching one again ends the search there at once, with the same result.
    ``blocks`` (one dict per ``H``) likewise keeps the block updates already computed.
    """
    groups = column_groups(s.shape[0], closed)
    s, sweeps = _converge(H, HT, s.copy(), groups, closed)
    energy = polygon_energy(H, s, closed=closed)
    n = H.shape[0]
    memo = {} if memo is None else memo
    visited: list[tuple] = []

    def first_better(moves: list[tuple[float, np.ndarray]]) -> np.ndarray | None:
        """The first move that, re-converged, ends lower than ``energy`` (ties, a move
        along a plateau, are not taken)."""
        nonlocal sweeps
        for _gain, moved in moves:
            dirty = _changed_columns(s, moved, n)
            moved, sw = _converge(H, HT, moved, groups, closed, dirty)
            sweeps += sw
            if improves(polygon_energy(H, moved, closed=closed), energy):
                return moved
        return None

    for _ in range(budget):
        key = (block, trials, s.tobytes())
        if key in memo:
            s, energy = memo[key]
            s = s.copy()
            break
        visited.append(key)
        better = first_better(_relocations(H, HT, s, closed, trials))
        if better is None and block > 1:
            moved = s.copy()
            if block_pass(H, moved, block, closed, cache=blocks):
                sweeps += 1
                better = first_better([(0.0, np.sort(moved) if closed else moved)])
        if better is None and block > 1:
            better = first_better(group_relocations(H, s, closed, block, trials))
        if better is None:
            break
        s, energy = better, polygon_energy(H, better, closed=closed)
    for key in visited:
        memo[key] = (s, energy)
    return s, energy, sweeps


def _greedy_merge(H: np.ndarray, m: int, closed: bool) -> np.ndarray | None:
    """Bottom-up start: from all points, repeatedly drop the vertices cheapest to remove.

    Each round selects the cheapest half of the surplus and drops every other vertex of each
    run of adjacent selected ones (so no two dropped vertices are neighbours).
    """
    n = H.shape[0]
    s = np.arange(n)
    while s.shape[0] > m:
        k = s.shape[0]
        idx = np.arange(k)
        prev, nxt = s[idx - 1], s[(idx + 1) % k]
        with np.errstate(invalid="ignore"):
            cost = H[prev, nxt] - H[prev, s] - H[s, nxt]
        cost = np.where(np.isfinite(cost), cost, np.inf)
        if not closed:
            cost[0] = cost[-1] = np.inf
        # rank by cost (a difference of chord costs: ties within the tie tolerance of
        # the largest merged chord's), ties broken by a fixed scrambled order
        merged = H[prev, nxt]
        scale = float(np.abs(merged[np.isfinite(merged)]).max(initial=0.0))
        prio = (idx * 2654435761) % 4294967296
        rank = np.empty(k, dtype=np.int64)
        rank[np.lexsort((prio, tie_groups(cost, TIE_RTOL * scale + 1e-300)))] = idx
        take = max(1, (k - m) // 2)
        sel = (rank < take) & np.isfinite(cost)
        if not sel.any():
            return None
        # within each run of consecutive selected vertices keep every other one
        pos = np.flatnonzero(sel)
        run_start = np.concatenate([[True], np.diff(pos) > 1])
        first = np.maximum.accumulate(np.where(run_start, np.arange(pos.size), 0))
        drop = pos[(np.arange(pos.size) - first) % 2 == 0]
        if closed and drop.size > 1 and drop[0] == 0 and drop[-1] == k - 1:
            drop = drop[:-1]
        s = np.delete(s, drop)
    return s


def _greedy_split(H: np.ndarray, HT: np.ndarray, m: int, closed: bool) -> np.ndarray | None:
    """Top-down start: repeatedly insert the vertex that lowers the energy most.

    It starts from the fewest evenly spaced (by index) vertices whose chords are all
    available in ``H``.
    """
    n = H.shape[0]
    low = 3 if closed else 2
    for k in range(low, m + 1):
        grid = np.linspace(0, n if closed else n - 1, k, endpoint=not closed)
        s = make_increasing(np.round(grid).astype(np.int64), n, closed)
        if np.isfinite(polygon_energy(H, s, closed=closed)):
            return _insert_greedy(H, HT, s, closed, m - k)
    return None


def _grown(
    H: np.ndarray,
    HT: np.ndarray,
    points: np.ndarray,
    m: int,
    closed: bool,
    trials: int,
    memo: dict,
) -> np.ndarray | None:
    """Growing start: the network from the paper's equidistant state with the fewest
    vertices (3 closed, 2 open), polished by the local search (no block moves), then one
    vertex inserted at the best split, and so on up to ``m`` vertices (polished like every
    start by :func:`competitive_hopfield`).

    With few vertices the network places the long chords; each added vertex goes where it
    helps most and the network re-converges around it. This finds the ``"max"`` optima
    made of one or two long chords across the curve and many vertices on straight runs
    (zero-cost chords), which a network started with all ``m`` vertices spread out misses.
    """
    s: np.ndarray | None = initial_state(points, 3 if closed else 2, closed=closed)
    while s is not None:
        k = s.shape[0]
        if k == m:
            break
        s, _energy, _sweeps = _local_search(H, HT, s, closed, trials, memo=memo)
        s = _insert_greedy(H, HT, s, closed, 1)
    return s


def _starts(
    H: np.ndarray,
    HT: np.ndarray,
    plain: np.ndarray,
    points: np.ndarray,
    closed: bool,
    trials: int,
    block: int,
    memo: dict,
) -> Iterator[np.ndarray | None]:
    """The deterministic initial states, in order (each made when it is needed): the plain
    network's result, the equidistant state shifted by half a spacing (closed curves), the
    greedy merge and split, and, where block moves are made (``block > 1``: the search
    can afford it), the growing start (:func:`_grown`)."""
    m = plain.shape[0]
    yield plain
    if closed:
        yield initial_state(points, m, closed=True, phase=0.5)
    yield _greedy_merge(H, m, closed)
    yield _greedy_split(H, HT, m, closed)
    if block > 1:
        yield _grown(H, HT, points, m, closed, trials, memo)


def _perturbed(
    H: np.ndarray,
    HT: np.ndarray,
    s: np.ndarray,
    closed: bool,
    rng: np.random.Generator,
    free: np.ndarray,
) -> np.ndarray | None:
    """A perturbation of state ``s``: a few columns (a random set, or a run of consecutive
    ones up to most of them) removed and re-inserted greedily."""
    if rng.random() < 0.5:  # a run of consecutive columns, up to most of them
        k = int(rng.integers(1, max(1, (2 * free.size) // 3) + 1))
        start = int(rng.integers(0, free.size))
        drop = free[(start + np.arange(k)) % free.size]
    else:
        k = int(rng.integers(1, max(1, free.size // 3) + 1))
        drop = rng.choice(free, size=k, replace=False)
    return _insert_greedy(H, HT, np.delete(s, drop), closed, k)


def _lower_bound(value: float | None) -> float | None:
    """``lower_bound`` checked (finite or None) and lowered by a few ulps, so that an
    optimum whose energy was summed in another order than the network's never stops
    the search above a state it could still keep."""
    if value is None:
        return None
    if not np.isfinite(value):
        raise InputError("lower_bound", f"{value!r} is not finite", "a finite energy or None")
    return float(value) - 8.0 * np.finfo(float).eps * abs(float(value))


def _later_starts(
    H: np.ndarray,
    HT: np.ndarray,
    best: Callable[[], tuple[np.ndarray, float]],
    closed: bool,
    rng: np.random.Generator,
    *,
    restarts: int,
    turns: bool,
    anneals: int,
) -> Iterator[np.ndarray | None]:
    """The initial states made from the best state so far (``best()`` when each is
    needed): ``restarts`` perturbations, then, with ``turns``, that state turned by a
    quarter, a half and three quarters of the curve, then ``anneals`` annealed runs."""
    n = H.shape[0]
    m = best()[0].shape[0]
    free = np.arange(m) if closed else np.arange(1, m - 1)
    for _ in range(restarts):
        if free.size == 0 or not np.isfinite(best()[1]):
            break
        yield _perturbed(H, HT, best()[0], closed, rng, free)
    for j in range(1, _TURNS if turns else 1):
        yield np.sort((best()[0] + (j * n) // _TURNS) % n)
    for _ in range(anneals if np.isfinite(best()[1]) else 0):
        s, e = best()
        t0 = _ANNEAL_T0 * e / m  # a typical chord's share of the energy
        temps = np.geomspace(max(t0, 1e-300), max(t0 * _ANNEAL_T1, 1e-300), _ANNEAL_SWEEPS)
        yield annealed_sweeps(H, HT, s, closed, rng, temps)


def default_block(n: int, m: int, closed: bool = True) -> int:
    """Block size of the block winner-take-all for ``n`` points and ``m`` vertices.

    ``min(8, m // 2)`` (at least half of the columns stay outside any one block) on closed
    curves of up to 200 points; 0 (no block moves) on longer ones, where the block moves
    would cost several times the rest of the search, and on open paths: the planner's
    finger paths, where they cost 1.5-3x the search (n = 40-150, m = 7-13) for energies
    already within a few per cent of the optimum.
    """
    return min(_BLOCK_MAX, m // 2) if closed and n <= _BLOCK_MAX_POINTS else 0


def competitive_hopfield(
    H: np.ndarray,
    m: int,
    *,
    closed: bool = False,
    initial: object = None,
    points: object = None,
    restarts: int = 6,
    seed: int = 0,
    plain: NetworkRun | None = None,
    trials: int = 2,
    block: int | None = None,
    anneals: int = 0,
    lower_bound: float | None = None,
) -> HopfieldResult:
    """Polygonal approximation with the competitive Hopfield network, plus restarts.

    First the plain network of the paper runs from its initial state (``initial``, or the
    equidistant state of :func:`initial_state`). Then, to escape its local minimum, the
    same network is re-converged from further states: the equidistant state shifted by half
    a spacing (closed curves), a greedy bottom-up merge, a greedy top-down split, where
    block moves are made the growing start, then ``restarts`` rounds of perturbation
    (remove a few vertices, re-insert them greedily) and, where block moves are made, the
    best state so far turned along the closed curve by a quarter, a half and three quarters
    of its points (the whole polygon moved as one block: a minimum whose vertices are
    packed on the wrong stretch of the curve cannot move there a few columns at a time).
    Only strictly better results are kept, so the answer is never worse than the plain
    network.

    Every state is polished by a local search: the network converges, then the ``trials``
    most promising relocations of one vertex to another chord are tried, each followed by
    re-convergence; the first that lowers the energy is kept and the search repeats. When
    none helps, blocks of ``block`` consecutive columns compete jointly
    (:mod:`~regrasp_pin.polygon.hopfield_moves`; the energy never rises) and the search
    repeats if one moved; if none did, runs of up to ``block`` consecutive vertices are
    moved together into another chord (the ``trials`` most promising, each
    re-converged and kept only if the energy drops). ``anneals`` annealed runs of the
    winner-take-all from the best state give further initial states.

    Args:
        H: Deviation matrix, shape ``(n, n)``; ``inf`` marks chords that may not be used.
        m: Number of vertices (``2 <= m <= n``; ``3 <= m`` if closed).
        closed: Closed curve.
        initial: Initial state, shape ``(m,)``; default: equidistant along ``points`` (or
            along the index if ``points`` is None).
        points: Curve points ``(n, d)`` used for the equidistant initial states.
        restarts: Number of perturbation rounds after the deterministic starts (0: none).
        seed: Seed of the perturbation draws.
        plain: The plain run from ``initial`` if already computed on this ``H`` (it is then
            not repeated).
        trials: Relocations tried (with re-convergence) when no single move helps.
        block: Columns per block of the block winner-take-all, and most vertices moved
            together by a group relocation (0 or 1: neither, and no turned starts); default
            :func:`default_block`.
        anneals: Annealed runs from the best state (40 sweeps each, the temperature
            falling from the mean chord energy to 1/1000 of it).
        lower_bound: An energy no state on ``H`` goes below (the optimum of
            :func:`~regrasp_pin.polygon.exact.exact_polygon`). The search stops once its
            best state is within the tie tolerance of it: no later state could be kept
            (:func:`~regrasp_pin.polygon.hopfield.improves`), so the result is the same,
            with fewer sweeps and a shorter energy record. Finite (or None).

    Returns:
        The best state, the plain network's result and the sweep/energy record.

    Raises:
        InputError: invalid ``H``, ``m``, ``initial``, ``restarts``, ``trials``,
            ``block``, ``anneals`` or ``lower_bound``.
    """
    H = check_deviation_matrix(H)
    n = H.shape[0]
    m = positive_int(m, "m", 3 if closed else 2)
    if m > n:
        raise InputError("m", f"{m} exceeds the number of points n={n}", f"m <= {n}")
    restarts = positive_int(restarts, "restarts", 0)
    trials = positive_int(trials, "trials", 0)
    block = positive_int(default_block(n, m, closed) if block is None else block, "block", 0)
    anneals = positive_int(anneals, "anneals", 0)
    bound = _lower_bound(lower_bound)
    pts = (
        np.arange(n, dtype=float)[:, None] * np.array([[1.0, 0.0]])
        if points is None
        else np.asarray(points, dtype=float)
    )
    if initial is None:
        initial = initial_state(pts, m, closed=closed)
    HT = np.ascontiguousarray(H.T)
    if plain is None:
        plain = run_from(H, HT, check_state(initial, n, closed), closed, MAX_SWEEPS)
    best_s, best_e = plain.indices, plain.energy
    history = list(plain.energy_history)
    sweeps = plain.sweeps

    memo: dict = {}  # converged states already searched -> where the search ended
    blocks: dict = {}  # block updates already computed

    def consider(s: np.ndarray | None) -> None:
        nonlocal best_s, best_e, sweeps
        if s is not None and s.shape[0] == m:
            s2, e2, sw = _local_search(
                H, HT, s, closed, trials, block=block, memo=memo, blocks=blocks
            )
            sweeps += sw
            if improves(e2, best_e):
                best_s, best_e = s2, e2
        history.append(best_e)

    def best() -> tuple[np.ndarray, float]:
        return best_s, best_e

    rng = np.random.default_rng(seed)
    later = _later_starts(
        H, HT, best, closed, rng, restarts=restarts, turns=closed and block > 1, anneals=anneals
    )

    def unbeatable() -> bool:  # no state can be kept any more: the search is over
        return bound is not None and not improves(bound, best_e)

    starts = itertools.chain(_starts(H, HT, plain.indices, pts, closed, trials, block, memo), later)
    for start in () if unbeatable() else starts:
        consider(start)
        if unbeatable():
            break  # before the next start is made
    logger.debug("hopfield: plain %.6g -> best %.6g (%d sweeps)", plain.energy, best_e, sweeps)
    return HopfieldResult(
        indices=np.asarray(best_s),
        energy=float(best_e),
        sweeps=sweeps,
        energy_history=np.asarray(history),
        plain_indices=plain.indices,
        plain_energy=plain.energy,
        plain_sweeps=plain.sweeps,
        plain_max_span=plain.max_span,
    )
