"""approximate_polygon: the public entry point (network and exact), its result and its errors."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pytest
from conftest import assert_close, placed, staircase

from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.polygon.approximate import METHODS, PolygonResult, approximate_polygon
from regrasp_pin.polygon.deviation import DEVIATIONS, chord_deviations, deviation_matrix
from regrasp_pin.polygon.exact import exact_polygon
from regrasp_pin.polygon.hopfield import TIE_RTOL, initial_state, run_network


def noisy_circle(n: int, seed: int = 0, noise: float = 0.01) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.c_[np.cos(t), np.sin(t)] + noise * rng.standard_normal((n, 2))


def sine_path_3d(n: int) -> np.ndarray:
    t = np.linspace(0, 1, n)
    return np.c_[4 * t, np.sin(3 * np.pi * t), 0.5 * np.cos(2 * np.pi * t)]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("closed", [False, True])
def test_result_is_a_valid_polygon(method, closed):
    P = noisy_circle(70, seed=1)
    res = approximate_polygon(P, 9, closed=closed, deviation="sum", method=method)
    assert isinstance(res, PolygonResult)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.energy = 0.0  # type: ignore[misc]
    assert res.indices.dtype == np.int64 and res.indices.shape == (9,)
    assert np.all(np.diff(res.indices) > 0), "ordered, distinct"
    if not closed:
        assert res.indices[0] == 0 and res.indices[-1] == 69, "P and Q kept"
    assert np.array_equal(res.vertices, P[res.indices])
    starts = res.indices
    ends = np.roll(starts, -1) if closed else starts[1:]
    starts = starts if closed else starts[:-1]
    chords = chord_deviations(P, starts, ends, "sum", closed=closed)
    assert chords.shape == (9 if closed else 8,)
    assert_close(res.energy, chords.sum(), atol=1e-9, what="energy = sum over the chords")
    assert (res.n, res.m, res.method, res.deviation, res.closed) == (70, 9, method, "sum", closed)
    assert res.energy <= res.plain_energy
    if method == "hopfield":
        assert res.sweeps > 0 and np.all(np.diff(res.energy_history) <= 1e-12)
    else:
        assert res.sweeps == 0 and res.energy_history.shape == (0,)


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_exact_method_is_the_optimum_and_network_is_not_better(deviation):
    P = sine_path_3d(120)
    for closed in (False, True):
        H = deviation_matrix(P, deviation, closed=closed)
        best = exact_polygon(H, 8, closed=closed).energy
        ex = approximate_polygon(P, 8, closed=closed, deviation=deviation, method="exact")
        hop = approximate_polygon(P, 8, closed=closed, deviation=deviation)
        # "max": the vertices spread among ties, within TIE_RTOL of the energy
        assert_close(ex.energy, best, atol=1e-12, rtol=2 * TIE_RTOL)
        assert ex.energy <= hop.energy * (1 + 2 * TIE_RTOL)


def test_banded_pipeline_matches_the_full_matrix(caplog):
    """n large enough for the band: the plain network still sees the full matrix (the band
    is widened when a column competes over a wider span), and the exact method is exact."""
    P = noisy_circle(200, seed=5)
    caplog.set_level(logging.DEBUG, logger="regrasp_pin.polygon.approximate")
    res = approximate_polygon(P, 20, closed=True, deviation="max", restarts=2)
    assert "plain network needed span" in caplog.text, "band widening not exercised"
    H = deviation_matrix(P, "max", closed=True)
    plain = run_network(H, initial_state(P, 20, closed=True), closed=True)
    assert res.plain_energy == plain.energy
    ex = approximate_polygon(P, 20, closed=True, deviation="max", method="exact")
    best = exact_polygon(H, 20, closed=True).energy
    assert_close(ex.energy, best, atol=1e-12, rtol=TIE_RTOL)  # "max": spread among ties
    assert ex.energy <= res.energy * (1 + TIE_RTOL)
    full = approximate_polygon(P, 20, closed=True, deviation="max", restarts=2, full_matrix=True)
    assert full.plain_energy == res.plain_energy, "same plain network with and without band"
    assert ex.energy <= full.energy * (1 + TIE_RTOL)
    assert full.energy <= full.plain_energy * (1 + TIE_RTOL)


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_stopping_at_the_optimum_gives_the_same_polygon_in_fewer_sweeps(deviation):
    """Open 3-D paths like the planner's (n 40-120, m 7-13): the same vertices and energy
    with and without the exact optimum as the search's stop, never more sweeps."""
    rng = np.random.default_rng(5)
    fewer = 0
    for n, m in ((40, 7), (80, 9), (120, 13)):
        P = np.cumsum(rng.normal(0.0, 1e-3, (n, 3)), axis=0)
        full = approximate_polygon(P, m, deviation=deviation)
        short = approximate_polygon(P, m, deviation=deviation, stop_at_optimum=True)
        assert np.array_equal(short.indices, full.indices) and short.energy == full.energy
        assert short.sweeps <= full.sweeps
        fewer += short.sweeps < full.sweeps
    assert fewer >= 1


def test_straight_path_and_pixels():
    line = np.c_[np.arange(30.0), np.zeros(30)]
    res = approximate_polygon(line, 4, deviation="max")
    assert res.energy == 0.0
    pixels = np.repeat(np.round(noisy_circle(25, noise=0) * 5), 2, axis=0)  # repeated pixels
    for deviation in DEVIATIONS:
        res = approximate_polygon(pixels, 6, closed=True, deviation=deviation, method="exact")
        assert np.isfinite(res.energy)


