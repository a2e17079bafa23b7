"""Planning a scenario, backing up to another initial grasp after a failure.

The initial grasp is each plan's first decision, and the planner's own backtracking
(:mod:`regrasp_pin.planning.recovery`) never changes it. When a plan fails at a finger
that still holds the contact it started on, that start led there: :func:`plan_scenario`
chooses another start for that finger the way the scenario's grasp was chosen
(``Scenario.grasp_search``) and plans again, on what is left of the search budget:

- after a ``force-closure`` failure (the others do not hold without the finger) the
  finger starts on a contact it holds to the end
  (:func:`~regrasp_pin.scenarios.contacts_held_through`; if it has none, there is no
  backup): starting it anywhere else would only meet the same failure later (in the
  default suite, 0 of 20 such backups planned);
- after any other failure it starts more than two of its tip radii from every contact
  it started on before (``grasp_for_motion(avoid=...)``).

The search is the one that chose the scenario's grasp, on its motion: for a turn that
was placed about the pivot's contact after the grasp was chosen for the turn about the
object's own axis (:func:`~regrasp_pin.scenarios.make_scenario`, the suite's
contact-axis specs), that own-axis turn; for :func:`~regrasp_pin.scenarios.scenario_for_hand`,
which chose the others' contacts again for the turn about the pivot, that turn.

There is no backup after a proof that no plan exists (``infeasible``: it holds for
every grasp), for the finger whose contact places the motion (``GraspSearch.pivot``:
every backup keeps its contact, and so the motion), or for a scenario whose grasp was
given rather than chosen (``grasp_search`` None).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._validate import positive_int
from .exceptions import ContactError, FailureKind, PlanningError
from .plan import Plan
from .planning.planner import ManipulationPlan, PlannerParams, plan_manipulation
from .planning.setup import PlanSetup, plan_setup
from .scenarios import Scenario, contacts_held_through

__all__ = ["HOLD_THROUGH", "GraspBackup", "plan_scenario", "recorded_backups"]

#: plan_scenario's ``progress`` and ``on_backup``
_Report = tuple[Callable[[float], None] | None, Callable[[str, str], None] | None]

#: A failure of this kind means that the others do not hold without the finger: its
#: backup starts it on a contact it holds to the end instead of anywhere else
HOLD_THROUGH = FailureKind.FORCE_CLOSURE


@dataclass(frozen=True)
class GraspBackup:
    """One backup to another initial grasp (:func:`plan_scenario`).

    Attributes:
        after: The kind of the failure backed up from (a ``FailureKind`` value).
        finger: The finger whose start contact changed.
        avoid_m: Its start contact before, object frame ``(3,)`` [m].
        how: ``"elsewhere"`` (more than two tip radii from every earlier start of it) or
            ``"held-through"`` (a contact it holds to the motion's end).
        outcome: ``"ok"`` (a full plan), the kind of the backup's own failure,
            ``"no-grasp:<kind>"`` (no such grasp), ``"none-held-through"``,
            ``"no-time"`` (the wall-clock budget was spent) or
            ``"exception:<Type>: <message>"`` (an unexpected error while choosing or
            planning it; the first failure stands).
        time_s: When the backup's plan failed [s], or None.
        choose_s: Wall time of choosing the grasp [s].
        plan_s: Wall time of its planning [s] (0 when it was not planned).
    """

    after: str
    finger: str
    avoid_m: tuple[float, ...]
    how: str
    outcome: str
    time_s: float | None = None
    choose_s: float = 0.0
    plan_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON values (``avoid_m`` as a list)."""
        d = dataclasses.asdict(self)
        d["avoid_m"] = list(self.avoid_m)
        return d


def plan_scenario(
    scenario: Scenario,
    *,
    params: PlannerParams | None = None,
    grasp_backups: int = 1,
    progress: Callable[[float], None] | None = None,
    on_backup: Callable[[str, str], None] | None = None,
) -> ManipulationPlan:
    """Plan a scenario from its initial grasp, backing up to other initial grasps.

    :func:`~regrasp_pin.planning.planner.plan_manipulation` of the scenario; when it
    fails at a finger that still holds its start contact, up to ``grasp_backups``
    other starts for that finger are planned in turn (the module docstring says which).
    The backups share the search budget: each gets the steps that the plans before it
    left (``PlannerParams.max_steps``) and what their planning left of ``budget_s``
    [s] (a backup's grasp search is not counted; none left: outcome ``"no-time"``).
    What every plan builds before its search is built once
    (:func:`~regrasp_pin.planning.setup.plan_setup`): the backups plan the same hand,
    object and motion.

    Args:
        scenario: The scenario (its ``grasp``; ``grasp_search`` to back up).
        params: Planner settings; default the scenario's.
        grasp_backups: Most initial grasps to back up to (0: none).
        progress: Called with the planned time [s] as planning advances; it goes back
            when the search backtracks, and to the start for a backup.
        on_backup: Called with the finger and the kind of the failure (a
            ``FailureKind`` value) when a backup, its grasp found, starts planning
            again.

    Returns:
        The first full plan. Its ``grasp`` is the start it planned from, and its plan's
        ``summary["grasp_backups"]`` lists the backups before it
        (:meth:`GraspBackup.to_dict`; empty when the first plan was full).

    Raises:
        InputError: ``grasp_backups`` is not a whole number >= 0.
        PlanningError: no full plan. The first plan's failure, whose partial plan's
            ``summary["grasp_backups"]`` lists the backups tried.
        ContactError: the scenario has no grasp and none is found.
    """
    backups = positive_int(grasp_backups, "grasp_backups", minimum=0)
    params = params or scenario.params
    t0 = time.perf_counter()
    # built once: each backup plans the same hand, object and motion
    setup = plan_setup(scenario.hand, scenario.obj, scenario.motion, params)
    first = _plan(scenario, _spent(params, time.perf_counter() - t0), progress, setup)
    if isinstance(first, ManipulationPlan):
        first.plan.summary["grasp_backups"] = []
        return first
    tried: list[GraspBackup] = []
    planned = _back_up(
        scenario,
        params,
        first,
        backups,
        tried,
        time.perf_counter() - t0,
        (progress, on_backup),
        setup,
    )
    record = [b.to_dict() for b in tried]
    if planned is not None:
        planned.plan.summary["grasp_backups"] = record
        return planned
    if isinstance(first.partial, Plan):
        first.partial.summary["grasp_backups"] = record
    raise first


def recorded_backups(
    outcome: ManipulationPlan | Plan | BaseException | None,
) -> list[dict[str, Any]]:
    """The backups (:meth:`GraspBackup.to_dict`) that :func:`plan_scenario` recorded
    with a plan (a :class:`ManipulationPlan` or its :class:`~regrasp_pin.plan.Plan`)
    or with a failure's partial plan; empty when none are recorded."""
    plan = outcome.plan if isinstance(outcome, ManipulationPlan) else outcome
    if isinstance(plan, BaseException):
        plan = getattr(plan, "partial", None)
    return (
        [dict(b) for b in plan.summary.get("grasp_backups", [])] if isinstance(plan, Plan) else []
    )


def _plan(
    scenario: Scenario,
    params: PlannerParams,
    progress: Callable[[float], None] | None,
    setup: PlanSetup,
) -> ManipulationPlan | PlanningError:
    """The scenario planned from ``setup``: its plan, or its PlanningError (other
    errors raise)."""
    try:
        return plan_manipulation(
            scenario.hand,
            scenario.obj,
            scenario.motion,
            grasp=scenario.grasp,
            params=params,
            progress=progress,
            setup=setup,
        )
    except PlanningError as exc:
        return exc


def _spent(params: PlannerParams, elapsed_s: float) -> PlannerParams:
    """``params`` with ``elapsed_s`` [s] taken off its wall-clock budget (if any)."""
    if params.budget_s is None:
        return params
    return dataclasses.replace(params, budget_s=max(params.budget_s - elapsed_s, 0.0))


def _steps_spent(exc: PlanningError) -> int:
    """The search steps a failed planning spent (its partial plan's summary)."""
    partial = exc.partial
    return int(partial.summary.get("search_steps", 0)) if isinstance(partial, Plan) else 0


#: The phases of a finger that is still on its start contact
_NOT_MOVED = ("contact", "idle")


def _backup_finger(scenario: Scenario, exc: PlanningError) -> str | None:
    """The finger whose start contact to change after the failure ``exc`` of a plan of
    ``scenario``, or None: not a proof that no plan exists, at a finger of the initial
    grasp that has not moved in the partial plan (no phase but holds, or nothing
    planned), not the pivot, and a scenario whose grasp was chosen (``grasp_search``)."""
    search, grasp, finger = scenario.grasp_search, scenario.grasp, exc.finger
    if (
        search is None
        or grasp is None
        or exc.kind == FailureKind.INFEASIBLE
        or not isinstance(exc.partial, Plan)
        or not isinstance(finger, str)
        or finger not in grasp.points_object
        or finger == search.pivot
    ):
        return None
    # a finger of the grasp that has not moved: it holds (``contact``), or it is
    # ``idle`` where nothing was planned for it (a plan that fails at its start)
    phases = exc.partial.phases.get(finger, [])
    return finger if all(ph.kind in _NOT_MOVED for ph in phases) else None


def _held_through(scenario: Scenario, finger: str, away: np.ndarray) -> int | None:
    """The best start contact (an index of the grasp search's 2 mm sample) that
    ``finger`` holds to the motion's end and that is more than two of its tip radii
    from ``away`` (its start contact), or None."""
    search = scenario.grasp_search
    assert search is not None
    held = contacts_held_through(
        scenario.hand,
        scenario.obj,
        scenario.motion,
        finger,
        contact=search.contact,
        grasp_dt_s=search.grasp_dt_s,
    )
    points = scenario.obj.sample_surface(0.002).points[held]
    radius = scenario.hand.finger(finger).tip_radius
    far = held[np.linalg.norm(points - away, axis=1) > 2.0 * radius]
    return int(far[0]) if far.size else None


def _another_start(
    scenario: Scenario, finger: str, hold: bool, avoid: dict[str, list[np.ndarray]]
) -> Scenario | str:
    """The scenario started from another grasp for ``finger`` (see the module
    docstring; ``avoid`` gains its start contact when it goes elsewhere), or why there
    is none: ``"none-held-through"`` or ``"no-grasp:<kind>"``."""
    search, grasp = scenario.grasp_search, scenario.grasp
    assert search is not None and grasp is not None
    point = np.asarray(grasp.points_object[finger], float)
    pivot = search.pivot
    keep = {pivot: int(grasp.indices[pivot])} if pivot in grasp.indices else {}
    if hold:
        index = _held_through(scenario, finger, point)
        if index is None:
            return "none-held-through"
        keep[finger] = index
    else:
        avoid.setdefault(finger, []).append(point)
    try:
        chosen = search.choose(
            scenario.hand,
            scenario.obj,
            keep=keep or None,
            avoid={n: np.array(p) for n, p in avoid.items()} or None,
        )
    except ContactError as no_grasp:
        return f"no-grasp:{no_grasp.kind.value}"
    return dataclasses.replace(scenario, grasp=chosen)


def _back_up(
    scenario: Scenario,
    params: PlannerParams,
    exc: PlanningError,
    backups: int,
    tried: list[GraspBackup],
    planning_s: float,
    report: _Report,
    setup: PlanSetup,
) -> ManipulationPlan | None:
    """Plan again from other initial grasps after ``exc`` (see :func:`plan_scenario`),
    appending each backup to ``tried``; the first full plan, or None. ``planning_s``
    is the wall time the planning took so far [s]; ``report``: :func:`plan_scenario`'s
    ``progress`` and ``on_backup``; ``setup``: the one every plan shares (a backup
    keeps the scenario's hand, object and motion)."""
    avoid: dict[str, list[np.ndarray]] = {}
    spent = _steps_spent(exc)
    while len(tried) < backups:
        finger = _backup_finger(scenario, exc)
        left = params.max_steps - spent
        if finger is None or left <= 0:
            return None
        budget = _spent(dataclasses.replace(params, max_steps=left), planning_s)
        backup, outcome = _one_backup(scenario, budget, exc, finger, avoid, report, setup)
        tried.append(backup)
        planning_s += backup.plan_s
        if outcome is None or isinstance(outcome, ManipulationPlan):
            return outcome
        exc, scenario = outcome
        spent += _steps_spent(exc)
    return None


def _one_backup(
    scenario: Scenario,
    params: PlannerParams,
    exc: PlanningError,
    finger: str,
    avoid: dict[str, list[np.ndarray]],
    report: _Report,
    setup: PlanSetup,
) -> tuple[GraspBackup, ManipulationPlan | tuple[PlanningError, Scenario] | None]:
    """One backup of ``finger`` after ``exc``, planned with ``params`` (the budget
    left): its record and its full plan, or its failure and scenario (to back up
    from again), or None (no grasp, no time left, or an unexpected error: recorded,
    and the first failure stands)."""
    assert scenario.grasp is not None
    hold = exc.kind == HOLD_THROUGH
    record = functools.partial(
        GraspBackup,
        after=exc.kind.value,
        finger=finger,
        avoid_m=tuple(float(v) for v in scenario.grasp.points_object[finger]),
        how="held-through" if hold else "elsewhere",
    )
    t0 = time.perf_counter()
    try:
        started = _another_start(scenario, finger, hold, avoid)
    except Exception as bug:  # recorded; the first failure stands
        started = f"exception:{type(bug).__name__}: {bug}"
    choose_s = time.perf_counter() - t0
    if isinstance(started, str):
        return record(outcome=started, choose_s=choose_s), None
    if params.budget_s is not None and params.budget_s <= 0:
        return record(outcome="no-time", choose_s=choose_s), None
    progress, on_backup = report
    if on_backup is not None:
        on_backup(finger, exc.kind.value)
    t0 = time.perf_counter()
    try:
        planned = _plan(started, params, progress, setup)
    except Exception as bug:  # recorded (a typed error by its kind); the first failure stands
        kind = getattr(bug, "kind", None)
        failed = (
            kind.value
            if isinstance(kind, FailureKind)
            else f"exception:{type(bug).__name__}: {bug}"
        )
        return record(outcome=failed, choose_s=choose_s, plan_s=time.perf_counter() - t0), None
    plan_s = time.perf_counter() - t0
    if isinstance(planned, ManipulationPlan):
        return record(outcome="ok", choose_s=choose_s, plan_s=plan_s), planned
    return (
        record(outcome=planned.kind.value, time_s=planned.time_s, choose_s=choose_s, plan_s=plan_s),
        (planned, started),
    )
