"""The independent plan re-check passes a clean plan and reports what a corrupted one breaks.

The clean plan is built by hand (no planner): the canonical scenario's grasp, the first
0.6 s of its motion, every finger holding by IK but the ring finger, which lifts 10 mm off
its contact along the contact normal and lands on it again. Corruptions are then made
in ``q`` or the phases, and each must be reported with its numbers.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from regrasp_pin import ContactPhase, Plan, RegraspPhase, make_scenario
from regrasp_pin.exceptions import InputError, ModelFileError
from regrasp_pin.grasp.contact import tip_targets
from regrasp_pin.grasp.holding import holding_hand, rest_configuration
from regrasp_pin.grasp.quality import ferrari_canny_epsilon
from regrasp_pin.model.clearance import LinkClearance
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.plan import IdlePhase
from regrasp_pin.verify._closure import epsilon as closure_epsilon
from regrasp_pin.verify.plan_check import recheck_plan

T_END = 0.6
LIFT = (0.1, 0.5)  # the ring regrasp [s]
LIFT_M = 0.010  # how far the ring tip rises off its contact at mid-regrasp [m]


def hand_made_plan() -> tuple[Plan, object, np.ndarray]:
    """The clean plan, the hand, and the ring's lift ``(S, k)`` [rad] added to its hold."""
    scen = make_scenario("five_finger", "hexagon", rate_deg_s=20)
    hand, obj, grasp = scen.hand, scen.obj, scen.grasp
    t = np.round(np.arange(0.0, T_END + 1e-9, 0.01), 9)
    motion = ObjectMotion.from_poses(t, scen.motion.pose(t))
    fingers = tuple(grasp.points_object)
    idle = [n for n in hand.finger_names if n not in fingers]
    q = holding_hand(hand, motion, grasp, fingers, moving="")(t)
    q[:, :] = np.where(
        np.isin(np.arange(hand.model.nq), [i for n in idle for i in hand.fingers[n].q_indices]),
        rest_configuration(hand, obj, motion, idle),
        q,
    )
    # the ring finger: lift along the contact normal and land on the same contact
    f = hand.fingers["ring"]
    p, n = grasp.points_object["ring"], grasp.normals_object["ring"]
    t_mid = 0.5 * sum(LIFT)
    k_mid = int(np.argmin(np.abs(t - t_mid)))
    above = tip_targets((p + LIFT_M * n)[None], n[None], f.tip_radius, motion.pose(t_mid))[0]
    res = f.ik(above, q[k_mid, f.q_indices])
    assert res.success[0]
    delta = res.q[0] - q[k_mid, f.q_indices]
    s = np.clip((t - LIFT[0]) / (LIFT[1] - LIFT[0]), 0.0, 1.0)
    lift = np.sin(np.pi * s)[:, None] ** 2 * delta  # (S, k) [rad]
    q[:, f.q_indices] += lift
    verts, tris = obj.mesh()
    phases = {
        name: [
            ContactPhase(
                finger=name,
                t_start=0.0,
                t_end=T_END,
                p_object=grasp.points_object[name],
                n_object=grasp.normals_object[name],
            )
        ]
        for name in fingers
        if name != "ring"
    }
    phases["ring"] = [
        ContactPhase(finger="ring", t_start=0.0, t_end=LIFT[0], p_object=p, n_object=n),
        RegraspPhase(
            finger="ring",
            t_start=LIFT[0],
            t_end=LIFT[1],
            P_object=p,
            Q_object=p,
            waypoints_object=np.array([p + LIFT_M * n]),
            min_clearance_m=0.0,
            planning_ms=0.0,
        ),
        ContactPhase(finger="ring", t_start=LIFT[1], t_end=T_END, p_object=p, n_object=n),
    ]
    plan = Plan(
        hand={
            "name": hand.name,
            "urdf": str(hand.urdf_path),
            "fingers": {
                name: {
                    "tip_frame": fi.tip_frame,
                    "tip_radius": fi.tip_radius,
                    "joints": list(fi.joint_names),
                }
                for name, fi in hand.fingers.items()
            },
        },
        object={
            "kind": obj.kind,
            "params": obj.params,
            "vertices": verts.tolist(),
            "faces": tris.tolist(),
        },
        t=t,
        q=q,
        T_palm_object=motion.as_xyzquat(t),
        phases=phases,
    )
    return plan, hand, lift


