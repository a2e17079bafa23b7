"""TipReach: how far a fingertip link reaches past the plane its tip sphere rests on,
checked against Coal's distance to a half-space."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import SHADOW_HAND_FILE, assert_close, shadow_urdf

from regrasp_pin.model.hand import (
    FIVE_FINGER_TIPS,
    PAD_CONE_SPHERE_DEG,
    PAD_CONE_STAND_IN_DEG,
    Hand,
    five_finger_urdf_path,
)
from regrasp_pin.model.tip_reach import TipReach


@pytest.fixture(scope="module", params=["five_finger", "allegro"])
def hand(request):
    return Hand.five_finger() if request.param == "five_finger" else Hand.allegro()


def _reference_overshoot(hand, finger, q, u_palm) -> float:
    """Minus the smallest Coal distance between the fingertip link's geometries and the
    half-space behind the plane that touches the tip sphere (outward normal ``-u``), in
    the palm frame: the signed distance of a convex shape to a half-space is its
    separation, so minus it is how far the shape reaches past the plane."""
    f = hand.finger(finger)
    _, c = f.tip_poses(q[None])
    contact = c[0] + f.tip_radius * u_palm
    data, gdata = hand.model.createData(), pin.GeometryData(hand.collision_model)
    pin.updateGeometryPlacements(
        hand.model, data, hand.collision_model, gdata, hand.to_full(finger, q)
    )
    plane = coal.Halfspace(-u_palm, float(-u_palm @ contact))
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    reach = -np.inf
    for g in f.tip_geometry_ids:
        shape, M = hand.collision_model.geometryObjects[g].geometry, gdata.oMg[g]
        res.clear()
        pose = coal.Transform3s(M.rotation, M.translation)
        reach = max(reach, -coal.distance(shape, pose, plane, coal.Transform3s(), req, res))
    return reach


def test_overshoot_is_the_reach_past_the_tangent_plane(hand):
    rng = np.random.default_rng(3)
    for name in hand.finger_names:
        f = hand.finger(name)
        tr = f.tip_reach
        assert isinstance(tr, TipReach)
        assert not tr.skipped and len(tr.names) == len(f.tip_geometry_ids)
        q = rng.uniform(f.lower, f.upper, (12, f.k))
        u = rng.normal(size=(12, 3))
        u[:6] = np.einsum("nij,j->ni", f.tip_poses(q[:6])[0], f.pad_axis_tip)  # the pad
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        R, _ = f.tip_poses(q)
        got = tr.overshoot(np.einsum("nji,nj->ni", R, u))
        want = [_reference_overshoot(hand, name, q[i], u[i]) for i in range(12)]
        assert_close(got, np.array(want), atol=1e-9, what=f"{hand.name} {name}")


def test_the_pad_facing_the_surface_does_not_overshoot(hand):
    # the tip sphere rests on the plane and the link lies behind the pad: nothing sinks
    for name in hand.finger_names:
        f = hand.finger(name)
        assert f.tip_reach.overshoot(f.pad_axis_tip[None])[0] <= 1e-9


def test_the_bundled_fingertips_carry_the_tip_sphere_itself(hand):
    # each fingertip link has a collision sphere of the tip radius on the tip frame:
    # every direction of the contact sphere's front hemisphere is the finger's surface
    for name in hand.finger_names:
        f = hand.finger(name)
        assert f.tip_reach.has_tip_sphere(), name
        assert f.pad_cone_deg == PAD_CONE_SPHERE_DEG, name
        # the sphere's support is the tip radius in every direction
        u = np.random.default_rng(5).normal(size=(50, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        assert np.all(f.tip_reach.overshoot(u) >= -1e-12), name


@pytest.mark.parametrize(
    ("centre", "params", "expected"),
    [
        ((0.0, 0.0, 0.0), (0, 0, 0, 0, 0, 0.01), True),
        ((0.0, 0.0, 0.0), (0, 0, 0, 0, 0, 0.0105), False),  # another radius
        ((0.0, 0.0, 0.002), (0, 0, 0, 0, 0, 0.01), False),  # off the tip frame
        ((0.0, 0.0, 0.0), (0, 0, 0, 0.002, 0, 0.01), False),  # a capsule
        ((0.0, 0.0, 0.0), (0.01, 0.01, 0.01, 0, 0, 0), False),  # a box
    ],
)
def test_only_a_sphere_of_the_tip_radius_on_the_tip_frame_is_the_tip_sphere(
    centre, params, expected
):
    reach = TipReach(0.01, np.array([centre]), np.eye(3)[None], np.array([params], float))
    assert reach.has_tip_sphere() is expected


def test_a_tip_radius_other_than_the_sphere_makes_it_a_stand_in():
    hand = Hand.from_urdf(five_finger_urdf_path(), FIVE_FINGER_TIPS, tip_radius=0.009)
    for name in hand.finger_names:
        assert not hand.finger(name).tip_reach.has_tip_sphere()
        assert hand.finger(name).pad_cone_deg == PAD_CONE_STAND_IN_DEG


def test_no_geometry_no_bound():
    empty = TipReach(0.01, np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 6)))
    assert np.all(empty.overshoot(np.eye(3)) == -np.inf)


def test_a_mesh_fingertip_bounds_nothing_here():
    """The Shadow Hand's distal links are meshes: TipReach leaves them out (named in
    ``skipped``) and bounds nothing, so its contacts' exit times are the manifold's and
    the tracking's Coal check alone lets a contact go (skipped without the third-party
    hands folder)."""
    shadow_urdf()
    hand = Hand.from_file(SHADOW_HAND_FILE)
    for name in hand.finger_names:
        f = hand.finger(name)
        assert f.tip_reach.names == ()
        assert len(f.tip_reach.skipped) == len(f.tip_geometry_ids) > 0
        assert np.all(f.tip_reach.overshoot(np.eye(3)) == -np.inf)
        # the 7.5-9 mm sphere stands in for a mesh pad: trusted near the pad only
        assert not f.tip_reach.has_tip_sphere()
        assert f.pad_cone_deg == PAD_CONE_STAND_IN_DEG
