"""The scenario suite: full-plan rate, failure kinds and planning times over many problems.

Runs the first ``--n`` scenarios of the deterministic suite ``--seed``
(:func:`regrasp_pin.suite.select_specs`; a spec without an initial grasp is skipped
and the next one drawn, at most 4 n draws) or, with ``--neighbours``, the canonical
demo and its 29 neighbours (:func:`regrasp_pin.suite.neighbour_specs`). Each scenario
is built, planned, and a full plan is saved, reloaded and re-checked with Pinocchio and
Coal alone (:func:`regrasp_pin.verify.plan_check.recheck_plan`).

Prints one line per scenario as it finishes (outcome, regrasps, times; the reason of a
failure on a second line), then :func:`regrasp_pin.suite.summarize` and where the time
went (:func:`regrasp_pin.suite.time_spent`: builds, planning with its setups, backups
and searches, re-checks, summed over the scenarios), then, with
``--baseline``, the change against a previous ``results.jsonl``: full-plan rate, median
planning times, the full plans won and lost with an exact sign test
(:func:`regrasp_pin.suite.report.paired_change`), and every scenario whose outcome
changed; for a baseline of other scenarios (another hand or seed), the two full-plan
rates with a Fisher exact test (:func:`regrasp_pin.suite.report.rate_difference`).
A fixed workload, the canonical scenario built and planned in this process
(:func:`machine.reference_s`, the fastest of ``--reference`` runs), is timed before and
after the suite and printed with the suite's wall time as a multiple of it: a coarse
gauge of the machine's speed during the run.
Writes ``results.jsonl`` (one :class:`~regrasp_pin.suite.ScenarioResult` per line, in spec order),
``skipped.jsonl`` and ``summary.txt`` into ``--out``, with the plans and partial plans.

``--hand`` picks the hands (bundled names or JSON hand files such as
``examples/hands/shadow_hand.json``; a hand file's canonical pose,
:func:`regrasp_pin.scenarios.setup_pose`, is searched once, here, and carried by its
specs as ``base_pose``: the processes that build them do not search it again).

The scenarios run on a local Dask cluster of ``--jobs`` workers, through the same code
as ``regrasp-pin suite`` (:func:`regrasp_pin.suite.cluster.run_suite`). With more than
one worker, the speed-up over one worker is first measured on the first ``--speedup``
scenarios (both runs in this run, one after the other) and printed.

Usage: ``python bench/suite.py [--n 100] [--seed 0] [--neighbours] [--hand NAME|FILE.json]
[--out out/suite] [--jobs 1] [--speedup K] [--max-steps 1600] [--grasp-backups 1] [--budget S]
[--time-law minimum-jerk|cruise] [--baseline old/results.jsonl] [--reference 3]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from machine import machine_line, reference_s

from regrasp_pin.planning.planner import PlannerParams
from regrasp_pin.planning.timing import TIME_LAWS
from regrasp_pin.scenarios import HANDS
from regrasp_pin.suite import (
    ScenarioResult,
    ScenarioSpec,
    load_results,
    neighbour_specs,
    select_specs,
    summarize,
    time_spent,
)
from regrasp_pin.suite.cluster import SuiteRun, run_suite
from regrasp_pin.suite.report import paired_change, rate_difference, result_line


def compare(results: list[ScenarioResult], baseline: list[ScenarioResult]) -> str:
    """Full-plan rate, median times and changed outcomes against a previous run."""

    def status(r: ScenarioResult) -> str:
        if r.ok:
            return "ok" if r.recheck_ok is not False else "ok (re-check failed)"
        return str(r.failure_kind)

    def median(values: list[float]) -> str:
        return f"{np.median(values):.3g}" if values else "n/a"

    old = {r.name: r for r in baseline}
    both = [r for r in results if r.name in old]
    if not both:  # another hand or seed: the rates alone compare
        return "against the baseline (no scenario in both runs): full plans " + (
            rate_difference(results, baseline).line()
        )
    out = [f"against the baseline ({len(both)} scenarios in both runs):"]
    k_new, k_old = sum(r.ok for r in both), sum(old[r.name].ok for r in both)
    out.append(f"  full plans          {k_old:4d} -> {k_new:4d} of {len(both)}")
    for what, get in (
        ("plan time [s]", lambda r: [r.plan_s] if r.plan_s is not None else []),
        ("regrasp time [ms]", lambda r: r.regrasp_ms),
    ):
        a = [v for r in both for v in get(old[r.name])]
        b = [v for r in both for v in get(r)]
        out.append(f"  median {what:18} {median(a):>8} -> {median(b):>8}")
    out.append(f"  full plans {paired_change(results, baseline).line()}")
    changed = [(r, old[r.name]) for r in both if status(r) != status(old[r.name])]
    out.append(f"  changed outcomes: {len(changed)}")
    for r, o in changed:
        out.append(f"    {r.name:60} {status(o)} -> {status(r)}")
    return "\n".join(out)


def speedup(specs: list[ScenarioSpec], k: int, jobs: int, out: Path, **kw) -> str:
    """The speed-up of ``jobs`` workers over one on the first ``k`` countable specs,
    both runs here and now (the same specs, the same machine, one after the other):
    scenarios per minute of work, the clusters' start left out (it is paid once per run,
    not per scenario) and shown apart."""
    runs = {w: run_suite(specs, k, out=out / f"speedup-{w}", workers=w, **kw) for w in (1, jobs)}

    def rate(r: SuiteRun) -> float:
        return len(r.results) / max(r.wall_s - r.startup_s, 1e-9) * 60.0

    one, many = runs[1], runs[jobs]
    return (
        f"speed-up of {jobs} workers over 1 on the first {len(one.results)} scenarios: "
        f"{rate(one):.1f} -> {rate(many):.1f} scenarios/min, {rate(many) / rate(one):.2f}x the "
        f"throughput (work {one.wall_s - one.startup_s:.0f} s -> "
        f"{many.wall_s - many.startup_s:.0f} s; starting the cluster {one.startup_s:.1f} s / "
        f"{many.startup_s:.1f} s)"
    )


def reference_line(before_s: float, after_s: float, done: SuiteRun) -> str:
    """The reference workload (:func:`machine.reference_s`) before and after the suite,
    and the suite's wall time as a multiple of their mean (a coarse gauge: it tells a
    machine that changed by much between two runs)."""
    mean = 0.5 * (before_s + after_s)
    return (
        f"reference workload (the canonical scenario built and planned here): {before_s:.2f} s "
        f"before the suite, {after_s:.2f} s after; the suite's wall time {done.wall_s:.0f} s "
        f"= {done.wall_s / mean:.0f} x the reference"
    )


def parse_args() -> argparse.Namespace:
    """The options, checked (hands resolved into ``args.hands``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100, help="scenarios with an initial grasp")
    parser.add_argument("--seed", type=int, default=0, help="suite seed")
    parser.add_argument(
        "--neighbours", action="store_true", help="the demo and its neighbours instead"
    )
    parser.add_argument(
        "--hand",
        action="append",
        dest="hands",
        metavar="NAME|FILE.json",
        help="a bundled hand or a JSON hand file (repeat for several; default: the bundled "
        "five_finger and allegro), e.g. examples/hands/shadow_hand.json",
    )
    parser.add_argument("--out", type=Path, default=Path("out/suite"), help="output folder")
    parser.add_argument("--jobs", type=int, default=1, help="workers of the local Dask cluster")
    parser.add_argument(
        "--speedup",
        type=int,
        default=None,
        metavar="K",
        help="first measure the speed-up of --jobs workers over one on the first K "
        "scenarios (default: 8 with --jobs > 1; 0: do not)",
    )
    parser.add_argument(
        "--max-steps",
        type=int,
        help="the planner's search budget in steps (default: PlannerParams.max_steps)",
    )
    parser.add_argument(
        "--grasp-backups",
        type=int,
        default=1,
        metavar="K",
        help="initial grasps a failed scenario backs up to (run_scenario; default 1, 0: none)",
    )
    parser.add_argument(
        "--budget",
        type=float,
        help="an optional wall-clock limit of each planning [s] (default: none; the step "
        "budget is the same on every machine, a time limit is not)",
    )
    parser.add_argument(
        "--time-law",
        choices=TIME_LAWS,
        help="the regrasps' time law (RegraspParams.time_law; default: the scenarios' own, "
        "minimum-jerk)",
    )
    parser.add_argument(
        "--torsion-mm",
        type=float,
        default=0.0,
        metavar="MM",
        help="soft fingertips: the torsional friction of every contact [mm] "
        "(ContactModel.torsion_m; default 0: point contacts with friction)",
    )
    parser.add_argument(
        "--baseline", type=Path, help="a previous results.jsonl (or its folder) to compare"
    )
    parser.add_argument(
        "--reference",
        type=int,
        default=3,
        metavar="K",
        help="time a fixed workload (the canonical scenario built and planned, the fastest "
        "of K runs) before and after the suite, a coarse gauge of the machine's speed "
        "during the run (default 3; 0: do not)",
    )
    args = parser.parse_args()
    if args.baseline is not None:  # checked now, not after the whole run
        if args.baseline.is_dir():
            args.baseline = args.baseline / "results.jsonl"
        if not args.baseline.is_file():
            parser.error(f"--baseline: no such file {args.baseline} (a results.jsonl)")
    if args.jobs < 1:
        parser.error("--jobs: at least 1")
    if args.grasp_backups < 0:
        parser.error("--grasp-backups: at least 0")
    if args.reference < 0:
        parser.error("--reference: at least 0")
    if not args.torsion_mm >= 0.0 or args.torsion_mm == float("inf"):
        parser.error("--torsion-mm: a finite number >= 0")

    hands = tuple(str(Path(h).resolve()) if h.endswith(".json") else h for h in args.hands or HANDS)
    for h in hands:
        if h.endswith(".json") and not Path(h).is_file():
            parser.error(f"--hand: no such hand file {h}")
        if not h.endswith(".json") and h not in HANDS:
            parser.error(f"--hand: {h!r} is neither a bundled hand {HANDS} nor a .json file")
    args.hands = hands
    return args


