"""Further moves of the competitive network: block winner-take-all, group relocations,
annealed sweeps (and the tie-break of :func:`spread_ties`).

They act on the same state (one vertex index per column) and the same inputs (Eq. 10) as
:mod:`regrasp_pin.polygon.hopfield`:

* **Block winner-take-all** (:func:`update_block`): ``k`` consecutive columns compete
  jointly, the way one column competes in Eq. 6. Given the two columns around the block,
  the block's share of the energy is ``h[p, x_1] + h[x_1, x_2] + ... + h[x_k, q]``, and the
  block takes the joint state that minimizes it (a small dynamic programme over the points
  between ``p`` and ``q``), only if it is strictly better. As for one column, the energy
  never rises. With ``k = 1`` this is Eq. 6 itself; larger blocks see moves that single
  columns cannot make one at a time (several vertices shifting together).
* **Group relocations** (:func:`group_relocations`): a run of consecutive columns is
  removed and as many vertices are put jointly into another chord (its best subdivision,
  :func:`subdivisions`, the same dynamic programme); a proposal, re-converged by the network
  and kept by the search only if the energy drops.
* **Annealed winner-take-all** (:func:`annealed_sweeps`): the winner of each column is drawn
  from the Boltzmann distribution of its inputs at a temperature ``T`` (``argmax`` of
  ``U / T`` plus Gumbel noise, seeded), ``T`` falling geometrically to almost 0. The energy
  may rise during these sweeps; they only produce a new initial state, from which the
  deterministic network converges again, and the result is kept only if its energy is
  lower than the best so far. At ``T -> 0`` the rule is Eq. 6.
"""

from __future__ import annotations

import numpy as np

from .hopfield import (
    TIE_RTOL,
    column_groups,
    polygon_energy,
    tie_tolerance,
    tolerant_order,
    window_costs,
    winners,
)

#: Default reach of a column in a block move [curve steps]: bounds a block's work to
#: ``k (2 BLOCK_RADIUS + 1)^2`` on long curves; short curves compete over all points.
BLOCK_RADIUS = 24


