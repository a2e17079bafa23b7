"""The scenario suite: deterministic balanced specs, exact rebuilds, and the summary's counts.

Only fast checks here (a build or two); the suite itself runs in ``bench/suite.py``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections import Counter

import numpy as np
import pytest
from conftest import assert_close
from scipy.spatial.transform import Rotation

import regrasp_pin.suite
from regrasp_pin import ferrari_canny_epsilon, make_scenario
from regrasp_pin.exceptions import (
    Attempt,
    ContactError,
    FailureKind,
    InputError,
    ModelFileError,
    UnknownNameError,
)
from regrasp_pin.scenarios import setup_pose
from regrasp_pin.suite import (
    MOTION_KINDS,
    OBJECT_KINDS,
    MotionSpec,
    ObjectSpec,
    ScenarioResult,
    ScenarioSpec,
    build_scenario,
    generate_specs,
    neighbour_specs,
    run_scenario,
    summarize,
    time_spent,
)
from regrasp_pin.suite.build import finger_clearance
from regrasp_pin.suite.report import paired_change, rate_difference, rate_interval


@pytest.fixture(scope="module")
def specs():
    return generate_specs(36, seed=0)


def test_specs_are_deterministic_and_prefix_stable(specs):
    assert generate_specs(36, seed=0) == specs
    assert generate_specs(7, seed=0) == specs[:7]
    other = generate_specs(36, seed=1)
    assert all(a != b for a, b in zip(specs, other, strict=True))
    assert len({s.name for s in specs + other}) == 72


def test_every_prefix_is_balanced(specs):
    for k in range(1, len(specs) + 1):
        for attr, values in (
            (lambda s: s.hand, ("five_finger", "allegro")),
            (lambda s: s.object.kind, OBJECT_KINDS),
            (lambda s: s.motion.kind, MOTION_KINDS),
        ):
            count = Counter(attr(s) for s in specs[:k])
            assert max(count[v] for v in values) - min(count[v] for v in values) <= 1, k
    # every 18 consecutive specs (aligned) hold each hand x object x motion once
    for block in (specs[:18], specs[18:36]):
        combos = {(s.hand, s.object.kind, s.motion.kind) for s in block}
        assert len(combos) == 18


def test_spec_values_are_in_range(specs):
    signs = set()
    for s in specs:
        m = s.motion
        assert 60.0 <= abs(m.angle_deg) <= 270.0 and 10.0 <= m.rate_deg_s <= 45.0
        signs.add(np.sign(m.angle_deg))
        axis = np.asarray(m.axis_object)
        tilt = np.degrees(np.arccos(np.clip(axis[2] / np.linalg.norm(axis), -1, 1)))
        assert tilt <= 10.0 + 1e-3
        if m.kind == "contact-axis":
            assert axis.tolist() == [0.0, 0.0, 1.0]
        drift = np.linalg.norm(m.translation_m)
        if m.kind == "rotate-translate":
            assert 0.003 - 1e-5 <= drift <= 0.010 + 1e-5
        else:
            assert drift == 0.0
        # the grasp search: about 2 deg per manifold step, over 120 deg at most
        assert 0.05 <= s.grasp_dt_s <= 0.2
        horizon = m.duration_s if s.grasp_horizon_s is None else s.grasp_horizon_s
        assert horizon <= m.duration_s and horizon * m.rate_deg_s <= 120.0 + 0.1
        assert np.linalg.norm(s.position_offset_m) <= 0.003 + 1e-5
        assert np.degrees(np.linalg.norm(s.rotation_offset_rotvec)) <= 15.0
        # sizes within +-10 % (plus rounding) of the hand's canonical objects
        r0 = {"five_finger": 0.033, "allegro": 0.0455}[s.hand]
        o = s.object
        if o.kind == "prism":
            assert 3 <= o.n_sides <= 8
            assert 0.9 * r0 - 1e-4 <= o.circumradius_m <= 1.1 * r0 + 1e-4
            assert 0.036 - 1e-4 <= o.height_m <= 0.044 + 1e-4
        elif o.kind == "mesh":
            assert 12 <= o.n_points <= 20
            assert_close(o.size_m, [2 * r0, 2 * r0, 0.04], atol=1e-4, rtol=0.1, what="extents")
    assert signs == {-1.0, 1.0}
    assert {s.object.n_sides for s in specs if s.object.kind == "prism"} != {6}


def test_specs_round_trip_through_json(specs):
    for s in specs[:6] + neighbour_specs()[:2]:
        back = ScenarioSpec.from_dict(json.loads(json.dumps(s.to_dict())))
        assert back == s
        assert back.to_dict() == s.to_dict()


def test_bad_specs_name_the_field():
    with pytest.raises(InputError, match="object.n_sides"):
        ObjectSpec("prism", circumradius_m=0.03, height_m=0.04)
    with pytest.raises(InputError, match="object.size_m"):
        ObjectSpec("prism", n_sides=6, circumradius_m=0.03, height_m=0.04, size_m=(1, 1, 1))
    with pytest.raises(UnknownNameError):
        ObjectSpec("sphere")
    d = generate_specs(1)[0].to_dict()
    with pytest.raises(InputError, match="unknown field"):
        ScenarioSpec.from_dict({**d, "colour": "red"})
    with pytest.raises(InputError, match="motion.angle_deg"):
        ScenarioSpec.from_dict({**d, "motion": {**d["motion"], "angle_deg": 0.0}})
    sheared = np.eye(4)
    sheared[0, 1] = 0.1
    for bad in ([1.0] * 15, sheared.ravel().tolist(), [float("nan")] * 16):
        with pytest.raises(InputError, match="base_pose"):
            ScenarioSpec.from_dict({**d, "base_pose": bad})


def test_random_meshes_are_seeded_convex_objects():
    spec = next(s for s in generate_specs(6) if s.object.kind == "mesh")
    a, b = spec.object.build(), spec.object.build()
    assert np.array_equal(a.vertices, b.vertices)
    assert 4 <= len(a.vertices) <= spec.object.n_points
    extent = a.vertices.max(axis=0) - a.vertices.min(axis=0)
    assert np.all(extent <= np.asarray(spec.object.size_m) * 1.05 + 1e-12)
    # convex and centred at its centre of mass: every vertex inside every face plane
    assert np.all(a.vertices @ a.normals.T - a.offsets <= 1e-12)


def test_neighbours_cover_the_grid():
    specs = neighbour_specs()
    combos = {(s.hand, s.motion.angle_deg, s.motion.rate_deg_s) for s in specs}
    assert len(specs) == len(combos) == 30
    assert {a for _, a, _ in combos} == {60.0, 100.0, 140.0, 180.0, -100.0}
    assert {r for _, _, r in combos} == {10.0, 20.0, 40.0}
    for s in specs:
        assert s.motion.kind == "contact-axis" and s.object.label == "prism6"
        assert s.position_offset_m == (0.0, 0.0, 0.0) == s.rotation_offset_rotvec


def test_a_neighbour_builds_the_same_scenario_as_make_scenario():
    spec = next(
        s
        for s in neighbour_specs()
        if s.hand == "five_finger" and s.motion.angle_deg == 60.0 and s.motion.rate_deg_s == 40
    )
    got = build_scenario(spec)
    want = make_scenario("five_finger", "hexagon", angle_deg=60.0, rate_deg_s=40.0)
    assert_close(got.obj.vertices, want.obj.vertices, atol=0.0, what="object")
    assert_close(got.motion.times_s, want.motion.times_s, atol=0.0, what="times")
    assert_close(got.motion.T_palm_object, want.motion.T_palm_object, atol=1e-12, what="poses")
    assert got.grasp.points_object.keys() == want.grasp.points_object.keys()
    for n in want.grasp.points_object:
        assert_close(got.grasp.points_object[n], want.grasp.points_object[n], atol=0.0, what=n)
        assert_close(got.grasp.q[n], want.grasp.q[n], atol=1e-12, what=n)
    assert got.params == want.params


def test_a_carried_base_pose_builds_the_scenario_of_the_hands_own():
    spec = next(s for s in neighbour_specs() if s.hand == "allegro")
    carried = dataclasses.replace(spec, base_pose=tuple(setup_pose("allegro").ravel()))
    a, b = build_scenario(spec), build_scenario(carried)
    assert np.array_equal(a.motion.T_palm_object, b.motion.T_palm_object)
    for n in a.grasp.points_object:
        assert np.array_equal(a.grasp.q[n], b.grasp.q[n])
    # and another pose is another scenario
    moved = np.reshape(carried.base_pose, (4, 4)).copy()
    moved[0, 3] += 0.002
    c = build_scenario(dataclasses.replace(spec, base_pose=tuple(moved.ravel())))
    assert_close(
        c.motion.T_palm_object[0, :3, 3] - a.motion.T_palm_object[0, :3, 3],
        np.array([0.002, 0.0, 0.0]),
        atol=1e-12,
        what="start",
    )


def test_a_built_spec_starts_in_force_closure_with_its_offsets():
    # a short tilted object-axis turn of a moved hexagon, with the fingers kept apart
    spec = ScenarioSpec(
        name="offsets",
        hand="five_finger",
        object=ObjectSpec("prism", n_sides=6, circumradius_m=0.033, height_m=0.041),
        motion=MotionSpec("object-axis", -80.0, 40.0, axis_object=(0.05, 0.0, 0.9987)),
        position_offset_m=(0.001, -0.0015, 0.0005),
        rotation_offset_rotvec=(0.0, 0.05, 0.02),
        grasp_dt_s=0.1,
        grasp_clearance_m=0.0,
    )
    scen = build_scenario(spec)
    g = scen.grasp
    names = list(g.points_object)
    eps = ferrari_canny_epsilon(
        np.array([g.points_object[n] for n in names]),
        np.array([g.normals_object[n] for n in names]),
        scen.params.mu,
        torque_scale_m=scen.obj.radius_m,
    )
    assert eps > 0.0
    # the object starts at the canonical pose moved by the spec's offsets
    T0 = scen.motion.T_palm_object[0]
    canonical = setup_pose(spec.hand)
    R_off = Rotation.from_rotvec(spec.rotation_offset_rotvec).as_matrix()
    assert_close(T0[:3, 3], canonical[:3, 3] + spec.position_offset_m, atol=1e-12, what="pos")
    assert_close(T0[:3, :3], R_off @ canonical[:3, :3], atol=1e-12, what="rotation")
    # an object-axis turn: the object's centre stays put, it turns by the angle
    centres = scen.motion.T_palm_object[:, :3, 3]
    assert_close(centres, np.broadcast_to(T0[:3, 3], centres.shape), atol=1e-12, what="centre")
    turn = Rotation.from_matrix(scen.motion.T_palm_object[-1, :3, :3] @ T0[:3, :3].T)
    assert turn.magnitude() == pytest.approx(np.radians(80.0))
    assert scen.motion.duration_s == pytest.approx(spec.motion.duration_s)
    # the contacts lie on the object's surface
    pts = np.array([g.points_object[n] for n in names])
    assert np.all(np.abs(scen.obj.signed_distance(pts)) <= 1e-9)


def _result(name, hand, obj, motion, ok, kind=None, stage=None, regrasp_ms=(), plan_s=1.0):
    return ScenarioResult(
        name=name,
        hand=hand,
        object_kind=obj,
        motion_kind=motion,
        ok=ok,
        failure_kind=kind,
        failed_stage=stage,
        regrasp_ms=list(regrasp_ms),
        n_regrasps=len(regrasp_ms),
        plan_s=plan_s,
        build_s=0.5,
        recheck_ok=True if ok else None,
    )


def test_summary_counts():
    results = [
        _result("a", "five_finger", "prism", "object-axis", True, regrasp_ms=[100, 200]),
        _result("b", "five_finger", "prism", "contact-axis", False, "velocity", "plan", [300]),
        _result("c", "five_finger", "box", "object-axis", False, "velocity", "plan"),
        _result("d", "allegro", "mesh", "rotate-translate", False, "no-candidate", "plan"),
        _result("e", "allegro", "mesh", "rotate-translate", True, regrasp_ms=[400]),
    ]
    results[-1].recheck_ok = False
    results[-1].recheck_problems = ["index penetrates the object by 1.000 mm"]
    text = summarize(results)
    assert "full plans: 2/5" in text
    rows = {ln.split()[0]: ln for ln in text.splitlines() if ln.startswith("  ")}
    assert rows["five_finger"].split()[1:] == ["1/2", "50%", "0/1", "0%", "-", "1/3", "33%"]
    assert rows["allegro"].split()[1:] == ["-", "-", "1/2", "50%", "1/2", "50%"]
    assert "1/2" in rows["object-axis"] and "0/1" in rows["contact-axis"]
    assert rows["velocity"].split()[1] == "2" and rows["no-candidate"].split()[1] == "1"
    assert "failures by kind: 3" in text
    assert "planning failures before any verified regrasp: 2/3" in text
    # per regrasp: 100, 200, 300, 400 ms -> median 250
    assert "planning time per regrasp: median 250 ms" in text
    assert "re-check of the full plans: 1/2 passed" in text
    assert "e: index penetrates" in text
    assert "proven to have no plan" not in text
    # a proven failure is counted apart: the others' rate leaves it out
    results.append(_result("f", "allegro", "box", "object-axis", False, "infeasible", "plan"))
    text = summarize(results)
    assert "full plans: 2/6" in text
    assert "proven to have no plan (kind infeasible): 1; full plans of the others: 2/5" in text


def test_time_spent_sums_where_a_suites_time_went():
    full = _result("a", "five_finger", "prism", "object-axis", True, plan_s=3.0)
    full.stage_s = {"manifolds": 0.5, "must hold": 0.25, "regrasps": 2.0}
    full.recheck_s = 0.7
    failed = _result("b", "allegro", "box", "object-axis", False, "velocity", "plan", plan_s=6.0)
    failed.stage_s = {"manifolds": 1.0, "must hold": 0.45, "regrasps": 4.0}
    failed.build_s = 2.5  # of it 1.5 s the backup's grasp search (run_scenario adds it)
    failed.backups = [{"outcome": "velocity", "choose_s": 1.5, "plan_s": 2.0}]
    older = _result("c", "allegro", "mesh", "contact-axis", False, "no-candidate", "plan")
    skipped = [
        _result(n, "allegro", "box", "object-axis", False, "no-candidate", "grasp") for n in "de"
    ]
    text = time_spent([full, failed, older], skipped)
    lines = text.splitlines()
    # builds 0.5 + 2.5 + 0.5 and skipped 2 x 0.5; planning 3 + 6 + 1; re-checks 0.7
    assert lines[0] == "time spent, summed over the scenarios: 15.2 s"
    assert lines[1].split()[:3] == ["builds", "4.5", "s"]
    assert "the scenarios' 3.5 s, of it the backups' grasp searches 1.5 s" in lines[1]
    assert "the 2 specs skipped 1.0 s" in lines[1]
    assert lines[2].split()[:3] == ["planning", "10.0", "s"]
    assert "full plans 3.0 s, failures 7.0 s" in lines[2]
    # the searches: 10 - (0.5 + 1.0) - (0.25 + 0.45) - the backup's plan 2.0
    assert "manifolds 1.5 s and must-hold proofs 0.7 s" in lines[2]
    assert "the backups' plans 2.0 s, the searches 5.8 s; 1 without stage times" in lines[2]
    assert lines[3].split()[:3] == ["re-checks", "0.7", "s"]
    assert "1 full plans" in lines[3]
    assert time_spent([]).splitlines()[0] == "time spent, summed over the scenarios: 0.0 s"


def test_the_rate_interval_is_wilsons():
    """The Wilson score interval, from its closed form: (k + z^2/2 +- z sqrt(k (n - k) / n
    + z^2 / 4)) / (n + z^2), z the normal quantile of the level."""
    z = 1.959963984540054
    for k, n in [(42, 100), (0, 30), (30, 30), (7, 15)]:
        half = z * math.sqrt(k * (n - k) / n + z * z / 4)
        want = ((k + z * z / 2 - half) / (n + z * z), (k + z * z / 2 + half) / (n + z * z))
        assert rate_interval(k, n) == pytest.approx(want, abs=1e-9)
    assert rate_interval(np.int64(42), np.int64(100)) == rate_interval(42, 100)
    lo, hi = rate_interval(42, 100)
    assert 0.32 < lo < 0.42 < hi < 0.53  # about +-10 points at 100 scenarios
    for k, n, arg in [(1, 0, "n"), (-1, 10, "k"), (11, 10, "k"), (1.0, 10, "k"), (True, 1, "k")]:
        with pytest.raises(InputError, match=f"^{arg}"):
            rate_interval(k, n)
    for bad in (0.0, 1.0, 95, "0.95"):
        with pytest.raises(InputError, match="^confidence"):
            rate_interval(4, 10, confidence=bad)


def test_the_summary_gives_the_rates_interval():
    results = [_result(str(i), "allegro", "box", "object-axis", i < 7) for i in range(15)]
    lo, hi = rate_interval(7, 15)
    first = summarize(results).splitlines()[0]
    assert first.endswith(f"full plans: 7/15  47% (95% interval {lo:.0%}-{hi:.0%})")


def test_a_paired_change_is_a_sign_test_of_won_against_lost():
    """Exact two-sided sign test: all of 6 changes one way happens with probability
    2 / 2^6 when each goes either way at random; 5 of 5 with 2 / 2^5."""

    def runs(before, after):
        old = [_result(str(i), "allegro", "box", "object-axis", ok) for i, ok in enumerate(before)]
        new = [_result(str(i), "allegro", "box", "object-axis", ok) for i, ok in enumerate(after)]
        return new, old

    new, old = runs([False] * 6 + [True] * 4, [True] * 10)
    change = paired_change(new, old)
    assert (change.n, change.won, change.lost) == (10, 6, 0)
    assert change.p_value == pytest.approx(2 / 2**6)
    assert "won 6, lost 0 of 10" in change.line() and "more than the noise" in change.line()
    new, old = runs([False] * 5, [True] * 5)
    assert paired_change(new, old).p_value == pytest.approx(2 / 2**5)
    assert "within the noise" in paired_change(new, old).line()
    # wins and losses that cancel, no change at all, and scenarios in one run only
    new, old = runs([True, False, True], [False, True, True])
    assert paired_change(new, old).p_value == pytest.approx(1.0)
    new, old = runs([True, False], [True, False])
    assert paired_change(new, old).p_value == 1.0 and paired_change(new, old).won == 0
    assert paired_change(new, old[:1]).n == 1


def test_a_rate_difference_is_fishers_exact_test():
    """Runs over different scenarios: 4 of 4 against 0 of 4 is, with the margins fixed,
    one of C(8, 4) = 70 equally likely tables, and as extreme as its mirror: p = 2 / 70;
    equal rates give p = 1."""

    def run(tag, oks):
        return [
            _result(f"{tag}{i}", "allegro", "box", "object-axis", ok) for i, ok in enumerate(oks)
        ]

    diff = rate_difference(run("a", [True] * 4), run("b", [False] * 4))
    assert (diff.k, diff.n, diff.k_other, diff.n_other) == (4, 4, 0, 4)
    assert diff.p_value == pytest.approx(2 / 70)
    assert "4/4 100% against 0/4 0%" in diff.line() and "more than chance" in diff.line()
    same = rate_difference(run("a", [True, False] * 5), run("b", [False, True] * 5))
    assert same.p_value == pytest.approx(1.0) and "beyond chance" in same.line()
    for a, b in (([], run("b", [True])), (run("a", [True]), [])):
        with pytest.raises(InputError, match="results|other"):
            rate_difference(a, b)


def test_summary_gives_how_far_distance_failures_missed():
    """required - measured of each distance failure [mm]: 0.1, 0.5 and 9 -> min, median,
    max; another kind's numbers (a velocity) are not distances and get none."""
    results = []
    for name, measured, required in [("a", -1e-4, 0.0), ("b", -5.5e-4, -5e-5), ("c", -6e-3, 3e-3)]:
        r = _result(name, "allegro", "box", "object-axis", False, "object-clearance", "plan")
        r.measured, r.required = measured, required
        results.append(r)
    fast = _result("d", "allegro", "box", "object-axis", False, "velocity", "plan")
    fast.measured, fast.required = 9.0, 7.0
    none = _result("e", "allegro", "box", "object-axis", False, "object-clearance", "plan")
    text = summarize([*results, fast, none])
    rows = {ln.split()[0]: ln for ln in text.splitlines() if ln.startswith("  ")}
    assert "missed by 0.10-9.00 mm, median 0.50 mm" in rows["object-clearance"]
    assert "missed by" not in rows["velocity"]


