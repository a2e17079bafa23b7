"""Tests of the contact model (regrasp_pin.grasp.contact).

Scene (palm frame: x toward the fingers, z out of the palm): the five-finger hand and a
box 40 x 60 x 40 mm. Tip targets and pad cosines are checked against their formulas
written out per point (the Coal clearances: tests/test_model_clearance.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

from regrasp_pin.exceptions import InputError
from regrasp_pin.grasp.contact import (
    ContactModel,
    pad_cosines,
    pad_cosines_and_overshoot,
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


def test_contact_model_defaults_are_consistent():
    cm = ContactModel()
    assert cm.cone_deg is None  # each finger's own pad cone
    # a new contact must start farther from the limits than the trigger margin, or it
    # would be let go at once
    assert cm.choice_margin_rad > cm.limit_margin_rad
    assert cm.choice_link_clearance_m >= cm.link_clearance_m


def test_the_pad_cone_is_the_fingers_own_unless_the_model_sets_one(hand):
    f = hand.finger("index")
    assert ContactModel().cone_deg_of(f) == f.pad_cone_deg == 90.0  # the tip sphere
    assert_close(ContactModel().cos_cone_of(f), 0.0, atol=1e-15, what="cos 90 deg")
    assert ContactModel(cone_deg=60.0).cone_deg_of(f) == 60.0
    assert_close(ContactModel(cone_deg=60.0).cos_cone_of(f), 0.5, atol=1e-15, what="cos 60")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("cone_deg", 0.0),
        ("cone_deg", 181.0),
        ("ik_tol_m", np.nan),
        ("limit_margin_rad", -0.01),
        ("torsion_m", -0.001),
        ("torsion_m", np.inf),
    ],
)
def test_contact_model_refuses_bad_values_by_name(field, value):
    with pytest.raises(InputError, match=f"ContactModel.{field}"):
        ContactModel(**{field: value})


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


def test_pad_cosines_come_with_the_tip_overshoot_unchanged():
    """pad_cosines_and_overshoot: the pad cosines bit for bit, and the fingertip link's
    overshoot of the tip frame's inward normal (TipReach)."""
    rng = np.random.default_rng(5)
    hand = Hand.allegro()
    f = hand.finger("index")
    q = rng.uniform(f.lower, f.upper, (40, f.k))
    n_palm = rng.normal(size=(40, 3))
    n_palm /= np.linalg.norm(n_palm, axis=1, keepdims=True)
    cos, over = pad_cosines_and_overshoot(f, q, n_palm)
    assert np.array_equal(cos, pad_cosines(f, q, n_palm))
    R, _ = f.tip_poses(q)
    u_tip = np.array([-R[i].T @ n_palm[i] for i in range(40)])
    assert_close(over, f.tip_reach.overshoot(u_tip), atol=1e-15, what="overshoot")
