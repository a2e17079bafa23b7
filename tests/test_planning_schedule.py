"""Lift-off windows and the start times tried in them."""

from __future__ import annotations

import numpy as np
import pytest

from regrasp_pin.exceptions import InputError
from regrasp_pin.grasp.contact import ContactModel
from regrasp_pin.grasp.tracking import ContactTrack
from regrasp_pin.planning.schedule import (
    LiftOffWindow,
    held_until,
    lift_off_window,
    regrasp_chain,
    start_times,
)


def _track(margin: np.ndarray, error: np.ndarray | None = None) -> ContactTrack:
    n = margin.size
    return ContactTrack(
        finger="index",
        times_s=np.linspace(0.0, 0.1 * (n - 1), n),
        p_object=np.zeros(3),
        n_object=np.array([0.0, 0.0, 1.0]),
        q=np.zeros((n, 3)),
        error_m=np.zeros(n) if error is None else error,
        margin_rad=margin,
        pad_cos=np.ones(n),
        cos_cone=0.5,
        link_clearance_m=np.full(n, np.inf),
        reasons=tuple("" for _ in range(n)),
    )


def test_held_until_is_the_last_time_inside_the_limits_without_a_break():
    margin = np.array([0.3, 0.2, 0.1, 0.04, 0.01, -0.01, 0.2])  # leaves at index 5
    assert held_until(_track(margin), ContactModel()) == pytest.approx(0.4)
    err = np.zeros(7)
    err[2] = 1.0  # IK loses the contact at index 2
    assert held_until(_track(margin, err), ContactModel()) == pytest.approx(0.1)
    assert held_until(_track(np.full(4, 0.3)), ContactModel()) == pytest.approx(0.3)


def test_window_reaches_past_the_trigger_to_the_limits_themselves():
    margin = np.array([0.3, 0.2, 0.1, 0.04, 0.01, -0.01])
    win = lift_off_window(
        "index", _track(margin), 0.3, earliest_s=0.0, lead_s=0.02, contact=ContactModel()
    )
    assert win.preferred_s == pytest.approx(0.28)
    assert win.latest_s == pytest.approx(0.4) and not win.empty
    lost = lift_off_window(
        "index",
        _track(margin),
        0.3,
        earliest_s=0.0,
        lead_s=0.02,
        contact=ContactModel(),
        lost_s=0.25,
    )
    assert lost.latest_s == pytest.approx(0.25) and lost.preferred_s == pytest.approx(0.25)


def test_start_times_go_outwards_from_the_preferred_one_within_the_window():
    win = LiftOffWindow("index", 1.0, earliest_s=0.75, latest_s=1.3, preferred_s=0.98)
    got = start_times(win, step_s=0.1, max_starts=5)
    np.testing.assert_allclose(got, [0.98, 0.88, 1.08, 0.78, 1.18])
    assert all(0.75 <= t <= 1.3 for t in got)
    # a further bound (the motion's end less the duration) leaves [0.75, 1.0]: shorter
    # than 4 steps, so sampled finer, 5 times across it (step 0.25 / 4)
    got = start_times(win, latest_s=1.0, step_s=0.1)
    np.testing.assert_allclose(got, [0.98, 0.9175, 0.855, 0.7925])
    assert all(0.75 <= t <= 1.0 for t in got)


def test_a_window_at_one_instant_gives_one_start_and_a_tiny_one_is_not_oversampled():
    win = LiftOffWindow("index", 1.0, earliest_s=0.5, latest_s=0.5, preferred_s=0.5)
    assert start_times(win) == [0.5]
    tiny = LiftOffWindow("index", 1.0, earliest_s=0.5, latest_s=0.53, preferred_s=0.5)
    np.testing.assert_allclose(start_times(tiny, min_step_s=0.02), [0.5, 0.52])


def test_an_empty_window_has_no_start():
    win = LiftOffWindow("index", 1.0, earliest_s=1.2, latest_s=1.1, preferred_s=1.1)
    assert win.empty and start_times(win) == []


def _brute_force_latest_start(lost: dict[str, float], d: float) -> float:
    """The latest start of a back-to-back chain over every order (the chain's claim:
    earliest loss first is the best order)."""
    from itertools import permutations

    best = -np.inf
    for order in permutations(lost):
        best = max(best, min(lost[n] - j * d for j, n in enumerate(order)))
    return best


def test_chain_starts_late_enough_for_every_hold_in_turn():
    rng = np.random.default_rng(3)
    for _ in range(200):
        names = ["thumb", "index", "middle", "ring"][: rng.integers(1, 5)]
        lost = {n: float(rng.uniform(0.0, 3.0)) for n in names}
        d = float(rng.uniform(0.1, 0.6))
        chain = regrasp_chain(lost, d)
        assert chain.latest_start_s == pytest.approx(_brute_force_latest_start(lost, d))
        assert [lost[n] for n in chain.order] == sorted(lost.values())
        # started then, back to back, every finger lifts off by its loss
        for j, n in enumerate(chain.order):
            assert chain.latest_start_s + j * d <= lost[n] + 1e-12
        # the first must land by the latest start of the others' chain
        rest = {n: lost[n] for n in chain.order[1:]}
        if rest:
            assert chain.land_by_s == pytest.approx(regrasp_chain(rest, d).latest_start_s)
        else:
            assert chain.land_by_s == np.inf


def test_chain_names_the_binding_hold_and_breaks_ties_by_name():
    chain = regrasp_chain({"ring": 2.0, "index": 1.0, "middle": 1.2}, 0.5)
    assert chain.order == ("index", "middle", "ring")
    assert chain.latest_start_s == pytest.approx(0.7)  # middle: 1.2 - 0.5
    assert chain.binding == "middle"
    tied = regrasp_chain({"ring": 1.0, "index": 1.0 + 1e-15}, 0.5)
    assert tied.order == ("index", "ring")  # equal to 1e-9 s: by name
    assert regrasp_chain({}, 0.5).order == ()
    with pytest.raises(InputError, match="duration_s"):
        regrasp_chain({"index": 1.0}, 0.0)
