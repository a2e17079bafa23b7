"""The demo end to end, stage by stage (target: <= 3 s after imports on 2 cores).

Builds the canonical scenario, plans the whole motion (manifolds, initial grasp,
tracking, every regrasp with its Coal verification, plan assembly) and prints each
stage's time, best of ``--repeats`` runs, on each IK backend installed: numpy (the
baseline, always) and numba (the optional accelerator, ``pip install -e '.[fast]'``),
their runs interleaved so that both see the same machine load. Then whether both
backends planned the same regrasps (fingers, lift-off and landing times, new contacts
within 0.1 mm). Imports and the numba kernels' compilation are not timed.
Usage: ``python bench/demo.py [--hand five_finger|allegro] [--repeats 2]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from machine import machine_line

from regrasp_pin import make_scenario, plan_manipulation
from regrasp_pin.grasp.manifold import default_threads, forget_first_times
from regrasp_pin.model.ik import IK_BACKENDS, ik_backend, set_ik_backend
from regrasp_pin.model.ik_numba import available as numba_available
from regrasp_pin.planning.planner import ManipulationPlan
from regrasp_pin.scenarios import Scenario

SAME_Q_M = 1e-4  # new contacts this close count as the same [m]


def run(hand: str, obj: str) -> tuple[float, dict[str, float], Scenario, ManipulationPlan]:
    """One demo run: total [s], stage times [s], the scenario and the plan."""
    forget_first_times()  # each run solves its manifolds' first times itself
    t0 = time.perf_counter()
    scen = make_scenario(hand, obj)
    t_scen = time.perf_counter() - t0
    result = plan_manipulation(
        scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params
    )
    total = time.perf_counter() - t0
    stages = {"scenario (hand, grasp)": t_scen, **result.stage_s}
    for r in result.regrasps:
        for k, v in r.stage_ms.items():
            key = f"  regrasp: {k}"
            stages[key] = stages.get(key, 0.0) + v / 1e3
    return total, stages, scen, result


def same_regrasps(a: ManipulationPlan, b: ManipulationPlan) -> tuple[bool, float]:
    """Whether two plans make the same regrasps (finger, times to 1 ms, Q within
    :data:`SAME_Q_M`), and the largest distance between their new contacts [m]."""
    ra, rb = a.regrasps, b.regrasps
    if [r.finger for r in ra] != [r.finger for r in rb]:
        return False, float("inf")
    times = all(
        abs(x.t_start - y.t_start) < 1e-3 and abs(x.t_end - y.t_end) < 1e-3
        for x, y in zip(ra, rb, strict=True)
    )
    dq = max(
        (float(np.linalg.norm(x.Q_object - y.Q_object)) for x, y in zip(ra, rb, strict=True)),
        default=0.0,
    )
    return times and dq <= SAME_Q_M, dq


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hand", default="five_finger", choices=("five_finger", "allegro"))
    parser.add_argument("--object", default="hexagon", choices=("hexagon", "octagon", "box"))
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    print(machine_line())

    backends = [b for b in IK_BACKENDS if b == "numpy" or numba_available()]
    previous = ik_backend()
    best: dict[str, tuple[float, dict[str, float], Scenario, ManipulationPlan]] = {}
    threads: dict[str, int] = {}
    try:
        if "numba" in backends:  # compile the kernels outside the timed runs
            set_ik_backend("numba")
            make_scenario(args.hand, args.object)
        for _ in range(args.repeats):
            for b in backends:
                set_ik_backend(b)
                threads[b] = default_threads()
                out = run(args.hand, args.object)
                if b not in best or out[0] < best[b][0]:
                    best[b] = out
    finally:
        set_ik_backend(previous)

    scen, result = best["numpy"][2], best["numpy"][3]
    print(scen.description)
    print(f"{len(result.regrasps)} regrasps by {sorted({r.finger for r in result.regrasps})}")
    print(
        f"{'stage [s], best of ' + str(args.repeats):28}"
        + "".join(f"{b + f' ({threads[b]} thr.)':>18}" for b in backends)
    )
    for name in best["numpy"][1]:
        print(f"{name:28}" + "".join(f"{best[b][1].get(name, 0.0):18.3f}" for b in backends))
    print(
        f"{'total (after imports)':28}"
        + "".join(f"{best[b][0]:18.3f}" for b in backends)
        + "   target <= 3 s"
    )
    for b in backends[1:]:
        same, dq = same_regrasps(result, best[b][3])
        print(
            f"{b} / numpy: {best[b][0] / best['numpy'][0]:.2f}x the time; same regrasps: "
            f"{same} (new contacts within {1e3 * dq:.2g} mm)"
        )
    if len(backends) == 1:
        print("numba is not installed (pip install -e '.[fast]'): numpy only")


if __name__ == "__main__":
    main()
