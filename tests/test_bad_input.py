"""The bad-input table: each case a user met (issue 14), the error type, and that the
message names the argument and what is accepted. (Per-module checks live beside each
module's tests; this table keeps the cases a new user reported in one place.)"""

from __future__ import annotations

import json

import numpy as np
import pytest

from regrasp_pin import ObjectMotion, Plan, make_scenario
from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.polygon.approximate import approximate_polygon


@pytest.fixture(scope="module")
def scen():
    return make_scenario("five_finger", "hexagon")


def test_an_unknown_finger_lists_the_hand_s_fingers(scen):
    with pytest.raises(UnknownNameError) as err:
        scen.hand.fingers["pinky"]  # the way the README reaches a finger
    text = str(err.value)
    assert text.startswith("fingers: unknown name 'pinky'")
    assert all(repr(n) in text for n in ("thumb", "index", "little"))
    assert isinstance(err.value, KeyError)  # `except KeyError` still works
    assert scen.hand.fingers.get("pinky") is None  # and so does .get


def test_a_finger_name_where_a_finger_is_needed(scen):
    sample = scen.obj.sample_surface(0.004)
    with pytest.raises(InputError, match=r"^finger: is a str.*hand\.finger\('index'\)"):
        build_manifold("index", sample, scen.motion, np.array([0.0]))


def test_1d_points_ask_for_the_right_shape():
    with pytest.raises(InputError, match=r"points: has shape \(10,\).*\(n, 2\) or \(n, 3\)"):
        approximate_polygon(np.arange(10.0), 3)


@pytest.mark.parametrize(
    ("points", "m", "message"),
    [
        (np.zeros((10, 2)), 3, "all 10 points are equal"),
        ([[0, 0], [0, 0], [1, 0], [1, 0], [1, 1e-13]], 3, "has 2 distinct points for m=3"),
    ],
)
def test_degenerate_curves_are_refused(points, m, message):
    with pytest.raises(InputError, match=f"^points: {message}"):
        approximate_polygon(np.asarray(points, float), m)


def test_a_straight_curve_is_approximated_with_zero_error():
    """Documented: every choice of vertices is optimal on a line (energy 0)."""
    line = np.c_[np.linspace(0.0, 1.0, 20), np.zeros(20)]
    for method in ("hopfield", "exact"):
        res = approximate_polygon(line, 4, method=method, deviation="ise")
        assert res.energy == pytest.approx(0.0, abs=1e-15)
        assert res.indices[0] == 0 and res.indices[-1] == 19  # an open curve keeps its ends
        assert len(set(res.indices.tolist())) == 4


def test_a_plan_file_that_is_not_an_object(tmp_path):
    path = tmp_path / "list.json"
    path.write_text("[1, 2]")
    with pytest.raises(InputError, match=r"^plan: is a JSON list"):
        Plan.load(path)


def test_a_plan_with_an_unknown_object_kind_is_refused(tmp_path, scen):
    from regrasp_pin.planning.planner import plan_manipulation

    plan = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    ).plan
    doc = plan.to_dict()
    doc["object"]["kind"] = "sphere"
    path = tmp_path / "sphere.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"^object\.kind: is 'sphere'.*'prism'"):
        Plan.load(path)


def test_the_turn_direction_is_the_angle_s_sign_not_the_rate_s():
    with pytest.raises(InputError, match=r"^rate_deg_s: -20 .*negative angle_deg"):
        make_scenario("five_finger", "hexagon", rate_deg_s=-20)
    # a twist's rate is signed (right-hand rule about its axis): -rate about a is +rate
    # about -a, the same motion
    T0 = np.eye(4)
    a = ObjectMotion.constant_twist(T0, axis_palm=[0, 0, 1], point_palm=[0.01, 0, 0],
                                    rate_rad_s=-1.0, duration_s=1.0)  # fmt: skip
    b = ObjectMotion.constant_twist(T0, axis_palm=[0, 0, -1], point_palm=[0.01, 0, 0],
                                    rate_rad_s=1.0, duration_s=1.0)  # fmt: skip
    t = np.linspace(0.0, 1.0, 7)
    np.testing.assert_allclose(a.pose(t), b.pose(t), atol=1e-12)
