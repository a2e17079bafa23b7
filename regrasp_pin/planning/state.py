"""Where a whole-hand plan stands, and what follows from it.

:class:`PlanState` is an immutable snapshot (who holds what since when, the phases so
far, the time before which no finger may lift off); :class:`PlanContext` the fixed
problem and the search's shared budget and memory. From them: the pending triggers
(:func:`pending_triggers`: contacts near their limits, holds about to be lost, fingers
closing in on each other, the regrasp chain's first finger brought forward), the other
fingers' configurations over time (:func:`q_hand_of`) and the hold a landing starts
(:func:`landing_hold`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

import numpy as np

from ..exceptions import PlanningError
from ..grasp.holding import Holding, holding_q, start_holding
from ..grasp.manifold import Manifold
from ..model.scene import Scene
from ..plan import ContactPhase, RegraspPhase, ReleasePhase
from .join import Join
from .params import PlannerParams
from .proximity import holding_proximity
from .regrasp import RegraspResult
from .release import Release
from .schedule import TIME_TOL_S, held_until, regrasp_chain
from .search import RegraspSearch, SearchBudget

__all__ = [
    "HandMotion",
    "PlanContext",
    "PlanState",
    "Trigger",
    "hold_ends",
    "landing_hold",
    "loss_reason",
    "pending_triggers",
    "q_hand_of",
]


@dataclass(frozen=True)
class PlanState:
    """Where the plan stands: who holds what since when, and what was done."""

    holding: dict[str, Holding]
    history: dict[str, tuple[Holding, ...]]
    phases: dict[str, tuple]
    regrasps: tuple[RegraspResult, ...]
    now: float  # no regrasp may start before this (one finger in the air)
    held_to_end: dict[str, str]
    released: dict[str, Release] = field(default_factory=dict)
    joined: dict[str, Join] = field(default_factory=dict)
    #: the earlier moves of fingers that let go and joined again: each release cut
    #: where the finger's join starts, and a join it made before
    ended: tuple[Release | Join, ...] = ()


@dataclass
class PlanContext:
    """The fixed problem of one plan and what its searches share: the scene, the time
    grid of the holds, the parameters, the fingers that take part, the regrasp search,
    its budget, the idle fingers' configuration ``base_q``, the manifolds (an idle
    finger's built when it joins), the options already taken at a state
    (``tried``), where let-go fingers park and the let-go and join outcomes already
    planned (``releases``, ``joins``, see :func:`~.letgo.let_go`)."""

    scene: Scene
    grid: np.ndarray
    params: PlannerParams
    active: tuple[str, ...]
    search: RegraspSearch
    budget: SearchBudget
    base_q: np.ndarray
    manifolds: dict[str, Manifold]
    tried: set[tuple] = field(default_factory=set)  # (state signature, option) taken
    parks: dict[str, np.ndarray] = field(default_factory=dict)  # where let-go fingers go
    releases: dict[tuple, Release | PlanningError] = field(default_factory=dict)
    joins: dict[tuple, tuple[Join, Holding] | None] = field(default_factory=dict)


@dataclass(frozen=True)
class Trigger:
    """A finger that must let go: when, why, and until when it can still hold [s]
    (``lost_near``: the finger whose approach ends the hold, if that is what ends it)."""

    time_s: float
    finger: str
    reason: str
    lost_s: float
    lost_near: str | None = None


def pending_triggers(
    ctx: PlanContext, state: PlanState, gone: tuple[str, ...] = ()
) -> list[Trigger]:
    """The pending triggers, earliest first (ties by name): a contact near its joint
    limits (or infeasible), or a holding finger near another finger (holding, idle,
    or let go: backing off, parking or still; ``gone``: fingers that are neither, e.g.
    one about to let go)."""
    p = ctx.params
    times = ctx.grid[ctx.grid >= state.now - TIME_TOL_S]
    # a finger that let go moves while it backs off and parks (another finger may
    # regrasp meanwhile and land near it), then stays
    base = with_released(ctx, state, times, np.tile(ctx.base_q, (times.size, 1)))
    prox = holding_proximity(
        ctx.scene.hand,
        state.holding,
        times,
        base,
        trigger_m=p.contact.finger_trigger_m,
        lost_m=p.regrasp.finger_clearance_m,
        still=[n for n in ctx.scene.hand.finger_names if n not in state.holding and n not in gone],
    )
    out = []
    for name, h in state.holding.items():
        if name in state.held_to_end:
            continue
        t, why = h.track.trigger()
        lost = held_until(h.track, p.contact)
        loss = loss_reason(h, lost)
        near = prox.get(name)
        lost_near = None
        if near is not None:
            if near.lost_s - p.dt_s < lost:
                lost, loss, lost_near = near.lost_s - p.dt_s, near.reason, near.other
            if t is None or near.trigger_s < t:
                t, why = near.trigger_s, near.reason
        # a hold that will be lost triggers at least one regrasp (and the lead) before:
        # a margin that closes fast (a link nearing the object) leaves no time otherwise
        due = lost - p.regrasp.duration_s - p.lead_s
        if lost < ctx.scene.motion.t_end - TIME_TOL_S and (t is None or due < t):
            t = max(due, state.now, h.t_from)
            why = f"its hold is lost after t={lost:.3f} s ({loss})"
        if t is not None:
            out.append(Trigger(t, name, why, lost, lost_near))
    return sorted(_chain_first(ctx, state, out), key=lambda e: (round(e.time_s, 9), e.finger))


def _chain_first(ctx: PlanContext, state: PlanState, triggers: list[Trigger]) -> list[Trigger]:
    """``triggers`` with the first finger of the regrasp chain (:func:`regrasp_chain`)
    triggered by the chain's latest start, if that comes before its own trigger: holds
    that end close together cannot wait for each other's triggers."""
    p = ctx.params
    end = ctx.scene.motion.t_end - TIME_TOL_S
    lost = {e.finger: e.lost_s for e in triggers if e.lost_s < end}
    chain = regrasp_chain(lost, p.regrasp.duration_s)
    if len(chain.order) < 2:
        return triggers
    first = next(e for e in triggers if e.finger == chain.order[0])
    if chain.latest_start_s >= first.time_s - TIME_TOL_S:
        return triggers
    h = state.holding[first.finger]
    early = replace(
        first,
        time_s=max(chain.latest_start_s, state.now, h.t_from),
        reason=(
            f"{chain.binding}'s hold is lost at t={lost[chain.binding or '']:.3f} s, "
            f"so the regrasps of {', '.join(chain.order)} must start by "
            f"t={chain.latest_start_s:.3f} s"
        ),
    )
    return [early if e is first else e for e in triggers]


