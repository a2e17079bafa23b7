"""Backing up to another initial grasp (regrasp_pin.backups.plan_scenario).

The planner is replaced by a script of outcomes (a failure at a finger, with the
partial plan it would leave, or a full plan), so that each rule is checked on its own
and at no planning cost; the grasps are the real grasp search's
(``Scenario.grasp_search``). Scene: the canonical scenario, the five-finger hand
turning the hexagonal prism 60 deg at 40 deg/s about the thumb's contact (the thumb is
the pivot).
"""

from __future__ import annotations

import dataclasses
import time
from types import SimpleNamespace

import numpy as np
import pytest

from regrasp_pin import backups, make_scenario
from regrasp_pin.backups import plan_scenario
from regrasp_pin.exceptions import ContactError, FailureKind, InputError, PlanningError
from regrasp_pin.plan import ContactPhase, IdlePhase, Plan, ReleasePhase
from regrasp_pin.planning.planner import ManipulationPlan
from regrasp_pin.scenarios import GraspSearch, contacts_held_through

STEPS = 1600  # the scenario's search budget (PlannerParams.max_steps)


@pytest.fixture(scope="module")
def scen():
    s = make_scenario("five_finger", "hexagon", angle_deg=60, rate_deg_s=40)
    assert s.params.max_steps == STEPS and s.grasp_search.pivot == "thumb"
    return s


def _plan(phases: dict, steps: int) -> Plan:
    return Plan(
        hand={},
        object={},
        t=np.array([0.0, 1.0]),
        q=np.zeros((2, 1)),
        T_palm_object=np.tile([0.0, 0, 0, 0, 0, 0, 1], (2, 1)),
        phases=phases,
        summary={"search_steps": steps},
    )


def fails(finger, kind, *, steps=100, time_s=1.0, released=False, at_start=False):
    """A scripted failure at ``finger`` after ``steps`` search steps: every finger of
    the grasp holds its start contact in the partial plan (``finger`` lets go of it
    afterwards if ``released``), or, ``at_start``, nothing is planned: every finger is
    idle, as the planner leaves a plan that fails at t = 0."""

    def fail(grasp):
        phases = {
            n: [ContactPhase(n, 0.0, 0.5, grasp.points_object[n], grasp.normals_object[n])]
            for n in grasp.points_object
        }
        if at_start:
            phases = {n: [IdlePhase(n, 0.0, 1.0)] for n in grasp.points_object}
        if released:
            phases[finger].append(ReleasePhase(finger, 0.5, 1.0, grasp.points_object[finger], 0.0))
        return PlanningError(
            "scripted", finger=finger, time_s=time_s, kind=kind, partial=_plan(phases, steps)
        )

    return fail


class Scripted:
    """``plan_manipulation`` replaced by outcomes in turn: a failure (``fails``), an
    exception to raise as it is, or ``"ok"`` (a full plan)."""

    def __init__(self, monkeypatch, *outcomes, setup_s=0.0):
        self.outcomes, self.calls, self.raised, self.setups = list(outcomes), [], [], []
        monkeypatch.setattr(backups, "plan_manipulation", self)
        monkeypatch.setattr(backups, "plan_setup", self.setup)
        self.setup_s = setup_s

    def setup(self, hand, obj, motion, params):
        """A stand-in for plan_setup that takes ``setup_s``."""
        time.sleep(self.setup_s)
        built = SimpleNamespace(motion=motion)
        self.setups.append(built)
        return built

    def __call__(self, hand, obj, motion, *, grasp, params, progress=None, setup=None):
        self.calls.append(
            SimpleNamespace(
                motion=motion, grasp=grasp, params=params, progress=progress, setup=setup
            )
        )
        out = self.outcomes.pop(0)
        if out == "ok":
            return ManipulationPlan(_plan({}, 0), [], grasp, {}, None, {})
        exc = out if isinstance(out, Exception) else out(grasp)
        self.raised.append(exc)
        raise exc


def _two_ring_backups(monkeypatch) -> Scripted:
    """Two failures at the ring finger, then a full plan."""
    return Scripted(
        monkeypatch,
        fails("ring", FailureKind.NO_CANDIDATE),
        fails("ring", FailureKind.VELOCITY),
        "ok",
    )


