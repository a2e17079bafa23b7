"""Stand-in tasks for the suite runner's tests.

They live in a module of their own (not a test file) so that Dask's worker processes and
the scenario processes they start import them by name. Each records that it ran by
appending a line to ``<out_dir>/ran/<spec name>``.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from regrasp_pin.suite.run import ScenarioResult, outcome_template
from regrasp_pin.suite.specs import ScenarioSpec


def _mark(spec: ScenarioSpec, out_dir: str | None) -> None:
    if out_dir is not None:
        ran = Path(out_dir) / "ran"
        ran.mkdir(exist_ok=True)
        with (ran / spec.name).open("a") as f:
            f.write("ran\n")


def quick(spec: ScenarioSpec, *, out_dir: str | None = None, **_: object) -> ScenarioResult:
    """A full 'plan' at once, with a number of regrasps that depends on the name."""
    _mark(spec, out_dir)
    r = outcome_template(spec)
    r.ok = True
    r.n_regrasps = len(spec.name) % 7
    r.plan_s = 0.01
    return r


def _worker_pid() -> int:
    """The Dask worker's pid: the parent of this process's parent (the forkserver)."""
    stat = Path(f"/proc/{os.getppid()}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[1])


def faulty(spec: ScenarioSpec, *, out_dir: str | None = None, **kw: object) -> ScenarioResult:
    """What the name says: ``crash`` (SIGSEGV), ``hang`` (past any test timeout),
    ``kill-worker`` (SIGKILL to the Dask worker), ``no-grasp`` (no initial grasp);
    otherwise :func:`quick`."""
    _mark(spec, out_dir)
    if "crash" in spec.name:
        os.kill(os.getpid(), signal.SIGSEGV)
    if "hang" in spec.name:
        time.sleep(60)
    if "kill-worker" in spec.name:
        if out_dir is not None:
            (Path(out_dir) / "ran" / f"{spec.name}.pid").write_text(str(os.getpid()))
        os.kill(_worker_pid(), signal.SIGKILL)
        time.sleep(60)
    if "no-grasp" in spec.name:
        r = outcome_template(spec)
        r.failed_stage, r.failure_kind = "grasp", "no-candidate"
        return r
    return quick(spec, **kw)


def exits(spec: ScenarioSpec, **_: object) -> ScenarioResult:
    """Leave the process with exit code 3, no result."""
    os._exit(3)


def raises(spec: ScenarioSpec, **_: object) -> ScenarioResult:
    """Raise instead of returning a result."""
    raise RuntimeError(f"no result for {spec.name}")


def caches(spec: ScenarioSpec, **_: object) -> ScenarioResult:
    """What this scenario process found built when it started: ``measured`` is the
    number of hands built (``suite.build.suite_hand``), ``required`` the number of workspace
    covers cached (``grasp.manifold.workspace_voxels``)."""
    from regrasp_pin.grasp.manifold import workspace_voxels
    from regrasp_pin.suite.build import suite_hand

    r = outcome_template(spec)
    r.measured = float(suite_hand.cache_info().currsize)
    r.required = float(workspace_voxels.cache_info().currsize)
    return r


def threads(spec: ScenarioSpec, *, out_dir: str | None = None, **_: object) -> ScenarioResult:
    """:func:`quick`, with the manifold threads the scenario's process is given
    (``REGRASP_PIN_THREADS``, -1 if unset) as its number of regrasps."""
    r = quick(spec, out_dir=out_dir)
    r.n_regrasps = int(os.environ.get("REGRASP_PIN_THREADS", "-1"))
    return r
