"""The plan file: JSON round trip, field checks, rebuilding the hand and the object."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SHADOW_HAND_FILE, assert_close, shadow_urdf

from regrasp_pin import Box, ContactPhase, Hand, InputError, ModelFileError, Plan, RegraspPhase
from regrasp_pin.plan import PLAN_FORMAT, IdlePhase, JoinPhase, ReleasePhase, hand_record


def _plan() -> Plan:
    hand = Hand.five_finger()
    box = Box((0.04, 0.06, 0.04))
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 1.0, 11)
    q = np.repeat(hand.neutral()[None], t.size, 0) + rng.normal(0, 0.01, (t.size, hand.model.nq))
    quat = np.tile([0.0, 0.0, np.sin(0.1), np.cos(0.1)], (t.size, 1))
    T = np.c_[np.tile([0.065, 0.0, 0.06], (t.size, 1)), quat]
    verts, faces = box.mesh()
    phases = {
        "index": [
            ContactPhase("index", 0.0, 0.4, np.array([0.02, 0.0, 0.0]), np.array([1.0, 0, 0])),
            RegraspPhase(
                "index",
                0.4,
                0.8,
                np.array([0.02, 0.0, 0.0]),
                np.array([0.02, 0.01, 0.01]),
                rng.normal(size=(7, 3)),
                0.004,
                12.5,
                reason="joint limit",
                extra={"grid_path_object": [[0.0, 0.0, 0.0]]},
            ),
            ContactPhase("index", 0.8, 1.0, np.array([0.02, 0.01, 0.01]), np.array([1.0, 0, 0])),
        ],
        "ring": [
            ReleasePhase("ring", 0.2, 1.0, np.array([0.0, -0.02, 0.0]), 0.003, reason="gone"),
        ],
        "little": [
            IdlePhase("little", 0.0, 0.3),
            JoinPhase("little", 0.3, 0.7, np.array([0.0, -0.02, 0.01]), 0.002, reason="joins"),
            ContactPhase("little", 0.7, 1.0, np.array([0.0, -0.02, 0.01]), np.array([0, -1.0, 0])),
        ],
    }
    return Plan(
        hand={
            "name": "five_finger",
            "urdf": "urdf/five_finger_hand.urdf",
            "fingers": {
                n: {
                    "tip_frame": f.tip_frame,
                    "tip_radius": f.tip_radius,
                    "joints": list(f.joint_names),
                }
                for n, f in hand.fingers.items()
            },
        },
        object={
            "kind": box.kind,
            "params": box.params,
            "vertices": verts.tolist(),
            "faces": faces.tolist(),
        },
        t=t,
        q=q,
        T_palm_object=T,
        phases=phases,
        summary={"regrasps": 1},
    )


def test_round_trip(tmp_path):
    plan = _plan()
    path = plan.save(tmp_path / "p" / "plan.json")
    doc = json.loads(path.read_text())
    assert doc["format"] == PLAN_FORMAT
    for key in ("hand", "object", "t", "q", "T_palm_object", "phases"):
        assert key in doc
    back = Plan.load(path)
    assert_close(back.t, plan.t, atol=0.0)
    assert_close(back.q, plan.q, atol=0.0)
    assert_close(back.T_palm_object, plan.T_palm_object, atol=0.0)
    assert back.to_dict() == plan.to_dict()
    r = back.regrasps()[0]
    assert r.reason == "joint limit" and r.extra["grid_path_object"] == [[0.0, 0.0, 0.0]]
    assert_close(r.waypoints_object, plan.phases["index"][1].waypoints_object, atol=0.0)
    (rel,), (join,) = back.releases(), back.joins()
    assert (rel.finger, rel.reason, join.finger, join.reason) == ("ring", "gone", "little", "joins")
    assert_close(join.Q_object, [0.0, -0.02, 0.01], atol=0.0)
    assert (join.t_start, join.t_end, join.min_clearance_m) == (0.3, 0.7, 0.002)
    (idle,) = back.idles()
    assert (idle.finger, idle.kind, idle.t_start, idle.t_end) == ("little", "idle", 0.0, 0.3)


def test_rebuilds_hand_object_and_poses():
    plan = _plan()
    hand = plan.load_hand()
    assert hand.finger_names == ("thumb", "index", "middle", "ring", "little")
    assert hand.model.nq == plan.q.shape[1]
    obj = plan.load_object()
    assert obj.kind == "box"
    assert_close(obj.mesh()[0], np.asarray(plan.object["vertices"]), atol=1e-12)
    T = plan.poses()
    # quaternion (0, 0, sin 0.1, cos 0.1) is a rotation of 0.2 rad about z
    assert_close(T[0, :3, :3][0, :2], [np.cos(0.2), -np.sin(0.2)], atol=1e-12)
    assert_close(T[:, :3, 3], plan.T_palm_object[:, :3], atol=0.0)


def test_bad_plans(tmp_path):
    with pytest.raises(ModelFileError, match="no such plan file"):
        Plan.load(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ModelFileError, match="not JSON"):
        Plan.load(bad)
    doc = _plan().to_dict()
    doc["format"] = "other/1"
    with pytest.raises(InputError, match="format"):
        Plan.from_dict(doc)
    doc = _plan().to_dict()
    doc["t"] = doc["t"][::-1]
    with pytest.raises(InputError, match="strictly increasing"):
        Plan.from_dict(doc)
    doc = _plan().to_dict()
    del doc["q"]
    with pytest.raises(InputError, match="missing field"):
        Plan.from_dict(doc)
    doc = _plan().to_dict()
    doc["phases"]["index"][0]["kind"] = "hover"
    with pytest.raises(InputError, match="unknown phase kind"):
        Plan.from_dict(doc)


def _moved(record: dict, tmp_path) -> dict:
    """The hand record as read on another machine: the URDF is no longer at its path."""
    return {**record, "urdf": str(tmp_path / "elsewhere" / "hand.urdf")}


def test_hand_opens_from_the_stored_urdf_text(tmp_path):
    """A plan made from an installed package (or another checkout) still opens: the
    URDF's text travels with it."""
    hand = Hand.five_finger()
    plan = _plan()
    plan.hand = _moved(hand_record(hand), tmp_path)
    rebuilt = plan.load_hand()
    assert rebuilt.model.nq == hand.model.nq and rebuilt.finger_names == hand.finger_names
    q = np.random.default_rng(0).uniform(hand.finger("index").lower, hand.finger("index").upper)
    assert_close(rebuilt.finger("index").fk(q), hand.finger("index").fk(q), atol=1e-15)
    plan.hand = {k: v for k, v in plan.hand.items() if k != "urdf_text"}
    with pytest.raises(ModelFileError, match="stores no text"):
        plan.load_hand()


