"""Whole-hand manipulation by regrasping (the paper's test, section 3).

The object follows its motion ``T_palm_object(t)``. Every finger holds a contact fixed
in the object frame and follows it by IK; when a contact comes within the trigger
margin of a boundary plane (or stops being feasible), that finger regrasps -- lifts
off, travels around the object and lands on a new contact Q -- while the others keep
holding. One finger is in the air at a time.

Scheduling. Triggers are taken in time order; a hold that will be lost triggers at
least one regrasp duration before it is. A finger may lift off anywhere in its
window (:mod:`.planning.schedule`): from when it is free (no other finger in the air)
to the last time its contact is still held inside the joint limits. The preferred
start is ``lead_s`` before the trigger, earlier if the next finger's trigger would
otherwise fall inside the regrasp; other starts are tried earlier and later in turn.
For each start the search (:mod:`.planning.search`) tries new contacts Q and durations
until one regrasp verifies and the contact it lands on is held (followed by IK from the
landing) at least as long as the shortest regrasp takes, or to the end. When a finger
finds none, the planner backs up once per failure (at most ``max_backtracks`` times):
another finger due soon goes first; or a neighbour whose contact takes the room of the
finger's best new contact regrasps first, out of that room (now, or before one of the
last regrasps); or the previous regrasp is planned again to land before this finger's
window closes, or, if time was not the problem, to land elsewhere. Every search shares one budget
(``max_steps``, counted, not timed, so that it is the same on every machine); a failure
that could not be backed out of because the budget was gone is a ``budget`` failure
(its message names the failure). A hold that no regrasp can
follow is let go (:mod:`.planning.letgo`: a verified back-off, a ``release`` phase, if
the others are enough to go on taking turns (more than ``min_holding``) or hold in
force closure to the end; or a hand-over to an idle finger, a ``join`` phase).
Where the plan stands and the triggers that follow from it are in
:mod:`.planning.state`; the parameters in :mod:`.planning.params`.
A motion that cannot be achieved raises :class:`~.exceptions.PlanningError` with the
finger, the time, the kind of the failure, every attempt and the partial plan up to
that time; one that provably cannot be (a finger that cannot let go, no grasp without
it existing, for longer than its contact lasts: :mod:`~regrasp_pin.grasp.necessity`)
fails at once with kind ``infeasible``, before any search.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..exceptions import Attempt, ContactError, FailureKind, PlanningError
from ..grasp.holding import Holding, holding_q, holds_to_end, rest_configuration, start_holding
from ..grasp.initial import Grasp, initial_grasp
from ..grasp.manifold import Manifold, build_manifold
from ..grasp.quality import ferrari_canny_epsilon
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject, SurfaceSample
from ..model.scene import Scene
from ..plan import Plan, RegraspPhase
from .assembly import plan_until
from .feasibility import first_infeasibility, must_hold_runs, no_plan_exists
from .letgo import let_go
from .params import PlannerParams
from .regrasp import RegraspResult
from .schedule import (
    TIME_TOL_S,
    LiftOffWindow,
    held_until,
    lift_off_window,
    regrasp_chain,
    start_times,
)
from .search import Found, RegraspSearch, SearchBudget
from .state import (
    PlanContext,
    PlanState,
    Trigger,
    hold_ends,
    landing_hold,
    loss_reason,
    pending_triggers,
    q_hand_of,
)

__all__ = ["ManipulationPlan", "PlannerParams", "plan_manipulation"]

log = logging.getLogger(__name__)


@dataclass
class ManipulationPlan:
    """The result of :func:`plan_manipulation`.

    Attributes:
        plan: The plan file content (:class:`~regrasp_pin.plan.Plan`).
        regrasps: The verified regrasps, in time order.
        grasp: The initial grasp.
        manifolds: The joint-space manifolds per finger.
        sample: The surface sample.
        stage_s: Time spent per stage [s].
    """

    plan: Plan
    regrasps: list[RegraspResult]
    grasp: Grasp
    manifolds: dict[str, Manifold]
    sample: SurfaceSample
    stage_s: dict[str, float]


@dataclass(frozen=True)
class _Step:
    """A regrasp decision that can be revisited: the state before it and its trigger."""

    before: PlanState
    trig: Trigger
    triggers: list[Trigger]
    Q_object: np.ndarray
    excluded: tuple[np.ndarray, ...] = ()


def plan_manipulation(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    *,
    grasp: Grasp | None = None,
    params: PlannerParams | None = None,
    progress: Callable[[float], None] | None = None,
) -> ManipulationPlan:
    """Plan the whole hand over the whole motion.

    Args:
        hand: The hand.
        obj: The object.
        motion: The object's motion ``T_palm_object(t)``.
        grasp: Initial grasp; found by :func:`~regrasp_pin.grasp.initial.initial_grasp` if None.
        params: :class:`PlannerParams`.
        progress: Called with the planned time [s] as planning advances (e.g. to
            drive a progress bar).

    Returns:
        A :class:`ManipulationPlan`.

    Raises:
        InputError: a part of the wrong type, a motion that takes the object more than
            1 m from the palm (lengths in millimetres by mistake).
        ContactError: no initial grasp.
        PlanningError: the motion cannot be achieved; ``kind`` says why, ``attempts``
            holds every failed attempt of the last search and ``partial`` the plan up
            to the failure.
    """
    scene = Scene(hand, obj, motion)  # checks types and scale before any work
    params = params or PlannerParams()
    budget = SearchBudget.of(params.max_steps, params.budget_s)  # the whole call
    active = tuple(params.fingers) if params.fingers else hand.finger_names
    for name in active:
        hand.finger(name)  # raises UnknownNameError listing the valid names
    base_q = rest_configuration(
        hand, obj, motion, [n for n in hand.finger_names if n not in active]
    )
    stage: dict[str, float] = {}
    t0 = time.perf_counter()
    sample = obj.sample_surface(params.sample_spacing_m)
    n_m = max(int(round(motion.duration_s / params.manifold_dt_s)), 1) + 1
    m_times = np.linspace(motion.t_start, motion.t_end, n_m)
    manifolds = {
        name: build_manifold(hand.fingers[name], sample, motion, m_times, contact=params.contact)
        for name in active
    }
    stage["manifolds"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    every, runs = must_hold_runs(hand, obj, motion, sample, m_times, manifolds, params)
    stage["must hold"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if grasp is None:
        grasp = initial_grasp(
            hand, obj, manifolds, sample, contact=params.contact, mu=params.mu, must_hold=runs
        )
    stage["initial grasp"] = time.perf_counter() - t0

    grid = _time_grid(motion, params.dt_s)
    t0 = time.perf_counter()
    holding = {
        name: start_holding(
            hand,
            obj,
            motion,
            grid,
            name,
            grasp.points_object[name],
            grasp.normals_object[name],
            grasp.q[name],
            motion.t_start,
            params.contact,
        )
        for name in active
    }
    stage["tracking"] = time.perf_counter() - t0
    search = RegraspSearch(
        scene,
        every,
        sample,
        regrasp=params.regrasp,
        contact=params.contact,
        mu=params.mu,
        dt_s=params.dt_s,
        candidates=params.candidates,
        exit_tolerance_s=params.exit_tolerance_s,
    )
    ctx = PlanContext(
        scene,
        grid,
        params,
        active,
        search,
        budget,
        base_q,
        every,
    )
    state = PlanState(
        holding=holding,
        history={n: () for n in active},
        phases={n: () for n in active},
        regrasps=(),
        now=motion.t_start,
        held_to_end={},
    )
    infeasible = first_infeasibility(ctx, state, runs)
    if infeasible is not None:
        raise no_plan_exists(ctx, infeasible, state)
    t0 = time.perf_counter()
    steps: list[_Step] = []
    backtracks = 0
    while True:
        triggers = pending_triggers(ctx, state)
        contenders = _contenders(triggers, ctx)
        if not contenders:
            break
        trig = contenders[0]
        try:
            state = _advance(ctx, state, trig, triggers, steps)
        except PlanningError as exc:
            redone = None
            may_back_up = backtracks < params.max_backtracks
            if may_back_up:
                backtracks += 1
                redone = _another_first(ctx, state, contenders, triggers, steps)
                if redone is None:
                    redone = _make_room(ctx, state, trig, triggers, steps, exc)
                if redone is None and steps:
                    redone = _backtrack(ctx, steps, exc, state, trig)
            if redone is None:
                stage["regrasps"] = time.perf_counter() - t0
                when = exc.time_s if exc.time_s is not None else trig.time_s
                until = min(max(min(when, trig.time_s), state.now), motion.t_end)
                cut_short = may_back_up and ctx.budget.exhausted
                raise PlanningError(
                    (
                        f"the search budget ran out while backing up from a "
                        f"{exc.kind.value} failure: {exc.reason}"
                        if cut_short and exc.kind != FailureKind.BUDGET
                        else exc.reason
                    ),
                    finger=exc.finger or trig.finger,
                    time_s=when,
                    partial=plan_until(ctx, state, until),
                    kind=FailureKind.BUDGET if cut_short else exc.kind,
                    measured=exc.measured,
                    required=exc.required,
                    attempts=exc.attempts,
                ) from exc
            state = redone
        if progress is not None:
            progress(state.now)
    stage["regrasps"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    plan = plan_until(ctx, state, motion.t_end, final=True)
    stage["assembly"] = time.perf_counter() - t0
    plan.summary.update(
        {
            "regrasps": len(state.regrasps),
            "fingers_regrasped": sorted({r.finger for r in state.regrasps}),
            "initial_epsilon": grasp.epsilon,
            "held_to_end": dict(state.held_to_end),
            "released": {n: r.t_start for n, r in state.released.items()},
            "joined": {n: j.t_start for n, j in state.joined.items()},
            "backtracks": backtracks,
            "stage_s": stage,
        }
    )
    taking_part = {n: m for n, m in every.items() if n in manifolds or n in state.joined}
    return ManipulationPlan(plan, list(state.regrasps), grasp, taking_part, sample, stage)


def _time_grid(motion: ObjectMotion, dt_s: float) -> np.ndarray:
    grid = np.arange(motion.t_start, motion.t_end + TIME_TOL_S, dt_s)
    if grid[-1] < motion.t_end - TIME_TOL_S:
        grid = np.append(grid, motion.t_end)
    grid[-1] = min(grid[-1], motion.t_end)
    return grid


def _contenders(triggers: list[Trigger], ctx: PlanContext) -> list[Trigger]:
    """The fingers that may regrasp next, the first to go first: earliest deadline first.

    Among the fingers whose triggers fall within one regrasp (plus the lead) of the
    first trigger -- they cannot all wait for each other -- the one whose hold is
    lost first goes first (ties: the earlier trigger, then the name).
    """
    if not triggers:
        return []
    p = ctx.params
    horizon = triggers[0].time_s + p.regrasp.duration_s + p.lead_s
    contenders = [e for e in triggers if e.time_s <= horizon + TIME_TOL_S]
    return sorted(contenders, key=lambda e: (round(e.lost_s, 9), round(e.time_s, 9), e.finger))


def _window(
    ctx: PlanContext, state: PlanState, trig: Trigger, triggers: list[Trigger]
) -> tuple[LiftOffWindow, str]:
    """The finger's lift-off window, with its preferred start and why."""
    p = ctx.params
    name, t_trig = trig.finger, trig.time_s
    h = state.holding[name]
    D = p.regrasp.duration_s
    win = lift_off_window(
        name,
        h.track,
        t_trig,
        earliest_s=max(state.now, h.t_from),
        lead_s=p.lead_s,
        contact=p.contact,
        lost_s=trig.lost_s,
    )
    why = f"at t={t_trig:.3f} s; lift-off {p.lead_s:.3f} s before"
    others = [e for e in triggers if e.finger != name]
    if others:
        t_next, next_name = others[0].time_s, others[0].finger
        if t_next - p.lead_s < win.preferred_s + D:
            preferred = max(t_next - p.lead_s - D, win.earliest_s)
            win = replace(win, preferred_s=min(preferred, win.latest_s))
            why += f", moved earlier so that {next_name} (trigger t={t_next:.3f} s) can follow"
    return win, why