@pytest.fixture(scope="module")
def clean():
    return hand_made_plan()


def _with_q(plan: Plan, q: np.ndarray) -> Plan:
    out = copy.deepcopy(plan)
    out.q = q
    return out


def test_clean_plan_passes(clean, tmp_path):
    plan, _, _ = clean
    chk = recheck_plan(Plan.load(plan.save(tmp_path / "plan.json")))
    assert chk.ok, chk.problems
    assert chk.min_holding == 3
    assert len(chk.regrasps) == 1
    r = chk.regrasps[0]
    # the ring touches the object at lift-off and landing, never closer
    assert -1e-4 <= r.min_object_distance_m <= 1e-4
    assert r.min_finger_distance_m > 0.0
    assert chk.max_contact_error_m <= 1e-4
    # densified: no joint moves more than 1 mrad between two checked samples
    sel = (plan.t >= LIFT[0] - 1e-9) & (plan.t <= LIFT[1] + 1e-9)
    assert r.n_samples >= np.abs(np.diff(plan.q[sel], axis=0)).max(axis=1).sum() / 1e-3


def test_a_finger_pushed_into_the_object_is_reported(clean):
    plan, hand, lift = clean
    f = hand.fingers["ring"]
    q = plan.q.copy()
    # around mid-regrasp, the lift reversed: the tip goes about 10 mm into the object
    k = np.flatnonzero(np.abs(plan.t - 0.3) <= 0.02 + 1e-9)
    q[k[:, None], f.q_indices] -= 2 * lift[k]
    chk = recheck_plan(_with_q(plan, q))
    assert not chk.ok
    r = chk.regrasps[0]
    assert r.penetration_m > 1e-3, r
    assert 0.26 <= r.t_min_object_s <= 0.34
    assert any("penetrates the object" in p and "ring" in p for p in chk.problems)
    # nothing else is blamed
    assert chk.max_contact_error_m <= 1e-4 and chk.min_holding == 3


def test_a_finger_off_its_contact_is_reported(clean):
    plan, hand, _ = clean
    f = hand.fingers["middle"]  # it holds throughout
    q = plan.q.copy()
    q[40, f.q_indices[1]] += 0.05  # 50 mrad at one joint: a few mm at the tip
    chk = recheck_plan(_with_q(plan, q))
    assert not chk.ok
    assert chk.contact_error_finger == "middle"
    assert chk.t_max_contact_error_s == pytest.approx(plan.t[40])
    assert 1e-3 < chk.max_contact_error_m < 1e-2
    assert any("middle" in p and "from its contact" in p for p in chk.problems)


def test_joint_limits_and_holding_count_are_reported(clean):
    plan, hand, _ = clean
    f = hand.fingers["middle"]
    q = plan.q.copy()
    q[5, f.q_indices[0]] = f.upper[0] + 0.1
    bad = _with_q(plan, q)
    # the thumb also lets go for 0.1 s while the ring is in the air: two fingers hold
    thumb = bad.phases["thumb"][0]
    bad.phases["thumb"] = [
        ContactPhase("thumb", 0.0, 0.2, thumb.p_object, thumb.n_object),
        ContactPhase("thumb", 0.3, T_END, thumb.p_object, thumb.n_object),
    ]
    chk = recheck_plan(bad)
    assert not chk.ok
    (v,) = chk.joint_limit_violations
    assert v.joint == f.joint_names[0] and v.excess_rad == pytest.approx(0.1)
    assert v.t_s == pytest.approx(plan.t[5])
    assert chk.min_holding == 2 and 0.2 < chk.t_min_holding_s < 0.3
    assert any("thumb" in p and "0.300" in p for p in chk.problems)  # the gap
    assert any("only 2 fingers hold" in p for p in chk.problems)