def test_shadow_plan_hand_keeps_its_load_options_and_meshes(tmp_path):
    """Palm frame, locked wrist and couplings are stored; meshes are found through the
    stored folder, or a folder given when the plan is opened."""
    shadow_urdf()
    hand = Hand.from_file(SHADOW_HAND_FILE)
    record = json.loads(json.dumps(hand_record(hand)))  # as written to and read from a file
    plan = _plan()
    plan.hand = _moved(record, tmp_path)
    rebuilt = plan.load_hand()
    assert rebuilt.model.nq == hand.model.nq
    assert rebuilt.finger("index").joint_names == ("FFJ4", "FFJ3", "FFJ2")
    assert rebuilt.collision_model.ngeoms == hand.collision_model.ngeoms
    plan.hand = {**plan.hand, "package_dirs": []}
    with pytest.raises(ModelFileError):
        plan.load_hand()  # no folder holds the meshes
    assert plan.load_hand(package_dirs=[shadow_urdf().parent]).model.nq == hand.model.nq


def test_repr_is_short():
    """A plan's repr names it; it does not print the URDF text and every sample."""
    text = repr(_plan())
    assert text.startswith("Plan(hand='five_finger', object='box', 11 samples")
    assert len(text) < 200


def test_the_stored_urdf_wins_over_a_changed_file(tmp_path):
    """A plan rebuilds the hand it was made with, even if the file at its path changed."""
    from regrasp_pin.model.hand import FIVE_FINGER_TIPS, five_finger_urdf_path

    urdf = tmp_path / "hand.urdf"
    urdf.write_text(five_finger_urdf_path().read_text())
    hand = Hand.from_urdf(urdf, FIVE_FINGER_TIPS, tip_radius=0.008)
    plan = _plan()
    plan.hand = hand_record(hand)
    urdf.write_text(urdf.read_text().replace('upper="1.745329"', 'upper="0.5"'))
    rebuilt = plan.load_hand()
    assert_close(rebuilt.finger("index").upper, hand.finger("index").upper, atol=0.0)
    assert Hand.from_urdf(urdf, FIVE_FINGER_TIPS, tip_radius=0.008).finger("index").upper.min() < 1
