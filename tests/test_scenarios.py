"""Ready-made scenarios (regrasp_pin.scenarios): the turn about the thumb's contact."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import SHADOW_HAND_FILE, assert_close, shadow_urdf

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


def _chosen_again(scen):
    """The grasp that the scenario's recorded grasp search chooses, its pivot kept."""
    search = scen.grasp_search
    keep = None if search.pivot is None else {search.pivot: scen.grasp.indices[search.pivot]}
    return search.choose(scen.hand, scen.obj, keep=keep)


def test_the_recorded_grasp_search_chooses_the_scenarios_grasp_again(scen):
    # a backup (regrasp_pin.backups) chooses another start the same way: the search
    # that chose the grasp, for the turn about the prism's own axis (the scenario's
    # turn was then placed about the thumb's contact), gives the same grasp when asked
    # again with nothing kept or avoided
    search = scen.grasp_search
    assert search.pivot == "thumb" and search.motion is not scen.motion
    assert search.choose(scen.hand, scen.obj).indices == scen.grasp.indices


def test_scenario_for_hand_records_the_search_about_the_pivots_contact():
    from regrasp_pin.scenarios import hand_model, scenario_for_hand, setup_pose

    hand = hand_model("five_finger")
    common = dict(fingers=setup_fingers("five_finger"), angle_deg=60.0, rate_deg_s=40.0)
    obj = setup_objects("five_finger")["hexagon"]()
    pivoted = scenario_for_hand(hand, obj, pose=setup_pose("five_finger"), **common)
    assert pivoted.grasp_search.pivot == "thumb"
    assert pivoted.grasp_search.motion is pivoted.motion  # the turn about the thumb
    assert _chosen_again(pivoted).indices == pivoted.grasp.indices
    centred = scenario_for_hand(hand, obj, pose=setup_pose("five_finger"), pivot=None, **common)
    assert centred.grasp_search.pivot is None and centred.grasp_search.motion is centred.motion
    assert _chosen_again(centred).indices == centred.grasp.indices


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


def test_a_hand_files_scenario_entry_names_its_time_law(tmp_path):
    """``scenario.time_law``: the law of a hand's ready-made scenarios (a bundled hand's
    and a file's without one: minimum jerk); another value is refused by its key."""
    from regrasp_pin.planning.regrasp import RegraspParams
    from regrasp_pin.scenarios import setup_time_law

    def hand_file(name, scenario):
        path = tmp_path / f"{name}.json"
        spec = {"urdf": str(five_finger_urdf_path()), "fingers": FIVE_FINGER_TIPS}
        path.write_text(json.dumps({**spec, "tip_radius": 0.008, "scenario": scenario}))
        return str(path)

    assert setup_time_law(hand_file("cruise", {"time_law": "cruise"})) == "cruise"
    default = RegraspParams().time_law
    assert setup_time_law(hand_file("plain", {})) == default == "minimum-jerk"
    assert setup_time_law("five_finger") == setup_time_law("allegro") == default
    for i, bad in enumerate(("fast", ["cruise"])):
        with pytest.raises(InputError, match="scenario.time_law.*not a time law.*minimum-jerk"):
            setup_time_law(hand_file(f"typo{i}", {"time_law": bad}))


@pytest.mark.parametrize(("hand", "angle"), [("five_finger", 60.0), ("allegro", -100.0)])
def test_the_grasp_search_maps_only_what_it_reads_and_picks_the_same_grasp(hand, angle):
    # StartTracking maps the entries initial_grasp reads exactly as the full manifolds
    # do: the grasp is the same, bit for bit, as with every entry mapped
    from regrasp_pin.grasp.contact import ContactModel
    from regrasp_pin.model.motion import ObjectMotion
    from regrasp_pin.scenarios import grasp_for_motion, hand_model, setup_pose

    h = hand_model(hand)
    obj = setup_objects(hand)["hexagon"]()
    T0 = setup_pose(hand)
    turn = ObjectMotion.constant_twist(
        T0,
        axis_palm=T0[:3, 2],
        point_palm=T0[:3, 3],
        rate_rad_s=np.sign(angle) * np.radians(40.0),
        duration_s=abs(angle) / 40.0,
        dt_s=0.01,
    )
    kw = dict(contact=ContactModel(), grasp_dt_s=0.1, seed=0)
    fingers = setup_fingers(hand)
    fast = grasp_for_motion(h, obj, turn, fingers, **kw)
    full = grasp_for_motion(h, obj, turn, fingers, track_start=False, **kw)
    assert fast.indices == full.indices
    assert fast.epsilon == full.epsilon
    for n in fingers:
        assert np.array_equal(fast.q[n], full.q[n])
        assert np.array_equal(fast.points_object[n], full.points_object[n])