def square_with_stem() -> np.ndarray:
    """Closed 8-connected outline of a 5 x 5 pixel square with a one-pixel-wide stem: the
    outline walks the stem out and back, so (4, 2), (5, 2), (6, 2) appear twice."""
    bottom = [(x, 0) for x in range(5)]
    right_low = [(4, 1), (4, 2)]
    stem = [(5, 2), (6, 2), (7, 2), (6, 2), (5, 2), (4, 2)]
    rest = [(4, 3), (4, 4), *[(x, 4) for x in range(3, -1, -1)], (0, 3), (0, 2), (0, 1)]
    return np.array(bottom + right_low + stem + rest, dtype=float)


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_repeated_pixels_give_no_nan_and_no_zero_length_chord(deviation):
    P = square_with_stem()
    for closed in (False, True):
        H = deviation_matrix(P, deviation, closed=closed)
        assert not np.isnan(H).any()
        for m in (4, 6, 9):
            for method in METHODS:
                res = approximate_polygon(P, m, closed=closed, deviation=deviation, method=method)
                ends = np.roll(res.vertices, -1, axis=0) if closed else res.vertices[1:]
                starts = res.vertices if closed else res.vertices[:-1]
                gaps = np.linalg.norm(ends - starts, axis=1)
                assert np.all(gaps > 0), f"zero-length chord ({method}, m={m}, {closed=})"
                assert np.isfinite(res.energy) and np.isfinite(res.plain_energy)
            ex = approximate_polygon(P, m, closed=closed, deviation=deviation, method="exact")
            H_best = exact_polygon(H, m, closed=closed).energy
            assert_close(ex.energy, H_best, atol=1e-12, rtol=TIE_RTOL)
    loop = np.vstack([P, P[:1]])  # an open path back to its start: m = 2 is a point
    with pytest.raises(InputError, match="m: 2 joins the first and last points"):
        approximate_polygon(loop, 2, deviation=deviation)
    assert np.isfinite(approximate_polygon(loop, 3, deviation=deviation).energy)


def test_all_points_and_two_points():
    P = noisy_circle(6)
    res = approximate_polygon(P, 6, closed=True)
    assert res.indices.tolist() == list(range(6)) and res.energy == 0.0
    res = approximate_polygon(P[:2], 2)
    assert res.indices.tolist() == [0, 1] and res.energy == 0.0


@pytest.mark.parametrize(
    ("kwargs", "exc", "text"),
    [
        (dict(m=1), InputError, "m: 1 is too small for an open curve (expected 2 <= m <= n=10)"),
        (
            dict(m=2, closed=True),
            InputError,
            "m: 2 is too small for a closed curve (expected 3 <= m <= n=10)",
        ),
        (dict(m=11), InputError, "m: 11 exceeds the number of points n=10"),
        (dict(m=3.5), InputError, "m: 3.5 is not an integer"),
        (dict(m=3, deviation="avg"), UnknownNameError, "valid names are: 'max', 'sum', 'ise'"),
        (dict(m=3, method="dp"), UnknownNameError, "valid names are: 'hopfield', 'exact'"),
        (dict(m=3, restarts=-2), InputError, "restarts"),
        (dict(m=3, seed=-1), InputError, "seed"),
    ],
)
def test_bad_arguments(kwargs, exc, text):
    with pytest.raises(exc) as err:
        approximate_polygon(noisy_circle(10), **kwargs)
    assert text in str(err.value)


@pytest.mark.parametrize(
    ("points", "text"),
    [
        (np.zeros((1, 2)), "points: has 1 point(s) (expected at least 2 points)"),
        (np.zeros((5, 4)), "points: has shape (5, 4) (expected shape (n, 2) or (n, 3))"),
        (np.zeros(5), "points: has shape (5,)"),
        (np.array([[0, 0], [1, np.nan], [2, 0]]), "points: contains NaN or inf"),
        (np.array([[0, 0], [1, np.inf], [2, 0]]), "points: contains NaN or inf"),
    ],
)
def test_bad_points(points, text):
    with pytest.raises(InputError) as err:
        approximate_polygon(points, 2)
    assert err.value.argument == "points"
    assert text in str(err.value)


def test_fig8_plot_2d_and_3d():
    pytest.importorskip("matplotlib")
    from regrasp_pin.plotting.polygon import plot_polygon

    for P, closed in ((noisy_circle(40), True), (sine_path_3d(40), False)):
        res = approximate_polygon(P, 6, closed=closed)
        fig = plot_polygon(P, res)
        ax = fig.axes[0]
        assert "6 vertices" in ax.get_title()
        assert len(ax.lines) == 2  # curve and polygon
    with pytest.raises(InputError, match="points: has shape"):
        plot_polygon(P[:10], res)


@pytest.mark.parametrize("deviation", DEVIATIONS)
@pytest.mark.parametrize("closed", [False, True])
def test_polygon_of_straight_runs_does_not_follow_the_placements_last_bits(deviation, closed):
    # lattice paths with more vertices than corners: many polygons of energy 0 (or of
    # equal energy), which rounding of the placed points would decide between
    rng = np.random.default_rng(11)
    for _ in range(8):
        P = staircase(rng, int(rng.integers(2, 5)))
        m = min(int(rng.integers(5, 12)), len(P))
        if closed:
            P = np.r_[P, P[-2:0:-1] + [0.0, 0.5]]  # back alongside: a closed loop
        first = approximate_polygon(0.004 * P, m, deviation=deviation, closed=closed)
        for _ in range(3):
            res = approximate_polygon(placed(P, rng), m, deviation=deviation, closed=closed)
            assert res.indices.tolist() == first.indices.tolist()