def _apart(a, b):
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)))


def test_a_failure_on_a_start_contact_plans_again_with_the_finger_elsewhere(scen, monkeypatch):
    planner = Scripted(monkeypatch, fails("index", FailureKind.FINGER_COLLISION, steps=300), "ok")
    result = plan_scenario(scen)
    first, again = planner.calls
    assert first.grasp is scen.grasp and first.params.max_steps == STEPS
    # the grasp search of the scenario, asked to keep the pivot and avoid the start
    thumb, p0 = scen.grasp.indices["thumb"], scen.grasp.points_object["index"]
    expected = scen.grasp_search.choose(
        scen.hand, scen.obj, keep={"thumb": thumb}, avoid={"index": p0[None]}
    )
    assert again.grasp.indices == expected.indices and again.grasp.epsilon > 0.0
    assert again.grasp.indices["thumb"] == thumb and again.motion is scen.motion
    assert _apart(again.grasp.points_object["index"], p0) > 2 * scen.hand.finger("index").tip_radius
    # the steps the first plan left, and the full plan with its start and its record
    assert again.params.max_steps == STEPS - 300
    assert result.grasp is again.grasp
    [b] = result.plan.summary["grasp_backups"]
    assert (b["after"], b["finger"], b["how"], b["outcome"], b["time_s"]) == (
        "finger-collision",
        "index",
        "elsewhere",
        "ok",
        None,
    )
    assert b["avoid_m"] == p0.tolist() and b["choose_s"] > 0.0


def test_each_backup_avoids_every_start_before_and_the_first_failure_stands(scen, monkeypatch):
    planner = Scripted(
        monkeypatch,
        fails("ring", FailureKind.NO_CANDIDATE, steps=100),
        fails("ring", FailureKind.IK_UNREACHABLE, steps=200, time_s=2.0),
        fails("ring", FailureKind.VELOCITY, steps=50, time_s=0.5),
    )
    with pytest.raises(PlanningError) as failed:
        plan_scenario(scen, grasp_backups=2)
    assert failed.value is planner.raised[0]
    starts = [c.grasp.points_object["ring"] for c in planner.calls]
    radius = scen.hand.finger("ring").tip_radius
    assert _apart(starts[2], starts[0]) > 2 * radius and _apart(starts[2], starts[1]) > 2 * radius
    assert [c.params.max_steps for c in planner.calls] == [STEPS, STEPS - 100, STEPS - 300]
    record = failed.value.partial.summary["grasp_backups"]
    assert [(b["after"], b["outcome"], b["time_s"]) for b in record] == [
        ("no-candidate", "ik-unreachable", 2.0),
        ("ik-unreachable", "velocity", 0.5),
    ]
    assert [b["avoid_m"] for b in record] == [starts[0].tolist(), starts[1].tolist()]


def test_a_failure_before_anything_was_planned_backs_up(scen, monkeypatch):
    # failing at t = 0, the planner leaves every finger idle: none has moved, so the
    # failing one is still on its start contact
    planner = Scripted(
        monkeypatch, fails("index", FailureKind.NO_CANDIDATE, time_s=0.0, at_start=True), "ok"
    )
    result = plan_scenario(scen)
    first, again = planner.calls
    p0 = first.grasp.points_object["index"]
    assert _apart(again.grasp.points_object["index"], p0) > 2 * scen.hand.finger("index").tip_radius
    [b] = result.plan.summary["grasp_backups"]
    assert (b["after"], b["finger"], b["how"], b["outcome"]) == (
        "no-candidate",
        "index",
        "elsewhere",
        "ok",
    )


def _asking(monkeypatch, refuse=lambda keep, avoid: False):
    """``GraspSearch.choose`` recorded (its ``keep`` and ``avoid``), raising a
    ``no-candidate`` ContactError where ``refuse(keep, avoid)``."""
    asked = []
    choose = GraspSearch.choose

    def spy(self, hand, obj, *, keep=None, avoid=None):
        asked.append((keep, avoid))
        if refuse(keep, avoid):
            raise ContactError("refused on purpose", kind=FailureKind.NO_CANDIDATE)
        return choose(self, hand, obj, keep=keep, avoid=avoid)

    monkeypatch.setattr(GraspSearch, "choose", spy)
    return asked