def min_plus(cost: np.ndarray, step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One step of a shortest-path dynamic programme: for every column ``y`` of ``step``,
    ``min_x cost[x] + step[x, y]``, won by the first row ``x`` within the tie tolerance of
    the minimum (:func:`~.hopfield.winners`). Returns (the new costs, the winning rows)."""
    total = cost[:, None] + step
    best = total.min(axis=0)
    threshold = np.abs(best)
    np.maximum(threshold, 1e-12, out=threshold)
    threshold *= TIE_RTOL
    threshold += best  # inf where best is inf: every row "wins", the first is taken
    arg = np.argmax(total <= threshold, axis=0)
    return total[arg, np.arange(arg.shape[0])], arg


def block_costs(
    H: np.ndarray, p: int, q: int, current: np.ndarray, radius: int | None = None
) -> tuple[float, np.ndarray | None]:
    """Best joint state of the ``k`` consecutive columns between vertices ``p`` and ``q``.

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        p: Vertex of the column before the block.
        q: Vertex of the column after the block (cyclic: the interval runs forward from
            ``p`` to ``q`` modulo ``n``).
        current: The block's current vertices, shape ``(k,)``, in order inside the interval.
        radius: If given, column ``j`` only competes over the points within ``radius``
            curve steps of its current vertex (bounds the work to ``k (2 radius + 1)^2``).

    Returns:
        (the block's share of the energy, its ``k`` vertices in order), or ``(inf, None)``
        when no joint state has a finite energy. Ties go to the earliest points (relative
        tolerance, see :func:`~.hopfield.winners`).
    """
    n = H.shape[0]
    k = current.shape[0]
    w = (q - p) % n - 1
    if w < k:
        return np.inf, None
    off = (current - p - 1) % n  # positions in the interval, 0 .. w-1
    if radius is None or 2 * radius + 1 >= w:
        cand = [np.arange(w)] * k
    else:
        cand = [np.arange(max(o - radius, 0), min(o + radius + 1, w)) for o in off.tolist()]
    X = [(p + 1 + c) % n for c in cand]
    cost = H[p, X[0]]
    back = []
    same = radius is None or 2 * radius + 1 >= w  # every column over the whole interval
    for j in range(1, k):
        if j == 1 or not same:
            step = H[X[j - 1][:, None], X[j][None, :]]
            step[cand[j - 1][:, None] >= cand[j][None, :]] = np.inf
        cost, arg = min_plus(cost, step)
        back.append(arg)
    total = cost + H[X[-1], q]
    y = int(winners(total[None, :])[0])
    if not np.isfinite(total[y]):
        return np.inf, None
    pos = [y]
    for arg in reversed(back):
        pos.append(int(arg[pos[-1]]))
    pos = pos[::-1]
    return float(total[y]), np.array([X[j][pos[j]] for j in range(k)])


def update_block(
    H: np.ndarray,
    s: np.ndarray,
    first: int,
    k: int,
    radius: int | None = None,
    cache: dict | None = None,
) -> bool:
    """Block winner-take-all of columns ``first .. first + k - 1`` (cyclic) in place.

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        s: State, shape ``(m,)``; ``k <= m - 2`` so that the block has two outside
            neighbours (on an open curve the block must not include column 0 or m-1).
        first: First column of the block.
        k: Block size.
        radius: See :func:`block_costs`.
        cache: Results of :func:`block_costs` already computed on this ``H`` with this
            ``radius`` (filled in): the block's best state depends only on ``p``, ``q``,
            ``k`` and, if the radius is narrower than the interval, the current vertices.

    Returns:
        Whether the block moved (only to a strictly better joint state: the energy never
        rises).
    """
    m = s.shape[0]
    cols = (first + np.arange(k)) % m
    p, q = int(s[(first - 1) % m]), int(s[(first + k) % m])
    chain = np.concatenate([[p], s[cols], [q]])
    current = float(H[chain[:-1], chain[1:]].sum())
    narrow = radius is not None and 2 * radius + 1 < (q - p) % H.shape[0] - 1
    key = (p, q, k, s[cols].tobytes() if narrow else b"")
    if cache is not None and key in cache:
        best, pos = cache[key]
    else:
        best, pos = block_costs(H, p, q, s[cols], radius)
        if cache is not None:
            cache[key] = (best, pos)
    if pos is None:
        return False
    tol = tie_tolerance(np.array([[best]]))[0, 0]
    if not best < current - tol:
        return False
    s[cols] = pos
    return True


def block_pass(
    H: np.ndarray,
    s: np.ndarray,
    k: int,
    closed: bool,
    radius: int | None = BLOCK_RADIUS,
    cache: dict | None = None,
) -> bool:
    """One pass of block updates over every block of ``k`` consecutive free columns
    (each column within ``radius`` curve steps of its vertex, see :func:`block_costs`;
    ``cache``: see :func:`update_block`).

    Returns:
        Whether any block moved. ``s`` is updated in place; on a closed curve it stays a
        cyclic rotation of an increasing sequence (sort it afterwards).
    """
    m = s.shape[0]
    k = min(k, m - 2)
    if k < 2:
        return False
    firsts = range(m) if closed else range(1, m - k)
    moved = False
    for i in firsts:
        moved |= update_block(H, s, i, k, radius, cache)
    return moved


def annealed_sweeps(
    H: np.ndarray,
    HT: np.ndarray,
    s: np.ndarray,
    closed: bool,
    rng: np.random.Generator,
    temperatures: np.ndarray,
) -> np.ndarray:
    """Sweeps of the annealed winner-take-all from state ``s``; returns the new state.

    In each sweep every free column (non-adjacent columns together) takes the row that
    maximizes ``U[x, i] / T + g`` with Gumbel noise ``g``: a draw from the Boltzmann
    distribution ``exp(U / T)`` over the rows between its neighbours.

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        HT: ``H.T`` made contiguous.
        s: State, shape ``(m,)``.
        closed: Closed curve.
        rng: Seeded generator (the draws).
        temperatures: One temperature per sweep [energy unit of H], e.g. falling.

    Returns:
        The state after the sweeps, shape ``(m,)``, increasing.
    """
    s = s.copy()
    m = s.shape[0]
    groups = column_groups(m, closed)
    for T in temperatures.tolist():
        for cols in groups:
            p, q = s[(cols - 1) % m], s[(cols + 1) % m]
            x, cost, _span = window_costs(H, HT, p, q)
            noisy = cost - T * rng.gumbel(size=cost.shape)
            win = np.argmin(noisy, axis=1)
            ok = np.isfinite(cost[np.arange(cols.size), win])
            s[cols[ok]] = x[np.arange(cols.size), win][ok]
    return np.sort(s) if closed else s


__all__ = [
    "BLOCK_RADIUS",
    "annealed_sweeps",
    "block_costs",
    "block_pass",
    "group_relocations",
    "min_plus",
    "spread_ties",
    "subdivision_vertices",
    "subdivisions",
    "update_block",
]


def spread_ties(
    H: np.ndarray, s: np.ndarray, points: np.ndarray, *, closed: bool, sweeps: int = 5
) -> np.ndarray:
    """Move each vertex, among the positions that cost its two chords no more (ties
    within :data:`~.hopfield.TIE_RTOL` of the polygon's energy), to the one nearest the
    arc-length midpoint of its neighbours (of positions as near within ``1e-12`` of the
    arc's length, the first): the tie-break toward spread-out vertices.

    The ``"max"`` measure (Eq. 7) makes a chord between adjacent points free, so its
    optima are degenerate (vertices may bunch up); the others have ties too where the
    curve runs straight (a vertex anywhere on a straight stretch costs the same). This
    keeps the energy (all moves together raise it by at most ``TIE_RTOL`` times itself:
    one budget, so that ties do not follow last-bit noise and the energy cannot creep)
    and spreads the vertices out; no move follows the last bits of ``H`` or of the
    arc lengths (ties between positions go to the first). Columns are visited in order,
    ``sweeps`` times at most (until nothing moves: a long plateau may be left before its
    vertices are evenly spread); an open path's end columns stay.

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        s: State, shape ``(m,)``, ordered.
        points: The curve, shape ``(n, d)`` (for the arc lengths).
        closed: Closed curve.
        sweeps: Most passes over the columns.

    Returns:
        The new state, shape ``(m,)``.
    """
    s = np.array(s, dtype=np.int64)
    n, m = H.shape[0], s.shape[0]
    seg = np.linalg.norm(np.diff(points, axis=0, append=points[:1]), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])  # arc[n]: the whole closed length
    energy = polygon_energy(H, s, closed=closed)
    tol = TIE_RTOL * float(np.maximum(abs(energy), 1e-12))
    eps = 1e-12 * float(np.maximum(arc[n], 1e-12))  # a move must get nearer by this

    def along(x: np.ndarray, p: int) -> np.ndarray:  # arc length from p, forward
        d = arc[x] - arc[p]
        return d % arc[n] if closed else d

    cols = range(m) if closed else range(1, m - 1)
    for _ in range(sweeps):
        moved = False
        for i in cols:
            p, q = int(s[i - 1]), int(s[(i + 1) % m])
            width = (q - p) % n - 1 if closed else q - p - 1
            if width < 2:
                continue
            xs = (p + 1 + np.arange(width)) % n
            half = float(along(np.array([q]), p)[0]) / 2.0
            current = float(H[p, s[i]] + H[s[i], q])
            cost = H[p, xs] + H[xs, q]
            miss = np.where(cost <= current + tol, np.abs(along(xs, p) - half), np.inf)
            best = float(miss.min())
            j = int(np.argmax(miss <= best + eps))  # ties within eps: the first
            here = abs(float(along(np.array([s[i]]), p)[0]) - half)
            # nearer by more than eps, or as near (a tie): the first of the nearest
            if xs[j] != s[i] and (miss[j] < here - eps or here <= best + eps):
                tol -= max(float(cost[j]) - current, 0.0)  # one budget for all moves
                s[i] = xs[j]
                moved = True
        if not moved:
            break
    if closed:
        s = np.sort(s)
    return s


def subdivisions(H: np.ndarray, a: int, b: int, kmax: int) -> tuple[np.ndarray, list]:
    """Best cost of the chord ``(a, b)`` subdivided by ``k = 0 .. kmax`` vertices of its arc.

    Returns:
        (costs, shape ``(kmax + 1,)``, inf where the arc has fewer than ``k`` points;
        back-pointers to recover the vertices with :func:`subdivision_vertices`).
    """
    n = H.shape[0]
    w = (b - a) % n - 1
    costs = np.full(kmax + 1, np.inf)
    costs[0] = H[a, b]
    X = (a + 1 + np.arange(max(w, 0))) % n
    if w < 1 or kmax < 1:
        return costs, [X]
    cost = H[a, X]  # one vertex, at each arc point
    ends: list[int] = [0]  # the last vertex of the best subdivision by k (k = 0: none)
    back: list = [X]
    step = H[X[:, None], X[None, :]]
    step[np.tri(w, dtype=bool)] = np.inf  # the vertices in order along the arc
    for k in range(1, min(kmax, w) + 1):
        if k > 1:
            cost, arg = min_plus(cost, step)  # previous vertex (rows), this one (columns)
            back.append(arg)
        final = cost + H[X, b]
        j = int(winners(final[None, :])[0])
        costs[k] = final[j]
        ends.append(j)
    back.append(ends)
    return costs, back


def subdivision_vertices(back: list, k: int) -> np.ndarray:
    """The ``k`` vertices of the best subdivision found by :func:`subdivisions`."""
    X, ends = back[0], back[-1]
    if k == 0:
        return np.zeros(0, dtype=np.int64)
    pos = [int(ends[k])]
    for j in range(k - 1, 0, -1):
        pos.append(int(back[j][pos[-1]]))
    return X[np.array(pos[::-1])]


def group_relocations(
    H: np.ndarray, s: np.ndarray, closed: bool, rmax: int, count: int, runs: int = 3
) -> list[tuple[float, np.ndarray]]:
    """The ``count`` most promising moves of a run of vertices into another chord.

    A run of ``r <= rmax`` consecutive columns is removed (its chords merge into one) and
    ``r`` vertices are inserted into the other chord whose best subdivision by ``r``
    vertices (:func:`subdivisions`, the vertices placed jointly) gains most. For every
    ``r`` the ``runs`` runs cheapest to remove are tried. With ``"max"`` a curved arc
    costs nothing only once enough vertices sit on it, so one vertex at a time gains
    nothing there; the vertices have to move together.

    Args:
        H: Deviation matrix, shape ``(n, n)``.
        s: State, shape ``(m,)``, ordered.
        closed: Closed curve (an open path's end columns stay).
        rmax: Most vertices moved together.
        count: Moves returned.
        runs: Runs tried per size.

    Returns:
        ``[(predicted energy change, new state), ...]``, most promising first (ties within
        :data:`~.hopfield.TIE_RTOL` of the energy: in the order found).
    """
    m = s.shape[0]
    nc = m if closed else m - 1
    a, b = s[:nc], s[(np.arange(nc) + 1) % m]
    chord = H[a, b]
    tol = TIE_RTOL * max(float(np.abs(chord[np.isfinite(chord)]).sum()), 1e-12)
    subs = [subdivisions(H, int(a[j]), int(b[j]), rmax) for j in range(nc)]
    with np.errstate(invalid="ignore"):
        ins = np.array([c for c, _ in subs]) - chord[:, None]  # (nc, rmax + 1)
    ins[~np.isfinite(ins)] = np.inf
    moves: list[tuple[float, np.ndarray]] = []
    for r in range(1, min(rmax, m - 3 if closed else m - 2) + 1):
        # removing columns i .. i + r - 1 merges chords i - 1 .. i + r - 1 into one
        first = np.arange(m) if closed else np.arange(1, m - r)
        merged = (first[:, None] - 1 + np.arange(r + 1)) % nc
        with np.errstate(invalid="ignore"):
            rem = H[s[(first - 1) % m], s[(first + r) % m]] - chord[merged].sum(axis=1)
        targets = tolerant_order(ins[:, r], tol)[: r + 2].tolist()  # best chords for r
        for t in tolerant_order(rem, tol)[:runs].tolist():
            if not np.isfinite(rem[t]):
                break
            hit = set(merged[t].tolist())
            j = next((j for j in targets if j not in hit), None)
            if j is None or not np.isfinite(ins[j, r]):
                continue
            kept = np.delete(s, (first[t] + np.arange(r)) % m)
            added = subdivision_vertices(subs[j][1], r)
            moves.append((float(rem[t] + ins[j, r]), np.sort(np.concatenate([kept, added]))))
    order = tolerant_order(np.array([g for g, _ in moves]), tol)[:count]
    return [moves[k] for k in order.tolist()]
