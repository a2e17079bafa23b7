"""The whole-hand planner on the demo scenario, re-checked from the plan file alone.

The re-check (:func:`regrasp_pin.plan_check.recheck_plan`) uses only the plan file
(URDF path, object mesh, q, poses, phases), Pinocchio and Coal: none of regrasp_pin's
own kinematics or verification.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from regrasp_pin import Plan, make_scenario, plan_manipulation
from regrasp_pin.exceptions import PlanningError
from regrasp_pin.plan_check import recheck_plan


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    scen = make_scenario("five_finger", "hexagon")
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    path = result.plan.save(tmp_path_factory.mktemp("plan") / "plan.json")
    return result, Plan.load(path)


def test_demo_criteria(demo):
    result, plan = demo
    regrasps = plan.regrasps()
    assert len(regrasps) >= 4
    assert len({r.finger for r in regrasps}) >= 3
    assert all(r.report.ok for r in result.regrasps)
    total_turn = np.degrees(
        (
            Rotation.from_quat(plan.T_palm_object[-1, 3:])
            * Rotation.from_quat(plan.T_palm_object[0, 3:]).inv()
        ).magnitude()
    )
    assert total_turn >= 90.0


def test_plan_round_trips(demo):
    _, plan = demo
    assert Plan.from_dict(plan.to_dict()).to_dict() == plan.to_dict()


@pytest.fixture(scope="module")
def recheck(demo):
    _, plan = demo
    return recheck_plan(plan, max_step_rad=1e-3, penetration_tol_m=1e-4, contact_tol_m=1e-4)


def test_three_fingers_hold_at_every_instant(recheck):
    assert recheck.min_holding >= 3, recheck.t_min_holding_s


def test_every_regrasp_passes_an_independent_dense_recheck(demo, recheck):
    _, plan = demo
    assert [(r.finger, r.t_start) for r in recheck.regrasps] == [
        (r.finger, r.t_start) for r in plan.regrasps()
    ]
    assert not recheck.joint_limit_violations, recheck.joint_limit_violations
    for r in recheck.regrasps:
        assert r.min_object_distance_m >= -1e-4, (
            f"{r.finger} at {r.t_start:.2f} s penetrates the object by "
            f"{r.penetration_m * 1e3:.3f} mm"
        )
        assert r.min_finger_distance_m > 0.0, (
            f"{r.finger} at {r.t_start:.2f} s touches another finger"
        )


def test_fingertips_stay_on_their_contacts(recheck):
    assert recheck.max_contact_error_m <= 1e-4, (
        recheck.contact_error_finger,
        recheck.t_max_contact_error_s,
    )


def test_unachievable_motion_raises_with_partial_plan():
    scen = make_scenario("five_finger", "hexagon", angle_deg=-100)
    from dataclasses import replace

    from regrasp_pin.contact import ContactModel

    # a trigger margin larger than any new contact can offer: the first regrasp fails
    params = replace(
        scen.params, contact=ContactModel(choice_margin_rad=2.0), max_starts=1, max_backtracks=0
    )
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params)
    assert err.value.finger is not None and err.value.time_s is not None
    assert err.value.partial is not None and err.value.partial.t[-1] <= err.value.time_s + 1e-6
