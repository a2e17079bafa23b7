"""Batched DLS IK: round trips through FK, limits, warm starts, unreachable targets."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close
from hypothesis import given, settings
from hypothesis import strategies as st

from regrasp_pin import Hand


@pytest.fixture(scope="module")
def five():
    return Hand.five_finger()


@pytest.fixture(scope="module")
def allegro():
    return Hand.allegro()


@pytest.mark.parametrize("which", ["five", "allegro"])
def test_cold_round_trip_success_rate(which, five, allegro):
    hand = five if which == "five" else allegro
    rng = np.random.default_rng(3)
    for finger in hand.fingers.values():
        q_true = rng.uniform(finger.lower, finger.upper, (2000, finger.k))
        targets = finger.fk(q_true)
        res = finger.ik(targets, tol_m=1e-5)
        assert res.success_rate >= 0.995, f"{finger.name}: {res.success_rate:.4f}"
        # reported residuals are true residuals
        err = np.linalg.norm(finger.fk(res.q) - targets, axis=1)
        assert_close(res.error_m, err, atol=1e-12, what="residual")
        assert np.all(err[res.success] <= 1e-5)
        assert np.all(finger.within_limits(res.q))


def test_warm_start_converges_in_few_iterations(five):
    finger = five.fingers["index"]
    rng = np.random.default_rng(4)
    q_prev = rng.uniform(finger.lower + 0.05, finger.upper - 0.05, (500, 3))
    q_next = q_prev + rng.normal(0, 0.01, q_prev.shape)
    res = finger.ik(finger.fk(q_next), q_prev)
    assert res.success.all()
    assert res.iterations <= 10


def test_unreachable_target_reports_residual_not_exception(five):
    finger = five.fingers["index"]
    far = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -0.5]])
    res = finger.ik(far)
    assert not res.success.any()
    # residual equals the distance from the target to the returned tip position
    assert_close(res.error_m, np.linalg.norm(finger.fk(res.q) - far, axis=1), atol=1e-12)
    # the finger reaches at most ~0.1 m from the palm, so these are far
    assert np.all(res.error_m > 0.3)
    assert np.all(finger.within_limits(res.q))


@settings(derandomize=True, max_examples=40, deadline=None)
@given(
    st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
    st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3),
)
def test_solutions_never_leave_the_joint_box(target, q_init):
    finger = Hand.five_finger().fingers["thumb"]
    res = finger.ik(np.array(target), np.array(q_init))
    assert np.all(res.q >= finger.lower) and np.all(res.q <= finger.upper)
    assert np.isfinite(res.error_m).all()


def test_ik_bad_inputs(five):
    finger = five.fingers["index"]
    from regrasp_pin.exceptions import InputError

    with pytest.raises(InputError, match="targets_palm"):
        finger.ik(np.zeros((4, 2)))
    with pytest.raises(InputError, match="NaN or inf"):
        finger.ik(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(InputError, match="q_init"):
        finger.ik(np.zeros((3, 3)), np.zeros((2, 3)))
    with pytest.raises(InputError, match="q_init.*NaN"):
        finger.ik(np.zeros(3), np.array([0.0, np.inf, 0.0]))
    with pytest.raises(InputError, match="tol_m"):
        finger.ik(np.zeros(3), tol_m=0.0)
    with pytest.raises(InputError, match="max_iter"):
        finger.ik(np.zeros(3), max_iter=0)


def test_dls_step_in_one_batch_equals_the_loop_bit_for_bit():
    # few points take _dls_step_few, many _dls_step_loop: the same operations per point,
    # and both the damped least-squares step J^T (J J^T + lambda^2 I)^-1 e
    from regrasp_pin.model.ik import _LAMBDA0_SQ, _LAMBDA_ERR, _dls_step_few, _dls_step_loop

    rng = np.random.default_rng(23)
    for k in (2, 3, 4):
        J = rng.normal(0.0, 0.05, (3, k, 300))
        J[:, 0, :40] = 0.0  # blocked joints
        J[1, -1, 40:45] = -0.0
        e = rng.normal(0.0, 1e-3, (3, 300))
        err_sq = (e * e).sum(axis=0)
        few, loop = _dls_step_few(J, e, err_sq), _dls_step_loop(J, e, err_sq)
        assert few.tobytes() == loop.tobytes(), k
        Jn = np.moveaxis(J, 2, 0)  # (n, 3, k)
        lam = _LAMBDA0_SQ + _LAMBDA_ERR * err_sq
        A = Jn @ np.swapaxes(Jn, 1, 2) + lam[:, None, None] * np.eye(3)
        ref = np.einsum("nak,na->nk", Jn, np.linalg.solve(A, e.T[:, :, None])[..., 0])
        # (nearly singular J J^T where joints are blocked: relative to the largest step)
        assert_close(few.T, ref, atol=1e-6 * np.abs(ref).max(), what=f"DLS step, k={k}")


def test_shared_starts_and_restarts_give_each_point_its_own_result(five):
    # consecutive equal starts share their first evaluation and restarts run seed by
    # seed; each point's result is still the one it gets solved alone, bit for bit
    from regrasp_pin.model.ik import solve_position_ik

    f = five.fingers["ring"]
    rng = np.random.default_rng(24)
    q_true = rng.uniform(f.lower - 0.3, f.upper + 0.3, (90, f.k))  # some out of reach
    targets = f.chain.positions(q_true) + rng.normal(0.0, 2e-3, (90, 3))
    starts = np.repeat(rng.uniform(f.lower, f.upper, (30, f.k)), 3, axis=0)  # runs of 3
    starts[3:6, 0] = 0.0
    starts[4, 0] = -0.0  # equal as numbers, not as bits: not shared
    for restarts in (False, True):
        batch = solve_position_ik(f.chain, f.lower, f.upper, targets, starts, restarts=restarts)
        assert (~batch.success).sum() >= 5  # the restarts are exercised
        for i in range(90):
            one = solve_position_ik(
                f.chain, f.lower, f.upper, targets[i : i + 1], starts[i : i + 1], restarts=restarts
            )
            assert np.array_equal(one.q[0], batch.q[i]), (restarts, i)
            assert np.array_equal(one.error_m[0], batch.error_m[i]), (restarts, i)


def test_restarts_keep_the_first_seed_that_converges(five):
    # among the seeds that converge, the first in seed order is kept (the smallest
    # residual below the tolerance would follow rounding); without one, the first of
    # the smallest (ties within RESIDUAL_RTOL), if nearer than the first solve
    from regrasp_pin.model.ik import RESIDUAL_RTOL, _seeds, solve_position_ik

    f = five.fingers["middle"]
    rng = np.random.default_rng(42)
    targets = f.chain.positions(rng.uniform(f.lower, f.upper, (60, f.k)))
    far_start = np.broadcast_to(f.lower, (60, f.k))
    kw = dict(tol_m=1e-5, max_iter=4)
    res = solve_position_ik(f.chain, f.lower, f.upper, targets, far_start, restarts=True, **kw)
    first = solve_position_ik(f.chain, f.lower, f.upper, targets, far_start, restarts=False, **kw)
    seeds = _seeds(f.lower, f.upper)
    per_seed = [
        solve_position_ik(
            f.chain, f.lower, f.upper, targets, np.broadcast_to(s, (60, f.k)), restarts=False, **kw
        )
        for s in seeds
    ]
    ok = np.stack([r.success for r in per_seed], axis=1)  # (point, seed)
    err = np.stack([r.error_m for r in per_seed], axis=1)
    retried = ~first.success
    assert retried.sum() >= 10 and (ok[retried].sum(axis=1) >= 2).sum() >= 5  # exercised
    for i in np.flatnonzero(retried):
        least = err[i].min()
        if ok[i].any():
            want = per_seed[int(np.argmax(ok[i]))]
        elif least < first.error_m[i] * (1.0 - RESIDUAL_RTOL):  # nearer, not by rounding
            want = per_seed[int(np.argmax(err[i] <= least * (1.0 + RESIDUAL_RTOL)))]
        else:
            want = first
        assert np.array_equal(res.q[i], want.q[i]), i


def test_restarts_that_stall_equally_far_keep_the_first_not_the_last_bits(allegro):
    # targets 4 mm out of reach sideways of the index's first joint at its limit: the
    # seeds stall at the same distance on other branches of the three flexion joints,
    # so the branch kept must not follow the targets' last bits
    from regrasp_pin.model.ik import solve_position_ik

    f = allegro.fingers["index"]
    rng = np.random.default_rng(0)
    q = rng.uniform(f.lower, f.upper, (300, f.k))
    q[:, 0] = f.upper[0]
    p = f.chain.positions(q)
    q_side = q.copy()
    q_side[:, 0] += 1e-6
    side = f.chain.positions(q_side) - p
    targets = p + 0.004 * side / np.linalg.norm(side, axis=1, keepdims=True)
    start = np.broadcast_to(0.5 * (f.lower + f.upper), q.shape)
    kw = dict(tol_m=1e-5, max_iter=40, restarts=True)
    base = solve_position_ik(f.chain, f.lower, f.upper, targets, start, **kw)
    assert not base.success.any()
    for _ in range(10):
        noisy = targets * (1.0 + rng.choice([-1.0, 1.0], targets.shape) * 2.2e-16)
        res = solve_position_ik(f.chain, f.lower, f.upper, noisy, start, **kw)
        assert_close(res.q, base.q, atol=1e-6, what="joint coordinates")
