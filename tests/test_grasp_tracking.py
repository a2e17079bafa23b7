"""Tests of contact tracking and the regrasp trigger (regrasp_pin.grasp.tracking).

Scene (palm frame: x toward the fingers, z out of the palm): the five-finger hand and a
box 40 x 60 x 40 mm at (65, 0, 60) mm turning about the palm y axis through its centre
at 30 deg/s for 3 s. Each finger holds the contact of its manifold at t = 0 that stays
usable longest (then the largest margin), with its links clear of the box.

The trigger is checked against a direct per-step loop written here: one ``Finger.ik``
call per time (warm-started from the previous time), the joint margin written out,
the pad cosine from the tip rotation and the link-object distance from Pinocchio's
``computeDistances`` with the box added to a copy of the hand's GeometryModel.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close

from regrasp_pin.exceptions import InputError, UnknownNameError
from regrasp_pin.grasp.choice import exit_times
from regrasp_pin.grasp.contact import ContactModel
from regrasp_pin.grasp.holding import Holding
from regrasp_pin.grasp.manifold import build_manifold
from regrasp_pin.grasp.tracking import track_contact
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box
from regrasp_pin.planning.schedule import held_until
from regrasp_pin.planning.state import loss_reason

#: A 60 deg pad cone (the bundled fingers' own is 90 deg, the front hemisphere): with it
#: every finger's best contact of the scene is let go within the turn, each for its own
#: reason, which the trigger tests need.
CONTACT = ContactModel(cone_deg=60.0)
TIMES = np.linspace(0.0, 3.0, 61)


@pytest.fixture(scope="module")
def scene():
    hand = Hand.five_finger()
    box = Box((0.04, 0.06, 0.04))
    T0 = np.eye(4)
    T0[:3, 3] = [0.065, 0.0, 0.06]
    motion = ObjectMotion.constant_twist(
        T0,
        axis_palm=[0.0, 1.0, 0.0],
        point_palm=T0[:3, 3],
        rate_rad_s=np.radians(30.0),
        duration_s=3.0,
        dt_s=0.05,
    )
    sample = box.sample_surface(0.004)
    contacts = {}
    for name in hand.finger_names:
        m = build_manifold(
            hand.finger(name), sample, motion, np.linspace(0.0, 3.0, 13), contact=CONTACT
        )
        idx = np.flatnonzero(m.usable(CONTACT.choice_margin_rad)[0])
        last = exit_times(m.usable(CONTACT.limit_margin_rad)[:, idx], m.times_s, 0)
        lc = LinkClearance(hand, name, box)
        tip = LinkClearance(hand, name, box, tip_only=True)
        for j in np.lexsort((-m.margin_rad[0, idx], -last)):
            i = idx[j]
            q_full = hand.to_full(name, m.q[0, i])[None]
            T = m.T_palm_object[0]
            if (
                lc(q_full, T)[0] >= CONTACT.choice_link_clearance_m
                and tip(q_full, T)[0] >= -CONTACT.tip_penetration_m
            ):
                contacts[name] = (sample.points[i], sample.normals[i], m.q[0, i])
                break
    return hand, box, motion, contacts


def _link_distance(hand, finger, box, q_full, T_palm_object, tip=False) -> float:
    """Pinocchio computeDistances between the finger's non-tip geometries (``tip``: its
    fingertip link's geometries) and the box."""
    f = hand.finger(finger)
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    placement = pin.SE3(T_palm_object[:3, :3], T_palm_object[:3, 3])
    oid = gm.addGeometryObject(pin.GeometryObject("box", 0, placement, box.coal_geometry()))
    for g in f.geometry_ids:
        if (g in f.tip_geometry_ids) == tip:
            gm.addCollisionPair(pin.CollisionPair(int(g), oid))
    data = hand.model.createData()
    gdata = pin.GeometryData(gm)
    pin.computeDistances(hand.model, data, gm, gdata, q_full)
    return min(r.min_distance for r in gdata.distanceResults)


