"""The machine a bench figure was measured on, printed first by every bench script.

Figures drift between machines and between runs on one machine (other jobs, CPU
frequency): a figure is only comparable with a baseline measured in the same run and
printed beside it, and it is only quotable with the machine it came from. The line
says which CPU, how many cores the process may use, how busy the machine was when the
script started (load average over the last minute), and the versions that set the
speed (Python, numpy, scipy, Pinocchio, Coal, numba) and the IK backend.
"""

from __future__ import annotations

import os
import platform
from importlib import metadata

PACKAGES = ("numpy", "scipy", "pin", "coal", "numba")


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; else what ``platform`` says)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def usable_cores() -> int:
    """The cores this process may run on (its affinity; else every core)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def versions() -> dict[str, str]:
    """Installed versions of :data:`PACKAGES` (``"-"`` for one not installed)."""
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "-"
    return out


def machine_line() -> str:
    """One line: CPU, usable / logical cores, the 1-minute load, versions, IK backend."""
    try:
        load = f"{os.getloadavg()[0]:.2f}"
    except (AttributeError, OSError):
        load = "?"
    from regrasp_pin.model.ik import ik_backend

    backend = ik_backend()
    packages = ", ".join(f"{k} {v}" for k, v in versions().items())
    return (
        f"machine: {cpu_model()}, {usable_cores()}/{os.cpu_count()} cores, load {load}; "
        f"{packages}; IK backend {backend}"
    )


def reference_s(repeats: int = 3) -> float:
    """A fixed workload's wall time on this machine now [s]: the fastest of ``repeats``
    runs (the others are that plus other jobs' noise) that build the canonical scenario
    and plan it (:func:`regrasp_pin.make_scenario`, :func:`regrasp_pin.plan_manipulation`;
    the IK backend and threads as they are set), after one run that compiles the kernels
    and fills the caches (the first-time IK solves that the manifolds remember are
    forgotten before each run).

    A long bench run (the scenario suite) has no baseline of its own in the same run:
    this workload, timed before and after it, gauges the machine's speed while it ran
    (the same machine can run 10-15 % slower an hour later). A coarse gauge: on the
    2-core machine its value spread over 2.04-2.63 s within an hour, so it tells a
    large change of the machine between two runs, not a few percent.
    """
    import time

    from regrasp_pin import make_scenario, plan_manipulation
    from regrasp_pin.grasp.manifold import forget_first_times

    def once() -> float:
        forget_first_times()  # each run solves its manifolds' first times itself
        t0 = time.perf_counter()
        scen = make_scenario()
        plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
        return time.perf_counter() - t0

    once()
    return min(once() for _ in range(max(int(repeats), 1)))


if __name__ == "__main__":
    print(machine_line())
