"""The bench scripts that patch package functions to time or compare them still find
those functions: a rename in the package must not leave a script that crashes (as
bench/scenario.py did after ``suite.build`` stopped importing ``grasp_for_motion``).
Each runs on its smallest input in a subprocess; the figures are not judged here
(speed targets live in the scripts), what they compare is."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "bench"


def test_scenario_bench_builds_the_same_scenario_by_both_paths():
    out = subprocess.run(
        [sys.executable, str(BENCH / "scenario.py"), "--neighbours-only", "--limit", "1"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=BENCH,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    # the current build path and the reference one (every manifold entry mapped) agree
    assert "same scenarios (bit for bit): 1 of 1" in out.stdout, out.stdout[-2000:]


def test_side_by_side_times_each_run_to_its_own_end():
    """Two runs that end 0.2 s and 3 s after their start: each wall time is its own
    (waiting for one run and then the other gave the first to end the other's time).
    Not a speed test: the bounds leave seconds for the interpreters to start."""
    sys.path.insert(0, str(BENCH))
    try:
        import side_by_side
    finally:
        sys.path.remove(str(BENCH))
    import time

    runs = {
        name: (subprocess.Popen([sys.executable, "-c", f"import time; time.sleep({s})"]), t0)
        for name, s, t0 in (("base", 3.0, time.perf_counter()), ("new", 0.2, time.perf_counter()))
    }
    wall = side_by_side.wall_times(runs)
    assert wall["base"] > 2.9 and 0.1 < wall["new"] < wall["base"] - 1.5
