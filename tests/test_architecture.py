"""The layout rules of docs/architecture.md, read from the code's imports."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_TOOL = Path(__file__).resolve().parents[1] / "docs" / "make_architecture.py"


@pytest.fixture(scope="module")
def arch():
    spec = importlib.util.spec_from_file_location("make_architecture", _TOOL)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` (a path that returns to its start), or None."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return stack[stack.index(w) :] + [w]
            if w not in state and (found := visit(w)):
                return found
        stack.pop()
        state[v] = 2
        return None

    for v in sorted(graph):
        if v not in state and (found := visit(v)):
            return found
    return None


def test_cycle_finder_finds_a_cycle_and_accepts_a_dag():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle_between_modules(arch):
    mods = arch.modules()
    graph = {}
    for name, path in mods.items():
        deps = set()
        for target, what in arch.imports(path, top_level_only=True):
            full = f"{target}.{what}"
            dep = full if full in mods else target
            if dep in mods and dep != name and not name.startswith(dep + "."):
                deps.add(dep)
        graph[name] = deps
    assert _cycle(graph) is None


def test_no_cycle_between_the_parts(arch):
    assert _cycle(arch.stage_graph()) is None


def test_stages_import_only_earlier_stages(arch):
    graph = arch.stage_graph()
    order = ["model", "grasp", "surface", "polygon", "plan", "verify", "planning"]
    for i, part in enumerate(order):
        later = set(order[i + 1 :]) | {"scenarios", "suite", "viz", "plotting", "commands"}
        assert not graph.get(part, set()) & later, part


def test_no_private_name_is_imported_from_another_module(arch):
    private = [
        f"{arch.module_name(path)} imports {target}.{what}"
        for path in arch.modules().values()
        for target, what in arch.imports(path, top_level_only=False)
        if what.startswith("_") and not what.startswith("__")
    ]
    assert private == []


def test_the_generated_diagram_is_current(arch):
    text = arch.DOC.read_text()
    assert arch.generated_block() in text, "run: python docs/make_architecture.py"
