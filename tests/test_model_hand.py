"""Hand loading, finger data, configuration helpers and bad input."""

from __future__ import annotations

import subprocess
import sys

import coal
import numpy as np
import pinocchio as pin
import pytest

import regrasp_pin
from regrasp_pin import Hand, InputError, ModelFileError, UnknownNameError
from regrasp_pin.model.hand import five_finger_urdf_path


@pytest.fixture(scope="module")
def five():
    return Hand.five_finger()


def test_five_finger_structure(five):
    assert five.finger_names == ("thumb", "index", "middle", "ring", "little")
    for f in five.fingers.values():
        assert f.k == 3  # a 3-D joint space per finger, as in the paper's Fig. 2
        assert f.tip_radius == pytest.approx(0.008)
        assert np.all(f.lower < f.upper)
        assert len(f.tip_geometry_ids) == 2
    idx = five.fingers["index"]
    assert idx.joint_names == ("index_abd", "index_mcp", "index_pip")
    assert np.degrees(idx.upper[1]) == pytest.approx(90.0)
    assert np.degrees(five.fingers["little"].lower[0]) == pytest.approx(-30.0)


def test_index_proportions_and_tip_sphere(five):
    # straight index finger: tip 45 + 25 + 22 mm beyond the MCP joint
    model, data = five.model, five.model.createData()
    q = five.to_full("index", np.zeros(3))
    pin.framesForwardKinematics(model, data, q)
    mcp = data.oMi[model.getJointId("index_mcp")].translation
    tip = data.oMf[model.getFrameId("index_tip")].translation
    assert np.linalg.norm(tip - mcp) == pytest.approx(0.092, abs=1e-9)
    # the fingertip sphere is centred on the tip frame
    geom = five.collision_model.geometryObjects[five.fingers["index"].tip_geometry_ids[-1]]
    assert isinstance(geom.geometry, coal.Sphere)
    assert geom.geometry.radius == pytest.approx(0.008)


def test_collision_model_is_primitives_coal_can_use(five):
    kinds = {type(g.geometry).__name__ for g in five.collision_model.geometryObjects}
    assert kinds == {"Box", "Cylinder", "Sphere"}
    # Coal distance between two fingertips at a known configuration equals the
    # distance of the sphere centres minus both radii
    model, data = five.model, five.model.createData()
    gdata = pin.GeometryData(five.collision_model)
    q = five.neutral()
    pin.framesForwardKinematics(model, data, q)
    pin.updateGeometryPlacements(model, data, five.collision_model, gdata)
    gi = five.fingers["index"].tip_geometry_ids[-1]
    gm = five.fingers["middle"].tip_geometry_ids[-1]
    objs = five.collision_model.geometryObjects
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    d = coal.distance(objs[gi].geometry, gdata.oMg[gi], objs[gm].geometry, gdata.oMg[gm], req, res)
    centres = np.linalg.norm(
        data.oMf[model.getFrameId("index_tip")].translation
        - data.oMf[model.getFrameId("middle_tip")].translation
    )
    assert d == pytest.approx(centres - 0.016, abs=1e-9)


def test_allegro_loads_offline():
    hand = Hand.allegro()
    assert hand.finger_names == ("thumb", "index", "middle", "ring")
    assert all(f.k == 4 for f in hand.fingers.values())
    assert hand.fingers["index"].tip_radius == pytest.approx(0.012)


def test_full_configuration_round_trip(five):
    rng = np.random.default_rng(5)
    q = rng.uniform(-1, 1, (7, 3))
    full = five.to_full("ring", q)
    assert full.shape == (7, five.model.nq)
    np.testing.assert_array_equal(five.from_full("ring", full), q)
    # other fingers keep the base configuration
    others = np.setdiff1d(np.arange(five.model.nq), five.fingers["ring"].q_indices)
    np.testing.assert_array_equal(full[:, others], np.broadcast_to(five.neutral()[others], (7, 12)))


def test_from_urdf_matches_five_finger(five):
    hand = Hand.from_urdf(five_finger_urdf_path(), {"index": "index_tip"}, tip_radius=0.008)
    q = np.array([0.1, 0.5, 0.7])
    np.testing.assert_allclose(hand.fingers["index"].fk(q), five.fingers["index"].fk(q))


def test_bad_inputs(five, tmp_path):
    with pytest.raises(UnknownNameError) as err:
        five.finger("pinky")
    assert "thumb" in str(err.value) and "little" in str(err.value)
    with pytest.raises(UnknownNameError, match="index_tip"):
        Hand.from_urdf(five_finger_urdf_path(), {"index": "nope"}, tip_radius=0.008)
    with pytest.raises(ModelFileError, match="no such URDF"):
        Hand.from_urdf(tmp_path / "missing.urdf", {"a": "b"}, tip_radius=0.01)
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot><link")
    with pytest.raises(ModelFileError, match="bad.urdf.*not valid XML"):
        Hand.from_urdf(bad, {"a": "b"}, tip_radius=0.01)
    unparsable = tmp_path / "unparsable.urdf"
    unparsable.write_text("<robot><link/></robot>")  # XML, but not a URDF Pinocchio takes
    with pytest.raises(ModelFileError, match="cannot be loaded by Pinocchio"):
        Hand.from_urdf(unparsable, {"a": "b"}, tip_radius=0.01)
    with pytest.raises(InputError, match="tip_radius"):
        Hand.from_urdf(five_finger_urdf_path(), {"index": "index_tip"}, tip_radius=-1)
    f = five.fingers["index"]
    with pytest.raises(InputError, match=r"q: has shape \(2, 4\)"):
        f.fk(np.zeros((2, 4)))
    with pytest.raises(InputError, match="NaN or inf"):
        f.fk(np.array([0.0, np.nan, 0.0]))
    with pytest.raises(InputError, match="q_finger"):
        five.to_full("index", np.zeros(2))


def test_limit_margin_and_within_limits(five):
    f = five.fingers["index"]
    q = np.array([f.lower + 0.1, f.upper + 0.05])
    np.testing.assert_allclose(f.limit_margin(q), [0.1, -0.05])
    np.testing.assert_array_equal(f.within_limits(q), [True, False])


def test_import_does_not_load_viewers():
    code = (
        "import sys, regrasp_pin; "
        "bad = [m for m in ('meshcat', 'matplotlib') if m in sys.modules]; "
        "print(','.join(bad))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_every_exported_name_exists():
    for name in regrasp_pin.__all__:
        assert hasattr(regrasp_pin, name), name
