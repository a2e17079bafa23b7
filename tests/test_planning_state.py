"""The plan state's views of the hand (regrasp_pin.planning.state)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from regrasp_pin import Hand, PlannerParams
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