def _advance(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[_Step],
    *,
    end_by_s: float | None = None,
    exclude: list[np.ndarray] | None = None,
    reserved: tuple[tuple[np.ndarray, float], ...] = (),
) -> PlanState:
    """The state after ``trig``: its finger held to the end, or one verified regrasp
    (landing by ``end_by_s``, away from the ``exclude`` points and out of the
    ``reserved`` room: see :meth:`RegraspSearch.find`)."""
    p, hand, motion = ctx.params, ctx.scene.hand, ctx.scene.motion
    D = p.regrasp.duration_s
    name, t_trig, reason = trig.finger, trig.time_s, trig.reason
    h = state.holding[name]
    win, why = _window(ctx, state, trig, triggers)
    why = f"{reason} {why}"
    if (
        win.preferred_s + D > motion.t_end
        and trig.lost_s >= motion.t_end - p.dt_s - TIME_TOL_S
        and holds_to_end(h.track, t_trig, p.contact)
    ):
        # too late to regrasp, but the contact stays inside the joint limits (within the
        # trigger margin only) and feasible until the motion ends: keep holding
        note = (
            f"{reason} at t={t_trig:.3f} s, too late for a regrasp; held to the end "
            "inside the joint limits"
        )
        log.info("%s: %s", name, note)
        return replace(state, held_to_end={**state.held_to_end, name: note})
    rush = _rush(ctx, state, trig, triggers, win)
    if rush is not None:
        # another hold is lost before a regrasp of D could land: a faster one, by then
        D, land_by, dead_end = rush
        end_by_s = land_by if end_by_s is None else min(end_by_s, land_by)
        why += f"; a faster regrasp, landing by t={end_by_s:.3f} s ({dead_end.reason})"
    stay = _fingers_that_stay(ctx, state, trig, win)
    end_by = motion.t_end if end_by_s is None else end_by_s
    starts = start_times(win, latest_s=end_by - D, step_s=p.start_step_s, max_starts=p.max_starts)
    if not starts:
        busy = win.empty
        released = None if busy else let_go(ctx, state, trig, win, stay, why)
        if released is not None:
            return released
        raise PlanningError(
            f"{reason} at t={t_trig:.3f} s, "
            + (
                f"while another finger is in the air until t={state.now:.3f} s and the "
                f"contact is lost at t={win.latest_s:.3f} s"
                if busy
                else f"but a regrasp ({D:.2f} s) would not land by t={end_by:.3f} s"
            ),
            finger=name,
            time_s=t_trig,
            kind=FailureKind.FINGER_BUSY if busy else FailureKind.TOO_LATE,
            measured=state.now if busy else win.earliest_s + D,
            required=win.latest_s if busy else end_by,
        )
    others = {n: (state.holding[n].p, state.holding[n].n) for n in stay}
    landed: dict[int, Holding] = {}  # id(verified regrasp) -> the hold after it

    def search(starts: list[float], end_by: float | None) -> Found:
        return ctx.search.find(
            name,
            (h.p, h.n),
            starts,
            lambda t: holding_q(hand, motion, name, h, np.array([t]), p.contact.ik_tol_m)[0],
            others,
            q_hand_of(ctx, state, stay),
            ctx.budget,
            end_by_s=end_by,
            exclude=exclude,
            landing_check=lambda res: _check_landing(ctx, name, res, landed, triggers),
            reserved=reserved,
            shortest_s=D,
        )

    tries = (starts, end_by_s)
    nxt = _next_deadline(ctx, triggers, trig, win) if end_by_s is None else None
    if nxt is not None:
        # land in time for the holds lost next (earliest deadline first): landing later
        # would leave the other fingers no time, a dead end rather than a plan; when no
        # start is early enough, the holds may still end later than now foreseen (a
        # neighbour's regrasp ends a proximity loss): search without the deadline
        deadline, other = nxt
        early = start_times(
            win, latest_s=deadline - D, step_s=p.start_step_s, max_starts=p.max_starts
        )
        if early:
            tries = (early, deadline)
            why += f"; lands by t={deadline:.3f} s, in time for {other}'s hold"
    try:
        found = search(*tries)
    except PlanningError as exc:
        released = let_go(ctx, state, trig, win, stay, why)
        if released is not None:
            return released
        if rush is not None:  # the dead end stands: no faster regrasp either
            dead_end = rush[2]
            raise PlanningError(
                f"{dead_end.reason}; no faster regrasp either: {exc.reason}",
                finger=name,
                time_s=trig.time_s,
                kind=FailureKind.FINGER_BUSY,
                measured=dead_end.measured,
                required=dead_end.required,
                attempts=exc.attempts,
            ) from exc
        raise
    if abs(found.result.t_start - starts[0]) > TIME_TOL_S:
        why += (
            f"; lifted off at t={found.result.t_start:.3f} s: "
            "no verified regrasp at the start times tried before"
        )
    steps.append(_Step(state, trig, triggers, found.result.Q_object, tuple(exclude or ())))
    return _apply(ctx, state, name, t_trig, why, found, landed.get(id(found.result)))