def test_summary_names_the_fingers_that_finger_collisions_came_near():
    """Per finger-collision failure, the finger its attempts of that kind name most
    often (ties by name), counted over the failures; attempts of other kinds, and
    failures whose attempts name none, are not counted; other kinds get no such part."""
    named = [["ring", "middle", "ring"], ["middle", "index"], ["thumb"], []]
    results = []
    for i, others in enumerate(named):
        r = _result(f"f{i}", "allegro", "box", "object-axis", False, "finger-collision", "plan")
        r.attempts = [Attempt(FailureKind.FINGER_COLLISION, other=o).to_dict() for o in others] + [
            Attempt(FailureKind.VELOCITY, other="little").to_dict()
        ]
        results.append(r)
    fast = _result("v", "allegro", "box", "object-axis", False, "velocity", "plan")
    fast.attempts = [Attempt(FailureKind.VELOCITY, other="ring").to_dict()]
    rows = {
        ln.split()[0]: ln for ln in summarize([*results, fast]).splitlines() if ln.startswith("  ")
    }
    assert "; near index 1, ring 1, thumb 1" in rows["finger-collision"]
    assert "near" not in rows["velocity"]


def test_results_round_trip_through_json():
    r = _result("a", "allegro", "box", "object-axis", False, "velocity", "plan", [1.5])
    r.time_s, r.min_clearance_m = 2.5, float("inf")
    d = json.loads(json.dumps(r.to_dict()))
    assert d["min_clearance_m"] is None
    back = ScenarioResult.from_dict(d)
    assert back.failure_kind == "velocity" and back.regrasp_ms == [1.5]


