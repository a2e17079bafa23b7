"""Backing up when a finger finds no regrasp (:func:`recover`): another decision than
the one that failed.

In order: another finger due soon goes first (:func:`_another_first`); when the
other fingers do not hold without the finger, one of them regrasps first, onto a
contact with which they would (:func:`_free_first`); a neighbour
whose contact or links take the room of the finger's best new contact regrasps first,
out of that room, now or before one of the last regrasps (:func:`_make_room`); where
the finger can only let go with an idle finger joining in its place, a neighbour that
takes the joining finger's room regrasps first, out of it (:func:`_make_room_for_join`);
an earlier regrasp is planned again, with another finger due then going first, to let
the finger go before it or to land in time, or, if time was not the problem, to land
elsewhere (:func:`_backtrack`). An option already tried from the same state is not
tried again (a retry that repeats what failed is not a search).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from ..exceptions import ContactError, FailureKind, PlanningError
from ..grasp.choice import TIP_GAP_M, NewContact, Room, apart_threshold, tip_gap
from ..grasp.necessity import closure_possible_with
from ..model.clearance import FingerClearance
from .advance import Step, advance, window
from .advance import contenders as contenders_of
from .letgo import idle_fingers, join_origin
from .schedule import TIME_TOL_S, LiftOffWindow
from .search import LANDING_FINGER_CLEARANCE_M
from .state import PlanContext, PlanState, Trigger, q_hand_of

__all__ = ["recover"]

log = logging.getLogger(__name__)


def recover(
    ctx: PlanContext,
    state: PlanState,
    contenders: list[Trigger],
    triggers: list[Trigger],
    steps: list[Step],
    failure: PlanningError,
) -> PlanState | None:
    """The state after another decision than the one that failed with ``failure`` for
    the first of ``contenders`` (see the module docstring); None if none helps. On
    success ``steps`` holds the regrasps of the new state."""
    trig = contenders[0]
    redone = _another_first(ctx, state, contenders, triggers, steps)
    if redone is None:
        redone = _free_first(ctx, state, trig, triggers, steps, failure)
    if redone is None:
        redone = _make_room(ctx, state, trig, triggers, steps, failure)
    if redone is None:
        redone = _make_room_for_join(ctx, state, trig, triggers, steps, failure)
    if redone is None and steps:
        redone = _backtrack(ctx, steps, failure, state, trig)
    return redone


def _signature(state: PlanState) -> tuple:
    """What identifies a state for the backtracking: who holds what since when, and
    who let go when and where to (with how many moves have ended before)."""
    return (
        round(state.now, 9),
        tuple(
            (n, round(h.t_from, 9), tuple(np.round(h.p, 6)))
            for n, h in sorted(state.holding.items())
        ),
        tuple(sorted(state.held_to_end)),
        tuple(
            (n, round(r.t_start, 9), tuple(np.round(r.q[-1], 6)))
            for n, r in sorted(state.released.items())
        ),
        len(state.ended),
    )


def _another_first(
    ctx: PlanContext,
    state: PlanState,
    contenders: list[Trigger],
    triggers: list[Trigger],
    steps: list[Step],
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
            new_state = advance(ctx, state, alt, triggers, trial)
        except PlanningError:
            continue
        steps[:] = trial
        return new_state
    return None


_BACKTRACK_DEPTH = 3  # how many earlier regrasps a failure may revisit
#: failures of time, not of room: no neighbour making room mends them
_OF_TIME = (FailureKind.FINGER_BUSY, FailureKind.TOO_LATE, FailureKind.BUDGET)


def _make_room(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[Step],
    failure: PlanningError,
) -> PlanState | None:
    """When ``trig.finger`` finds no regrasp, let a neighbour whose contact or links
    take the room of the finger's best new contact regrasp first, away from that room;
    None if no neighbour does or can.

    A neighbour takes the room if, without it, the finger could choose a new contact
    (:meth:`RegraspSearch.choose`) within the separation of the neighbour's contact, or,
    after a finger-collision failure, one at which the two fingers' links would meet
    (:func:`_room_taken`). The neighbour
    then regrasps (now, or before one of the last regrasps if there is no time left
    now), lands before the finger's hold is lost, and keeps out of that room: its new
    contact away from the wanted one, its finger clear of the finger standing there;
    what follows is planned again after it. Not after a failure of time (finger-busy,
    too-late, budget), nor of force closure: that finger never chose a contact, as the
    others do not hold without it (:func:`_free_first` moves one of them for that)."""
    if failure.kind in _OF_TIME or failure.kind == FailureKind.FORCE_CLOSURE:
        return None  # a matter of time, or of the others' grasp: not of room
    name, h = trig.finger, state.holding[trig.finger]
    win, _ = window(ctx, state, trig, triggers)
    # where to go first from: now, or before one of the last regrasps (the finger
    # holding the same contact), as long as a regrasp lands before its hold is lost
    bases = _room_bases(ctx, state, triggers, steps, name, h.t_from, win.latest_s)
    if not bases:
        return None
    links = failure.kind == FailureKind.FINGER_COLLISION
    for other, rooms in _blockers(ctx, state, trig, win, links):
        for (base, base_triggers, k), (j, room) in itertools.product(bases, enumerate(rooms)):
            if ctx.budget.exhausted:
                return None
            if other not in base.holding:
                continue
            key = (_signature(base), f"{other} makes room for {name}", j)
            if key in ctx.tried:
                continue
            ctx.tried.add(key)
            log.info("%s failed (%s): %s makes room first", name, failure.kind.value, other)
            why = f"makes room for {name} (its {failure.kind.value} failure)"
            new_state = _neighbour_first(
                ctx, (base, base_triggers, k), other, why, win.latest_s, steps, room=room
            )
            if new_state is not None:
                return new_state
    return None


def _free_first(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[Step],
    failure: PlanningError,
) -> PlanState | None:
    """When ``trig.finger`` must let go but the other fingers are not in force closure
    without it (a ``force-closure`` failure), let one of them regrasp first, onto a
    contact with which the others would hold without ``trig.finger``
    (:meth:`RegraspSearch.find`'s ``frees``), held for two regrasps after it lands
    (``trig.finger``'s, then its own); None if none can.

    As in :func:`_make_room`, the neighbour goes now or before one of the last
    regrasps (the finger holding the same contact), and lands before the finger's
    lift-off window closes; what follows is planned again after it."""
    if failure.kind != FailureKind.FORCE_CLOSURE:
        return None
    name, h = trig.finger, state.holding[trig.finger]
    win, _ = window(ctx, state, trig, triggers)
    bases = _room_bases(ctx, state, triggers, steps, name, h.t_from, win.latest_s)
    holding = [n for n in ctx.scene.hand.finger_names if n != name and n in state.holding]
    for other in holding:
        for base, base_triggers, k in bases:
            if ctx.budget.exhausted:
                return None
            if other not in base.holding or not _may_free(ctx, base, other, name, win):
                continue
            key = (_signature(base), f"{other} frees {name}")
            if key in ctx.tried:
                continue
            ctx.tried.add(key)
            log.info("%s cannot let go (force closure): %s regrasps to free it", name, other)
            why = f"moves so that {name} can lift off"
            new_state = _neighbour_first(
                ctx, (base, base_triggers, k), other, why, win.latest_s, steps, frees=(name,)
            )
            if new_state is not None:
                return new_state
    return None


def _may_free(ctx: PlanContext, base: PlanState, other: str, name: str, win: LiftOffWindow) -> bool:
    """Whether ``other``, regrasping from ``base`` and landing by ``win.latest_s``,
    could free ``name`` at all: the contacts held in ``base`` but theirs, plus one that
    ``other`` could use at a manifold time of that landing window, could be in force
    closure (:func:`~regrasp_pin.grasp.necessity.closure_possible_with`, an upper
    bound: False proves that no such regrasp frees it, and its search is skipped)."""
    rest = [n for n in ctx.scene.hand.finger_names if n in base.holding and n not in (name, other)]
    manifold = ctx.search.manifolds[other]
    times = manifold.times_s
    first = max(base.now, base.holding[other].t_from) + ctx.params.regrasp.duration_s
    step = float(times[1] - times[0]) if times.size > 1 else 0.0
    rows = np.flatnonzero((times >= first - step) & (times <= win.latest_s + step))
    return closure_possible_with(
        np.array([base.holding[n].p for n in rest]),
        np.array([base.holding[n].n for n in rest]),
        manifold,
        ctx.search.sample,
        ctx.scene.obj,
        ctx.params.mu,
        rows,
        torsion_m=ctx.params.contact.torsion_m,
    )


def _neighbour_first(
    ctx: PlanContext,
    base: tuple[PlanState, list[Trigger], int],
    other: str,
    why: str,
    end_by_s: float,
    steps: list[Step],
    *,
    room: Room | None = None,
    frees: tuple[str, ...] = (),
) -> PlanState | None:
    """The state after the holding finger ``other`` regrasps from ``base`` (a state,
    its triggers and how many of ``steps`` it keeps, :func:`_room_bases`), landing by
    ``end_by_s`` [s], out of ``room`` (:func:`_room_taken`) if given,
    on a contact that frees the ``frees`` fingers (:func:`~.advance.advance`), and not
    held on instead (moving it is the point); None if no such regrasp verifies. On
    success ``steps`` holds the regrasps of the new state."""
    state, triggers, k = base
    lost = {e.finger: e.lost_s for e in triggers}
    go = Trigger(
        time_s=max(state.now, state.holding[other].t_from),
        finger=other,
        reason=why,
        lost_s=lost.get(other, ctx.scene.motion.t_end),
    )
    trial = list(steps[:k])
    try:
        new_state = advance(
            ctx,
            state,
            go,
            triggers,
            trial,
            end_by_s=end_by_s,
            reserved=() if room is None else (room,),
            may_hold=False,
            frees=frees,
        )
    except PlanningError:
        return None
    steps[:] = trial
    return new_state


def _make_room_for_join(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    triggers: list[Trigger],
    steps: list[Step],
    failure: PlanningError,
) -> PlanState | None:
    """When ``trig.finger`` finds no regrasp and the one way left to go on is a
    hand-over (:mod:`.letgo`: it lets go, an idle finger joins in its place, because
    the fingers that stay are too few to take turns), let a holding neighbour whose
    contact or links take the room of the joining finger's best new contact regrasp
    first, out of that room (around that contact); None if no neighbour does or can.

    As in :func:`_make_room`, the neighbour goes now, or before one of the last
    regrasps (the finger holding the same contact), and lands before the finger's
    lift-off window closes. The joining finger's contact is the one
    :meth:`RegraspSearch.choose` would give it were the neighbour not there, landing
    after the neighbour's regrasp, a release's back-off and a join (:func:`_room_taken`
    decides whether the neighbour takes its room). What follows, the hand-over
    included, is planned again from the new state."""
    p = ctx.params
    if failure.kind in _OF_TIME:
        return None  # a matter of time, not of room
    name, h = trig.finger, state.holding[trig.finger]
    stay = [n for n in ctx.scene.hand.finger_names if n != name and n in state.holding]
    idle = idle_fingers(ctx, state)
    if not p.release or not idle or len(stay) > p.fewest_holding:
        return None  # no hand-over: none allowed, nobody to join, or it may just let go
    win, _ = window(ctx, state, trig, triggers)
    D, motion = p.regrasp.duration_s, ctx.scene.motion
    bases = _room_bases(ctx, state, triggers, steps, name, h.t_from, win.latest_s)
    for b in bases:
        t_arrive = min(
            max(win.preferred_s, b[0].now + D) + p.release_back_off_s + D,
            motion.t_end - p.dt_s,
        )
        for joining, other, rooms in _join_blockers(ctx, b[0], stay, idle, t_arrive):
            log.info(
                "%s failed (%s): %s makes room for %s to join",
                name,
                failure.kind.value,
                other,
                joining,
            )
            why = f"makes room for {joining} to join in place of {name}"
            for room in rooms:
                new_state = _neighbour_first(ctx, b, other, why, win.latest_s, steps, room=room)
                if new_state is not None:
                    return new_state
    return None


def _join_blockers(
    ctx: PlanContext,
    base: PlanState,
    stay: list[str],
    idle: list[str],
    t_arrive: float,
) -> Iterator[tuple[str, str, tuple[Room, ...]]]:
    """``(joining, neighbour, rooms)`` for each idle finger of ``base`` that could join
    at ``t_arrive`` [s] and each of the ``stay`` fingers, nearest its best contact
    first, that takes that contact's room (:func:`_room_taken`), each pair not tried
    before from ``base``; stops when the budget is spent."""
    near = [n for n in stay if n in base.holding]
    for joining in [n for n in idle if n not in base.phases]:
        _, P = join_origin(ctx, joining, t_arrive)
        sep = 2 * ctx.scene.hand.finger(joining).tip_radius + 0.001
        for other in sorted(
            near, key=lambda n: (round(float(np.linalg.norm(base.holding[n].p - P[0])), 9), n)
        ):
            if ctx.budget.exhausted:
                return
            key = (_signature(base), f"{other} makes room for {joining} to join")
            if key in ctx.tried:
                continue
            ctx.tried.add(key)
            rest = [n for n in near if n != other]
            try:
                ctx.budget.spend()
                wanted = ctx.search.choose(
                    joining,
                    P,
                    t_arrive,
                    {n: (base.holding[n].p, base.holding[n].n) for n in rest},
                    q_hand_of(ctx, base, rest),
                    [],
                    absent=(other,),
                )
            except ContactError:
                continue  # no room for the joining finger even without this neighbour
            rooms = _room_taken(ctx, base, joining, other, wanted, sep)
            if rooms is not None:
                yield joining, other, rooms


def _room_bases(
    ctx: PlanContext,
    state: PlanState,
    triggers: list[Trigger],
    steps: list[Step],
    name: str,
    t_from: float,
    latest_s: float,
) -> list[tuple[PlanState, list[Trigger], int]]:
    """Where a neighbour may go first from, ``(state, triggers, steps kept)``: now, or
    before one of the last ``_BACKTRACK_DEPTH`` regrasps at which ``name`` held the
    contact it holds now (since ``t_from``), latest first; only those from which a
    regrasp lands by ``latest_s`` [s]."""
    D = ctx.params.regrasp.duration_s
    bases = [(state, triggers, len(steps))] + [
        (steps[k].before, steps[k].triggers, k)
        for k in range(len(steps) - 1, max(len(steps) - _BACKTRACK_DEPTH, 0) - 1, -1)
        if steps[k].before.holding.get(name) is not None
        and steps[k].before.holding[name].t_from == t_from
    ]
    return [b for b in bases if b[0].now + D <= latest_s - TIME_TOL_S]


def _blockers(
    ctx: PlanContext, state: PlanState, trig: Trigger, win: LiftOffWindow, links: bool
) -> list[tuple[str, tuple[Room, ...]]]:
    """The holding fingers whose contacts or links take the room of ``trig.finger``'s
    best new contact, nearest first, each with the rooms to leave (:func:`_room_taken`)
    around the contact :func:`choose_new_contact` would choose, landing one regrasp
    after the neighbour's, were the neighbour not there (``links``: a neighbour's links
    count too; only after a finger-collision failure, the one failure they can
    cause)."""
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
                absent=(other,),
            )
        except ContactError:
            continue  # no room for the finger even without this neighbour
        rooms = _room_taken(ctx, state, name, other, wanted, sep, links)
        if rooms is not None:
            out.append((other, rooms))
    return out


def _room_taken(
    ctx: PlanContext,
    state: PlanState,
    name: str,
    other: str,
    wanted: NewContact,
    sep: float,
    links: bool = True,
) -> tuple[Room, ...] | None:
    """The rooms around ``wanted`` (``name``'s new contact) that the holding finger
    ``other`` may leave, to be tried in order, or None if its hold leaves ``name`` room
    there: if the two fingertip spheres would stand nearer than
    :data:`~regrasp_pin.grasp.choice.TIP_GAP_M` (the choice's own test) or, only with
    ``links``, the fingers' links would meet (Coal, closer than
    :data:`~.search.LANDING_FINGER_CLEARANCE_M` at the landing).

    First the room of ``name`` standing at ``wanted``: no contact within ``sep`` of it,
    ``other``'s finger clear of ``name``'s there at its arrival (a
    :class:`~regrasp_pin.grasp.choice.Room` with that posture). Then a room of that
    contact alone, wider where the links met (farther from it than ``other``'s contact
    is now, by a tip radius): it leaves room to ``name``'s other contacts near it."""
    h = state.holding[other]
    posture = Room(wanted.p_object, sep, name, wanted.q_arrive, wanted.t_arrive_s)
    gap = tip_gap(ctx.scene.hand, name, (wanted.p_object, wanted.n_object), other, (h.p, h.n))
    if gap < apart_threshold(TIP_GAP_M):  # the choice's own test
        return posture, Room(wanted.p_object, sep)
    if not links:
        return None
    hand = ctx.scene.hand
    q = q_hand_of(ctx, state, [other])(np.array([wanted.t_arrive_s]))[0]
    q[hand.finger(name).q_indices] = wanted.q_arrive
    if FingerClearance.shared(hand, name, [other])(q) < LANDING_FINGER_CLEARANCE_M:
        d = float(np.linalg.norm(wanted.p_object - h.p))
        return posture, Room(wanted.p_object, d + hand.finger(name).tip_radius)
    return None


def _backtrack(
    ctx: PlanContext,
    steps: list[Step],
    failure: PlanningError,
    state: PlanState,
    trig: Trigger,
) -> PlanState | None:
    """Change an earlier decision so that ``trig.finger`` can go; None if none helps.

    The last regrasps are revisited, the latest first (at most ``_BACKTRACK_DEPTH``).
    At each, first another finger due then (a contender of that step) regrasps first,
    as :func:`_another_first` offers at a failure: a finger whose regrasp came later
    may, by going first, leave the revisited finger a way out. Then, if the finger ran
    out of time (its window closed, or no regrasp landed in time), it regrasps early,
    before that regrasp; or that regrasp lands one regrasp before the finger's hold is
    lost. Otherwise that regrasp lands elsewhere than it did. On success the steps
    after the revisited one are dropped (they are planned again).
    """
    timing = failure.kind in (FailureKind.FINGER_BUSY, FailureKind.TOO_LATE)
    D = ctx.params.regrasp.duration_s
    h_now = state.holding[trig.finger]
    for depth in range(1, min(_BACKTRACK_DEPTH, len(steps)) + 1):
        step = steps[-depth]
        kept = steps[: len(steps) - depth]
        # another finger due then goes first (the key _another_first gives it)
        options: list[tuple[str, Trigger, dict]] = [
            (f"{alt.finger} first", alt, {})
            for alt in contenders_of(step.triggers, ctx)
            if alt.finger != step.trig.finger
        ]
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
                new_state = advance(ctx, step.before, t_alt, step.triggers, trial, **kw)
            except PlanningError:
                continue
            steps[:] = trial
            return new_state
    return None
