"""The suite on Dask: the same results as one by one, faults kept to their scenario,
streamed results that survive an interruption, and resuming without redoing work."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import suite_tasks
from conftest import assert_close

from regrasp_pin.exceptions import InputError, MissingExtraError
from regrasp_pin.grasp.manifold import THREADS_ENV
from regrasp_pin.model import ik_numba
from regrasp_pin.plan import Plan
from regrasp_pin.suite import neighbour_specs, run_scenario
from regrasp_pin.suite.cluster import (
    WORKER_DIED,
    load_run,
    local_manifold_threads,
    manifold_threads,
    require_scale,
    run_suite,
)
from regrasp_pin.suite.isolate import CRASH, TIMEOUT

pytest.importorskip("distributed", reason="the scale extra (dask, distributed) is not installed")

SCHEMA = Path(__file__).resolve().parents[1] / "docs" / "suite_result.schema.json"


def _named(*names: str):
    base = neighbour_specs()[0]
    return [replace(base, name=n) for n in names]


def _valid_lines(path: Path) -> list[dict]:
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA.read_text()))
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    for d in lines:
        errors = [e.message for e in validator.iter_errors(d)]
        assert not errors, (d["name"], errors)
    return lines


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _regrasps(path: str) -> list[tuple[str, float, np.ndarray]]:
    return [(p.finger, p.t_start, np.asarray(p.Q_object)) for p in Plan.load(path).regrasps()]


def test_two_workers_give_the_results_of_one_by_one(tmp_path):
    """Four small scenarios: the same outcomes, regrasps (finger, start, Q) as in-process."""
    fast = {
        "five_finger-hexagon-+60deg-40dps",
        "five_finger-hexagon-+60deg-20dps",
        "allegro-hexagon-+60deg-40dps",
        "allegro-hexagon-+60deg-20dps",
    }
    specs = [s for s in neighbour_specs() if s.name in fast]
    assert len(specs) == 4
    done = run_suite(specs, out=tmp_path / "dask", workers=2, skip_no_grasp=False)
    assert [r.name for r in done.results] == [s.name for s in specs]  # spec order
    assert done.workers == 2 and len(done.task_s) == 4
    for spec, r in zip(specs, done.results, strict=True):
        alone = run_scenario(spec, out_dir=tmp_path / "alone")
        assert (r.ok, r.failure_kind, r.n_regrasps) == (
            alone.ok,
            alone.failure_kind,
            alone.n_regrasps,
        )
        if not r.ok:
            continue
        assert r.recheck_ok is True
        a, b = _regrasps(r.plan_path), _regrasps(alone.plan_path)
        assert [(f, round(t, 9)) for f, t, _ in a] == [(f, round(t, 9)) for f, t, _ in b]
        for (_, _, qa), (_, _, qb) in zip(a, b, strict=True):
            assert_close(qa, qb, atol=1e-9, what="Q [m]")
    lines = _valid_lines(tmp_path / "dask" / "results.jsonl")
    assert [d["name"] for d in lines] == [s.name for s in specs]


def test_a_crash_a_hang_and_a_lost_worker_end_only_their_scenario(tmp_path):
    if not Path("/proc/self/stat").is_file():
        pytest.skip("finding the worker's pid needs /proc")
    specs = _named("a", "b-crash", "c", "d-hang", "e-kill-worker", "f", "g")
    done = run_suite(specs, out=tmp_path, workers=2, timeout_s=3.0, task=suite_tasks.faulty)
    kinds = {r.name: r.failure_kind for r in done.results}
    assert kinds == {
        "a": None,
        "b-crash": CRASH,
        "c": None,
        "d-hang": TIMEOUT,
        "e-kill-worker": WORKER_DIED,
        "f": None,
        "g": None,
    }
    # the scenario whose worker died does not outlive it (it would sleep for a minute)
    pid = int((tmp_path / "ran" / "e-kill-worker.pid").read_text())
    deadline = time.monotonic() + 10.0
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _alive(pid)
    ok = [r for r in done.results if r.ok]
    assert [r.n_regrasps for r in ok] == [len(r.name) % 7 for r in ok]  # the task's own results
    assert len(_valid_lines(tmp_path / "results.jsonl")) == 7


def test_an_existing_cluster_by_its_scheduler_address(tmp_path):
    """``scheduler=``: the same run on a cluster started elsewhere (here, in this test)."""
    import dask
    import distributed

    with (
        dask.config.set({"distributed.worker.daemon": False}),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, dashboard_address=":0"
        ) as cluster,
    ):
        done = run_suite(
            _named(*"abcd"), out=tmp_path, scheduler=cluster.scheduler_address,
            task=suite_tasks.quick,
        )  # fmt: skip
        assert done.workers == 2
        assert len(cluster.scheduler.workers) == 2  # the run left the cluster up
    assert [r.name for r in done.results] == list("abcd") and all(r.ok for r in done.results)


def test_manifold_threads_share_out_the_idle_cores():
    assert [manifold_threads(w, 2, "numba") for w in (1, 2, 3)] == [2, 1, 1]
    assert [manifold_threads(w, 8, "numba") for w in (1, 2, 3, 8)] == [8, 4, 2, 1]
    assert manifold_threads(1, 8, "numpy") == 1  # numpy's threads contend for the GIL


def test_a_local_cluster_reads_the_workers_backend_from_the_environment(monkeypatch):
    import regrasp_pin.suite.cluster as cluster

    monkeypatch.setattr(cluster.os, "cpu_count", lambda: 4)
    monkeypatch.setenv("REGRASP_PIN_IK_BACKEND", "numba")
    assert [local_manifold_threads(w) for w in (1, 2, 4)] == [4, 2, 1]
    monkeypatch.setenv("REGRASP_PIN_IK_BACKEND", "numpy")
    assert local_manifold_threads(1) == 1
    monkeypatch.delenv("REGRASP_PIN_IK_BACKEND")  # numba where it is installed
    monkeypatch.setattr(ik_numba, "available", lambda: True)
    assert local_manifold_threads(1) == 4
    monkeypatch.setattr(ik_numba, "available", lambda: False)
    assert local_manifold_threads(1) == 1


def test_scenarios_are_given_their_manifold_threads(tmp_path):
    # what the scenario's own process sees (-1: not set)
    done = run_suite(_named("a", "b"), out=tmp_path, workers=1, task=suite_tasks.threads)
    want = local_manifold_threads(1)
    assert [r.n_regrasps for r in done.results] == [want, want]


def test_each_local_cluster_gives_its_own_threads_and_leaves_the_environment(tmp_path, monkeypatch):
    """A nanny copies its workers' environment into this process and leaves it there;
    a later cluster must still give its own threads (here a count per worker number,
    whatever the backend), and this process's environment is as it was."""
    import regrasp_pin.suite.cluster as cluster

    monkeypatch.setattr(cluster, "local_manifold_threads", lambda workers: 10 + workers)
    monkeypatch.delenv(THREADS_ENV, raising=False)
    before = dict(os.environ)
    got = []
    for workers in (2, 1):
        done = run_suite(
            _named("a", "b"), out=tmp_path / str(workers), workers=workers,
            task=suite_tasks.threads,
        )  # fmt: skip
        got.append([r.n_regrasps for r in done.results])
        assert dict(os.environ) == before
    assert got == [[12, 12], [11, 11]]