def test_a_backup_without_a_grasp_ends_the_backups(scen, monkeypatch):
    # the second backup, away from both starts, has no grasp: the backups end there
    asked = _asking(monkeypatch, lambda keep, avoid: len(avoid["ring"]) == 2)
    planner = Scripted(
        monkeypatch,
        fails("ring", FailureKind.NO_CANDIDATE),
        fails("ring", FailureKind.NO_CANDIDATE),
        "ok",
    )
    with pytest.raises(PlanningError) as failed:
        plan_scenario(scen, grasp_backups=3)
    assert len(planner.calls) == 2 and len(asked) == 2
    outcomes = [b["outcome"] for b in failed.value.partial.summary["grasp_backups"]]
    assert outcomes == ["no-candidate", "no-grasp:no-candidate"]


def test_without_a_pivot_no_contact_is_kept(scen, monkeypatch):
    asked = _asking(monkeypatch)
    free = dataclasses.replace(
        scen, grasp_search=dataclasses.replace(scen.grasp_search, pivot=None)
    )
    Scripted(monkeypatch, fails("thumb", FailureKind.NO_CANDIDATE), "ok")
    result = plan_scenario(free)
    [(keep, avoid)] = asked
    assert keep is None and list(avoid) == ["thumb"]
    assert result.plan.summary["grasp_backups"][0]["finger"] == "thumb"


@pytest.mark.parametrize(
    ("failure", "backups_allowed", "searched"),
    [
        pytest.param(fails("thumb", FailureKind.NO_CANDIDATE), 1, True, id="the pivot"),
        pytest.param(fails("index", FailureKind.INFEASIBLE), 1, True, id="a proof"),
        pytest.param(
            fails("index", FailureKind.NO_CANDIDATE, released=True), 1, True, id="it let go"
        ),
        pytest.param(fails("little", FailureKind.NO_CANDIDATE), 1, True, id="not a start"),
        pytest.param(fails("index", FailureKind.BUDGET, steps=STEPS), 1, True, id="no steps"),
        pytest.param(fails("index", FailureKind.NO_CANDIDATE), 0, True, id="none asked"),
        pytest.param(fails("index", FailureKind.NO_CANDIDATE), 1, False, id="grasp given"),
    ],
)
def test_no_backup_where_the_start_did_not_lead_there(
    scen, monkeypatch, failure, backups_allowed, searched
):
    s = scen if searched else dataclasses.replace(scen, grasp_search=None)
    planner = Scripted(monkeypatch, failure, "ok")
    with pytest.raises(PlanningError) as failed:
        plan_scenario(s, grasp_backups=backups_allowed)
    assert failed.value is planner.raised[0] and len(planner.calls) == 1
    assert failed.value.partial.summary["grasp_backups"] == []


def test_a_finger_the_others_do_not_hold_without_starts_where_it_holds_to_the_end(
    scen, monkeypatch
):
    # after force-closure, the middle's start is asked to be its best contact held to
    # the end that is more than two tip radii from where it was (the grasp search then
    # refuses, on purpose); the index has no such contact: no search, no backup
    asked = _asking(monkeypatch, lambda keep, avoid: True)
    points = scen.obj.sample_surface(0.002).points

    def far_held(finger):
        held = contacts_held_through(
            scen.hand, scen.obj, scen.motion, finger, contact=scen.params.contact
        )
        p0, radius = scen.grasp.points_object[finger], scen.hand.finger(finger).tip_radius
        return [int(i) for i in held if _apart(points[i], p0) > 2 * radius]

    def backed_up(finger):
        asked.clear()
        planner = Scripted(monkeypatch, fails(finger, FailureKind.FORCE_CLOSURE), "ok")
        with pytest.raises(PlanningError) as failed:
            plan_scenario(scen)
        assert len(planner.calls) == 1
        [b] = failed.value.partial.summary["grasp_backups"]
        assert (b["after"], b["finger"], b["how"]) == ("force-closure", finger, "held-through")
        return b["outcome"]

    far = far_held("middle")
    assert far, "the scene's middle has a contact held to the end, away from its start"
    assert backed_up("middle") == "no-grasp:no-candidate"
    assert asked == [({"thumb": scen.grasp.indices["thumb"], "middle": far[0]}, None)]
    assert far_held("index") == [], "the scene's index has none"
    assert backed_up("index") == "none-held-through" and asked == []


