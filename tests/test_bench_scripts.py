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
