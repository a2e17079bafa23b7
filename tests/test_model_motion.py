"""Object motion: closed-form twists, interpolation, conversions, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import InputError
from regrasp_pin.model.motion import ObjectMotion

AXIS = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
POINT = np.array([0.02, 0.01, 0.1])
RATE = 1.3  # rad/s
VEL = np.array([0.0, 0.01, -0.005])


def _start_pose() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.2, 0.5, -0.1]).as_matrix()
    T[:3, 3] = [0.05, -0.01, 0.12]
    return T


def _closed_form(tau: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, written independently of the implementation."""
    T0 = _start_pose()
    K = np.array([[0, -AXIS[2], AXIS[1]], [AXIS[2], 0, -AXIS[0]], [-AXIS[1], AXIS[0], 0]])
    out = np.zeros((tau.size, 4, 4))
    for i, t in enumerate(tau):
        a = RATE * t
        Ra = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
        out[i, :3, :3] = Ra @ T0[:3, :3]
        out[i, :3, 3] = Ra @ (T0[:3, 3] - POINT) + POINT + VEL * t
        out[i, 3, 3] = 1.0
    return out


@pytest.fixture(scope="module")
def twist() -> ObjectMotion:
    return ObjectMotion.constant_twist(
        _start_pose(),
        axis_palm=AXIS,
        point_palm=POINT,
        rate_rad_s=RATE,
        velocity_palm_m_s=VEL,
        duration_s=2.0,
        dt_s=0.01,
    )


def test_constant_twist_is_exact_at_the_samples(twist):
    assert len(twist) == 201 and twist.t_start == 0.0 and twist.t_end == 2.0
    assert_close(np.diff(twist.times_s), np.full(200, 0.01), atol=1e-12, what="grid")
    assert_close(twist.T_palm_object, _closed_form(twist.times_s), atol=1e-12, what="samples")
    assert_close(twist.pose(twist.times_s), twist.T_palm_object, atol=1e-12, what="pose()")


def test_constant_twist_keeps_the_axis_point_fixed(twist):
    # A point of the object on the axis stays put (without drift): check with VEL = 0.
    still = ObjectMotion.constant_twist(
        _start_pose(), axis_palm=AXIS, point_palm=POINT, rate_rad_s=RATE, duration_s=1.0, dt_s=0.1
    )
    T0 = _start_pose()
    p_obj = T0[:3, :3].T @ (POINT + 0.03 * AXIS - T0[:3, 3])
    p = still.transform_points(still.times_s, p_obj[None])[:, 0]
    assert_close(p, np.tile(POINT + 0.03 * AXIS, (len(still), 1)), atol=1e-12, what="axis")


def test_interpolation_between_samples(twist):
    mid = twist.times_s[:-1] + 0.005
    got, exact = twist.pose(mid), _closed_form(mid)
    # Slerp is exact for a constant-axis rotation; the translation chord deviates from
    # the arc by about r (rate dt)^2 / 8 (r <= 0.05 m here).
    assert_close(got[:, :3, :3], exact[:, :3, :3], atol=1e-12, what="rotation")
    assert_close(
        got[:, :3, 3],
        exact[:, :3, 3],
        atol=0.05 * (RATE * 0.01) ** 2 / 8 + 1e-12,
        what="translation",
    )
    # Rotation blocks remain rotations.
    R = got[:, :3, :3]
    assert_close(
        np.einsum("kji,kjl->kil", R, R),
        np.broadcast_to(np.eye(3), R.shape),
        atol=1e-12,
        what="orthonormal",
    )