def test_bad_arguments_name_themselves(clean, tmp_path):
    plan, _, _ = clean
    path = tmp_path / "plan.json"
    plan.save(path)
    with pytest.raises(InputError, match=r"plan.*is a (str|PosixPath).*Plan\.load"):
        recheck_plan(str(path))  # a path, not the plan it holds
    with pytest.raises(InputError, match="plan"):
        recheck_plan(path)
    with pytest.raises(ValueError, match="max_step_rad"):
        recheck_plan(plan, max_step_rad=0.0)
    bad = _with_q(plan, plan.q[:, :-1])
    with pytest.raises(ValueError, match="plan.q"):
        recheck_plan(bad)
    bad = copy.deepcopy(plan)
    bad.hand["urdf"] = "/nonexistent/hand.urdf"
    with pytest.raises(ModelFileError, match="nonexistent"):
        recheck_plan(bad)
    bad = copy.deepcopy(plan)
    bad.hand["fingers"]["index"]["joints"] = ["no_such_joint"]
    with pytest.raises(InputError, match="no_such_joint"):
        recheck_plan(bad)


def test_holding_fingers_that_touch_are_reported(clean):
    plan, hand, _ = clean
    q = plan.q.copy()
    k = np.flatnonzero(plan.t >= 0.55 - 1e-9)  # after the regrasp: every finger holds
    q[k, hand.fingers["middle"].q_indices[0]] += 0.3  # abduct the middle into the index
    chk = recheck_plan(_with_q(plan, q))
    assert not chk.ok
    assert chk.regrasps[0].min_finger_distance_m > 0.0  # the regrasp itself is clean
    assert chk.min_finger_distance_samples_m < 0.0
    assert set(chk.finger_pair_samples) == {"index", "middle"}
    assert chk.t_min_finger_samples_s >= 0.55 - 1e-9
    assert any(p.startswith("index and middle touch at t=") for p in chk.problems)


def test_every_finger_against_the_object_at_every_sample(clean):
    """The smallest finger-object distance over the plan's samples is Coal's exact
    minimum over every finger geometry and sample (the holding fingertips touch the
    object); a holding finger flexed into the object at one sample is reported, with
    its geometry and time, though no regrasp moves it."""
    import coal
    import pinocchio as pin

    plan, hand, _ = clean
    chk = recheck_plan(plan)
    model, geom = hand.model, hand.collision_model
    data, gdata = model.createData(), pin.GeometryData(geom)
    pts = coal.StdVec_Vec3s()
    pts.extend([np.asarray(v, float) for v in plan.object["vertices"]])
    obj = coal.Convex.convexHull(pts, False, None)
    poses = plan.poses()
    best = np.inf
    for k in range(plan.t.size):
        pin.updateGeometryPlacements(model, data, geom, gdata, plan.q[k])
        tf = coal.Transform3s(poses[k][:3, :3], poses[k][:3, 3])
        for g, o in enumerate(geom.geometryObjects):
            if int(o.parentJoint) == 0:
                continue  # the palm: checked against the object on its own
            M = gdata.oMg[g]
            d = coal.distance(
                o.geometry,
                coal.Transform3s(M.rotation, M.translation),
                obj,
                tf,
                coal.DistanceRequest(),
                coal.DistanceResult(),
            )
            best = min(best, d)
    assert chk.min_object_distance_samples_m == pytest.approx(best, abs=1e-9)
    assert abs(chk.min_object_distance_samples_m) <= 1e-4  # the fingertips touch
    f = hand.fingers["middle"]  # it holds throughout
    q = plan.q.copy()
    q[40, f.q_indices[1]] += 0.3  # flexed into the object at one sample
    bad = recheck_plan(_with_q(plan, q))
    assert not bad.ok and bad.min_object_distance_samples_m < -1e-3
    assert bad.t_min_object_samples_s == pytest.approx(plan.t[40])
    assert bad.object_geometry_samples.startswith("middle")
    assert any(
        p.startswith(f"the finger geometry {bad.object_geometry_samples!r} enters the object")
        for p in bad.problems
    )


