"""The plan state's views of the hand (regrasp_pin.planning.state)."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import held_grasp

from regrasp_pin import Hand, PlannerParams, make_scenario
from regrasp_pin.grasp.holding import holding_q
from regrasp_pin.planning import state as plan_state


@pytest.fixture(scope="module")
def hand():
    return Hand.five_finger()


def _let_go(hand, grid):
    """A context and a state in which nobody holds and the middle finger let go at
    0.1 s: it moves from its lower limits to its mid-range until 0.5 s, then stays."""
    f = hand.fingers["middle"]
    times = np.linspace(0.1, 2.0, 191)
    share = np.clip((times - 0.1) / 0.4, 0.0, 1.0)[:, None]
    q = f.lower + share * (f.q_mid - f.lower)
    ctx = SimpleNamespace(
        grid=grid,
        base_q=hand.neutral(),
        scene=SimpleNamespace(hand=hand, motion=SimpleNamespace(t_end=2.0)),
        params=PlannerParams(),
    )
    state = SimpleNamespace(
        now=0.2,
        holding={},
        released={"middle": SimpleNamespace(times_s=times, q=q)},
        held_to_end=frozenset(),
    )
    return ctx, state, f


def test_a_finger_that_let_go_is_where_its_release_puts_it_at_each_time(hand):
    """While it backs off and parks the finger moves: the hand's configurations follow
    its release sample by sample (interpolated), and its final posture after; the other
    fingers keep theirs."""
    grid = np.round(np.arange(0.0, 2.0 + 1e-9, 0.01), 9)
    ctx, state, f = _let_go(hand, grid)
    times = grid[grid >= 0.2]
    q = plan_state.with_released(ctx, state, times, np.tile(ctx.base_q, (times.size, 1)))
    rel = state.released["middle"]
    for j, i in enumerate(f.q_indices):
        np.testing.assert_allclose(q[:, i], np.interp(times, rel.times_s, rel.q[:, j]))
    parked = times >= 0.5
    np.testing.assert_allclose(q[parked][:, f.q_indices], np.tile(f.q_mid, (parked.sum(), 1)))
    assert not np.allclose(q[0, f.q_indices], f.q_mid)  # still moving at 0.2 s
    others = np.setdiff1d(np.arange(hand.model.nq), f.q_indices)
    np.testing.assert_array_equal(q[:, others], np.tile(ctx.base_q[others], (times.size, 1)))


def test_the_triggers_measure_a_finger_that_let_go_where_it_is_then(hand, monkeypatch):
    """The holding fingers' proximity is measured against a finger that let go at its
    configuration at each time (another finger may land near it while it parks), not
    at its final posture only."""
    grid = np.round(np.arange(0.0, 2.0 + 1e-9, 0.01), 9)
    ctx, state, f = _let_go(hand, grid)
    seen = {}

    def capture(hand_, holding, times, base, **kwargs):
        seen.update(times=times, base=np.asarray(base), still=kwargs["still"])
        return {}

    monkeypatch.setattr(plan_state, "holding_proximity", capture)
    assert plan_state.pending_triggers(ctx, state) == []
    times = seen["times"]
    assert times[0] == pytest.approx(0.2) and "middle" in seen["still"]
    rel = state.released["middle"]
    for j, i in enumerate(f.q_indices):
        np.testing.assert_allclose(seen["base"][:, i], np.interp(times, rel.times_s, rel.q[:, j]))


def test_a_hand_motion_is_its_holds_and_releases_and_its_key_says_which():
    """``HandMotion``: the holding fingers by their exact IK, the others at the base
    configuration, bit for bit; its key is the same for the same holds (other objects,
    copied arrays, the fingers in another order) and differs when a contact moves by
    1e-12 m, a finger lets go or another finger holds."""
    scen = make_scenario()
    _, base, holding = held_grasp(scen)
    hand, motion, tol = scen.hand, scen.motion, scen.params.contact.ik_tol_m
    ctx = SimpleNamespace(
        scene=SimpleNamespace(hand=hand, motion=motion), params=scen.params, base_q=base
    )
    state = SimpleNamespace(holding=holding, released={})
    stay = ["thumb", "middle", "ring"]
    times = np.linspace(0.3, 0.8, 11)
    moving = plan_state.HandMotion(ctx, state, stay)
    expected = np.tile(base, (times.size, 1))
    for n in stay:
        expected[:, hand.fingers[n].q_indices] = holding_q(hand, motion, n, holding[n], times, tol)
    assert np.array_equal(moving(times), expected)

    def copied(h, **change):
        track = dataclasses.replace(h.track, times_s=h.track.times_s.copy(), q=h.track.q.copy())
        return dataclasses.replace(
            h, **{"p": h.p.copy(), "n": h.n.copy(), "track": track, **change}
        )

    same = SimpleNamespace(holding={n: copied(h) for n, h in holding.items()}, released={})
    assert plan_state.HandMotion(ctx, same, stay[::-1]).key == moving.key
    nudged = dict(same.holding, middle=copied(holding["middle"], p=holding["middle"].p + 1e-12))
    rel = SimpleNamespace(times_s=times, q=np.tile(hand.fingers["index"].q_mid, (times.size, 1)))
    others = [
        plan_state.HandMotion(ctx, SimpleNamespace(holding=nudged, released={}), stay),
        plan_state.HandMotion(ctx, SimpleNamespace(holding=holding, released={"index": rel}), stay),
        plan_state.HandMotion(ctx, state, ["thumb", "middle", "index"]),
    ]
    keys = {moving.key, *(o.key for o in others)}
    assert len(keys) == 4
