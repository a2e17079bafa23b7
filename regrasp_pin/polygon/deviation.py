"""Arc-to-chord deviation matrices H for polygonal approximation (paper section 2.2).

For an ordered point sequence ``P = (p_0, ..., p_{n-1})`` the entry ``H[x, y]`` measures how
badly the chord ``p_x p_y`` represents the arc of the curve between its ends (Eq. 2,
Fig. 5). Every measure is built on the distance ``d(p, p_x p_y)`` of an arc point to the
straight line through the chord ends:

* ``"max"``: the largest distance of the arc's points to the chord (Eq. 7);
* ``"sum"``: the sum of those distances (the Araujo-Tanaka deviation of Fig. 5);
* ``"ise"``: the sum of squared distances (integral square error).

Only points strictly inside the arc count (the chord ends lie on the chord), so
neighbouring points give ``H[x, x + 1] = 0``. The diagonal is ``H[x, x] = inf`` (Eq. 7) for
every measure, and so is every chord whose two ends coincide (closer than
:data:`COINCIDENT_RTOL` times the curve's extent): digital curves repeat pixels (a
one-pixel-wide part is walked along both sides), and a zero-length chord has no line to
measure against and would give the polygon two vertices at one place, which Eq. 7 rules
out for one point. No entry is NaN. A deviation at or below :func:`zero_floor` (about
:data:`ZERO_RTOL` times the curve's size) is exactly 0: an arc on its chord costs
nothing wherever the curve lies, not rounding whose sign and size follow the
coordinates' last bits.

Open curves (a path from P to Q) only have forward arcs, ``H[x, y] = inf`` for ``y <= x``.
Closed curves use cyclic indices (Eq. 5): the arc from ``x`` to ``y`` runs through
``x + 1, x + 2, ...`` modulo ``n``, so ``H`` is not symmetric.

Cost: ``"ise"`` is O(n^2) from prefix sums of the coordinates and their products.
``"max"`` and ``"sum"`` need every (chord, arc point) pair, O(n^3); they are evaluated one
arc length at a time from cross-product tables, so that a pair costs three vectorized
passes. With ``cap`` (and ``m``) chords that provably cannot appear in a polygon of energy
``<= cap`` are skipped and marked ``inf``; that is what makes the polygon pipeline fast.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .._validate import as_array, choice, positive_int
from ..exceptions import InputError

#: Accepted deviation names.
DEVIATIONS: tuple[str, ...] = ("max", "sum", "ise")

_SUPPORTED_DIMS = (2, 3)
# Relative slack when comparing a lower bound with the cap (float rounding).
_CAP_RTOL = 1e-9
#: Points closer than this fraction of the curve's extent (largest coordinate range)
#: coincide: a chord between them is unavailable (``inf``), like the diagonal of Eq. 7.
COINCIDENT_RTOL = 1e-9
#: Deviations at or below this fraction of the curve's unit (:func:`zero_floor`) are
#: exactly 0: the arc lies on its chord, and what is left is rounding (a few times ``n``
#: machine epsilons of the unit). Without it the ties of a curve that runs straight
#: (energies of 0) would be decided by the last bits of the points' coordinates.
ZERO_RTOL = 1e-12


def validate_points(points: object, argument: str = "points") -> np.ndarray:
    """Return ``points`` as a finite ``(n, 2)`` or ``(n, 3)`` float array with ``n >= 2``.

    Raises:
        InputError: wrong shape, fewer than 2 points, or NaN/inf values.
    """
    given: Any = points
    try:
        ndim = np.ndim(given)
    except ValueError:  # ragged rows: as_array says so
        ndim = 2
    if ndim != 2:  # as_array would ask for "(N, N)"
        raise InputError(argument, f"has shape {np.shape(given)}", "shape (n, 2) or (n, 3)")
    arr = as_array(points, argument, (None, None))
    if arr.shape[1] not in _SUPPORTED_DIMS:
        raise InputError(argument, f"has shape {arr.shape}", "shape (n, 2) or (n, 3)")
    if arr.shape[0] < 2:
        raise InputError(argument, f"has {arr.shape[0]} point(s)", "at least 2 points")
    return arr


def deviation_matrix(
    points: object,
    deviation: str = "max",
    *,
    closed: bool = False,
    cap: float | None = None,
    m: int | None = None,
    max_span: int | None = None,
    min_span: int = 1,
) -> np.ndarray:
    """The connection matrix H of arc-to-chord deviations (Eqs. 2 and 7).

    Args:
        points: Ordered curve points, shape ``(n, 2)`` or ``(n, 3)`` [length unit].
        deviation: ``"max"`` (Eq. 7), ``"sum"`` (Araujo-Tanaka) or ``"ise"``.
        closed: Closed curve (cyclic indices, Eq. 5); otherwise an open path.
        cap: Optional energy bound. Chords that cannot appear in any polygon whose energy
            (sum of its chords' deviations) is ``<= cap`` are not evaluated and hold
            ``inf``. A chord is dropped when a lower bound of its deviation (the distance
            of the arc's middle point for ``"max"``/``"sum"``, the exact value for
            ``"ise"``) plus a lower bound of the cheapest cover of the rest of the curve
            by the polygon's other chords (``m - 1`` of them if closed, ``m - 2`` if open;
            see :func:`rest_lower_bound`) exceeds ``cap``.
            Every finite entry is exact. Pass the energy of any feasible polygon (e.g.
            the network's initial state) to get a matrix on which the optimum, and every
            polygon at least as good, is unchanged.
        m: Number of polygon vertices the cap refers to (tightens the pruning); without
            it only the chord's own lower bound is compared with ``cap``.
        max_span: Optional band: only chords spanning at most this many curve steps are
            evaluated, longer ones hold ``inf``. A solver whose vertices never compete
            over a wider span sees exactly the same numbers as with the full matrix.
        min_span: Chords spanning fewer steps hold ``inf`` (with ``max_span``, builds one
            band of spans; ``numpy.minimum`` of two bands is the matrix of their union).

    Returns:
        H, shape ``(n, n)``: ``H[x, y]`` is the deviation of the arc from point ``x``
        forward to point ``y`` [length unit for ``"max"``/``"sum"``, squared for
        ``"ise"``]; ``inf`` on the diagonal, for open curves when ``y < x``, and for
        pruned chords.

    Raises:
        InputError: bad ``points``, ``cap``, ``m`` or ``max_span``.
        UnknownNameError: unknown ``deviation``.
    """
    P = validate_points(points)
    deviation = choice(deviation, "deviation", DEVIATIONS)
    n = P.shape[0]
    if cap is not None:
        try:
            cap = float(cap)
        except (TypeError, ValueError):
            raise InputError("cap", f"{cap!r} is not a number", "a number >= 0 or None") from None
        if np.isnan(cap) or cap < 0:
            raise InputError("cap", f"{cap!r} is not allowed", "a number >= 0 or None")
    if m is not None:
        m = positive_int(m, "m", 2)
        if m > n:
            raise InputError("m", f"{m} exceeds the number of points n={n}", f"2 <= m <= {n}")
    if max_span is not None:
        max_span = positive_int(max_span, "max_span", 1)
    min_span = positive_int(min_span, "min_span", 1)
    return _Builder(P, closed).build(deviation, cap, m, max_span, min_span)


def chord_deviations(
    points: object,
    starts: object,
    ends: object,
    deviation: str = "max",
    *,
    closed: bool = False,
) -> np.ndarray:
    """Deviations of a few chords, computed directly from their arc points.

    Prices a given polygon without building H (e.g. the paper's initial state).

    Args:
        points: Curve points, shape ``(n, 2)`` or ``(n, 3)``.
        starts: Chord start indices, shape ``(k,)``.
        ends: Chord end indices, shape ``(k,)``; arcs run forward (modulo n if closed).
        deviation: ``"max"``, ``"sum"`` or ``"ise"``.
        closed: Closed curve.

    Returns:
        Deviations, shape ``(k,)``; ``inf`` where ``start == end`` (Eq. 7), where the two
        ends coincide (see :data:`COINCIDENT_RTOL`) and, for open curves, where
        ``end < start``.
    """
    P = validate_points(points)
    deviation = choice(deviation, "deviation", DEVIATIONS)
    n = P.shape[0]
    a: np.ndarray = np.asarray(starts, dtype=np.int64).ravel() % n
    b: np.ndarray = np.asarray(ends, dtype=np.int64).ravel() % n
    lengths = (b - a) % n if closed else b - a
    out = np.zeros(a.shape[0])
    gone = (lengths <= 0) | (_sq_norm(P[b] - P[a]) <= coincident_sq(P))
    out[gone] = np.inf
    inner = np.where((lengths > 1) & ~gone, lengths - 1, 0)
    if inner.sum() == 0:
        return out
    chord = np.repeat(np.arange(a.shape[0]), inner)
    first = np.cumsum(inner) - inner
    z = (a[chord] + np.arange(chord.shape[0]) - first[chord] + 1) % n
    d2 = point_line_sq(P[z], P[a[chord]], P[b[chord]])
    seg = np.flatnonzero(inner > 0)
    if deviation == "max":
        out[seg] = np.sqrt(np.maximum.reduceat(d2, first[seg]))
    elif deviation == "sum":
        out[seg] = np.add.reduceat(np.sqrt(d2), first[seg])
    else:
        out[seg] = np.add.reduceat(d2, first[seg])
    out[out <= zero_floor(deviation, P)] = 0.0  # on the chord (inf stays)
    return out


def deviation_unit(kind: str, scale: float, n: int) -> float:
    """The size of a deviation ``kind`` on a curve of ``n`` points within ``scale`` of
    their mean [length unit, squared for ``"ise"``]: one point's distance for ``"max"``,
    ``n`` of them for ``"sum"``, ``n`` squared distances for ``"ise"``."""
    return {"max": scale, "sum": scale * n, "ise": scale**2 * n}[kind]


def zero_floor(kind: str, P: np.ndarray) -> float:
    """The deviation ``kind`` at or below which an arc of curve ``P`` ``(n, d)`` lies on
    its chord [length unit, squared for ``"ise"``]: :data:`ZERO_RTOL` times the unit
    (:func:`deviation_unit`) of the points' spread about their mean, or for ``"max"``
    and ``"sum"`` of their distance from the origin if larger (centring the points
    rounds each by about that many machine epsilons, which those measures see to first
    order). For ``"ise"`` the floor is also what one point about ``1e-6 sqrt(n)`` of the
    spread off its chord costs: far below what the planner's paths read."""
    spread = float(np.abs(P - P.mean(axis=0)).max())
    size = spread if kind == "ise" else max(spread, float(np.abs(P).max()))
    return ZERO_RTOL * deviation_unit(kind, size, P.shape[0])


def coincident_sq(points: np.ndarray) -> float:
    """Squared distance [length^2] at or below which two points of ``points`` coincide."""
    extent = float(np.ptp(points, axis=0).max())
    return (COINCIDENT_RTOL * extent) ** 2


def _sq_norm(v: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", v, v)


def point_line_sq(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared distance of points ``p`` to the lines through ``a`` and ``b``, row by row.

    Uses ``|w x v|^2 / |w|^2`` (Lagrange identity over the coordinate planes), accurate
    near zero. Where ``a == b`` it is the squared distance to ``a``.

    Args:
        p: Points, shape ``(k, d)``.
        a: Line points, shape ``(k, d)``.
        b: Second line points, shape ``(k, d)``.

    Returns:
        Squared distances, shape ``(k,)`` [length^2].
    """
    v = p - a
    w = b - a
    ww = np.einsum("ij,ij->i", w, w)
    cross2 = np.zeros(p.shape[0])
    d = p.shape[1]
    for i in range(d):
        for j in range(i + 1, d):
            c = w[:, i] * v[:, j] - w[:, j] * v[:, i]
            cross2 += c * c
    vv = np.einsum("ij,ij->i", v, v)
    return np.where(ww > 0, cross2 / np.where(ww > 0, ww, 1.0), vv)


def rest_lower_bound(min_by_length: np.ndarray, chords: int, lengths: np.ndarray) -> np.ndarray:
    """Lower bound of the cheapest cover of ``lengths`` curve steps by ``chords`` chords.

    If every chord spanning ``L`` steps costs at least ``min_by_length[L]``, then ``k``
    chords whose spans add up to ``l`` cost at least ``k * g(l / k)``, where ``g`` is the
    lower convex minorant of ``min_by_length`` (Jensen's inequality).

    Args:
        min_by_length: Shape ``(n,)``; entry ``L`` bounds from below every chord spanning
            ``L`` steps (``inf`` if there is none); entry 0 is ignored.
        chords: Number of chords ``k >= 0``.
        lengths: Total spans to cover, any shape (integers >= 0).

    Returns:
        The bound, shape of ``lengths`` (``inf`` where no cover exists, 0 for ``k = 0``
        and length 0).
    """
    lengths = np.asarray(lengths, dtype=float)
    if chords == 0:
        return np.where(lengths == 0, 0.0, np.inf)
    L = np.arange(min_by_length.shape[0])
    ok = np.isfinite(min_by_length) & (L >= 1)
    if not ok.any():
        return np.full(lengths.shape, np.inf)
    hx, hy = _lower_hull(L[ok].astype(float), min_by_length[ok])
    u = lengths / chords
    out = chords * np.interp(u, hx, hy)
    out[(u < hx[0]) | (u > hx[-1])] = np.inf
    return out


def _lower_hull(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices of the lower convex hull of points sorted by ``x`` (monotone chain)."""
    hx: list[float] = []
    hy: list[float] = []
    for xi, yi in zip(x.tolist(), y.tolist(), strict=True):
        while (
            len(hx) >= 2
            and (hx[-1] - hx[-2]) * (yi - hy[-2]) - (hy[-1] - hy[-2]) * (xi - hx[-2]) <= 0
        ):
            hx.pop()
            hy.pop()
        hx.append(xi)
        hy.append(yi)
    return np.asarray(hx), np.asarray(hy)


class _Builder:
    """Builds H for one curve. Internally a chord is indexed by its start ``x`` and span ``L``.

    The offset form ``F[x, L] = H[x, (x + L) mod n]`` only holds spans ``L <= Lcap`` (the
    band), so a band-limited build costs O(n Lcap) memory and O(n Lcap^2) time.
    """

    def __init__(self, P: np.ndarray, closed: bool) -> None:
        self.n, self.d = P.shape
        self.closed = closed
        self.P = P - P.mean(axis=0)  # deviations are translation invariant
        self.scale = float(np.abs(self.P).max())
        self.zero = {kind: zero_floor(kind, P) for kind in DEVIATIONS}
        self.tiny2 = coincident_sq(P)
        self.P3 = np.concatenate([self.P, self.P, self.P])  # index i + n for i in [-n, 2n)
        self.planes = [(i, j) for i in range(self.d) for j in range(i + 1, self.d)]
        self._kind = "max"
        self._min_span = 1

    # -------------------------------------------------------------------- helpers
    def _window(self, coord: int, start: int, width: int, rows: int) -> np.ndarray:
        """View ``V[x, k] = P[(x + start + k) mod n, coord]``, shape ``(rows, width)``."""
        col = self.P3[:, coord]
        base = self.n + start
        return sliding_window_view(col[base : base + rows + width - 1], width)

    def _valid(self, ncols: int) -> np.ndarray:
        """Chords that exist, offset form ``(n, ncols)``: span >= 1, forward-only if open."""
        n = self.n
        L = np.arange(ncols)[None, :]
        valid = np.broadcast_to(L >= 1, (n, ncols)).copy()
        if not self.closed:
            valid &= (np.arange(n)[:, None] + L) < n
        return valid

    def _middle_lower_bound(self, ncols: int) -> np.ndarray:
        """Distance of each arc's middle point ``x + L // 2`` to its chord, ``(n, ncols)``.

        A lower bound of both the ``"max"`` and the ``"sum"`` deviation of the chord.
        """
        n = self.n
        half = (ncols + 1) // 2
        w = [self._window(c, 0, ncols, n) - self.P[:, c, None] for c in range(self.d)]
        v = [
            np.repeat(self._window(c, 0, half, n), 2, axis=1)[:, :ncols] - self.P[:, c, None]
            for c in range(self.d)
        ]
        cross2 = np.zeros((n, ncols))
        for i, j in self.planes:
            c = w[i] * v[j]
            c -= w[j] * v[i]
            c *= c
            cross2 += c
        ww = w[0] * w[0]
        for wc in w[1:]:
            ww += wc * wc
        # coincident ends (inf in H anyway): 0 keeps the chord here
        lb = np.sqrt(np.divide(cross2, ww, out=np.zeros((n, ncols)), where=ww > 0))
        lb[:, :2] = 0.0
        return lb

    def _coincident(self, ncols: int) -> np.ndarray:
        """Chords whose two ends coincide, offset form ``(n, ncols)``."""
        ww = np.zeros((self.n, ncols))
        for c in range(self.d):
            wc = self._window(c, 0, ncols, self.n) - self.P[:, c, None]
            ww += wc * wc
        return ww <= self.tiny2

    def _keep(self, lower: np.ndarray, valid: np.ndarray, cap: float, m: int | None) -> np.ndarray:
        """Chords that may appear in a polygon of energy <= cap, offset form."""
        n, ncols = lower.shape
        unit = deviation_unit(self._kind, self.scale, n)
        budget = np.full(ncols, cap + _CAP_RTOL * (cap + unit))
        if m is not None:
            min_by_length = np.where(valid, lower, np.inf).min(axis=0)
            others = m - 1 if self.closed else m - 2
            total = n if self.closed else n - 1
            budget = budget - rest_lower_bound(min_by_length, others, total - np.arange(ncols))
        return valid & (lower <= budget[None, :])

    # ---------------------------------------------------------------------- build
    def build(
        self,
        kind: str,
        cap: float | None,
        m: int | None,
        max_span: int | None,
        min_span: int = 1,
    ) -> np.ndarray:
        """H for deviation ``kind`` with optional pruning (see :func:`deviation_matrix`)."""
        self._kind = kind
        n = self.n
        ncols = n if max_span is None else min(n, max_span + 1)
        prune = cap is not None and np.isfinite(cap)
        valid = self._valid(ncols)
        self._min_span = min_span
        keep: np.ndarray | None = None
        if kind == "ise":
            F = self._ise(ncols, valid)
            if prune:
                assert cap is not None
                keep = self._keep(F, valid, cap, m)
        else:
            F = np.full((n, ncols), np.inf)
            F[:, 1] = 0.0
            if prune and n >= 3:
                assert cap is not None
                keep = self._keep(self._middle_lower_bound(ncols), valid, cap, m)
            self._max_or_sum(F, kind, keep)
        F[F <= self.zero[kind]] = 0.0  # the arc on its chord: rounding, not deviation
        F[~(valid if keep is None else keep)] = np.inf
        F[self._coincident(ncols)] = np.inf  # zero-length chords, like h_xx (Eq. 7)
        F[:, :min_span] = np.inf
        return self._assemble(F)

    def _assemble(self, F: np.ndarray) -> np.ndarray:
        """``H[x, (x + L) mod n] = F[x, L]``, written one strided diagonal per span."""
        n, ncols = F.shape
        H = np.full((n, n), np.inf)
        flat = H.reshape(-1)
        for L in range(1, ncols):
            flat[L : (n - L) * n : n + 1] = F[: n - L, L]
            if self.closed:
                flat[(n - L) * n :: n + 1] = F[n - L :, L]
        return H

    # ----------------------------------------------------------- ISE, O(n^2) total
    def _ise(self, ncols: int, valid: np.ndarray) -> np.ndarray:
        """Sum of squared distances to the chord line over every arc, offset form.

        For a coordinate plane ``(i, j)`` and chord vector ``w`` from ``a = p_x``:
        ``sum_z (w_i (p_zj - a_j) - w_j (p_zi - a_i))^2`` expands into prefix sums of
        ``p``, ``p_i p_j``; the planes add up to ``sum_z |w x (p_z - a)|^2`` and dividing by
        ``|w|^2`` gives the sum of squared distances.
        """
        n, d = self.n, self.d
        P2 = np.concatenate([self.P, self.P])
        zero = np.zeros(1)
        cum1 = [np.concatenate([zero, np.cumsum(P2[:, i])]) for i in range(d)]
        cum2 = {
            (i, j): np.concatenate([zero, np.cumsum(P2[:, i] * P2[:, j])])
            for i in range(d)
            for j in range(i, d)
        }

        def arc_sum(S: np.ndarray) -> np.ndarray:
            # sum over the interior points x+1 .. x+L-1 = S[x + L] - S[x + 1]
            return sliding_window_view(S[: n + ncols - 1], ncols) - S[1 : n + 1, None]

        k = np.maximum(np.arange(ncols) - 1, 0).astype(float)[None, :]
        a = self.P
        s1 = [arc_sum(cum1[i]) for i in range(d)]
        w = [self._window(i, 0, ncols, n) - a[:, i, None] for i in range(d)]
        ww = w[0] * w[0]
        for wc in w[1:]:
            ww += wc * wc
        total = np.zeros((n, ncols))
        for i, j in self.planes:
            c = w[i] * a[:, j, None]
            c -= w[j] * a[:, i, None]
            lin = w[i] * s1[j]
            lin -= w[j] * s1[i]
            quad = (w[i] * w[i]) * arc_sum(cum2[(j, j)])
            quad -= (2.0 * w[i] * w[j]) * arc_sum(cum2[(i, j)])
            quad += (w[j] * w[j]) * arc_sum(cum2[(i, i)])
            quad -= 2.0 * c * lin
            quad += k * c * c
            total += quad
        np.maximum(total, 0.0, out=total)
        F = np.divide(total, ww, out=np.zeros((n, ncols)), where=ww > 0)
        F[:, :2] = 0.0
        F[~valid] = np.inf
        return F

    # -------------------------------------------------- MAX / SUM, O(n^3) total
    def _max_or_sum(self, F: np.ndarray, kind: str, keep: np.ndarray | None) -> None:
        """Fill ``F[x, L]`` for (kept) chords with ``L >= 2``, one span ``L`` at a time.

        With ``K[a, b] = p_a[i] p_b[j] - p_a[j] p_b[i]`` (coordinate plane ``(i, j)``) the
        plane component of ``(p_y - p_x) x (p_z - p_x)`` is ``K[x, y] + K[y, z] - K[x, z]``
        (bilinearity), so each arc point costs one table lookup and one subtraction; the
        distance is ``|(p_y - p_x) x (p_z - p_x)| / |p_y - p_x|``. Tables are stored with the
        arc offset as the leading axis so that the reduction over arc points runs over
        contiguous rows.
        """
        n, ncols = F.shape
        first = max(2, self._min_span)
        if keep is None:
            spans = np.arange(first, ncols)
        else:
            spans = np.flatnonzero(keep[:, first:].any(axis=0)) + first
        if spans.size == 0:
            return
        Lmax = int(spans[-1])
        tables, inv_len = self._cross_tables(Lmax)
        buf = np.empty((Lmax, n))
        for L in spans.tolist():
            sel = self._span_rows(L, keep)
            if sel is None:
                continue
            rows, back, kr = sel
            vals = self._span_values(tables, rows, back, L, Lmax, kind, buf)
            vals *= inv_len[rows, L]
            if kr is not None:
                vals[~kr] = np.inf
            F[rows, L] = vals

    def _cross_tables(self, Lmax: int) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
        """Per coordinate plane ``(KfT, KzT)`` (see :meth:`_max_or_sum`) up to span
        ``Lmax``, and ``(n, Lmax + 1)`` 1 / chord length (0 for coincident ends, which
        are set to inf afterwards)."""
        n = self.n
        tables = []
        for i, j in self.planes:
            xi, xj = self.P[:, i], self.P[:, j]
            # KfT[k, x] = K[x, x + k], k = 0 .. Lmax
            KfT = xi[None, :] * self._window(j, 0, Lmax + 1, n).T
            KfT -= xj[None, :] * self._window(i, 0, Lmax + 1, n).T
            # KzT[c, y] = K[y, y - Lmax + c], y in [0, 2n), c = 0 .. Lmax
            yi = np.concatenate([xi, xi])[None, :]
            yj = np.concatenate([xj, xj])[None, :]
            KzT = yi * self._window(j, -Lmax, Lmax + 1, 2 * n).T
            KzT -= yj * self._window(i, -Lmax, Lmax + 1, 2 * n).T
            tables.append((KfT, KzT))
        ww = np.zeros((n, Lmax + 1))
        for c in range(self.d):
            wc = self._window(c, 0, Lmax + 1, n) - self.P[:, c, None]
            ww += wc * wc
        inv_len = np.divide(1.0, np.sqrt(ww), out=np.zeros_like(ww), where=ww > 0)
        return tables, inv_len

    def _span_rows(
        self, L: int, keep: np.ndarray | None
    ) -> tuple[slice | np.ndarray, slice | np.ndarray, np.ndarray | None] | None:
        """The chords of span ``L`` to fill: ``(rows, rows + L, mask of kept rows or
        None)``, a slice when most rows are kept; None when none is."""
        R = self.n if self.closed else self.n - L
        if keep is None:
            return slice(0, R), slice(L, L + R), None
        kr = keep[:R, L]
        cnt = int(np.count_nonzero(kr))
        if cnt == 0:
            return None
        if cnt <= 0.6 * R:
            rows = np.flatnonzero(kr)
            return rows, rows + L, None
        return slice(0, R), slice(L, L + R), kr

    @staticmethod
    def _span_values(
        tables: list[tuple[np.ndarray, np.ndarray]],
        rows: slice | np.ndarray,
        back: slice | np.ndarray,
        L: int,
        Lmax: int,
        kind: str,
        buf: np.ndarray,
    ) -> np.ndarray:
        """MAX or SUM of the arc points' distances times the chord length, per chord."""
        lo_c = Lmax - L + 1
        width = (rows.stop - rows.start) if isinstance(rows, slice) else rows.shape[0]
        if len(tables) == 1:
            KfT, KzT = tables[0]
            t = buf[: L - 1, :width]
            np.subtract(KzT[lo_c:Lmax, back], KfT[1:L, rows], out=t)  # K[y,z] - K[x,z]
            c0 = KfT[L, rows]  # K[x, y]
            if kind == "max":
                hi = np.maximum.reduce(t, axis=0)
                lo = np.minimum.reduce(t, axis=0)
                return np.maximum(c0 + hi, -(c0 + lo))
            t += c0
            np.abs(t, out=t)
            return t.sum(axis=0)
        acc = np.zeros((L - 1, width))
        for KfT, KzT in tables:
            t = KzT[lo_c:Lmax, back] - KfT[1:L, rows]
            t += KfT[L, rows]
            t *= t
            acc += t
        if kind == "max":
            return np.sqrt(acc.max(axis=0))
        np.sqrt(acc, out=acc)
        return acc.sum(axis=0)