def test_specs_without_a_grasp_do_not_count(tmp_path):
    specs = _named("a", "b-no-grasp", "c", "d", "e")
    done = run_suite(specs, 3, out=tmp_path, workers=1, task=suite_tasks.faulty)
    assert [r.name for r in done.results] == ["a", "c", "d"]  # the first 3 that count
    assert [r.name for r in done.skipped] == ["b-no-grasp"]
    assert not (tmp_path / "ran" / "e").exists()  # never started
    results, skipped = load_run(tmp_path)
    assert [r.name for r in results] == ["a", "c", "d"] and len(skipped) == 1


def test_an_interrupted_run_resumes_without_redoing_work(tmp_path):
    specs = _named(*"abcdef")
    seen = []

    def stop_after_two(r, counted, total):
        seen.append(r.name)
        if counted == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_suite(specs, out=tmp_path, workers=1, task=suite_tasks.quick, on_result=stop_after_two)
    kept = _valid_lines(tmp_path / "results.jsonl")
    assert [d["name"] for d in kept] == seen == ["a", "b"]
    done = run_suite(specs, out=tmp_path, workers=2, task=suite_tasks.quick, resume=True)
    assert done.resumed == 2
    assert [r.name for r in done.results] == list("abcdef")
    runs = {n: (tmp_path / "ran" / n).read_text().count("ran") for n in "abcdef"}
    assert runs == dict.fromkeys("abcdef", 1)  # each ran once over both calls