def _five_finger_turn():
    from regrasp_pin.model.motion import ObjectMotion
    from regrasp_pin.scenarios import hand_model, setup_pose

    h = hand_model("five_finger")
    obj = setup_objects("five_finger")["hexagon"]()
    T0 = setup_pose("five_finger")
    turn = ObjectMotion.constant_twist(
        T0,
        axis_palm=T0[:3, 2],
        point_palm=T0[:3, 3],
        rate_rad_s=np.radians(40.0),
        duration_s=1.5,
        dt_s=0.01,
    )
    return h, obj, turn


def test_grasps_are_ranked_by_the_fingers_room_to_regrasp():
    # with room_fingers, the grasp kept is at least as good as the score's pick by
    # (holds that cannot be regrasped in turn, smallest regrasp room), both recounted
    # here on the same manifolds: exit times by a loop, the room by regrasp_room
    from regrasp_pin.grasp.contact import ContactModel
    from regrasp_pin.placing import regrasp_room
    from regrasp_pin.scenarios import grasp_for_motion

    h, obj, turn = _five_finger_turn()
    contact = ContactModel()
    fingers = setup_fingers("five_finger")
    movers = [n for n in fingers if n != "thumb"]
    kw = dict(contact=contact, grasp_dt_s=0.1, seed=0, track_start=False)
    plain = grasp_for_motion(h, obj, turn, fingers, **kw)
    roomy = grasp_for_motion(h, obj, turn, fingers, room_fingers=movers, room_after_s=0.25, **kw)
    sample = obj.sample_surface(0.002)
    times = np.linspace(turn.t_start, turn.t_end, int(turn.duration_s / 0.1) + 1)
    manifolds = {
        n: build_manifold(h.finger(n), sample, turn, times, contact=contact) for n in fingers
    }

    def rank(g):
        ends = []
        for n in movers:
            ok = manifolds[n].usable(contact.limit_margin_rad)[:, g.indices[n]]
            k = 0
            while k < times.size and ok[k]:
                k += 1
            if k < times.size:
                ends.append(times[k] - times[0])
        late = sum(t < 0.25 * j - 1e-9 for j, t in enumerate(sorted(ends), start=1))
        counts = regrasp_room(
            h,
            manifolds,
            sample,
            g.indices,
            movers,
            [0, 3],  # the start and the first time 0.25 s later
            margin_rad=contact.choice_margin_rad,
            clearance_m=contact.finger_trigger_m + 0.0005,
            obj=obj,
            contact=contact,
        )
        return -late, min(counts.values())

    assert rank(roomy) >= rank(plain)
    assert rank(roomy)[1] > 0
    with pytest.raises(UnknownNameError):
        grasp_for_motion(h, obj, turn, fingers, room_fingers=["pinky"], **kw)


