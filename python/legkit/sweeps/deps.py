"""The optional dependencies of ``legkit.sweeps``, checked up front: one place that names each one's extra.

``require("pyarrow", "ray")`` raises ImportError with one line naming the install command of the first
missing module, before a command creates any output."""

from __future__ import annotations

import importlib.util

#: module -> the extra that installs it (pyproject.toml's optional dependencies).
EXTRAS = {"pyarrow": "sweep", "optuna": "sweep", "ray": "cluster"}


def require(*modules: str) -> None:
    """ImportError naming the install command unless every module of ``modules`` can be imported."""
    for module in modules:
        if importlib.util.find_spec(module) is None:
            extra = EXTRAS.get(module, "all")
            raise ImportError(f"{module} is not installed; install it with: pip install 'legkit[{extra}]'")