def main() -> None:
    args = parse_args()
    machine = machine_line()
    print(machine)
    hands = args.hands
    args.out.mkdir(parents=True, exist_ok=True)
    if args.neighbours:
        specs = neighbour_specs(hands)
        n, skip = len(specs), False
        what = f"the demo and its neighbours ({n} scenarios)"
    else:
        n, skip = args.n, True
        specs = select_specs(n, args.seed, hands)
        what = f"suite seed {args.seed}: {n} scenarios with an initial grasp"
    steps = args.max_steps or PlannerParams.max_steps
    limit = "" if args.budget is None else f" and {args.budget:g} s"
    if args.time_law is not None:
        limit += f", time law {args.time_law}"
    if args.torsion_mm > 0.0:
        limit += f", soft fingertips (torsion {args.torsion_mm:g} mm)"
    kw = {
        "skip_no_grasp": skip,
        "max_steps": args.max_steps,
        "budget_s": args.budget,
        "grasp_backups": args.grasp_backups,
        "time_law": args.time_law,
        "torsion_m": args.torsion_mm * 1e-3,
    }
    k = args.speedup if args.speedup is not None else (8 if args.jobs > 1 else 0)
    measured = None
    if k > 0:
        print(f"measuring the speed-up: the first {min(k, n)} scenarios on 1, then on "
              f"{args.jobs} worker(s)", flush=True)  # fmt: skip
        measured = speedup(specs, min(k, n), args.jobs, args.out, **kw)
        print(measured, flush=True)
    before = reference_s(args.reference) if args.reference else None
    print(f"{what}, {args.jobs} worker(s), budget {steps} steps{limit}, output {args.out}")

    def show(r: ScenarioResult, counted: int, total: int) -> None:
        if skip and r.failed_stage == "grasp":
            print(f"[skip]    {r.name:60} no initial grasp: {(r.failure or '')[:120]}", flush=True)
        else:
            print(result_line(r, counted, total), flush=True)

    done: SuiteRun = run_suite(specs, n, out=args.out, workers=args.jobs, on_result=show, **kw)
    reference = "" if before is None else reference_line(before, reference_s(args.reference), done)
    results = done.results
    text = summarize(results)
    if skip:
        skipped_line = done.describe().split("\n", 1)[0]  # with the kinds
        text += f"\nspecs drawn: {len(results) + len(done.skipped)}, {skipped_line}"
        if len(results) < n:
            text += f" -- only {len(results)} of {n} found in {len(specs)} draws"
    text += "\n" + done.describe().split("\n", 1)[1]
    text += "\n" + time_spent(results, done.skipped)
    if reference:
        text += "\n" + reference
    if measured:
        text += "\n" + measured
    if args.baseline is not None:
        text += "\n" + compare(results, load_results(args.baseline))
    text += "\n" + machine
    (args.out / "summary.txt").write_text(text + "\n")
    print()
    print(text)


if __name__ == "__main__":
    main()
