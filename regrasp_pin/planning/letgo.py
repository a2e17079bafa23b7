"""Letting a finger go when no regrasp of it verifies.

A finger whose contact cannot be followed and that has no verified regrasp lets go
for the rest of the motion (:func:`~.release.plan_release`, a ``release`` phase) if
more than ``min_holding`` others remain to take turns, or if the others hold in force
closure to the end; otherwise a finger that does not hold may join in its place
(:func:`~.join.plan_join`, a ``join`` phase) once it has let go: a hand-over. The
joining finger took no part so far, or let go earlier and stands still where it
parked (its contacts may be back within reach: it joins again, and its ``release``
phase ends where its ``join`` starts). With the others too few to take turns, a
finger may also let go while they hold alone and join again itself before their
first hold is lost. Each moves the plan's time on (to the release, or to the joining
finger's landing); one that would take it past the loss of another finger's hold is
refused (a regrasp is refused when such a loss comes before its earliest landing).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import TypeVar

import numpy as np

from ..exceptions import ContactError, PlanningError
from ..grasp.holding import Holding, holding_q, rest_configuration
from ..grasp.manifold import build_manifold
from ..plan import JoinPhase, ReleasePhase
from .join import Join, join_durations, plan_join
from .release import Release, plan_release
from .schedule import TIME_TOL_S, LiftOffWindow, held_until
from .state import (
    PlanContext,
    PlanState,
    Trigger,
    hold_ends,
    landing_hold,
    pending_triggers,
    q_hand_of,
)

__all__ = ["idle_fingers", "join_origin", "joinable", "let_go", "still_from"]

log = logging.getLogger(__name__)

_C = TypeVar("_C")


def let_go(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    win: LiftOffWindow,
    stay: list[str],
    why: str,
) -> PlanState | None:
    """The state after ``trig.finger``, which has no verified regrasp, lets go
    (:func:`_try_release`), or lets go with a finger that does not hold joining in its
    place (:func:`_try_handover`), or lets go and joins again itself
    (:func:`_try_rejoin`); None if none verifies."""
    return (
        _try_release(ctx, state, trig, win, stay, why)
        or _try_handover(ctx, state, trig, win, stay, why)
        or _try_rejoin(ctx, state, trig, win, stay, why)
    )


def _try_release(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    win: LiftOffWindow,
    stay: list[str],
    why: str,
) -> PlanState | None:
    """The state after ``trig.finger`` lets go for the rest of the motion, or None.

    Only when releases are allowed and the hold is lost before the end, and, if the
    fingers that stay are too few to take turns (no more than ``min_holding``), when
    every one of them holds to the end once this one has gone (a neighbour it was
    closing in on no longer ends their hold). The release times tried are the latest in
    the window first, then earlier ones.
    """
    p, motion = ctx.params, ctx.scene.motion
    name = trig.finger
    end = motion.t_end - TIME_TOL_S
    if not p.release or win.empty or trig.lost_s >= end:
        return None
    if len(stay) <= p.fewest_holding and _first_loss(ctx, state, gone=name) < end:
        return None
    q_hand = q_hand_of(ctx, state, stay)
    tried: list[str] = []
    for t_r in _release_times(ctx, win):
        rel = _release_either(ctx, state, name, t_r, stay, q_hand, tried)
        if rel is not None:
            others = (
                f"{len(stay)} others go on"
                if len(stay) > p.fewest_holding
                else "the others hold to the end"
            )
            note = f"{why}; no verified regrasp: let go ({others})"
            after = _apply_release(state, name, rel, note)
            lost = _lost_before_now(ctx, after)
            if lost is not None:
                tried.append(f"{t_r:.3f} s: {lost.finger}'s hold is lost at {lost.lost_s:.3f} s")
                continue
            log.info("%s lets go at t=%.3f s", name, t_r)
            return after
    log.info("%s cannot let go (%s)", name, "; ".join(tried) or "no time")
    return None


def _first_loss(ctx: PlanContext, state: PlanState, gone: str | None = None) -> float:
    """When the first hold of ``state`` that ends before the motion does is lost [s]
    (inf: none is; holds kept to the end count as never lost); with ``gone``, once that
    finger has let go (a neighbour it was closing in on no longer ends their hold)."""
    if gone is not None:
        state = replace(state, holding={n: h for n, h in state.holding.items() if n != gone})
    end = ctx.scene.motion.t_end - TIME_TOL_S
    return min(
        (
            e.lost_s
            for e in pending_triggers(ctx, state, gone=() if gone is None else (gone,))
            if e.lost_s < end and e.finger not in state.held_to_end
        ),
        default=math.inf,
    )


def _lost_before_now(ctx: PlanContext, after: PlanState) -> Trigger | None:
    """A hold of ``after`` that is lost before ``after.now`` (the plan would have that
    finger hold past its loss while the others moved on), the first lost first; None
    if every hold lasts until then."""
    end = min(after.now, ctx.scene.motion.t_end) - TIME_TOL_S
    lost = [e for e in pending_triggers(ctx, after) if e.lost_s < end]
    return min(lost, key=lambda e: (round(e.lost_s, 9), e.finger), default=None)


def _release_times(ctx: PlanContext, win: LiftOffWindow) -> Iterator[float]:
    """Release times to try [s]: the latest in the window first, then earlier ones by
    ``start_step_s`` (at most ``max_starts``), while the budget lasts."""
    p = ctx.params
    for k in range(p.max_starts):
        t_r = win.latest_s - k * p.start_step_s
        if t_r < win.earliest_s - TIME_TOL_S or ctx.budget.exhausted:
            return
        yield max(t_r, win.earliest_s)


def _park(ctx: PlanContext, name: str) -> np.ndarray:
    """Where ``name`` goes after letting go: its posture clearest of the object over the
    motion (:func:`~.holding.rest_configuration`), computed once."""
    if name not in ctx.parks:
        q = rest_configuration(ctx.scene.hand, ctx.scene.obj, ctx.scene.motion, [name])
        ctx.parks[name] = q[ctx.scene.hand.fingers[name].q_indices]
    return ctx.parks[name]


def _release_either(
    ctx: PlanContext,
    state: PlanState,
    name: str,
    t_r: float,
    stay: list[str],
    q_hand: Callable[[np.ndarray], np.ndarray],
    tried: list[str],
    until: float | None = None,
) -> Release | None:
    """A verified release of ``name`` at ``t_r`` [s] (``q_hand``: the ``stay`` fingers
    holding; ``until``: planned to then [s], None: to the motion's end): staying where
    it backed off, else moving to its parking posture (:func:`_park`); None if neither
    verifies (the failures noted in ``tried``)."""
    h = state.holding[name]
    q_r = holding_q(
        ctx.scene.hand, ctx.scene.motion, name, h, np.array([t_r]), ctx.params.contact.ik_tol_m
    )[0]
    for park in (None, _park(ctx, name)):
        rel = _release_at(ctx, state, name, t_r, q_r, stay, q_hand, park, tried, until)
        if rel is not None:
            return rel
    return None


def _release_at(
    ctx: PlanContext,
    state: PlanState,
    name: str,
    t_r: float,
    q_r: np.ndarray,
    stay: list[str],
    q_hand: Callable[[np.ndarray], np.ndarray],
    park: np.ndarray | None,
    tried: list[str],
    until: float | None = None,
) -> Release | None:
    """A verified release of ``name`` at ``t_r`` (``park``, ``until``: see
    plan_release), or None (the failure noted in ``tried``).

    The outcome is kept for the plan (``ctx.releases``), by what it depends on: the
    finger, the time, parked or not, the time it is planned to, its hold and the holds
    and releases the others' motion comes from. Backing up asks for the same release
    again from other branches; it is answered, not planned or paid for again."""
    key = (
        name,
        round(t_r, 9),
        park is None,
        None if until is None else round(until, 9),
        _hold_key(state.holding[name]),
        tuple((n, _hold_key(state.holding[n])) for n in sorted(stay)),
        _released_key(state),
    )
    outcome = ctx.releases.get(key)
    if outcome is None:
        outcome = ctx.releases[key] = _plan_release(ctx, state, name, t_r, q_r, q_hand, park, until)
    if isinstance(outcome, PlanningError):
        tried.append(f"{t_r:.3f} s{' (park)' if park is not None else ''}: {outcome.kind.value}")
        return None
    return outcome


def _released_key(state: PlanState) -> tuple:
    """What the fingers let go of ``state`` are, for the other fingers' moves: where
    each moves and stands."""
    return tuple((n, r.times_s.tobytes(), r.q.tobytes()) for n, r in sorted(state.released.items()))


def _hold_key(h: Holding) -> tuple:
    """What a hold's configurations over time follow from: the contact, when it was
    taken and the track followed from there."""
    return (round(h.t_from, 9), h.p.tobytes(), h.n.tobytes(), h.track.q.tobytes())


def _plan_release(
    ctx: PlanContext,
    state: PlanState,
    name: str,
    t_r: float,
    q_r: np.ndarray,
    q_hand: Callable[[np.ndarray], np.ndarray],
    park: np.ndarray | None,
    until: float | None = None,
) -> Release | PlanningError:
    """:func:`~.release.plan_release` of ``name`` at ``t_r``, or its failure."""
    p, h = ctx.params, state.holding[name]
    ctx.budget.spend()
    try:
        return plan_release(
            ctx.scene.hand,
            ctx.scene.obj,
            ctx.scene.motion,
            name,
            t_r,
            (h.p, h.n),
            q_r,
            q_hand,
            clearance_m=p.regrasp.clearance_m,
            back_off_s=p.release_back_off_s,
            dt_s=p.dt_s,
            link_clearance_m=p.regrasp.link_clearance_m,
            finger_clearance_m=p.regrasp.finger_clearance_m,
            ik_tol_m=p.contact.ik_tol_m,
            q_park=park,
            park_s=p.regrasp.duration_s,
            until_s=until,
        )
    except PlanningError as exc:
        return exc


def _apply_release(state: PlanState, name: str, rel: Release, why: str) -> PlanState:
    """The state after a verified release of ``name``."""
    off = ReleasePhase(
        finger=name,
        t_start=rel.t_start,
        t_end=rel.t_end,
        P_object=rel.P_object,
        min_clearance_m=rel.min_clearance_m,
        reason=why,
    )
    return replace(
        hold_ends(state, name, rel.t_start, off),
        holding={n: x for n, x in state.holding.items() if n != name},
        now=max(state.now, rel.t_start),
        released={**state.released, name: rel},
    )


_JOIN_CANDIDATES = 3  # new contacts tried per joining finger and release time


_JOIN_APPROACH_S = 0.1  # the joining fingertip's final approach along Q's normal [s]


def _try_handover(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    win: LiftOffWindow,
    stay: list[str],
    why: str,
) -> PlanState | None:
    """The state after ``trig.finger`` lets go and a finger that does not hold (it took
    no part so far, or let go before and stands still) joins in its place
    (:mod:`.planning.join`), or None.

    Only when releases are allowed and such a finger exists. The release times tried
    are the latest in the window first; the joining fingers in the hand's order, each
    with its best new contacts (:meth:`RegraspSearch.choose`, the paper's criterion);
    the join starts when the release has backed off (at least
    ``release_back_off_s`` after it), the others holding.
    """
    p = ctx.params
    name = trig.finger
    if not p.release or win.empty or not [n for n in joinable(ctx, state, math.inf) if n != name]:
        return None
    q_hand = q_hand_of(ctx, state, stay)
    for t_r in _release_times(ctx, win):
        if t_r + p.release_back_off_s + p.regrasp.duration_s > ctx.scene.motion.t_end - p.dt_s:
            continue  # no time for the other finger to join
        failed: list[str] = []
        rel = _release_either(ctx, state, name, t_r, stay, q_hand, failed)
        if rel is None:
            log.debug("%s cannot let go at %s", name, failed)
            continue
        for other in [n for n in joinable(ctx, state, rel.t_backed_off) if n != name]:
            note = f"{why}; no verified regrasp: let go, {other} joins in its place"
            after = _apply_release(state, name, rel, note)
            joined = _join(ctx, after, other, rel.t_backed_off, stay, name)
            if joined is None:
                continue
            lost = _lost_before_now(ctx, joined)
            if lost is not None:
                log.debug(
                    "%s cannot join: %s's hold is lost at t=%.3f s, before it lands",
                    other,
                    lost.finger,
                    lost.lost_s,
                )
                continue
            log.info("%s lets go at t=%.3f s, %s joins", name, t_r, other)
            return joined
    return None


def _try_rejoin(
    ctx: PlanContext,
    state: PlanState,
    trig: Trigger,
    win: LiftOffWindow,
    stay: list[str],
    why: str,
) -> PlanState | None:
    """The state after ``trig.finger`` lets go while the fingers that stay are too few
    to take turns, and joins again, once its contacts are back within reach, before
    their first hold is lost; None if it cannot.

    For a finger whose every contact leaves its joint limits for a while (the object
    turns away from it), or that has no verified regrasp: the others hold alone
    meanwhile (in force closure without it: the caller's test). Tried after a release
    for good and a hand-over at once. The release is the first that verifies of the
    window's release times (latest first), planned only to the others' first loss
    (the finger joins before; another finger joining instead would leave it let go
    for the rest of the motion, which this release does not cover); the joins start
    every regrasp duration from the back-off, once the finger stands still (it may
    park first), earliest first, and must land a regrasp duration before the first
    hold is lost once it has joined (its own approach may bring a neighbour's loss
    earlier), so that the finger losing its hold first can still regrasp.
    """
    p, motion = ctx.params, ctx.scene.motion
    name, D = trig.finger, p.regrasp.duration_s
    if not p.release or win.empty or len(stay) > p.fewest_holding:
        return None  # none allowed, or the others take turns without it (a release)
    lost_by = _first_loss(ctx, state, gone=name)
    if lost_by >= motion.t_end - TIME_TOL_S:
        return None  # the others hold to the end: a release
    q_hand = q_hand_of(ctx, state, stay)
    for t_r in _release_times(ctx, win):
        # planned to the others' first loss, by which a finger must have joined
        rel = _release_either(ctx, state, name, t_r, stay, q_hand, [], until=lost_by)
        if rel is None:
            continue
        note = f"{why}; no verified regrasp: let go, to join again"
        after = _apply_release(state, name, rel, note)
        t0 = rel.t_backed_off
        while t0 + 2 * D <= lost_by + TIME_TOL_S and not ctx.budget.exhausted:
            joined = None
            if name in joinable(ctx, after, t0):  # standing still by then
                joined = _join(ctx, after, name, t0, stay, name)
            if joined is not None and _first_loss(ctx, joined) >= joined.now + D - TIME_TOL_S:
                log.info("%s lets go at t=%.3f s, joins again at t=%.3f s", name, t_r, t0)
                return joined
            t0 += D
        return None  # the first release that verifies: later joins were all tried
    return None


def join_origin(
    ctx: PlanContext, name: str, t_arrive: float, released: Release | None = None
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Where the finger ``name`` joins from: where it rests ``(k,)`` [rad] (idle, or
    where its ``released`` let-go left it), and the surface sample nearest that
    fingertip at ``t_arrive`` [s] ``(point, normal)`` (object frame [m]), the "P" its
    new contact is chosen away from. Builds the finger's manifold on the plan's times
    if the plan has none yet."""
    f, motion = ctx.scene.hand.finger(name), ctx.scene.motion
    if name not in ctx.manifolds:
        m_times = ctx.manifolds[ctx.active[0]].times_s
        ctx.manifolds[name] = build_manifold(
            f, ctx.search.sample, motion, m_times, contact=ctx.params.contact
        )
    q_from = ctx.base_q[f.q_indices] if released is None else released.q[-1]
    T = motion.pose(np.array([t_arrive]))[0]
    tip_obj = T[:3, :3].T @ (f.fk(q_from) - T[:3, 3])  # the resting tip, object frame
    k0 = int(np.argmin(np.linalg.norm(ctx.search.sample.points - tip_obj, axis=1)))
    return q_from, (ctx.search.sample.points[k0], ctx.search.sample.normals[k0])


def idle_fingers(ctx: PlanContext, state: PlanState) -> list[str]:
    """The fingers that took no part in the plan so far (they may join), in the hand's
    order."""
    return [n for n in ctx.scene.hand.finger_names if n not in state.phases]


def joinable(ctx: PlanContext, state: PlanState, t0: float) -> list[str]:
    """The fingers that may join from ``t0`` [s], in the hand's order: those that took
    no part so far, and those that let go and stand still by ``t0`` (backed off and
    parked: :func:`still_from`)."""
    return [
        n
        for n in ctx.scene.hand.finger_names
        if n not in state.holding
        and (
            n not in state.phases
            or (n in state.released and still_from(state.released[n]) <= t0 + TIME_TOL_S)
        )
    ]


_STILL_RAD = 1e-12  # a let-go finger's joints moving less than this between samples: still


def still_from(rel: Release) -> float:
    """When the finger of the let-go ``rel`` stops moving [s]: the first sample after
    which its configuration no longer changes (by more than rounding: a minimum-jerk
    move ends at 1 - 1e-16 of its way)."""
    moving = np.flatnonzero(np.any(np.abs(np.diff(rel.q, axis=0)) > _STILL_RAD, axis=1))
    return float(rel.times_s[moving[-1] + 1]) if moving.size else float(rel.times_s[0])


def _cut(rel: Release, t0: float) -> Release:
    """The let-go ``rel`` up to ``t0`` [s], when the finger, standing still since
    :func:`still_from`, starts to join again."""
    keep = rel.times_s < t0 - TIME_TOL_S
    return replace(
        rel,
        t_end=t0,
        times_s=np.append(rel.times_s[keep], t0),
        q=np.vstack([rel.q[keep], rel.q[-1:]]),
    )


_ARRIVAL_ROUNDS = 3


def arrival_choice(
    choose: Callable[[float], _C], duration_of: Callable[[_C], float], first_s: float
) -> tuple[_C, float, float]:
    """A choice made for the duration it needs, by fixed-point iteration.

    ``choose(d)`` chooses a new contact for a landing ``d`` [s] after the join's start;
    ``duration_of(c)`` is the shortest duration [s] a join to choice ``c`` takes (its
    velocity limits). A choice that needs longer than the duration it was chosen for is
    chosen again for the duration it needs, at most ``_ARRIVAL_ROUNDS`` times in all.

    Returns:
        ``(choice, chosen_s, needed_s)``: the last choice, the duration it was chosen for
        and the duration it needs; when ``needed_s`` is not longer (within
        :data:`TIME_TOL_S`) the join lands after :func:`join_duration_of` these,
        otherwise no choice settled.
    """
    chosen_s = first_s
    choice = choose(chosen_s)
    needed_s = duration_of(choice)
    for _ in range(_ARRIVAL_ROUNDS - 1):
        if needed_s <= chosen_s + TIME_TOL_S:
            break
        chosen_s = needed_s
        choice = choose(chosen_s)
        needed_s = duration_of(choice)
    return choice, chosen_s, needed_s


def join_duration_of(chosen_s: float, needed_s: float) -> float:
    """The duration [s] of a settled join (:func:`arrival_choice`): the one its choice
    needs when that is the one it was chosen for (within :data:`TIME_TOL_S`; the value
    rounded to whole steps, not a difference of times), else the longer one it was
    chosen for (the object's pose at landing is the one the choice was made at)."""
    return needed_s if abs(needed_s - chosen_s) <= TIME_TOL_S else chosen_s


def _join(
    ctx: PlanContext, state: PlanState, name: str, t0: float, stay: list[str], instead_of: str
) -> PlanState | None:
    """The state after ``name`` (not holding) joins from ``t0`` [s] with the ``stay``
    fingers holding, in place of ``instead_of``; None if no new contact verifies or
    holds long enough.

    The outcome is kept for the plan (``ctx.joins``), by what it depends on: the finger,
    the time, the holds of the fingers that stay and the fingers let go (where they
    move and stand). Backing up asks for the same join again from other branches; it
    is answered, not planned or paid for again."""
    key = (
        name,
        round(t0, 9),
        tuple((n, _hold_key(state.holding[n])) for n in sorted(stay)),
        _released_key(state),
    )
    if key in ctx.joins:
        outcome = ctx.joins[key]
    else:
        outcome = _plan_join(ctx, state, name, t0, stay)
        if not ctx.budget.exhausted:  # a search cut short is no outcome
            ctx.joins[key] = outcome
    if outcome is None:
        return None
    join, hold = outcome
    phase = JoinPhase(
        finger=name,
        t_start=join.t_start,
        t_end=join.t_end,
        Q_object=join.Q_object,
        min_clearance_m=join.min_clearance_m,
        reason=("joins again" if name in state.released else "joins")
        + (
            f" in place of {instead_of}, which let go"
            if name != instead_of
            else ": its contacts are back within reach"
        ),
    )
    return _apply_join(state, name, join, hold, phase)


def _plan_join(
    ctx: PlanContext, state: PlanState, name: str, t0: float, stay: list[str]
) -> tuple[Join, Holding] | None:
    """The verified join of ``name`` from ``t0`` [s] (its best new contacts tried in
    turn, the ``stay`` fingers holding) and the hold it lands on; None if none verifies
    or holds long enough."""
    p, hand, motion = ctx.params, ctx.scene.hand, ctx.scene.motion
    f = hand.finger(name)
    first_s = p.regrasp.duration_s
    t_arrive = t0 + first_s
    if t_arrive > motion.t_end - p.dt_s:
        return None
    q_from, P = join_origin(ctx, name, t_arrive, state.released.get(name))
    others = {n: (state.holding[n].p, state.holding[n].n) for n in stay}
    q_hand = q_hand_of(ctx, state, stay)
    excluded: list[np.ndarray] = []

    def durations(q_land: np.ndarray) -> np.ndarray:
        return join_durations(
            q_from,
            q_land,
            f.velocity_limit,
            minimum_s=p.regrasp.duration_s,
            approach_s=_JOIN_APPROACH_S,
            dt_s=p.dt_s,
        )

    # a Q whose join would land with no time left to hold it is not a candidate
    landing = (lambda q_land: t0 + durations(q_land), motion.t_end - p.dt_s)
    for _ in range(_JOIN_CANDIDATES):
        if ctx.budget.exhausted:
            return None
        ctx.budget.spend(2)  # the choice of Q and the join
        try:
            choice, chosen_s, needed_s = arrival_choice(
                lambda d: ctx.search.choose(
                    name, P, t0 + d, others, q_hand, excluded, landing=landing
                ),
                lambda c: float(durations(c.q_arrive[None])[0]),
                first_s,
            )
        except ContactError as exc:
            log.debug("%s cannot join: %s", name, exc)
            return None
        excluded.append(choice.p_object)
        if needed_s > chosen_s + TIME_TOL_S:
            log.debug("%s cannot join: Q needs %.3f s to reach", name, needed_s)
            continue
        duration = join_duration_of(chosen_s, needed_s)
        try:
            join = plan_join(
                hand,
                ctx.scene.obj,
                motion,
                name,
                t0,
                q_from,
                (choice.p_object, choice.n_object),
                choice.q_arrive,
                q_hand,
                duration_s=duration,
                approach_s=_JOIN_APPROACH_S,
                clearance_m=p.regrasp.clearance_m,
                dt_s=p.dt_s,
                link_clearance_m=p.regrasp.link_clearance_m,
                finger_clearance_m=p.regrasp.finger_clearance_m,
                ik_tol_m=p.contact.ik_tol_m,
            )
        except PlanningError as exc:
            log.debug("%s cannot join: %s", name, exc)
            continue
        hold = landing_hold(ctx, name, join)
        lost = held_until(hold.track, p.contact)
        if lost < min(join.t_end + p.regrasp.duration_s, motion.t_end) - TIME_TOL_S:
            log.debug("%s cannot join: Q held only to t=%.3f s", name, lost)
            continue
        return join, hold
    return None


def _apply_join(
    state: PlanState, name: str, join: Join, hold: Holding, phase: JoinPhase
) -> PlanState:
    """The state after a verified join of ``name``; a finger that let go before ends
    its let-go where the join starts (its earlier moves kept in ``ended``)."""
    phases = state.phases.get(name, ())
    ended = state.ended
    rel = state.released.get(name)
    if rel is not None:
        off = phases[-1]
        assert isinstance(off, ReleasePhase), off
        phases = (*phases[:-1], replace(off, t_end=join.t_start))
        ended = (*ended, _cut(rel, join.t_start))
    if name in state.joined:
        ended = (*ended, state.joined[name])
    return replace(
        state,
        holding={**state.holding, name: hold},
        history={**state.history, name: state.history.get(name, ())},
        phases={**state.phases, name: (*phases, phase)},
        joined={**state.joined, name: join},
        released={n: r for n, r in state.released.items() if n != name},
        ended=ended,
        now=max(state.now, join.t_end),
    )