def test_the_wall_clock_budget_is_shared(scen, monkeypatch):
    def slow(grasp):
        time.sleep(0.02)
        return fails("index", FailureKind.NO_CANDIDATE)(grasp)

    planner = Scripted(monkeypatch, slow, "ok")
    with pytest.raises(PlanningError) as failed:
        plan_scenario(scen, params=dataclasses.replace(scen.params, budget_s=0.01))
    assert len(planner.calls) == 1
    [b] = failed.value.partial.summary["grasp_backups"]
    assert b["outcome"] == "no-time" and b["plan_s"] == 0.0


def test_a_backup_gets_what_the_planning_left_of_the_wall_clock_budget(scen, monkeypatch):
    def slow(grasp):
        time.sleep(0.05)
        return fails("index", FailureKind.NO_CANDIDATE)(grasp)

    planner = Scripted(monkeypatch, slow, "ok", setup_s=0.03)
    params = dataclasses.replace(scen.params, budget_s=10.0)
    seen = []
    plan_scenario(scen, params=params, progress=seen.append)
    first, again = planner.calls
    # the setup built for both counts against the first plan's budget
    assert 9.0 < first.params.budget_s <= 10.0 - 0.03
    assert 9.0 < again.params.budget_s <= first.params.budget_s - 0.05
    assert first.progress is again.progress  # the caller's, for every plan


def test_the_caller_hears_of_each_backup_as_it_starts_planning(scen, monkeypatch):
    planner = _two_ring_backups(monkeypatch)
    heard = []
    plan_scenario(
        scen, grasp_backups=2, on_backup=lambda *a: heard.append((*a, len(planner.calls)))
    )
    # the finger and the kind backed up from, before each backup's plan (1 and 2 made)
    assert heard == [("ring", "no-candidate", 1), ("ring", "velocity", 2)]
    # a backup that finds no grasp does not plan: nothing to hear
    _asking(monkeypatch, lambda keep, avoid: True)
    Scripted(monkeypatch, fails("index", FailureKind.NO_CANDIDATE), "ok")
    heard.clear()
    with pytest.raises(PlanningError):
        plan_scenario(scen, on_backup=lambda *a: heard.append(a))
    assert heard == []


def test_an_unexpected_error_in_a_backup_is_its_outcome(scen, monkeypatch):
    planner = Scripted(
        monkeypatch, fails("index", FailureKind.NO_CANDIDATE), RuntimeError("broken on purpose")
    )
    with pytest.raises(PlanningError) as failed:
        plan_scenario(scen)
    assert failed.value is planner.raised[0] and len(planner.calls) == 2
    [b] = failed.value.partial.summary["grasp_backups"]
    assert b["outcome"] == "exception:RuntimeError: broken on purpose"


def test_the_plans_share_one_setup_built_for_the_scenario(scen, monkeypatch):
    planner = _two_ring_backups(monkeypatch)
    plan_scenario(scen, grasp_backups=2)
    [built] = planner.setups
    assert [c.setup for c in planner.calls] == [built] * 3
    assert len({id(c.grasp) for c in planner.calls}) == 3  # three grasps, one setup


def test_a_full_first_plan_lists_no_backup(scen, monkeypatch):
    planner = Scripted(monkeypatch, "ok")
    result = plan_scenario(scen)
    assert result.grasp is scen.grasp and len(planner.calls) == 1
    assert result.plan.summary["grasp_backups"] == []


@pytest.mark.parametrize("bad", [-1, 1.5, "2", None])
def test_bad_grasp_backups_name_the_argument(scen, bad):
    with pytest.raises(InputError, match="grasp_backups"):
        plan_scenario(scen, grasp_backups=bad)