def test_a_failure_records_the_finger_it_came_near():
    from regrasp_pin.suite.run import _record_failure

    r = _result("a", "allegro", "box", "object-axis", False, None, None, [])
    err = ContactError(
        "two fingers too close",
        finger="ring",
        other="middle",
        kind=FailureKind.FINGER_COLLISION,
        measured=0.0019,
        required=0.002,
    )
    _record_failure(r, err, "grasp")
    assert (r.failure_kind, r.finger, r.other, r.failed_stage) == (
        "finger-collision",
        "ring",
        "middle",
        "grasp",
    )
    back = ScenarioResult.from_dict(json.loads(json.dumps(r.to_dict())))
    assert back.other == "middle"


def test_grasp_clearance_keeps_the_initial_fingers_apart():
    # make_scenario's grasp for this neighbour has the index inside the middle finger;
    # asking for clearance gives another grasp whose fingers are apart, or none
    spec = dataclasses.replace(
        next(
            s
            for s in neighbour_specs()
            if s.hand == "five_finger" and s.motion.angle_deg == 60.0 and s.motion.rate_deg_s == 40
        ),
        grasp_clearance_m=0.0,
    )
    try:
        scen = build_scenario(spec)
    except ContactError as exc:
        assert exc.kind is FailureKind.NO_CANDIDATE
        return
    clearance = finger_clearance(scen.hand, scen.obj, scen.motion, tuple(scen.grasp.q), 0.0)
    assert clearance(scen.grasp.q) > 0.0


