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
finds none, the planner backs up once per failure (at most ``max_backtracks`` times
before the plan gets further than it ever got, :mod:`.planning.recovery`):
another finger due soon goes first; or a neighbour whose contact takes the room of the
finger's best new contact regrasps first, out of that room (now, or before one of the
last regrasps); or the previous regrasp is planned again to land before this finger's
window closes, or, if time was not the problem, to land elsewhere. Every search shares one budget
(``max_steps``, counted, not timed, so that it is the same on every machine); a failure
that could not be backed out of because the budget was gone is a ``budget`` failure
(its message names the failure). A hold that no regrasp can
follow is let go (:mod:`.planning.letgo`: a verified back-off, a ``release`` phase, if
the others are enough to go on taking turns (more than ``min_holding``) or hold in
force closure to the end; or a hand-over to a finger that does not hold, idle or let
go before, a ``join`` phase).
Where the plan stands and the triggers that follow from it are in
:mod:`.planning.state`; one step (a trigger's regrasp, hold to the end or let-go) in
:mod:`.planning.advance`; the parameters in :mod:`.planning.params`.
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
from dataclasses import dataclass

import numpy as np

from ..exceptions import FailureKind, InputError, PlanningError
from ..grasp.holding import start_holding
from ..grasp.initial import Grasp, initial_grasp
from ..grasp.manifold import Manifold
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject, SurfaceSample
from ..model.scene import Scene
from ..plan import Plan
from ..verify.finger_motion import PENETRATION_TOL_M
from ..verify.plan_check import phase_gaps
from .advance import Step, advance, contenders
from .assembly import joint_speed_failure, object_penetration_failure, plan_until
from .feasibility import first_infeasibility, no_plan_exists
from .params import PlannerParams
from .recovery import recover
from .regrasp import RegraspResult
from .schedule import TIME_TOL_S
from .search import RegraspSearch, SearchBudget
from .setup import PlanSetup, plan_setup
from .state import PlanContext, PlanState, pending_triggers

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
        stage_s: Time spent per stage [s]; ``"manifolds"`` and ``"must hold"`` as
            they took in its setup (:func:`~.setup.plan_setup`), which may have been
            built once for several plans.
    """

    plan: Plan
    regrasps: list[RegraspResult]
    grasp: Grasp
    manifolds: dict[str, Manifold]
    sample: SurfaceSample
    stage_s: dict[str, float]


def plan_manipulation(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    *,
    grasp: Grasp | None = None,
    params: PlannerParams | None = None,
    progress: Callable[[float], None] | None = None,
    setup: PlanSetup | None = None,
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
        setup: What the plan builds before its search, built once by
            :func:`~.setup.plan_setup` for planning from several grasps: the same plan
            as without it (a wall-clock ``params.budget_s`` then counts only this
            call's own work); None: built here.

    Returns:
        A :class:`ManipulationPlan`.

    Raises:
        InputError: a part of the wrong type, a motion that takes the object more than
            1 m from the palm (lengths in millimetres by mistake), a ``setup`` built
            for another hand, object, motion or parameters.
        ContactError: no initial grasp.
        PlanningError: the motion cannot be achieved; ``kind`` says why, ``attempts``
            holds every failed attempt of the last search and ``partial`` the plan up
            to the failure (its summary: the search steps spent, ``"search_steps"``,
            the backtracks, and the time each stage took so far [s], ``"stage_s"``).
    """
    scene = Scene(hand, obj, motion)  # checks types and scale before any work
    params = params or PlannerParams()
    budget = SearchBudget.of(params.max_steps, params.budget_s)  # the whole call
    if setup is None:
        setup = plan_setup(hand, obj, motion, params)
    elif not isinstance(setup, PlanSetup):
        raise InputError("setup", f"is a {type(setup).__name__}", "a PlanSetup from plan_setup()")
    else:
        setup.check(hand, obj, motion, params)
    stage = dict(setup.stage_s)  # the setup's stages as they took, if built once for several
    active, base_q, sample = setup.active, setup.base_q, setup.sample
    manifolds, runs = setup.manifolds, setup.runs
    every = dict(setup.every)  # a join adds its finger's manifold to the plan's own
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
        raise _with_stages(no_plan_exists(ctx, infeasible, state), stage)
    t0 = time.perf_counter()
    steps: list[Step] = []
    backtracks = 0  # in all (the plan's summary)
    # backtracks since the plan last got further than ever before: each new furthest
    # time gets ``max_backtracks`` of them (the budget bounds the whole search)
    stuck, furthest = 0, state.now
    while True:
        triggers = pending_triggers(ctx, state)
        going = contenders(triggers, ctx)
        if not going:
            break
        trig = going[0]
        try:
            state = advance(ctx, state, trig, triggers, steps)
        except PlanningError as exc:
            redone = None
            may_back_up = stuck < params.max_backtracks
            if may_back_up:
                backtracks += 1
                stuck += 1
                redone = recover(ctx, state, going, triggers, steps, exc)
            if redone is None:
                stage["regrasps"] = time.perf_counter() - t0
                when = exc.time_s if exc.time_s is not None else trig.time_s
                until = min(max(min(when, trig.time_s), state.now), motion.t_end)
                cut_short = may_back_up and ctx.budget.exhausted
                partial = plan_until(ctx, state, until)
                # what the search spent, for a caller that shares a budget with it
                partial.summary.update(
                    search_steps=ctx.budget.steps, backtracks=backtracks, stage_s=dict(stage)
                )
                raise PlanningError(
                    (
                        f"the search budget ran out while backing up from a "
                        f"{exc.kind.value} failure: {exc.reason}"
                        if cut_short and exc.kind != FailureKind.BUDGET
                        else exc.reason
                    ),
                    finger=exc.finger or trig.finger,
                    time_s=when,
                    partial=partial,
                    kind=FailureKind.BUDGET if cut_short else exc.kind,
                    measured=exc.measured,
                    required=exc.required,
                    attempts=exc.attempts,
                    other=exc.other,
                ) from exc
            state = redone
        if state.now > furthest + TIME_TOL_S:
            stuck, furthest = 0, state.now
        if progress is not None:
            progress(state.now)
    stage["regrasps"] = time.perf_counter() - t0

    plan = _assembled(ctx, state, stage)
    plan.summary.update(
        {
            "regrasps": len(state.regrasps),
            "fingers_regrasped": sorted({r.finger for r in state.regrasps}),
            "initial_epsilon": grasp.epsilon,
            "held_to_end": dict(state.held_to_end),
            # every let-go and join of each finger (one that joined again has several)
            "released": _starts(plan.releases()),
            "joined": _starts(plan.joins()),
            "backtracks": backtracks,
            "search_steps": ctx.budget.steps,
            "stage_s": stage,
        }
    )
    taking_part = {n: m for n, m in every.items() if n in manifolds or n in state.joined}
    return ManipulationPlan(plan, list(state.regrasps), grasp, taking_part, sample, stage)


def _assembled(ctx: PlanContext, state: PlanState, stage: dict[str, float]) -> Plan:
    """:func:`_final_plan`, its time in ``stage["assembly"]`` [s]; its PlanningError (the
    whole plan's joint speeds or penetration) with the stages (:func:`_with_stages`)."""
    t0 = time.perf_counter()
    try:
        return _final_plan(ctx, state)
    except PlanningError as exc:
        _with_stages(exc, {**stage, "assembly": time.perf_counter() - t0})
        raise
    finally:
        stage["assembly"] = time.perf_counter() - t0


def _with_stages(exc: PlanningError, stage: dict[str, float]) -> PlanningError:
    """``exc`` with the time each stage took so far [s] in its partial plan's summary
    (``"stage_s"``, as a full plan's)."""
    if isinstance(exc.partial, Plan):
        exc.partial.summary["stage_s"] = dict(stage)
    return exc


def _starts(phases: list) -> dict[str, list[float]]:
    """The start times [s] of ``phases`` per finger, in time order."""
    out: dict[str, list[float]] = {}
    for ph in sorted(phases, key=lambda ph: (ph.t_start, ph.finger)):
        out.setdefault(ph.finger, []).append(float(ph.t_start))
    return out


def _final_plan(ctx: PlanContext, state: PlanState) -> Plan:
    """The whole plan of ``state``, checked where only the assembled plan can be: its
    phases and samples span the motion (else a bug: AssertionError), the holds, placed
    by IK at every sample, keep the joints within their velocity limits (else a
    ``velocity`` PlanningError with the plan before it), and no finger enters the
    object at any sample by more than the holds and the moves allow (the larger of
    ``ContactModel.tip_penetration_m`` and the verification's tolerance, plus the
    holds' IK tolerance; else an ``object-clearance`` PlanningError with the plan
    before it: :func:`~.assembly.object_penetration_failure`)."""
    motion = ctx.scene.motion
    plan = plan_until(ctx, state, motion.t_end, final=True)
    uncovered = phase_gaps(plan)
    ends = (abs(float(plan.t[0]) - motion.t_start), abs(float(plan.t[-1]) - motion.t_end))
    spans = max(ends) <= 1e-6
    if uncovered or not spans:
        # every move was verified on its samples; a plan whose samples or phases do not
        # span the motion would leave part of it unverified (a bug, not an outcome)
        raise AssertionError(
            f"the assembled plan spans {float(plan.t[0]):.4f}-{float(plan.t[-1]):.4f} s of "
            f"the motion's {motion.t_start:.4f}-{motion.t_end:.4f} s: " + "; ".join(uncovered)
        )
    too_fast = joint_speed_failure(ctx.scene.hand, plan.t, plan.q)
    if too_fast is not None:
        # the holds are placed by IK at the plan's samples: checked where they are known
        reason = f"the assembled plan is too fast where the fingers hold: {too_fast.reason}"
        raise _with_partial(ctx, state, too_fast, reason)
    contact = ctx.params.contact
    sinks = object_penetration_failure(
        ctx.scene.hand,
        ctx.scene.obj,
        plan.t,
        plan.q,
        plan.poses(),
        # what the holds (fingertip) and the moves (verification) allow, and the holds'
        # IK tolerance at the plan's samples
        max(contact.tip_penetration_m, PENETRATION_TOL_M) + contact.ik_tol_m,
    )
    if sinks is not None:
        raise _with_partial(ctx, state, sinks, sinks.reason)
    return plan


def _with_partial(
    ctx: PlanContext, state: PlanState, failure: PlanningError, reason: str
) -> PlanningError:
    """``failure`` of the assembled plan (its finger, time, kind and numbers) told as
    ``reason``, with the plan of ``state`` up to its time."""
    return PlanningError(
        reason,
        finger=failure.finger,
        time_s=failure.time_s,
        partial=plan_until(ctx, state, failure.time_s or ctx.scene.motion.t_start),
        kind=failure.kind,
        measured=failure.measured,
        required=failure.required,
        other=failure.other,
    )


def _time_grid(motion: ObjectMotion, dt_s: float) -> np.ndarray:
    grid = np.arange(motion.t_start, motion.t_end + TIME_TOL_S, dt_s)
    if grid[-1] < motion.t_end - TIME_TOL_S:
        grid = np.append(grid, motion.t_end)
    grid[-1] = min(grid[-1], motion.t_end)
    return grid
