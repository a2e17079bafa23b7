"""One step of the whole-hand plan: the next trigger's regrasp, hold to the end or
let-go (:func:`advance`), and the order in which fingers go (:func:`contenders`).

A step takes the first contender's trigger: if its contact stays inside the joint
limits to the end and no regrasp fits, it is held to the end; otherwise a regrasp is
searched (:mod:`.search`) in the finger's lift-off window (:func:`window`), faster when
another finger's hold would be lost first (``rush_duration_s``), landing in time for
the holds lost next, and judged by the hold it lands on; with none verified the finger
lets go (:mod:`.letgo`). Each regrasp is recorded as a :class:`Step` that the
backtracking (:mod:`.recovery`) can revisit.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from ..exceptions import Attempt, FailureKind, PlanningError
from ..grasp.choice import Room
from ..grasp.holding import Holding, holding_q, holds_to_end
from ..grasp.quality import FORCE_CLOSURE_TOL, ferrari_canny_epsilon, is_force_closure
from ..plan import RegraspPhase
from .feasibility import longest_start_hold
from .letgo import let_go
from .regrasp import RegraspResult
from .schedule import (
    TIME_TOL_S,
    LiftOffWindow,
    held_until,
    lift_off_window,
    regrasp_chain,
    start_times,
)
from .search import Found
from .state import (
    PlanContext,
    PlanState,
    Trigger,
    hold_ends,
    landing_hold,
    loss_reason,
    q_hand_of,
)

__all__ = ["Step", "advance", "contenders", "window"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """A regrasp decision that can be revisited: the state before it and its trigger."""

    before: PlanState
    trig: Trigger
    triggers: list[Trigger]
    Q_object: np.ndarray
    excluded: tuple[np.ndarray, ...] = ()


def contenders(triggers: list[Trigger], ctx: PlanContext) -> list[Trigger]:
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


def window(
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


def advance(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[Step],
    *,
    end_by_s: float | None = None,
    exclude: list[np.ndarray] | None = None,
    reserved: tuple[Room | tuple[np.ndarray, float], ...] = (),
    may_hold: bool = True,
    frees: tuple[str, ...] = (),
) -> PlanState:
    """The state after ``trig``: one verified regrasp (landing by ``end_by_s``, away
    from the ``exclude`` points, out of the ``reserved`` room and, with ``frees``, on a
    contact with which the others would hold without those fingers, held long enough
    for one of them to regrasp and then this finger: see
    :meth:`RegraspSearch.find`), a let-go, or its finger held to the end: when it is
    too late for a regrasp, or (``may_hold``: False for a regrasp whose point is to
    move the finger) when no regrasp or let-go is found, if its contact lasts to the
    end (:func:`_held_to_end`; a trigger warns before a hold is lost, and a hold that
    is not lost needs no regrasp)."""
    win, why = window(ctx, state, trig, triggers)
    if win.preferred_s + ctx.params.regrasp.duration_s > ctx.scene.motion.t_end:
        held = _held_to_end(ctx, state, trig, "too late for a regrasp")
        if held is not None:
            return held
    try:
        return _advance(
            ctx, state, trig, triggers, steps, (win, why), end_by_s, exclude, reserved, frees
        )
    except PlanningError as exc:
        held = _held_to_end(ctx, state, trig, f"no regrasp ({exc.kind.value})")
        if held is None or not may_hold:
            raise
        return held


def _advance(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[Step],
    window_why: tuple[LiftOffWindow, str],
    end_by_s: float | None,
    exclude: list[np.ndarray] | None,
    reserved: tuple[Room | tuple[np.ndarray, float], ...],
    frees: tuple[str, ...] = (),
) -> PlanState:
    """:func:`advance` before its last resort (holding to the end); ``window_why``:
    the finger's lift-off window and why (:func:`window`)."""
    p, hand, motion = ctx.params, ctx.scene.hand, ctx.scene.motion
    D = p.regrasp.duration_s
    name, t_trig, reason = trig.finger, trig.time_s, trig.reason
    h = state.holding[name]
    win, why = window_why
    why = f"{reason} {why}"
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
        released = None if busy or frees else let_go(ctx, state, trig, win, stay, why)
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
    others_lost = _others_lost_by(ctx, state, name, triggers)

    def search(starts: list[float], end_by: float | None) -> Found:
        return ctx.search.find(
            name,
            (h.p, h.n),
            starts,
            lambda t: holding_q(hand, motion, name, h, np.array([t]), p.contact.ik_tol_m)[0],
            others,
            q_hand_of(ctx, state, stay),
            ctx.budget,
            end_by_s=_earliest(end_by, others_lost),  # landing later: a dead end
            exclude=exclude,
            landing_check=lambda res: _check_landing(
                ctx, name, res, landed, triggers, turns=2 if frees else 1
            ),
            reserved=reserved,
            shortest_s=D,
            frees=frees,
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
        # a finger that moves to free another must land (letting go frees nothing)
        released = None if frees else let_go(ctx, state, trig, win, stay, why)
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
    steps.append(Step(state, trig, triggers, found.result.Q_object, tuple(exclude or ())))
    return _apply(ctx, state, name, t_trig, why, found, landed.get(id(found.result)))


def _held_to_end(ctx: PlanContext, state: PlanState, trig: Trigger, why: str) -> PlanState | None:
    """The state with ``trig.finger`` holding its contact to the end of the motion when
    it need not regrasp (``why``: why it does not): its hold is not lost before the
    motion's end (its last sample included) and the contact stays reached, inside the
    joint limits (within the trigger margin only), pad facing and its links clear until
    the end; else None."""
    p, motion = ctx.params, ctx.scene.motion
    h = state.holding[trig.finger]
    if trig.lost_s < motion.t_end - TIME_TOL_S or not holds_to_end(h.track, trig.time_s, p.contact):
        return None
    note = f"{trig.reason} at t={trig.time_s:.3f} s, {why}; held to the end inside the joint limits"
    log.info("%s: %s", trig.finger, note)
    return replace(state, held_to_end={**state.held_to_end, trig.finger: note})


def _tip_path_record(res: RegraspResult) -> list:
    """The tip path of a regrasp's record, at most about 200 points: the curve over the
    inflated surface, or the executed tip of a joint-space transfer (object frame)."""
    pts = res.tip_object if res.tip_path is None else res.tip_path.points_object
    return pts[:: max(1, len(pts) // 200)].tolist()


def _must_let_go_note(ctx: PlanContext, state: PlanState, name: str) -> str:
    """What a finger that cannot let go (the others not in force closure without it)
    tells the user, as ``"; ..."`` (empty for a finger that was not in the initial
    grasp and joined later, or without its manifold): whether any start contact of it
    could have been held to the end, by its manifold
    (:func:`~.feasibility.longest_start_hold`), and what to change."""
    man = ctx.manifolds.get(name)
    if man is None or name not in ctx.active:
        return ""
    motion, c = ctx.scene.motion, ctx.params.contact
    lasts = longest_start_hold(man, c.limit_margin_rad)
    if math.isinf(lasts):
        return (
            f"; {name} could hold a contact from the start to the end (by its manifold: "
            "inside its joint limits, the pad facing the surface, the fingertip link "
            "clear): start it on such a contact, one whose links stay clear of the object "
            "and of the other fingers"
        )
    return (
        f"; no contact that {name} can hold at the start stays holdable (inside its joint "
        "limits, the pad facing the surface, the fingertip link clear) to the end of the "
        f"motion (the longest until t={lasts:.2f} s, the motion ends at "
        f"t={motion.t_end:.2f} s), so every plan must let {name} go while the others "
        f"hold alone: place the object so that a contact of {name} stays within its "
        f"limits through the motion (for a turn about an axis through the object, the "
        f"axis through a contact {name} reaches), or turn less"
    )


def _fingers_that_stay(
    ctx: PlanContext, state: PlanState, trig: Trigger, win: LiftOffWindow
) -> list[str]:
    """The fingers that hold while ``trig.finger`` is in the air; PlanningError if they
    are fewer than ``min_holding`` or not in force closure without it
    (:func:`~regrasp_pin.grasp.quality.is_force_closure`, the test a regrasp that frees
    a finger passes: ``choose_new_contact``'s ``frees``)."""
    p, name = ctx.params, trig.finger
    stay = [n for n in ctx.scene.hand.finger_names if n != name and n in state.holding]
    if len(stay) < p.fewest_holding:
        raise PlanningError(
            f"only {len(stay)} fingers would hold (need {p.fewest_holding})",
            finger=name,
            time_s=win.preferred_s,
            kind=FailureKind.TOO_FEW_FINGERS,
            measured=len(stay),
            required=p.fewest_holding,
        )
    p_stay = np.array([state.holding[n].p for n in stay])
    n_stay = np.array([state.holding[n].n for n in stay])
    scale = ctx.scene.obj.radius_m
    torsion = p.contact.torsion_m
    if not is_force_closure(p_stay, n_stay, p.mu, torque_scale_m=scale, torsion_m=torsion):
        eps_stay = ferrari_canny_epsilon(
            p_stay, n_stay, p.mu, torque_scale_m=scale, torsion_m=torsion
        )
        raise PlanningError(
            f"{trig.reason} at t={trig.time_s:.3f} s, but without it the other fingers are "
            f"not in force closure{_must_let_go_note(ctx, state, name)}",
            finger=name,
            time_s=win.preferred_s,
            kind=FailureKind.FORCE_CLOSURE,
            measured=eps_stay,
            required=FORCE_CLOSURE_TOL,
        )
    return stay


def _check_landing(
    ctx: PlanContext,
    name: str,
    res: RegraspResult,
    landed: dict[int, Holding],
    triggers: list[Trigger],
    turns: int = 1,
) -> Attempt | None:
    """Follow the contact a verified regrasp lands on (kept in ``landed``) and judge
    what it leaves: a ``short-hold`` attempt if it is lost sooner after landing than
    ``turns`` shortest regrasps take (1: another finger could take its turn before
    this one must go again; 2 for a regrasp that frees a finger: that one's regrasp and
    then this one's), unless it is held to the end of the motion; a ``finger-busy``
    attempt if, with it, the holds of the fingers (``triggers``: the others' losses)
    can no longer be regrasped in turn (:func:`regrasp_chain` must start before the
    landing) while without it they could."""
    p = ctx.params
    hold = landing_hold(ctx, name, res)
    landed[id(res)] = hold
    lost = held_until(hold.track, p.contact)
    end = ctx.scene.motion.t_end
    need = min(res.t_end + turns * p.regrasp.duration_s, end)
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
        if e.finger != name and e.lost_near != name and e.lost_s < end - TIME_TOL_S
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


def _others_lost_by(
    ctx: PlanContext, state: PlanState, name: str, triggers: list[Trigger]
) -> float | None:
    """The earliest time [s] at which another finger's hold is lost (not because
    ``name`` comes near it), or None: a regrasp of ``name`` that lands later leaves that
    finger no turn to let go (one finger in the air at a time), a dead end whatever
    follows (a long regrasp, stretched for the joint velocity limits, used to land
    there and the search went on from a state it could not leave)."""
    end = ctx.scene.motion.t_end - TIME_TOL_S
    lost = [
        e.lost_s
        for e in triggers
        if e.finger != name
        and e.finger in state.holding
        and e.finger not in state.held_to_end
        and e.lost_near != name
        and e.lost_s < end
    ]
    return min(lost) if lost else None


def _earliest(*times_s: float | None) -> float | None:
    """The earliest of the times given [s] (None: no time), or None."""
    given = [t for t in times_s if t is not None]
    return min(given) if given else None


def _refuse_dead_end(
    ctx: PlanContext, state: PlanState, trig: Trigger, triggers: list[Trigger], win: LiftOffWindow
) -> None:
    """Raise ``finger-busy`` if another finger's hold is lost before ``trig.finger``
    could land (and not because ``trig.finger`` comes near it): whatever this regrasp
    does, that finger would lose its hold while this one is in the air."""
    p, name = ctx.params, trig.finger
    land = win.earliest_s + p.regrasp.duration_s
    end = ctx.scene.motion.t_end
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
            "time_law": res.params.time_law,
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
