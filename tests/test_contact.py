"""Tests of the contact model (regrasp_pin.grasp.contact).

Scene (palm frame: x toward the fingers, z out of the palm): the five-finger hand and a
box 40 x 60 x 40 mm. Tip targets and pad cosines are checked against their formulas
written out per point; the Coal clearances against Pinocchio's own distance pipeline
(the object added to a copy of the hand's GeometryModel, ``pin.computeDistances`` over
explicit collision pairs), which shares no code with :mod:`regrasp_pin.grasp.contact`.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

from regrasp_pin.grasp.contact import (
    ContactModel,
    FingerClearance,
    LinkClearance,
    pad_cosines,
    tip_targets,
)
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.objects import Box


@pytest.fixture(scope="module")
def hand() -> Hand:
    return Hand.five_finger()


@pytest.fixture(scope="module")
def box() -> Box:
    return Box((0.04, 0.06, 0.04))


def _random_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    T = np.zeros((n, 4, 4))
    T[:, :3, :3] = Rotation.random(n, random_state=rng.integers(1 << 31)).as_matrix()
    T[:, :3, 3] = rng.uniform(-0.1, 0.1, (n, 3))
    T[:, 3, 3] = 1.0
    return T


def _pinocchio_distances(hand: Hand, geometry_ids, others, q_full, T_palm_object=None, obj=None):
    """Smallest distance between ``geometry_ids`` and ``others`` (or the object)."""
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    if obj is not None:
        placement = pin.SE3(T_palm_object[:3, :3], T_palm_object[:3, 3])
        oid = gm.addGeometryObject(pin.GeometryObject("object", 0, placement, obj.coal_geometry()))
        others = [oid]
    for a in geometry_ids:
        for b in others:
            gm.addCollisionPair(pin.CollisionPair(int(a), int(b)))
    data = hand.model.createData()
    gdata = pin.GeometryData(gm)
    pin.computeDistances(hand.model, data, gm, gdata, q_full)
    return min(r.min_distance for r in gdata.distanceResults)


def test_contact_model_defaults_are_consistent():
    cm = ContactModel()
    assert_close(cm.cos_cone, 0.5, atol=1e-15, what="cos 60 deg")
    # a new contact must start farther from the limits than the trigger margin, or it
    # would be let go at once
    assert cm.choice_margin_rad > cm.limit_margin_rad
    assert cm.choice_link_clearance_m >= cm.link_clearance_m


def test_tip_targets_are_the_sphere_centres_in_the_palm_frame(hand, box):
    rng = np.random.default_rng(1)
    sample = box.sample_surface(0.01)
    r = hand.finger("index").tip_radius
    T = _random_poses(rng, 4)
    got = tip_targets(sample.points, sample.normals, r, T)
    assert got.shape == (4, len(sample), 3)
    for t in range(4):
        for i in range(0, len(sample), 7):
            c = sample.points[i] + r * sample.normals[i]
            expected = T[t, :3, :3] @ c + T[t, :3, 3]
            assert_close(got[t, i], expected, atol=1e-15, what=f"target t={t} i={i}")
        single = tip_targets(sample.points, sample.normals, r, T[t])
        assert_close(single, got[t], atol=0.0, what="one pose = that slice of many")
    # the sphere touches the surface: the centre is r from the box along the normal
    c_object = sample.points + r * sample.normals
    assert_close(
        box.signed_distance(c_object),
        np.full(len(sample), r),
        atol=1e-12,
        what="centre at r from the surface",
    )


def test_pad_cosines_match_the_tip_frame(hand):
    rng = np.random.default_rng(2)
    for name in hand.finger_names:
        f = hand.finger(name)
        q = rng.uniform(f.lower, f.upper, (50, f.k))
        n_palm = rng.normal(size=(50, 3))
        n_palm /= np.linalg.norm(n_palm, axis=1, keepdims=True)
        got = pad_cosines(f, q, n_palm)
        expected = np.empty(50)
        for i in range(50):
            R, _ = f.tip_poses(q[i])
            expected[i] = float((R @ f.pad_axis_tip) @ -n_palm[i])
        assert_close(got, expected, atol=1e-12, what=f"{name} pad cosines")
        # a surface whose inward normal is the pad direction is faced squarely
        pads = f.pad_normals(q)
        assert_close(pad_cosines(f, q, -pads), np.ones(50), atol=1e-12, what="facing")
        assert_close(pad_cosines(f, q, pads), -np.ones(50), atol=1e-12, what="back")


def test_pad_points_where_the_tip_moves_when_the_finger_flexes(hand):
    # the default pad axis is the tip's motion under the last joint of the chain; the
    # last independent joint also drives it (through the coupled DIP on the fingers)
    for name in hand.finger_names:
        f = hand.finger(name)
        dq = np.zeros(f.k)
        dq[-1] = 1e-6
        v = (f.fk(f.q_mid + dq) - f.fk(f.q_mid)) / 1e-6
        assert v @ f.pad_normals(f.q_mid) / np.linalg.norm(v) > 0.95, name


@pytest.mark.parametrize("finger", ["thumb", "index", "little"])
def test_link_clearance_matches_pinocchio_distances(hand, box, finger):
    rng = np.random.default_rng(3)
    f = hand.finger(finger)
    lc = LinkClearance(hand, finger, box)
    lc_tip = LinkClearance(hand, finger, box, include_tip=True)
    assert set(lc.geometry_ids) == set(f.geometry_ids) - set(f.tip_geometry_ids)
    assert lc.geometry_ids and f.tip_geometry_ids
    q = rng.uniform(f.lower, f.upper, (6, f.k))
    q_full = hand.to_full(finger, q)
    T = np.tile(np.eye(4), (6, 1, 1))
    T[:, :3, :3] = Rotation.random(6, random_state=4).as_matrix()
    # object near the finger: centred between the tip and the middle of the finger
    T[:, :3, 3] = 0.5 * f.fk(q) + rng.uniform(-0.01, 0.01, (6, 3))
    got = lc(q_full, T)
    got_tip = lc_tip(q_full, T)
    for i in range(6):
        expected = _pinocchio_distances(hand, lc.geometry_ids, None, q_full[i], T[i], box)
        expected_tip = _pinocchio_distances(hand, f.geometry_ids, None, q_full[i], T[i], box)
        assert_close(got[i], expected, atol=1e-9, what=f"links, config {i}")
        assert_close(got_tip[i], expected_tip, atol=1e-9, what=f"with tip, config {i}")
    assert np.all(got_tip <= got + 1e-12)
    # one pose for all configurations broadcasts
    assert_close(
        lc(q_full, T[0]),
        [lc(q_full[i : i + 1], T[0])[0] for i in range(6)],
        atol=0.0,
        what="broadcast pose",
    )


def test_link_clearance_is_negative_when_the_object_swallows_a_link(hand, box):
    f = hand.finger("index")
    q_full = hand.to_full("index", f.q_mid)
    lc = LinkClearance(hand, "index", box)
    # the object's centre on the proximal joint: the box surrounds the first link
    data = hand.model.createData()
    pin.forwardKinematics(hand.model, data, q_full)
    T = np.eye(4)
    T[:3, 3] = data.oMi[int(f.chain.joint_ids[1])].translation
    assert lc(q_full[None], T)[0] < 0.0
    T[:3, 3] = [1.0, 1.0, 1.0]  # far away: about the distance to the box
    assert lc(q_full[None], T)[0] > 1.0


def test_finger_clearance_matches_pinocchio_distances(hand):
    rng = np.random.default_rng(5)
    for finger in ("index", "thumb"):
        fc = FingerClearance(hand, finger)
        mine = hand.finger(finger).geometry_ids
        others = [g for n, o in hand.fingers.items() if n != finger for g in o.geometry_ids]
        for _ in range(3):
            q = hand.neutral()
            for f in hand.fingers.values():
                q[f.q_indices] = rng.uniform(f.lower, f.upper)
            expected = _pinocchio_distances(hand, mine, others, q)
            assert_close(fc(q), expected, atol=1e-9, what=f"{finger} to the other fingers")


def test_finger_clearance_sees_two_fingers_pressed_together(hand):
    # index and middle both abducted toward each other until their links overlap
    fc = FingerClearance(hand, "index")
    q = hand.neutral()
    base = fc(q)
    idx, mid = hand.finger("index"), hand.finger("middle")
    # turn each abduction joint to the end that brings it toward the other finger
    best = base
    for a in (idx.lower[0], idx.upper[0]):
        for b in (mid.lower[0], mid.upper[0]):
            q2 = q.copy()
            q2[idx.q_indices[0]], q2[mid.q_indices[0]] = a, b
            best = min(best, fc(q2))
    assert best < base
