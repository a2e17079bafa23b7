"""The scenario suite's time for two revisions of the code, run side by side.

A machine's speed drifts between runs minutes apart by more than most savings (on the
2-core machine of 2026-12-07 the same code took 601 s and 495 s one run after the
other), and a workload timed before and after a run cannot see it when it runs the
code under test. Two runs at the same time, each on cores of its own, see the same
machine. This script checks out the two revisions (``git archive``, into
``--out``/src-<rev>; both fresh, so both compile their numba kernels), starts
``bench/suite.py`` of each with the same options (everything after ``--``) in a
process pinned to half of the usable cores (``os.sched_setaffinity``; its workers
inherit it), waits for both, and prints each run's wall time and time spent (builds,
planning, re-checks, summed over its scenarios), the ratio, and the scenarios whose
outcome differs.

Usage: ``python bench/side_by_side.py --base REV [--new REV] [--out out/side_by_side]
-- --n 100 --jobs 1 --speedup 0 --reference 0``.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import tarfile
import time
from pathlib import Path

from machine import machine_line

from regrasp_pin.suite import load_results

ROOT = Path(__file__).resolve().parents[1]


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the baseline revision (a git rev)")
    parser.add_argument("--new", default="HEAD", help="the revision measured (default HEAD)")
    parser.add_argument("--out", type=Path, default=Path("out/side_by_side"))
    parser.add_argument("suite_args", nargs=argparse.REMAINDER, help="-- bench/suite.py options")
    args = parser.parse_args()
    args.suite_args = [a for a in args.suite_args if a != "--"]
    if "--out" in args.suite_args:
        parser.error("--out of bench/suite.py is set here (--out/<rev>)")
    cores = sorted(os.sched_getaffinity(0))
    if len(cores) < 2:
        parser.error(f"needs at least 2 usable cores, has {len(cores)}")
    args.cores = (cores[: len(cores) // 2], cores[len(cores) // 2 :])
    return args


def resolve(rev: str) -> str:
    """The commit of ``rev`` (raises if git does not know it)."""
    return subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", f"{rev}^{{commit}}"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()


def checkout(commit: str, into: Path) -> Path:
    """The tree of ``commit`` written into ``into`` (``git archive``)."""
    tar = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "--format=tar", commit],
        check=True,
        capture_output=True,
    ).stdout
    into.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(tar)) as t:
        if hasattr(tarfile, "data_filter"):  # Python >= 3.11.4, 3.10.12
            t.extractall(into, filter="data")
        else:
            t.extractall(into)  # our own repository's archive
    return into


def start(tree: Path, out: Path, suite_args: list[str], cores: list[int]) -> subprocess.Popen:
    """``bench/suite.py`` of ``tree``, its output in ``out``/suite.log, pinned to
    ``cores``."""
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    with open(out / "suite.log", "w") as log:  # the child keeps its own descriptor
        return subprocess.Popen(
            [sys.executable, "bench/suite.py", *suite_args, "--out", str(out / "run")],
            cwd=tree,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            preexec_fn=lambda: os.sched_setaffinity(0, cores),
        )


def sums(results_path: Path) -> dict[str, float]:
    """The scenarios' summed builds, planning and re-checks [s], and their outcomes."""
    results = load_results(results_path)
    return {
        "builds": sum(r.build_s or 0.0 for r in results),
        "planning": sum(r.plan_s or 0.0 for r in results),
        "re-checks": sum(r.recheck_s or 0.0 for r in results),
        "full plans": sum(r.ok for r in results),
        "outcomes": {r.name: (r.ok, r.failure_kind, r.n_regrasps) for r in results},
    }


def wall_times(runs: dict[str, tuple[subprocess.Popen, float]]) -> dict[str, float]:
    """Each run's wall time [s], from its start to its own end: the runs are polled
    together (waiting for one after the other would give a run that ends first the
    other's end)."""
    wall: dict[str, float] = {}
    while len(wall) < len(runs):
        for name, (proc, t0) in runs.items():
            if name not in wall and proc.poll() is not None:
                wall[name] = time.perf_counter() - t0
        time.sleep(0.2)
    return wall


def main() -> None:
    args = parse_args()
    print(machine_line())
    revs = {"base": resolve(args.base), "new": resolve(args.new)}
    runs = {}
    for (name, commit), cores in zip(revs.items(), args.cores, strict=True):
        tree = checkout(commit, args.out / f"src-{commit[:10]}")
        out = args.out / name
        print(f"{name}: {commit[:10]} on cores {cores}, log {out / 'suite.log'}", flush=True)
        runs[name] = (start(tree, out, args.suite_args, cores), time.perf_counter())
    wall = wall_times(runs)
    for name, (proc, _) in runs.items():
        if proc.returncode != 0:
            sys.exit(f"{name}: bench/suite.py failed, see {args.out / name / 'suite.log'}")
    got = {name: sums(args.out / name / "run" / "results.jsonl") for name in runs}
    print(f"{'':12} {'base':>10} {'new':>10} {'new/base':>9}")
    for key in ("wall", "builds", "planning", "re-checks"):
        a = wall["base"] if key == "wall" else got["base"][key]
        b = wall["new"] if key == "wall" else got["new"][key]
        print(f"{key:12} {a:9.1f}s {b:9.1f}s {b / a if a else float('nan'):9.3f}")
    print(f"{'full plans':12} {got['base']['full plans']:10d} {got['new']['full plans']:10d}")
    old, new = got["base"]["outcomes"], got["new"]["outcomes"]
    changed = sorted(n for n in old.keys() | new.keys() if old.get(n) != new.get(n))
    print(f"outcomes changed: {len(changed)} of {len(old.keys() | new.keys())}")
    for n in changed:
        print(f"  {n}: {old.get(n)} -> {new.get(n)}")


if __name__ == "__main__":
    main()
