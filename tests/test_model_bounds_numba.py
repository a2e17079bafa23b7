"""The compiled broad phase (regrasp_pin.model.bounds_numba) against numpy's batches.

The loop computes :class:`PairDistances`' lower bounds one (sample, column) at a time
with numpy's formulas, and the sweep parameter of every column with numpy's operations
in numpy's order (the same bits). Numpy's matrix products of the object frame go through BLAS, so
the two agree to rounding, not to the bit; what the verification decides from them must
be the same: which samples are below their requirement, and the reports. Without numba
the plain Python runs (a few hundred samples); with numba the compiled loop is checked
on more, and against Coal.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_pin import Hand
from regrasp_pin.model import bounds_numba, ik
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.distances import PairDistances, object_gap_bounds
from regrasp_pin.model.objects import Box, Prism
from regrasp_pin.verify.finger_motion import densify, verify_finger_motion

ROUNDING_M = 1e-15  # bounds of distances below 0.2 m, a few products each

CASES = [  # hand, moving finger, object, object centre in the palm frame
    ("five_finger", "index", Box((0.06, 0.04, 0.04)), [0.07, 0.0, 0.06]),
    ("five_finger", "thumb", Prism(6, 0.03, 0.05), [0.07, 0.02, 0.05]),
    ("allegro", "index", Box((0.05, 0.04, 0.04)), [0.08, 0.02, 0.08]),
    ("allegro", "middle", Prism(5, 0.03, 0.05), [0.08, 0.03, 0.06]),
]


@pytest.fixture(scope="module")
def hands():
    return {"five_finger": Hand.five_finger(), "allegro": Hand.allegro()}


def _motion(hands, case, seed, step_rad, away_m=0.0):
    """A smooth motion of ``CASES[case]``'s finger through four random configurations
    (half its joint ranges about their middles), the object turning and shifting near
    it (moved ``away_m`` along the palm's z), densified; the other fingers at random
    configurations of their own (they cross the finger's way at times)."""
    hand_name, finger, obj, centre = CASES[case]
    hand = hands[hand_name]
    f = hand.finger(finger)
    rng = np.random.default_rng(seed)
    n = 4
    q = np.tile(hand.neutral(), (n, 1))
    for other in hand.fingers.values():
        q[:, other.q_indices] = other.q_mid + rng.uniform(-0.25, 0.25, other.k) * (
            other.upper - other.lower
        )
    q[:, f.q_indices] = f.q_mid + rng.uniform(-0.25, 0.25, (n, f.k)) * (f.upper - f.lower)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(rng.normal(0.0, 0.3, (n, 3))).as_matrix()
    T[:, :3, 3] = np.asarray(centre) + rng.normal(0.0, 0.008, (n, 3)) + [0.0, 0.0, away_m]
    t, q_d, T_d = densify(np.arange(n, dtype=float), q, T, step_rad)
    return hand, obj, finger, t, q_d, T_d


def _pairs(hands, case, seed, step_rad, stride, backend):
    hand, obj, finger, _, q_d, T_d = _motion(hands, case, seed, step_rad)
    ik.set_ik_backend(backend)
    req = np.full(q_d.shape[0], 0.002)
    return PairDistances(hand, obj, hand.finger(finger), q_d, T_d, req, 0.002, 0.004, stride)


def _check_same_bounds(hands, step_rad):
    """Both paths' bounds, every case, coarse to fine and not: equal to rounding, below
    their requirement at the same samples; both sides of the near-pair cut occur."""
    near = below = 0
    for case in range(len(CASES)):
        for stride in (1, 8):
            ref = _pairs(hands, case, 3 + case, step_rad, stride, "numpy")
            got = _pairs(hands, case, 3 + case, step_rad, stride, "numba")
            assert got._compiled and not ref._compiled
            # the sweep parameter (the steps' sums in one order): the same bits
            assert got._sweep.tobytes() == ref._sweep.tobytes()
            assert got.max_step_m == ref.max_step_m > 0.0
            np.testing.assert_allclose(got.lb, ref.lb, rtol=0.0, atol=ROUNDING_M)
            assert np.array_equal(got.lb < got.required, ref.lb < ref.required)
            near += int(np.sum(ref.lb[:, ref.kind == 2] < 0.004 + 0.005))
            below += int(np.sum(ref.lb < ref.required))
    assert near > 0 and below > 0


def _check_same_object_bounds(hands, step_rad):
    """object_gap_bounds (a finger's links and its fingertip link against the object)
    on both paths, every case: equal to rounding, and each a lower bound of Coal's
    distance."""
    for case in range(len(CASES)):
        hand, obj, finger, _, q_d, T_d = _motion(hands, case, 40 + case, step_rad)
        f = hand.finger(finger)
        tip = list(f.tip_geometry_ids)
        groups = [[g for g in f.geometry_ids if g not in tip], tip]
        ik.set_ik_backend("numpy")
        ref = object_gap_bounds(hand, groups, obj, q_d, T_d)
        ik.set_ik_backend("numba")
        got = object_gap_bounds(hand, groups, obj, q_d, T_d)
        np.testing.assert_allclose(got, ref, rtol=0.0, atol=ROUNDING_M)
        rows = np.arange(0, q_d.shape[0], max(q_d.shape[0] // 12, 1))
        links = LinkClearance(hand, finger, obj)(q_d[rows], T_d[rows])
        assert np.all(got[0, rows] <= links + 1e-9)
        assert np.ptp(got[0]) > 0.005  # and they follow the motion (not a constant)


def test_uncompiled_loop_gives_numpys_bounds(hands, backend, monkeypatch):
    monkeypatch.setattr(ik.ik_numba, "available", lambda: True)
    monkeypatch.setattr(bounds_numba, "wanted", lambda name: name == "numba")
    monkeypatch.setattr(bounds_numba, "bounds", bounds_numba.bounds_python)
    monkeypatch.setattr(bounds_numba, "sweep", bounds_numba.sweep_python)
    monkeypatch.setattr(bounds_numba, "interpolate", bounds_numba.interpolate_python)
    monkeypatch.setattr(bounds_numba, "object_bounds", bounds_numba.object_bounds_python)
    _check_same_bounds(hands, step_rad=0.05)
    _check_same_object_bounds(hands, step_rad=0.2)


def test_compiled_loop_gives_numpys_bounds(hands, backend):
    pytest.importorskip("numba")
    assert bounds_numba.available()
    _check_same_bounds(hands, step_rad=0.005)
    _check_same_object_bounds(hands, step_rad=0.02)


def test_compiled_bounds_never_exceed_coal_distances(hands, backend):
    """Every compiled bound (coarse to fine or not) is below the exact Coal distance."""
    pytest.importorskip("numba")
    for case in range(len(CASES)):
        for stride in (1, 8):
            pairs = _pairs(hands, case, 20 + case, 0.02, stride, "numba")
            pairs._query(*np.nonzero(np.ones(pairs.lb.shape, dtype=bool)))
            assert np.all(pairs.exact >= pairs.lb - 1e-9)
            assert np.mean(pairs.lb > 0.0) > 0.3  # and they are not trivial


@pytest.mark.parametrize("exact_minima", [True, False])
def test_verification_reports_the_same_on_both_backends(hands, backend, exact_minima):
    """The verification of the same motions (failing and passing ones) reports the same
    decisions and failures with either path's bounds, and, with exact minima, the same
    minima (without, they are read partly from the bounds: equal to rounding)."""
    pytest.importorskip("numba")
    outcomes = set()
    mins = ("min_tip_object_m", "min_link_object_m", "min_finger_finger_m")
    mins += ("min_clearance_margin_m",)
    for case in range(len(CASES)):
        for seed, away_m in ((30, 0.0), (31, 0.0), (32, 0.3)):
            hand, obj, finger, t, q_d, T_d = _motion(hands, case, seed + case, 0.05, away_m)
            reports = {}
            for name in ("numpy", "numba"):
                ik.set_ik_backend(name)
                reports[name] = verify_finger_motion(
                    hand, obj, finger, t, q_d, T_d, tip_clearance_m=0.002,
                    link_clearance_m=0.002, finger_clearance_m=0.004,
                    exact_minima=exact_minima,
                )  # fmt: skip
            ref, got = reports["numpy"], reports["numba"]
            assert got.failures == ref.failures and got.ok == ref.ok
            assert got.n_failures == ref.n_failures and got.time_s == ref.time_s
            got_mins, ref_mins = ([getattr(r, m) for m in mins] for r in (got, ref))
            if exact_minima:
                assert got_mins == ref_mins
                assert got.minima_exact and ref.minima_exact
            else:
                np.testing.assert_allclose(got_mins, ref_mins, rtol=0.0, atol=ROUNDING_M)
            outcomes.add(ref.ok)
    assert outcomes == {True, False}  # both kinds of motion were checked


def test_compiled_loop_without_numba_says_how_to_install(monkeypatch):
    monkeypatch.setattr(bounds_numba, "_compile", lambda: None)
    assert not bounds_numba.available()
    assert not bounds_numba.wanted("numba")
    with pytest.raises(ImportError, match=r"regrasp-pin\[fast\]"):
        bounds_numba.bounds(*([None] * 18))
