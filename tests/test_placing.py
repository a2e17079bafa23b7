"""Placing an object in a hand: workspace centres, screened poses, and the scenario
built on them, checked against FK, Coal and the motion's definition."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close

from regrasp_pin.exceptions import InputError
from regrasp_pin.model.clearance import palm_clearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.placing import candidate_placements, workspace_centres
from regrasp_pin.scenarios import scenario_for_hand, setup_objects

FINGERS = ("thumb", "index", "middle", "ring")


@pytest.fixture(scope="module")
def five():
    return Hand.five_finger()


@pytest.fixture(scope="module")
def hexagon():
    return setup_objects("five_finger")["hexagon"]()


def test_workspace_centres_are_reached_by_every_finger(five, hexagon):
    """At each centre, every finger has sampled tips in the contact shell."""
    centres = workspace_centres(five, hexagon, FINGERS, count=2)
    assert centres.shape == (2, 3)
    assert np.linalg.norm(centres[0] - centres[1]) >= 0.02 - 1e-9
    r_in = -hexagon.signed_distance(np.zeros((1, 3)))[0]
    r_out = np.linalg.norm(hexagon.vertices, axis=1).max()
    rng = np.random.default_rng(7)
    for name in FINGERS:
        f = five.finger(name)
        tips = f.fk(rng.uniform(f.lower, f.upper, (4000, f.k)))
        d = np.linalg.norm(tips[:, None, :] - centres[None], axis=2)
        shell = (d >= r_in + f.tip_radius) & (d <= r_out + f.tip_radius)
        assert shell.any(axis=0).all(), name


def test_placements_are_ranked_clear_of_the_palm_and_reachable(five, hexagon):
    found = candidate_placements(five, hexagon, FINGERS, centres=1, pivot="thumb")
    assert found
    scores = [p.score for p in found]
    assert scores == sorted(scores, reverse=True) and scores[-1] > 0
    for p in found:
        assert palm_clearance(five, hexagon, p.T_palm_object[None])[0] >= 0.003
        assert set(p.usable) == set(FINGERS)
        R = p.T_palm_object[:3, :3]
        assert_close(R.T @ R, np.eye(3), atol=1e-12, what="rotation")
    with pytest.raises(InputError, match="pivot"):
        candidate_placements(five, hexagon, FINGERS, pivot="little")


def test_scenario_for_hand_pins_the_pivot_contact(five, hexagon):
    """The grasp's contacts are where the fingertips are (FK), the thumb's contact is on
    an end face, and the motion leaves it fixed in the palm frame."""
    scen = scenario_for_hand(five, hexagon, fingers=FINGERS, angle_deg=90.0, rate_deg_s=30.0)
    g = scen.grasp
    for name in FINGERS:
        f = five.finger(name)
        T0 = scen.motion.pose(0.0)
        centre = T0[:3, :3] @ (g.points_object[name] + f.tip_radius * g.normals_object[name])
        assert_close(f.fk(g.q[name]), centre + T0[:3, 3], atol=2e-5, what=name)
    assert abs(g.normals_object["thumb"][2]) > np.cos(np.radians(10.0))
    times = np.linspace(scen.motion.t_start, scen.motion.t_end, 7)
    pivot = scen.motion.transform_points(times, np.repeat(g.points_object["thumb"][None], 7, 0))
    assert_close(pivot, np.repeat(pivot[:1], 7, 0), atol=1e-9, what="pivot")
    turned = scen.motion.pose(scen.motion.t_end)[:3, :3] @ scen.motion.pose(0.0)[:3, :3].T
    assert_close(np.degrees(np.arccos((np.trace(turned) - 1) / 2)), 90.0, atol=1e-6)


def test_scenario_for_hand_bad_inputs(five, hexagon):
    with pytest.raises(InputError, match="pivot"):
        scenario_for_hand(five, hexagon, fingers=("index", "middle"), pivot="ring")
    with pytest.raises(InputError, match="angle_deg"):
        scenario_for_hand(five, hexagon, angle_deg=0.0)
    with pytest.raises(InputError, match="pose"):
        scenario_for_hand(five, hexagon, pose=np.eye(3))
