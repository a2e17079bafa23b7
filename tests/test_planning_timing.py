"""Regrasp timing: the time laws' progress and durations from joint velocity limits."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import FailureKind, InputError, PlanningError
from regrasp_pin.planning.timing import (
    CRUISE_ACCEL,
    CRUISE_PEAK,
    CRUISE_RAMP,
    MJ_PEAK,
    PATH_FACTOR,
    STRETCH_MARGIN,
    TIME_LAWS,
    check_joint_speed,
    cruise,
    duration_for_move,
    durations_for_moves,
    inverse_minimum_jerk,
    inverse_progress,
    joint_paced,
    minimum_jerk,
    next_duration,
    peak_ratio,
    progress,
    stretched_duration,
    velocity_blend,
)


def _peak_speed(dq: np.ndarray, duration: float, law: str = "minimum-jerk") -> np.ndarray:
    """Peak joint speeds [rad/s] of a straight joint move by the time ``law``, by
    finite differences of the sampled trajectory."""
    t = np.linspace(0.0, duration, 20001)
    q = progress(t / duration, law)[:, None] * dq[None]
    return np.abs(np.diff(q, axis=0) / np.diff(t)[:, None]).max(axis=0)


def test_mj_peak_is_the_peak_over_mean_speed_of_minimum_jerk():
    v = _peak_speed(np.array([1.0]), 1.0)[0]
    assert v == pytest.approx(MJ_PEAK, rel=1e-6)


def test_the_cruise_law_peaks_at_its_ratio_with_its_acceleration_and_is_smooth():
    """The cruise law rises from 0 to 1 with its speed and acceleration zero at both
    ends and continuous (the ramps meet the cruise where minimum jerk's speed is at its
    top and its acceleration 0); its peak speed and acceleration, measured by finite
    differences, are CRUISE_PEAK and CRUISE_ACCEL; its middle is a constant speed."""
    n = 200_000
    tau = np.linspace(0.0, 1.0, n + 1)
    s = cruise(tau)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0, abs=1e-15)
    assert np.all(np.diff(s) >= 0.0) and np.all(np.diff(s[::1000]) > 0.0)
    v = np.diff(s) * n  # at the midpoints
    a = np.diff(v) * n
    assert v.max() == pytest.approx(CRUISE_PEAK, rel=1e-6)
    assert np.abs(a).max() == pytest.approx(CRUISE_ACCEL, rel=1e-3)
    assert v[0] < 1e-9 and v[-1] < 1e-9 and abs(a[0]) < 1e-3 and abs(a[-1]) < 1e-3
    assert np.abs(np.diff(v)).max() < 1e-3  # no jump of the speed anywhere
    assert np.abs(np.diff(a)).max() < 2e-3  # nor of the acceleration
    middle = (tau[:-1] > CRUISE_RAMP + 1e-3) & (tau[1:] < 1.0 - CRUISE_RAMP - 1e-3)
    np.testing.assert_allclose(v[middle], CRUISE_PEAK, rtol=1e-9)
    # the same move in less time than minimum jerk's within the same speed limit
    assert CRUISE_PEAK / MJ_PEAK == pytest.approx(0.762, abs=1e-3)
    assert _peak_speed(np.array([1.0]), 1.0, "cruise")[0] == pytest.approx(CRUISE_PEAK, rel=1e-6)


@pytest.mark.parametrize("law", TIME_LAWS)
def test_inverse_progress_round_trips(law):
    tau = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(inverse_progress(progress(tau, law), law), tau, atol=2e-3)


def test_an_unknown_time_law_is_refused_by_name():
    with pytest.raises(InputError, match="time_law") as err:
        progress(np.array([0.5]), "bang-bang")
    assert "cruise" in err.value.expected
    with pytest.raises(InputError, match="time_law"):
        peak_ratio("linear")


@pytest.mark.parametrize("seed", range(3))
def test_durations_for_moves_by_the_cruise_law_keep_its_moves_under_the_limits(seed):
    """The cruise law's durations keep every path-factor-longer move under the limits,
    one step less would not, and they are never longer than minimum jerk's."""
    rng = np.random.default_rng(seed)
    q_from, q_to = rng.uniform(-1, 1, 4), rng.uniform(-1, 1, (6, 4))
    vmax = rng.uniform(1.0, 3.0, 4)
    fast = durations_for_moves(q_from, q_to, vmax, minimum_s=0.2, dt_s=0.01, law="cruise")
    smooth = durations_for_moves(q_from, q_to, vmax, minimum_s=0.2, dt_s=0.01)
    assert np.all(fast <= smooth + 1e-12) and np.any(fast < smooth - 1e-9)
    for D, q in zip(fast, q_to, strict=True):
        dq = PATH_FACTOR * (q - q_from)
        assert np.all(_peak_speed(dq, D, "cruise") <= vmax * (1 + 1e-6))
        if D > 0.2 + 1e-9:
            assert np.any(_peak_speed(dq, D - 0.01, "cruise") > vmax)


