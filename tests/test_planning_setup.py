"""What a plan builds before its search (regrasp_pin.planning.setup), built once.

Plans from one setup must be the plans built without it: the same regrasps and the
same joint trajectories, bit for bit, whatever was planned from the setup before (a
plan adds a joining finger's manifold to its own copy of the setup's, never to the
setup's). Scene: the canonical scenario turned 60 deg at 40 deg/s, from its grasp and
from the grasp that avoids the index finger's start contact (a backup's).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import CONE_60

from regrasp_pin import make_scenario, plan_manipulation
from regrasp_pin.exceptions import InputError, PlanningError
from regrasp_pin.planning import plan_setup


@pytest.fixture(scope="module")
def scen():
    return make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40)


@pytest.fixture(scope="module")
def other_grasp(scen):
    away = {"index": np.asarray(scen.grasp.points_object["index"])[None]}
    return scen.grasp_search.choose(scen.hand, scen.obj, avoid=away)


def _outcome(scen, grasp, setup=None):
    """What a plan gives: its regrasps (finger, lift-off, Q) and trajectory, or its
    failure (kind, finger, time)."""
    try:
        r = plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=grasp, params=scen.params, setup=setup
        )
    except PlanningError as exc:
        return ("failed", exc.kind, exc.finger, exc.time_s)
    regrasps = [(g.finger, g.t_start, tuple(g.Q_object)) for g in r.regrasps]
    return ("planned", regrasps, r.plan.q.tobytes())


def test_plans_from_one_setup_are_the_plans_without_it(scen, other_grasp):
    assert not np.allclose(
        other_grasp.points_object["index"], scen.grasp.points_object["index"], atol=1e-3
    )
    setup = plan_setup(scen.hand, scen.obj, scen.motion, scen.params)
    every_before = dict(setup.every)
    shared = [_outcome(scen, g, setup) for g in (scen.grasp, other_grasp)]
    alone = [_outcome(scen, g) for g in (scen.grasp, other_grasp)]
    assert shared == alone
    assert shared[0][0] == "planned"  # the canonical scenario plans fully
    # the plans left the setup as it was
    assert list(setup.every) == list(every_before)
    assert all(setup.every[n] is m for n, m in every_before.items())


def test_a_setup_for_another_motion_or_parameters_is_an_input_error(scen):
    setup = plan_setup(scen.hand, scen.obj, scen.motion, scen.params)
    other_motion = make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40).motion
    with pytest.raises(InputError, match="setup.*another motion"):
        plan_manipulation(
            scen.hand, scen.obj, other_motion, grasp=scen.grasp, params=scen.params, setup=setup
        )
    coarser = dataclasses.replace(scen.params, sample_spacing_m=0.004)
    with pytest.raises(InputError, match="sample_spacing_m built 0.002, given 0.004"):
        plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=coarser, setup=setup
        )
    with pytest.raises(InputError, match="setup.*PlanSetup"):
        plan_manipulation(
            scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params, setup={}
        )
    # the search's own settings are free: a setup serves any budget
    fewer = dataclasses.replace(scen.params, max_steps=1, budget_s=5.0)
    setup.check(scen.hand, scen.obj, scen.motion, fewer)


def test_the_setup_holds_the_taking_part_fingers_manifolds(scen):
    params = dataclasses.replace(scen.params, fingers=("thumb", "index", "middle"))
    setup = plan_setup(scen.hand, scen.obj, scen.motion, params)
    assert setup.active == ("thumb", "index", "middle")
    assert list(setup.manifolds) == ["thumb", "index", "middle"]
    assert set(setup.manifolds) <= set(setup.every)
    n_m = round(scen.motion.duration_s / params.manifold_dt_s) + 1
    for m in setup.manifolds.values():
        np.testing.assert_allclose(
            m.times_s, np.linspace(scen.motion.t_start, scen.motion.t_end, n_m), atol=1e-12
        )


def test_a_finger_that_joins_adds_its_manifold_to_the_plan_not_to_the_setup():
    # -80 deg at 10 deg/s, searched without the proof of what must hold (whose
    # manifolds would include the idle little finger): the little finger joins, and
    # its manifold is built by the plan that joins it
    scen = make_scenario("five_finger", "hexagon", angle_deg=-80, rate_deg_s=10, contact=CONE_60)
    params = dataclasses.replace(scen.params, prove_infeasible=False)
    setup = plan_setup(scen.hand, scen.obj, scen.motion, params)
    assert "little" not in setup.every
    joins = []
    for _ in range(2):  # the second plan from the same setup plans as the first
        try:
            plan = plan_manipulation(
                scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params, setup=setup
            ).plan
        except PlanningError as exc:
            plan = exc.partial
        joins.append([p.t_start for p in plan.phases["little"] if p.kind == "join"])
        assert "little" not in setup.every and list(setup.manifolds) == list(params.fingers)
    assert joins[0] and joins[0] == joins[1]