def test_slerp_of_two_poses_at_half_time():
    Ta, Tb = np.eye(4), np.eye(4)
    Tb[:3, :3] = Rotation.from_rotvec([0.0, 0.0, np.pi / 2]).as_matrix()
    Tb[:3, 3] = [0.1, 0.0, -0.2]
    motion = ObjectMotion.from_poses([1.0, 3.0], np.stack([Ta, Tb]))
    half = motion.pose(2.0)
    assert_close(
        half[:3, :3],
        Rotation.from_rotvec([0, 0, np.pi / 4]).as_matrix(),
        atol=1e-12,
        what="half rotation",
    )
    assert_close(half[:3, 3], [0.05, 0.0, -0.1], atol=1e-15, what="half translation")
    assert motion.duration_s == 2.0


def test_transform_points_and_directions_shapes_and_values(twist):
    rng = np.random.default_rng(0)
    p = rng.normal(size=(5, 3)) * 0.02
    times = np.array([0.0, 0.333, 1.9])
    batch = twist.transform_points(times, p)
    assert batch.shape == (3, 5, 3)
    for k, t in enumerate(times):
        T = twist.pose(t)
        assert_close(batch[k], p @ T[:3, :3].T + T[:3, 3], atol=1e-15, what="points")
        assert_close(twist.transform_points(t, p), batch[k], atol=0, what="scalar t")
        assert_close(
            twist.transform_directions(t, p), p @ T[:3, :3].T, atol=1e-15, what="directions"
        )
    back = twist.to_object(times, batch[1])  # (K, N, 3): the palm points seen at each time
    assert back.shape == (3, 5, 3)
    assert_close(back[1], p, atol=1e-15, what="inverse at the matching time")
    assert_close(twist.to_object(0.333, batch[1]), p, atol=1e-15, what="inverse")


def test_xyzquat_round_trip_and_resample(twist):
    xq = twist.as_xyzquat()
    assert xq.shape == (len(twist), 7)
    again = ObjectMotion.from_xyzquat(twist.times_s, xq)
    assert_close(again.T_palm_object, twist.T_palm_object, atol=1e-12, what="round trip")
    times = np.array([0.123, 1.5])
    assert_close(
        ObjectMotion.from_xyzquat(twist.times_s, xq).as_xyzquat(times),
        twist.as_xyzquat(times),
        atol=1e-12,
        what="interpolated xyzquat",
    )
    coarse = twist.resample(0.3)
    assert len(coarse) == 8  # ceil(2.0 / 0.3) = 7 steps
    assert_close(coarse.T_palm_object, twist.pose(coarse.times_s), atol=1e-12, what="resample")


@pytest.mark.parametrize("t", [-0.1, 2.1, np.array([0.5, 3.0])])
def test_times_outside_range_are_refused(twist, t):
    with pytest.raises(InputError) as info:
        twist.pose(t)
    assert info.value.argument == "t_s"
    assert "[0, 2]" in str(info.value)


def test_bad_poses_and_times():
    good = np.stack([np.eye(4)] * 3)
    nan = good.copy()
    nan[1, 0, 3] = np.nan
    skew = good.copy()
    skew[2, :3, :3] = np.diag([1.0, 1.0, 1.1])
    mirror = good.copy()
    mirror[1, :3, :3] = np.diag([1.0, 1.0, -1.0])
    cases = [
        ([0.0, 1.0, 2.0], nan, "T_palm_object", "NaN"),
        ([0.0, 1.0, 1.0], good, "times_s", "strictly increasing"),
        ([0.0, 2.0, 1.0], good, "times_s", "strictly increasing"),
        ([0.0, np.nan, 2.0], good, "times_s", "NaN"),
        ([0.0, 1.0, 2.0], skew, "T_palm_object", "not a rotation"),
        ([0.0, 1.0, 2.0], mirror, "T_palm_object", "not a rotation"),
        ([0.0], good[:1], "times_s", "at least 2"),
        ([0.0, 1.0], good, "T_palm_object", "shape"),
    ]
    for times, poses, argument, words in cases:
        with pytest.raises(InputError, match=words) as info:
            ObjectMotion.from_poses(times, poses)
        assert info.value.argument == argument


