"""The package's layers, read from its source: the library does not import the command-line experiments, and the
optimiser's modules import each other downward only (no import circle)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "legkit"


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> set[str]:
    """Every legkit module `path` imports when it runs, at any depth of its code (function-level imports included;
    not those under `if TYPE_CHECKING:`, which only type checkers read)."""
    tree = ast.parse(path.read_text())
    typing_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If) and ast.unparse(block.test).endswith("TYPE_CHECKING")
                   for statement in block.body for n in ast.walk(statement)}
    found = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return {name for name in found if name.startswith("legkit")}


def library_modules() -> list[Path]:
    """The library: every module but the command line (`cli.py`, `experiments/`)."""
    return [p for p in sorted(PACKAGE.rglob("*.py"))
            if p.name != "cli.py" and "experiments" not in p.relative_to(PACKAGE).parts]


def test_the_library_does_not_import_the_experiments():
    offenders = {module_name(p): sorted(n for n in imports(p) if n.startswith("legkit.experiments")) for p in library_modules()}
    assert {m: n for m, n in offenders.items() if n} == {}


def test_the_checker_sees_an_import_of_the_experiments(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from legkit.experiments.gait import main\n")
    assert "legkit.experiments.gait" in imports(module)
    module.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from legkit.experiments.gait import main\n")
    assert imports(module) == set()


def cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle of `graph` (module -> modules it imports), or None (depth-first search)."""
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for child in sorted(graph.get(node, ())):
            if state.get(child) == 1:
                return path[path.index(child):] + [child]
            if child not in state and (found := visit(child)) is not None:
                return found
        state[node] = 2
        path.pop()
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)) is not None:
            return found
    return None


@pytest.mark.parametrize("package", ["optimize", "gaits"])
def test_a_package_imports_downward_only(package):
    paths = [p for p in sorted((PACKAGE / package).glob("*.py")) if p.name != "__init__.py"]
    names = {module_name(p) for p in paths}
    graph = {module_name(p): {n for n in imports(p) if n in names} for p in paths}
    assert cycle(graph) is None


def test_the_cycle_finder_finds_a_cycle():
    assert cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
