"""Every ``legkit`` command's ``--help``: each option with a default shows it, and no RST backticks."""

from __future__ import annotations

import argparse
import re

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
