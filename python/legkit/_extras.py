"""legkit's optional dependencies (pyproject.toml's extras), imported where a feature needs them.

The base install is NumPy and SciPy: the dynamics, the simulation, the agents, the strain models and the
stability indices. A feature that needs more calls ``require`` (or ``load``) first, so that a missing module
raises one ImportError naming the extra and the command that installs it from the checkout.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Iterable
from types import ModuleType
from typing import Any, TypeVar

T = TypeVar("T")

#: module -> the extra that installs it (pyproject.toml's ``[project.optional-dependencies]``).
EXTRAS = {
    "casadi": "optimize",
    "meshcat": "viewer",
    "PIL": "viewer",
    "matplotlib": "plot",
    "tqdm": "plot",
    "pyarrow": "sweep",
    "optuna": "sweep",
    "ray": "cluster",
}


class MissingExtra(ImportError):
    """An optional dependency is missing; the message names its extra and the install command."""


def install_command(extra: str) -> str:
    """The command that adds ``extra`` to the project's environment, run from a legkit checkout."""
    return f".venv/bin/pip install '.[{extra}]'"


def missing_message(module: str, extra: str) -> str:
    return f"{module} is not installed; it comes with legkit's '{extra}' extra: install it from the legkit checkout with {install_command(extra)}"


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ImportError:  # a finder that refuses the module (or a broken parent package)
        return False


def require(*modules: str, extra: str | None = None) -> None:
    """ImportError naming the extra and its install command unless every module of ``modules`` can be imported.

    ``extra`` overrides the table ``EXTRAS`` (a module that several extras carry, named by the one the
    feature at hand belongs to)."""
    for module in modules:
        if not _installed(module):
            raise MissingExtra(missing_message(module, extra or EXTRAS.get(module, "all")))


def load(module: str, extra: str | None = None) -> ModuleType:
    """``module`` imported, after ``require``; the import's own ImportError (a broken install) is re-raised
    with the install command."""
    require(module.partition(".")[0], extra=extra)
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise MissingExtra(f"{missing_message(module, extra or EXTRAS.get(module.partition('.')[0], 'all'))} ({error})") from error


def progress(iterable: Iterable[T], *, enabled: bool = True, extra: str = "plot", **options: Any) -> Iterable[T]:
    """``iterable`` behind a tqdm progress bar when ``enabled`` (tqdm comes with ``extra``); as it is otherwise."""
    if not enabled:
        return iterable
    tqdm = load("tqdm", extra).tqdm
    return tqdm(iterable, **options)


def progress_bar(*, extra: str = "plot", **options: Any) -> Any:
    """A tqdm progress bar for work that ticks as it goes (``update``; a context manager), tqdm from ``extra``."""
    return load("tqdm", extra).tqdm(**options)