def test_inverse_minimum_jerk_round_trips():
    tau = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(inverse_minimum_jerk(minimum_jerk(tau)), tau, atol=2e-3)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_duration_for_move_keeps_a_path_factor_longer_move_under_the_limits(seed):
    rng = np.random.default_rng(seed)
    dq = rng.uniform(-1.5, 1.5, 4)
    vmax = rng.uniform(1.0, 4.0, 4)
    D = duration_for_move(np.zeros(4), dq, vmax, minimum_s=0.1, dt_s=0.01)
    assert D >= 0.1 and abs(D / 0.01 - round(D / 0.01)) < 1e-9  # a whole number of steps
    # a joint path PATH_FACTOR longer than the straight move still respects the limits
    assert np.all(_peak_speed(PATH_FACTOR * dq, D) <= vmax * (1 + 1e-6))
    # and one step shorter would not, unless the minimum decided
    if D > 0.1 + 1e-9:
        assert np.any(_peak_speed(PATH_FACTOR * dq, D - 0.01) > vmax)


def test_duration_for_move_is_exact_on_a_step_boundary():
    # 1.875 * 1.5 * 0.32 / 1.2 = 0.75 exactly: no spurious extra step from rounding noise
    D = duration_for_move(np.zeros(1), np.array([0.32]), np.array([1.2]), minimum_s=0.1, dt_s=0.01)
    assert D == pytest.approx(0.75, abs=1e-12)


@pytest.mark.parametrize("ratio", [1.0, 1.3, 2.7])
def test_stretched_duration_brings_a_measured_overspeed_under_the_limit(ratio):
    D = 0.4
    dq = np.array([ratio * 1.0 * D / MJ_PEAK])  # peaks at `ratio` x a 1 rad/s limit
    assert _peak_speed(dq, D)[0] == pytest.approx(ratio, rel=1e-5)
    D2 = stretched_duration(D, ratio, dt_s=0.01)
    assert _peak_speed(dq, D2)[0] <= 1.0
    assert D2 >= D


@pytest.mark.parametrize(("a", "b"), [(0.5, 0.0), (0.4, 0.3), (0.2, 0.6), (0.3, 0.9)])
def test_next_duration_follows_speeds_that_do_not_fall_as_one_over_the_duration(a, b):
    # peak speed / limit = a / D + b: part of the motion grows with the duration (the
    # object turns further), so time scaling alone undershoots when b > 0
    def ratio(D):
        return a / D + b

    tried = [(0.25, ratio(0.25))]
    first = next_duration(tried, dt_s=0.01)
    assert first == stretched_duration(0.25, ratio(0.25), dt_s=0.01)
    tried.append((first, ratio(first)))
    if ratio(first) <= 1.0:
        return  # time scaling was enough
    second = next_duration(tried, dt_s=0.01)
    if b >= 1.0 / STRETCH_MARGIN:
        assert second is None  # no duration brings a / D + b under the limit margin
        return
    # the fit is exact for this model: the next try is under the limit, by the margin
    assert second >= first
    assert ratio(second) <= 1.0 / STRETCH_MARGIN + 1e-9
    # and no longer than the longer of time scaling and the exact need, rounded up
    need = a / (1.0 / STRETCH_MARGIN - b)
    assert second <= max(stretched_duration(first, ratio(first), dt_s=0.01), need + 0.01 + 1e-9)


def test_next_duration_without_a_trend_falls_back_to_time_scaling():
    # the second try was no slower: nothing to extrapolate, scale the last one
    tried = [(0.3, 1.2), (0.4, 1.3)]
    assert next_duration(tried, dt_s=0.01) == stretched_duration(0.4, 1.3, dt_s=0.01)


