"""Every example script runs to the end (outputs go to a temporary folder)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    "name", ["polygonal_approximation", "manifold", "regrasp_prism", "allegro_regrasp"]
)
def test_example_runs(name, tmp_path, capsys):
    module = _load(name)
    assert module.__doc__, "every example says what it shows"
    module.main(out=tmp_path)
    out = capsys.readouterr().out
    assert out.strip(), "the example prints what it did"


def test_examples_are_listed():
    listed = (EXAMPLES / "README.md").read_text()
    for script in EXAMPLES.glob("*.py"):
        assert script.name in listed, script.name