def loss_reason(h: Holding, lost_s: float) -> str:
    """Why the hold ends right after ``lost_s`` [s] (the track's reason there)."""
    k = int(np.searchsorted(h.track.times_s, lost_s + TIME_TOL_S))
    reasons = h.track.reasons
    return reasons[min(k, len(reasons) - 1)] or "it leaves the joint limits"


class HandMotion:
    """The hand's configurations over time ``(S,) -> (S, nq)`` [rad] with the ``stay``
    fingers holding (exact IK, :func:`~regrasp_pin.grasp.holding.holding_q`), the
    fingers that let go where their releases put them, the others at the plan's base
    configuration.

    :attr:`key` digests everything those configurations follow from (the base
    configuration, each holding finger's contact and track, each release's samples;
    the hand, the motion and the IK tolerance are the plan's): two of one plan with the
    same key give the same configurations at any times, bit for bit.
    """

    def __init__(self, ctx: PlanContext, state: PlanState, stay: list[str]):
        self._ctx, self._state, self._stay = ctx, state, list(stay)
        self._key: bytes | None = None

    def __call__(self, times: np.ndarray) -> np.ndarray:
        """The configurations ``(S, nq)`` [rad] at ``times`` ``(S,)`` [s]."""
        ctx, state = self._ctx, self._state
        hand, motion = ctx.scene.hand, ctx.scene.motion
        q = np.broadcast_to(ctx.base_q, (times.size, hand.model.nq)).copy()
        for n in self._stay:
            q[:, hand.fingers[n].q_indices] = holding_q(
                hand, motion, n, state.holding[n], times, ctx.params.contact.ik_tol_m
            )
        return with_released(ctx, state, times, q)

    @property
    def key(self) -> bytes:
        """The digest of what the configurations follow from (computed once)."""
        if self._key is None:
            digest = hashlib.sha1(np.ascontiguousarray(self._ctx.base_q, float).tobytes())
            for n in sorted(self._stay):
                h = self._state.holding[n]
                tr = h.track
                digest.update(n.encode() + b"\0")
                for a in (h.p, h.n, tr.times_s, tr.q, [tr.followed_until_s]):
                    digest.update(np.ascontiguousarray(a, float).tobytes())
            for n in sorted(self._state.released):
                rel = self._state.released[n]
                digest.update(b"released " + n.encode() + b"\0")
                for a in (rel.times_s, rel.q):
                    digest.update(np.ascontiguousarray(a, float).tobytes())
            self._key = digest.digest()
        return self._key


def q_hand_of(ctx: PlanContext, state: PlanState, stay: list[str]) -> HandMotion:
    """Hand configurations over time with the ``stay`` fingers holding (exact IK):
    a :class:`HandMotion`."""
    return HandMotion(ctx, state, stay)


def with_released(
    ctx: PlanContext, state: PlanState, times: np.ndarray, q: np.ndarray
) -> np.ndarray:
    """The hand configurations ``q`` ``(T, nq)`` at ``times`` [s], changed in place,
    with the fingers that let go where their releases put them: backing off, parking,
    then still."""
    for n, rel in state.released.items():
        idx = ctx.scene.hand.fingers[n].q_indices
        for j in range(idx.size):
            q[:, idx[j]] = np.interp(times, rel.times_s, rel.q[:, j])
    return q


def hold_ends(
    state: PlanState, name: str, t_s: float, phase: RegraspPhase | ReleasePhase
) -> PlanState:
    """``state`` with ``name``'s current hold ended at ``t_s`` [s] and ``phase`` after it
    (who holds what, and the time, are the caller's to change)."""
    h = state.holding[name]
    hold = ContactPhase(finger=name, t_start=h.t_from, t_end=t_s, p_object=h.p, n_object=h.n)
    return replace(
        state,
        history={**state.history, name: (*state.history[name], replace(h, t_to=t_s))},
        phases={**state.phases, name: (*state.phases[name], hold, phase)},
    )


def landing_hold(ctx: PlanContext, name: str, res: RegraspResult | Join) -> Holding:
    """The hold that follows a regrasp's landing."""
    return start_holding(
        ctx.scene.hand,
        ctx.scene.obj,
        ctx.scene.motion,
        ctx.grid,
        name,
        res.Q_object,
        res.n_Q_object,
        res.q[-1],
        res.t_end,
        ctx.params.contact,
    )
