"""What no plan can avoid (regrasp_pin.planning.feasibility): how long a finger could
hold from the start without a regrasp, read from its manifold, and an idle finger that
must hold where too few fingers reach the object."""

from __future__ import annotations

import math

import numpy as np
import pytest

from regrasp_pin.exceptions import FailureKind, PlanningError
from regrasp_pin.grasp.manifold import Manifold
from regrasp_pin.planning.feasibility import longest_start_hold
from regrasp_pin.planning.planner import plan_manipulation
from regrasp_pin.planning.setup import plan_setup
from regrasp_pin.suite.build import build_scenario
from regrasp_pin.suite.specs import generate_specs

TIMES = np.array([1.0, 1.5, 2.0, 2.5, 3.0])  # the motion's start need not be 0


def _manifold(holdable: np.ndarray, margin: float = 0.1) -> Manifold:
    """A manifold of ``holdable.shape[1]`` points whose entries are holdable (inside
    with ``margin`` to the limits, pad facing, fingertip link clear) exactly where
    ``holdable`` is True; elsewhere one of the three fails in turn."""
    n_t, n = holdable.shape
    fails = np.arange(n_t * n).reshape(n_t, n) % 3
    inside = holdable | (fails != 0)
    pad_ok = holdable | (fails != 1)
    tip_clear = holdable | (fails != 2)
    return Manifold(
        finger="index",
        times_s=TIMES[:n_t],
        q=np.zeros((n_t, n, 3)),
        reachable=np.ones((n_t, n), bool),
        inside=inside,
        margin_rad=np.full((n_t, n), margin),
        pad_ok=pad_ok,
        lower=np.full(3, -1.0),
        upper=np.full(3, 1.0),
        T_palm_object=np.broadcast_to(np.eye(4), (n_t, 4, 4)).copy(),
        tip_clear=tip_clear,
    )


def test_the_longest_lasting_start_contact_bounds_the_hold():
    """The exit of the contact that lasts longest from the start, without a break:
    a contact holdable again after a break, or only later (even to the end), does not
    count."""
    # columns: lost at 2.0 s, lost at 2.5 s, back after a break at 1.5 s, holdable
    # from 1.5 s to the end
    h = np.array(
        [
            [True, True, True, False],
            [True, True, False, True],
            [False, True, True, True],
            [False, False, True, True],
            [False, False, True, True],
        ]
    )
    assert longest_start_hold(_manifold(h), 0.1) == 2.5
    # every entry is checked: a fifth point lasting to the end from the start
    h2 = np.hstack([h, np.ones((5, 1), bool)])
    assert math.isinf(longest_start_hold(_manifold(h2), 0.1))


def test_the_margin_to_the_limits_counts_and_none_holdable_is_the_start():
    h = np.ones((5, 2), bool)
    assert math.isinf(longest_start_hold(_manifold(h, margin=0.1), 0.1))
    assert longest_start_hold(_manifold(h, margin=0.1), 0.2) == TIMES[0]
    h[0] = False
    assert longest_start_hold(_manifold(h), 0.1) == TIMES[0]


def test_an_idle_finger_that_must_hold_where_too_few_fingers_reach_proves_no_plan():
    """Suite spec 42 (the five-finger hand turning a triangular prism -256 deg about
    the thumb's contact): for two seconds neither the index nor the middle finger has a
    usable contact, so the thumb, the ring and the idle little finger are the only
    fingers that could hold, and all three must, each on one contact (a flight spans a
    grid time). No contact of the little finger stays usable that long, so no plan
    exists: the planner says so before any search, naming the little finger."""
    scen = build_scenario(generate_specs(43, 0)[42])
    with pytest.raises(PlanningError) as failed:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    exc = failed.value
    assert exc.kind == FailureKind.INFEASIBLE and exc.finger == "little"
    assert "regrasps" not in exc.partial.summary["stage_s"]  # no search ran
    # the claim, read from the manifolds on its own
    every = plan_setup(scen.hand, scen.obj, scen.motion, scen.params).every
    t = every["little"].times_s
    run = (t >= exc.time_s - 1e-9) & (t <= exc.time_s + exc.required + 1e-9)
    assert run.sum() >= 3  # a stretch of grid times, longer than a flight
    reach = {n: m.usable(0.0)[run].any(axis=1) for n, m in every.items()}
    assert set(reach) == {"thumb", "index", "middle", "ring", "little"}
    assert not reach["index"].any() and not reach["middle"].any()
    assert all(reach[n].all() for n in ("thumb", "ring", "little"))
    assert scen.params.fewest_holding == 3
    assert not every["little"].usable(0.0)[run].all(axis=0).any()
    assert every["ring"].usable(0.0)[run].all(axis=0).any()  # the ring could
