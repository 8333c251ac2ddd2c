"""Every ``legkit`` command's ``--help``: each option with a default shows it, and no RST backticks."""

from __future__ import annotations

import argparse
import re

import numpy as np
import pytest

from legkit import cli
from legkit._help import HelpFormatter, default_text

COMMANDS = [[], ["demo"], *([name] for name in cli.EXPERIMENTS)]


def _parser_and_help(argv: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> tuple[argparse.ArgumentParser, str]:
    """The parser that ``legkit <argv> --help`` prints, and what it prints."""
    parsers: list[argparse.ArgumentParser] = []
    original = argparse.ArgumentParser.parse_args

    def recording(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> object:
        parsers.append(self)
        return original(self, *args, **kwargs)  # type: ignore[call-overload]

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", recording)
    with pytest.raises(SystemExit) as stop:
        cli.run([*argv, "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    assert parsers, argv
    return parsers[-1] if not argv or argv[0] in cli.EXPERIMENTS else parsers[0], text


def _option_blocks(text: str) -> dict[str, str]:
    """Each option's entry of a help text (its ``  --name`` line and the indented lines below), whitespace folded."""
    blocks: dict[str, str] = {}
    names: list[str] = []
    for line in text.splitlines():
        if line.startswith("  -"):
            invocation = re.split(r"\s{2,}", line.strip())[0]
            names = [part.split()[0] for part in invocation.split(", ")]
        elif not (line.startswith("    ") and names):
            names = []
            continue
        for name in names:
            blocks[name] = " ".join(f"{blocks.get(name, '')} {line}".split())
    return blocks


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: " ".join(a) or "legkit")
def test_help_shows_every_default_and_no_backticks(argv: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    parser, text = _parser_and_help(argv, monkeypatch, capsys)
    assert "`" not in text, text
    blocks = _option_blocks(text)
    for action in parser._actions:
        if not action.option_strings or action.nargs == 0 or action.default in (None, argparse.SUPPRESS):
            continue  # positionals, flags and options without a default
        name = max(action.option_strings, key=len)
        block = " ".join(blocks[name].split())
        # The value as the user would type it (the help may wrap a long list over lines: folded above).
        assert "default" in block and default_text(action.default) in block, f"{name}: {block!r}"


def test_help_formatter_adds_a_missing_default_once() -> None:
    parser = argparse.ArgumentParser(formatter_class=HelpFormatter)
    parser.add_argument("--rate", type=float, default=0.5, help="a `rate`")
    parser.add_argument("--stated", type=int, default=3, help="stated (default 3)")
    parser.add_argument("--items", nargs="+", default=["a", "b"], help="items")
    parser.add_argument("--flag", action="store_true", help="a flag")
    text = " ".join(parser.format_help().split())
    assert "a rate (default: 0.5)" in text
    assert "stated (default 3)" in text and "(default 3) (default" not in text
    assert "items (default: a b)" in text
    assert "a flag" in text and "a flag (default" not in text


WRITERS = ["balance", "strain", "gait", "sweep"]


@pytest.mark.parametrize("command", WRITERS)
def test_every_command_writes_to_out_under_legkit_out_by_default(command: str, monkeypatch: pytest.MonkeyPatch,
                                                                 capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    monkeypatch.chdir(tmp_path)  # parsing the default creates it: here, not in the checkout
    parser, _ = _parser_and_help([command], monkeypatch, capsys)
    (out,) = [a for a in parser._actions if "--out" in a.option_strings]
    assert str(out.default) == f"legkit-out/{command}"
    assert str(parser.parse_args([]).out) == f"legkit-out/{command}"
    assert str(parser.parse_args(["--out", str(tmp_path / "elsewhere")]).out) == str(tmp_path / "elsewhere")


def test_the_demo_turns_the_com_nearest_the_support_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.run(["demo"]) == 0
    text = capsys.readouterr().out
    theta = float(re.search(r"theta = (-?[\d.]+) deg", text).group(1))  # type: ignore[union-attr]
    before, after = (float(x) for x in re.findall(r"([\d.]+) m from the line", text))
    # Brute force: the composite's COM (mass-weighted by hand) yawed through every tenth of a degree.
    masses = np.array([0.25, 0.10, 0.05])
    com = (masses[:, None] * np.array([[0.0, 0.0, 0.042], [0.15, 0.0, 0.1], [0.3, 0.0, 0.1]])).sum(axis=0) / masses.sum()
    angles = np.radians(np.arange(0.0, 360.0, 0.1))
    y, z = np.hypot(com[0], com[1]) * np.sin(angles), np.full(angles.shape, com[2])
    distance = np.hypot(y - 0.12, z)
    assert before == pytest.approx(np.hypot(com[1] - 0.12, com[2]), abs=1e-4)
    assert after == pytest.approx(distance.min(), abs=1e-4) and after < before
    assert theta == pytest.approx(np.degrees(angles[np.argmin(distance)]), abs=0.1)