def test_the_object_against_the_palm(clean):
    """The smallest object-palm distance is Coal's at the plan's own poses (the same as
    palm_clearance's), and an object moved into the palm is reported."""
    from regrasp_pin.model.clearance import palm_clearance
    from regrasp_pin.model.objects import object_from_params

    plan, hand, _ = clean
    chk = recheck_plan(plan)
    obj = object_from_params(plan.object["kind"], plan.object["params"])
    expected = palm_clearance(hand, obj, plan.poses())
    assert chk.min_palm_distance_m > 0.01
    assert chk.min_palm_distance_m == pytest.approx(float(expected.min()), abs=1e-9)
    assert chk.t_min_palm_s == pytest.approx(float(plan.t[int(np.argmin(expected))]))
    palm = next(o for o in hand.collision_model.geometryObjects if int(o.parentJoint) == 0)
    moved = copy.deepcopy(plan)
    moved.T_palm_object[-5:, :3] = palm.placement.translation  # the object's centre there
    bad = recheck_plan(moved)
    assert not bad.ok and bad.min_palm_distance_m < -0.005
    assert any("enters the hand's fixed geometry" in p for p in bad.problems)
    assert bad.t_min_palm_s >= plan.t[-5] - 1e-12


def _with_idle_little(plan: Plan, q: np.ndarray | None = None) -> Plan:
    """The plan with the little finger (idle, no phase in the hand-made plan) in an idle
    phase, optionally with the configurations ``q``."""
    out = _with_q(plan, plan.q if q is None else q)
    out.phases["little"] = [IdlePhase("little", float(plan.t[0]), float(plan.t[-1]))]
    return out


def test_an_idle_finger_is_checked_against_the_object(clean):
    """An idle phase is re-checked like a moving one, finger against object with Coal:
    at rest the little finger is as far from the object as the planner's own clearance
    (model/clearance, the other pipeline) says; bent into the object, it is reported."""
    plan, hand, _ = clean
    f = hand.fingers["little"]
    obj, T = plan.load_object(), plan.poses()
    clearance = LinkClearance(hand, "little", obj, include_tip=True)
    chk = recheck_plan(_with_idle_little(plan))
    assert chk.ok, chk.problems
    (idle,) = chk.idles
    assert (idle.finger, idle.t_start, idle.t_end) == ("little", plan.t[0], plan.t[-1])
    at_samples = clearance(plan.q, T)
    assert 0.0 < idle.min_object_distance_m <= at_samples.min() + 1e-9
    assert idle.min_object_distance_m == pytest.approx(at_samples.min(), abs=1e-4)

    # the fingertip pulled 80 % of the way to the object's centre: into the object
    tip = f.fk(plan.q[0, f.q_indices])
    bent = f.ik((tip + 0.8 * (T[0][:3, 3] - tip))[None], plan.q[0, f.q_indices]).q[0]
    q = plan.q.copy()
    q[:, f.q_indices] = bent
    inside = clearance(q, T)
    assert inside.min() < -1e-3  # the premise: the other pipeline sees it inside
    chk = recheck_plan(_with_idle_little(plan, q))
    assert not chk.ok
    assert chk.idles[0].min_object_distance_m == pytest.approx(inside.min(), abs=5e-4)
    assert any("little (idle at 0.000 s) penetrates the object" in p for p in chk.problems)


@pytest.mark.parametrize("share", [0.999, 1.5])
def test_a_joint_faster_than_its_velocity_limit_is_reported(clean, share):
    """The idle little finger's first joint steps between two samples at ``share`` of
    its URDF velocity limit (the motion between samples is linear, so that is its
    speed): over the limit, that joint, its finger, when and how fast are reported;
    under it, nothing."""
    plan, hand, _ = clean
    f = hand.fingers["little"]
    k, j = 30, f.q_indices[0]
    limit = float(hand.model.velocityLimit[j])  # revolute joints: idx_v == idx_q
    q = plan.q.copy()
    step = share * limit * (plan.t[k + 1] - plan.t[k])
    q[k + 1 :, j] += step if q[k, j] + step <= f.upper[0] else -step
    chk = recheck_plan(_with_idle_little(plan, q))
    if share < 1.0:
        assert chk.ok, chk.problems
        assert chk.joint_speed_violations == ()
        return
    assert not chk.ok
    (v,) = chk.joint_speed_violations
    assert (v.joint, v.finger, v.t_s) == (f.joint_names[0], "little", plan.t[k])
    assert v.speed_rad_s == pytest.approx(share * limit, rel=1e-9)
    assert v.limit_rad_s == limit
    assert any(f"joint {v.joint} (little) moves at" in p for p in chk.problems)


