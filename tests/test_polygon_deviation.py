"""Deviation matrices H (Eqs. 2, 7): every entry against a direct Python loop."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from conftest import assert_close, placed, staircase
from hypothesis import given, settings
from hypothesis import strategies as st

from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.polygon.deviation import (
    DEVIATIONS,
    chord_deviations,
    deviation_matrix,
    rest_lower_bound,
)


def loop_matrix(P: np.ndarray, deviation: str, closed: bool) -> np.ndarray:
    """Reference: one chord at a time, one arc point at a time, |w x v| / |w|."""
    P = np.asarray(P, dtype=float)
    n, d = P.shape
    H = np.full((n, n), math.inf)
    for x in range(n):
        for L in range(1, n if closed else n - x):
            y = (x + L) % n
            w = P[y] - P[x]
            ww = float(w @ w)
            if ww == 0.0:  # coincident chord ends: a zero-length chord is unavailable
                continue
            dists = []
            for k in range(1, L):
                v = P[(x + k) % n] - P[x]
                if d == 2:
                    dists.append(abs(w[0] * v[1] - w[1] * v[0]) / math.sqrt(ww))
                else:
                    dists.append(float(np.linalg.norm(np.cross(w, v))) / math.sqrt(ww))
            H[x, y] = {
                "max": max(dists, default=0.0),
                "sum": sum(dists),
                "ise": sum(t * t for t in dists),
            }[deviation]
    return H


def curve(kind: str, n: int, d: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if kind == "noisy":
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        P = np.c_[np.cos(t), np.sin(t)] + 0.05 * rng.standard_normal((n, 2))
    elif kind == "digital":  # integer pixels with repeats (coincident chord ends)
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        P = np.round(np.c_[3 * np.cos(t), 2 * np.sin(2 * t)])
    else:
        P = rng.standard_normal((n, 2)) * 5
    if d == 3:
        P = np.c_[P, np.round(rng.standard_normal(n), 1)]
    return P


def matches_loop(H: np.ndarray, ref: np.ndarray, scale: float) -> None:
    finite = np.isfinite(ref)
    assert np.array_equal(np.isfinite(H), finite), "inf pattern differs from the loop"
    assert not np.isnan(H).any()
    assert_close(H[finite], ref[finite], atol=1e-9 * scale, rtol=1e-9, what="H vs loop")


@pytest.mark.parametrize("deviation", DEVIATIONS)
@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("kind", ["noisy", "digital", "random"])
def test_entries_equal_direct_loop(kind, d, closed, deviation):
    P = curve(kind, 17, d, seed=3)
    H = deviation_matrix(P, deviation, closed=closed)
    ref = loop_matrix(P, deviation, closed)
    scale = max(1.0, float(np.abs(ref[np.isfinite(ref)]).max()))
    matches_loop(H, ref, scale)


@settings(derandomize=True, max_examples=25, deadline=None)
@given(
    st.integers(3, 12),
    st.sampled_from([2, 3]),
    st.booleans(),
    st.sampled_from(DEVIATIONS),
    st.integers(0, 10_000),
)
def test_entries_equal_direct_loop_random(n, d, closed, deviation, seed):
    rng = np.random.default_rng(seed)
    P = np.round(rng.standard_normal((n, d)) * 3, 1)  # rounding makes repeats likely
    H = deviation_matrix(P, deviation, closed=closed)
    ref = loop_matrix(P, deviation, closed)
    scale = max(1.0, float(np.abs(ref[np.isfinite(ref)]).max()))
    matches_loop(H, ref, scale)


def test_structure_of_h():
    P = curve("noisy", 12, 2, seed=1)
    for closed in (False, True):
        H = deviation_matrix(P, "max", closed=closed)
        assert np.all(np.isinf(np.diag(H))), "h_xx = inf (Eq. 7)"
        n = len(P)
        nxt = np.arange(n - (0 if closed else 1))
        assert np.all(H[nxt, (nxt + 1) % n] == 0.0), "neighbouring points: empty arc"
        if not closed:
            assert np.all(np.isinf(H[np.tril_indices(n)])), "open: arcs only go forward"
        else:
            off = ~np.eye(n, dtype=bool)
            assert np.all(np.isfinite(H[off]))


def test_straight_line_has_zero_deviation_and_coincident_ends_are_unavailable():
    P = np.c_[np.arange(8.0), 2 * np.arange(8.0) + 1]
    for dev in DEVIATIONS:
        H = deviation_matrix(P, dev)
        assert np.all(H[np.triu_indices(8, 1)] == 0.0)
    # the curve leaves (0, 0) and comes back (chord 0 -> 4), then repeats (3, 3) (chord
    # 5 -> 6, neighbours): both chords have zero length, so they are inf like h_xx
    Q = np.array([[0.0, 0], [1, 0], [1, 2], [0, 1], [0, 0], [3, 3], [3, 3], [4, 2]])
    for dev in DEVIATIONS:
        for closed in (False, True):
            H = deviation_matrix(Q, dev, closed=closed)
            assert np.isinf(H[0, 4]) and np.isinf(H[5, 6]), (dev, closed)
            assert not np.isnan(H).any()
            assert np.isfinite(H[0, 3]) and np.isfinite(H[4, 7]) and H[4, 5] == 0.0
            assert np.isinf(chord_deviations(Q, [0, 5], [4, 6], dev, closed=closed)).all()
    # a point nudged by far less than the tolerance still coincides; one a bit farther does not
    R = Q.copy()
    R[4] += 1e-12
    assert np.isinf(deviation_matrix(R, "max")[0, 4])
    R[4] = [1e-6, 0.0]
    assert_close(deviation_matrix(R, "max")[0, 4], 2.0, atol=1e-5, what="line along x")


def test_chord_deviations_match_matrix():
    P = curve("random", 15, 3, seed=7)
    for closed in (False, True):
        for dev in DEVIATIONS:
            H = deviation_matrix(P, dev, closed=closed)
            x, y = np.nonzero(np.isfinite(H))
            assert_close(
                chord_deviations(P, x, y, dev, closed=closed), H[x, y], atol=1e-9, rtol=1e-9
            )
    assert np.isinf(chord_deviations(P, [3], [3])[0])
    assert np.isinf(chord_deviations(P, [5], [2])[0]), "open: backward chord"


def test_band_is_exact_and_bands_compose():
    P = curve("noisy", 40, 2, seed=2)
    for closed in (False, True):
        full = deviation_matrix(P, "max", closed=closed)
        low = deviation_matrix(P, "max", closed=closed, max_span=7)
        high = deviation_matrix(P, "max", closed=closed, min_span=8)
        n = len(P)
        span = (np.arange(n)[None, :] - np.arange(n)[:, None]) % n
        inside = (span <= 7) & np.isfinite(full)
        assert np.array_equal(low[inside], full[inside])
        assert np.all(np.isinf(low[~inside]))
        assert np.array_equal(np.minimum(low, high), full)


def polygons(n: int, m: int, closed: bool):
    if closed:
        yield from itertools.combinations(range(n), m)
    else:
        for c in itertools.combinations(range(1, n - 1), m - 2):
            yield (0, *c, n - 1)


def energy(H, s, closed):
    s = np.asarray(s)
    return H[s, np.roll(s, -1)].sum() if closed else H[s[:-1], s[1:]].sum()


@pytest.mark.parametrize("deviation", DEVIATIONS)
@pytest.mark.parametrize("closed", [False, True])
def test_cap_prunes_only_chords_of_worse_polygons(deviation, closed):
    """Every finite entry is exact; every polygon that uses a pruned chord costs > cap."""
    P = curve("noisy", 11, 2, seed=5)
    m = 4
    full = deviation_matrix(P, deviation, closed=closed)
    energies = sorted(energy(full, s, closed) for s in polygons(11, m, closed))
    cap = energies[len(energies) // 10]  # keep the best tenth of all polygons
    H = deviation_matrix(P, deviation, closed=closed, cap=cap, m=m)
    finite = np.isfinite(H)
    assert np.array_equal(H[finite], full[finite])
    assert (np.isfinite(full) & ~finite).any(), "the cap pruned nothing"
    for s in polygons(11, m, closed):
        e = energy(full, s, closed)
        if e <= cap:
            assert np.isfinite(energy(H, s, closed)), f"polygon {s} (E={e}) lost a chord"


def test_rest_lower_bound_never_exceeds_cheapest_cover():
    rng = np.random.default_rng(4)
    min_by_length = np.r_[np.inf, 0.0, np.sort(rng.random(10)) * rng.random(10)]
    n = min_by_length.shape[0]
    for k in range(1, 4):
        for total in range(0, 3 * n):
            best = math.inf
            for parts in itertools.product(range(1, n), repeat=k):
                if sum(parts) == total:
                    best = min(best, sum(min_by_length[p] for p in parts))
            bound = float(rest_lower_bound(min_by_length, k, np.array([total]))[0])
            assert bound <= best + 1e-12, (k, total, bound, best)
    assert rest_lower_bound(min_by_length, 0, np.array([0, 3])).tolist() == [0.0, math.inf]


@pytest.mark.parametrize(
    ("points", "argument", "text"),
    [
        (np.zeros((5, 4)), "points", "shape (n, 2) or (n, 3)"),
        (np.zeros((5, 1)), "points", "shape (n, 2) or (n, 3)"),
        (np.zeros(6), "points", "shape (n, 2) or (n, 3)"),
        (np.zeros((1, 2)), "points", "at least 2 points"),
        (np.array([[0.0, 0.0], [np.nan, 1.0]]), "points", "finite values"),
        (np.array([[0.0, 0.0], [np.inf, 1.0]]), "points", "finite values"),
        ([["a", "b"], ["c", "d"]], "points", "not a numeric array"),
    ],
)
def test_bad_points(points, argument, text):
    with pytest.raises(InputError) as err:
        deviation_matrix(points)
    assert err.value.argument == argument
    assert text in str(err.value)


def test_bad_names_and_options():
    P = curve("noisy", 6, 2, seed=0)
    with pytest.raises(UnknownNameError) as err:
        deviation_matrix(P, "mean")
    assert "deviation" in str(err.value) and "'max', 'sum', 'ise'" in str(err.value)
    with pytest.raises(InputError, match="cap"):
        deviation_matrix(P, cap=-1.0)
    with pytest.raises(InputError, match="cap"):
        deviation_matrix(P, cap=float("nan"))
    with pytest.raises(InputError, match="m: 7 exceeds"):
        deviation_matrix(P, cap=1.0, m=7)
    with pytest.raises(InputError, match="max_span"):
        deviation_matrix(P, max_span=0)


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_arcs_on_their_chords_deviate_by_exactly_zero_wherever_the_curve_lies(deviation):
    # rounding leaves collinear arcs 1e-17 to 1e-15 m off their chords, with a sign and
    # size that follow the placement's last bits: those are exactly 0, the others not
    rng = np.random.default_rng(7)
    for _ in range(5):
        P = staircase(rng, 3)
        for closed in (False, True):
            Q = placed(P, rng)
            H = deviation_matrix(Q, deviation, closed=closed)
            exact = deviation_matrix(0.004 * P, deviation, closed=closed)
            on_chord = loop_matrix(P, deviation, closed) == 0.0  # lattice: exact in floats
            assert np.all(H[on_chord] == 0.0) and on_chord.sum() > len(P)
            np.testing.assert_allclose(H[~on_chord], exact[~on_chord], rtol=1e-9, atol=0)
            assert np.all(H[~on_chord] > 0.0)
            x, y = np.nonzero(np.isfinite(H))
            direct = chord_deviations(Q, x, y, deviation, closed=closed)
            np.testing.assert_allclose(direct, H[x, y], rtol=1e-9, atol=0)


@pytest.mark.parametrize("deviation", DEVIATIONS)
def test_a_short_straight_curve_far_from_the_origin_deviates_by_exactly_zero(deviation):
    # centring 2 mm of line 100 m away rounds each point by ~1e-14 m: still on the chord
    rng = np.random.default_rng(2)
    line = np.c_[np.linspace(0.0, 0.002, 20), np.zeros(20), np.zeros(20)]
    for offset_m in (1.0, 10.0, 100.0):
        R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
        P = line @ R.T + offset_m * rng.standard_normal(3)
        H = deviation_matrix(P, deviation)
        assert np.all(H[np.isfinite(H)] == 0.0), offset_m
        assert np.all(chord_deviations(P, [0, 3], [19, 17], deviation) == 0.0)
