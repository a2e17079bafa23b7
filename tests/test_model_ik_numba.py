"""The compiled IK loop (regrasp_pin.model.ik_numba) against the numpy iterations.

The kernel is plain Python that numba compiles unchanged, so the tests that do not need
numba run the same code uncompiled through the public backend switch (a few hundred
points); with numba installed, the compiled kernel is checked the same way on more
points and on a manifold. Both backends must give the same bits: joint coordinates,
residuals and flags (they do the same float64 operations in the same order, their
cos/sin included: :mod:`regrasp_pin.model.trig`); the residuals are FK round trips.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close

from regrasp_pin import Hand
from regrasp_pin.exceptions import InputError
from regrasp_pin.model import ik, ik_numba

TOL_M = 1e-5


@pytest.fixture(scope="module")
def five():
    return Hand.five_finger()


@pytest.fixture(scope="module")
def allegro():
    return Hand.allegro()


@pytest.fixture
def uncompiled(monkeypatch, backend):
    """The 'numba' backend running the kernel as plain Python."""
    monkeypatch.setattr(ik_numba, "available", lambda: True)
    monkeypatch.setattr(ik_numba, "iterate", ik_numba.iterate_python)


def _problems(finger, n, seed):
    """Warm targets (each joint moved by N(0, 0.02) rad) and cold random targets."""
    rng = np.random.default_rng(seed)
    q_prev = rng.uniform(finger.lower, finger.upper, (n, finger.k))
    q_next = np.clip(q_prev + rng.normal(0.0, 0.02, q_prev.shape), finger.lower, finger.upper)
    cold = finger.fk(rng.uniform(finger.lower - 0.3, finger.upper + 0.3, (n, finger.k)))
    return finger.fk(q_next), q_prev, cold


def _solve_both(finger, targets, q_init):
    out = {}
    for name in ("numpy", "numba"):
        ik.set_ik_backend(name)
        out[name] = finger.ik(targets, q_init, tol_m=TOL_M)
    return out["numpy"], out["numba"]


def _check_same(finger, targets, a, b, what):
    assert np.array_equal(a.success, b.success), what
    for r in (a, b):  # reported residuals are FK round trips, solutions in the limits
        err = np.linalg.norm(finger.fk(r.q) - targets, axis=1)
        assert_close(r.error_m, err, atol=1e-12, what=f"{what} residual")
        assert np.all(finger.within_limits(r.q)), what
    # the same bits: iterates, residuals and the restarts' choices
    assert np.array_equal(a.q, b.q) and np.array_equal(a.error_m, b.error_m), what


@pytest.mark.parametrize("which", ["five", "allegro"])
def test_uncompiled_kernel_equals_numpy(which, five, allegro, uncompiled):
    hand = five if which == "five" else allegro
    for finger in hand.fingers.values():
        warm, q_prev, cold = _problems(finger, 60, seed=11)
        a, b = _solve_both(finger, warm, q_prev)
        assert a.success.all(), finger.name
        _check_same(finger, warm, a, b, f"{finger.name} warm")
        # cold: some targets beyond the limits (restarts, stalls, unreachable points)
        a, b = _solve_both(finger, cold, None)
        assert 0 < a.success.sum() < len(cold), finger.name
        _check_same(finger, cold, a, b, f"{finger.name} cold")


def test_compiled_kernel_equals_numpy(five, allegro, backend):
    pytest.importorskip("numba")
    for hand in (five, allegro):
        for finger in hand.fingers.values():
            warm, q_prev, cold = _problems(finger, 3000, seed=12)
            a, b = _solve_both(finger, warm, q_prev)
            _check_same(finger, warm, a, b, f"{finger.name} warm")
            a, b = _solve_both(finger, cold, None)
            _check_same(finger, cold, a, b, f"{finger.name} cold")


def _turning_box():
    """A 40 x 60 x 40 mm box turning about the palm y axis: its surface every 4 mm, the
    motion and 21 times over its 2 s."""
    from regrasp_pin.model.motion import ObjectMotion
    from regrasp_pin.model.objects import Box

    box = Box((0.04, 0.06, 0.04))
    T0 = np.eye(4)
    T0[:3, 3] = [0.065, 0.0, 0.06]
    motion = ObjectMotion.constant_twist(
        T0, axis_palm=[0, 1, 0], point_palm=T0[:3, 3], rate_rad_s=0.5, duration_s=2.0
    )
    return box.sample_surface(0.004), motion, np.linspace(0.0, 2.0, 21)


def test_compiled_manifold_equals_numpy(five, backend):
    pytest.importorskip("numba")
    from regrasp_pin.grasp.manifold import build_manifold

    sample, motion, times = _turning_box()
    for name in ("index", "middle", "little"):
        m = {}
        for b in ("numpy", "numba"):
            ik.set_ik_backend(b)
            m[b] = build_manifold(five.finger(name), sample, motion, times)
        a, b = m["numpy"], m["numba"]
        for field in ("q", "reachable", "inside", "pad_ok", "tip_clear", "margin_rad"):
            assert np.array_equal(getattr(a, field), getattr(b, field), equal_nan=True), (
                name,
                field,
            )


def test_compiled_kernels_run_fingers_on_threads_alike(five, backend):
    """The compiled kernels release the GIL; fingers mapped on two threads are those
    mapped one by one, bit for bit."""
    pytest.importorskip("numba")
    from regrasp_pin.grasp.manifold import build_manifolds

    sample, motion, times = _turning_box()
    ik.set_ik_backend("numba")
    names = five.finger_names
    one = build_manifolds(five, names, sample, motion, times, threads=1)
    two = build_manifolds(five, names, sample, motion, times, threads=2)
    for n in names:
        for field in ("q", "reachable", "inside", "pad_ok", "tip_clear"):
            assert np.array_equal(getattr(one[n], field), getattr(two[n], field), equal_nan=True)


def test_backend_switch_and_its_errors(backend, monkeypatch):
    assert ik.ik_backend() in ik.IK_BACKENDS
    with pytest.raises(InputError, match="one of"):
        ik.set_ik_backend("cuda")
    monkeypatch.setattr(ik_numba, "available", lambda: False)
    with pytest.raises(InputError, match="numba is not installed"):
        ik.set_ik_backend("numba")
    ik.set_ik_backend("numpy")
    assert ik.ik_backend() == "numpy"
    # the environment variable is read once, at the first call, and checked
    saved = list(ik._backend)
    try:
        for value, what in (("cuda", "one of"), ("numba", "numba is not installed")):
            ik._backend.clear()
            monkeypatch.setenv("REGRASP_PIN_IK_BACKEND", value)
            with pytest.raises(InputError, match=f"REGRASP_PIN_IK_BACKEND.*{what}"):
                ik.ik_backend()
        ik._backend.clear()
        monkeypatch.setenv("REGRASP_PIN_IK_BACKEND", "numpy")
        assert ik.ik_backend() == "numpy"
        # without the variable: numba where it is installed (the same bits), else numpy
        monkeypatch.delenv("REGRASP_PIN_IK_BACKEND")
        ik._backend.clear()
        assert ik.ik_backend() == "numpy"  # available() is False here
        monkeypatch.setattr(ik_numba, "available", lambda: True)
        ik._backend.clear()
        assert ik.ik_backend() == "numba"
    finally:
        ik._backend[:] = saved


def test_packed_chain_is_the_kernel_of_forward_kinematics(five):
    # the packed constants, run through the uncompiled kernel with zero iterations,
    # give the tip positions of Finger.fk
    rng = np.random.default_rng(13)
    for finger in five.fingers.values():
        q = rng.uniform(finger.lower, finger.upper, (40, finger.k))
        p = finger.fk(q)
        far = p + 1.0  # 1 m away: one evaluation, no step
        err, iters = ik_numba.iterate_python(
            finger.chain.packed(),
            finger.lower,
            finger.upper,
            np.ascontiguousarray(far.T),
            np.ascontiguousarray(q.T),
            TOL_M,
            0,
            (1e-8, 1e-2, 0.4, 0.995**2, 10.0),
        )
        assert iters == 0
        assert_close(err, np.full(40, np.sqrt(3.0)), atol=1e-12, what=finger.name)
