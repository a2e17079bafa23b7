"""The suite's report files: rates per hand x object x motion, failures by kind, the
planning-time histogram, and links to each plan and its viewer page."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from regrasp_pin.exceptions import InputError
from regrasp_pin.suite import neighbour_specs, run_scenario
from regrasp_pin.suite.pages import write_report
from regrasp_pin.suite.run import ScenarioResult


def _result(name, hand, obj, motion, ok, kind=None, plan_s=1.0, plan_path=None):
    return ScenarioResult(
        name=name, hand=hand, object_kind=obj, motion_kind=motion, ok=ok,
        failure_kind=kind, failed_stage=None if ok else "plan", plan_s=plan_s,
        plan_path=plan_path, recheck_ok=True if ok else None,
    )  # fmt: skip


RESULTS = [
    _result("a", "five_finger", "prism", "object-axis", True, plan_s=0.5, plan_path="a.json"),
    _result("b", "five_finger", "prism", "contact-axis", False, "velocity", 3.0, "b.partial.json"),
    _result("c", "five_finger", "box", "object-axis", False, "velocity", 12.0),
    _result("d", "allegro", "prism", "object-axis", True, plan_s=7.0),
    _result("e", "allegro", "prism", "object-axis", False, "timeout", 130.0),
]


def test_tables_count_what_the_results_say(tmp_path):
    (tmp_path / "a.json").write_text("{}")  # a plan file present; b's is missing
    files = write_report(tmp_path, RESULTS, viewer_pages=False)
    md = files.markdown.read_text()
    # hand x object rows: five_finger prism has a (ok, object-axis) and b (contact-axis)
    assert "| five_finger | prism | 1/1 (100%) | 0/1 (0%) | 1/2 (50%) |" in md
    assert "| allegro | prism | 1/2 (50%) | - | 1/2 (50%) |" in md
    assert "| all | all | 2/4 (50%) | 0/1 (0%) | 2/5 (40%) |" in md
    assert re.search(r"\| velocity \| 2 \| #{20} \|", md)  # the most common: a full bar
    assert re.search(r"\| timeout \| 1 \| #{10} \|", md)
    hist = {m[0]: int(m[1]) for m in re.findall(r"^\| ([^|]+ s) \| (\d+) \|$", md, re.M)}
    assert sum(hist.values()) == 5 and hist["0-1 s"] == 1 and hist[">= 120 s"] == 1
    assert "[a.json](a.json)" in md and "b.partial.json" not in md  # only files present
    html = files.html.read_text()
    assert html.count("class='bar'") == 2 + len(hist)  # failure kinds + time bins
    assert "<a href='a.json'>" in html and files.viewer_pages == ()


def test_viewer_page_per_plan(tmp_path):
    pytest.importorskip("meshcat", reason="the viz extra is not installed")
    spec = next(s for s in neighbour_specs() if s.name == "five_finger-hexagon-+60deg-40dps")
    r = run_scenario(spec, out_dir=tmp_path)
    files = write_report(tmp_path, [r, replace(r, name="copy", plan_path=None)])
    assert [p.name for p in files.viewer_pages] == [f"{spec.name}.html"]
    assert files.viewer_pages[0].stat().st_size > 100_000  # meshcat inlined
    assert f"href='viewer/{spec.name}.html'" in files.html.read_text()


def test_no_results_or_no_folder_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no results"):
        write_report(tmp_path)
    with pytest.raises(InputError, match="not a folder"):
        write_report(tmp_path / "missing", RESULTS)
