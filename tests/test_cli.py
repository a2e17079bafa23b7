"""The regrasp-pin command line: demo, info, view --html, and errors."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from regrasp_pin.cli import build_parser, main
from regrasp_pin.exceptions import FailureKind
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
    # the URDF's tip spheres are 8 mm: the fingertips hold on their front hemispheres
    assert all(f["pad_cone_deg"] == 90.0 for f in doc["fingers"].values())
    spec["tip_radius"] = 0.009  # a stand-in sphere: the cone stays near the pad
    path.write_text(json.dumps(spec))
    assert main(["info", "--hand", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert all(f["pad_cone_deg"] == 60.0 for f in doc["fingers"].values())


def test_demo_json_writes_plan_and_figures(tmp_path, capsys):
    pytest.importorskip("meshcat", reason="the viz extra is not installed")
    html = tmp_path / "plan.html"
    code = main(["demo", "--out", str(tmp_path), "--json", "--html", str(html)])
    assert code == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)  # stdout holds the JSON alone, even with --html
    assert doc["ok"] is True and html.is_file() and str(html) in captured.err
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
    _check_readme_table(doc["rows"], capsys)


def _check_readme_table(rows, capsys):
    """The README's demo table is what the demo prints with the default (numpy) IK: every
    column but the planning time, the one that depends on the machine. The numba backend
    stops its IK within the same tolerance at other iterates, so its paths may differ."""
    from regrasp_pin.commands.summary import print_table
    from regrasp_pin.model.ik import ik_backend

    if ik_backend() != "numpy":
        return  # the README documents the default backend's plan
    empty = {"fingers_regrasped": ["-"], "all_verified": True, "releases": [], "joins": []}
    print_table(rows, {**empty, "stage_s": {}, "total_s": 0.0, "plan": "", "figures": []})
    printed = capsys.readouterr().out.splitlines()
    readme = (Path(__file__).parents[1] / "README.md").read_text().splitlines()
    start = readme.index(next(line for line in readme if line.startswith("finger   trigger")))
    documented = readme[start + 3 : start + 3 + len(rows)]
    first = printed.index(next(line for line in printed if line.startswith("finger ")))
    shown = printed[first + 3 : first + 3 + len(rows)]
    assert [line[:-8] for line in documented] == [line[:-8] for line in shown]
    assert readme[start + 3 + len(rows)].startswith("---")  # and no more rows


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


def test_version_text(capsys):
    from regrasp_pin import __version__

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"regrasp-pin {__version__}"


def _planned_once(monkeypatch):
    """The planner, planning each scenario once: a second call for the same scenario
    (the same poses, grasp and parameters) raises the PlanningError that the first one
    ended in, without planning it again. Returns the scenarios planned, with how often
    each was asked for."""
    import numpy as np

    from regrasp_pin import backups
    from regrasp_pin.exceptions import PlanningError

    plan, failed, asked = backups.plan_manipulation, {}, {}

    def scenario(motion, grasp, params):
        times = np.linspace(motion.t_start, motion.t_end, 101)
        return motion.pose(times).tobytes(), repr(sorted(grasp.indices.items())), repr(params)

    def planned_once(hand, obj, motion, *, grasp, params, **kw):
        key = scenario(motion, grasp, params)
        asked[key] = asked.get(key, 0) + 1
        if key in failed:
            raise failed[key]
        try:
            return plan(hand, obj, motion, grasp=grasp, params=params, **kw)
        except PlanningError as exc:
            failed[key] = exc
            raise

    monkeypatch.setattr(backups, "plan_manipulation", planned_once)
    return asked


def test_no_plan_exits_1_with_json_on_stdout(tmp_path, capsys, monkeypatch):
    """A turn the five-finger hand cannot follow (-140 deg at 40 deg/s; -100 deg failed
    so until a backtrack let another finger due then go first): exit code 1, the
    failure as JSON with its kind, and the partial plan written. The failing finger is
    the little finger, which joined: it has no start contact to change, so there is no
    backup. (Planned once: the second command is given the failure the first planned,
    the same scenario; what it makes of it is checked.)"""
    asked = _planned_once(monkeypatch)
    argv = ["demo", "--angle", "-140", "--rate", "40", "--no-plots", "--out", str(tmp_path)]
    assert main([*argv, "--json"]) == 1
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert doc["ok"] is False and doc["failure_kind"] in {k.value for k in FailureKind}
    assert Plan.load(doc["partial_plan"]).t[-1] <= doc["duration_s"]
    assert doc["finger"] == "little" and doc["grasp_backups"] == []
    # without --json: one line on stderr, the same exit code
    assert main([*argv, "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("regrasp-pin demo: no plan: ") and "Traceback" not in err
    assert list(asked.values()) == [2]


def test_a_plan_from_a_backup_says_so(tmp_path, capsys, monkeypatch):
    """The first plan fails at the index on its start contact (scripted: the planner's
    own plan is kept for the second call); the demo plans again from the grasp search's
    start with the index elsewhere, and says so in its table and its JSON."""
    import dataclasses

    from regrasp_pin import backups
    from regrasp_pin.exceptions import PlanningError

    plan, kept = backups.plan_manipulation, []

    def first_fails(hand, obj, motion, *, grasp, params, progress=None, setup=None):
        if not kept:  # the demo's own plan, once
            kept.append((plan(hand, obj, motion, grasp=grasp, params=params, setup=setup), grasp))
        result, first = kept[0]
        for t in (0.6, 0.3, 0.9) if progress is not None else ():
            progress(t)  # the search backtracks: not a backup
        if grasp.indices["index"] != first.indices["index"]:
            return result  # a backup: its grasp avoids the index's first start
        full = result.plan  # cut: the index still on its start contact
        phases = {**full.phases, "index": full.phases["index"][:1]}
        partial = dataclasses.replace(full, phases=phases, summary={"search_steps": 10})
        raise PlanningError(
            "scripted", finger="index", time_s=0.5, kind=FailureKind.NO_CANDIDATE, partial=partial
        )

    monkeypatch.setattr(backups, "plan_manipulation", first_fails)
    argv = [
        "demo",
        "--angle",
        "60",
        "--rate",
        "40",
        "--no-plots",
        "--quiet",
        "--out",
        str(tmp_path),
    ]
    assert main([*argv, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    [b] = doc["grasp_backups"]
    assert (b["after"], b["finger"], b["how"], b["outcome"]) == (
        "no-candidate",
        "index",
        "elsewhere",
        "ok",
    )
    assert main(argv) == 0
    shown = capsys.readouterr().out.splitlines()
    assert "backed up after no-candidate at index: index started elsewhere -> ok" in shown
    # with the progress bar: the backup said once, when it plans, and not the backtracks
    assert main([a for a in argv if a != "--quiet"]) == 0
    said = capsys.readouterr()
    note = "index failed (no-candidate) on its start contact: another initial grasp"
    assert (said.out + said.err).count(note) == 1
    assert (said.out + said.err).count("another initial grasp") == 1


@pytest.mark.parametrize("command", ["demo", "plan", "suite"])
def test_grasp_backups_must_be_a_whole_number(command, capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args([command, "--grasp-backups", "-1"])
    assert stop.value.code == 2
    assert "--grasp-backups: '-1' is not a whole number >= 0" in capsys.readouterr().err


def test_plan_by_the_cruise_time_law(tmp_path, capsys):
    """``--time-law cruise`` reaches every regrasp (the law's own trajectories are
    tested in test_planning_regrasp and test_planning_search): the plan file records it
    for each, the table says so, and the plan passes its re-check from the file (joint
    speeds included)."""
    from regrasp_pin.verify.plan_check import recheck_plan

    argv = ["plan", "--angle", "60", "--time-law", "cruise", "--out", str(tmp_path)]
    assert main([*argv, "--no-plots", "--no-viewer"]) == 0
    assert "by the cruise time law (RegraspParams.time_law)" in capsys.readouterr().out
    plan = Plan.load(tmp_path / "plan.json")
    regrasps = plan.regrasps()
    assert regrasps and all(p.extra["time_law"] == "cruise" for p in regrasps)
    assert recheck_plan(plan).ok


def test_plan_for_soft_fingertips_records_its_torsion(tmp_path):
    """``--torsion-mm`` reaches the contact model of the grasp search and the planner:
    the plan file records the torsional friction in metres, and its re-check (which
    reads it from the file) passes."""
    from regrasp_pin.verify.plan_check import recheck_plan

    argv = ["plan", "--angle", "60", "--torsion-mm", "1", "--out", str(tmp_path)]
    assert main([*argv, "--no-plots", "--no-viewer"]) == 0
    plan = Plan.load(tmp_path / "plan.json")
    assert plan.torsion_m == pytest.approx(0.001)
    assert recheck_plan(plan).ok


@pytest.mark.parametrize("command", ["demo", "plan", "suite"])
@pytest.mark.parametrize("value", ["-1", "nan", "inf", "soft"])
def test_a_torsion_must_be_a_number_at_least_zero(command, value, capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args([command, "--torsion-mm", value])
    assert stop.value.code == 2
    assert f"--torsion-mm: {value!r} is not a number >= 0 [mm]" in capsys.readouterr().err


def test_an_unknown_time_law_is_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["plan", "--time-law", "linear"])
    assert stop.value.code == 2
    assert "--time-law: invalid choice: 'linear'" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["demo", "--out", "{file}"], "--out"),
        (["demo", "--html", "{missing}/plan.html"], "--html"),
        (["approx", "{csv}", "-m", "3", "--plot", "{missing}/fig8.png"], "--plot"),
    ],
)
def test_outputs_that_cannot_be_written_are_one_line(tmp_path, capsys, argv, option):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    csv = tmp_path / "c.csv"
    csv.write_text("0,0\n1,0\n1,1\n0,1\n")
    names = {"file": str(a_file), "missing": str(tmp_path / "missing"), "csv": str(csv)}
    assert main([a.format(**names) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and option in err and "Traceback" not in err


def test_log_levels(tmp_path, capsys):
    before = logging.getLogger().level
    csv = tmp_path / "c.csv"
    csv.write_text("0,0\n1,0\n1,1\n0,1\n2,2\n")
    assert main(["-v", "approx", str(csv), "-m", "3"]) == 0
    assert logging.getLogger().level == logging.INFO
    assert main(["--log-level", "debug", "approx", str(csv), "-m", "3"]) == 0
    assert logging.getLogger().level == logging.DEBUG
    assert main(["-q", "approx", str(csv), "-m", "3"]) == 0
    assert logging.getLogger().level == logging.ERROR
    assert "DEBUG regrasp_pin" in capsys.readouterr().err  # what -v/--log-level let through
    # a library that raises its own logger's level later (distributed does when a
    # suite starts its cluster) is still held back by -q
    lib = logging.getLogger("distributed.scheduler")
    lib_level = lib.level
    lib.setLevel(logging.INFO)
    lib.info("State start")
    lib.error("a real error")
    err = capsys.readouterr().err
    assert "State start" not in err and "ERROR distributed.scheduler: a real error" in err
    lib.setLevel(lib_level)
    logging.getLogger().setLevel(before)


def test_plan_a_users_own_mesh_in_one_command(tmp_path, capsys):
    """The README's own-object example: an OBJ in millimetres, a bundled hand."""
    from pathlib import Path

    obj = Path(__file__).resolve().parents[1] / "examples" / "objects" / "hexagonal_prism_mm.obj"
    argv = ["plan", "--object", str(obj), "--scale", "0.001", "--angle", "60"]
    assert main([*argv, "--out", str(tmp_path), "--json", "--no-plots"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] and doc["object"] == "convex_mesh" and doc["object_note"] is None
    plan = Plan.load(doc["plan"])
    assert plan.object["kind"] == "convex_mesh" and len(plan.regrasps()) == doc["regrasps"]
    if doc["viewer"] is not None:  # with the viz extra
        assert Path(doc["viewer"]).stat().st_size > 100_000


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--object", "sphere"], "--object: 'sphere' is not known"),
        (["--object", "box:0.04,0.05"], "--object: 'box:0.04,0.05' has the wrong number"),
        (["--object", "missing.obj"], "missing.obj: no such mesh file"),
        (["--motion", "missing.csv"], "missing.csv: no such motion file"),
    ],
)
def test_plan_bad_problems_are_one_line(tmp_path, capsys, argv, message):
    assert main(["plan", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def test_suite_choices_match_the_library():
    """`regrasp-pin suite --help` lists literal copies (no heavy import): the library's."""
    from regrasp_pin.commands import suite as command
    from regrasp_pin.suite import MOTION_KINDS, OBJECT_KINDS

    assert (command.OBJECT_KINDS, command.MOTION_KINDS) == (OBJECT_KINDS, MOTION_KINDS)


def test_the_demo_table_marks_a_joint_space_regrasp_and_says_what_it_is(capsys):
    from regrasp_pin.commands.summary import print_table

    def row(finger, route, waypoints):
        return {
            "finger": finger,
            "trigger_s": 1.0,
            "t_start_s": 0.98,
            "t_end_s": 1.3,
            "P_object_mm": [1.0, 2.0, 3.0],
            "Q_object_mm": [4.0, 5.0, 6.0],
            "path_length_mm": 20.0,
            "waypoints": waypoints,
            "route": route,
            "min_clearance_mm": 3.0,
            "planning_ms": 50.0,
        }

    summary = {
        "fingers_regrasped": ["index", "ring"],
        "all_verified": True,
        "releases": [],
        "joins": [],
        "stage_s": {},
        "total_s": 1.0,
        "plan": "plan.json",
        "figures": [],
    }
    print_table([row("index", "surface", 7)], summary)
    plain = capsys.readouterr().out
    assert "*" not in plain and "joint-space" not in plain
    print_table([row("index", "surface", 7), row("ring", "joint-space", 4)], summary)
    lines = capsys.readouterr().out.splitlines()
    ring = next(line for line in lines if line.startswith("ring"))
    index = next(line for line in lines if line.startswith("index"))
    assert " 4* " in ring and " 7 " in index and "*" not in index
    assert any(line.startswith("* the joint-space fallback") for line in lines)
