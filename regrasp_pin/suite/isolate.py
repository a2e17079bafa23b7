"""Running one scenario in a process of its own: a time limit, and a crash that stays there.

A scenario that hangs, or that kills its process (a segfault in a compiled library, the
out-of-memory killer), must end as a failure *of that scenario* and leave the run and
every other result alone. :func:`run_isolated` runs a task in a child process forked
from a ``forkserver`` (a clean single-threaded process that has imported the planner
once, so that a child starts in milliseconds and never inherits the locks of a threaded
parent such as a Dask worker), waits at most ``timeout_s``, and turns each way it can
end into a :class:`~.run.ScenarioResult`:

* the task's own result (every planning outcome is data already, :func:`~.run.run_scenario`);
* ``failure_kind="timeout"``: still running after ``timeout_s``; the child is killed;
* ``failure_kind="crash"``: the child died without a result (a signal such as SIGSEGV
  or SIGKILL, or an exit code); ``measured`` holds the exit code (negative: the signal).
"""

from __future__ import annotations

import json
import multiprocessing
import multiprocessing.connection
import multiprocessing.forkserver
import os
import signal
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from .._validate import positive
from .run import ScenarioResult, outcome_template
from .specs import ScenarioSpec
from .warm import HANDS_ENV

__all__ = ["CRASH", "TIMEOUT", "Task", "run_isolated", "warm_up"]

TIMEOUT = "timeout"  #: ScenarioResult.failure_kind of a scenario past its time limit
CRASH = "crash"  #: ScenarioResult.failure_kind of a scenario whose process died

#: A task: ``task(spec, **kwargs) -> ScenarioResult`` (a module-level function).
Task = Callable[..., ScenarioResult]

_PRELOAD = ["regrasp_pin.suite.run", "regrasp_pin.suite.warm"]
_MALLOC_TRIM = "MALLOC_TRIM_THRESHOLD_"
_context: Any = None


def _forkserver(hands: Sequence[str] = ()) -> Any:
    """The forkserver context, with the planner imported in the server and ``hands``
    warmed there (:mod:`.warm`), once per process (later calls return the running one).

    The server is started without ``MALLOC_TRIM_THRESHOLD_`` in its environment: Dask's
    nanny sets it to 64 KiB in every worker, which makes glibc hand memory back to the
    system after nearly every numpy temporary and slows a scenario down by ~1.6x
    (measured: s0-045 of the suite plans in 9.5 s with it, 5.8 s without).
    """
    global _context
    if _context is None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(_PRELOAD)
        saved = {key: os.environ.pop(key, None) for key in (_MALLOC_TRIM, HANDS_ENV)}
        if hands:
            os.environ[HANDS_ENV] = json.dumps(list(hands))
        try:
            multiprocessing.forkserver.ensure_running()
        finally:
            os.environ.pop(HANDS_ENV, None)
            os.environ.update({key: value for key, value in saved.items() if value is not None})
        _context = ctx
    return _context


def warm_up(hands: Sequence[str] = ()) -> None:
    """Start this process's forkserver ahead of the first scenario, with the planner
    imported in it and the named hands built and their caches filled
    (:func:`~.warm.warm_hands`), so that no scenario pays for them. Only the first
    call of a process starts it: call this before any scenario runs."""
    ctx = _forkserver(tuple(hands))
    proc = ctx.Process(target=_noop)
    proc.start()
    proc.join()


def _noop() -> None:
    pass


def _watch(pid: int, period_s: float = 1.0) -> None:
    """End this process once process ``pid`` (the one that asked for this scenario,
    e.g. a Dask worker) is gone, so that no scenario outlives the run that started it."""

    def watch() -> None:
        while True:
            time.sleep(period_s)
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:  # alive, under another user (a reused pid)
                pass

    threading.Thread(target=watch, name="watch-parent", daemon=True).start()


def _child(conn: Any, task: Task, spec: ScenarioSpec, kwargs: dict[str, Any], parent: int) -> None:
    # Ctrl-C stops the run (the driver), not this scenario with a bogus outcome
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _watch(parent)
    try:
        result = task(spec, **kwargs)
    except BaseException as exc:  # a task should not raise; if it does, say what
        result = outcome_template(spec)
        result.failure_kind = f"exception:{type(exc).__name__}"
        result.failure = f"{type(exc).__name__}: {exc}"
        result.failed_stage = "run"
    try:
        conn.send(result)
        conn.close()
    except OSError:  # the parent is gone (its worker died): nobody to tell
        pass


def _signal_name(code: int) -> str:
    try:
        return signal.Signals(-code).name
    except ValueError:
        return f"signal {-code}"


def run_isolated(
    task: Task,
    spec: ScenarioSpec,
    *,
    timeout_s: float | None = None,
    **kwargs: Any,
) -> ScenarioResult:
    """``task(spec, **kwargs)`` in a child process, at most ``timeout_s`` [s].

    Args:
        task: A module-level function (it is sent to the child by reference), e.g.
            :func:`~.run.run_scenario`.
        spec: The scenario.
        timeout_s: Wall-clock limit [s] of the child (None: none).
        **kwargs: Passed to ``task``.

    Returns:
        The task's result, or a ``"timeout"`` / ``"crash"`` failure of the spec
        (``failed_stage="run"``; ``plan_s`` holds the time the child ran).

    Raises:
        InputError: a ``timeout_s`` that is not positive.
    """
    limit = None if timeout_s is None else positive(timeout_s, "timeout_s")
    ctx = _forkserver()
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(
        target=_child, args=(send, task, spec, kwargs, os.getpid()), name=f"scenario {spec.name}"
    )
    t0 = time.perf_counter()
    proc.start()
    send.close()  # the child holds the only sending end: EOF when it dies
    result: ScenarioResult | None = None
    timed_out = False
    try:
        if recv.poll(limit):
            try:
                result = recv.recv()
            except EOFError:  # died before sending
                result = None
        else:
            timed_out = True
    finally:
        if timed_out or result is None:
            proc.kill()
        proc.join()
        recv.close()
    if result is not None:
        return result
    failed = outcome_template(spec)
    failed.failed_stage = "run"
    failed.plan_s = time.perf_counter() - t0
    if timed_out:
        failed.failure_kind = TIMEOUT
        failed.failure = f"still running after the time limit of {limit:g} s; stopped"
        failed.measured, failed.required = failed.plan_s, limit
    else:
        code = proc.exitcode if proc.exitcode is not None else 0
        how = f"killed by {_signal_name(code)}" if code < 0 else f"exited with code {code}"
        failed.failure_kind = CRASH
        failed.failure = f"the process running the scenario died ({how}) without a result"
        failed.measured = float(code)
    return failed
