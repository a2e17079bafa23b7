"""Whole-hand manipulation by regrasping (the paper's test, section 3).

The object follows its motion ``T_palm_object(t)``. Every finger holds a contact fixed
in the object frame and follows it by IK; when a contact comes within the trigger
margin of a boundary plane (or stops being feasible), that finger regrasps -- lifts
off, travels around the object and lands on a new contact Q -- while the others keep
holding. One finger is in the air at a time.

Scheduling. Triggers are taken in time order. A regrasp starts ``lead_s`` before its
trigger, earlier if the next finger's trigger would otherwise fall inside it (so that
finger can go right after), and never while the fingers that stay would lose force
closure or be fewer than ``min_holding``. Each regrasp phase records why it started
when it did. A motion that cannot be achieved raises :class:`~.exceptions.PlanningError`
with the finger, the time, the reason and the partial plan up to that time.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .contact import ContactModel
from .contact_choice import Grasp, NewContact, choose_new_contact, initial_grasp
from .exceptions import ContactError, PlanningError, RegraspError
from .grasp_quality import ferrari_canny_epsilon
from .hand import Hand
from .holding import Holding, holding_q, holds_to_end, rest_configuration, start_holding
from .manifold import Manifold, build_manifold
from .motion import ObjectMotion
from .objects import ConvexObject, SurfaceSample
from .plan import ContactPhase, Plan, RegraspPhase
from .regrasp import RegraspParams, RegraspResult, plan_regrasp

__all__ = ["ManipulationPlan", "PlannerParams", "plan_manipulation"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlannerParams:
    """Parameters of the whole-hand planner.

    Attributes:
        dt_s: Time step of the holding phases [s].
        manifold_dt_s: Time step of the joint-space manifolds used to choose Q [s].
        sample_spacing_m: Surface sampling spacing for the manifolds [m].
        lead_s: A regrasp starts at least this long before its trigger [s].
        min_holding: Fewest fingers that must hold while one is in the air.
        mu: Friction coefficient for force closure.
        candidates: How many new contacts Q to try per regrasp before giving up.
        exit_tolerance_s: New contacts whose exit times differ by less than this are
            ties, broken by the shorter move (see :func:`~.contact_choice.choose_new_contact`).
        earlier_starts_s: When no verified regrasp starts at the scheduled time, the
            planner retries this much earlier [s] (0 first).
        fingers: The fingers that take part (default: all). The others stay idle at
            the configuration of :func:`rest_configuration`, as obstacles that every
            regrasp is verified against.
        contact: The contact model (trigger margin, pad cone, tolerances).
        regrasp: Parameters of each regrasp.
    """

    dt_s: float = 0.01
    manifold_dt_s: float = 0.05
    sample_spacing_m: float = 0.002
    lead_s: float = 0.02
    min_holding: int = 3
    mu: float = 0.8
    candidates: int = 6
    fingers: tuple[str, ...] | None = None
    earlier_starts_s: tuple[float, ...] = (0.0, 0.1, 0.2)
    exit_tolerance_s: float = 0.25
    contact: ContactModel = field(default_factory=ContactModel)
    regrasp: RegraspParams = field(default_factory=RegraspParams)


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
        grasp: Initial grasp; found by :func:`~.contact_choice.initial_grasp` if None.
        params: :class:`PlannerParams`.
        progress: Called with the planned time [s] as planning advances (e.g. to
            drive a progress bar).

    Returns:
        A :class:`ManipulationPlan`.

    Raises:
        ContactError: no initial grasp.
        PlanningError: the motion cannot be achieved; ``partial`` holds the plan up to
            the failure.
    """
    params = params or PlannerParams()
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
    if grasp is None:
        grasp = initial_grasp(hand, obj, manifolds, sample, contact=params.contact, mu=params.mu)
    stage["initial grasp"] = time.perf_counter() - t0

    grid = np.arange(motion.t_start, motion.t_end + 1e-9, params.dt_s)
    if grid[-1] < motion.t_end - 1e-9:
        grid = np.append(grid, motion.t_end)
    grid[-1] = min(grid[-1], motion.t_end)

    t0 = time.perf_counter()
    holding: dict[str, Holding] = {}
    for name in active:
        holding[name] = start_holding(
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
    phases: dict[str, list] = {name: [] for name in active}
    regrasps: list[RegraspResult] = []
    stage["tracking"] = time.perf_counter() - t0
    stage["regrasps"] = 0.0
    now = motion.t_start  # no regrasp may start before this (one finger in the air)
    D = params.regrasp.duration_s

    history: dict[str, list[Holding]] = {name: [] for name in active}
    held_to_end: dict[str, str] = {}

    def partial_plan(until: float) -> Plan:
        """The plan up to ``until``: every finger holding its current contact."""
        for n, h in holding.items():
            if h.t_from < until:
                phases[n].append(
                    ContactPhase(
                        finger=n, t_start=h.t_from, t_end=until, p_object=h.p, n_object=h.n
                    )
                )
        return _assemble(
            hand,
            obj,
            motion,
            grid,
            history,
            holding,
            phases,
            regrasps,
            until=until,
            params=params,
            base_q=base_q,
        )

    while True:
        triggers = sorted(
            (h.track.trigger()[0], name)
            for name, h in holding.items()
            if h.track.trigger()[0] is not None and name not in held_to_end
        )
        triggers = [(t, n) for t, n in triggers if t is not None]
        if not triggers:
            break
        t_trig, name = triggers[0]
        reason_trig = holding[name].track.trigger()[1]
        start = t_trig - params.lead_s
        why = f"{reason_trig} at t={t_trig:.3f} s; lift-off {params.lead_s:.3f} s before"
        if len(triggers) > 1:
            t_next, next_name = triggers[1]
            if t_next - params.lead_s < start + D:
                start = t_next - params.lead_s - D
                why += f", moved earlier so that {next_name} (trigger t={t_next:.3f} s) can follow"
        start = max(start, now, holding[name].t_from)
        if start + D > motion.t_end and holds_to_end(holding[name].track, t_trig, params.contact):
            # too late to regrasp, but the contact stays inside the joint limits (within
            # the trigger margin only) and feasible until the motion ends: keep holding
            held_to_end[name] = (
                f"{reason_trig} at t={t_trig:.3f} s, too late for a regrasp; held to the end "
                "inside the joint limits"
            )
            log.info("%s: %s", name, held_to_end[name])
            continue
        if start + D > motion.t_end:
            # too late to regrasp before the end; holding to the trigger is impossible
            raise PlanningError(
                f"{reason_trig} at t={t_trig:.3f} s, but a regrasp ({D:.2f} s) would not end "
                "before the motion does",
                finger=name,
                time_s=t_trig,
                partial=partial_plan(min(t_trig, motion.t_end)),
            )
        if start > t_trig:
            raise PlanningError(
                f"{reason_trig} at t={t_trig:.3f} s while another finger is still in the air "
                f"(free from t={now:.3f} s)",
                finger=name,
                time_s=t_trig,
                partial=partial_plan(max(start, now)),
            )
        stay = [n for n in active if n != name]
        if len(stay) < params.min_holding:
            raise PlanningError(
                f"only {len(stay)} fingers would hold (need {params.min_holding})",
                finger=name,
                time_s=start,
                partial=partial_plan(max(start, now)),
            )
        p_stay = np.array([holding[n].p for n in stay])
        n_stay = np.array([holding[n].n for n in stay])
        eps_stay = ferrari_canny_epsilon(p_stay, n_stay, params.mu, torque_scale_m=obj.radius_m)
        if eps_stay <= 0.0:
            raise PlanningError(
                f"{reason_trig} at t={t_trig:.3f} s, but without it the other fingers are not "
                "in force closure",
                finger=name,
                time_s=start,
                partial=partial_plan(max(start, now)),
            )

        t_r = time.perf_counter()
        # if no verified regrasp starts there, try lifting off earlier (other contacts
        # are free then), never before the previous regrasp ended
        result: tuple[RegraspResult, object] | RegraspError = PlanningError("not tried")
        for early in params.earlier_starts_s:
            s_try = start - early
            if s_try < max(now, holding[name].t_from) - 1e-9:
                continue
            result = _regrasp(
                hand, obj, motion, manifolds[name], sample, name, s_try, holding, params, base_q
            )
            if not isinstance(result, RegraspError):
                if early > 0:
                    why += (
                        f"; lifted off {early:.2f} s earlier still: "
                        "no verified path from the first start"
                    )
                break
        # a regrasp that ends after another finger must let go leaves that finger no
        # time: lift off earlier by the overlap, if possible
        if not isinstance(result, RegraspError):
            others_trig = [holding[n].track.trigger()[0] for n in active if n != name]
            others_trig = [t for t in others_trig if t is not None]
            if others_trig:
                t_other = min(others_trig) - params.lead_s
                overlap = result[0].t_end - t_other
                s_try = result[0].t_start - overlap
                if overlap > 0 and s_try >= max(now, holding[name].t_from) - 1e-9:
                    earlier = _regrasp(
                        hand,
                        obj,
                        motion,
                        manifolds[name],
                        sample,
                        name,
                        s_try,
                        holding,
                        params,
                        base_q,
                    )
                    if not isinstance(earlier, RegraspError) and earlier[0].t_end <= t_other + 1e-9:
                        result = earlier
                        why += (
                            f"; lifted off {overlap:.2f} s earlier so that the next finger "
                            "can let go in time"
                        )
        stage["regrasps"] += time.perf_counter() - t_r
        if isinstance(result, RegraspError):
            raise PlanningError(
                f"no verified regrasp: {result}",
                finger=name,
                time_s=start,
                partial=partial_plan(max(start, now)),
            ) from result
        res, choice = result
        h = holding[name]
        phases[name].append(
            ContactPhase(
                finger=name, t_start=h.t_from, t_end=res.t_start, p_object=h.p, n_object=h.n
            )
        )
        phases[name].append(
            RegraspPhase(
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
                    "grid_path_object": res.grid_path.points_object.tolist(),
                    "tip_path_object": res.tip_path.points_object[
                        :: max(1, len(res.tip_path) // 200)
                    ].tolist(),
                    "path_length_m": res.path_length_m,
                    "m": int(res.waypoints_object.shape[0]),
                    "q_exit_time_s": choice.exit_time_s,
                    "quality_kept": choice.quality_kept,
                    "epsilon": choice.epsilon,
                    "stage_ms": res.stage_ms,
                    "attempts": list(res.attempts),
                },
            )
        )
        regrasps.append(res)
        h.t_to = res.t_start
        history[name].append(h)
        holding[name] = start_holding(
            hand,
            obj,
            motion,
            grid,
            name,
            res.Q_object,
            res.n_Q_object,
            res.q[-1],
            res.t_end,
            params.contact,
        )
        now = res.t_end
        if progress is not None:
            progress(now)
        log.info("%s regrasped at t=%.3f s (%s)", name, res.t_start, why)

    for name, h in holding.items():
        phases[name].append(
            ContactPhase(
                finger=name, t_start=h.t_from, t_end=motion.t_end, p_object=h.p, n_object=h.n
            )
        )
    t0 = time.perf_counter()
    plan = _assemble(
        hand,
        obj,
        motion,
        grid,
        history,
        holding,
        phases,
        regrasps,
        until=motion.t_end,
        params=params,
        base_q=base_q,
    )
    stage["assembly"] = time.perf_counter() - t0
    plan.summary.update(
        {
            "regrasps": len(regrasps),
            "fingers_regrasped": sorted({r.finger for r in regrasps}),
            "initial_epsilon": grasp.epsilon,
            "held_to_end": held_to_end,
            "stage_s": stage,
        }
    )
    return ManipulationPlan(plan, regrasps, grasp, manifolds, sample, stage)


def _regrasp(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    manifold: Manifold,
    sample: SurfaceSample,
    name: str,
    start: float,
    holding: dict[str, Holding],
    params: PlannerParams,
    base_q: np.ndarray,
) -> tuple[RegraspResult, object] | RegraspError:
    f = hand.fingers[name]
    h = holding[name]
    stay = {n: (holding[n].p, holding[n].n) for n in holding if n != name}
    # exact IK at the lift-off time so the regrasp starts on P
    q_start = holding_q(hand, motion, name, h, np.array([start]), params.contact.ik_tol_m)[0]
    others_tips = np.array([p + hand.fingers[n].tip_radius * nn for n, (p, nn) in stay.items()])

    def q_hand(times: np.ndarray) -> np.ndarray:
        q = np.broadcast_to(base_q, (times.size, hand.model.nq)).copy()
        for n in stay:
            q[:, hand.fingers[n].q_indices] = holding_q(
                hand, motion, n, holding[n], times, params.contact.ik_tol_m
            )
        return q

    failed: list[np.ndarray] = []
    last: RegraspError | None = None

    def choose(duration: float) -> NewContact:
        return choose_new_contact(
            hand,
            obj,
            manifold,
            sample,
            start + duration,
            P_object=h.p,
            n_P_object=h.n,
            others=stay,
            contact=params.contact,
            mu=params.mu,
            exclude_radius_m=2 * f.tip_radius,
            exclude_points_object=np.array(failed) if failed else None,
            q_hand_arrive=q_hand(np.array([start + duration]))[0],
            finger_clearance_m=0.001,
            exit_tolerance_s=params.exit_tolerance_s,
        )

    def attempt(choice: NewContact, duration: float) -> RegraspResult:
        return plan_regrasp(
            hand,
            obj,
            motion,
            name,
            start,
            h.p,
            h.n,
            choice.p_object,
            choice.n_object,
            q_start,
            q_hand,
            others_tips_object=others_tips,
            params=replace(params.regrasp, duration_s=duration),
        )

    for _ in range(params.candidates):
        duration = params.regrasp.duration_s
        try:
            choice = choose(duration)
            # long moves take longer: a minimum-jerk profile peaks at 1.875 x the mean
            # speed; 1.5 more for a path that is not straight in joint space
            needed = (
                1.875 * 1.5 * float(np.max(np.abs(choice.q_arrive - q_start) / f.velocity_limit))
            )
            if needed > duration and start + needed <= motion.t_end:
                duration = float(np.ceil(needed / params.dt_s) * params.dt_s)
                choice = choose(duration)
        except ContactError as exc:
            return exc if last is None else last
        try:
            return attempt(choice, duration), choice
        except RegraspError as exc:
            log.info("regrasp %s to %s failed: %s", name, choice.p_object.round(4), exc)
            last = exc
            if "rad/s" in str(exc) and start + 1.5 * duration <= motion.t_end:
                # too fast for the joints: the same start, a longer regrasp, a new Q
                try:
                    choice = choose(1.5 * duration)
                    return attempt(choice, 1.5 * duration), choice
                except RegraspError as exc2:
                    last = exc2
            failed.append(choice.p_object)
    return last if last is not None else PlanningError("no candidate", finger=name, time_s=start)


def _assemble(
    hand: Hand,
    obj: ConvexObject,
    motion: ObjectMotion,
    grid: np.ndarray,
    history: dict[str, list[Holding]],
    holding: dict[str, Holding],
    phases: dict[str, list],
    regrasps: list[RegraspResult],
    *,
    until: float,
    params: PlannerParams,
    base_q: np.ndarray,
) -> Plan:
    """Sample the whole hand: grid times outside the regrasps, the regrasps' own samples
    inside them (so linear interpolation between samples is what was verified).

    Holding fingers are placed by exact IK on their contact at every sample (warm from
    their track), which is exactly what the regrasp verification used for them.
    """
    keep = np.ones(grid.size, bool)
    for r in regrasps:
        keep &= ~((grid > r.t_start - 1e-9) & (grid < r.t_end + 1e-9))
    times = np.unique(np.round(np.concatenate([grid[keep]] + [r.times_s for r in regrasps]), 9))
    times = times[times <= until + 1e-9]
    if times.size < 2:
        times = np.array([motion.t_start, max(until, motion.t_start + params.dt_s)])
    q = np.broadcast_to(base_q, (times.size, hand.model.nq)).copy()
    for name in holding:
        f = hand.fingers[name]
        in_air = np.zeros(times.size, bool)
        for r in regrasps:
            if r.finger == name:
                sel = (times >= r.t_start - 1e-9) & (times <= r.t_end + 1e-9)
                for j in range(f.k):
                    q[sel, f.q_indices[j]] = np.interp(times[sel], r.times_s, r.q[:, j])
                in_air |= sel
        for h in [*history[name], holding[name]]:
            b = h.t_to if h.t_to is not None else until
            sel = (times >= h.t_from - 1e-9) & (times <= b + 1e-9) & ~in_air
            if sel.any():
                q[np.ix_(np.flatnonzero(sel), f.q_indices)] = holding_q(
                    hand, motion, name, h, times[sel], params.contact.ik_tol_m
                )
    hand_dict = {
        "name": hand.name,
        "urdf": _urdf_entry(hand),
        "fingers": {
            n: {"tip_frame": f.tip_frame, "tip_radius": f.tip_radius, "joints": list(f.joint_names)}
            for n, f in hand.fingers.items()
        },
    }
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
        phases={n: list(ps) for n, ps in phases.items()},
        summary={},
    )


def _urdf_entry(hand: Hand) -> str:
    from .plan import repo_root

    path = hand.urdf_path.resolve()
    try:
        return str(path.relative_to(repo_root()))
    except ValueError:
        return str(path)