def test_exact_min_is_the_minimum_with_few_evaluations():
    """With a loose bound and a tighter one, the exact minimum is found, at its first
    entry in bound order, evaluating few entries."""
    from regrasp_pin.verify.plan_check import _exact_min

    rng = np.random.default_rng(0)
    value = rng.uniform(0.0, 1.0, (400, 50))
    value[123, 7] = value[321, 9] = -0.05  # a tie: either entry is the minimum
    loose = value - rng.uniform(0.0, 0.5, value.shape)
    tight = value - rng.uniform(0.0, 0.01, value.shape)
    seen = []

    def exact(k, j):
        seen.append((k, j))
        return value[k, j]

    d, (k, j) = _exact_min(loose, exact, lambda idx: tight.ravel()[idx])
    assert d == -0.05 and (k, j) in {(123, 7), (321, 9)}
    assert len(seen) < 0.01 * value.size
    seen.clear()
    d, (k, j) = _exact_min(loose, exact)  # the loose bound alone: more calls
    assert d == -0.05 and (k, j) in {(123, 7), (321, 9)}
    assert len(seen) > 100


def test_force_closure_of_the_held_contacts_is_checked_given_mu(clean, tmp_path):
    """With ``mu``, the contacts held at once must be in force closure: while the ring
    is in the air the thumb, index and middle hold, and the weakest epsilon is theirs
    (the planner's own ferrari_canny_epsilon of those contacts, to rounding); without
    friction point contacts cannot hold, which is reported with the time and the
    fingers. Without ``mu``, given or recorded in the plan, nothing is checked."""
    plan, _, _ = clean
    loaded = Plan.load(plan.save(tmp_path / "plan.json"))
    chk = recheck_plan(loaded, mu=0.8)
    assert chk.ok, chk.problems
    assert chk.closure_fingers == ("index", "middle", "thumb")
    assert LIFT[0] < chk.t_min_closure_s < LIFT[1]
    held = [loaded.phases[n][0] for n in chk.closure_fingers]
    radius = float(np.max(np.linalg.norm(np.asarray(loaded.object["vertices"]), axis=1)))
    expected = ferrari_canny_epsilon(
        np.array([c.p_object for c in held]),
        np.array([c.n_object for c in held]),
        0.8,
        torque_scale_m=radius,
    )
    assert expected > 1e-3
    assert chk.min_closure_epsilon == pytest.approx(expected, abs=1e-12)
    frictionless = recheck_plan(loaded, mu=0.0)
    assert not frictionless.ok and frictionless.min_closure_epsilon == 0.0
    # every hold is 0 then: the first, all four fingers holding, is reported
    assert frictionless.t_min_closure_s < LIFT[0]
    assert any(
        "not in force closure" in p and "index, middle, ring, thumb" in p
        for p in frictionless.problems
    )
    assert recheck_plan(loaded).min_closure_epsilon is None  # the plan records no mu
    # a plan that records its mu is checked with it, and keeps it through the file
    loaded.mu = 0.8
    again = Plan.load(loaded.save(tmp_path / "with_mu.json"))
    assert again.mu == 0.8
    assert recheck_plan(again).min_closure_epsilon == chk.min_closure_epsilon
    assert not recheck_plan(again, mu=0.0).ok  # the argument overrides it
    with pytest.raises(InputError, match="mu"):
        recheck_plan(loaded, mu=-0.1)


