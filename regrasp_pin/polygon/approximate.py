"""Polygonal approximation of a curve: the public entry point (paper section 2.2, Fig. 8).

:func:`approximate_polygon` reduces an ordered point sequence (a path on the object's
surface grid, or any 2-D/3-D curve) to ``m`` vertices that minimize the sum of the chord
deviations, with the paper's competitive Hopfield network (:mod:`regrasp_pin.polygon.hopfield`) or
the exact dynamic-programming optimum (:mod:`regrasp_pin.polygon.exact`).

Pipeline for ``method="hopfield"``: the paper's initial state (equidistant vertices) is
built first; H (:mod:`regrasp_pin.polygon.deviation`) is then computed only for chords spanning up
to a few times the widest gap of that state (a band); the network runs on it. If the plain
network ever competed over a wider span than the band, H is rebuilt in full and the network
rerun, so the plain network always sees exactly the numbers of the full matrix. The further
restarts (:func:`~regrasp_pin.polygon.hopfield_search.competitive_hopfield`) search within the band.

For ``method="exact"`` the network result is the incumbent; the chords longer than the band
that can still appear in a polygon at least as good (pruning with ``cap`` and ``m``) are
added to H, and the DP returns the global optimum.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from .._validate import choice, positive_int
from ..exceptions import InputError
from .deviation import (
    COINCIDENT_RTOL,
    DEVIATIONS,
    coincident_sq,
    deviation_matrix,
    validate_points,
)
from .exact import exact_polygon
from .hopfield import NetworkRun, initial_state, polygon_energy, run_network
from .hopfield_moves import spread_ties
from .hopfield_search import competitive_hopfield

logger = logging.getLogger(__name__)

#: Accepted method names.
METHODS: tuple[str, ...] = ("hopfield", "exact")

# Full H below this many (chord, arc point) pairs; otherwise a band around the initial gaps.
_FULL_PAIRS = 1_500_000
_BAND_FACTOR = 3


@dataclass(frozen=True)
class PolygonResult:
    """A polygonal approximation of a curve.

    Attributes:
        indices: Vertex indices into the input points, shape ``(m,)``, 0-based, ascending
            (cyclic order for closed curves; open curves start at 0 and end at n-1).
        vertices: The vertex points, shape ``(m, d)`` [input length unit].
        energy: Sum of the chord deviations: over the m-1 chords of an open curve, over all
            m chords (including the closing one) of a closed curve [length unit for
            ``"max"``/``"sum"``, squared for ``"ise"``]. This is Eq. 8 divided by 2.
        method: ``"hopfield"`` or ``"exact"``.
        deviation: ``"max"``, ``"sum"`` or ``"ise"``.
        closed: Whether the curve was treated as closed.
        sweeps: Network sweeps performed (all runs); 0 for ``"exact"``.
        energy_history: Network energies: before and after each sweep of the plain run, then
            the best energy after each restart; never increasing. Empty for ``"exact"``.
        n: Number of input points.
        m: Number of vertices.
        plain_energy: Energy of the plain network from the paper's initial state
            (``energy <= plain_energy``).
        timings_ms: Wall-clock time of the stages [ms]: ``"H"`` (the matrix the network
            uses, including any widening of its band), ``"network"`` (plain run and
            restarts) and, for ``"exact"``, ``"exact"`` (pruned H and the DP).
    """

    indices: np.ndarray
    vertices: np.ndarray
    energy: float
    method: str
    deviation: str
    closed: bool
    sweeps: int
    energy_history: np.ndarray = field(repr=False)
    n: int
    m: int
    plain_energy: float
    timings_ms: dict[str, float] = field(default_factory=dict, compare=False)


def validate_m(m: object, n: int, closed: bool) -> int:
    """Return ``m`` if it is a valid vertex count for ``n`` points.

    Raises:
        InputError: ``m`` is not an integer, ``m < 2`` (open) / ``m < 3`` (closed), or
            ``m > n``.
    """
    low = 3 if closed else 2
    kind = "a closed" if closed else "an open"
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)):
        raise InputError("m", f"{m!r} is not an integer", f"an integer {low} <= m <= n={n}")
    if m < low:
        raise InputError("m", f"{m} is too small for {kind} curve", f"{low} <= m <= n={n}")
    if m > n:
        raise InputError("m", f"{m} exceeds the number of points n={n}", f"{low} <= m <= {n}")
    return int(m)


def _refuse_degenerate(P: np.ndarray, m: int, closed: bool) -> None:
    """InputError for a curve with fewer than ``m`` distinct points (all points equal
    included): ``m`` vertices would repeat a point, i.e. a chord of zero length, which H
    does not offer (:data:`~regrasp_pin.polygon.deviation.COINCIDENT_RTOL`). Points closer
    than that fraction of the curve's extent count as one. The same for an open path whose
    two ends coincide and ``m = 2`` (its only chord would have zero length)."""
    extent = float(np.ptp(P, axis=0).max())
    if extent == 0.0:
        raise InputError("points", f"all {P.shape[0]} points are equal", "a curve with extent")
    distinct = np.unique(np.round((P - P.min(axis=0)) / (COINCIDENT_RTOL * extent)), axis=0)
    if distinct.shape[0] < m:
        raise InputError(
            "points",
            f"has {distinct.shape[0]} distinct points for m={m}",
            f"at least m={m} distinct points",
        )
    if not closed and m == 2 and np.sum((P[-1] - P[0]) ** 2) <= coincident_sq(P):
        raise InputError(
            "m", "2 joins the first and last points, which coincide", "m >= 3 for this path"
        )


def approximate_polygon(
    points: object,
    m: int,
    *,
    closed: bool = False,
    deviation: str = "max",
    method: str = "hopfield",
    seed: int = 0,
    restarts: int = 6,
    full_matrix: bool = False,
    stop_at_optimum: bool = False,
) -> PolygonResult:
    """Approximate an ordered curve by ``m`` of its points (Fig. 8).

    Args:
        points: Ordered curve points, shape ``(n, 2)`` or ``(n, 3)`` [length unit].
        m: Number of polygon vertices (``2 <= m <= n`` open, ``3 <= m <= n`` closed).
        closed: Closed curve (cyclic indices, Eq. 5); otherwise a path from the first to
            the last point, both kept as vertices.
        deviation: Arc-to-chord deviation: ``"max"`` (Eq. 7, the paper's), ``"sum"`` or
            ``"ise"``; see :mod:`regrasp_pin.polygon.deviation`.
        method: ``"hopfield"`` (competitive network with restarts) or ``"exact"`` (DP).
        seed: Seed of the network's perturbation rounds.
        restarts: Perturbation rounds of the network (0 = plain network + deterministic
            starts only).
        full_matrix: Give the network the full H instead of a band of chord spans around
            the initial gaps. Slower (O(n^3) for ``"max"``/``"sum"``), but the restarts can
            then use long chords, which the ``"max"`` optimum often does on curves that fold
            back (spirals, lattice paths). The plain network is the same either way.
        stop_at_optimum: On an open path, solve the network's band of H exactly first
            (:func:`exact_polygon`) and stop the network's restarts once they reach that
            optimum: the same result with fewer sweeps. It pays on short paths (the
            planner's, n = 40-150 and m = 7-13: the search about halves), not on long
            ones (n = 500, m = 20: the dynamic programme alone costs more than the
            network). Ignored on closed curves and with ``method="exact"``.

    Returns:
        The vertices, their indices and energy, and the network record.

    Raises:
        InputError: bad ``points`` (shape, fewer than 2, NaN/inf, all equal, fewer
            distinct points than ``m``), ``m`` (also ``m = 2`` on an open path whose ends
            coincide), ``seed`` or ``restarts``.
        UnknownNameError: unknown ``deviation`` or ``method``.

    A straight curve (all points collinear) deviates from every chord by 0: any ``m``
    vertices are optimal (energy 0) and the ones returned are the network's (or the
    exact solver's) first, spread out among the ties
    (:func:`~regrasp_pin.polygon.hopfield_moves.spread_ties`).
    """
    P = validate_points(points)
    n = P.shape[0]
    deviation = choice(deviation, "deviation", DEVIATIONS)
    method = choice(method, "method", METHODS)
    m = validate_m(m, n, closed)
    _refuse_degenerate(P, m, closed)
    seed = positive_int(seed, "seed", 0)
    restarts = positive_int(restarts, "restarts", 0)

    clock = time.perf_counter
    t0 = clock()
    s0 = initial_state(P, m, closed=closed)
    band = None if full_matrix else network_band(s0, n, closed)
    H = deviation_matrix(P, deviation, closed=closed, max_span=band)
    t_h, t_net = clock() - t0, 0.0
    t0 = clock()
    plain = run_network(H, s0, closed=closed)
    # a column competing between neighbours p and q reads chords spanning < q - p steps
    while band is not None and plain.max_span - 1 > band:
        # the plain network competed over spans outside the band: widen it and rerun, so
        # that the plain network sees exactly the full matrix
        widest = max(plain.max_span, int(1.5 * band))
        wider = None if widest >= n - 1 else widest
        logger.debug("plain network needed span %d > band %d", plain.max_span - 1, band)
        t_net += clock() - t0
        t0 = clock()
        extra = deviation_matrix(P, deviation, closed=closed, max_span=wider, min_span=band + 1)
        H = np.minimum(H, extra)
        band = wider
        t_h += clock() - t0
        t0 = clock()
        plain = run_network(H, s0, closed=closed)
    hop = competitive_hopfield(
        H,
        m,
        closed=closed,
        initial=s0,
        points=P,
        restarts=restarts,
        seed=seed,
        plain=plain,
        lower_bound=(
            _optimum(H, m, plain)
            if stop_at_optimum and not closed and method == "hopfield"
            else None
        ),
    )
    t_net += clock() - t0
    timings = {"H": t_h * 1e3, "network": t_net * 1e3}
    Hx = H
    if method == "hopfield":
        idx, energy = hop.indices, hop.energy
        sweeps, history = hop.sweeps, hop.energy_history
    else:
        t0 = clock()
        if band is None:  # H is already the full matrix
            Hx = H
        else:  # the band is exact; add the longer chords that a better polygon may use
            longer = deviation_matrix(
                P, deviation, closed=closed, cap=hop.energy, m=m, min_span=band + 1
            )
            Hx = np.minimum(H, longer)
        ex = exact_polygon(Hx, m, closed=closed, incumbent=hop.indices)
        timings["exact"] = (clock() - t0) * 1e3
        idx, energy = ex.indices, ex.energy
        sweeps, history = 0, np.zeros(0)
    idx = np.asarray(idx, dtype=np.int64)
    # degenerate optima ("max": chords between neighbours are free; any measure where
    # the curve runs straight): spread the vertices among the ties
    idx = spread_ties(Hx, idx, P, closed=closed)
    energy = polygon_energy(Hx, idx, closed=closed)
    return PolygonResult(
        indices=idx,
        vertices=P[idx].copy(),
        energy=float(energy),
        method=method,
        deviation=deviation,
        closed=closed,
        sweeps=int(sweeps),
        energy_history=np.asarray(history, dtype=float),
        n=n,
        m=m,
        plain_energy=float(hop.plain_energy),
        timings_ms=timings,
    )


def _optimum(H: np.ndarray, m: int, plain: NetworkRun) -> float | None:
    """The optimal energy of an open path's polygon on ``H`` (:func:`exact_polygon`, a
    dynamic programme bounded by the plain network's state: 0.6-2 ms for the planner's
    paths), which lets the restarts stop once they reach it; None when ``H`` admits no
    finite polygon."""
    try:
        return exact_polygon(H, m, closed=False, incumbent=plain.indices).energy
    except InputError:  # no polygon with finite energy: nothing to stop at
        return None


def network_band(initial: np.ndarray, n: int, closed: bool) -> int | None:
    """Chord span up to which H is built for the network (None: the full matrix).

    ``_BAND_FACTOR`` times the widest gap of the initial state, unless the full matrix is
    cheap anyway.

    Args:
        initial: Initial state, shape ``(m,)``.
        n: Number of points.
        closed: Closed curve.

    Returns:
        The band width in curve steps, or None.
    """
    if n**3 / (2 if closed else 6) <= _FULL_PAIRS:
        return None
    gaps = np.diff(np.append(initial, initial[0] + n)) if closed else np.diff(initial)
    band = int(_BAND_FACTOR * gaps.max())
    return None if band >= n - 1 else band