def test_run_scenario_records_a_missing_grasp_as_data():
    # a 6 mm cube is far too small for the five-finger hand: no initial grasp
    spec = ScenarioSpec(
        name="tiny",
        hand="five_finger",
        object=ObjectSpec("box", size_m=(0.006, 0.006, 0.006)),
        motion=MotionSpec("object-axis", 60.0, 45.0),
        grasp_dt_s=0.2,
    )
    r = run_scenario(spec)
    assert not r.ok and r.failed_stage == "grasp" and r.failure_kind == "no-candidate"
    assert r.failure and r.plan_s is None and r.build_s > 0.0
    d = json.loads(json.dumps(r.to_dict()))
    assert ScenarioSpec.from_dict(d["spec"]) == spec
    assert "failures by kind: 1" in summarize([r])


def test_every_exported_name_imports():
    for name in regrasp_pin.suite.__all__:
        assert getattr(regrasp_pin.suite, name) is not None, name


def _hand_file(tmp_path) -> str:
    """A JSON hand file for the bundled five-finger URDF (any URDF would do)."""
    from regrasp_pin.model.hand import FIVE_FINGER_TIPS, five_finger_urdf_path

    path = tmp_path / "my_hand.json"
    spec = {"urdf": str(five_finger_urdf_path()), "fingers": FIVE_FINGER_TIPS, "tip_radius": 0.008}
    path.write_text(json.dumps(spec))
    return str(path)


