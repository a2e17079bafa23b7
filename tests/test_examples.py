"""Every example script runs to the end (outputs go to a temporary folder), and what it
returns is checked against a reason: the exact optimum bounds the Hopfield energy, the
manifold round-trips through forward kinematics, the saved plan passes the independent
re-check, the regrasp lands on its contact."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from conftest import shadow_urdf
from scipy.spatial.transform import Rotation

from regrasp_pin import Hand
from regrasp_pin.plan import Plan
from regrasp_pin.verify.plan_check import recheck_plan

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _run(name: str, tmp_path: Path, capsys):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.__doc__, "every example says what it shows"
    result = module.main(out=tmp_path)
    assert capsys.readouterr().out.strip(), "the example prints what it did"
    return result


def test_polygonal_approximation_never_beats_the_exact_optimum(tmp_path, capsys):
    energies = _run("polygonal_approximation", tmp_path, capsys)
    assert len(energies) == 4
    for hopfield, exact in energies:
        assert np.isfinite(hopfield) and exact > 0
        assert hopfield >= exact * (1 - 1e-12)


def test_manifold_points_round_trip_through_forward_kinematics(tmp_path, capsys):
    man, sample = _run("manifold", tmp_path, capsys)
    finger = Hand.five_finger().fingers[man.finger]
    assert np.all(man.feasible <= man.inside) and np.all(man.inside <= man.reachable)
    k = man.times_s.size // 2
    idx = np.flatnonzero(man.feasible[k])
    assert idx.size > 0
    tip_palm = finger.fk(man.q[k, idx])
    T = man.T_palm_object[k]
    tip_object = (tip_palm - T[:3, 3]) @ T[:3, :3]
    # the fingertip centre sits one tip radius out along the surface normal
    on_surface = tip_object - finger.tip_radius * sample.normals[idx]
    assert np.max(np.linalg.norm(on_surface - sample.points[idx], axis=1)) < 1e-4


def test_regrasp_prism_writes_a_plan_that_passes_the_recheck(tmp_path, capsys):
    path = _run("regrasp_prism", tmp_path, capsys)
    check = recheck_plan(Plan.load(path))
    assert check.ok, check.problems
    assert len(check.regrasps) >= 1


def test_allegro_regrasp_lands_on_its_new_contact(tmp_path, capsys):
    result = _run("allegro_regrasp", tmp_path, capsys)
    assert result.report.ok
    # the executed tip (forward kinematics of the returned joints, in the object frame)
    # ends one tip radius out from Q along its normal, at the landing time
    radius = Hand.allegro().fingers["index"].tip_radius
    want = result.Q_object + radius * result.n_Q_object
    assert result.times_s[-1] == pytest.approx(result.t_end)
    assert np.linalg.norm(result.tip_object[-1] - want) < 1e-4


def test_soft_fingertips_plan_a_turn_with_two_fingers_holding_at_times(tmp_path, capsys):
    """The example's plan is for soft fingertips (its file records the torsion), two
    fingers hold the box alone at times, and the re-check, reading the torsion from the
    file, finds every held set in force closure; with point contacts it fails."""
    spec = importlib.util.spec_from_file_location("soft", EXAMPLES / "soft_fingertips.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    plan = Plan.load(module.main(out=tmp_path))
    printed = capsys.readouterr().out
    assert "point contacts: finger-" in printed or "point contacts: too-" in printed
    assert plan.torsion_m == 0.001
    check = recheck_plan(plan)
    assert check.ok, check.problems
    assert check.min_holding == 2 and check.min_closure_epsilon > 1e-9
    assert any(len(held) == 2 for _, _, held in module.holding(plan))


def test_examples_are_listed():
    listed = (EXAMPLES / "README.md").read_text()
    for script in EXAMPLES.glob("*.py"):
        assert script.name in listed, script.name


def test_shadow_hand_plans_a_full_turn_that_passes_the_recheck(tmp_path, capsys):
    """The real Shadow Hand (third-party models, skipped when absent): a prism turned
    at least 90 deg with at least 3 regrasps, every one re-checked from the plan file."""
    shadow_urdf()
    path = _run("shadow_hand", tmp_path, capsys)
    plan = Plan.load(path)
    check = recheck_plan(plan)
    assert check.ok, check.problems
    assert len(check.regrasps) >= 3
    R = Rotation.from_quat(plan.T_palm_object[[0, -1], 3:])
    assert np.degrees((R[1] * R[0].inv()).magnitude()) >= 90.0 - 1e-6
