"""Running one spec: build, plan, save, re-check, and the outcome as data."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._validate import known_fields, positive, positive_int
from ..backups import plan_scenario, recorded_backups
from ..exceptions import ContactError, FailureKind, PlanningError
from ..grasp.contact import ContactModel
from ..plan import Plan
from ..planning.params import with_time_law
from ..planning.timing import checked_time_law
from ..scenarios import hand_label
from ..verify.plan_check import recheck_plan
from .build import build_scenario, finger_clearance
from .specs import ScenarioSpec

__all__ = ["ScenarioResult", "load_results", "outcome_template", "run_scenario"]

log = logging.getLogger(__name__)


@dataclass
class ScenarioResult:
    """The outcome of :func:`run_scenario` (JSON-able with :meth:`to_dict`).

    Attributes:
        name: The spec's name.
        hand: The hand.
        object_kind: ``"prism"``, ``"box"`` or ``"mesh"``.
        motion_kind: One of :data:`MOTION_KINDS`.
        ok: A full plan was found.
        failure_kind: The failure's :class:`~regrasp_pin.exceptions.FailureKind` value (e.g.
            ``"velocity"``), ``"exception:<Type>"`` for an unexpected error, ``"timeout"``
            or ``"crash"`` when the process running it was stopped or died
            (:mod:`.isolate`), ``"worker-died"`` when a Dask worker was lost
            (:mod:`.cluster`), or None.
        failure: The failure's message (for an unexpected error, with its traceback's
            last lines), or None.
        failed_stage: ``"grasp"`` (no initial grasp: the spec is skipped by the suite),
            ``"build"`` (another error while building), ``"plan"``, ``"run"`` (the
            process or worker running it: timeout, crash, lost worker), or None.
        finger: The finger of the failure, if any.
        other: For a ``finger-collision`` failure, the finger it came too near, when
            known (the planner's, or the initial grasp's nearest pair).
        time_s: When in the motion the failure happened [s], if known.
        measured: The failure's measured value (units by kind), if any.
        required: The value that was required, if any.
        attempts: The failed attempts behind the failure (``Attempt.to_dict()``).
        n_regrasps: Verified regrasps (of the partial plan, for a failure).
        regrasp_ms: Planning time of each verified regrasp [ms].
        plan_s: Wall time of the planning [s]: :func:`~regrasp_pin.backups.plan_scenario`
            but the backups' grasp searches.
        build_s: Wall time of :func:`build_scenario` and of the backups' grasp
            searches [s].
        duration_s: Duration of the motion [s].
        planned_until_s: End of the (partial) plan [s]; None without a plan.
        min_clearance_m: Smallest regrasp clearance reported by the planner [m].
        initial_finger_clearance_m: Smallest Coal distance between two fingers at the
            initial grasp (idle fingers at their rest posture) [m]; negative when the
            scenario starts with fingers inside each other.
        recheck_ok: Full plans: :func:`~regrasp_pin.verify.plan_check.recheck_plan` of the saved and
            reloaded plan file passed; None otherwise.
        recheck_problems: Its problems.
        recheck_s: Its wall time [s].
        plan_path: Where the plan (or partial plan) was saved, if it was.
        stage_s: The planner's time per stage [s] (``ManipulationPlan.stage_s``): of the
            full plan, or of the first plan up to its failure (its partial plan's
            ``summary["stage_s"]``); the setup's stages (``"manifolds"``, ``"must
            hold"``) are built once for the backups too.
        spec: The spec (``ScenarioSpec.to_dict()``), to rebuild the scenario.
        backups: The initial grasps backed up to after a failure, in order
            (:meth:`~regrasp_pin.backups.GraspBackup.to_dict`): the failure's kind
            (``"after"``), the finger whose start changed and the contact it started on
            (object frame [m]), how (``"elsewhere"``: that contact avoided;
            ``"held-through"``: a contact held to the end), the outcome (``"ok"``, a
            failure kind, ``"no-grasp:<kind>"``, ``"none-held-through"``, ``"no-time"``
            or ``"exception:<Type>: <message>"``), when its plan failed [s], and the
            wall times of its grasp search and plan [s]. ``plan_s`` and ``build_s``
            include theirs.
    """

    name: str
    hand: str
    object_kind: str
    motion_kind: str
    ok: bool
    failure_kind: str | None = None
    failure: str | None = None
    failed_stage: str | None = None
    finger: str | None = None
    other: str | None = None
    time_s: float | None = None
    measured: float | None = None
    required: float | None = None
    attempts: list[dict[str, Any]] = field(default_factory=list)
    n_regrasps: int = 0
    regrasp_ms: list[float] = field(default_factory=list)
    plan_s: float | None = None
    build_s: float | None = None
    duration_s: float | None = None
    planned_until_s: float | None = None
    min_clearance_m: float | None = None
    initial_finger_clearance_m: float | None = None
    recheck_ok: bool | None = None
    recheck_problems: list[str] = field(default_factory=list)
    recheck_s: float | None = None
    plan_path: str | None = None
    stage_s: dict[str, float] = field(default_factory=dict)
    spec: dict[str, Any] = field(default_factory=dict)
    backups: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON values (non-finite numbers become None)."""
        return _json_safe(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ScenarioResult:
        """Rebuild a result from :meth:`to_dict` (e.g. a line of ``results.jsonl``)."""
        known_fields(d, cls, "result")
        return cls(**d)


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, FailureKind):
        return value.value
    return value


