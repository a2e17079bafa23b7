"""Exact DP optimum: equals brute force over all vertex sets; never worse than the network."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from regrasp_pin.exceptions import InputError
from regrasp_pin.polygon.deviation import DEVIATIONS, deviation_matrix
from regrasp_pin.polygon.exact import exact_polygon
from regrasp_pin.polygon.hopfield import polygon_energy
from regrasp_pin.polygon.hopfield_search import competitive_hopfield


def brute_force(H: np.ndarray, m: int, closed: bool) -> float:
    n = H.shape[0]
    if closed:
        sets = itertools.combinations(range(n), m)
    else:
        sets = ((0, *c, n - 1) for c in itertools.combinations(range(1, n - 1), m - 2))
    return min(polygon_energy(H, np.array(s), closed=closed) for s in sets)


def small_curve(n: int, d: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.random(n)) * 2 * np.pi
    P = np.c_[np.cos(t), np.sin(2 * t)] + 0.2 * rng.standard_normal((n, 2))
    return np.c_[P, rng.standard_normal(n)] if d == 3 else P


@pytest.mark.parametrize("deviation", DEVIATIONS)
@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("d", [2, 3])
def test_equals_brute_force(deviation, closed, d):
    for seed, n in enumerate((7, 10, 12)):
        P = small_curve(n, d, seed)
        H = deviation_matrix(P, deviation, closed=closed)
        for m in range(3 if closed else 2, n + 1, 2):
            best = brute_force(H, m, closed)
            res = exact_polygon(H, m, closed=closed)
            assert_close(res.energy, best, atol=1e-12, rtol=1e-12, what=f"n={n} m={m}")
            assert_close(polygon_energy(H, res.indices, closed=closed), res.energy, atol=0)
            assert res.indices.shape == (m,) and np.all(np.diff(res.indices) > 0)
            if not closed:
                assert res.indices[0] == 0 and res.indices[-1] == n - 1


@settings(derandomize=True, max_examples=30, deadline=None)
@given(
    st.integers(5, 11),
    st.booleans(),
    st.sampled_from(DEVIATIONS),
    st.integers(0, 10_000),
)
def test_brute_force_on_digital_curves_with_incumbent(n, closed, deviation, seed):
    rng = np.random.default_rng(seed)
    P = np.round(rng.standard_normal((n, 2)) * 2)  # repeated pixels, coincident chord ends
    m = int(rng.integers(3 if closed else 2, n + 1))
    H = deviation_matrix(P, deviation, closed=closed)
    best = brute_force(H, m, closed)
    hop = competitive_hopfield(H, m, closed=closed, points=P, restarts=2, seed=seed)
    if not np.isfinite(best):  # every polygon has a zero-length chord (coincident ends)
        assert not np.isfinite(hop.energy)
        with pytest.raises(InputError, match="admits no polygon"):
            exact_polygon(H, m, closed=closed)
        return
    assert np.isfinite(hop.energy), "the network found no polygon without zero-length chords"
    with_incumbent = exact_polygon(H, m, closed=closed, incumbent=hop.indices)
    assert_close(with_incumbent.energy, best, atol=1e-12, rtol=1e-12)
    assert_close(exact_polygon(H, m, closed=closed).energy, best, atol=1e-12, rtol=1e-12)


@settings(derandomize=True, max_examples=25, deadline=None)
@given(
    st.integers(12, 70),
    st.booleans(),
    st.sampled_from(DEVIATIONS),
    st.sampled_from([2, 3]),
    st.integers(0, 10_000),
)
def test_exact_never_worse_than_network(n, closed, deviation, d, seed):
    rng = np.random.default_rng(seed)
    P = np.cumsum(rng.standard_normal((n, d)), axis=0)  # random walk
    m = int(rng.integers(3, min(n, 15) + 1))
    H = deviation_matrix(P, deviation, closed=closed)
    hop = competitive_hopfield(H, m, closed=closed, points=P, restarts=2, seed=seed)
    ex = exact_polygon(H, m, closed=closed)
    assert ex.energy <= hop.energy * (1 + 1e-12) + 1e-12
    assert ex.energy <= hop.plain_energy * (1 + 1e-12) + 1e-12


@pytest.mark.parametrize("closed", [False, True])
def test_pruned_matrix_keeps_the_optimum(closed):
    """H built with cap = a feasible energy and m gives the same optimum as the full H."""
    P = small_curve(90, 2, seed=9)
    for deviation in DEVIATIONS:
        full = deviation_matrix(P, deviation, closed=closed)
        hop = competitive_hopfield(full, 9, closed=closed, points=P, restarts=0)
        pruned = deviation_matrix(P, deviation, closed=closed, cap=hop.energy, m=9)
        a = exact_polygon(full, 9, closed=closed)
        b = exact_polygon(pruned, 9, closed=closed, incumbent=hop.indices)
        assert_close(b.energy, a.energy, atol=1e-12, rtol=1e-12, what=deviation)


def test_edge_cases():
    P = small_curve(8, 2, seed=1)
    H = deviation_matrix(P, "ise")
    assert exact_polygon(H, 2).indices.tolist() == [0, 7]
    assert exact_polygon(H, 8).energy == 0.0
    Hc = deviation_matrix(P, "ise", closed=True)
    assert exact_polygon(Hc, 8, closed=True).energy == 0.0
    assert_close(exact_polygon(Hc, 3, closed=True).energy, brute_force(Hc, 3, True), atol=1e-12)


def test_bad_inputs():
    H = deviation_matrix(small_curve(8, 2, seed=1), "max")
    with pytest.raises(InputError, match="m: 9 exceeds"):
        exact_polygon(H, 9)
    with pytest.raises(InputError, match="m: 2 is too small"):
        exact_polygon(H, 2, closed=True)
    with pytest.raises(InputError, match="incumbent: has 3 vertices"):
        exact_polygon(H, 4, incumbent=[0, 3, 7])
    with pytest.raises(InputError, match="incumbent: is not strictly increasing"):
        exact_polygon(H, 3, incumbent=[0, 9, 7])
    blocked = np.full((6, 6), np.inf)
    with pytest.raises(InputError, match="H: has no available chord"):
        exact_polygon(blocked, 3)
    with pytest.raises(InputError, match="H: has shape"):
        exact_polygon(np.zeros((4, 5)), 3)