def test_bad_twist_arguments():
    kw = dict(axis_palm=[0, 0, 1], point_palm=[0, 0, 0], rate_rad_s=1.0, duration_s=1.0)
    for change, argument in [
        ({"axis_palm": [0, 0, 0]}, "axis_palm"),
        ({"duration_s": 0.0}, "duration_s"),
        ({"dt_s": -0.01}, "dt_s"),
        ({"rate_rad_s": 100.0, "dt_s": 0.1}, "dt_s"),  # a step turns more than pi
        ({"point_palm": [0, np.nan, 0]}, "point_palm"),
    ]:
        with pytest.raises(InputError) as info:
            ObjectMotion.constant_twist(np.eye(4), **{**kw, **change})
        assert info.value.argument == argument
    with pytest.raises(InputError) as info:
        ObjectMotion.constant_twist(np.diag([1.0, 1.0, 2.0, 1.0]), **kw)
    assert info.value.argument == "T_palm_object_start"
    with pytest.raises(InputError) as info:
        ObjectMotion.from_xyzquat([0.0, 1.0], np.zeros((2, 7)))
    assert info.value.argument == "xyzquat"


def test_rotations_are_scipys_slerp_and_each_point_alone():
    # random rotations, steps from 1e-7 rad (the series branch) to nearly pi
    from scipy.spatial.transform import Slerp

    rng = np.random.default_rng(41)
    steps = [1e-7, 3e-5, 1e-3, 0.5, 2.0, 3.1]
    R = [Rotation.random(random_state=7)]
    for angle in steps:
        axis = rng.normal(size=3)
        R.append(R[-1] * Rotation.from_rotvec(angle * axis / np.linalg.norm(axis)))
    rot = Rotation.concatenate(R)
    t = np.arange(len(R), dtype=float)
    motion = ObjectMotion(t, rot, rng.normal(size=(len(R), 3)))
    tq = np.sort(np.concatenate([rng.uniform(0, t[-1], 400), t]))
    got = motion.pose(tq)[:, :3, :3]
    assert_close(got, Slerp(t, rot)(tq).as_matrix(), atol=2e-15, what="slerp")
    assert_close(got[np.isin(tq, t)], rot.as_matrix(), atol=2e-15, what="at the samples")
    assert motion.pose(tq[5:9]).tobytes() == motion.pose(tq)[5:9].tobytes()


def test_poses_asked_for_again_are_the_same_bits_and_the_callers_own():
    from regrasp_pin.model import motion as motion_module

    fresh = ObjectMotion.constant_twist(
        _start_pose(), axis_palm=AXIS, point_palm=POINT, rate_rad_s=RATE,
        velocity_palm_m_s=VEL, duration_s=2.0, dt_s=0.01,
    )  # fmt: skip
    rng = np.random.default_rng(3)
    times = [rng.uniform(0.0, 2.0, int(n)) for n in rng.integers(1, 50, 80)]
    scalars = [0.0, -0.0, 1.25, 2.0]
    first = [fresh.pose(t) for t in times] + [fresh.pose(t) for t in scalars]
    first[0][:] = 0.0  # the caller's copy: the kept poses must not change with it
    first[0] = fresh.pose(times[0].copy())
    again = [fresh.pose(t.copy()) for t in times] + [fresh.pose(t) for t in scalars]
    assert len(fresh._poses) <= motion_module._POSES_KEPT
    # an independent motion (nothing kept yet) answers each one alone
    for t, a, b in zip(times + scalars, first, again, strict=True):
        other = ObjectMotion.constant_twist(
            _start_pose(), axis_palm=AXIS, point_palm=POINT, rate_rad_s=RATE,
            velocity_palm_m_s=VEL, duration_s=2.0, dt_s=0.01,
        )  # fmt: skip
        assert a.tobytes() == b.tobytes() == other.pose(t).tobytes()
    # bad times are still refused
    with pytest.raises(InputError, match="t_s"):
        fresh.pose(np.array([2.5]))
    import pickle

    assert pickle.loads(pickle.dumps(fresh))._poses == {}