def _tip_path_record(res: RegraspResult) -> list:
    """The tip path of a regrasp's record, at most about 200 points: the curve over the
    inflated surface, or the executed tip of a joint-space transfer (object frame)."""
    pts = res.tip_object if res.tip_path is None else res.tip_path.points_object
    return pts[:: max(1, len(pts) // 200)].tolist()


def _fingers_that_stay(
    ctx: PlanContext, state: PlanState, trig: Trigger, win: LiftOffWindow
) -> list[str]:
    """The fingers that hold while ``trig.finger`` is in the air; PlanningError if they
    are fewer than ``min_holding`` or not in force closure without it."""
    p, name = ctx.params, trig.finger
    stay = [n for n in ctx.scene.hand.finger_names if n != name and n in state.holding]
    if len(stay) < p.min_holding:
        raise PlanningError(
            f"only {len(stay)} fingers would hold (need {p.min_holding})",
            finger=name,
            time_s=win.preferred_s,
            kind=FailureKind.TOO_FEW_FINGERS,
            measured=len(stay),
            required=p.min_holding,
        )
    p_stay = np.array([state.holding[n].p for n in stay])
    n_stay = np.array([state.holding[n].n for n in stay])
    eps_stay = ferrari_canny_epsilon(p_stay, n_stay, p.mu, torque_scale_m=ctx.scene.obj.radius_m)
    if eps_stay <= 0.0:
        raise PlanningError(
            f"{trig.reason} at t={trig.time_s:.3f} s, but without it the other fingers are "
            "not in force closure",
            finger=name,
            time_s=win.preferred_s,
            kind=FailureKind.FORCE_CLOSURE,
            measured=eps_stay,
            required=0.0,
        )
    return stay


def _check_landing(
    ctx: PlanContext,
    name: str,
    res: RegraspResult,
    landed: dict[int, Holding],
    triggers: list[Trigger],
) -> Attempt | None:
    """Follow the contact a verified regrasp lands on (kept in ``landed``) and judge
    what it leaves: a ``short-hold`` attempt if it is lost sooner after landing than
    the shortest regrasp takes (no other finger could take its turn before this one
    must go again), unless it is held to the end of the motion; a ``finger-busy``
    attempt if, with it, the holds of the fingers (``triggers``: the others' losses)
    can no longer be regrasped in turn (:func:`regrasp_chain` must start before the
    landing) while without it they could."""
    p = ctx.params
    hold = landing_hold(ctx, name, res)
    landed[id(res)] = hold
    lost = held_until(hold.track, p.contact)
    end = ctx.scene.motion.t_end - p.dt_s
    need = min(res.t_end + p.regrasp.duration_s, end)
    where = f"start {res.t_start:.2f} s, Q={np.round(res.Q_object, 4).tolist()}"
    if lost < need - TIME_TOL_S:
        return Attempt(
            FailureKind.SHORT_HOLD,
            name,
            res.t_start,
            measured=lost - res.t_end,
            required=need - res.t_end,
            what=f"{where}: held {lost - res.t_end:.2f} s after landing "
            f"({loss_reason(hold, lost)})",
        )
    losses = {
        e.finger: e.lost_s
        for e in triggers
        if e.finger != name and e.lost_near != name and e.lost_s < end
    }
    if lost < end - TIME_TOL_S:
        losses[name] = lost
    chain = regrasp_chain(losses, p.regrasp.duration_s)
    if len(chain.order) < 2 or chain.latest_start_s >= res.t_end - TIME_TOL_S:
        return None
    without = regrasp_chain({n: t for n, t in losses.items() if n != name}, p.regrasp.duration_s)
    if without.latest_start_s < res.t_end - TIME_TOL_S:
        return None  # the others' turns were too tight before this landing: not its doing
    return Attempt(
        FailureKind.FINGER_BUSY,
        name,
        res.t_start,
        measured=res.t_end,
        required=chain.latest_start_s,
        what=f"{where}: lands at t={res.t_end:.2f} s, after the regrasps of "
        f"{', '.join(chain.order)} must start (t={chain.latest_start_s:.2f} s, "
        f"{chain.binding}'s hold)",
    )


def _refuse_dead_end(
    ctx: PlanContext, state: PlanState, trig: Trigger, triggers: list[Trigger], win: LiftOffWindow
) -> None:
    """Raise ``finger-busy`` if another finger's hold is lost before ``trig.finger``
    could land (and not because ``trig.finger`` comes near it): whatever this regrasp
    does, that finger would lose its hold while this one is in the air."""
    p, name = ctx.params, trig.finger
    land = win.earliest_s + p.regrasp.duration_s
    end = ctx.scene.motion.t_end - p.dt_s
    lost = [
        e
        for e in triggers
        if e.finger != name
        and e.finger in state.holding
        and e.finger not in state.held_to_end
        and e.lost_near != name
        and e.lost_s < min(land, end) - TIME_TOL_S
    ]
    if lost:
        first = min(lost, key=lambda e: (round(e.lost_s, 9), e.finger))
        raise PlanningError(
            f"{first.finger}'s hold is lost at t={first.lost_s:.3f} s, before a regrasp "
            f"of {name} could land (t={land:.3f} s)",
            finger=name,
            time_s=trig.time_s,
            kind=FailureKind.FINGER_BUSY,
            measured=land,
            required=first.lost_s,
        )


def _rush(
    ctx: PlanContext, state: PlanState, trig: Trigger, triggers: list[Trigger], win: LiftOffWindow
) -> tuple[float, float, PlanningError] | None:
    """``(shortest regrasp [s], time to land by [s], the dead end)`` if
    :func:`_refuse_dead_end` finds a dead end that a regrasp of
    ``params.rush_duration_s`` could still escape, landing before that hold is lost;
    None if there is no dead end; raises the dead end if no faster regrasp could land
    in time either."""
    try:
        _refuse_dead_end(ctx, state, trig, triggers, win)
    except PlanningError as busy:
        shortest, land_by = ctx.params.rush_duration_s, busy.required
        if shortest is None or land_by is None or win.earliest_s + shortest > land_by - TIME_TOL_S:
            raise
        return shortest, land_by, busy
    return None


def _next_deadline(
    ctx: PlanContext, triggers: list[Trigger], trig: Trigger, win: LiftOffWindow
) -> tuple[float, str] | None:
    """The time this regrasp should have landed by so that the other holds lost before
    the end can each be regrasped in turn (:func:`regrasp_chain` over them; those lost
    within one regrasp of the earliest start are dead ends, left out), if that falls
    within two regrasps of this finger's preferred start; and the finger whose loss
    sets it."""
    p = ctx.params
    D = p.regrasp.duration_s
    lost = {
        e.finger: e.lost_s
        for e in triggers
        if e.finger != trig.finger
        and e.lost_s < ctx.scene.motion.t_end - TIME_TOL_S
        and e.lost_s >= win.earliest_s + D + TIME_TOL_S
    }
    if not lost:
        return None
    chain = regrasp_chain(lost, D)  # the others' regrasps, in turn after this one
    if chain.latest_start_s > win.preferred_s + 2 * D + p.lead_s:
        return None
    return chain.latest_start_s, chain.binding or ""


def _apply(
    ctx: PlanContext,
    state: PlanState,
    name: str,
    t_trig: float,
    why: str,
    found: Found,
    new_hold: Holding | None = None,
) -> PlanState:
    """The state after a verified regrasp of ``name`` (``new_hold``: the hold after its
    landing, if already followed)."""
    res, choice = found.result, found.choice
    fly = RegraspPhase(
        finger=name,
        t_start=res.t_start,
        t_end=res.t_end,
        P_object=res.P_object,
        Q_object=res.Q_object,
        waypoints_object=res.waypoints_object,
        min_clearance_m=res.min_clearance_m,
        planning_ms=res.planning_ms,
        reason=why,
        extra={
            "n_P_object": res.n_P_object.tolist(),
            "n_Q_object": res.n_Q_object.tolist(),
            "trigger_time_s": t_trig,
            "waypoint_times_s": res.waypoint_times_s.tolist(),
            "route": res.route,
            "grid_path_object": []
            if res.grid_path is None
            else res.grid_path.points_object.tolist(),
            "tip_path_object": _tip_path_record(res),
            "path_length_m": res.path_length_m,
            "m": int(res.waypoints_object.shape[0]),
            "q_exit_time_s": choice.exit_time_s,
            "quality_kept": choice.quality_kept,
            "epsilon": choice.epsilon,
            "stage_ms": res.stage_ms,
            "attempts": [a.to_dict() for a in (*found.attempts, *res.attempts)],
        },
    )
    if new_hold is None:
        new_hold = landing_hold(ctx, name, res)
    log.info("%s regrasped at t=%.3f s (%s)", name, res.t_start, why)
    return replace(
        hold_ends(state, name, res.t_start, fly),
        holding={**state.holding, name: new_hold},
        regrasps=(*state.regrasps, res),
        now=res.t_end,
    )


def _signature(state: PlanState) -> tuple:
    """What identifies a state for the backtracking: who holds what since when."""
    return (
        round(state.now, 9),
        tuple(
            (n, round(h.t_from, 9), tuple(np.round(h.p, 6)))
            for n, h in sorted(state.holding.items())
        ),
        tuple(sorted(state.held_to_end)),
        tuple(sorted(state.released)),
    )


def _another_first(
    ctx: PlanContext,
    state: PlanState,
    contenders: list[Trigger],
    triggers: list[Trigger],
    steps: list[_Step],
) -> PlanState | None:
    """When the first contender finds no regrasp, let another contender go first
    (e.g. the other finger of two that close in on each other); None if none can."""
    for alt in contenders[1:]:
        key = (_signature(state), f"{alt.finger} first")
        if key in ctx.tried or ctx.budget.exhausted:
            continue
        ctx.tried.add(key)
        log.info("%s failed: %s regrasps first", contenders[0].finger, alt.finger)
        trial = list(steps)
        try:
            new_state = _advance(ctx, state, alt, triggers, trial)
        except PlanningError:
            continue
        steps[:] = trial
        return new_state
    return None


_BACKTRACK_DEPTH = 3  # how many earlier regrasps a failure may revisit


def _make_room(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[_Step],
    failure: PlanningError,
) -> PlanState | None:
    """When ``trig.finger`` finds no regrasp, let a neighbour whose contact takes the
    room of the finger's best new contact regrasp first, away from that room; None if
    no neighbour does or can.

    A neighbour takes the room if, without its contact, the finger could choose a new
    contact (:meth:`RegraspSearch.choose`) within the separation of the neighbour's
    contact. The neighbour then regrasps (now, or before one of the last regrasps if
    there is no time left now), lands before the finger's hold is lost, and keeps its
    new contact out of that room (the finger's separation around the wanted contact);
    what follows is planned again after it."""
    if failure.kind in (FailureKind.FINGER_BUSY, FailureKind.TOO_LATE, FailureKind.BUDGET):
        return None  # a matter of time, not of room
    name, h = trig.finger, state.holding[trig.finger]
    win, _ = _window(ctx, state, trig, triggers)
    D = ctx.params.regrasp.duration_s
    # where to go first from: now, or before one of the last regrasps (the finger
    # holding the same contact), as long as a regrasp lands before its hold is lost
    bases = [(state, triggers, len(steps))] + [
        (steps[k].before, steps[k].triggers, k)
        for k in range(len(steps) - 1, max(len(steps) - _BACKTRACK_DEPTH, 0) - 1, -1)
        if steps[k].before.holding.get(name) is not None
        and steps[k].before.holding[name].t_from == h.t_from
    ]
    bases = [b for b in bases if b[0].now + D <= win.latest_s - TIME_TOL_S]
    if not bases:
        return None
    for other, wanted in _blockers(ctx, state, trig, win):
        for base, base_triggers, k in bases:
            if ctx.budget.exhausted:
                return None
            if other not in base.holding:
                continue
            key = (_signature(base), f"{other} makes room for {name}")
            if key in ctx.tried:
                continue
            ctx.tried.add(key)
            lost = {e.finger: e.lost_s for e in base_triggers}
            go = Trigger(
                time_s=max(base.now, base.holding[other].t_from),
                finger=other,
                reason=f"makes room for {name} (its {failure.kind.value} failure)",
                lost_s=lost.get(other, ctx.scene.motion.t_end),
            )
            log.info("%s failed (%s): %s makes room first", name, failure.kind.value, other)
            trial = list(steps[:k])
            try:
                new_state = _advance(
                    ctx, base, go, base_triggers, trial, end_by_s=win.latest_s, reserved=(wanted,)
                )
            except PlanningError:
                continue
            steps[:] = trial
            return new_state
    return None


def _blockers(
    ctx: PlanContext, state: PlanState, trig: Trigger, win: LiftOffWindow
) -> list[tuple[str, tuple[np.ndarray, float]]]:
    """The holding fingers whose contacts take the room of ``trig.finger``'s best new
    contact, nearest first, each with that room: ``(point, radius)`` (object frame,
    the finger's separation [m]) as :func:`choose_new_contact` would choose it, landing
    one regrasp after the neighbour's, were the neighbour's contact not there."""
    hand, name = ctx.scene.hand, trig.finger
    h = state.holding[name]
    D = ctx.params.regrasp.duration_s
    t_arrive = min(max(win.preferred_s, state.now + D) + D, ctx.scene.motion.t_end)
    holding = [n for n in hand.finger_names if n != name and n in state.holding]
    sep = 2 * hand.finger(name).tip_radius + 0.001
    out = []
    for other in sorted(
        holding,
        key=lambda n: (round(float(np.linalg.norm(state.holding[n].p - h.p)), 9), n),
    ):
        if ctx.budget.exhausted:
            break
        rest = [n for n in holding if n != other]
        try:
            ctx.budget.spend()
            wanted = ctx.search.choose(
                name,
                (h.p, h.n),
                t_arrive,
                {n: (state.holding[n].p, state.holding[n].n) for n in rest},
                q_hand_of(ctx, state, rest),
                [],
            )
        except ContactError:
            continue  # no room for the finger even without this neighbour
        if np.linalg.norm(wanted.p_object - state.holding[other].p) < sep:
            out.append((other, (wanted.p_object, sep)))
    return out


def _backtrack(
    ctx: PlanContext,
    steps: list[_Step],
    failure: PlanningError,
    state: PlanState,
    trig: Trigger,
) -> PlanState | None:
    """Change an earlier decision so that ``trig.finger`` can go; None if none helps.

    The last regrasps are revisited, the latest first (at most ``_BACKTRACK_DEPTH``).
    If the finger ran out of time (its window closed, or no regrasp landed in time),
    it regrasps early, before that regrasp; or that regrasp lands one regrasp before
    the finger's hold is lost. Otherwise that regrasp lands elsewhere than it did.
    On success the steps after the revisited one are dropped (they are planned again).
    """
    timing = failure.kind in (FailureKind.FINGER_BUSY, FailureKind.TOO_LATE)
    D = ctx.params.regrasp.duration_s
    h_now = state.holding[trig.finger]
    for depth in range(1, min(_BACKTRACK_DEPTH, len(steps)) + 1):
        step = steps[-depth]
        kept = steps[: len(steps) - depth]
        options: list[tuple[str, Trigger, dict]] = []
        h_then = step.before.holding.get(trig.finger)
        if (
            timing
            and step.trig.finger != trig.finger
            and h_then is not None
            and (h_then.t_from == h_now.t_from)
        ):
            early = replace(
                trig,
                time_s=max(step.before.now, h_then.t_from),
                reason=f"{trig.reason} at t={trig.time_s:.3f} s (early: no time left after "
                f"{step.trig.finger}'s regrasp)",
            )
            options.append((f"{trig.finger} before {step.trig.finger}", early, {}))
        if timing:
            end_by = trig.lost_s - D
            if end_by > step.before.now + D + TIME_TOL_S:
                options.append(
                    (
                        f"{step.trig.finger} lands by t={end_by:.3f} s",
                        step.trig,
                        {"end_by_s": end_by},
                    )
                )
        else:
            exclude = [*step.excluded, step.Q_object]
            options.append((f"{step.trig.finger} lands elsewhere", step.trig, {"exclude": exclude}))
        for what, t_alt, kw in options:
            if ctx.budget.exhausted:
                return None
            key = (_signature(step.before), what)
            if key in ctx.tried:
                continue  # a retry that repeats what already failed is not a search
            ctx.tried.add(key)
            log.info("%s failed (%s): %s", trig.finger, failure.kind.value, what)
            trial = list(kept)
            try:
                new_state = _advance(ctx, step.before, t_alt, step.triggers, trial, **kw)
            except PlanningError:
                continue
            steps[:] = trial
            return new_state
    return None
