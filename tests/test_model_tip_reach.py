"""TipReach: how far a fingertip link reaches past the plane its tip sphere rests on,
checked against Coal's distance to a half-space."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close

from regrasp_pin.model.hand import Hand
from regrasp_pin.model.tip_reach import TipReach


@pytest.fixture(scope="module", params=["five_finger", "allegro"])
def hand(request):
    return Hand.five_finger() if request.param == "five_finger" else Hand.allegro()


def _coal_overshoot(hand, finger, q, u_palm) -> float:
    """Minus the smallest Pinocchio computeDistances distance between the fingertip
    link's geometries and the half-space behind the plane that touches the tip sphere
    (outward normal ``-u``): the signed distance of a convex shape to a half-space is
    its separation, so minus it is how far the shape reaches past the plane."""
    f = hand.finger(finger)
    R, c = f.tip_poses(q[None])
    contact = c[0] + f.tip_radius * u_palm
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    plane = coal.Halfspace(-u_palm, float(-u_palm @ contact))
    oid = gm.addGeometryObject(pin.GeometryObject("plane", 0, pin.SE3.Identity(), plane))
    for g in f.tip_geometry_ids:
        gm.addCollisionPair(pin.CollisionPair(int(g), oid))
    gdata = pin.GeometryData(gm)
    pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, hand.to_full(finger, q))
    return -min(r.min_distance for r in gdata.distanceResults)


def test_overshoot_is_coal_distance_to_the_tangent_half_space(hand):
    rng = np.random.default_rng(3)
    for name in hand.finger_names:
        f = hand.finger(name)
        tr = f.tip_reach
        assert isinstance(tr, TipReach)
        assert not tr.skipped and len(tr.names) == len(f.tip_geometry_ids)
        q = rng.uniform(f.lower, f.upper, (12, f.k))
        u = rng.normal(size=(12, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        R, _ = f.tip_poses(q)
        got = tr.overshoot(np.einsum("nji,nj->ni", R, u))
        want = [_coal_overshoot(hand, name, q[i], u[i]) for i in range(12)]
        assert_close(got, np.array(want), atol=1e-9, what=f"{hand.name} {name}")


def test_the_pad_facing_the_surface_does_not_overshoot(hand):
    # the tip sphere rests on the plane and the link lies behind the pad: nothing sinks
    for name in hand.finger_names:
        f = hand.finger(name)
        assert f.tip_reach.overshoot(f.pad_axis_tip[None])[0] <= 1e-9


def test_no_geometry_no_bound():
    empty = TipReach(0.01, np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 6)))
    assert np.all(empty.overshoot(np.eye(3)) == -np.inf)
