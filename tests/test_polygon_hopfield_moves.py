"""Block winner-take-all and annealed sweeps: exact block optimum, energy never rising."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from regrasp_pin.exceptions import InputError
from regrasp_pin.polygon.approximate import approximate_polygon
from regrasp_pin.polygon.deviation import DEVIATIONS, deviation_matrix
from regrasp_pin.polygon.exact import exact_polygon
from regrasp_pin.polygon.hopfield import TIE_RTOL, initial_state, polygon_energy, run_network
from regrasp_pin.polygon.hopfield_moves import (
    annealed_sweeps,
    block_costs,
    block_pass,
    group_relocations,
    min_plus,
    spread_ties,
    subdivision_vertices,
    subdivisions,
    update_block,
)
from regrasp_pin.polygon.hopfield_search import competitive_hopfield


def pixel_curve(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 1 + 0.3 * np.sin(3 * t) + 0.1 * rng.standard_normal(n)
    return np.round(np.c_[r * np.cos(t), r * np.sin(t)] * n / 8)  # repeated pixels


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_block_costs_equal_brute_force(deviation):
    """The block's joint state is the best over all ordered choices between p and q."""
    P = pixel_curve(30, seed=1)
    H = deviation_matrix(P, deviation, closed=True)
    n = len(P)
    for p, q, k in ((3, 14, 3), (25, 6, 2), (10, 19, 4)):  # (25, 6) wraps around
        inside = [(p + 1 + i) % n for i in range((q - p) % n - 1)]
        best = min(
            H[p, c[0]] + sum(H[a, b] for a, b in itertools.pairwise(c)) + H[c[-1], q]
            for c in itertools.combinations(inside, k)
        )
        cost, pos = block_costs(H, p, q, np.array(inside[:k]))
        assert_close(cost, best, atol=1e-12, rtol=1e-12, what=f"block {p}->{q}, k={k}")
        chain = [p, *pos.tolist(), q]
        assert_close(sum(H[a, b] for a, b in itertools.pairwise(chain)), cost, atol=1e-12)
        assert [inside.index(x) for x in pos] == sorted(inside.index(x) for x in pos)


@settings(derandomize=True, max_examples=25, deadline=None)
@given(
    st.integers(10, 40),
    st.integers(0, 10_000),
    st.booleans(),
    st.sampled_from(DEVIATIONS),
    st.integers(2, 5),
)
def test_block_moves_never_raise_the_energy(n, seed, closed, deviation, k):
    rng = np.random.default_rng(seed)
    P = np.round(rng.standard_normal((n, 2)) * 4, 1)
    m = int(rng.integers(k + 2, n + 1))
    H = deviation_matrix(P, deviation, closed=closed)
    if closed:
        s = np.sort(rng.choice(n, m, replace=False))
    else:
        s = np.r_[0, np.sort(rng.choice(np.arange(1, n - 1), m - 2, replace=False)), n - 1]
    before = polygon_energy(H, s, closed=closed)
    for radius in (None, 2):
        t = s.copy()
        moved = block_pass(H, t, k, closed, radius=radius)
        t = np.sort(t) if closed else t
        after = polygon_energy(H, t, closed=closed)
        assert after <= before or (np.isinf(before) and np.isinf(after)), (before, after)
        if moved:
            assert after < before
        assert np.all(np.diff(t) > 0) and len(np.unique(t)) == m
        if not closed:
            assert t[0] == 0 and t[-1] == n - 1


def test_block_of_one_column_is_the_winner_take_all():
    """k = 1: the block update moves a column exactly where Eq. 6 moves it."""
    P = pixel_curve(40, seed=2)
    H = deviation_matrix(P, "ise", closed=True)
    s0 = initial_state(P, 6, closed=True)
    run = run_network(H, s0, closed=True)
    for i in range(6):  # a converged state: no single column moves
        assert not update_block(H, run.indices.copy(), i, 1)


def test_annealed_sweeps_are_seeded_and_valid():
    P = pixel_curve(50, seed=3)
    H = deviation_matrix(P, "max", closed=True)
    HT = np.ascontiguousarray(H.T)
    s0 = initial_state(P, 8, closed=True)
    temps = np.geomspace(1.0, 1e-3, 20)
    a = annealed_sweeps(H, HT, s0, True, np.random.default_rng(5), temps)
    b = annealed_sweeps(H, HT, s0, True, np.random.default_rng(5), temps)
    assert np.array_equal(a, b) and np.all(np.diff(a) > 0) and a.shape == (8,)
    cold = annealed_sweeps(H, HT, s0, True, np.random.default_rng(5), np.full(3, 1e-300))
    assert polygon_energy(H, cold, closed=True) <= polygon_energy(H, s0, closed=True)


