"""Backing up (regrasp_pin.planning.recovery): which neighbour takes a finger's room
(and when none is asked), and another finger going first at a backtrack."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from regrasp_pin import make_scenario
from regrasp_pin.backups import plan_scenario
from regrasp_pin.exceptions import FailureKind, PlanningError
from regrasp_pin.grasp.choice import NewContact
from regrasp_pin.grasp.holding import start_holding
from regrasp_pin.model.clearance import FingerClearance
from regrasp_pin.plan import RegraspPhase
from regrasp_pin.planning import recovery
from regrasp_pin.planning.advance import contenders as contenders_of
from regrasp_pin.planning.recovery import _room_taken, _signature
from regrasp_pin.planning.release import Release
from regrasp_pin.planning.search import LANDING_FINGER_CLEARANCE_M, SearchBudget
from regrasp_pin.planning.state import PlanState, Trigger
from regrasp_pin.suite.build import build_scenario
from regrasp_pin.suite.specs import neighbour_specs
from regrasp_pin.verify.plan_check import recheck_plan


@pytest.fixture(scope="module")
def crowded():
    """The demo scene at t = 0.5 s with the middle finger holding its grasp contact,
    and ring configurations whose links come within the landing clearance of the
    middle finger (Coal) or stay well clear of it."""
    scen = make_scenario("five_finger", "hexagon", angle_deg=100, rate_deg_s=20)
    hand, g, p = scen.hand, scen.grasp, scen.params
    grid = np.arange(0.0, scen.motion.t_end + 1e-9, p.dt_s)
    hold = start_holding(
        hand,
        scen.obj,
        scen.motion,
        grid,
        "middle",
        g.points_object["middle"],
        g.normals_object["middle"],
        g.q["middle"],
        0.0,
        p.contact,
    )
    ctx = SimpleNamespace(scene=scen, params=p, base_q=hand.neutral())
    state = SimpleNamespace(holding={"middle": hold}, released={})
    # the middle finger's configuration at the landing, from the hold's own IK
    t = 0.5
    q = hand.neutral()
    q[hand.finger("middle").q_indices] = hold.q_at(np.array([t]))[0]
    ring = hand.finger("ring")
    rng = np.random.default_rng(0)
    meet, clear = None, None
    gap = FingerClearance(hand, "ring", ["middle"])
    for q_ring in ring.lower + rng.random((400, ring.k)) * (ring.upper - ring.lower):
        q[ring.q_indices] = q_ring
        d = gap(q)
        if meet is None and d < LANDING_FINGER_CLEARANCE_M:
            meet = q_ring.copy()
        if clear is None and d > 0.005:
            clear = q_ring.copy()
    assert meet is not None and clear is not None
    return ctx, state, hold, meet, clear, t


def _wanted(p_object, q_arrive, t):
    return NewContact(
        finger="ring",
        index=0,
        p_object=np.asarray(p_object, float),
        n_object=np.array([0.0, 0.0, 1.0]),
        q_arrive=q_arrive,
        t_arrive_s=t,
        exit_time_s=t + 1.0,
        margin_rad=0.1,
        distance_from_P_m=0.02,
        epsilon=0.1,
        epsilon_with_P=0.1,
        quality_kept=True,
        n_candidates=1,
        rank=0,
    )


def _is_room(rooms, wanted, sep, wider):
    """The rooms of ``wanted`` (the ring's new contact), in order: contacts kept
    ``sep`` away with the ring's posture there, at its arrival, kept clear; then
    contacts kept ``wider`` away, without a posture."""
    posture, plain = rooms
    assert posture.point is wanted.p_object and posture.radius_m == sep
    assert posture.finger == "ring" and posture.t_s == wanted.t_arrive_s
    np.testing.assert_array_equal(posture.q_finger, wanted.q_arrive)
    assert plain.point is wanted.p_object and plain.finger is None
    assert plain.radius_m == pytest.approx(wider, abs=1e-12)


def test_a_neighbour_whose_contact_is_within_the_separation_takes_the_room(crowded):
    ctx, state, hold, _, clear, t = crowded
    sep = 0.017
    near = hold.p + np.array([0.01, 0.0, 0.0])  # 10 mm from the middle's contact
    wanted = _wanted(near, clear, t)
    _is_room(_room_taken(ctx, state, "ring", "middle", wanted, sep), wanted, sep, sep)


def test_a_neighbour_whose_links_meet_the_finger_takes_the_room_of_its_posture(crowded):
    """Contacts 30 mm apart, but the ring at the wanted contact would come within the
    landing clearance of the middle finger: the middle must leave the room, its finger
    clear of the ring standing at the wanted contact, or else land farther from it than
    its contact is now (by a tip radius)."""
    ctx, state, hold, meet, clear, t = crowded
    sep = 0.017
    far = hold.p + np.array([0.0, 0.03, 0.0])
    wanted = _wanted(far, meet, t)
    r = ctx.scene.hand.finger("ring").tip_radius
    _is_room(_room_taken(ctx, state, "ring", "middle", wanted, sep), wanted, sep, 0.03 + r)
    # not counting the links (a failure they cannot have caused), it leaves the room
    assert _room_taken(ctx, state, "ring", "middle", wanted, sep, False) is None
    # the same contact with the fingers apart leaves the room
    assert _room_taken(ctx, state, "ring", "middle", _wanted(far, clear, t), sep) is None


def test_no_neighbour_makes_room_for_a_finger_that_cannot_lift_off():
    """A force-closure failure: without the finger the others are not in force closure,
    so it never got to choose a contact, and room is not what it lacks (a neighbour
    moving to free it is _free_first's, with that as its test). No neighbour is asked to
    make room, and no search step is spent on it."""
    budget = SearchBudget.of(100)
    ctx = SimpleNamespace(budget=budget, tried=set())
    trig = Trigger(time_s=1.0, finger="thumb", reason="joint near its limit", lost_s=1.3)
    failure = PlanningError(
        "without it the others are not in force closure",
        finger="thumb",
        time_s=1.0,
        kind=FailureKind.FORCE_CLOSURE,
    )
    assert recovery._make_room(ctx, None, trig, [trig], [], failure) is None
    assert budget.steps == 0 and not ctx.tried


def _released(t_start: float, q_end: float) -> Release:
    times = np.array([t_start, t_start + 0.1, 1.0])
    q = np.array([[0.2, 0.3], [q_end, 0.3], [q_end, 0.3]])
    return Release("index", t_start, t_start + 0.1, 1.0, np.zeros(3), times, q, 0.004)


def _state(**released: Release) -> PlanState:
    return PlanState(
        holding={}, history={}, phases={}, regrasps=(), now=0.5, held_to_end={}, released=released
    )


def test_states_whose_let_go_fingers_differ_are_not_the_same_for_the_backtracking():
    # an option tried from one state is skipped from another only if they are the same:
    # a finger let go at another time, or parked elsewhere, makes another state
    same = _signature(_state(index=_released(0.2, 0.5)))
    assert _signature(_state(index=_released(0.2, 0.5))) == same
    assert _signature(_state(index=_released(0.3, 0.5))) != same
    assert _signature(_state(index=_released(0.2, 0.6))) != same
    assert _signature(_state()) != same
    ended = replace(_state(index=_released(0.2, 0.5)), ended=(_released(0.1, 0.4),))
    assert _signature(ended) != same


def test_a_backtrack_lets_another_finger_due_then_go_first(monkeypatch):
    """The demo's -100 deg neighbour at 40 deg/s: the little finger, joined on a side
    face that the turn carries out of its reach, cannot lift off at 1.87 s. Backing up
    to its regrasp at 1.47 s, the ring finger, due then too, regrasps first, and the plan
    goes on to the end (re-checked from the plan alone). Without that option the
    backtrack only lands the little finger elsewhere on that face, and the plan fails."""
    spec = next(s for s in neighbour_specs() if s.name == "five_finger-hexagon--100deg-40dps")
    scen = build_scenario(spec)
    plan = plan_scenario(scen)
    check = recheck_plan(plan.plan, mu=scen.params.mu)
    assert check.ok, check.problems
    ring = [p for p in plan.plan.phases["ring"] if isinstance(p, RegraspPhase)]
    assert any(p.t_start == pytest.approx(1.47) for p in ring)  # where the little went
    little = plan.plan.phases["little"]
    assert not any(isinstance(p, RegraspPhase) and p.t_start > 1.47 for p in little)
    monkeypatch.setattr(
        recovery, "contenders_of", lambda triggers, ctx: contenders_of(triggers, ctx)[:1]
    )
    with pytest.raises(PlanningError) as failed:
        plan_scenario(scen)
    assert failed.value.finger == "little" and failed.value.time_s == pytest.approx(1.87)
