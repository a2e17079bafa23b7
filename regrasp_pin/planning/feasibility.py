"""What no plan can do: the runs in which a finger cannot let go, and the first one
that no plan gets through (:mod:`~regrasp_pin.grasp.necessity` applied to a plan's
start).
"""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import FailureKind, PlanningError
from ..grasp.choice import exit_times
from ..grasp.holding import Holding
from ..grasp.manifold import Manifold
from ..grasp.necessity import MustHold, must_hold, with_idle_fingers
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject, SurfaceSample
from .assembly import plan_until
from .params import PlannerParams
from .schedule import TIME_TOL_S
from .state import PlanContext, PlanState

__all__ = ["first_infeasibility", "longest_start_hold", "must_hold_runs", "no_plan_exists"]


def must_hold_runs(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    sample: SurfaceSample,
    m_times: np.ndarray,
    manifolds: dict[str, Manifold],
    params: PlannerParams,
) -> tuple[dict[str, Manifold], list[MustHold]]:
    """The manifolds of every finger that could hold and the runs in which a finger
    cannot let go (:func:`~regrasp_pin.grasp.necessity.must_hold`).

    An idle finger may join in place of one that lets go (:mod:`.planning.letgo`), so it
    counts among those that could hold; its manifold is the one a join would build. It
    is examined too: where the others cannot hold without it (e.g. only three fingers
    have a usable contact at all), it must be holding, on one contact through the run,
    though it did not start in the grasp. The runs are only claimed when every flight
    spans a grid time (regrasps last longer than the grid step), as the proof needs, and
    ``params.prove_infeasible``; else there are none.
    """
    step = float(np.diff(m_times).max()) if m_times.size > 1 else np.inf
    if not params.prove_infeasible or params.regrasp.duration_s <= step + TIME_TOL_S:
        return dict(manifolds), []
    every = (
        with_idle_fingers(hand, manifolds, sample, motion, params.contact)
        if params.release
        else dict(manifolds)
    )
    # a plan holds to the motion's end, its last sample included (planning.state)
    return every, must_hold(
        every, sample, obj, params.mu, list(every), torsion_m=params.contact.torsion_m
    )


def longest_start_hold(man: Manifold, margin_rad: float) -> float:
    """How long a finger could hold without a regrasp, by its manifold: the time [s] at
    which the longest-lasting of the contacts it can hold at the manifold's first time
    (:meth:`~regrasp_pin.grasp.manifold.Manifold.holdable` with ``margin_rad``) stops
    being holdable; ``math.inf`` if one stays holdable to the last time, the first time
    if none is holdable there.

    An estimate on the manifold's sample of the surface and its time grid, read as the
    choice of contacts reads it: the tracking of a hold (Coal, the velocity limits) may
    end it sooner. Below the motion's end it says that every plan in which the finger
    holds from the start must let it go at least once, whatever contact it starts on.
    """
    holdable = man.holdable(margin_rad)
    if holdable.all(axis=0).any():
        return math.inf
    # a contact not holdable at the first time exits there (exit_times)
    exits = exit_times(holdable, man.times_s, 0)
    return float(exits.max()) if exits.size else float(man.times_s[0])


def _held_until(ctx: PlanContext, h: Holding, t_to: float) -> float | None:
    """The first time in ``[h.t_from, t_to]`` at which the tracked hold ``h`` is lost
    (not reached, not within the velocity limits, outside the joint limits or the pad
    turned away), or None if it is held."""
    tr, c = h.track, ctx.params.contact
    sel = (tr.times_s <= min(t_to, ctx.scene.motion.t_end) + TIME_TOL_S) & (
        tr.times_s >= h.t_from - TIME_TOL_S
    )
    lost = sel & tr.lost(c)
    return float(tr.times_s[np.argmax(lost)]) if lost.any() else None


def first_infeasibility(
    ctx: PlanContext, state: PlanState, runs: list[MustHold]
) -> tuple[MustHold, float] | None:
    """The first run that no plan can get through, with the time the finger's contact
    leaves its limits: a run from the start that the finger's tracked starting hold
    does not last through, or a later run no contact of the finger lasts through (as
    the manifolds find; the finger idle or holding); None if there is none."""
    bad = []
    for run in runs:
        held = state.holding.get(run.finger)
        if held is not None and run.k_from == 0:
            lost = _held_until(ctx, held, run.t_to_s)
            if lost is not None:
                bad.append((run, lost))
        elif run.k_from > 0 and not run.possible:
            man = ctx.manifolds[run.finger]
            usable = man.usable(0.0)
            last = exit_times(usable[:, usable[run.k_from]], man.times_s, run.k_from)
            bad.append((run, float(last.max()) if last.size else run.t_from_s))
    return min(bad, key=lambda b: (b[0].k_from, b[0].finger), default=None)


def no_plan_exists(
    ctx: PlanContext, found: tuple[MustHold, float], state: PlanState
) -> PlanningError:
    """The INFEASIBLE failure of a finger that cannot let go during a run but cannot
    hold that long either; the partial plan is the start."""
    run, lost = found
    which = "its contact does not stay" if run.k_from == 0 else "none of its contacts stays"
    return PlanningError(
        f"no plan exists: from t={run.t_from_s:.3f} s to t={run.t_to_s:.3f} s no grasp "
        f"without it is in force closure, so it must hold without letting go, but "
        f"{which} within its joint limits that long (it leaves them at t={lost:.3f} s)",
        finger=run.finger,
        time_s=run.t_from_s,
        partial=plan_until(ctx, state, ctx.scene.motion.t_start),
        kind=FailureKind.INFEASIBLE,
        measured=lost - run.t_from_s,
        required=run.duration_s,
    )
