"""The README's and the guides' snippets do what they show.

Every ```python block of a page runs, in order, in one namespace per page, in a scratch folder (a long one
shortened as ``SHORTER`` says). A statement that is an expression followed by a comment holding a Python literal
(``r.distance   # 1.0``) must evaluate to that literal (numbers to 1e-9). A line naming a piece of ``NOT_RUN`` is
left out, for the reason given there. Every ``legkit`` command of the ```bash blocks of ``COMMAND_PAGES`` is parsed
as written by its own parser (its options and their values accepted), ``legkit demo`` and a small ``legkit
balance`` run, and each ``python benches/...`` command is parsed the same way (a bench without options compiles).
Not run here: the install and test commands (``bash scripts/test.sh``, ``.venv/bin/pip install``, ``cargo bench``,
``python -m pytest``), which CI runs as its own steps.
"""

from __future__ import annotations

import argparse
import ast
import io
import re
import runpy
import shlex
import subprocess
import sys
import tokenize
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from legkit import cli

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", "docs/urdf_to_simulation.md", "docs/robots.md", "docs/agents.md", "docs/control.md", "docs/viewer.md"]
PAGES.append("docs/sweeps.md")
SLOW_PAGES = {"docs/viewer.md", "docs/sweeps.md"}  # pictures of Solo-12's meshes; a process pool: seconds each
#: Per page, (text, replacement) applied to its snippets before they run: a short variant of a long snippet.
SHORTER = {
    "docs/sweeps.md": [
        ("trees=64,", "trees=1,"), ("modules=20, branches=4,", "modules=4, branches=2,"), ("c0=[0.0, 0.5, 1.0]", "c0=[0.5]"),
        ('c1={"distance": [0.1, 0.3, 1.0], "momentum": [1.0, 5.0, 20.0]}', 'c1={"distance": [0.1], "momentum": [1.0]}'),
        ("seeds=2,", "seeds=1,"), ("duration=2.0,", "duration=0.02,"),
    ],
}

#: Statements not run, by a piece of their source, and why.
NOT_RUN = {
    "viewer.Viewer(": "starts meshcat's server process for a browser to connect to (tests/test_viewer.py starts one)",
    "live.": "uses that live viewer",
}


def blocks(page: str, language: str) -> list[tuple[int, str]]:
    """The ```language blocks of ``page``: (line number of the block's first line, code)."""
    text = (ROOT / page).read_text()
    found = []
    for match in re.finditer(rf"^```{language}\n(.*?)^```", text, re.M | re.S):
        found.append((text.count("\n", 0, match.start(1)) + 1, match.group(1)))
    return found


def shown_value(comment: str) -> tuple[bool, Any]:
    """(True, the literal) if a comment (``# ...``) is one Python literal, else (False, None)."""
    try:
        return True, ast.literal_eval(comment.lstrip("#").strip())
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        return False, None


def checked_code(code: str, first_line: int) -> tuple[ast.Module, dict[int, Any]]:
    """``code`` with every shown expression wrapped in ``_shows(line, value)`` and the lines naming a ``NOT_RUN``
    piece left out, and the shown values by line; line numbers are the page's."""
    tree = ast.parse(code)
    comments = {t.start[0]: t.string for t in tokenize.generate_tokens(io.StringIO(code).readline) if t.type == tokenize.COMMENT}
    shown: dict[int, Any] = {}
    body: list[ast.stmt] = []
    skipped = {n for n, line in enumerate(code.splitlines(), 1) if any(piece in line for piece in NOT_RUN)}
    for statement in tree.body:
        assert statement.end_lineno is not None
        if skipped & set(range(statement.lineno, statement.end_lineno + 1)):
            continue  # the whole line: what follows on it uses what it makes
        has_value, value = shown_value(comments.get(statement.end_lineno, ""))
        if isinstance(statement, ast.Expr) and has_value:
            line = first_line + statement.end_lineno - 1
            shown[line] = value
            statement = ast.Expr(ast.Call(ast.Name("_shows", ast.Load()), [ast.Constant(line), statement.value], []))
        body.append(statement)
    module = ast.Module(body, [])
    ast.increment_lineno(ast.fix_missing_locations(module), first_line - 1)
    return module, shown


def same(value: Any, shown: Any) -> bool:
    if isinstance(shown, (tuple, list)) and isinstance(value, (tuple, list)) and len(value) == len(shown) and not all(
        isinstance(s, (int, float)) for s in shown
    ):
        return all(same(v, s) for v, s in zip(value, shown))
    if isinstance(shown, (str, bool)):
        return not isinstance(value, np.ndarray) and bool(value == shown)
    try:
        return bool(np.allclose(np.asarray(value, dtype=float), np.asarray(shown, dtype=float), rtol=1e-9, atol=1e-12))
    except (TypeError, ValueError):
        return bool(value == shown)


