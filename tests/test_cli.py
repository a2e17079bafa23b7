"""The regrasp-pin command line: demo, info, view --html, and errors."""

from __future__ import annotations

import json

import pytest

from regrasp_pin.cli import build_parser, main
from regrasp_pin.plan import Plan


def test_help_lists_every_command(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for name in ("demo", "view", "approx", "info", "suite"):
        assert name in out


def test_info_json(capsys):
    assert main(["info", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["fingers"]) == {"thumb", "index", "middle", "ring", "little"}
    assert all(f["ik_success"] for f in doc["fingers"].values())


def test_info_takes_a_hand_file(tmp_path, capsys):
    """Any hand through a JSON hand file: here two fingers of the bundled URDF."""
    from regrasp_pin.model.hand import five_finger_urdf_path

    path = tmp_path / "two_fingers.json"
    fingers = {"thumb": "thumb_tip", "index": "index_tip"}
    spec = {"urdf": str(five_finger_urdf_path()), "fingers": fingers, "tip_radius": 0.008}
    path.write_text(json.dumps(spec))
    assert main(["info", "--hand", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["hand"] == "five_finger_hand" and set(doc["fingers"]) == set(fingers)
    assert all(f["ik_success"] for f in doc["fingers"].values())


def test_demo_json_writes_plan_and_figures(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path), "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["all_verified"] is True
    assert (tmp_path / "plan.json").is_file()
    for f in doc["figures"]:
        assert (tmp_path / f.split("/")[-1]).stat().st_size > 5000
    # the summary is the plan file's: one row per regrasp phase, one entry per release
    plan = Plan.load(tmp_path / "plan.json")
    phases = plan.regrasps()
    assert len(doc["rows"]) == len(phases) >= 3
    for row, ph in zip(doc["rows"], phases, strict=True):
        assert row["finger"] == ph.finger and row["t_start_s"] == pytest.approx(ph.t_start)
        assert row["Q_object_mm"] == pytest.approx(1e3 * ph.Q_object, abs=0.051)
        assert row["min_clearance_mm"] == pytest.approx(1e3 * ph.min_clearance_m)
    assert [(r["finger"], r["t_s"]) for r in doc["releases"]] == [
        (p.finger, p.t_start) for p in plan.releases()
    ]


def test_bad_arguments_are_reported(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["demo", "--hand", "robotiq"])
    assert (
        "not a hand: expected five_finger, allegro or a .json hand file" in capsys.readouterr().err
    )
    assert main(["view", "/nonexistent/plan.json", "--html", "x.html"]) == 2
    assert "no such plan file" in capsys.readouterr().err


def test_suite_runs_plans_and_reports(tmp_path, capsys):
    """One real scenario on a one-worker local cluster: results, summary, report."""
    pytest.importorskip("distributed", reason="the scale extra is not installed")
    out = tmp_path / "suite"
    argv = ["suite", "--n", "1", "--hand", "five_finger", "--object", "prism"]
    argv += ["--motion", "object-axis", "--workers", "1", "--out", str(out), "--no-viewer"]
    assert main(argv) == 0
    lines = (out / "results.jsonl").read_text().splitlines()
    assert len(lines) == 1
    result = json.loads(lines[0])
    assert result["spec"]["object"]["kind"] == "prism"
    assert result["spec"]["motion"]["kind"] == "object-axis"
    printed = capsys.readouterr().out
    assert result["name"] in printed and "scenarios: 1, full plans" in printed
    assert (out / "report.html").is_file() and (out / "summary.txt").is_file()
    # the report alone, rebuilt from the results file
    (out / "report.md").unlink()
    assert main(["suite", "--report", str(out), "--no-viewer"]) == 0
    assert result["name"] in (out / "report.md").read_text()


def test_suite_without_out_is_a_one_line_error(capsys):
    assert main(["suite", "--n", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--out" in err and len(err.splitlines()) == 1