@pytest.mark.parametrize(("deviation", "seed"), [("max", 0), ("max", 5), ("ise", 3), ("ise", 11)])
def test_block_moves_close_the_gap_on_digital_curves(deviation, seed):
    """On these pixel outlines the search without block moves ends more than 3 % above the
    exact optimum; with them it reaches the optimum (to 0.5 %), never above the plain network."""
    P = pixel_curve(70, seed)
    H = deviation_matrix(P, deviation, closed=True)
    best = exact_polygon(H, 12, closed=True).energy
    without = competitive_hopfield(H, 12, closed=True, points=P, block=0)
    with_blocks = competitive_hopfield(H, 12, closed=True, points=P)
    assert without.energy > 1.03 * best, "the case no longer needs block moves"
    assert with_blocks.energy <= 1.005 * best
    assert with_blocks.energy <= with_blocks.plain_energy


def test_bad_block_and_anneals():
    P = pixel_curve(70, 0)
    H = deviation_matrix(P, "max", closed=True)
    with pytest.raises(InputError, match="block"):
        competitive_hopfield(H, 12, closed=True, block=-1)
    with pytest.raises(InputError, match="anneals"):
        competitive_hopfield(H, 12, closed=True, anneals=-1)
    annealed = competitive_hopfield(H, 12, closed=True, points=P, anneals=2)
    assert annealed.energy <= annealed.plain_energy and np.isfinite(annealed.energy)


def _u_path() -> np.ndarray:
    """Three straight runs of 20 steps (a U): every "max" optimum has its vertices at
    the two corners and the ends, and the others anywhere on the runs (energy 0)."""
    a = np.c_[np.zeros(21), np.arange(21)]
    b = np.c_[np.arange(1, 21), np.full(20, 20)]
    c = np.c_[np.full(20, 20), np.arange(19, -1, -1)]
    return np.vstack([a, b, c]).astype(float)


@pytest.mark.parametrize("method", ["hopfield", "exact"])
def test_max_ties_are_broken_toward_spread_out_vertices(method):
    P = _u_path()
    raw = exact_polygon(deviation_matrix(P, "max", closed=False), 8, closed=False).indices
    assert np.diff(raw).min() == 1  # the degenerate optimum: free vertices bunched up
    res = approximate_polygon(P, 8, deviation="max", method=method)
    assert res.energy == pytest.approx(0.0, abs=1e-12)  # still optimal
    assert {0, 20, 40, 60} <= set(res.indices.tolist())  # ends and corners
    assert np.diff(res.indices).min() >= 6  # 4 free vertices over 3 runs of 20 steps


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_a_vertex_as_near_the_midpoint_from_both_sides_goes_to_the_first(deviation):
    """A straight path of 6 evenly spaced points: the middle vertex of 3 costs nothing
    anywhere, and positions 2 and 3 are as near the midpoint (2.5 steps): from either,
    spreading ends on 2 (which of two such ties a search ends on follows its start and
    the last bits of H; the spread does not)."""
    P = np.c_[np.arange(6.0), 0.5 * np.arange(6.0)]
    H = deviation_matrix(P, deviation, closed=False)
    for start in ([0, 2, 5], [0, 3, 5]):
        assert spread_ties(H, np.array(start), P, closed=False).tolist() == [0, 2, 5]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), closed=st.booleans())
