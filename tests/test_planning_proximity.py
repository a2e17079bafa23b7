"""Holding fingers that close in on each other, against Pinocchio's computeDistances."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest
from conftest import held_grasp

from regrasp_pin import make_scenario
from regrasp_pin.planning.proximity import clear_of_fingers, holding_proximity

TRIGGER_M, LOST_M = 0.0015, 0.0005


@pytest.fixture(scope="module")
def holds():
    """The demo's initial grasp, every finger holding its contact over the whole turn
    (no regrasp), so that fingers close in on each other."""
    scen = make_scenario("five_finger", "hexagon")
    grid, base, holding = held_grasp(scen)
    return scen.hand, holding, grid, base


def _distance(hand, holding, base, a, b, t):
    """computeDistances over every geometry pair of fingers a and b at time t."""
    gm = pin.GeometryModel()
    for g in hand.collision_model.geometryObjects:
        gm.addGeometryObject(pin.GeometryObject(g))
    for ga, gb in itertools.product(hand.finger(a).geometry_ids, hand.finger(b).geometry_ids):
        gm.addCollisionPair(pin.CollisionPair(int(ga), int(gb)))
    gdata = pin.GeometryData(gm)
    q = base.copy()
    for n, h in holding.items():
        q[hand.finger(n).q_indices] = h.q_at(np.array([t]))[0]
    pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, q)
    return min(r.min_distance for r in gdata.distanceResults)


def _both_hold(holding, times, *fingers):
    """The times at which every one of the holding ``fingers`` still holds: up to where
    its contact is lost (a still finger, not in ``holding``, always counts)."""
    until = min(
        (holding[f].track.followed_until_s for f in fingers if f in holding), default=np.inf
    )
    return times[times <= until + 1e-9]


def _brute_force(hand, holding, base, times):
    """Per finger, its earliest (trigger time, other, lost time) from computeDistances of
    every pair at every time at which both hold (ties: the other finger's name)."""
    out = {}
    for a, b in itertools.combinations(sorted(holding), 2):
        d = np.array(
            [_distance(hand, holding, base, a, b, t) for t in _both_hold(holding, times, a, b)]
        )
        below = np.flatnonzero(d < TRIGGER_M)
        if below.size == 0:
            continue
        i = below[0]
        lost = np.flatnonzero(d[i:] < LOST_M)
        t_lost = times[i + lost[0]] if lost.size else np.inf
        for me, other in ((a, b), (b, a)):
            new = (times[i], other, t_lost)
            if me not in out or new[:2] < out[me][:2]:
                out[me] = new
    return out


@pytest.mark.parametrize("until_s", [0.5, None], ids=["first-half-second", "whole-turn"])
def test_proximity_finds_the_first_time_below_each_distance(holds, until_s):
    hand, holding, grid, base = holds
    times = grid[::5] if until_s is None else grid[grid <= until_s + 1e-9][::5]
    prox = holding_proximity(hand, holding, times, base, trigger_m=TRIGGER_M, lost_m=LOST_M)
    expected = _brute_force(hand, holding, base, times)
    assert set(prox) == set(expected)  # fingers that stay apart are absent
    for me, (t_trig, other, t_lost) in expected.items():
        p = prox[me]
        assert (p.trigger_s, p.other, p.lost_s) == (pytest.approx(t_trig), other, t_lost), me
        d = _distance(hand, holding, base, me, other, p.trigger_s)
        assert p.distance_m == pytest.approx(d, abs=1e-6)  # GJK tolerances differ
    if until_s is None:
        # held through the whole turn without regrasping, some fingers close in
        assert expected


def test_a_holding_finger_near_a_still_one_triggers(holds):
    """Of two holding fingers that close in on each other, one stops at the time they
    are nearest the trigger distance and stays there; the others hold through the turn.
    Pairs with the still finger count for the holding finger only, as computeDistances
    finds them."""
    hand, holding, grid, base = holds
    times = grid[::5]
    first = min(
        holding_proximity(hand, holding, times, base, trigger_m=TRIGGER_M, lost_m=LOST_M).values(),
        key=lambda p: (p.trigger_s, p.finger),
    )
    gone = first.other
    still = base.copy()
    still[hand.finger(gone).q_indices] = holding[gone].q_at(np.array([first.trigger_s]))[0]
    rest = {n: h for n, h in holding.items() if n != gone}
    prox = holding_proximity(
        hand, rest, times, still, trigger_m=TRIGGER_M, lost_m=LOST_M, still=[gone, "little"]
    )
    expected = {}
    for me in sorted(rest):
        firsts = []
        for other in sorted(set(rest) - {me}) + [gone, "little"]:
            both = _both_hold(rest, times, me, other)
            d = np.array([_distance(hand, rest, still, me, other, t) for t in both])
            below = np.flatnonzero(d < TRIGGER_M)
            if below.size:
                lost = np.flatnonzero(d[below[0] :] < LOST_M)
                t_lost = times[below[0] + lost[0]] if lost.size else np.inf
                firsts.append((times[below[0]], other, t_lost))
        if firsts:
            expected[me] = min(firsts, key=lambda x: x[:2])
    assert set(prox) == set(expected) and gone not in prox
    for me, (t_trig, other, t_lost) in expected.items():
        assert (prox[me].trigger_s, prox[me].other, prox[me].lost_s) == (
            pytest.approx(t_trig),
            other,
            t_lost,
        ), me
    # the neighbour it was closing in on meets it, by the time it stopped at the latest
    assert prox[first.finger].other == gone
    assert prox[first.finger].trigger_s <= first.trigger_s + 1e-9


def test_a_still_finger_that_moves_is_measured_where_it_is_at_each_time(holds):
    """A finger that let go moves while it backs off and parks, and another may land
    near it meanwhile: ``base_q`` has one configuration per time. Moved along its own
    hold's configurations without holding, the neighbour gives the holding finger the
    proximity it had when both held; left where it was at the start, it does not."""
    hand, holding, grid, base = holds
    times = grid[::5]
    kw = {"trigger_m": TRIGGER_M, "lost_m": LOST_M}
    first = min(
        holding_proximity(hand, holding, times, base, **kw).values(),
        key=lambda p: (p.trigger_s, p.finger),
    )
    gone = first.other
    rest = {n: h for n, h in holding.items() if n != gone}
    moving = np.tile(base, (times.size, 1))
    moving[:, hand.finger(gone).q_indices] = holding[gone].q_at(times)
    prox = holding_proximity(hand, rest, times, moving, still=[gone], **kw)
    assert prox[first.finger].other == gone
    assert prox[first.finger].trigger_s == pytest.approx(first.trigger_s)
    start = base.copy()
    start[hand.finger(gone).q_indices] = holding[gone].q_at(times[:1])[0]
    left = holding_proximity(hand, rest, times, start, still=[gone], **kw).get(first.finger)
    assert left is None or (left.trigger_s, left.other) != (prox[first.finger].trigger_s, gone)


def test_candidates_stay_clear_until_a_finger_comes_near(holds):
    """clear_of_fingers against computeDistances at every time: the mask is False
    from the first time the candidate finger is within the limit of another one."""
    hand, holding, grid, base = holds
    times = grid[::25]
    rng = np.random.default_rng(0)
    f = hand.finger("middle")
    # the middle finger's own hold plus random configurations near it
    q_own = holding["middle"].q_at(times)
    q_finger = np.stack(
        [q_own, *[q_own + rng.normal(0.0, 0.15, q_own.shape) for _ in range(3)]], axis=1
    )
    q_finger = np.clip(q_finger, f.lower, f.upper)
    q_hand = np.broadcast_to(base, (times.size, base.size)).copy()
    for n, h in holding.items():
        q_hand[:, hand.finger(n).q_indices] = h.q_at(times)
    others = ["index", "ring"]
    ok = clear_of_fingers(hand, "middle", q_finger, q_hand, others, TRIGGER_M)
    assert ok.shape == (times.size, 4)
    firsts = []
    for c in range(4):
        per_time = []
        for k in range(times.size):
            gm = pin.GeometryModel()
            for g in hand.collision_model.geometryObjects:
                gm.addGeometryObject(pin.GeometryObject(g))
            for o in others:
                for ga, gb in itertools.product(f.geometry_ids, hand.finger(o).geometry_ids):
                    gm.addCollisionPair(pin.CollisionPair(int(ga), int(gb)))
            gdata = pin.GeometryData(gm)
            q = q_hand[k].copy()
            q[f.q_indices] = q_finger[k, c]
            pin.computeDistances(hand.model, hand.model.createData(), gm, gdata, q)
            per_time.append(min(r.min_distance for r in gdata.distanceResults))
        below = np.flatnonzero(np.array(per_time) < TRIGGER_M)
        first = below[0] if below.size else times.size
        firsts.append(first)
        assert np.all(ok[:first, c]) and not np.any(ok[first:, c]), (c, first)
    # some of the perturbed candidates come near the index or ring finger
    assert not ok.all()
    # with a horizon per candidate, only its first times are measured: the same mask
    # there (the first time below the limit when it falls within), True after it
    horizon = np.array([times.size, 0, *[max(fc - 1, 1) for fc in firsts[2:]]])
    part = clear_of_fingers(hand, "middle", q_finger, q_hand, others, TRIGGER_M, horizon=horizon)
    for c, h in enumerate(horizon):
        assert np.array_equal(part[:h, c], ok[:h, c]) and part[h:, c].all(), (c, h)
