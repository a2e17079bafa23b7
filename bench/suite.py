"""The scenario suite: full-plan rate, failure kinds and planning times over many problems.

Runs the first ``--n`` scenarios of the deterministic suite ``--seed``
(:func:`regrasp_pin.suite.generate_specs`; a spec without an initial grasp is skipped
and the next one drawn, as :func:`regrasp_pin.suite.suite_scenarios` does, at most
4 n draws) or, with ``--neighbours``, the canonical demo and its 29 neighbours
(:func:`regrasp_pin.suite.neighbour_specs`). Each scenario is built, planned, and a
full plan is saved, reloaded and re-checked with Pinocchio and Coal alone
(:func:`regrasp_pin.verify.plan_check.recheck_plan`).

Prints one line per scenario as it finishes (outcome, regrasps, times; the reason of a
failure on a second line), then :func:`regrasp_pin.suite.summarize`, then, with
``--baseline``, the change against a previous ``results.jsonl``: full-plan rate, median
planning times, and every scenario whose outcome changed. Writes ``results.jsonl``
(one :class:`~regrasp_pin.suite.ScenarioResult` per line, in spec order),
``skipped.jsonl`` and ``summary.txt`` into ``--out``, with the plans and partial plans.

``--hand`` picks the hands (bundled names or JSON hand files such as
``examples/hands/shadow_hand.json``; a hand file's canonical pose is searched once per
process, :func:`regrasp_pin.scenarios.setup_pose`).

Usage: ``python bench/suite.py [--n 100] [--seed 0] [--neighbours] [--hand NAME|FILE.json]
[--out out/suite] [--jobs 1] [--max-steps 400] [--budget S] [--baseline old/results.jsonl]``.
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

import numpy as np

from regrasp_pin.planning.planner import PlannerParams
from regrasp_pin.scenarios import HANDS
from regrasp_pin.suite import (
    MAX_DRAWS_PER_SCENARIO,
    ScenarioResult,
    ScenarioSpec,
    generate_specs,
    load_results,
    neighbour_specs,
    run_scenario,
    summarize,
)


def line(r: ScenarioResult, done: int, total: int) -> str:
    """One line per scenario (and the failure's reason on a second line)."""
    plan = "     -  " if r.plan_s is None else f"{r.plan_s:6.1f} s"
    times = f"build {r.build_s or 0:5.1f} s  plan {plan}"
    head = f"[{done:3d}/{total}] {r.name:60}"
    c0 = r.initial_finger_clearance_m
    if c0 is not None and c0 <= 0.0:
        times += f"  (starts with fingers {-c0 * 1e3:.1f} mm inside each other)"
    if r.ok:
        check = {True: "re-check ok", False: "RE-CHECK FAILED", None: "not re-checked"}
        status = f"ok   {r.n_regrasps:2d} regrasps  {check[r.recheck_ok]:15}"
        text = f"{head} {status} {times}"
        if r.recheck_ok is False:
            text += "\n      " + "; ".join(r.recheck_problems[:3])
        return text
    where = " ".join(
        x
        for x in (
            r.finger or "",
            f"t={r.time_s:.2f}/{r.duration_s:.1f} s" if r.time_s is not None else "",
        )
        if x
    )
    status = f"FAIL {r.failure_kind} ({r.failed_stage}) {where} after {r.n_regrasps} regrasps"
    return f"{head} {status:45} {times}\n      {(r.failure or '')[:200]}"


def run(
    specs: list[ScenarioSpec],
    n: int,
    *,
    skip_no_grasp: bool,
    out: Path,
    jobs: int,
    max_steps: int | None,
    budget_s: float | None,
) -> tuple[list[ScenarioResult], list[ScenarioResult]]:
    """Run specs in order until ``n`` count (skipped ones do not), on ``jobs`` processes.

    A spec is started only while fewer than ``n`` are counted or running, so the
    counted ones are the first ``n`` countable specs whatever the completion order.
    Returns ``(counted, skipped)``, both in spec order.
    """
    counted: dict[int, ScenarioResult] = {}
    skipped: dict[int, ScenarioResult] = {}
    stream = (out / "results.jsonl").open("w")

    def take(i: int, r: ScenarioResult) -> None:
        if skip_no_grasp and r.failed_stage == "grasp":
            skipped[i] = r
            print(f"[skip]    {r.name:60} no initial grasp: {(r.failure or '')[:120]}", flush=True)
            return
        counted[i] = r
        stream.write(json.dumps(r.to_dict()) + "\n")
        stream.flush()
        print(line(r, len(counted), n), flush=True)

    nxt = 0
    if jobs <= 1:
        while len(counted) < n and nxt < len(specs):
            take(nxt, run_scenario(specs[nxt], out_dir=out, max_steps=max_steps, budget_s=budget_s))
            nxt += 1
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            pending: dict[Future, int] = {}
            while True:
                while len(counted) + len(pending) < n and nxt < len(specs):
                    fut = pool.submit(
                        run_scenario,
                        specs[nxt],
                        out_dir=out,
                        max_steps=max_steps,
                        budget_s=budget_s,
                    )
                    pending[fut] = nxt
                    nxt += 1
                if not pending:
                    break
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in sorted(done, key=pending.__getitem__):
                    take(pending.pop(fut), fut.result())
    stream.close()
    return [counted[i] for i in sorted(counted)], [skipped[i] for i in sorted(skipped)]


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
    changed = [(r, old[r.name]) for r in both if status(r) != status(old[r.name])]
    out.append(f"  changed outcomes: {len(changed)}")
    for r, o in changed:
        out.append(f"    {r.name:60} {status(o)} -> {status(r)}")
    return "\n".join(out)


def main() -> None:
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
    parser.add_argument("--jobs", type=int, default=1, help="processes (1: in this one)")
    parser.add_argument(
        "--max-steps",
        type=int,
        help="the planner's search budget in steps (default: PlannerParams.max_steps)",
    )
    parser.add_argument(
        "--budget",
        type=float,
        help="an optional wall-clock limit of each planning [s] (default: none; the step "
        "budget is the same on every machine, a time limit is not)",
    )
    parser.add_argument(
        "--baseline", type=Path, help="a previous results.jsonl (or its folder) to compare"
    )
    args = parser.parse_args()
    if args.baseline is not None:  # checked now, not after the whole run
        if args.baseline.is_dir():
            args.baseline = args.baseline / "results.jsonl"
        if not args.baseline.is_file():
            parser.error(f"--baseline: no such file {args.baseline} (a results.jsonl)")

    hands = tuple(str(Path(h).resolve()) if h.endswith(".json") else h for h in args.hands or HANDS)
    for h in hands:
        if h.endswith(".json") and not Path(h).is_file():
            parser.error(f"--hand: no such hand file {h}")
        if not h.endswith(".json") and h not in HANDS:
            parser.error(f"--hand: {h!r} is neither a bundled hand {HANDS} nor a .json file")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.neighbours:
        specs = neighbour_specs(hands)
        n, skip = len(specs), False
        what = f"the demo and its neighbours ({n} scenarios)"
    else:
        n, skip = args.n, True
        specs = generate_specs(MAX_DRAWS_PER_SCENARIO * n, args.seed, hands)
        what = f"suite seed {args.seed}: {n} scenarios with an initial grasp"
    steps = args.max_steps or PlannerParams.max_steps
    limit = "" if args.budget is None else f" and {args.budget:g} s"
    print(f"{what}, {args.jobs} process(es), budget {steps} steps{limit}, output {args.out}")
    t0 = time.perf_counter()
    results, skipped = run(
        specs,
        n,
        skip_no_grasp=skip,
        out=args.out,
        jobs=args.jobs,
        max_steps=args.max_steps,
        budget_s=args.budget,
    )
    wall = time.perf_counter() - t0
    with (args.out / "results.jsonl").open("w") as f:  # in spec order
        f.writelines(json.dumps(r.to_dict()) + "\n" for r in results)
    with (args.out / "skipped.jsonl").open("w") as f:
        f.writelines(json.dumps(r.to_dict()) + "\n" for r in skipped)
    text = summarize(results)
    if skip:
        text += (
            f"\nspecs drawn: {len(results) + len(skipped)}, skipped without an initial "
            f"grasp: {len(skipped)}"
        )
        if len(results) < n:
            text += f" -- only {len(results)} of {n} found in {len(specs)} draws"
    text += f"\nwall time: {wall:.0f} s on {args.jobs} process(es)"
    if args.baseline is not None:
        text += "\n" + compare(results, load_results(args.baseline))
    (args.out / "summary.txt").write_text(text + "\n")
    print()
    print(text)


if __name__ == "__main__":
    main()