def _direct(hand, finger, box, motion, times, p, n, q_start, contact=CONTACT, links=True):
    """Per-step holdability, written out; returns (holdable, kind, q) per time."""
    f = hand.finger(finger)
    q_prev = q_start
    out = []
    for t in times:
        T = motion.pose(t)
        target = T[:3, :3] @ (p + f.tip_radius * n) + T[:3, 3]
        res = f.ik(target, q_prev, tol_m=contact.ik_tol_m)
        q = res.q[0]
        q_prev = q
        margin = min(np.min(q - f.lower), np.min(f.upper - q))
        R, _ = f.tip_poses(q)
        cos = float((R @ f.pad_axis_tip) @ -(T[:3, :3] @ n))
        if res.error_m[0] > contact.ik_tol_m:
            kind = "IK"
        elif margin < contact.limit_margin_rad:
            kind = "joint"
        elif cos < contact.cos_cone_of(f):
            kind = "pad"
        elif links and _link_distance(hand, finger, box, hand.to_full(finger, q), T) < (
            contact.link_clearance_m
        ):
            kind = "link"
        elif links and _link_distance(hand, finger, box, hand.to_full(finger, q), T, tip=True) < (
            -contact.tip_penetration_m
        ):
            kind = "tip"
        else:
            kind = ""
        out.append((kind, q))
    return out


_REASON_WORDS = {
    "IK": "IK cannot reach",
    "joint": "rad of its",
    "pad": "pad turned",
    "link": "link of the finger comes within",
    "tip": "fingertip link sinks into",
}


def test_by_default_a_finger_holds_within_its_own_pad_cone(scene):
    # the index's contact is let go when its pad turns 60 deg from the normal; the
    # finger's own cone (the tip sphere's front hemisphere) holds it longer
    hand, box, motion, contacts = scene
    p, n, q0 = contacts["index"]
    narrow = track_contact(hand, "index", box, motion, TIMES, p, n, q0, contact=CONTACT)
    own = track_contact(hand, "index", box, motion, TIMES, p, n, q0)
    assert own.cos_cone == pytest.approx(0.0, abs=1e-15)
    assert "pad turned" in narrow.trigger()[1]
    k = narrow.n_followed
    assert k < TIMES.size and own.followed_until_s > narrow.followed_until_s
    assert_close(own.q[:k], narrow.q[:k], atol=0.0, what="the same IK until the 60 deg cone")


@pytest.mark.parametrize("finger", ["thumb", "index", "middle", "ring", "little"])
def test_trigger_agrees_with_a_direct_per_step_check(scene, finger):
    hand, box, motion, contacts = scene
    p, n, q0 = contacts[finger]
    track = track_contact(hand, finger, box, motion, TIMES, p, n, q0, contact=CONTACT)
    direct = _direct(hand, finger, box, motion, TIMES, p, n, q0)
    kinds = [k for k, _ in direct]
    first = next((i for i, k in enumerate(kinds) if k), None)
    assert track.trigger_index() == first, (finger, track.reasons[first or 0])
    assert first is not None and first > 0, "the contact holds at first and is let go later"
    t_trig, reason = track.trigger()
    assert t_trig == pytest.approx(TIMES[first])
    assert _REASON_WORDS[kinds[first]] in reason, reason
    # the same configurations up to the trigger: both reach the target within 10 um,
    # so they agree to about tol / smallest singular value of J (same IK branch)
    q_direct = np.array([q for _, q in direct[: first + 1]])
    assert_close(track.q[: first + 1], q_direct, atol=2e-3, what=f"{finger} q")