def run_page(page: str) -> int:
    """Runs every Python block of ``page``; returns how many shown values it checked."""
    checked = 0
    namespace: dict[str, Any] = {"__name__": "__snippet__"}

    def shows(line: int, value: Any) -> None:
        nonlocal checked
        assert same(value, expected[line]), f"{page}:{line}: gives {value!r}, the page shows {expected[line]!r}"
        checked += 1

    namespace["_shows"] = shows
    expected: dict[int, Any] = {}
    replacements = SHORTER.get(page, [])
    code_blocks = blocks(page, "python")
    for text, _ in replacements:
        assert any(text in code for _, code in code_blocks), f"{page}: SHORTER's {text!r} is no longer in the page"
    for first_line, code in code_blocks:
        for text, replacement in replacements:
            code = code.replace(text, replacement)
        module, shown = checked_code(code, first_line)
        expected.update(shown)
        exec(compile(module, f"{page}", "exec"), namespace)
    return checked


@pytest.mark.parametrize("page", [pytest.param(p, marks=pytest.mark.slow) if p in SLOW_PAGES else p for p in PAGES])
def test_python_snippets_run_and_show_what_they_give(page: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert blocks(page, "python"), f"{page} has no Python snippet"
    monkeypatch.chdir(tmp_path)
    assert run_page(page) > 0, f"{page} shows no value to check"


def test_the_checker_catches_a_snippet_that_shows_a_wrong_value() -> None:
    module, shown = checked_code("x = 2\nx + 1   # 4\nx   # not a literal\n", 10)
    assert shown == {11: 4}

    def shows(line: int, value: Any) -> None:
        assert same(value, shown[line]), line

    with pytest.raises(AssertionError, match="11"):
        exec(compile(module, "page", "exec"), {"_shows": shows})
    assert same((1.0, [[1, 0, 0]], False), (1.0, [[1, 0, 0]], False)) and not same([0.5], [0.6])
    module, _ = checked_code("x = 1\nlive = viewer.Viewer(model); live.display(q)\n", 1)
    assert [ast.unparse(s) for s in module.body] == ["x = 1"]


#: The pages whose ```bash commands are checked.
COMMAND_PAGES = ["README.md", "docs/sweeps.md"]


def commands(prefix: str) -> list[str]:
    """The command lines (comments stripped) of ``COMMAND_PAGES`` that start with ``prefix``, each once."""
    lines = [line.split("  #")[0].strip() for page in COMMAND_PAGES for _, code in blocks(page, "bash") for line in code.splitlines()]
    return list(dict.fromkeys(line for line in lines if line.startswith(prefix)))


class Parsed(Exception):
    """Raised in place of running a command once its parser accepted the arguments."""


def legkit_arguments() -> list[list[str]]:
    # scripts/run.sh passes its arguments to `legkit`.
    return [shlex.split(line)[1:] for line in commands("legkit ")] + [shlex.split(line)[2:] for line in commands("bash scripts/run.sh ")]


@pytest.mark.parametrize("argv", legkit_arguments(), ids=" ".join)
def test_every_legkit_command_of_the_readme_parses_as_written(argv: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    original = argparse.ArgumentParser.parse_args

    def parse_then_stop(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> Any:
        namespace = original(self, *args, **kwargs)
        if argv[0] in cli.EXPERIMENTS:
            raise Parsed(namespace)
        return namespace

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_then_stop)
    if argv[0] in cli.EXPERIMENTS:
        with pytest.raises(Parsed):
            cli.run(argv)
    else:
        assert cli.run(argv) == 0  # `legkit demo`: a few lines, run whole


def test_the_readme_commands_include_the_quick_start_and_every_experiment() -> None:
    names = {argv[0] for argv in legkit_arguments()}
    assert {"balance", "strain", "gait", "demo", "sweep", "tune"} <= names
    assert ["balance", "--duration", "1.5"] in legkit_arguments()


@pytest.mark.slow
def test_a_short_legkit_balance_runs_from_the_command_line(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "legkit.cli", "balance", "--trees", "1", "--modules", "4", "--branches", "2", "--duration", "0.05",
         "--no-animation", "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert "msg/mod/s" in done.stdout and (out / "balance.csv").exists()


def bench_commands() -> list[list[str]]:
    return [shlex.split(line)[1:] for line in commands("python benches/")]


@pytest.mark.slow
@pytest.mark.parametrize("argv", bench_commands(), ids=" ".join)
def test_every_bench_command_of_the_readme_parses_as_written(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Its options accepted by its own parser, run in this process up to the parse (a bench without options
    only compiles: running it is the benchmark, minutes)."""
    path = ROOT / argv[0]
    source = path.read_text()
    if "argparse" not in source:
        assert len(argv) == 1, f"{argv[0]} takes no options"
        compile(source, str(path), "exec")
        return
    original = argparse.ArgumentParser.parse_args

    def parse_then_stop(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> Any:
        raise Parsed(original(self, *args, **kwargs))

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_then_stop)
    monkeypatch.setattr(sys, "argv", [str(path), *argv[1:]])
    monkeypatch.syspath_prepend(str(path.parent))
    with pytest.raises(Parsed):
        runpy.run_path(str(path), run_name="__main__")
