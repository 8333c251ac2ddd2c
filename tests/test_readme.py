"""The README's and the guides' commands parse as written.

Every ``legkit`` command of the ```bash blocks of ``COMMAND_PAGES`` is parsed as written by its own parser (its
options and their values accepted), ``legkit demo`` and a small ``legkit balance`` run, and each
``python benches/...`` command is parsed the same way (a bench without options compiles). Not run here: the
install and test commands (``bash scripts/test.sh``, ``.venv/bin/pip install``, ``cargo bench``,
``python -m pytest``), which CI runs as its own steps. The ```python blocks run in tests/test_docs.py.
"""

from __future__ import annotations

import argparse
import re
import runpy
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from legkit import cli

ROOT = Path(__file__).resolve().parents[1]


def blocks(page: str, language: str) -> list[str]:
    """The code of the ```language blocks of ``page``."""
    return re.findall(rf"^```{language}\n(.*?)^```", (ROOT / page).read_text(), re.M | re.S)


#: The pages whose ```bash commands are checked.
COMMAND_PAGES = ["README.md", "docs/experiments.md", "docs/sweeps.md", "CONTRIBUTING.md"]


def commands(prefix: str) -> list[str]:
    """The command lines (comments stripped) of ``COMMAND_PAGES`` that start with ``prefix``, each once."""
    lines = [line.split("  #")[0].strip() for page in COMMAND_PAGES for code in blocks(page, "bash") for line in code.splitlines()]
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
