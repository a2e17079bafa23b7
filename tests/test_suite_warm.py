"""Warming the scenario processes (regrasp_pin.suite.warm, isolate.warm_up)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from regrasp_pin.grasp.manifold import build_manifold, workspace_voxels
from regrasp_pin.model.motion import ObjectMotion
from regrasp_pin.model.objects import Box
from regrasp_pin.suite.build import suite_hand
from regrasp_pin.suite.warm import warm_hands


def test_warming_fills_the_caches_a_manifold_reads_and_changes_no_number():
    hand = suite_hand("five_finger")
    f = hand.finger("index")
    T = np.eye(4)
    T[:3, 3] = f.fk(f.q_mid[None])[0] + [0.0, 0.0, -0.02]
    motion = ObjectMotion.from_poses(np.array([0.0, 0.2]), np.stack([T, T]))
    sample = Box((0.03, 0.03, 0.03)).sample_surface(0.004)
    times = np.array([0.0, 0.1, 0.2])
    workspace_voxels.cache_clear()
    cold = build_manifold(f, sample, motion, times)
    warm_hands(["five_finger"])
    assert suite_hand("five_finger") is hand  # one hand per process
    hits = workspace_voxels.cache_info().hits
    warm = build_manifold(f, sample, motion, times)
    assert workspace_voxels.cache_info().hits == hits + 1  # the cover was there
    assert cold.reachable.any()
    for name in ("q", "reachable", "inside", "margin_rad", "pad_ok", "tip_clear"):
        assert getattr(cold, name).tobytes() == getattr(warm, name).tobytes(), name


_CHILD = """
import sys
from regrasp_pin.suite.isolate import run_isolated, warm_up
from regrasp_pin.suite.specs import generate_specs
import suite_tasks
hands = sys.argv[1:]
warm_up(hands)
r = run_isolated(suite_tasks.caches, generate_specs(1, 0)[0])
print(int(r.measured), int(r.required))
"""


def _caches_in_a_scenario_process(*hands: str) -> tuple[int, int]:
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, *hands],
        capture_output=True,
        text=True,
        check=True,
        cwd=Path(__file__).parent,
        timeout=300,
    )
    built, covers = out.stdout.split()[-2:]
    return int(built), int(covers)


def test_a_scenario_process_starts_with_the_hands_of_the_run_built():
    # warmed: both hands and a cover per finger (4 Allegro + 5 five-finger fingers)
    assert _caches_in_a_scenario_process("allegro", "five_finger") == (2, 9)
    assert _caches_in_a_scenario_process() == (0, 0)  # not warmed: a cold start
