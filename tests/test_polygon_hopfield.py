"""Competitive Hopfield network (Eqs. 6, 8-10): energy, inputs, monotone sweeps, restarts."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from regrasp_pin.exceptions import InputError
from regrasp_pin.polygon.deviation import DEVIATIONS, deviation_matrix
from regrasp_pin.polygon.hopfield import (
    initial_state,
    network_input,
    polygon_energy,
    run_network,
    tie_groups,
    tolerant_order,
)
from regrasp_pin.polygon.hopfield_search import competitive_hopfield


def noisy_curve(n: int, d: int = 2, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    P = np.c_[np.cos(t) * (1 + 0.3 * np.sin(3 * t)), np.sin(t)] + 0.03 * rng.standard_normal((n, 2))
    return np.c_[P, 0.2 * np.sin(2 * t)] if d == 3 else P


def binary_state(indices: np.ndarray, n: int) -> np.ndarray:
    """Neuron matrix V (n x m): V[x, i] = 1 iff point x is vertex i."""
    V = np.zeros((n, indices.shape[0]))
    V[indices, np.arange(indices.shape[0])] = 1.0
    return V


def test_energy_is_eq8_halved_and_input_is_eq10():
    """With a finite H, Eq. 8 and Eq. 10 summed over the binary neurons literally."""
    rng = np.random.default_rng(1)
    n, m = 9, 4
    H = rng.random((n, n))  # finite: the literal sums need no inf * 0
    s = np.array([0, 2, 5, 7])
    V = binary_state(s, n)
    Vm1, Vp1 = np.roll(V, 1, axis=1), np.roll(V, -1, axis=1)  # V[:, i-1], V[:, i+1] (Eq. 5)
    e8 = np.einsum("yx,xi,yi->", H, V, Vm1) + np.einsum("xy,xi,yi->", H, V, Vp1)
    assert_close(polygon_energy(H, s, closed=True), e8 / 2, atol=1e-12, what="E = E_8 / 2")
    for i in range(m):
        u10 = -(H.T @ Vm1[:, i] + H @ Vp1[:, i])  # Eq. 10
        between = (np.arange(n) - s[i - 1]) % n < (s[(i + 1) % m] - s[i - 1]) % n
        between &= np.arange(n) != s[i - 1]
        u = network_input(H, s, i, closed=True)
        assert_close(u[between], u10[between], atol=1e-12, what=f"U[:, {i}]")
        assert np.all(np.isneginf(u[~between])), "rows outside the neighbours' interval"


def test_initial_state_is_equidistant_along_the_curve():
    # points bunched at the start: equidistance is in arc length, not in index
    x = np.r_[np.linspace(0, 1, 21), np.linspace(1.5, 10, 18)]
    P = np.c_[x, np.zeros_like(x)]
    s = initial_state(P, 5)
    assert s[0] == 0 and s[-1] == len(x) - 1
    assert_close(x[s], [0, 2.5, 5, 7.5, 10], atol=0.5, what="arc length of the vertices")
    closed = initial_state(P, 4, closed=True)
    assert np.all(np.diff(closed) > 0) and closed[0] == 0
    same = np.zeros((10, 2))  # all points coincide: index spacing
    assert initial_state(same, 4).tolist() == [0, 3, 6, 9]


def test_initial_state_target_midway_between_points_snaps_to_the_later_wherever_placed():
    # 20 evenly spaced points, m = 3: the middle target lies exactly midway between
    # points 9 and 10, which the arc lengths' last bits would decide, placement by placement
    rng = np.random.default_rng(3)
    line = np.c_[np.arange(20.0), np.zeros(20), np.zeros(20)] * 0.004
    for _ in range(30):
        R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
        P = line @ R.T + rng.uniform(-1.0, 1.0, 3)
        assert initial_state(P, 3).tolist() == [0, 10, 19]
        assert initial_state(P, 5).tolist() == [0, 5, 10, 14, 19]  # 4.75 and 14.25 nearer


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_converged_state_is_winner_take_all_fixed_point(closed, deviation):
    P = noisy_curve(60, seed=2)
    H = deviation_matrix(P, deviation, closed=closed)
    run = run_network(H, initial_state(P, 8, closed=closed), closed=closed)
    s = run.indices
    assert np.all(np.diff(s) > 0), "ordered and distinct"
    if not closed:
        assert s[0] == 0 and s[-1] == len(P) - 1, "end points P and Q kept"
    cols = range(8) if closed else range(1, 7)
    for i in cols:
        u = network_input(H, s, i, closed=closed)
        assert u[s[i]] == u.max(), f"column {i} is not a winner of Eq. 6"
    assert run.sweeps == len(run.energy_history) - 1
    assert_close(run.energy, polygon_energy(H, s, closed=closed), atol=1e-12)
    assert not np.isnan(run.energy_history).any()


@settings(derandomize=True, max_examples=30, deadline=None)
@given(
    st.integers(6, 40),
    st.integers(0, 10_000),
    st.booleans(),
    st.sampled_from(DEVIATIONS),
    st.sampled_from([2, 3]),
)
def test_energy_never_rises_between_sweeps(n, seed, closed, deviation, d):
    rng = np.random.default_rng(seed)
    P = np.round(rng.standard_normal((n, d)) * 4, 1)
    m = int(rng.integers(3, n + 1))
    H = deviation_matrix(P, deviation, closed=closed)
    # a random valid initial state, not only the equidistant one
    if closed:
        s0 = np.sort(rng.choice(n, m, replace=False))
    else:
        s0 = np.r_[0, np.sort(rng.choice(np.arange(1, n - 1), m - 2, replace=False)), n - 1]
    with np.errstate(invalid="raise"):  # inf - inf or inf * 0 would raise
        run = run_network(H, s0, closed=closed)
    hist = run.energy_history
    assert np.all(np.diff(hist) <= 1e-12 * np.maximum(1.0, hist[:-1])), hist
    assert np.all(np.diff(run.indices) > 0)
    assert np.isfinite(run.energy)


@settings(derandomize=True, max_examples=20, deadline=None)
@given(st.integers(8, 45), st.integers(0, 10_000), st.booleans(), st.sampled_from(DEVIATIONS))
def test_restarts_never_worse_than_plain_network(n, seed, closed, deviation):
    P = noisy_curve(n, seed=seed)
    m = 3 + seed % (n - 3)
    H = deviation_matrix(P, deviation, closed=closed)
    res = competitive_hopfield(H, m, closed=closed, points=P, restarts=3, seed=seed)
    plain = run_network(H, initial_state(P, m, closed=closed), closed=closed)
    assert res.plain_energy == plain.energy
    assert np.array_equal(res.plain_indices, plain.indices)
    assert res.energy <= res.plain_energy
    assert_close(res.energy, polygon_energy(H, res.indices, closed=closed), atol=1e-12)
    assert np.all(np.diff(res.indices) > 0) and res.indices.shape == (m,)
    assert np.all(np.diff(res.energy_history) <= 0), "best-so-far record"
    assert res.sweeps >= res.plain_sweeps


def test_restarts_are_seeded_and_close_the_gap():
    P = noisy_curve(80, seed=4)
    H = deviation_matrix(P, "ise", closed=True)
    a = competitive_hopfield(H, 9, closed=True, points=P, seed=3)
    b = competitive_hopfield(H, 9, closed=True, points=P, seed=3)
    assert np.array_equal(a.indices, b.indices) and a.energy == b.energy
    assert a.energy < a.plain_energy, "the plain network stopped in a local minimum here"


def test_max_deviation_inf_diagonal_never_gives_nan():
    P = np.round(noisy_curve(30, seed=5) * 4)  # repeated pixels
    for closed in (False, True):
        H = deviation_matrix(P, "max", closed=closed)
        with np.errstate(invalid="raise"):
            res = competitive_hopfield(H, 6, closed=closed, points=P)
        assert np.isfinite(res.energy) and not np.isnan(res.energy_history).any()


def test_unavailable_chords_are_never_used():
    P = noisy_curve(50, seed=6)
    H = deviation_matrix(P, "sum", max_span=12)  # chords over 12 steps are inf
    res = competitive_hopfield(H, 8, points=P)
    assert np.isfinite(res.energy)
    assert np.all(np.diff(res.indices) <= 12)


def test_bad_inputs():
    H = deviation_matrix(noisy_curve(10), "max")
    with pytest.raises(InputError, match="H: has shape"):
        run_network(np.zeros((3, 4)), [0, 1, 2])
    bad = H.copy()
    bad[0, 3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        run_network(bad, [0, 5, 9])
    with pytest.raises(InputError, match="indices: is not strictly increasing"):
        run_network(H, [0, 5, 5, 9])
    with pytest.raises(InputError, match="indices: does not start at 0"):
        run_network(H, [1, 5, 9])
    with pytest.raises(InputError, match="m: 11 exceeds"):
        competitive_hopfield(H, 11)
    with pytest.raises(InputError, match="m: 2 is too small"):
        competitive_hopfield(H, 2, closed=True)
    with pytest.raises(InputError, match="restarts"):
        competitive_hopfield(H, 4, restarts=-1)


def test_tolerant_order_ignores_last_bit_noise():
    """Values within the tolerance of the first of their group keep the index order, so
    that noise in the last bits cannot reorder them; inf and NaN come last."""
    v = np.array([3.0, 1.0 + 1e-15, np.inf, 1.0, 2.0, np.nan, 1.0 - 1e-15, 0.5])
    assert tolerant_order(v, 1e-12).tolist() == [7, 1, 3, 6, 4, 0, 2, 5]
    assert tolerant_order(v, 0.0)[:4].tolist() == [7, 6, 3, 1]  # no tolerance: by value
    assert tolerant_order(np.zeros(0), 1e-9).tolist() == []


def test_tie_groups_chain_from_each_groups_least():
    values = np.array([3.0, 1.0, 1.0 + 1e-12, np.inf, 2.0, np.nan, 1.0 + 2e-9, -np.inf])
    groups = tie_groups(values, 1e-9)
    assert groups.tolist() == [4, 1, 1, 5, 3, 5, 2, 0]  # -inf first, inf and NaN last
    assert tie_groups(np.array([np.inf, np.inf]), 1e-9).tolist() == [0, 0]
    assert tie_groups(np.zeros(0), 1e-9).size == 0
    # tolerant_order: the same groups, -inf last with inf and NaN
    assert tolerant_order(values, 1e-9).tolist() == [1, 2, 6, 4, 0, 3, 5, 7]