def test_a_plan_for_soft_fingertips_is_checked_with_its_torsion(clean, tmp_path):
    """A plan records the torsional friction it was made for; the re-check reads it
    through the file: two fingers may then hold (a soft pinch can), and force closure is
    judged with the spins. Here the thumb also lets go while the ring is in the air:
    the index and middle press the same way and are not in force closure, torsion or
    not, which the problem names with the torsion; an explicit ``min_holding`` or
    ``torsion_m`` overrides the plan's, and a negative one is refused by name."""
    plan, _, _ = clean
    soft = copy.deepcopy(plan)
    soft.mu, soft.torsion_m = 0.8, 0.001
    thumb = soft.phases["thumb"][0]
    soft.phases["thumb"] = [
        ContactPhase("thumb", 0.0, 0.2, thumb.p_object, thumb.n_object),
        ContactPhase("thumb", 0.3, T_END, thumb.p_object, thumb.n_object),
    ]
    loaded = Plan.load(soft.save(tmp_path / "soft.json"))
    assert loaded.torsion_m == 0.001
    assert Plan.load(plan.save(tmp_path / "point.json")).torsion_m == 0.0
    chk = recheck_plan(loaded)
    assert chk.min_holding == 2
    assert not any("only 2 fingers hold" in p for p in chk.problems)
    assert chk.closure_fingers == ("index", "middle")
    assert chk.min_closure_epsilon == 0.0
    assert any("not in force closure" in p and "torsion 1 mm" in p for p in chk.problems)
    strict = recheck_plan(loaded, min_holding=3)
    assert any("only 2 fingers hold" in p for p in strict.problems)
    # the held sets of the plan as made (three fingers) hold better with the spins
    whole = Plan.load(plan.save(tmp_path / "whole.json"))
    whole.mu = 0.8
    point = recheck_plan(whole)
    spun = recheck_plan(whole, torsion_m=0.001)
    assert point.ok and spun.ok, (point.problems, spun.problems)
    assert spun.min_closure_epsilon > point.min_closure_epsilon
    with pytest.raises(InputError, match="torsion_m"):
        recheck_plan(whole, torsion_m=-0.001)
    with pytest.raises(InputError, match="torsion_m"):
        Plan.from_dict({**whole.to_dict(), "torsion_m": -1.0})


def test_the_recheck_epsilon_is_the_planners_and_zero_where_no_grasp_holds():
    """The re-check's own wrench model gives the planner's epsilon on random contact
    sets (to rounding, whatever their order), with point contacts and with soft ones
    (torsional friction, never less); two antipodal point contacts, or contacts on one
    face, are never in force closure (0), two antipodal soft ones are."""
    rng = np.random.default_rng(12)
    for _ in range(20):
        k = int(rng.integers(3, 6))
        n = rng.normal(size=(k, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        p = -0.02 * n + rng.normal(scale=0.003, size=(k, 3))  # roughly on a sphere
        mu = float(rng.uniform(0.3, 1.0))
        mine = closure_epsilon(p, n, mu, 0.03)
        assert mine == pytest.approx(
            ferrari_canny_epsilon(p, n, mu, torque_scale_m=0.03), abs=1e-12
        )
        order = rng.permutation(k)
        assert closure_epsilon(p[order], n[order], mu, 0.03) == pytest.approx(mine, abs=1e-12)
        soft = closure_epsilon(p, n, mu, 0.03, 0.001)  # soft fingertips too
        assert soft == pytest.approx(
            ferrari_canny_epsilon(p, n, mu, torque_scale_m=0.03, torsion_m=0.001), abs=1e-12
        )
        assert soft >= mine - 1e-12
    z = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    assert closure_epsilon(0.02 * z, z, 0.8, 0.03) == 0.0
    pinch = closure_epsilon(0.02 * z, z, 0.8, 0.03, 0.001)  # a soft pinch holds
    assert pinch == pytest.approx(
        ferrari_canny_epsilon(0.02 * z, z, 0.8, torque_scale_m=0.03, torsion_m=0.001), abs=1e-12
    )
    assert pinch > 1e-3
    face = np.array([[0.01, 0.0, 0.02], [-0.01, 0.01, 0.02], [0.0, -0.01, 0.02]])
    assert closure_epsilon(face, np.tile([0.0, 0.0, 1.0], (3, 1)), 0.8, 0.03) == 0.0
