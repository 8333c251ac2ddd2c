"""The ``--help`` layout of every ``legkit`` command: each option shows its default, and no RST markup."""

from __future__ import annotations

import argparse
from typing import Any


def default_text(value: Any) -> str:
    """A default as a user would type it: list items space-separated, numbers as given."""
    if isinstance(value, (list, tuple)):
        return " ".join(default_text(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions kept as written (examples stay on their lines); an option whose help does not state its
    default gets " (default: ...)"; RST backticks (docstrings reused as descriptions) are dropped."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        shown = "default" in text or "%(default)" in text
        if action.option_strings and action.nargs != 0 and action.default not in (None, argparse.SUPPRESS) and not shown:
            text += " (default: " + default_text(action.default).replace("%", "%%") + ")"
        return text.replace("`", "")

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        return super()._fill_text(text.replace("`", ""), width, indent)
