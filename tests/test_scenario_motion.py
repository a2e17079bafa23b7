"""A user's own motion: relative twists, CSV poses, and a scenario built on them."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import InputError, ModelFileError
from regrasp_pin.grasp.quality import ferrari_canny_epsilon
from regrasp_pin.scenario_motion import (
    relative_motion_from_csv,
    relative_twist,
    scenario_for_motion,
)
from regrasp_pin.scenarios import hand_model, setup_fingers, setup_objects


def test_relative_twist_turns_about_its_axis_through_its_point():
    rel = relative_twist(
        axis_object=(0, 0, 2), point_object=(0.01, 0, 0), angle_deg=-90, rate_deg_s=45
    )
    assert rel.duration_s == pytest.approx(2.0)
    T = rel.pose(rel.t_end)
    assert_close(T[:3, :3], Rotation.from_euler("z", -90, degrees=True).as_matrix(), atol=1e-12)
    c = np.array([0.01, 0.0, 0.0])
    assert_close(T[:3, :3] @ c + T[:3, 3], c, atol=1e-12, what="the axis point stays")
    p = np.array([-0.01, 0.0, 0.0])  # 2 cm from the axis: a quarter turn clockwise about c
    assert_close(T[:3, :3] @ p + T[:3, 3], [0.01, 0.02, 0.0], atol=1e-12)
    assert_close(rel.pose(rel.t_start), np.eye(4), atol=1e-15)


def test_csv_poses_are_the_motion_they_describe(tmp_path):
    rel = relative_twist(axis_object=(1, 1, 0), angle_deg=60, rate_deg_s=30, dt_s=0.05)
    rows = np.c_[rel.times_s, rel.as_xyzquat()]
    path = tmp_path / "motion.csv"
    path.write_text(
        "t,x,y,z,qx,qy,qz,qw\n" + "\n".join(",".join(f"{v:.12g}" for v in r) for r in rows)
    )
    back = relative_motion_from_csv(path)
    t = np.linspace(0.0, rel.t_end, 13)
    assert_close(back.pose(t), rel.pose(t), atol=1e-9)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0\n", "line 2 has 7 columns"),
        ("0,0.01,0,0,0,0,0,1\n1,0,0,0,0,0,0,1\n", "the first pose is"),
        ("0,0,0,0,0,0,0,1\n", "1 pose"),
        ("0,0,0,0,0,0,0,1\n1,a,0,0,0,0,0,1\n", "line 2 is not numeric"),
    ],
)
def test_bad_csv_is_named(tmp_path, text, message):
    path = tmp_path / "m.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=f"^motion: .*{message}"):
        relative_motion_from_csv(path)
    with pytest.raises(ModelFileError):
        relative_motion_from_csv(tmp_path / "missing.csv")


def test_zero_axis_is_refused():
    with pytest.raises(InputError, match="axis_object"):
        relative_twist(axis_object=(0, 0, 0))


def test_a_scenario_follows_the_relative_motion_from_where_it_holds_the_object():
    hand = hand_model("five_finger")
    obj = setup_objects("five_finger")["hexagon"]()
    rel = relative_twist(angle_deg=60, rate_deg_s=20)
    scen = scenario_for_motion(hand, obj, rel, fingers=setup_fingers("five_finger"))
    T0 = scen.motion.pose(scen.motion.t_start)
    t = np.linspace(rel.t_start, rel.t_end, 9)
    assert_close(scen.motion.pose(t), T0 @ rel.pose(t), atol=1e-9)  # T0 T_rel(t)
    g = scen.grasp
    names = list(g.indices)
    P = np.array([g.points_object[n] for n in names])
    N = np.array([g.normals_object[n] for n in names])
    assert ferrari_canny_epsilon(P, N, 0.8, torque_scale_m=obj.radius_m) > 0  # force closure
    assert "60" not in scen.description or "own motion" in scen.description
    # the grasp was chosen for the motion itself, with no pivot (a backup's search)
    search = scen.grasp_search
    assert search.motion is scen.motion and search.pivot is None
    assert search.choose(hand, obj).indices == g.indices


def test_the_example_csv_is_a_motion_from_the_identity():
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "objects" / "turn_and_drift.csv"
    rel = relative_motion_from_csv(path)
    assert rel.duration_s == pytest.approx(2.0)
    end = rel.pose(rel.t_end)
    assert_close(end[:3, 3], [0.006, 0.0, 0.0], atol=1e-9, what="the drift [m]")
    angle = np.degrees(Rotation.from_matrix(end[:3, :3]).magnitude())
    assert angle == pytest.approx(10.0, abs=1e-4)
