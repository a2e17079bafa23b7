"""Exact clearances (regrasp_pin.model.clearance).

Scene (palm frame): the five-finger hand and a box 40 x 60 x 40 mm. ``LinkClearance``
and ``FingerClearance``, which are built on Pinocchio's distance pipeline
(``pin.computeDistances`` over explicit collision pairs), are checked against
``coal.distance`` called pair by pair on the placements Pinocchio gives (the object's
pose as given), to the bit; ``LinkClearance`` also against a fresh pipeline with the
object placed in the model.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

from regrasp_pin.model import clearance
from regrasp_pin.model.clearance import FingerClearance, LinkClearance
from regrasp_pin.model.hand import Hand
from regrasp_pin.model.objects import Box


@pytest.fixture(scope="module")
def hand() -> Hand:
    return Hand.five_finger()


@pytest.fixture(scope="module")
def box() -> Box:
    return Box((0.04, 0.06, 0.04))


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


def _coal_object(hand: Hand, geometry_ids, q_full, T_palm_object, obj) -> float:
    """Smallest ``coal.distance`` between ``geometry_ids`` and the object, pair by pair."""
    data = hand.model.createData()
    gdata = pin.GeometryData(hand.collision_model)
    pin.updateGeometryPlacements(hand.model, data, hand.collision_model, gdata, q_full)
    objs = hand.collision_model.geometryObjects
    tf = coal.Transform3s(T_palm_object[:3, :3], T_palm_object[:3, 3])
    best = np.inf
    for a in geometry_ids:
        res = coal.DistanceResult()
        d = coal.distance(
            objs[a].geometry, gdata.oMg[a], obj.coal_geometry(), tf, coal.DistanceRequest(), res
        )
        best = min(best, d)
    return best


def _coal_pairs(hand: Hand, geometry_ids, others, q_full) -> float:
    """Smallest ``coal.distance`` between ``geometry_ids`` and ``others``, pair by pair."""
    data = hand.model.createData()
    gdata = pin.GeometryData(hand.collision_model)
    pin.updateGeometryPlacements(hand.model, data, hand.collision_model, gdata, q_full)
    objs = hand.collision_model.geometryObjects
    best = np.inf
    for a in geometry_ids:
        for b in others:
            res = coal.DistanceResult()
            d = coal.distance(
                objs[a].geometry, gdata.oMg[a], objs[b].geometry, gdata.oMg[b],
                coal.DistanceRequest(), res,
            )  # fmt: skip
            best = min(best, d)
    return best


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
        assert got[i] == _coal_object(hand, lc.geometry_ids, q_full[i], T[i], box)
        assert got_tip[i] == _coal_object(hand, f.geometry_ids, q_full[i], T[i], box)
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


def _near_poses(hand, finger, n, seed):
    """``n`` random configurations of ``finger`` and object poses about its middle."""
    rng = np.random.default_rng(seed)
    f = hand.finger(finger)
    q_full = hand.to_full(finger, rng.uniform(f.lower, f.upper, (n, f.k)))
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=seed + 1).as_matrix()
    T[:, :3, 3] = 0.5 * f.fk(hand.from_full(finger, q_full)) + rng.uniform(-0.02, 0.02, (n, 3))
    return q_full, T


def _same_as_coal(hand, finger, obj, q_full, T, **kwargs):
    lc = LinkClearance(hand, finger, obj, **kwargs)
    got = lc(q_full, T)
    ref = [_coal_object(hand, lc.geometry_ids, q, Ti, obj) for q, Ti in zip(q_full, T, strict=True)]
    assert got.tobytes() == np.array(ref).tobytes(), kwargs
    return got


@pytest.mark.parametrize("which", ["five_finger", "allegro"])
def test_link_clearance_is_coals_distance_pair_by_pair_for_any_object_and_thread(which, box):
    """Many configurations, penetrating or not, against two objects in turn (the pairs
    are kept per object) and from other threads at once: each distance is the smallest
    of one ``coal.distance`` call per geometry, to the bit."""
    import threading

    from regrasp_pin.model.objects import Prism

    hand = getattr(Hand, which)()
    q_full, T = _near_poses(hand, "middle", 40, 8)
    for obj in (box, Prism(6, 0.03, 0.04), box):
        for kwargs in ({}, {"include_tip": True}, {"tip_only": True}):
            got = _same_as_coal(hand, "middle", obj, q_full, T, **kwargs)
            assert (got < 0).any() and (got > 0).any()  # both sides occur
    lc = LinkClearance(hand, "middle", box, include_tip=True)
    alone = lc(q_full, T).tobytes()
    in_threads: list[bytes] = []
    workers = [
        threading.Thread(
            target=lambda: in_threads.extend(lc(q_full, T).tobytes() for _ in range(5))
        )
        for _ in range(3)
    ]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert in_threads == [alone] * 15


def test_link_clearance_measures_geometries_whose_collisions_are_disabled(box):
    """A collision model may disable a geometry's collisions (Pinocchio then leaves its
    pairs out): its distance to the object is still measured, as Coal measures it."""
    hand = Hand.five_finger()
    for g in hand.finger("index").geometry_ids:
        hand.collision_model.geometryObjects[g].disableCollision = True
    q_full, T = _near_poses(hand, "index", 20, 12)
    got = _same_as_coal(hand, "index", box, q_full, T, include_tip=True)
    assert (got < 0).any()


def test_finger_clearance_measures_geometries_whose_collisions_are_disabled():
    """As LinkClearance: a geometry whose collisions the model disables is measured."""
    hand = Hand.five_finger()
    for g in hand.finger("middle").geometry_ids:
        hand.collision_model.geometryObjects[g].disableCollision = True
    rng = np.random.default_rng(6)
    for _ in range(10):
        q = hand.neutral()
        for f in hand.fingers.values():
            q[f.q_indices] = rng.uniform(f.lower, f.upper)
        ids = list(hand.finger("index").geometry_ids)
        expected = _coal_pairs(hand, ids, list(hand.finger("middle").geometry_ids), q)
        assert FingerClearance(hand, "index", ["middle"])(q) == expected


def test_link_clearance_without_a_smallest_pair_takes_the_smallest_result(hand, box, monkeypatch):
    """Where Pinocchio names no pair (none below +inf, or NaN), the smallest result is
    read, NaN left out, as the pair-by-pair minimum does."""
    q_full, T = _near_poses(hand, "thumb", 10, 14)
    expected = LinkClearance(hand, "thumb", box)(q_full, T)
    measure = pin.computeDistances

    def none_named(pairs, gdata):
        measure(pairs, gdata)
        return len(pairs.collisionPairs)

    monkeypatch.setattr(clearance.pin, "computeDistances", none_named)
    assert LinkClearance(hand, "thumb", box)(q_full, T).tobytes() == expected.tobytes()


def test_finger_clearance_matches_coal_pair_by_pair(hand):
    rng = np.random.default_rng(5)
    for finger in ("index", "thumb"):
        fc = FingerClearance(hand, finger)
        mine = hand.finger(finger).geometry_ids
        others = [g for n, o in hand.fingers.items() if n != finger for g in o.geometry_ids]
        for _ in range(3):
            q = hand.neutral()
            for f in hand.fingers.values():
                q[f.q_indices] = rng.uniform(f.lower, f.upper)
            expected = _coal_pairs(hand, mine, others, q)
            assert_close(fc(q), expected, atol=1e-9, what=f"{finger} to the other fingers")


def test_finger_clearance_names_the_finger_it_measures_to(hand):
    """``nearest``: the distance of the call and the other finger it belongs to, the
    one whose pairs alone, by Coal, give that distance (random configurations); a
    clearance without pairs is infinite and names none."""
    rng = np.random.default_rng(15)
    for finger in ("index", "ring", "thumb"):
        fc = FingerClearance(hand, finger)
        mine = hand.finger(finger).geometry_ids
        for _ in range(4):
            q = hand.neutral()
            for f in hand.fingers.values():
                q[f.q_indices] = rng.uniform(f.lower, f.upper)
            d, other = fc.nearest(q)
            assert d == fc(q)
            each = {
                n: _coal_pairs(hand, mine, [g for g in o.geometry_ids if g not in mine], q)
                for n, o in hand.fingers.items()
                if n != finger
            }
            assert_close(each[other], d, atol=1e-9, what=f"{finger} to {other}")
            assert all(v >= d - 1e-9 for v in each.values())
    assert FingerClearance(hand, "index", others=[]).nearest(hand.neutral()) == (np.inf, None)


def test_finger_clearance_measures_a_configuration_once(hand, monkeypatch):
    """A configuration asked again (the same bits) gives the same distance without a
    measurement; another one is measured; the oldest is forgotten past the memo's
    size."""
    rng = np.random.default_rng(8)
    fc = FingerClearance(hand, "index")
    qs = []
    for _ in range(4):
        q = hand.neutral()
        for f in hand.fingers.values():
            q[f.q_indices] = rng.uniform(f.lower, f.upper)
        qs.append(q)
    first = [fc(q) for q in qs[:3]]
    calls = []
    measure = pin.computeDistances

    def counted(*args):
        calls.append(1)
        return measure(*args)

    monkeypatch.setattr(clearance.pin, "computeDistances", counted)
    monkeypatch.setattr(clearance, "_MEMO_KEPT", 3)
    assert [fc(q.copy()) for q in qs[:3]] == first and not calls
    nudged = qs[0].copy()
    nudged[hand.finger("index").q_indices[0]] += 1e-12
    fc(nudged)  # another configuration: measured, and qs[0] (the oldest) forgotten
    assert len(calls) == 1
    assert fc(qs[0]) == first[0] and len(calls) == 2
    assert first == [FingerClearance(hand, "index")(q) for q in qs[:3]]


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


def _shared_in_a_thread(hand: Hand) -> FingerClearance:
    import threading

    out: list[FingerClearance] = []
    t = threading.Thread(
        target=lambda h: out.append(FingerClearance.shared(h, "index", ["middle"])), args=(hand,)
    )
    t.start()
    t.join()
    return out[0]


def test_a_shared_finger_clearance_is_one_per_hand_pair_and_thread_and_dies_with_the_hand():
    import gc
    import weakref

    hand = Hand.five_finger()
    fc = FingerClearance.shared(hand, "index", ["middle"])
    assert FingerClearance.shared(hand, "index", ("middle",)) is fc
    assert FingerClearance.shared(hand, "index") is not fc  # every other finger
    assert FingerClearance.shared(Hand.five_finger(), "index", ["middle"]) is not fc
    rng = np.random.default_rng(2)
    q = hand.neutral()
    for f in hand.fingers.values():
        q[f.q_indices] = rng.uniform(f.lower, f.upper)
    assert fc(q) == FingerClearance(hand, "index", ["middle"])(q)  # the same distance
    # its Pinocchio data is not shared across threads
    assert _shared_in_a_thread(hand) is not fc
    gone = weakref.ref(hand)
    del hand, fc
    gc.collect()
    assert gone() is None  # the shared checks do not keep the hand alive
