"""TipReach: how far a fingertip link reaches past the plane its tip sphere rests on,
checked against Coal's distance to a half-space."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import SHADOW_HAND_FILE, assert_close, shadow_urdf

from regrasp_pin.model.hand import Hand
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
