"""The intervals in which a finger cannot let go (regrasp_pin.grasp.necessity)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from regrasp_pin.exceptions import ContactError, FailureKind, PlanningError
from regrasp_pin.grasp.initial import Grasp
from regrasp_pin.grasp.manifold import Manifold
from regrasp_pin.grasp.necessity import (
    MustHold,
    closure_possible_with,
    closure_possible_without,
    first_infeasibility,
    must_hold,
)
from regrasp_pin.grasp.quality import ferrari_canny_epsilon, is_force_closure
from regrasp_pin.model.objects import Box
from regrasp_pin.planning.planner import plan_manipulation

MU = 0.8


def _manifold(name: str, usable: np.ndarray, times: np.ndarray) -> Manifold:
    """A manifold whose ``usable(0.0)`` is ``usable`` ``(T, N)`` (margin 0.1 rad there)."""
    n_t, n = usable.shape
    margin = np.where(usable, 0.1, -0.1)
    return Manifold(
        finger=name,
        times_s=times,
        q=np.zeros((n_t, n, 1)),
        reachable=np.ones((n_t, n), bool),
        inside=usable.copy(),
        margin_rad=margin,
        pad_ok=np.ones((n_t, n), bool),
        lower=np.array([-1.0]),
        upper=np.array([1.0]),
        T_palm_object=np.tile(np.eye(4), (n_t, 1, 1)),
    )


@pytest.fixture(scope="module")
def box():
    obj = Box((0.04, 0.06, 0.05))
    return obj, obj.sample_surface(0.005)


def test_one_face_is_never_closure_and_opposite_faces_with_friction_are(box):
    obj, sample = box
    times = np.linspace(0.0, 1.0, 3)
    top = sample.normals[:, 2] > 0.99
    bottom = sample.normals[:, 2] < -0.99
    only_top = np.tile(top, (3, 1))
    both = np.tile(top | bottom, (3, 1))
    both[0] = top  # at t=0 the others reach the top only
    mans = {
        "a": _manifold("a", np.ones((3, len(sample)), bool), times),
        "b": _manifold("b", only_top, times),
        "c": _manifold("c", both, times),
        "d": _manifold("d", both, times),
    }
    # without "a": the others push on the top only at t=0, squeeze top and bottom later
    assert closure_possible_without(mans, sample, obj, "a", MU).tolist() == [False, True, True]
    # two fingers never hold (no torque about the line through their contacts)
    del mans["d"]
    assert not closure_possible_without(mans, sample, obj, "a", MU).any()
    # a squeeze between two opposite faces with friction is in force closure (exact check)
    i_top = np.flatnonzero(top)[:3]
    i_bot = np.flatnonzero(bottom)[:3]
    ii = np.r_[i_top, i_bot]
    assert ferrari_canny_epsilon(sample.points[ii], sample.normals[ii], MU) > 0


def test_bound_holds_for_every_grasp_of_the_other_fingers(box):
    """Where some grasp of the others (one contact each, exact epsilon) is in force
    closure, the bound must say so: it may only be looser, never tighter."""
    obj, sample = box
    rng = np.random.default_rng(3)
    n_t = 12
    times = np.linspace(0.0, 1.1, n_t)
    mans = {}
    for name in ("thumb", "index", "middle", "ring"):
        faces = rng.choice(6, size=3, replace=False)
        near = np.isin(sample.face_ids, faces)
        mans[name] = _manifold(name, near[None, :] & (rng.random((n_t, len(sample))) < 0.3), times)
    free = closure_possible_without(mans, sample, obj, "thumb", MU)
    found_closure = 0
    for k in range(n_t):
        for _ in range(60):
            ii = [
                rng.choice(np.flatnonzero(mans[n].usable(0.0)[k]))
                for n in ("index", "middle", "ring")
            ]
            if ferrari_canny_epsilon(sample.points[ii], sample.normals[ii], MU) > 0:
                found_closure += 1
                assert free[k], f"time {k}: a grasp without the thumb exists"
    assert found_closure > 0  # the test exercised the bound


def test_with_soft_fingertips_two_fingers_may_hold_and_the_bound_stays_an_upper_bound(box):
    """With torsional friction the proof counts two fingers as enough (a soft pinch
    between the top and bottom faces holds: exact test), still finds no grasp on one
    face, and is never tighter than a soft grasp of the others that exists (random
    pinches of two fingers on random faces, the planner's soft epsilon)."""
    obj, sample = box
    torsion = 0.001
    times = np.linspace(0.0, 1.0, 3)
    top = sample.normals[:, 2] > 0.99
    bottom = sample.normals[:, 2] < -0.99
    mans = {
        "a": _manifold("a", np.ones((3, len(sample)), bool), times),
        "b": _manifold("b", np.tile(top, (3, 1)), times),
        "c": _manifold("c", np.tile(top | bottom, (3, 1)), times),
    }
    assert not closure_possible_without(mans, sample, obj, "a", MU).any()
    soft = closure_possible_without(mans, sample, obj, "a", MU, torsion_m=torsion)
    assert soft.all()
    pinch = np.r_[np.flatnonzero(top)[0], np.flatnonzero(bottom)[0]]
    p, n = sample.points[pinch], sample.normals[pinch]
    assert is_force_closure(p, n, MU, torque_scale_m=obj.radius_m, torsion_m=torsion)
    mans["c"] = _manifold("c", np.tile(top, (3, 1)), times)  # both on the top
    assert not closure_possible_without(mans, sample, obj, "a", MU, torsion_m=torsion).any()
    rng = np.random.default_rng(5)
    found = 0
    for _ in range(40):
        faces = [rng.choice(6, size=2, replace=False) for _ in range(2)]
        mans = {"a": mans["a"]}
        for name, f in zip(("b", "c"), faces, strict=True):
            near = np.isin(sample.face_ids, f) & (rng.random(len(sample)) < 0.3)
            mans[name] = _manifold(name, np.tile(near, (3, 1)), times)
        free = closure_possible_without(mans, sample, obj, "a", MU, torsion_m=torsion)
        for _ in range(20):
            ii = [rng.choice(np.flatnonzero(mans[x].usable(0.0)[0])) for x in ("b", "c")]
            if (
                ferrari_canny_epsilon(sample.points[ii], sample.normals[ii], MU, torsion_m=torsion)
                > 0
            ):
                found += 1
                assert free[0], "a soft pinch of the others exists"
    assert found > 0  # the test exercised the bound


def test_closure_possible_with_tests_the_one_more_contact_one_face_at_a_time(box):
    """Two contacts on the top face, and a finger that reaches two opposite side faces:
    both side faces' corners together would span with the top (the bound before, all
    faces at once), but the one more contact lies on one face, and neither side face
    with the top does; no usable point puts the three in force closure (exact test)."""
    obj, sample = box
    top = np.flatnonzero(sample.normals[:, 2] > 0.99)
    sides = (sample.normals[:, 0] > 0.99) | (sample.normals[:, 0] < -0.99)
    fixed = sample.points[top[[0, -1]]], sample.normals[top[[0, -1]]]
    m = _manifold("a", sides[None], np.array([0.0]))
    assert not closure_possible_with(*fixed, m, sample, obj, MU, np.array([0]))
    for q in np.flatnonzero(sides):
        three = np.vstack([fixed[0], sample.points[q]]), np.vstack([fixed[1], sample.normals[q]])
        assert not is_force_closure(*three, MU, torque_scale_m=obj.radius_m)
    # with the bottom face in reach too, the bottom with the top could
    reach = sides | (sample.normals[:, 2] < -0.99)
    m = _manifold("a", reach[None], np.array([0.0]))
    assert closure_possible_with(*fixed, m, sample, obj, MU, np.array([0]))


def test_closure_possible_with_one_more_contact_is_an_upper_bound(box):
    """closure_possible_with: where fixed contacts plus one usable contact of a finger
    (exact epsilon, the planner's test) are in force closure at a time, the bound says
    so at that time; two contacts on the top face plus a finger that reaches only the
    top face never are (one face pushes one way), and with the bottom face in reach at
    one time they could be, at that time only."""
    obj, sample = box
    rng = np.random.default_rng(5)
    times = np.linspace(0.0, 1.0, 4)
    top = np.flatnonzero(sample.normals[:, 2] > 0.99)
    bottom = np.flatnonzero(sample.normals[:, 2] < -0.99)
    fixed = sample.points[top[[0, -1]]], sample.normals[top[[0, -1]]]
    only_top = np.zeros((4, len(sample)), bool)
    only_top[:, top] = True
    assert not closure_possible_with(
        *fixed, _manifold("a", only_top, times), sample, obj, MU, np.arange(4)
    )
    reach = only_top.copy()
    reach[2, bottom] = True
    m = _manifold("a", reach, times)
    assert [closure_possible_with(*fixed, m, sample, obj, MU, np.array([k])) for k in range(4)] == [
        False, False, True, False,
    ]  # fmt: skip
    assert not closure_possible_with(*fixed, m, sample, obj, MU, np.array([], int))
    # the bound against exact grasps: random fixed pairs and a random usable set
    found = 0
    for _ in range(30):
        two = rng.choice(len(sample), size=2, replace=False)
        usable = rng.random((1, len(sample))) < 0.2
        m = _manifold("b", usable, times[:1])
        bound = closure_possible_with(
            sample.points[two], sample.normals[two], m, sample, obj, MU, np.array([0])
        )
        for q in np.flatnonzero(usable[0])[:40]:
            ii = [*two, q]
            if is_force_closure(
                sample.points[ii], sample.normals[ii], MU, torque_scale_m=obj.radius_m
            ):
                found += 1
                assert bound, (two, q)
    assert found > 0  # the test exercised the bound


def test_runs_lasting_contacts_and_first_infeasibility(box):
    obj, sample = box
    n_t = 10
    times = np.linspace(0.0, 0.9, n_t)
    n = len(sample)
    top = sample.normals[:, 2] > 0.99
    # one other finger (on the top face only): the thumb can never let go
    other = _manifold("index", np.tile(top, (n_t, 1)), times)
    thumb_usable = np.zeros((n_t, n), bool)
    thumb_usable[0:5, 0] = True  # point 0: usable at times 0..4
    thumb_usable[3:10, 1] = True  # point 1: at times 3..9
    thumb = _manifold("thumb", thumb_usable, times)
    runs = must_hold({"thumb": thumb, "index": other}, sample, obj, MU, ["thumb"])
    assert [(r.finger, r.k_from, r.k_to) for r in runs] == [("thumb", 0, n_t - 1)]
    run = runs[0]
    assert run.t_from_s == 0.0 and run.t_to_s == pytest.approx(0.9)
    assert not run.possible  # neither point lasts the whole run
    assert first_infeasibility(runs) is run
    # a shorter run that point 0 lasts through: feasible from point 0, not from point 1
    short = MustHold("thumb", 0, 3, 0.0, 0.3, thumb_usable[0:4].all(axis=0))
    assert short.possible
    assert first_infeasibility([short], {"thumb": 0}) is None
    assert first_infeasibility([short], {"thumb": 1}) is short
    # a later run is judged on any contact, not on the starting one
    later = MustHold("thumb", 4, 9, 0.4, 0.9, thumb_usable[4:10].all(axis=0))
    assert first_infeasibility([later], {"thumb": 0}) is None


@pytest.fixture(scope="module")
def three_fingers():
    """A neighbour scenario (five-finger hand, hexagon turned 100 deg about the thumb's
    contact) planned with the thumb, index and middle only, nobody joining: without
    any one of them two fingers remain, never in force closure."""
    from regrasp_pin.suite import build_scenario, neighbour_specs

    spec = next(s for s in neighbour_specs() if s.name == "five_finger-hexagon-+100deg-20dps")
    scen = build_scenario(spec)
    params = replace(scen.params, fingers=("thumb", "index", "middle"), release=False)
    return scen, params


def test_planner_refuses_a_grasp_that_cannot_last(three_fingers):
    scen, params = three_fingers
    keep = params.fingers
    g = scen.grasp
    grasp = Grasp(
        points_object={n: g.points_object[n] for n in keep},
        normals_object={n: g.normals_object[n] for n in keep},
        q={n: g.q[n] for n in keep},
        indices={n: g.indices[n] for n in keep},
        epsilon=g.epsilon,
    )
    with pytest.raises(PlanningError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=grasp, params=params)
    e = err.value
    assert e.kind == FailureKind.INFEASIBLE
    assert e.finger in keep and e.time_s == scen.motion.t_start
    # the run is the whole motion, its last sample included (a plan holds there too);
    # the contact leaves before its end
    assert e.required == pytest.approx(scen.motion.duration_s, abs=1e-9)
    assert 0.0 <= e.measured <= e.required
    assert e.partial is not None and e.attempts == ()
    # the partial plan says what the plan spent before the proof (as a full plan does)
    stages = e.partial.summary["stage_s"]
    assert {"manifolds", "must hold", "initial grasp", "tracking"} <= set(stages)
    assert "regrasps" not in stages and all(v >= 0.0 for v in stages.values())


def test_planner_grasp_search_says_when_no_contact_lasts(three_fingers):
    scen, params = three_fingers
    with pytest.raises(ContactError) as err:
        plan_manipulation(scen.hand, scen.obj, scen.motion, params=params)
    e = err.value
    assert e.kind == FailureKind.INFEASIBLE
    assert e.finger in params.fingers
    assert e.measured <= e.required
    assert e.required > scen.motion.duration_s - params.dt_s - params.manifold_dt_s - 1e-9
