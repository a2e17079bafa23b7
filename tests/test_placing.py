"""Placing an object in a hand: workspace centres, screened poses, and the scenario
built on them, checked against FK, Coal and the motion's definition."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_close

from regrasp_pin import make_scenario
from regrasp_pin.exceptions import InputError
from regrasp_pin.grasp.contact import ContactModel
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.model.clearance import FingerClearance, LinkClearance, palm_clearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.placing import candidate_placements, regrasp_room, workspace_centres
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


def test_scenario_for_hand_turns_about_the_thumbs_end_face(five, hexagon):
    """The grasp's contacts are where the fingertips are (FK); the object turns about
    its own axis direction, about a point of the thumb's end face that stays fixed in
    the palm frame, near the thumb's contact."""
    scen = scenario_for_hand(five, hexagon, fingers=FINGERS, angle_deg=90.0, rate_deg_s=30.0)
    g, motion = scen.grasp, scen.motion
    T0 = motion.pose(0.0)
    for name in FINGERS:
        f = five.finger(name)
        centre = T0[:3, :3] @ (g.points_object[name] + f.tip_radius * g.normals_object[name])
        assert_close(f.fk(g.q[name]), centre + T0[:3, 3], atol=2e-5, what=name)
    times = np.linspace(motion.t_start, motion.t_end, 7)[1:]
    T = motion.pose(times)
    # points x (object frame) with T(t) x = T(0) x for every t: the turn's axis
    A = np.concatenate([Ti[:3, :3] - T0[:3, :3] for Ti in T])
    b = np.concatenate([T0[:3, 3] - Ti[:3, 3] for Ti in T])
    x0 = np.linalg.lstsq(A, b, rcond=None)[0]
    assert_close(A @ x0, b, atol=1e-9, what="fixed point")
    axis = np.linalg.svd(A)[2][-1]  # the null direction of A
    assert abs(axis[2]) > 1 - 1e-9, "the turn is about the object's z axis"
    thumb = g.points_object["thumb"]
    on_face = x0 + (thumb[2] - x0[2]) * np.array([0.0, 0.0, 1.0])
    assert abs(abs(thumb[2]) - hexagon.params["height_m"] / 2) < 1e-9, "thumb on an end face"
    assert np.linalg.norm(on_face - thumb) < 0.005
    turned = T[-1][:3, :3] @ T0[:3, :3].T
    assert_close(np.degrees(np.arccos((np.trace(turned) - 1) / 2)), 90.0, atol=1e-6)


def test_scenario_for_hand_bad_inputs(five, hexagon):
    with pytest.raises(InputError, match="pivot"):
        scenario_for_hand(five, hexagon, fingers=("index", "middle"), pivot="ring")
    with pytest.raises(InputError, match="angle_deg"):
        scenario_for_hand(five, hexagon, angle_deg=0.0)
    with pytest.raises(InputError, match="pose"):
        scenario_for_hand(five, hexagon, pose=np.eye(3))


@pytest.fixture(scope="module")
def held():
    """The bundled hand's canonical grasp, its manifolds at three times of the turn."""
    scen = make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40)
    sample = scen.obj.sample_surface(0.002)
    times = np.array([0.0, 0.3, 0.6])
    manifolds = {
        n: build_manifold(scen.hand.finger(n), sample, scen.motion, times, contact=ContactModel())
        for n in scen.grasp.indices
    }
    return scen, sample, manifolds


def _room_direct(hand, manifolds, sample, indices, name, k, margin, clearance):
    """The contacts of ``name`` counted at time ``k``, one by one, and each one's Coal
    distance to the other grasping fingers at their contacts."""
    f = hand.finger(name)
    m = manifolds[name]
    q = hand.neutral()
    for n, i in indices.items():
        if n != name:
            q[hand.finger(n).q_indices] = manifolds[n].q[k, i]
    coal = FingerClearance(hand, name, others=[n for n in indices if n != name])
    own = sample.points[indices[name]]
    out = []
    for i in np.flatnonzero(m.usable(margin)[k]):
        if np.linalg.norm(sample.points[i] - own) < f.tip_radius:
            continue
        q[f.q_indices] = m.q[k, i]
        out.append(coal(q))
    return np.array(out)


def test_regrasp_room_counts_contacts_clear_of_the_other_fingers(held):
    """Each finger's room is the number of its usable contacts away from its own whose
    Coal distance to the other fingers is at least the clearance (counted one by one
    here), the smallest over the times, and shrinks as the clearance grows."""
    scen, sample, manifolds = held
    hand, idx = scen.hand, scen.grasp.indices
    margin, clearance = 0.08, 0.002
    names = list(idx)
    room = regrasp_room(
        hand, manifolds, sample, idx, names, [0, 2], margin_rad=margin, clearance_m=clearance
    )
    assert set(room) == set(names)
    for name in names:
        per_time = []
        for k in (0, 2):
            d = _room_direct(hand, manifolds, sample, idx, name, k, margin, clearance)
            one = regrasp_room(
                hand, manifolds, sample, idx, [name], [k], margin_rad=margin, clearance_m=clearance
            )[name]
            assert one == np.count_nonzero(d >= clearance), (name, k)
            per_time.append(one)
        assert room[name] == min(per_time)
    wider = regrasp_room(
        hand, manifolds, sample, idx, names, [0, 2], margin_rad=margin, clearance_m=0.01
    )
    assert all(wider[n] <= room[n] for n in names)
    far = regrasp_room(hand, manifolds, sample, idx, names, [0], margin_rad=margin, clearance_m=1.0)
    assert far == {n: 0 for n in names}
    assert regrasp_room(
        hand, manifolds, sample, idx, names, [], margin_rad=margin, clearance_m=clearance
    ) == {n: 0 for n in names}


def test_regrasp_room_with_the_object_counts_what_a_new_contact_must_pass(held):
    """With the object, a place also lies two tip radii + 1 mm from each other contact,
    and there the finger's other links keep the choice clearance from the object and
    its fingertip link does not sink in (counted one by one here): never more places
    than without the object."""
    scen, sample, manifolds = held
    hand, idx, obj = scen.hand, scen.grasp.indices, scen.obj
    contact = ContactModel()
    margin, clearance = contact.choice_margin_rad, 0.002
    kw = dict(margin_rad=margin, clearance_m=clearance)
    for name in idx:
        f, m = hand.finger(name), manifolds[name]
        links = LinkClearance(hand, name, obj)
        tip = LinkClearance(hand, name, obj, tip_only=True)
        for k in (0, 2):
            d = _room_direct(hand, manifolds, sample, idx, name, k, margin, clearance)
            usable = [
                i
                for i in np.flatnonzero(m.usable(margin)[k])
                if np.linalg.norm(sample.points[i] - sample.points[idx[name]]) >= f.tip_radius
            ]
            expected = 0
            for i, d_fingers in zip(usable, d, strict=True):
                q_full = hand.to_full(name, m.q[k, i][None])
                T = m.T_palm_object[k]
                expected += bool(
                    d_fingers >= clearance
                    and links(q_full, T)[0] >= contact.choice_link_clearance_m
                    and tip(q_full, T)[0] >= -contact.tip_penetration_m
                    and all(
                        np.linalg.norm(sample.points[i] - sample.points[j])
                        >= 2 * f.tip_radius + 0.001
                        for n, j in idx.items()
                        if n != name
                    )
                )
            room = regrasp_room(hand, manifolds, sample, idx, [name], [k], obj=obj, **kw)
            assert room[name] == expected, (name, k)
            assert room[name] <= regrasp_room(hand, manifolds, sample, idx, [name], [k], **kw)[name]
