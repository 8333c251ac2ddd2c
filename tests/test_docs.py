"""Every ```python block of README.md and docs/*.md runs on its own.

Each block runs alone in a fresh Python process (this file run as a script: ``python tests/test_docs.py PAGE LINE``),
in an empty temporary folder, with a timeout; a failure names the page and the line. A statement that is an
expression followed by a comment holding a Python literal (``r.distance   # 1.0``) must evaluate to that literal
(numbers to 1e-9). A line naming a piece of ``NOT_RUN`` is left out, for the reason given there; ``SHORTER`` shortens
a long block. A block preceded by the line ``<!-- slow -->`` (it takes more than about 10 s) is in the slow tier.
Blocks that are not meant to run use other fences (```bash, ```text).
"""

from __future__ import annotations

import ast
import io
import re
import subprocess
import sys
import tokenize
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]
SLOW_MARK = "<!-- slow -->"
TIMEOUT = 600  # seconds a block may take (a slow one, on a loaded machine)

#: Per page, (text, replacement) applied to its blocks before they run: a short variant of a long block.
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


def blocks(page: str, language: str = "python") -> list[tuple[int, str, bool]]:
    """The ```language blocks of ``page``: (line number of the block's first line, code, marked slow)."""
    text = (ROOT / page).read_text()
    found = []
    for match in re.finditer(rf"^```{language}\n(.*?)^```", text, re.M | re.S):
        before = text[: match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        found.append((text.count("\n", 0, match.start(1)) + 1, match.group(1), before.strip() == SLOW_MARK))
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


def run_block(page: str, first_line: int) -> int:
    """Runs the block of ``page`` that starts at ``first_line`` in this process; returns how many shown values it
    checked."""
    (code,) = [code for line, code, _ in blocks(page) if line == first_line]
    for text, replacement in SHORTER.get(page, []):
        code = code.replace(text, replacement)
    module, expected = checked_code(code, first_line)
    checked = 0

    def shows(line: int, value: Any) -> None:
        nonlocal checked
        assert same(value, expected[line]), f"{page}:{line}: gives {value!r}, the page shows {expected[line]!r}"
        checked += 1

    exec(compile(module, page, "exec"), {"__name__": "__main__", "_shows": shows})
    return checked


def all_blocks() -> list[Any]:
    return [
        pytest.param(page, line, id=f"{page}:{line}", marks=[pytest.mark.slow] if slow else [])
        for page in PAGES
        for line, _, slow in blocks(page)
    ]


@pytest.mark.parametrize(("page", "first_line"), all_blocks())
def test_every_python_block_runs_alone(page: str, first_line: int, tmp_path: Path) -> None:
    try:
        done = subprocess.run(
            [sys.executable, __file__, page, str(first_line)], cwd=tmp_path, capture_output=True, text=True, timeout=TIMEOUT,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{page}:{first_line}: the block did not finish in {TIMEOUT} s")
    assert done.returncode == 0, f"{page}:{first_line}: the block fails when run alone\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}"


def test_the_long_variants_still_match_their_pages() -> None:
    for page, replacements in SHORTER.items():
        code = "".join(code for _, code, _ in blocks(page))
        for text, _ in replacements:
            assert text in code, f"{page}: SHORTER's {text!r} is no longer in the page"


def test_the_checker_catches_a_block_that_shows_a_wrong_value() -> None:
    module, shown = checked_code("x = 2\nx + 1   # 4\nx   # not a literal\n", 10)
    assert shown == {11: 4}

    def shows(line: int, value: Any) -> None:
        assert same(value, shown[line]), line

    with pytest.raises(AssertionError, match="11"):
        exec(compile(module, "page", "exec"), {"_shows": shows})
    assert same((1.0, [[1, 0, 0]], False), (1.0, [[1, 0, 0]], False)) and not same([0.5], [0.6])
    module, _ = checked_code("x = 1\nlive = viewer.Viewer(model); live.display(q)\n", 1)
    assert [ast.unparse(s) for s in module.body] == ["x = 1"]


def test_a_block_that_needs_an_earlier_one_fails_alone(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("```python\nx = 1\n```\n\n<!-- slow -->\n```python\nprint(x)\n```\n")
    assert [(line, slow) for line, _, slow in blocks(str(page))] == [(2, False), (7, True)]
    done = subprocess.run([sys.executable, __file__, str(page), "7"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert done.returncode != 0 and "NameError" in done.stderr and f"{page}\", line 7" in done.stderr


if __name__ == "__main__":
    run_block(sys.argv[1], int(sys.argv[2]))