def test_velocity_blend_is_zero_at_both_ends_with_the_given_end_velocities():
    rng = np.random.default_rng(3)
    times = np.linspace(0.2, 0.7, 50001)
    v_from, v_to = rng.normal(size=3), rng.normal(size=3)
    d = velocity_blend(times, v_from, v_to)
    assert_close = np.testing.assert_allclose
    assert_close(d[0], 0.0, atol=1e-15)
    assert_close(d[-1], 0.0, atol=1e-15)
    # finite differences at the ends give the requested velocities
    h = times[1] - times[0]
    assert_close((d[1] - d[0]) / h, v_from, rtol=1e-3, atol=1e-6)
    assert_close((d[-1] - d[-2]) / h, v_to, rtol=1e-3, atol=1e-6)
    # added to a move at rest at both ends, the sum starts and ends at those velocities
    move = minimum_jerk((times - times[0]) / 0.5)[:, None] * np.ones(3)
    total = move + d
    assert_close((total[1] - total[0]) / h, v_from, rtol=1e-3, atol=1e-6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_joint_paced_brings_an_uneven_path_under_its_mean_joint_pace(seed):
    """Two joints that turn through most of their move over short stretches of a path
    (tanh steps): paced by their motion, every joint peaks within MJ_PEAK times the
    path's whole time at full speed over the duration (plus the floor's quarter), far
    below what pacing by the path's length gives."""
    rng = np.random.default_rng(seed)
    centres, widths = rng.uniform(0.2, 0.8, 2), rng.uniform(0.03, 0.08, 2)
    vlim = rng.uniform(1.0, 3.0, 2)

    def q_of(u: np.ndarray) -> np.ndarray:
        return np.tanh((u[:, None] - centres) / widths)

    S, D = 801, 1.0
    t = np.linspace(0.0, D, S)
    progress = minimum_jerk(t / D)
    u = progress.copy()  # paced by length: the path parameter is its length
    paced = joint_paced(u, q_of(u), vlim, progress)
    assert paced[0] == u[0] and paced[-1] == u[-1]
    assert np.all(np.diff(paced) > 0.0)

    def peak(uu: np.ndarray) -> float:
        return float((np.abs(np.diff(q_of(uu), axis=0)) / np.diff(t)[:, None] / vlim).max())

    fine = np.linspace(0.0, 1.0, 200001)
    full = float(np.sum(np.max(np.abs(np.diff(q_of(fine), axis=0)) / vlim, axis=1)))  # [s]
    assert peak(paced) <= 1.25 * MJ_PEAK * full / D * 1.02
    assert peak(u) > 1.5 * peak(paced)


def test_joint_paced_keeps_a_path_whose_joints_do_not_move():
    u = minimum_jerk(np.linspace(0.0, 1.0, 11))
    np.testing.assert_array_equal(joint_paced(u, np.zeros((11, 3)), np.ones(3), u), u)


@pytest.mark.parametrize("seed", [0, 1])
def test_durations_for_moves_keeps_each_path_factor_longer_move_under_the_limits(seed):
    rng = np.random.default_rng(seed)
    q_from, q_to = rng.uniform(-1, 1, 4), rng.uniform(-1, 1, (6, 4))
    vmax = rng.uniform(1.0, 3.0, 4)
    batch = durations_for_moves(q_from, q_to, vmax, minimum_s=0.2, dt_s=0.01)
    for D, q in zip(batch, q_to, strict=True):
        dq = q - q_from
        assert D >= 0.2 and abs(D / 0.01 - round(D / 0.01)) < 1e-9
        assert np.all(_peak_speed(PATH_FACTOR * dq, D) <= vmax * (1 + 1e-6))
        if D > 0.2 + 1e-9:  # one step shorter would not do
            assert np.any(_peak_speed(PATH_FACTOR * dq, D - 0.01) > vmax)


def test_joint_speed_check_skips_joints_without_a_limit_but_not_the_others():
    """A joint whose velocity limit is 0 (none in the URDF) is not counted, as the plan
    re-check does not count it; it neither fails the check nor hides another joint over
    its own limit (10x here)."""
    times = np.array([0.0, 0.01])
    limit = np.array([1.0, 0.0, 1.0])
    still = np.array([[0.0, 0.0, 0.0], [0.005, 0.0, 0.0]])  # 0.5 rad/s, the 0-limit joint still
    check_joint_speed("f", ("a", "b", "c"), limit, times, still)
    moved = np.array([[0.0, 0.0, 0.0], [0.005, 0.3, 0.0]])  # the 0-limit joint at 30 rad/s
    check_joint_speed("f", ("a", "b", "c"), limit, times, moved)
    fast = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.1]])  # c at 10 rad/s
    with pytest.raises(PlanningError) as err:
        check_joint_speed("f", ("a", "b", "c"), limit, times, fast)
    assert err.value.kind == FailureKind.VELOCITY and "joint c" in err.value.reason
    assert err.value.measured == pytest.approx(10.0) and err.value.required == 1.0