@pytest.mark.parametrize("finger", ["index", "thumb"])
def test_track_records_what_it_checks(scene, finger):
    hand, box, motion, contacts = scene
    f = hand.finger(finger)
    p, n, q0 = contacts[finger]
    track = track_contact(hand, finger, box, motion, TIMES, p, n, q0, contact=CONTACT)
    assert track.finger == finger
    assert_close(track.p_object, p, atol=0.0, what="P")
    # q always within the limits; holdable times reach the target
    assert np.all(f.within_limits(track.q))
    T = motion.pose(TIMES)
    targets = T[:, :3, :3] @ (p + f.tip_radius * n) + T[:, :3, 3]
    err = np.linalg.norm(f.fk(track.q) - targets, axis=1)
    # followed until the contact is lost, then the documented fill
    k = track.n_followed
    assert track.followed_until_s == TIMES[k - 1]
    if k < TIMES.size:
        last = k - 1
        assert (
            err[last] > CONTACT.ik_tol_m
            or track.speed_share[last] > 1.0
            or track.margin_rad[last] < 0.0
            or track.pad_cos[last] < CONTACT.cos_cone_of(f)
        ), "a track stops only where the contact is lost"
        assert np.all(track.q[k:] == track.q[last]) and np.all(track.error_m[k:] == np.inf)
        assert np.all(track.margin_rad[k:] == -np.inf) and np.all(track.pad_cos[k:] == -np.inf)
        assert not track.holdable[k:].any()
    assert_close(track.error_m[:k], err[:k], atol=1e-12, what="residuals")
    # the speed shares are the configurations' steps over the times' steps
    steps = np.abs(np.diff(track.q[:k], axis=0)) / f.velocity_limit / np.diff(TIMES[:k])[:, None]
    assert track.speed_share[0] == 0.0
    assert_close(track.speed_share[1:k], steps.max(axis=1), atol=1e-12, what="speed shares")
    hold = track.holdable
    assert np.all(track.speed_share[hold] <= 1.0)
    assert np.all(err[hold] <= CONTACT.ik_tol_m)
    assert_close(track.margin_rad[:k], f.limit_margin(track.q[:k]), atol=1e-15, what="margins")
    assert np.all(track.margin_rad[hold] >= CONTACT.limit_margin_rad)
    assert track.cos_cone == CONTACT.cos_cone_of(f)
    assert np.all(track.pad_cos[hold] >= CONTACT.cos_cone_of(f))
    assert np.all(track.link_clearance_m[hold] >= CONTACT.link_clearance_m)
    assert np.all(track.tip_clearance_m[hold] >= -CONTACT.tip_penetration_m)
    # the clearances: Coal's (Pinocchio's computeDistances here) wherever they are below
    # what is compared with them, else at least that and never above Coal's
    for tip, recorded, limit in (
        (False, track.link_clearance_m, max(CONTACT.link_clearance_m, 0.0)),
        (True, track.tip_clearance_m, -CONTACT.tip_penetration_m),
    ):
        coal = np.array(
            [
                _link_distance(hand, finger, box, hand.to_full(finger, q), Ti, tip)
                for q, Ti in zip(track.q[:k], T[:k], strict=True)
            ]
        )
        low = coal < limit + 1e-6
        assert_close(recorded[:k][low], coal[low], atol=1e-9, what=f"exact (tip={tip})")
        assert np.all(recorded[:k][~low] >= limit) and np.all(recorded[:k] <= coal + 1e-6)
    # the numbers in the reasons are the recorded values
    for i in np.flatnonzero(~hold):
        r = track.reasons[i]
        if r.startswith("pad turned"):
            deg = np.degrees(np.arccos(track.pad_cos[i]))
            assert f"{deg:.0f} deg" in r
        elif "rad of its" in r:
            assert f"{track.margin_rad[i]:.3f} rad" in r


def test_a_larger_margin_triggers_earlier_at_a_boundary_plane(scene):
    hand, box, motion, contacts = scene
    p, n, q0 = contacts["index"]
    f = hand.finger("index")
    base = track_contact(
        hand, "index", box, motion, TIMES, p, n, q0, check_links=False, contact=CONTACT
    )
    wide = dataclasses.replace(CONTACT, limit_margin_rad=0.25)
    track = track_contact(
        hand, "index", box, motion, TIMES, p, n, q0, contact=wide, check_links=False
    )
    i = track.trigger_index()
    assert i is not None and i <= base.trigger_index()
    direct = _direct(hand, "index", box, motion, TIMES, p, n, q0, contact=wide, links=False)
    assert i == next(j for j, (k, _) in enumerate(direct) if k)
    if "rad of its" in track.reasons[i]:  # a boundary plane: name the joint and side
        q = track.q[i]
        j = int(np.argmin(np.minimum(q - f.lower, f.upper - q)))
        side = "lower" if q[j] - f.lower[j] < f.upper[j] - q[j] else "upper"
        assert f"joint {f.joint_names[j]} within" in track.reasons[i]
        assert f"{side} limit" in track.reasons[i]
    assert np.all(np.isinf(track.link_clearance_m))


def test_a_still_object_never_triggers(scene):
    hand, box, motion, contacts = scene
    p, n, q0 = contacts["middle"]
    T = motion.pose(0.0)
    still = ObjectMotion.from_poses([0.0, 3.0], [T, T])
    track = track_contact(hand, "middle", box, still, TIMES, p, n, q0, contact=CONTACT)
    assert track.trigger() == (None, "")
    assert track.holdable.all()
    assert_close(
        track.q, np.broadcast_to(track.q[0], track.q.shape), atol=1e-5, what="the finger stays put"
    )


