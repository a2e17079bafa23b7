"""Scenario construction (initial grasp): build time per scenario and where it goes.

Target: median build <= 1 s on 2 cores. Builds the canonical demo and its 29
neighbours (:func:`regrasp_pin.suite.neighbour_specs`) and the first ``--random``
specs of the random suite (:func:`regrasp_pin.suite.generate_specs`, seed 0) with
:func:`regrasp_pin.suite.build_scenario`, twice in this run, one after the other per
spec: the current path, and the reference path in which the grasp search maps every
entry of its manifolds (``grasp_for_motion(track_start=False)``, the implementation
before start tracking). Prints median and p95 build times of both, a per-stage
breakdown (manifolds, the must-hold proof with the idle fingers' manifolds, the
initial-grasp search, the rest) and whether both built the same scenarios (grasp
indices, points, configurations and epsilon, object poses; bit for bit).

Usage: ``python bench/scenario.py [--random 20] [--neighbours-only] [--limit K]``.
"""

from __future__ import annotations

import argparse
import functools
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np
from machine import machine_line

import regrasp_pin.scenarios as scenarios
from regrasp_pin.exceptions import ContactError
from regrasp_pin.grasp.manifold import default_threads, forget_first_times
from regrasp_pin.model.ik import set_ik_backend
from regrasp_pin.model.ik_numba import available as numba_available
from regrasp_pin.scenarios import Scenario
from regrasp_pin.suite import ScenarioSpec, build_scenario, generate_specs, neighbour_specs

STAGES = ("manifolds", "must hold", "initial grasp")


class StageTimer:
    """Wall time [s] per stage of the grasp search, by wrapping the functions that
    :func:`regrasp_pin.scenarios.grasp_for_motion` calls (nothing in the package
    changes)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)

    def wrap(self, stage: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(fn)
        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[stage] += time.perf_counter() - t0

        return timed


def build(
    spec: ScenarioSpec, reference: bool, backend: str = "numpy"
) -> tuple[float, dict[str, float], Any]:
    """Build one spec with its IK on ``backend``; its wall time [s], stage times [s] and
    fingerprint (or the error)."""
    previous = set_ik_backend(backend)
    try:
        return _build(spec, reference)
    finally:
        set_ik_backend(previous)


def _build(spec: ScenarioSpec, reference: bool) -> tuple[float, dict[str, float], Any]:
    timer = StageTimer()
    saved = {
        "build_manifolds": scenarios.build_manifolds,
        "must_hold": scenarios.must_hold,
        "with_idle_fingers": scenarios.with_idle_fingers,
        "initial_grasp": scenarios.initial_grasp,
    }
    saved_gfm = scenarios.grasp_for_motion
    scenarios.build_manifolds = timer.wrap("manifolds", saved["build_manifolds"])
    scenarios.must_hold = timer.wrap("must hold", saved["must_hold"])
    scenarios.with_idle_fingers = timer.wrap("must hold", saved["with_idle_fingers"])
    scenarios.initial_grasp = timer.wrap("initial grasp", saved["initial_grasp"])
    if reference:
        scenarios.grasp_for_motion = functools.partial(saved_gfm, track_start=False)
    forget_first_times()  # each build solves its manifolds' first times itself
    try:
        t0 = time.perf_counter()
        try:
            out: Any = fingerprint(build_scenario(spec))
        except ContactError as exc:
            out = ("ContactError", str(exc))
        wall = time.perf_counter() - t0
    finally:
        for name, fn in saved.items():
            setattr(scenarios, name, fn)
        scenarios.grasp_for_motion = saved_gfm
    stages = dict(timer.seconds)
    stages["other"] = wall - sum(stages.values())
    return wall, stages, out


def fingerprint(scen: Scenario) -> tuple[Any, ...]:
    """What must not change: the grasp (indices, points, configurations, epsilon) and
    the object's motion (its sampled poses), as exact bytes."""
    g = scen.grasp
    assert g is not None
    return (
        tuple(sorted(g.indices.items())),
        tuple((n, g.points_object[n].tobytes(), g.q[n].tobytes()) for n in sorted(g.q)),
        float(g.epsilon),
        scen.motion.T_palm_object.tobytes(),
    )


def summary(label: str, walls: list[float], stages: list[dict[str, float]]) -> str:
    w = np.array(walls)
    parts = "  ".join(
        f"{s} {np.median([st.get(s, 0.0) for st in stages]):.3f}" for s in (*STAGES, "other")
    )
    return (
        f"{label:10} median {np.median(w):6.2f} s  p95 {np.percentile(w, 95):6.2f} s  "
        f"mean {w.mean():6.2f} s | median per stage [s]: {parts}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random", type=int, default=20, help="random specs (seed 0)")
    parser.add_argument("--neighbours-only", action="store_true")
    parser.add_argument("--limit", type=int, default=None, help="only the first K specs")
    args = parser.parse_args()
    print(machine_line())
    specs = neighbour_specs() + ([] if args.neighbours_only else generate_specs(args.random, 0))
    specs = specs[: args.limit]
    # the current path on numpy, the reference path, and the current path on numba
    labels = ["current", "reference"] + (["numba"] if numba_available() else [])
    for label in labels:  # per-process caches (hands, workspace covers, numba kernels)
        build(specs[0], reference=label == "reference", backend=_backend(label))
    rows: dict[str, dict[str, list[Any]]] = {k: defaultdict(list) for k in labels}
    same = same_grasp = 0
    print(f"{'spec':58} " + " ".join(f"{k:>9}" for k in labels) + "  same")
    for spec in specs:
        results = {}
        for label in labels:
            wall, stages, fp = build(spec, label == "reference", _backend(label))
            rows[label]["wall"].append(wall)
            rows[label]["stages"].append(stages)
            results[label] = fp
        ok = results["current"] == results["reference"]
        same += ok
        if "numba" in results:
            same_grasp += _contacts(results["numba"]) == _contacts(results["current"])
        print(
            f"{spec.name[:58]:58} "
            + " ".join(f"{rows[k]['wall'][-1]:8.2f}s" for k in labels)
            + f"  {ok}",
            flush=True,
        )
    print()
    for label in labels:
        print(summary(label, rows[label]["wall"], rows[label]["stages"]))
    n_nb = sum(s in neighbour_specs() for s in specs)
    for label in labels:
        w = np.array(rows[label]["wall"])
        print(
            f"{label:10} neighbours median {np.median(w[:n_nb]):.2f} s"
            + (f", random median {np.median(w[n_nb:]):.2f} s" if len(w) > n_nb else "")
        )
    print(f"same scenarios (bit for bit): {same} of {len(specs)}   target: median <= 1 s")
    if "numba" in labels:
        print(
            f"numba: the IK on numba, manifolds on {_numba_threads()} thread(s); the same "
            f"contacts as on numpy in {same_grasp} of {len(specs)} scenarios"
        )
    else:
        print("numba not installed: no numba row (pip install -e '.[fast]')")


def _backend(label: str) -> str:
    return "numba" if label == "numba" else "numpy"


def _numba_threads() -> int:
    previous = set_ik_backend("numba")
    try:
        return default_threads()
    finally:
        set_ik_backend(previous)


def _contacts(fp: Any) -> Any:
    """The grasp's contacts (sample indices) of a fingerprint, or the error."""
    return fp if fp and fp[0] == "ContactError" else fp[0]


if __name__ == "__main__":
    main()
