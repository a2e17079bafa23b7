"""Keeping a batched IK on one branch of a redundant finger's solutions (model.follow_on).

The Allegro's index has four joints for a 3-D tip centre: each target has a curve of
solutions. A smooth joint path gives smooth targets (FK); one sample replaced by
another solution of its own target, far along that curve, is the jump that a batch
warm-started from one configuration makes.
"""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin import Hand
from regrasp_pin.model.follow_on import follow_on
from regrasp_pin.model.hand import speed_shares

TOL_M = 1e-6
DT_S = 0.01


@pytest.fixture(scope="module")
def index():
    return Hand.allegro().finger("index")


def _smooth(f, n=12):
    """A joint path inside the limits at a third of the joints' speed limits, its
    targets (FK) and the time steps (the first sample's step 0)."""
    mid = 0.5 * (f.lower + f.upper)
    t = np.arange(n)[:, None] * DT_S
    q = mid + np.sin(3.0 * t + np.arange(f.k)) * f.velocity_limit / 9.0
    assert np.all(f.within_limits(q))
    step = np.full(n, DT_S)
    step[0] = 0.0
    return q, f.fk(q), step


def _other_branch(f, target, q_near):
    """A solution of ``target`` far from ``q_near`` along the solution curve."""
    rng = np.random.default_rng(0)
    starts = rng.uniform(f.lower, f.upper, (400, f.k))
    res = f.ik(np.repeat(target[None], len(starts), 0), starts, tol_m=TOL_M, restarts=False)
    ok = res.error_m <= TOL_M
    far = np.abs(res.q[ok] - q_near).max(axis=1)
    assert far.max() > 0.3  # the finger is redundant: far solutions exist
    return res.q[ok][np.argmax(far)]


def _fastest(f, q, q_before, step):
    before = np.vstack([q_before[None], q[:-1]])
    return speed_shares(q - before, step, f.velocity_limit).max(axis=1)


def test_a_jump_to_another_branch_is_solved_again_from_the_sample_before(index):
    f = index
    q_true, targets, step = _smooth(f)
    q = q_true.copy()
    q[7] = jump = _other_branch(f, targets[7], q_true[7])
    err = np.linalg.norm(f.fk(q) - targets, axis=1)
    assert _fastest(f, q, q_true[0], step)[7] > 1.0  # the jump the velocity test refuses
    kept = follow_on(f, q, err, targets, q_true[0], step, TOL_M)
    assert kept == 1
    # the sample reaches its target (FK) near its neighbours, within the speed limits
    assert np.linalg.norm(f.fk(q[7]) - targets[7]) <= TOL_M and err[7] <= TOL_M
    assert _fastest(f, q, q_true[0], step).max() <= 1.0
    # back on the path's branch: nearer the true sample than a tenth of the jump
    assert np.abs(q[7] - q_true[7]).max() < 0.1 * np.abs(jump - q_true[7]).max()
    np.testing.assert_array_equal(np.delete(q, 7, 0), np.delete(q_true, 7, 0))


def test_a_run_of_samples_on_another_branch_comes_back_sample_by_sample(index):
    """The batch's case: from sample 7 on, every sample on another branch (each its own
    target's solution): solved one after another from the one before, all of them
    reach their targets within the speed limits, near the path."""
    f = index
    q_true, targets, step = _smooth(f)
    q = q_true.copy()
    q[7:] = [_other_branch(f, targets[i], q_true[i]) for i in range(7, len(q))]
    err = np.linalg.norm(f.fk(q) - targets, axis=1)
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M) == len(q) - 7
    assert np.all(np.linalg.norm(f.fk(q) - targets, axis=1) <= TOL_M)
    assert _fastest(f, q, q_true[0], step).max() <= 1.0
    assert np.abs(q - q_true).max() < 0.1


def test_a_sample_the_batch_missed_is_solved_from_the_one_before(index):
    f = index
    q_true, targets, step = _smooth(f)
    q, err = q_true.copy(), np.zeros(len(q_true))
    q[4], err[4] = f.lower, 1.0  # the batch's residual: not reached
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M) == 1
    assert err[4] <= TOL_M and np.linalg.norm(f.fk(q[4]) - targets[4]) <= TOL_M
    assert _fastest(f, q, q_true[0], step).max() <= 1.0


def test_a_smooth_batch_is_left_as_it_is(index):
    f = index
    q_true, targets, step = _smooth(f)
    q, err = q_true.copy(), np.zeros(len(q_true))
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M) == 0
    np.testing.assert_array_equal(q, q_true)
    # the first sample's step takes no time: any change there is not a speed
    q[0] = _other_branch(f, targets[0], q_true[0])
    first = q[0].copy()
    q[1:] = _smooth_from(f, q[0], targets[1:])
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M) == 0
    np.testing.assert_array_equal(q[0], first)


def _smooth_from(f, q0, targets):
    out, last = [], q0
    for x in targets:
        last = f.ik(x[None], last, tol_m=TOL_M, restarts=False).q[0]
        out.append(last)
    return np.array(out)


def test_an_unreachable_target_stays_missed(index):
    f = index
    q_true, targets, step = _smooth(f)
    targets = targets.copy()
    targets[5] += np.array([1.0, 0.0, 0.0])  # a metre away: out of reach
    q, err = q_true.copy(), np.zeros(len(q_true))
    err[5] = 0.9
    before = q[5].copy()
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M) == 0
    assert err[5] == 0.9
    np.testing.assert_array_equal(q[5], before)


def test_what_counts_as_reached_can_be_given_per_sample(index):
    """A residual within the sample's own tolerance is reached: left as it is; one
    above it is solved again."""
    f = index
    q_true, targets, step = _smooth(f)
    q, err = q_true.copy(), np.full(len(q_true), 5e-5)
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M, reached_m=1e-4) == 0
    np.testing.assert_array_equal(q, q_true)
    reached = np.full(len(q), 1e-4)
    reached[9] = 1e-5  # 5e-5 misses this one
    assert follow_on(f, q, err, targets, q_true[0], step, TOL_M, reached_m=reached) == 1
    assert err[9] <= TOL_M and np.all(err[np.arange(len(q)) != 9] == 5e-5)