def _attempts_of(exc: BaseException) -> list[dict[str, Any]]:
    """The attempts of an outcome error, else of its cause (as dicts)."""
    for e in (exc, exc.__cause__):
        attempts = getattr(e, "attempts", ())
        if attempts:
            return [_json_safe(a.to_dict()) for a in attempts]
    return []


def _record_failure(result: ScenarioResult, exc: Exception, stage: str) -> None:
    kind = getattr(exc, "kind", None)
    result.failed_stage = stage
    if isinstance(kind, FailureKind) and isinstance(exc, (ContactError, PlanningError)):
        result.failure_kind = kind.value
        result.failure = str(exc)
    else:
        result.failure_kind = f"exception:{type(exc).__name__}"
        tb = traceback.format_exception(type(exc), exc, exc.__traceback__)
        result.failure = f"{type(exc).__name__}: {exc} | " + " | ".join(
            line.strip().replace("\n", " ") for line in tb[-3:-1]
        )
    result.finger = getattr(exc, "finger", None)
    result.other = getattr(exc, "other", None)
    time_s = getattr(exc, "time_s", None)
    result.time_s = None if time_s is None else float(time_s)
    result.measured = getattr(exc, "measured", None)
    result.required = getattr(exc, "required", None)
    result.attempts = _attempts_of(exc)


def outcome_template(spec: ScenarioSpec) -> ScenarioResult:
    """A result of ``spec`` that records nothing yet (``ok=False``, no failure)."""
    return ScenarioResult(
        name=spec.name,
        hand=hand_label(spec.hand),
        object_kind=spec.object.kind,
        motion_kind=spec.motion.kind,
        ok=False,
        duration_s=spec.motion.duration_s,
        spec=spec.to_dict(),
    )


def run_scenario(
    spec: ScenarioSpec,
    *,
    out_dir: str | Path | None = None,
    max_steps: int | None = None,
    budget_s: float | None = None,
    grasp_backups: int = 1,
    time_law: str | None = None,
    torsion_m: float = 0.0,
) -> ScenarioResult:
    """Build and plan one spec; re-check a full plan from its saved file.

    The plan backs up to other initial grasps as
    :func:`~regrasp_pin.backups.plan_scenario` does (up to ``grasp_backups``, on what
    is left of the search budget): a backup that plans fully is the result; otherwise
    the first failure is, and every backup is listed in ``backups``.

    Never raises for an outcome: a :class:`~regrasp_pin.exceptions.ContactError`
    while building (no initial grasp) or a :class:`~regrasp_pin.exceptions.PlanningError`
    / ContactError while planning is recorded with its kind, numbers and attempts; any
    other exception is recorded as ``"exception:<Type>"`` with the end of its
    traceback (a re-check that raises, as a re-check problem), so that a suite runs on.

    Args:
        spec: The spec.
        out_dir: Folder for ``<name>.json`` (a full plan) or ``<name>.partial.json``
            (the plan up to a failure); default: a temporary folder for the re-check
            only, removed afterwards.
        max_steps: The planner's search budget in steps (``PlannerParams.max_steps``;
            None: the scenario's own), the same on every machine; shared by the
            backups.
        budget_s: An optional wall-clock limit of the planning [s]
            (``PlannerParams.budget_s``; None: none), shared by the backups.
        grasp_backups: Most initial grasps to back up to (0: none).
        time_law: The regrasps' time law (``RegraspParams.time_law``; None: the
            scenario's own).
        torsion_m: The fingertips' torsional friction [m]
            (:attr:`~regrasp_pin.grasp.contact.ContactModel.torsion_m`: the initial
            grasp, the planner and the re-check alike); 0: point contacts.

    Returns:
        The :class:`ScenarioResult`.

    Raises:
        InputError: a bad ``max_steps``, ``budget_s``, ``grasp_backups``,
            ``time_law`` or ``torsion_m`` (before any work).
    """
    steps = None if max_steps is None else positive_int(max_steps, "max_steps")
    budget = None if budget_s is None else positive(budget_s, "budget_s")
    backups = positive_int(grasp_backups, "grasp_backups", minimum=0)
    if time_law is not None:
        checked_time_law(time_law)
    contact = ContactModel(torsion_m=torsion_m)  # names a bad value
    result = outcome_template(spec)
    t0 = time.perf_counter()
    try:
        scen = build_scenario(spec, contact)
    except Exception as exc:  # no initial grasp ("grasp"), or a bug ("build")
        result.build_s = time.perf_counter() - t0
        _record_failure(result, exc, "grasp" if isinstance(exc, ContactError) else "build")
        return result
    result.build_s = time.perf_counter() - t0
    if scen.grasp is None:  # build_scenario always chooses one (or raises ContactError)
        raise AssertionError("build_scenario returned a scenario without a grasp")
    result.initial_finger_clearance_m = _start_clearance(scen)
    params = with_time_law(
        dataclasses.replace(
            scen.params,
            max_steps=scen.params.max_steps if steps is None else steps,
            budget_s=budget,
        ),
        time_law,
    )

    t0 = time.perf_counter()
    try:
        planned = plan_scenario(scen, params=params, grasp_backups=backups)
    except Exception as exc:  # the first plan's failure (the backups in its partial plan)
        _record_times(result, exc, time.perf_counter() - t0)
        _record_failure(result, exc, "plan")
        _record_partial(result, spec, exc, out_dir)
        log.info("suite: %s failed: %s", spec.name, result.failure)
        return result
    _record_times(result, planned, time.perf_counter() - t0)
    if result.backups:  # planned from a backup's grasp
        result.initial_finger_clearance_m = _start_clearance(
            dataclasses.replace(scen, grasp=planned.grasp)
        )
    _record_plan(result, spec, planned, params, out_dir)
    return result


