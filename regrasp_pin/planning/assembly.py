"""The plan file's content from a planner state: the whole hand sampled over time.

:func:`plan_until` turns a :class:`~.state.PlanState` (holds, regrasps, releases,
joins) into a :class:`~regrasp_pin.plan.Plan` up to a time: grid times outside the
moves, the moves' own samples inside them, the holding fingers placed by exact IK.
"""

from __future__ import annotations

import numpy as np

from ..exceptions import FailureKind, PlanningError
from ..grasp.holding import Holding, holding_q
from ..model.clearance import LinkClearance
from ..model.hand import Hand
from ..model.motion import ObjectMotion
from ..model.objects import ConvexObject
from ..plan import ContactPhase, IdlePhase, Plan, hand_record
from .join import Join
from .params import PlannerParams
from .regrasp import RegraspResult
from .release import Release
from .schedule import TIME_TOL_S
from .state import PlanContext, PlanState
from .timing import check_joint_speed

__all__ = ["joint_speed_failure", "object_penetration_failure", "plan_until"]


def plan_until(ctx: PlanContext, state: PlanState, until: float, *, final: bool = False) -> Plan:
    """The plan up to ``until``: every finger holding its current contact to then (the
    whole plan with ``final``, which keeps a hold that starts at the very end)."""
    phases = {n: list(state.phases[n]) for n in state.released}
    for n, h in state.holding.items():
        hold = ContactPhase(finger=n, t_start=h.t_from, t_end=until, p_object=h.p, n_object=h.n)
        phases[n] = [*state.phases[n], *([hold] if final or h.t_from < until else [])]
    return _assemble(
        ctx.scene.hand,
        ctx.scene.obj,
        ctx.scene.motion,
        ctx.grid,
        state.history,
        state.holding,
        phases,
        [*state.regrasps, *state.ended, *state.released.values(), *state.joined.values()],
        until=until,
        params=ctx.params,
        base_q=ctx.base_q,
    )


def _assemble(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    grid: np.ndarray,
    history: dict[str, tuple[Holding, ...]],
    holding: dict[str, Holding],
    phases: dict[str, list],
    regrasps: list[RegraspResult | Release | Join],
    *,
    until: float,
    params: PlannerParams,
    base_q: np.ndarray,
) -> Plan:
    """Sample the whole hand: grid times outside the regrasps (and releases), their own
    samples inside them (so linear interpolation between samples is what was verified).

    Holding fingers are placed by exact IK on their contact at every sample (warm from
    their track), which is exactly what the regrasp verification used for them.
    """
    keep = np.ones(grid.size, bool)
    for r in regrasps:
        keep &= ~((grid > r.t_start - TIME_TOL_S) & (grid < r.t_end + TIME_TOL_S))
    times = np.unique(np.round(np.concatenate([grid[keep]] + [r.times_s for r in regrasps]), 9))
    times = times[times <= until + TIME_TOL_S]
    if times.size < 2:
        times = np.array([motion.t_start, max(until, motion.t_start + params.dt_s)])
    q = np.broadcast_to(base_q, (times.size, hand.model.nq)).copy()
    for name in history:
        f = hand.fingers[name]
        in_air = np.zeros(times.size, bool)
        for r in regrasps:
            if r.finger == name:
                sel = (times >= r.t_start - TIME_TOL_S) & (times <= r.t_end + TIME_TOL_S)
                for j in range(f.k):
                    q[sel, f.q_indices[j]] = np.interp(times[sel], r.times_s, r.q[:, j])
                in_air |= sel
        for h in [*history[name], *([holding[name]] if name in holding else [])]:
            b = h.t_to if h.t_to is not None else until
            sel = (times >= h.t_from - TIME_TOL_S) & (times <= b + TIME_TOL_S) & ~in_air
            if sel.any():
                q[np.ix_(np.flatnonzero(sel), f.q_indices)] = holding_q(
                    hand, motion, name, h, times[sel], params.contact.ik_tol_m
                )
    hand_dict = hand_record(hand)
    verts, faces = obj.mesh()
    obj_dict = {
        "kind": obj.kind,
        "params": obj.params,
        "vertices": np.asarray(verts).tolist(),
        "faces": np.asarray(faces).tolist(),
    }
    return Plan(
        hand=hand_dict,
        object=obj_dict,
        t=times,
        q=q,
        T_palm_object=motion.as_xyzquat(times),
        phases=_with_idle(hand, phases, float(times[0]), float(times[-1])),
        summary={},
        mu=params.mu,
        torsion_m=params.contact.torsion_m,
    )


def joint_speed_failure(hand: Hand, times: np.ndarray, q: np.ndarray) -> PlanningError | None:
    """The first finger (in the hand's order) of the hand configurations ``q``
    ``(S, nq)`` [rad] at ``times`` ``(S,)`` [s] that moves a joint faster than its
    velocity limit between two samples, as :func:`~.timing.check_joint_speed`'s
    ``velocity`` PlanningError (its fastest joint); None if none does. The assembled
    plan's holds are placed by IK at every sample, so their speeds are checked here,
    where the plan's samples are known."""
    for name in hand.finger_names:
        f = hand.fingers[name]
        try:
            check_joint_speed(name, f.joint_names, f.velocity_limit, times, q[:, f.q_indices])
        except PlanningError as exc:
            return exc
    return None


def object_penetration_failure(
    hand: Hand,
    obj: ConvexObject,
    times: np.ndarray,
    q: np.ndarray,
    T_palm_object: np.ndarray,
    allowed_m: float,
) -> PlanningError | None:
    """The first finger (in the hand's order) one of whose geometries, fingertip
    included, enters the object by more than ``allowed_m`` [m] at one of the samples
    ``times`` ``(S,)`` [s] of the hand configurations ``q`` ``(S, nq)`` [rad], the object
    at ``T_palm_object`` ``(S, 4, 4)`` (Coal), as an ``object-clearance`` PlanningError
    (that finger's deepest sample); None if none does.

    Every move was verified on its own samples and every hold tracked on the time
    grid, but the holds are placed by IK at the plan's samples, and a rule of the
    search that let a hold's loss through (one lost at the motion's last sample used
    to count as held to the end) would show only in the plan. So the whole plan is
    measured once more here, as the re-check of its file will measure it
    (:func:`~regrasp_pin.verify.plan_check.recheck_plan`): a safety net."""
    for name in hand.finger_names:
        d = LinkClearance(hand, name, obj, include_tip=True)(q, T_palm_object)
        i = int(np.argmin(d))
        if d[i] < -allowed_m:
            return PlanningError(
                f"a geometry of the finger enters the object by {-1e3 * d[i]:.3f} mm "
                f"(at most {1e3 * allowed_m:.3f} mm allowed) in the assembled plan",
                finger=name,
                time_s=float(times[i]),
                kind=FailureKind.OBJECT_CLEARANCE,
                measured=float(d[i]),
                required=-float(allowed_m),
            )
    return None


def _with_idle(hand: Hand, phases: dict[str, list], t0: float, t1: float) -> dict[str, list]:
    """Every finger's phases from ``t0`` to ``t1`` [s]: an ``idle`` phase for a finger
    that takes no part, and before the ``join`` of one that joins later."""
    out = {n: list(ps) for n, ps in phases.items()}
    for name in hand.finger_names:
        ps = out.get(name, [])
        start = min(ps[0].t_start, t1) if ps else t1
        if start > t0 + TIME_TOL_S:
            out[name] = [IdlePhase(name, t0, start), *ps]
    return out
