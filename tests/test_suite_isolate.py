"""One scenario in a process of its own: its result, or a timeout or crash as data."""

from __future__ import annotations

import time
from dataclasses import replace

import pytest
import suite_tasks

from regrasp_pin.exceptions import InputError
from regrasp_pin.suite import neighbour_specs
from regrasp_pin.suite.isolate import CRASH, TIMEOUT, run_isolated

SPEC = neighbour_specs()[0]


def test_result_comes_back_as_the_task_made_it(tmp_path):
    direct = suite_tasks.quick(SPEC)
    r = run_isolated(suite_tasks.quick, SPEC, out_dir=str(tmp_path))
    assert r.to_dict() == direct.to_dict()
    assert (tmp_path / "ran" / SPEC.name).read_text() == "ran\n"  # ran once, in the child


def test_a_segfault_is_a_crash_of_that_scenario():
    r = run_isolated(suite_tasks.faulty, replace(SPEC, name="x-crash"))
    assert (r.ok, r.failure_kind, r.failed_stage) == (False, CRASH, "run")
    assert r.measured == -11.0  # SIGSEGV
    assert "SIGSEGV" in (r.failure or "")


def test_an_exit_without_result_is_a_crash_with_its_code():
    r = run_isolated(suite_tasks.exits, SPEC)
    assert (r.failure_kind, r.measured) == (CRASH, 3.0)


def test_a_task_past_its_time_limit_is_stopped():
    t0 = time.perf_counter()
    r = run_isolated(suite_tasks.faulty, replace(SPEC, name="x-hang"), timeout_s=1.0)
    waited = time.perf_counter() - t0
    assert (r.failure_kind, r.required) == (TIMEOUT, 1.0)
    assert 1.0 <= waited < 10.0  # killed, not waited for (it sleeps 600 s)


def test_a_task_that_raises_is_recorded_with_its_type():
    r = run_isolated(suite_tasks.raises, SPEC)
    assert r.failure_kind == "exception:RuntimeError"
    assert SPEC.name in (r.failure or "")


def test_bad_timeout_is_refused():
    with pytest.raises(InputError, match="timeout_s"):
        run_isolated(suite_tasks.quick, SPEC, timeout_s=0.0)
