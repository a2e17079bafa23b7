"""Ready-made scenarios (regrasp_pin.scenarios): the turn about the thumb's contact."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import assert_close

from regrasp_pin import make_scenario
from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.grasp.choice import exit_times
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.model.hand import FIVE_FINGER_TIPS, five_finger_urdf_path
from regrasp_pin.scenarios import setup_fingers, setup_objects


@pytest.fixture(scope="module")
def scen():
    return make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40)


def test_the_thumb_pins_the_object(scen):
    # the turn's axis passes through the thumb's contact: it stays put in the palm frame
    T = scen.motion.T_palm_object
    p = scen.grasp.points_object["thumb"]
    pivot = T[:, :3, :3] @ p + T[:, :3, 3]
    assert_close(pivot, np.broadcast_to(pivot[0], pivot.shape), atol=1e-9, what="pivot")


def test_the_thumb_holds_through_the_whole_turn(scen):
    # pinned in space, the thumb's contact keeps one configuration: inside its limits
    # from start to end (by its manifold over the turn, built independently)
    contact = scen.params.contact
    sample = scen.obj.sample_surface(0.002)
    times = np.linspace(scen.motion.t_start, scen.motion.t_end, 7)
    m = build_manifold(scen.hand.finger("thumb"), sample, scen.motion, times, contact=contact)
    i = scen.grasp.indices["thumb"]
    usable = m.usable(contact.limit_margin_rad)
    assert usable[:, i].all()
    assert exit_times(usable[:, [i]], times, 0)[0] == pytest.approx(times[-1])
    q = m.q[:, i]
    assert_close(q, np.broadcast_to(q[0], q.shape), atol=1e-4, what="thumb q")


def test_a_hand_files_scenario_entry_picks_fingers_and_scales_objects(tmp_path):
    def hand_file(name, scenario):
        path = tmp_path / f"{name}.json"
        spec = {
            "urdf": str(five_finger_urdf_path()),
            "fingers": FIVE_FINGER_TIPS,
            "tip_radius": 0.008,
            "scenario": scenario,
        }
        path.write_text(json.dumps(spec))
        return str(path)

    f = hand_file("scaled", {"fingers": ["thumb", "index", "middle"], "object_scale": 1.5})
    assert setup_fingers(f) == ("thumb", "index", "middle")
    base, scaled = setup_objects("five_finger"), setup_objects(f)
    for name in ("hexagon", "octagon", "box"):
        assert_close(scaled[name]().vertices, 1.5 * base[name]().vertices, atol=1e-15, what=name)
    everything = hand_file("plain", {})
    assert setup_fingers(everything) == tuple(FIVE_FINGER_TIPS)
    with pytest.raises(UnknownNameError):
        setup_fingers(hand_file("typo", {"fingers": ["pinky"]}))
    with pytest.raises(InputError):
        setup_fingers(hand_file("extra", {"speed": 2}))
