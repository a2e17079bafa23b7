"""The scenario suite on Dask: one task per scenario, on this machine or on a cluster.

:func:`run_suite` hands the scenarios to a Dask cluster, a
:class:`distributed.LocalCluster` with ``workers`` processes started and stopped here,
or an existing cluster at ``scheduler`` (``dask scheduler`` / ``dask worker``,
dask-jobqueue on SLURM, Kubernetes) with no other change. Each task runs its scenario in
a process of its own (:func:`~.isolate.run_isolated`): a time limit, and a crash that
ends only that scenario. Results stream to ``out/results.jsonl`` as tasks finish (one
:class:`~.run.ScenarioResult` per line; specs without an initial grasp go to
``skipped.jsonl``); once the run ends both files are rewritten in spec order.

* ``resume=True`` reads both files first and runs only the specs that are in neither;
  a run stopped by Ctrl-C (KeyboardInterrupt) leaves every finished result on disk in
  complete lines, so resuming completes it without redoing finished work.
* A scenario past ``timeout_s`` is a ``"timeout"`` failure, one whose process dies a
  ``"crash"``, one whose Dask worker is lost a ``"worker-died"`` failure; the run goes
  on and no other result is lost (results are collected as soon as each task ends).

Dask is the optional ``scale`` extra (``pip install "regrasp-pin[scale]"``); it is
imported when a suite runs, never by ``import regrasp_pin``.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections import Counter
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._validate import positive, positive_int
from ..exceptions import FailureKind, InputError, MissingExtraError
from ..grasp.manifold import THREADS_ENV, manifold_threads
from ..model.ik import environment_backend
from ..planning.timing import checked_time_law
from .isolate import Task, run_isolated, warm_up
from .run import ScenarioResult, outcome_template, run_scenario
from .specs import ScenarioSpec

__all__ = [
    "WORKER_DIED",
    "SuiteRun",
    "load_run",
    "local_manifold_threads",
    "manifold_threads",
    "require_scale",
    "run_suite",
]

log = logging.getLogger(__name__)

WORKER_DIED = "worker-died"  #: ScenarioResult.failure_kind when the Dask worker was lost
RESULTS, SKIPPED = "results.jsonl", "skipped.jsonl"


def require_scale() -> Any:
    """The ``distributed`` module once the scale extra (dask, distributed, tqdm) is
    importable, or a MissingExtraError that says which extra to install."""
    try:
        import distributed
        import tqdm  # noqa: F401  (the progress bar of ``regrasp-pin suite``)
    except ImportError as exc:
        raise MissingExtraError(exc.name or "dask", "scale") from None
    return distributed


@dataclass
class SuiteRun:
    """What :func:`run_suite` did.

    Attributes:
        results: The counted results (spec order), earlier ones included on resume.
        skipped: Specs without an initial grasp (spec order).
        wall_s: Wall time of this call [s], the cluster's start included.
        startup_s: Of which starting the cluster (and each worker's scenario server) [s].
        workers: Worker threads of the cluster (one scenario each at a time).
        resumed: Results (and skips) taken from an earlier run.
        task_s: Per scenario run now: its time inside the worker [s].
        overhead_s: Per scenario run now: the time from handing it to the cluster to
            having its result back, minus ``task_s`` [s] (scheduling, transfer).
    """

    results: list[ScenarioResult]
    skipped: list[ScenarioResult]
    wall_s: float
    workers: int
    resumed: int = 0
    startup_s: float = 0.0
    task_s: list[float] = field(default_factory=list)
    overhead_s: list[float] = field(default_factory=list)

    def describe(self) -> str:
        """Skipped specs, wall time, workers and the scheduling overhead, in a few lines."""
        kinds = Counter(r.failure_kind or "no kind" for r in self.skipped).most_common()
        counts = ", ".join(_kind_count(k, n, self.skipped) for k, n in kinds)
        lines = [
            f"skipped without an initial grasp: {len(self.skipped)}"
            + (f" ({counts})" if kinds else ""),
            f"wall time: {self.wall_s:.0f} s on {self.workers} worker(s) "
            f"({self.startup_s:.1f} s to start them)"
            + (f"; {self.resumed} earlier result(s) kept, skips included" if self.resumed else ""),
        ]
        if self.task_s:
            over, task = np.array(self.overhead_s), np.array(self.task_s)
            lines.append(
                f"scheduling overhead per scenario: median {np.median(over) * 1e3:.0f} ms, "
                f"{over.sum() / max(task.sum(), 1e-9):.1%} of the scenarios' time"
            )
        return "\n".join(lines)


def _worker_task(
    task: Task, spec: ScenarioSpec, timeout_s: float | None, kwargs: dict[str, Any]
) -> tuple[ScenarioResult, float]:
    """What runs on a worker: the scenario in its own process, and the time it took."""
    t0 = time.perf_counter()
    result = run_isolated(task, spec, timeout_s=timeout_s, **kwargs)
    return result, time.perf_counter() - t0


def _read_lines(path: Path) -> list[ScenarioResult]:
    """The complete result lines of ``path`` (a line cut short by a kill is dropped)."""
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        if not line.strip():
            continue
        try:
            out.append(ScenarioResult.from_dict(json.loads(line)))
        except (json.JSONDecodeError, InputError, TypeError):
            log.warning("%s: an incomplete result line is ignored", path)
    return out


def load_run(out: str | Path) -> tuple[list[ScenarioResult], list[ScenarioResult]]:
    """``(results, skipped)`` of a suite folder, as :func:`run_suite` wrote them."""
    folder = Path(out)
    return _read_lines(folder / RESULTS), _read_lines(folder / SKIPPED)


def _write_sorted(path: Path, results: list[ScenarioResult]) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text("".join(json.dumps(r.to_dict()) + "\n" for r in results))
    os.replace(tmp, path)  # never a half-written file


def local_manifold_threads(workers: int) -> int:
    """:func:`manifold_threads` for a local cluster of ``workers`` on this machine's
    cores, by the IK backend its workers will read from the environment
    (``REGRASP_PIN_IK_BACKEND``; a backend set in code here does not reach them)."""
    return manifold_threads(workers, os.cpu_count() or 1, environment_backend())


@contextmanager
def _environ_kept() -> Any:
    """This process's environment as it was before, on leaving.

    A nanny of a local cluster copies its ``pre-spawn-environ`` (and a
    ``PYTHONHASHSEED``) into the environment of the process that starts it, this one,
    and leaves them there, and a later nanny prefers a variable of the environment to
    its configuration: without this, a second cluster of this process gave its workers
    the first one's manifold threads. A variable the user set before stays theirs
    (the environment's value wins, as distributed decides).
    """
    before = dict(os.environ)
    try:
        yield
    finally:
        for key in set(os.environ) - set(before):
            del os.environ[key]
        os.environ.update(before)


@contextmanager
def _client(workers: int | None, scheduler: str | None) -> Any:
    """A Dask client: on a LocalCluster of ``workers`` single-threaded processes
    (started and stopped here), or on the cluster at ``scheduler``."""
    distributed = require_scale()
    import dask

    # a lost worker fails its task at once (no retry on the next worker); workers may
    # start processes (each scenario runs in its own); no MALLOC_TRIM_THRESHOLD_ (see
    # isolate._forkserver: it slows the planner down by ~1.6x)
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    n = workers or os.cpu_count() or 1
    # a remote cluster's workers read their own environment (docs/suite.md)
    environ[THREADS_ENV] = str(local_manifold_threads(n))
    settings = {
        "distributed.scheduler.allowed-failures": 0,
        "distributed.worker.daemon": False,
        "distributed.nanny.pre-spawn-environ": environ,
    }
    with dask.config.set(settings), _environ_kept():
        if scheduler is not None:
            client = distributed.Client(scheduler)
            try:
                yield client
            finally:
                client.close()
            return
        cluster = distributed.LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0"
        )
        client = distributed.Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()


def _lost(spec: ScenarioSpec, exc: BaseException, waited_s: float) -> ScenarioResult:
    """The failure of a scenario whose task did not return (its worker died, or the
    task raised on the worker)."""
    r = outcome_template(spec)
    r.failed_stage = "run"
    r.plan_s = waited_s
    if isinstance(exc, require_scale().KilledWorker):
        r.failure_kind = WORKER_DIED
        r.failure = f"the Dask worker running it died ({exc})"
    else:
        r.failure_kind = f"exception:{type(exc).__name__}"
        r.failure = f"the task raised on its worker: {type(exc).__name__}: {exc}"
    return r


def run_suite(
    specs: Sequence[ScenarioSpec],
    n: int | None = None,
    *,
    out: str | Path,
    workers: int | None = None,
    scheduler: str | None = None,
    timeout_s: float | None = None,
    resume: bool = False,
    skip_no_grasp: bool = True,
    max_steps: int | None = None,
    budget_s: float | None = None,
    grasp_backups: int = 1,
    time_law: str | None = None,
    torsion_m: float = 0.0,
    on_result: Callable[[ScenarioResult, int, int], None] | None = None,
    task: Task = run_scenario,
) -> SuiteRun:
    """Run the first ``n`` countable specs, one Dask task each.

    A spec counts unless ``skip_no_grasp`` and it has no initial grasp; a spec is
    handed to the cluster only while fewer than ``n`` are counted or running and a
    worker is free, so the counted specs are the first ``n`` countable ones whatever
    the order in which tasks end, on any number of workers.

    Args:
        specs: The specs, in order.
        n: How many to count; default all.
        out: Folder for plans, ``results.jsonl`` and ``skipped.jsonl`` (created).
        workers: Processes of the LocalCluster; default the machine's cores. Ignored
            with ``scheduler``.
        scheduler: Address of an existing Dask scheduler (``tcp://host:8786``); its
            workers must be able to start processes (``distributed.worker.daemon:
            False``; set here for a LocalCluster).
        timeout_s: Wall-clock limit of each scenario [s]; None: none.
        resume: Keep the results already in ``out`` and run only the other specs.
        skip_no_grasp: Specs without an initial grasp do not count (the suite's rule).
        max_steps: The planner's step budget (None: the scenario's own).
        budget_s: An optional wall-clock limit of each planning [s].
        grasp_backups: Most initial grasps a failed scenario backs up to
            (:func:`~.run.run_scenario`; 0: none).
        time_law: The regrasps' time law (``RegraspParams.time_law``; None: the
            scenario's own).
        torsion_m: The fingertips' torsional friction [m] (``ContactModel.torsion_m``;
            0: point contacts).
        on_result: Called with ``(result, counted, n)`` as each result arrives
            (skipped ones included, ``counted`` unchanged); it may raise
            KeyboardInterrupt to stop the run, as Ctrl-C does.
        task: ``task(spec, out_dir=, max_steps=, budget_s=, grasp_backups=,
            time_law=, torsion_m=) -> ScenarioResult``, a
            module-level function; default :func:`~.run.run_scenario`.

    Returns:
        The :class:`SuiteRun`.

    Raises:
        InputError: bad ``n``, ``workers``, ``timeout_s``, ``grasp_backups``,
            ``time_law`` or ``torsion_m``; dask not installed.
        KeyboardInterrupt: the run was stopped; the finished results are on disk.
    """
    specs = list(specs)
    total = len(specs) if n is None else positive_int(n, "n", minimum=0)
    if workers is not None:
        positive_int(workers, "workers")
    positive_int(grasp_backups, "grasp_backups", minimum=0)
    if time_law is not None:
        checked_time_law(time_law)
    positive(torsion_m, "torsion_m", allow_zero=True)
    limit = None if timeout_s is None else positive(timeout_s, "timeout_s")
    ledger = _Ledger(Path(out), specs, resume=resume, skip_no_grasp=skip_no_grasp)
    run = SuiteRun([], [], 0.0, 0, ledger.size)
    kwargs = {
        "out_dir": str(ledger.folder),
        "max_steps": max_steps,
        "budget_s": budget_s,
        "grasp_backups": grasp_backups,
        "time_law": time_law,
        "torsion_m": torsion_m,
    }
    t_start = time.perf_counter()
    try:
        with _client(workers, scheduler) as client:
            run.workers = max(sum(client.nthreads().values()), 1)
            # each worker's forkserver, with the hands of the run, before a task's clock
            client.run(warm_up, sorted({spec.hand for spec in specs}))
            run.startup_s = time.perf_counter() - t_start
            pending: dict[Any, tuple[int, float]] = {}
            todo = iter(ledger.todo())
            nxt = next(todo, None)
            while True:
                while (
                    nxt is not None
                    and len(ledger.counted) + len(pending) < total
                    and len(pending) < run.workers
                ):
                    fut = client.submit(
                        _worker_task, task, specs[nxt], limit, kwargs, pure=False,
                        key=f"scenario-{nxt}-{specs[nxt].name}",
                    )  # fmt: skip
                    pending[fut] = (nxt, time.perf_counter())
                    nxt = next(todo, None)
                if not pending:
                    break
                finished = require_scale().wait(list(pending), return_when="FIRST_COMPLETED").done
                for fut in sorted(finished, key=lambda f: pending[f][0]):
                    i, t_sub = pending.pop(fut)
                    result = _collect(fut, specs[i], t_sub, run)
                    ledger.take(i, result)
                    if on_result is not None:
                        on_result(result, len(ledger.counted), total)
    finally:
        run.results, run.skipped = ledger.close()
        run.wall_s = time.perf_counter() - t_start
    return run


def _collect(fut: Any, spec: ScenarioSpec, t_sub: float, run: SuiteRun) -> ScenarioResult:
    """A finished task's result (its times noted in ``run``), or the failure that
    ended it (a lost worker, an error on the worker); the future is released."""
    try:
        result, inside = fut.result()
        run.task_s.append(inside)
        run.overhead_s.append(max(time.perf_counter() - t_sub - inside, 0.0))
    except Exception as exc:  # the worker died or the task raised there
        result = _lost(spec, exc, time.perf_counter() - t_sub)
    fut.release()
    return result


class _Ledger:
    """The results of a suite folder: those kept from an earlier run, and each new one
    appended to ``results.jsonl`` / ``skipped.jsonl`` as one complete line."""

    def __init__(
        self, folder: Path, specs: list[ScenarioSpec], *, resume: bool, skip_no_grasp: bool
    ) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        index = {s.name: i for i, s in enumerate(specs)}
        if len(index) != len(specs):
            raise InputError("specs", "two specs have the same name", "unique spec names")
        self.folder, self.n_specs, self.skip_no_grasp = folder, len(specs), skip_no_grasp
        self.counted: dict[int, ScenarioResult] = {}
        self.skipped: dict[int, ScenarioResult] = {}
        if resume:
            old, old_skipped = load_run(folder)
            self.counted.update((index[r.name], r) for r in old if r.name in index)
            self.skipped.update((index[r.name], r) for r in old_skipped if r.name in index)
        else:
            for name in (RESULTS, SKIPPED):
                (folder / name).unlink(missing_ok=True)
        self.size = len(self.counted) + len(self.skipped)
        self.streams = {k: (folder / k).open("a") for k in (RESULTS, SKIPPED)}

    def todo(self) -> list[int]:
        """The specs with no result yet, in order."""
        return [i for i in range(self.n_specs) if i not in self.counted and i not in self.skipped]

    def take(self, i: int, r: ScenarioResult) -> None:
        skip = self.skip_no_grasp and r.failed_stage == "grasp"
        (self.skipped if skip else self.counted)[i] = r
        stream = self.streams[SKIPPED if skip else RESULTS]
        stream.write(json.dumps(r.to_dict()) + "\n")  # one complete line at a time
        stream.flush()

    def close(self) -> tuple[list[ScenarioResult], list[ScenarioResult]]:
        """Both files rewritten in spec order; ``(results, skipped)``."""
        for s in self.streams.values():
            s.close()
        results = [self.counted[i] for i in sorted(self.counted)]
        skipped = [self.skipped[i] for i in sorted(self.skipped)]
        _write_sorted(self.folder / RESULTS, results)
        _write_sorted(self.folder / SKIPPED, skipped)
        return results, skipped


def _kind_count(kind: str, n: int, skipped: list[ScenarioResult]) -> str:
    """``"<kind> <n>"``; for finger collisions with the fingers named, which finger came
    near which, counted (most first, then by name): ``"finger-collision 4 [middle near
    index 2, ring near middle 2]"``."""
    if kind != FailureKind.FINGER_COLLISION.value:
        return f"{kind} {n}"
    pairs = Counter(
        f"{r.finger} near {r.other}"
        for r in skipped
        if r.failure_kind == kind and r.finger and r.other
    )
    named = sorted(pairs.items(), key=lambda kv: (-kv[1], kv[0]))
    return f"{kind} {n}" + (" [" + ", ".join(f"{p} {c}" for p, c in named) + "]" if named else "")