def test_a_grasp_that_avoids_a_start_contact_keeps_the_finger_two_tip_radii_away():
    # the grasp chosen again after a failure (suite backups): the avoided finger's new
    # contact is more than two tip radii from the avoided point (which the first grasp
    # held), and the grasp is a force-closure grasp as any other
    from regrasp_pin.grasp.contact import ContactModel
    from regrasp_pin.grasp.quality import ferrari_canny_epsilon
    from regrasp_pin.scenarios import grasp_for_motion

    h, obj, turn = _five_finger_turn()
    fingers = setup_fingers("five_finger")
    kw = dict(contact=ContactModel(), grasp_dt_s=0.1, seed=0)
    first = grasp_for_motion(h, obj, turn, fingers, **kw)
    avoided = first.points_object["index"]
    again = grasp_for_motion(h, obj, turn, fingers, avoid={"index": avoided[None]}, **kw)
    assert (
        np.linalg.norm(again.points_object["index"] - avoided) > 2.0 * h.finger("index").tip_radius
    )
    pts = np.array([again.points_object[n] for n in fingers])
    nrm = np.array([again.normals_object[n] for n in fingers])
    assert ferrari_canny_epsilon(pts, nrm, 0.8, torque_scale_m=obj.radius_m) > 0.0


def test_bad_avoid_names_the_argument():
    from regrasp_pin.grasp.contact import ContactModel
    from regrasp_pin.scenarios import grasp_for_motion

    h, obj, turn = _five_finger_turn()
    fingers = setup_fingers("five_finger")
    kw = dict(contact=ContactModel(), grasp_dt_s=0.25, seed=0)
    with pytest.raises(UnknownNameError, match="avoid"):
        grasp_for_motion(h, obj, turn, fingers, avoid={"little": np.zeros((1, 3))}, **kw)
    with pytest.raises(InputError, match=r"avoid\['index'\].*shape \(\?, 3\)|avoid\['index'\]"):
        grasp_for_motion(h, obj, turn, fingers, avoid={"index": np.zeros(2)}, **kw)
    with pytest.raises(InputError, match=r"avoid\['index'\].*NaN"):
        grasp_for_motion(h, obj, turn, fingers, avoid={"index": np.full((1, 3), np.nan)}, **kw)


def test_bad_held_through_arguments_name_them():
    from regrasp_pin.grasp.contact import ContactModel
    from regrasp_pin.scenarios import contacts_held_through

    h, obj, turn = _five_finger_turn()
    with pytest.raises(UnknownNameError, match="pinky"):
        contacts_held_through(h, obj, turn, "pinky", contact=ContactModel())
    with pytest.raises(InputError, match="grasp_dt_s"):
        contacts_held_through(h, obj, turn, "thumb", contact=ContactModel(), grasp_dt_s=0.0)


def test_the_shadow_hands_grasp_leaves_every_walking_finger_room_to_regrasp():
    # the real Shadow Hand (third-party models, skipped when absent): with the score
    # alone, no usable contact of the little finger cleared the middle finger's body;
    # the room rank leaves each finger but the pivot somewhere to land, at the start
    # and one regrasp later (recounted on manifolds built here at those two times)
    from regrasp_pin.grasp.contact import ContactModel
    from regrasp_pin.placing import regrasp_room
    from regrasp_pin.scenarios import hand_model, scenario_for_hand, setup_pose

    shadow_urdf()
    hand_file = str(SHADOW_HAND_FILE)
    # at the hand file's canonical pose, as the suite builds its neighbourhood
    scen = scenario_for_hand(
        hand_model(hand_file),
        setup_objects(hand_file)["hexagon"](),
        fingers=setup_fingers(hand_file),
        angle_deg=60.0,
        rate_deg_s=10.0,
        pose=setup_pose(hand_file),
    )
    contact = ContactModel()
    sample = scen.obj.sample_surface(0.002)
    t0 = scen.motion.t_start
    times = np.array([t0, t0 + scen.params.regrasp.duration_s])
    manifolds = {
        n: build_manifold(scen.hand.finger(n), sample, scen.motion, times, contact=contact)
        for n in scen.grasp.indices
    }
    walkers = [n for n in scen.grasp.indices if n != "thumb"]
    room = regrasp_room(
        scen.hand,
        manifolds,
        sample,
        scen.grasp.indices,
        walkers,
        [0, 1],
        margin_rad=contact.choice_margin_rad,
        clearance_m=contact.finger_trigger_m + 0.0005,
        obj=scen.obj,
        contact=contact,
    )
    assert min(room.values()) > 0, room
