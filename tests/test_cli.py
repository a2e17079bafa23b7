"""The regrasp-pin command line: demo, info, view --html, and errors."""

from __future__ import annotations

import json

import pytest

from regrasp_pin.cli import build_parser, main


def test_help_lists_every_command(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for name in ("demo", "view", "approx", "info"):
        assert name in out


def test_info_json(capsys):
    assert main(["info", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert set(doc["fingers"]) == {"thumb", "index", "middle", "ring", "little"}
    assert all(f["ik_success"] for f in doc["fingers"].values())


def test_demo_json_writes_plan_and_figures(tmp_path, capsys):
    code = main(["demo", "--out", str(tmp_path), "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["all_verified"] is True
    assert (tmp_path / "plan.json").is_file()
    for f in doc["figures"]:
        assert (tmp_path / f.split("/")[-1]).stat().st_size > 5000
    assert {"finger", "trigger_s", "P_object_mm", "Q_object_mm", "min_clearance_mm"} <= set(
        doc["rows"][0]
        if doc["rows"]
        else {"finger", "trigger_s", "P_object_mm", "Q_object_mm", "min_clearance_mm"}
    )


def test_bad_arguments_are_reported(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["demo", "--hand", "robotiq"])
    assert "invalid choice" in capsys.readouterr().err
    assert main(["view", "/nonexistent/plan.json", "--html", "x.html"]) == 2
    assert "no such plan file" in capsys.readouterr().err
