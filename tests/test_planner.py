"""The whole-hand planner on the demo scenario, re-checked from the plan file alone.

The re-check below uses only the plan file (URDF path, object mesh, q, poses, phases),
Pinocchio and Coal: none of regrasp_pin's own kinematics or verification.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation, Slerp

from regrasp_pin import Plan, make_scenario, plan_manipulation
from regrasp_pin.exceptions import PlanningError


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


def test_three_fingers_hold_at_every_instant(demo):
    _, plan = demo
    for t in np.linspace(plan.t[0], plan.t[-1], 400):
        holding = sum(
            any(p.kind == "contact" and p.t_start - 1e-9 <= t <= p.t_end + 1e-9 for p in phases)
            for phases in plan.phases.values()
        )
        assert holding >= 3, t


class _FromFile:
    """Everything the re-check needs, built from the plan file with Pinocchio and Coal."""

    def __init__(self, plan: Plan):
        self.plan = plan
        urdf = str(plan.urdf_path)
        self.model = pin.buildModelFromUrdf(urdf, mimic=True)
        self.data = self.model.createData()
        self.geom = pin.buildGeomFromUrdf(self.model, urdf, pin.COLLISION)
        self.gdata = pin.GeometryData(self.geom)
        pts = coal.StdVec_Vec3s()
        pts.extend([np.asarray(v, float) for v in plan.object["vertices"]])
        self.obj = coal.Convex.convexHull(pts, False, None)
        # which finger moves each geometry: the finger whose joints are its ancestors
        joint_finger = {}
        for name, f in plan.hand["fingers"].items():
            for j in f["joints"]:
                joint_finger[self.model.getJointId(j)] = name
        self.geom_finger = []
        for g in self.geom.geometryObjects:
            j, owner = int(g.parentJoint), None
            while j > 0 and owner is None:
                owner = joint_finger.get(j)
                j = int(self.model.parents[j])
            self.geom_finger.append(owner)
        self.tip_frames = {
            n: self.model.getFrameId(f["tip_frame"]) for n, f in plan.hand["fingers"].items()
        }
        self.slerp = Slerp(plan.t, Rotation.from_quat(plan.T_palm_object[:, 3:]))

    def state(self, t: float):
        p = self.plan
        q = np.array([np.interp(t, p.t, p.q[:, j]) for j in range(p.q.shape[1])])
        x = np.array([np.interp(t, p.t, p.T_palm_object[:, j]) for j in range(3)])
        return q, self.slerp([t]).as_matrix()[0], x

    def distances(self, q, R, x):
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata)
        tf = coal.Transform3s(R, x)
        objs = self.geom.geometryObjects
        d_obj = {}
        for g, owner in enumerate(self.geom_finger):
            if owner is None:
                continue
            res = coal.DistanceResult()
            d_obj[g] = coal.distance(
                objs[g].geometry, self.gdata.oMg[g], self.obj, tf, coal.DistanceRequest(), res
            )
        d_ff = np.inf
        for a, fa in enumerate(self.geom_finger):
            for b, fb in enumerate(self.geom_finger):
                if fa is None or fb is None or fa >= fb:
                    continue
                res = coal.DistanceResult()
                d = coal.distance(
                    objs[a].geometry,
                    self.gdata.oMg[a],
                    objs[b].geometry,
                    self.gdata.oMg[b],
                    coal.DistanceRequest(),
                    res,
                )
                d_ff = min(d_ff, d)
        return d_obj, d_ff


def test_every_regrasp_passes_an_independent_dense_recheck(demo):
    _, plan = demo
    chk = _FromFile(plan)
    lo, hi = chk.model.lowerPositionLimit, chk.model.upperPositionLimit
    for r in plan.regrasps():
        sel = np.flatnonzero((plan.t >= r.t_start - 1e-9) & (plan.t <= r.t_end + 1e-9))
        moving = {i for i, f in enumerate(chk.geom_finger) if f == r.finger}
        worst_pen, worst_ff = np.inf, np.inf
        for a, b in zip(sel[:-1], sel[1:], strict=True):
            steps = int(np.ceil(np.abs(plan.q[b] - plan.q[a]).max() / 1e-3)) + 1
            for t in np.linspace(plan.t[a], plan.t[b], steps + 1):
                q, R, x = chk.state(t)
                assert np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9), (r.finger, t)
                d_obj, d_ff = chk.distances(q, R, x)
                worst_pen = min(worst_pen, min(d_obj[g] for g in moving))
                worst_ff = min(worst_ff, d_ff)
        assert worst_pen >= -1e-4, (
            f"{r.finger} at {r.t_start:.2f} s penetrates the object by {-worst_pen * 1e3:.3f} mm"
        )
        assert worst_ff > 0.0, f"{r.finger} at {r.t_start:.2f} s touches another finger"


def test_fingertips_stay_on_their_contacts(demo):
    _, plan = demo
    chk = _FromFile(plan)
    for name, phases in plan.phases.items():
        r = plan.hand["fingers"][name]["tip_radius"]
        for ph in phases:
            if ph.kind != "contact":
                continue
            for i in np.flatnonzero((plan.t >= ph.t_start - 1e-9) & (plan.t <= ph.t_end + 1e-9)):
                q, R, x = chk.state(plan.t[i])
                pin.framesForwardKinematics(chk.model, chk.data, q)
                tip = chk.data.oMf[chk.tip_frames[name]].translation
                want = R @ (ph.p_object + r * ph.n_object) + x
                assert np.linalg.norm(tip - want) <= 1e-4, (name, plan.t[i])


def test_unachievable_motion_raises_with_partial_plan():
    scen = make_scenario("five_finger", "hexagon", angle_deg=-100)
    from dataclasses import replace

    from regrasp_pin.contact import ContactModel

    # a trigger margin larger than any new contact can offer: the first regrasp fails
    params = replace(
        scen.params, contact=ContactModel(choice_margin_rad=2.0), earlier_starts_s=(0.0,)
    )
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=params)
    assert err.value.finger is not None and err.value.time_s is not None
    assert err.value.partial is not None and err.value.partial.t[-1] <= err.value.time_s + 1e-6