def test_an_unreachable_contact_triggers_at_once(scene):
    hand, box, motion, contacts = scene
    p, n, q0 = contacts["index"]
    far = p + np.array([0.0, 0.0, 1.0])  # one metre away
    track = track_contact(hand, "index", box, motion, TIMES[:5], far, n, q0, contact=CONTACT)
    assert track.trigger_index() == 0
    assert "IK cannot reach" in track.reasons[0]


def test_bad_input_is_rejected(scene):
    hand, box, motion, contacts = scene
    p, n, q0 = contacts["index"]
    with pytest.raises(InputError, match="NaN"):
        track_contact(hand, "index", box, motion, np.array([0.0, np.nan]), p, n, q0)
    with pytest.raises(InputError, match="increasing"):
        track_contact(hand, "index", box, motion, np.array([0.0, 1.0, 0.5]), p, n, q0)
    with pytest.raises(InputError, match="p_object"):
        track_contact(hand, "index", box, motion, TIMES, [np.nan, 0, 0], n, q0)
    with pytest.raises(InputError, match="q_start"):
        track_contact(hand, "index", box, motion, TIMES, p, n, q0[:2])
    with pytest.raises(InputError, match="outside the motion"):
        track_contact(hand, "index", box, motion, np.array([0.0, 9.0]), p, n, q0)
    with pytest.raises(UnknownNameError, match="valid names"):
        track_contact(hand, "pinky", box, motion, TIMES, p, n, q0)


def test_a_redundant_fingers_spare_joint_keeps_its_fingertip_link_off_the_face(monkeypatch):
    """Suite spec 25 (Allegro, a box turned and moved): the thumb's start contact leaves
    its distal box flush with the face, and plain warm-started IK lets the box sink in
    before the turn ends; turned by its spare joint (grasp.settle) the thumb holds to the end,
    its fingertip link off the face as Coal measures it. While any finger holds, no
    joint moves faster than its limit (the turn stays within a time step's reach of the
    time before)."""
    import regrasp_pin.grasp.tracking as tracking_module
    from regrasp_pin.suite import build_scenario, generate_specs

    scen = build_scenario(generate_specs(26, seed=0)[25])
    g = scen.grasp
    times = np.arange(0.0, scen.motion.t_end, 0.01)

    def track(name="thumb"):
        return track_contact(
            scen.hand,
            name,
            scen.obj,
            scen.motion,
            times,
            g.points_object[name],
            g.normals_object[name],
            g.q[name],
        )

    settled = track()
    assert settled.trigger()[0] is None and settled.holdable.all()
    assert settled.tip_clearance_m.min() >= -ContactModel().tip_penetration_m
    for name in g.q:
        held = track(name)
        i = held.trigger_index()
        n = len(times) if i is None else i  # the times held
        speed = np.abs(np.diff(held.q[:n], axis=0)) / np.diff(times[:n])[:, None]
        assert np.all(speed <= scen.hand.finger(name).velocity_limit), name
    monkeypatch.setattr(
        tracking_module, "settle_tip_link", lambda finger, q, *args, **kwargs: q.copy()
    )
    plain = track()
    # the first time is the landing's (or the grasp's) own configuration: never turned
    np.testing.assert_array_equal(settled.q[0], plain.q[0])
    assert np.any(settled.q[1:] != plain.q[1:])
    t_lost = plain.trigger()[0]
    assert t_lost is not None and t_lost < times[-1]
    i = plain.trigger_index()
    assert plain.tip_clearance_m[i] < -ContactModel().tip_penetration_m


def test_settling_only_the_rows_that_sink_gives_the_same_track(monkeypatch):
    """A chunk's rows before its first turn that do not sink are not handed to the
    settle (it would leave them as they are): the track is the same, bit for bit, as
    when every row of a sinking chunk goes through it."""
    import regrasp_pin.grasp.tracking as tracking_module
    from regrasp_pin.suite import build_scenario, generate_specs

    scen = build_scenario(generate_specs(26, seed=0)[25])
    g = scen.grasp
    times = np.arange(0.0, scen.motion.t_end, 0.01)

    def track():
        p, n, q0 = g.points_object["thumb"], g.normals_object["thumb"], g.q["thumb"]
        return track_contact(scen.hand, "thumb", scen.obj, scen.motion, times, p, n, q0)

    calls = []
    settle = tracking_module.settle_tip_link
    monkeypatch.setattr(
        tracking_module, "settle_tip_link", lambda *a, **k: calls.append(1) or settle(*a, **k)
    )
    skipped = track()
    n_skipped = len(calls)
    sinking = tracking_module.sinking
    # every row of a chunk with a sinking row counts as sinking: all go through the settle
    monkeypatch.setattr(
        tracking_module,
        "sinking",
        lambda f, q, n: np.full(len(q), sinking(f, q, n).any()),
    )
    calls.clear()
    every = track()
    assert 0 < n_skipped < len(calls)
    np.testing.assert_array_equal(skipped.q, every.q)
    np.testing.assert_array_equal(skipped.error_m, every.error_m)
    assert skipped.reasons == every.reasons