def test_a_line_cut_short_is_dropped_on_resume(tmp_path):
    specs = _named(*"abc")
    run_suite(specs, out=tmp_path, workers=1, task=suite_tasks.quick)
    lines = (tmp_path / "results.jsonl").read_text().splitlines()
    (tmp_path / "results.jsonl").write_text(lines[0] + "\n" + lines[1][:40])  # killed mid-line
    assert [r.name for r in load_run(tmp_path)[0]] == ["a"]
    done = run_suite(specs, out=tmp_path, workers=1, task=suite_tasks.quick, resume=True)
    assert [r.name for r in done.results] == ["a", "b", "c"]
    assert (tmp_path / "ran" / "b").read_text().count("ran") == 2  # b ran again


@pytest.mark.parametrize(
    ("kwargs", "argument"),
    [
        ({"n": -1}, "n"),
        ({"workers": 0}, "workers"),
        ({"timeout_s": 0.0}, "timeout_s"),
        ({"time_law": "linear"}, "time_law"),
        ({"torsion_m": -0.001}, "torsion_m"),
    ],
)
def test_bad_arguments_are_named(tmp_path, kwargs, argument):
    with pytest.raises(InputError, match=argument):
        run_suite(_named("a"), out=tmp_path, task=suite_tasks.quick, **kwargs)


def test_duplicate_spec_names_are_refused(tmp_path):
    with pytest.raises(InputError, match="same name"):
        run_suite(_named("a", "a"), out=tmp_path, task=suite_tasks.quick)


def test_import_regrasp_pin_does_not_import_dask():
    code = (
        "import sys, regrasp_pin, regrasp_pin.suite, regrasp_pin.cli; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_without_the_scale_extra_the_error_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    with pytest.raises(MissingExtraError, match=r"regrasp-pin\[scale\]"):
        require_scale()


def test_describe_counts_the_skipped_specs_by_kind():
    from regrasp_pin.suite.cluster import SuiteRun
    from regrasp_pin.suite.run import outcome_template

    specs = _named("a", "b", "c")
    skipped = [
        replace(outcome_template(s), ok=False, failure_kind=k, failed_stage="grasp")
        for s, k in zip(specs, ["infeasible", "force-closure", "infeasible"], strict=True)
    ]
    text = SuiteRun(results=[], skipped=skipped, wall_s=1.0, workers=1).describe()
    assert "skipped without an initial grasp: 3 (infeasible 2, force-closure 1)" in text
    assert "skipped without an initial grasp: 0\n" in SuiteRun([], [], 1.0, 1).describe() + "\n"


def test_describe_names_the_fingers_of_the_skipped_finger_collisions():
    from regrasp_pin.suite.cluster import SuiteRun
    from regrasp_pin.suite.run import outcome_template

    near = [("middle", "index"), ("ring", "middle"), ("middle", "index"), (None, None)]
    skipped = [
        replace(
            outcome_template(s),
            ok=False,
            failure_kind="finger-collision",
            failed_stage="grasp",
            finger=f,
            other=o,
        )
        for s, (f, o) in zip(_named("a", "b", "c", "d"), near, strict=True)
    ]
    skipped.append(replace(outcome_template(_named("e")[0]), failure_kind="no-candidate"))
    text = SuiteRun(results=[], skipped=skipped, wall_s=1.0, workers=1).describe()
    assert (
        "skipped without an initial grasp: 5 (finger-collision 4 [middle near index 2, "
        "ring near middle 1], no-candidate 1)"
    ) in text