def _start_clearance(scen: Any) -> float:
    """The smallest Coal distance between two fingers at the scenario's initial grasp
    (idle fingers at rest) [m]."""
    q = scen.grasp.q
    return float(finger_clearance(scen.hand, scen.obj, scen.motion, tuple(q), 0.0)(q))


def _record_times(result: ScenarioResult, outcome: Any, wall_s: float) -> None:
    """The backups that :func:`~regrasp_pin.backups.plan_scenario` made (read from the
    plan, or from the partial plan of ``outcome``, its failure) in ``result.backups``,
    their grasp searches' time in ``result.build_s`` and the rest of ``wall_s`` in
    ``result.plan_s``."""
    backups = recorded_backups(outcome)
    result.backups = backups
    choose_s = sum(b["choose_s"] for b in backups)
    result.build_s = (result.build_s or 0.0) + choose_s
    result.plan_s = wall_s - choose_s


def _record_partial(
    result: ScenarioResult, spec: ScenarioSpec, exc: Exception, out_dir: str | Path | None
) -> None:
    """The failure's partial plan in ``result`` (and saved into ``out_dir``)."""
    partial = getattr(exc, "partial", None)
    if not isinstance(partial, Plan):
        return
    phases = partial.regrasps()
    result.stage_s = {k: float(v) for k, v in partial.summary.get("stage_s", {}).items()}
    result.n_regrasps = len(phases)
    result.regrasp_ms = [float(p.planning_ms) for p in phases]
    result.min_clearance_m = min((p.min_clearance_m for p in phases), default=None)
    result.planned_until_s = float(partial.t[-1])
    if out_dir is not None:
        path = partial.save(Path(out_dir) / f"{spec.name}.partial.json")
        result.plan_path = str(path)


def _record_plan(
    result: ScenarioResult,
    spec: ScenarioSpec,
    planned: Any,
    params: Any,
    out_dir: str | Path | None,
) -> None:
    """A full plan in ``result``: saved, reloaded and re-checked."""
    result.ok = True
    result.n_regrasps = len(planned.regrasps)
    result.regrasp_ms = [float(r.planning_ms) for r in planned.regrasps]
    result.min_clearance_m = min((r.min_clearance_m for r in planned.regrasps), default=None)
    result.planned_until_s = float(planned.plan.t[-1])
    result.stage_s = {k: float(v) for k, v in planned.stage_s.items()}

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(out_dir) if out_dir is not None else Path(tmp)
        path = planned.plan.save(folder / f"{spec.name}.json")
        if out_dir is not None:
            result.plan_path = str(path)
        try:
            check = recheck_plan(Plan.load(path), mu=params.mu)
            result.recheck_ok = check.ok
            result.recheck_problems = list(check.problems)
        except Exception as exc:  # a plan file the re-check cannot read is a problem too
            result.recheck_ok = False
            result.recheck_problems = [f"the re-check raised {type(exc).__name__}: {exc}"]
    result.recheck_s = time.perf_counter() - t0


def load_results(path: str | Path) -> list[ScenarioResult]:
    """Read a ``results.jsonl`` written by ``bench/suite.py``."""
    lines = Path(path).read_text().splitlines()
    return [ScenarioResult.from_dict(json.loads(line)) for line in lines if line.strip()]