def test_a_contact_the_joints_cannot_follow_in_time_is_let_go(scene):
    """The same object poses, those after time index m reached c times sooner: the same
    IK solutions, their steps c times faster. The contact is lost at the first time a
    joint would have to move faster than its velocity limit (read here from the slow
    track's configurations), with that reason; until then the configurations are the
    slow track's (to the IK's response to the poses' last bits)."""
    hand, box, motion, contacts = scene
    f = hand.finger("index")
    p, n, q0 = contacts["index"]
    slow = track_contact(hand, "index", box, motion, TIMES, p, n, q0, contact=CONTACT)
    k = slow.trigger_index()
    assert k is not None and k > 6
    # the fastest joint's share of its limit moving into times 1 .. k - 1
    share = np.max(np.abs(np.diff(slow.q[:k], axis=0)) / f.velocity_limit, axis=1)
    share /= np.diff(TIMES[:k])
    m = k // 2
    c = 1.01 / share[m - 1 :].max()  # a step from m on goes over the limit
    assert share.max() < 1.0 and c > 1.0
    steps = np.diff(TIMES)
    steps[m - 1 :] /= c
    times = np.concatenate([[0.0], np.cumsum(steps)])
    first = m + int(np.flatnonzero(c * share[m - 1 :] > 1.0)[0])
    fast_motion = ObjectMotion.from_poses(times, motion.pose(TIMES))
    fast = track_contact(hand, "index", box, fast_motion, times, p, n, q0, contact=CONTACT)
    assert fast.trigger_index() == first
    assert "cannot follow" in fast.reasons[first], fast.reasons[first]
    assert f"{c * share[first - 1]:.2f}x its velocity limit" in fast.reasons[first]
    assert_close(fast.q[:first], slow.q[:first], atol=1e-9, what="q before the loss")
    assert fast.n_followed == first + 1  # lost there: not followed further
    assert np.flatnonzero(fast.cannot_follow).tolist() == [first]
    assert not slow.cannot_follow.any()
    # the planner's lift-off window and loss reason read the same loss: the hold ends
    # at the time before (as for every other kind of loss), for this reason
    assert held_until(fast, CONTACT) == times[first - 1]
    h = Holding(p=p, n=n, t_from=0.0, track=fast)
    assert loss_reason(h, times[first - 1]) == fast.reasons[first]


def test_a_hold_is_not_lost_to_a_jump_between_the_ik_branches_of_a_batch(monkeypatch):
    """Suite spec s1-093 (Allegro, a triangular prism turned about its axis): the
    index's start contact. Its four joints have a curve of solutions per target; the
    batch warm-starts a chunk's times from one configuration, and from t = 0.05 s on
    it lands elsewhere on that curve: joint_3.0 jumps by 0.09 rad in 0.01 s, over its
    7 rad/s, and the hold was "lost" there. Solved again from the time before
    (model.follow_on), the track stays on its branch: held on, every step within the
    velocity limits, every time reached."""
    import regrasp_pin.grasp.tracking as tracking_module
    from regrasp_pin.suite import build_scenario, generate_specs

    scen = build_scenario(generate_specs(94, seed=1)[93])
    g, f = scen.grasp, scen.hand.finger("index")
    times = np.arange(0.0, 0.3, 0.01)

    def track():
        p, n, q0 = g.points_object["index"], g.normals_object["index"], g.q["index"]
        return track_contact(scen.hand, "index", scen.obj, scen.motion, times, p, n, q0)

    held = track()
    assert held.holdable.all() and held.error_m.max() <= ContactModel().ik_tol_m
    speed = np.abs(np.diff(held.q, axis=0)) / np.diff(times)[:, None]
    assert np.all(speed <= f.velocity_limit)
    # the batch as it was: the jump, taken for the hold's loss
    monkeypatch.setattr(tracking_module, "follow_on", lambda *args: 0)
    batch = track()
    i = batch.trigger_index()
    assert i is not None and batch.cannot_follow[i] and "joint_3.0" in batch.reasons[i]
