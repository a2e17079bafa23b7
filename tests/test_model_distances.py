"""Capsule lower bounds on distances between hand geometries (model.distances)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, random_q

from regrasp_pin import Hand
from regrasp_pin.exceptions import InputError
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.distances import (
    _geometry,
    _placements,
    _segment_distance,
    _segment_ends,
    capsule_ends,
    capsule_gap,
    capsule_gaps,
    capsule_pair_gaps,
    object_gap_bound,
    object_gap_bounds,
)
from regrasp_pin.model.objects import Box


@pytest.fixture(scope="module")
def hand():
    return Hand.five_finger()


def test_capsule_gap_is_the_pair_by_pair_minimum_bit_for_bit(hand):
    # all pairs in one batch: each pair's distances as computed alone, minimum in order
    names = ("index", "middle")
    ids_a, ids_b = (list(hand.fingers[n].geometry_ids) for n in names)
    q = random_q(hand, 200, 31, names)
    ga, gb = [_geometry(hand, g) for g in ids_a], [_geometry(hand, g) for g in ids_b]
    A1, B1 = _segment_ends(ga, q)
    A2, B2 = _segment_ends(gb, q)
    # the segments' ends are the geometries' placements applied to their capsules
    for geoms, (A, B) in ((ga, (A1, B1)), (gb, (A2, B2))):
        R, p = _placements(geoms, q)
        for i, g in enumerate(geoms):
            assert_close(A[i], p[:, i] + R[:, i] @ g.seg_a, atol=1e-15, what="segment start")
            assert_close(B[i], p[:, i] + R[:, i] @ g.seg_b, atol=1e-15, what="segment end")
    ref = np.full(q.shape[0], np.inf)
    for i, g in enumerate(ga):
        for j, h in enumerate(gb):
            d = _segment_distance(A1[i], B1[i], A2[j], B2[j])[0]
            ref = np.minimum(ref, d - g.radius - h.radius)
    assert capsule_gap(hand, ids_a, ids_b, q).tobytes() == ref.tobytes()
    # pair by pair: the same bits, and their minimum is the bound
    pairs = capsule_pair_gaps(hand, ids_a, ids_b, q)
    assert pairs.shape == (len(ids_a), len(ids_b), q.shape[0])
    for i, g in enumerate(ga):
        for j, h in enumerate(gb):
            d = _segment_distance(A1[i], B1[i], A2[j], B2[j])[0] - g.radius - h.radius
            assert pairs[i, j].tobytes() == d.tobytes()
    assert pairs.min(axis=(0, 1)).tobytes() == ref.tobytes()
    # from ends known before: the same bits; ids_b held still at one configuration
    # (its ends at one row) is the same as that configuration in every row
    known = capsule_pair_gaps(
        hand, ids_a, ids_b, ends_a=capsule_ends(hand, ids_a, q), ends_b=(A2, B2)
    )
    assert known.tobytes() == pairs.tobytes()
    still = q.copy()
    still[:, hand.fingers["middle"].q_indices] = q[7, hand.fingers["middle"].q_indices]
    one = capsule_pair_gaps(
        hand, ids_a, ids_b, ends_a=(A1, B1), ends_b=capsule_ends(hand, ids_b, q[7:8])
    )
    assert one.tobytes() == capsule_pair_gaps(hand, ids_a, ids_b, still).tobytes()
    with pytest.raises(InputError, match="q"):
        capsule_pair_gaps(hand, ids_a, ids_b, ends_a=(A1, B1))
    assert np.all(np.isinf(capsule_pair_gaps(hand, ids_a, [], q)))
    assert np.all(np.isinf(capsule_gap(hand, [], ids_b, q)))
    # with a cap, the pairs whose bounding spheres are that far apart are skipped: the
    # gaps below it are the same bits, the others the cap
    for cap in (0.0, 0.004, float(np.median(ref)), 1.0):
        capped = capsule_gap(hand, ids_a, ids_b, q, cap_m=cap)
        assert capped.tobytes() == np.minimum(ref, cap).tobytes()
    assert 0 < (ref < 0.004).sum() < ref.size  # both sides of the cap occur


def test_capsule_gap_places_the_second_geometries_from_their_own_rows_bit_for_bit(hand):
    # the middle finger takes 7 distinct configurations over 200 rows (as the other
    # fingers repeat over a regrasp's grid nodes); the index moves in every row
    q = random_q(hand, 200, 37, ("index", "middle"))
    mid = hand.fingers["middle"].q_indices
    distinct = random_q(hand, 7, 38, ("middle",))
    rows = np.random.default_rng(39).integers(0, 7, 200)
    q[:, mid] = distinct[rows][:, mid]
    ids_a = list(hand.fingers["index"].geometry_ids)
    ids_b = list(hand.fingers["middle"].geometry_ids)
    # the index's joints in `distinct` differ from q's: only the middle's chain counts
    for cap in (np.inf, 0.004):
        full = capsule_gap(hand, ids_a, ids_b, q, cap_m=cap)
        split = capsule_gap(hand, ids_a, ids_b, q, cap_m=cap, q_b=distinct, rows_b=rows)
        assert split.tobytes() == full.tobytes()
    assert np.isfinite(full).any() and (full < 0.004).any()


def test_capsule_gaps_by_group_are_each_groups_own_bits(hand):
    """One finger against each other finger at once: every group's row is the bits of
    capsule_gap against that group alone (placed from its own rows, capped or not)."""
    q = random_q(hand, 150, 41, ("index", "middle", "ring", "thumb"))
    distinct = random_q(hand, 9, 42, ("middle", "ring", "thumb"))
    rows = np.random.default_rng(43).integers(0, 9, 150)
    ids_a = list(hand.fingers["index"].geometry_ids)
    groups = [list(hand.fingers[n].geometry_ids) for n in ("middle", "ring", "thumb")]
    for cap in (np.inf, 0.004):
        for kwargs in ({}, {"q_b": distinct, "rows_b": rows}):
            both = capsule_gaps(hand, ids_a, groups, q, cap_m=cap, **kwargs)
            assert both.shape == (3, 150)
            for g, ids_b in enumerate(groups):
                alone = capsule_gap(hand, ids_a, ids_b, q, cap_m=cap, **kwargs)
                assert both[g].tobytes() == alone.tobytes()
    assert (both < 0.004).any() and (both == 0.004).any()  # both sides of the cap
    assert np.all(np.isinf(capsule_gaps(hand, ids_a, [[], []], q)))


def test_capsule_gap_is_a_lower_bound_on_the_coal_distance(hand):
    names = ("ring", "little")
    ids_a, ids_b = (list(hand.fingers[n].geometry_ids) for n in names)
    q = random_q(hand, 40, 32, names)
    gap = capsule_gap(hand, ids_a, ids_b, q)
    gm = hand.collision_model
    gd = pin.GeometryData(gm)
    data = hand.model.createData()
    for row, qi in enumerate(q):
        pin.updateGeometryPlacements(hand.model, data, gm, gd, qi)
        exact = min(_coal_distance(gm, gd, a, b) for a in ids_a for b in ids_b)
        assert np.isfinite(gap[row]) and gap[row] <= exact + 1e-9, (row, gap[row], exact)


def _coal_distance(gm, gd, a, b):
    import coal

    req, res = coal.DistanceRequest(), coal.DistanceResult()
    oa, ob = gm.geometryObjects[a], gm.geometryObjects[b]
    return coal.distance(oa.geometry, gd.oMg[a], ob.geometry, gd.oMg[b], req, res)


@pytest.mark.parametrize("hand_name", ["five_finger", "allegro"])
def test_object_gap_bound_is_below_coal(hand_name):
    """object_gap_bound never exceeds Coal's distance (LinkClearance) from a finger's
    links or fingertip link to a box, near it or inside it, and is inf without
    geometries."""
    hand = Hand.five_finger() if hand_name == "five_finger" else Hand.allegro()
    box = Box((0.04, 0.06, 0.04))
    rng = np.random.default_rng(4)
    for name in hand.finger_names:
        f = hand.finger(name)
        q = rng.uniform(f.lower, f.upper, (60, f.k))
        full = hand.to_full(name, q)
        T = np.tile(np.eye(4), (60, 1, 1))
        T[:, :3, 3] = f.fk(q) + rng.normal(scale=0.02, size=(60, 3))
        for tip_only in (False, True):
            lc = LinkClearance(hand, name, box, tip_only=tip_only)
            exact = lc(full, T)
            bound = object_gap_bound(hand, lc.geometry_ids, box, full, T)
            assert np.all(bound <= exact + 1e-9), (name, tip_only)
            assert np.any(exact < 0) and np.any(bound > exact - 0.002)  # both cases, tight
    assert np.all(object_gap_bound(hand, [], box, full, T) == np.inf)


def test_object_gap_bounds_of_groups_are_the_bounds_of_each_group():
    """object_gap_bounds places the groups' geometries once: each row is, to the bit,
    object_gap_bound of that group alone (an empty group: inf)."""
    hand = Hand.five_finger()
    box = Box((0.04, 0.06, 0.04))
    rng = np.random.default_rng(5)
    f = hand.finger("index")
    q = rng.uniform(f.lower, f.upper, (50, f.k))
    full = hand.to_full("index", q)
    T = np.tile(np.eye(4), (50, 1, 1))
    T[:, :3, 3] = f.fk(q) + rng.normal(scale=0.02, size=(50, 3))
    links = LinkClearance(hand, "index", box).geometry_ids
    tip = LinkClearance(hand, "index", box, tip_only=True).geometry_ids
    thumb = LinkClearance(hand, "thumb", box, include_tip=True).geometry_ids
    groups = [links, [], tip, thumb]
    got = object_gap_bounds(hand, groups, box, full, T)
    assert got.shape == (4, 50)
    for row, group in zip(got, groups, strict=True):
        np.testing.assert_array_equal(row, object_gap_bound(hand, group, box, full, T))
    assert np.all(got[1] == np.inf) and np.isfinite(got[[0, 2, 3]]).all()