def test_hand_files_join_the_suite(tmp_path):
    """Specs for a hand file alternate with the bundled hands, are named after its stem,
    and round-trip through JSON; a missing file or an unknown name is refused."""
    hand = _hand_file(tmp_path)
    mixed = generate_specs(6, 0, hands=("five_finger", hand))
    assert [s.hand for s in mixed] == ["five_finger", hand] * 3
    assert all("-my_hand-" in s.name for s in mixed[1::2])
    assert ScenarioSpec.from_dict(json.loads(json.dumps(mixed[1].to_dict()))) == mixed[1]
    neighbours = neighbour_specs(hands=(hand,))
    assert len(neighbours) == 15 and all(s.name.startswith("my_hand-") for s in neighbours)
    # the hand file's canonical pose travels with its specs (a process that builds one
    # does not search it again); a bundled hand's is a constant, not carried
    pose = tuple(setup_pose(hand).ravel())
    assert all(s.base_pose == pose for s in [*mixed[1::2], *neighbours])
    assert all(s.base_pose is None for s in mixed[::2])
    with pytest.raises(UnknownNameError):
        generate_specs(2, 0, hands=("shadow",))
    with pytest.raises(InputError):
        generate_specs(2, 0, hands=())
    missing = dataclasses.replace(mixed[1], hand=str(tmp_path / "gone.json"))
    with pytest.raises(ModelFileError, match="no such hand file"):
        build_scenario(missing)


def test_a_hand_files_time_law_reaches_its_scenarios(tmp_path):
    """A suite scenario of a hand file plans its regrasps by the file's
    ``scenario.time_law``; a bundled hand's by the default law."""
    from regrasp_pin.model.hand import FIVE_FINGER_TIPS, five_finger_urdf_path

    path = tmp_path / "slow_hand.json"
    spec = {"urdf": str(five_finger_urdf_path()), "fingers": FIVE_FINGER_TIPS, "tip_radius": 0.008}
    path.write_text(json.dumps({**spec, "scenario": {"time_law": "cruise"}}))
    own = neighbour_specs(hands=(str(path),))[0]
    assert build_scenario(own).params.regrasp.time_law == "cruise"
    bundled = neighbour_specs(hands=("five_finger",))[0]
    assert build_scenario(bundled).params.regrasp.time_law == "minimum-jerk"