def test_spreading_ties_keeps_the_energy_and_the_order(seed, closed):
    rng = np.random.default_rng(seed)
    n, m = 50, 7
    P = np.cumsum(rng.integers(-1, 2, size=(n, 2)), axis=0).astype(float)
    P += 1e-3 * np.arange(n)[:, None]  # no two points coincide
    H = deviation_matrix(P, "max", closed=closed)
    s = run_network(H, initial_state(P, m, closed=closed), closed=closed).indices
    before = polygon_energy(H, s, closed=closed)
    after_s = spread_ties(H, s, P, closed=closed)
    after = polygon_energy(H, after_s, closed=closed)
    # all moves together within the tie tolerance of the energy (one budget)
    assert after <= before + TIE_RTOL * max(before, 1e-12) + 1e-15
    assert np.all(np.diff(after_s) > 0) and after_s.size == m
    if not closed:
        assert after_s[0] == s[0] and after_s[-1] == s[-1]  # the pinned ends stay


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_subdivisions_equal_brute_force(deviation):
    """The best k-vertex subdivision of a chord is the best over all ordered choices of
    k points of its arc, for every k at once; the vertices returned cost what is claimed."""
    P = pixel_curve(30, seed=2)
    H = deviation_matrix(P, deviation, closed=True)
    n = len(P)
    for a, b in ((3, 13), (24, 5)):  # (24, 5) wraps around
        inside = [(a + 1 + i) % n for i in range((b - a) % n - 1)]
        costs, back = subdivisions(H, a, b, 4)
        assert costs[0] == H[a, b]
        for k in range(1, 5):
            best = min(
                sum(H[x, y] for x, y in itertools.pairwise([a, *c, b]))
                for c in itertools.combinations(inside, k)
            )
            assert_close(costs[k], best, atol=1e-12, rtol=1e-12, what=f"{a}->{b}, k={k}")
            xs = subdivision_vertices(back, k).tolist()
            assert [inside.index(x) for x in xs] == sorted(inside.index(x) for x in xs)
            chain = [a, *xs, b]
            assert_close(sum(H[x, y] for x, y in itertools.pairwise(chain)), costs[k], atol=1e-12)
    costs, _ = subdivisions(H, 3, 6, 4)  # two points on the arc: no 3- or 4-subdivision
    assert np.isfinite(costs[:3]).all() and np.isinf(costs[3:]).all()


@pytest.mark.parametrize("deviation", DEVIATIONS)
@pytest.mark.parametrize("closed", [True, False])
def test_group_relocations_predict_the_energy_change(deviation, closed):
    """Each move removes a run of r <= rmax consecutive vertices and puts r vertices into
    another chord: the state stays valid (m ordered vertices, an open path's
    ends kept) and its energy changes by exactly the predicted amount."""
    for seed in range(4):
        P = pixel_curve(40 + 7 * seed, seed)
        H = deviation_matrix(P, deviation, closed=closed)
        m = 9 + seed
        s = run_network(H, initial_state(P, m, closed=closed), closed=closed).indices
        e0 = polygon_energy(H, s, closed=closed)
        moves = group_relocations(H, s, closed, 4, 50)
        assert moves, "no move found"
        assert [g for g, _ in moves] == sorted(g for g, _ in moves)
        for gain, state in moves:
            assert state.shape == (m,) and np.all(np.diff(state) > 0)
            if not closed:
                assert state[0] == 0 and state[-1] == len(P) - 1
            gone, added = np.setdiff1d(s, state), np.setdiff1d(state, s)
            assert 1 <= len(gone) == len(added) <= 4
            cols = set(np.flatnonzero(np.isin(s, gone)).tolist())  # consecutive columns
            starts = range(m) if closed else range(1, m - 1)
            assert any(cols == {(c + t) % m for t in range(len(cols))} for c in starts)
            chord = np.searchsorted(s, added)  # all inside one chord of the old state
            assert len(np.unique(chord % m if closed else chord)) == 1
            change = polygon_energy(H, state, closed=closed) - e0
            assert_close(change, gain, atol=1e-9 * max(e0, 1.0), what="predicted change")


def test_min_plus_takes_the_first_of_near_ties():
    cost = np.array([1.0, 1.0 + 1e-13, 0.5, np.inf])
    step = np.array([[0.0, 1.0], [-1e-13, 1.0], [0.5, np.inf], [0.0, 0.0]])
    new, arg = min_plus(cost, step)
    assert arg.tolist() == [0, 0]  # rows 0, 1 and 2 tie on column 0: the first wins
    assert new.tolist() == [1.0, 2.0]
    new, arg = min_plus(np.full(2, np.inf), np.zeros((2, 3)))
    assert np.isinf(new).all() and arg.tolist() == [0, 0, 0]


@pytest.mark.parametrize("deviation", DEVIATIONS)
@pytest.mark.parametrize("radius", [None, 3])
def test_block_cache_changes_nothing(deviation, radius):
    """Block passes with a shared cache of block updates end exactly where passes without
    it end, pass after pass, from several states (so the cache is hit)."""
    P = pixel_curve(45, seed=3)
    H = deviation_matrix(P, deviation, closed=True)
    cache: dict = {}
    hits = 0
    for phase in (0.0, 0.25, 0.5, 0.0):
        a = initial_state(P, 12, closed=True, phase=phase)
        b = a.copy()
        for _ in range(4):
            size = len(cache)
            moved_a = block_pass(H, a, 4, True, radius=radius)
            moved_b = block_pass(H, b, 4, True, radius=radius, cache=cache)
            hits += len(cache) == size
            assert moved_a == moved_b and np.array_equal(a, b)
            a, b = np.sort(a), np.sort(b)
    assert hits > 0
