"""The defaults a docstring states are the defaults the signature has.

Every public callable of `legkit` and of its subpackages' ``__all__`` (classes with their public methods,
`legkit._core`'s included) is read with `inspect.signature` (a PyO3 function's ``__text_signature__``), and its
docstring is searched for the ways docstrings here state a default:

- a stated signature, ``Simulation(model, dt=1e-3, ...)``: every ``name=value`` in it, and it must list every
  parameter that has a default (a stated signature that leaves one out hides it);
- ``name=value (default)`` and ``name: value (default)``;
- ``name`` (default value) and ``name`` (default: value);
- ``name defaults to value``.

Only literal values (numbers, strings, True, False, None, tuples of them) are compared; a default described in
words ("one per core") is not. The stubs' defaults are compared with the signatures in test_hostile_forms.py.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
from collections.abc import Callable, Iterator

import pytest

import legkit as lk

NAME = r"[A-Za-z_][A-Za-z0-9_]*"
# A literal as docstrings write it: a quoted string, a number, True/False/None, or a parenthesised tuple of those.
ATOM = r"""(?:"[^"\n]*"|'[^'\n]*'|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|True|False|None|inf)"""
LITERAL = rf"(?:{ATOM}|\((?:\s*{ATOM}\s*,)+\s*(?:{ATOM}\s*)?\)|\[(?:\s*{ATOM}\s*,?)*\])"
QUOTE = r"[`']{0,2}"
STATED_DEFAULTS = [
    re.compile(rf"{QUOTE}\b(?P<name>{NAME}){QUOTE}\s*=\s*{QUOTE}(?P<value>{LITERAL}){QUOTE}\s*\(default\)"),
    re.compile(rf"{QUOTE}\b(?P<name>{NAME}){QUOTE}:\s*{QUOTE}(?P<value>{LITERAL}){QUOTE}\s*\(default\)"),
    re.compile(rf"{QUOTE}\b(?P<name>{NAME}){QUOTE}\s*\(default:?\s+{QUOTE}(?P<value>{LITERAL}){QUOTE}\s*[),;]"),
    re.compile(rf"{QUOTE}\b(?P<name>{NAME}){QUOTE}\s+defaults\s+to\s+{QUOTE}(?P<value>{LITERAL}){QUOTE}(?![\w(]|\.\w)"),
]


def public_callables() -> Iterator[tuple[str, Callable[..., object]]]:
    """(dotted name, callable) for every public function, class and class method, each object once."""
    seen: set[int] = set()
    submodules = (importlib.import_module(f"legkit.{m.name}") for m in pkgutil.iter_modules(lk.__path__) if not m.name.startswith("_"))
    for module in [lk, *submodules]:
        for name in getattr(module, "__all__", []):
            value = getattr(module, name)
            if id(value) in seen or not callable(value):
                continue
            seen.add(id(value))
            yield f"{module.__name__}.{name}", value
            if inspect.isclass(value) and not issubclass(value, BaseException):
                for member, attribute in vars(value).items():
                    method = getattr(value, member)
                    if not member.startswith("_") and callable(method) and not inspect.isclass(attribute):
                        yield f"{module.__name__}.{name}.{member}", method


def literal(text: str) -> object:
    return float("inf") if text == "inf" else ast.literal_eval(text)


def same(stated: object, default: object) -> bool:
    """Equal values (1e-3 and 0.001, 2 and 2.0 alike; True not 1; a tuple and a list of the same items alike)."""
    if isinstance(default, (list, tuple)) and isinstance(stated, (list, tuple)):
        return len(stated) == len(default) and all(same(a, b) for a, b in zip(stated, default))
    if isinstance(default, bool) or isinstance(stated, bool):
        return stated is default
    if isinstance(default, (int, float)) and isinstance(stated, (int, float)):
        return stated == default
    return type(stated) is type(default) and stated == default


def stated_signatures(name: str, doc: str) -> Iterator[str]:
    """The argument lists of the signatures a docstring writes out for `name`, as ``name(a, b=1)``."""
    for match in re.finditer(rf"(?<![\w.]){re.escape(name)}\(", doc):
        depth, start = 1, match.end()
        for end in range(start, len(doc)):
            depth += {"(": 1, ")": -1}.get(doc[end], 0)
            if depth == 0:
                yield doc[start:end]
                break


def split_arguments(text: str) -> list[str]:
    parts, depth, current = [], 0, ""
    for char in text:
        depth += {"(": 1, "[": 1, ")": -1, "]": -1}.get(char, 0)
        if char == "," and depth == 0:
            parts.append(current.strip())
            current = ""
        else:
            current += char
    return [*parts, current.strip()] if current.strip() else parts


def stated_defaults(dotted: str, function: Callable[..., object]) -> Iterator[tuple[str, str | None]]:
    """(parameter, stated value) for each default the docstring of `function` states, the value None for a
    parameter with a default that a stated signature leaves out."""
    doc = inspect.getdoc(function) or ""
    parameters = inspect.signature(function).parameters
    short = dotted.rsplit(".", 1)[-1]
    for arguments in stated_signatures(short, doc):
        items = [argument.partition("=") for argument in split_arguments(arguments)]
        stated = {key.strip(): value.strip() for key, equals, value in items if equals}
        if not stated or not any(not equals and key.strip() in parameters for key, equals, _ in items):
            continue  # a call in an example (all keywords, or no keyword at all), not a signature
        yield from ((p.name, None) for p in parameters.values() if p.default is not p.empty and p.name not in stated)
        yield from stated.items()
    for pattern in STATED_DEFAULTS:
        yield from ((match["name"], match["value"]) for match in pattern.finditer(doc) if match["name"] in parameters)


def mismatches(dotted: str, function: Callable[..., object]) -> Iterator[str]:
    """Each default the docstring of `function` states that its signature does not have."""
    parameters = inspect.signature(function).parameters
    for name, value in stated_defaults(dotted, function):
        default = parameters[name].default if name in parameters else "no such parameter"
        if value is None:
            yield f"{dotted}: the stated signature leaves out {name}={default!r}"
        elif re.fullmatch(LITERAL, value) and not same(literal(value), default):
            yield f"{dotted}: states {name} = {value} by default, the signature has {default!r}"


def has_signature(function: Callable[..., object]) -> bool:
    try:
        inspect.signature(function)
    except (TypeError, ValueError):
        return False
    return True


CALLABLES = {name: function for name, function in public_callables() if has_signature(function)}


def test_the_walk_reaches_the_core_classes_methods_and_the_subpackages():
    assert {"legkit.Simulation", "legkit.Simulation.step", "legkit.Model.from_urdf", "legkit.integrate"} <= CALLABLES.keys()
    assert {name.split(".")[1] for name in CALLABLES} >= {"optimize", "strain", "stability", "sweeps"}
    assert len(CALLABLES) > 300, len(CALLABLES)


@pytest.mark.parametrize(
    ("doc", "expected"),
    [
        ("`f(a, b=2, c='x')`: ...", []),
        ("`f(a, b=3, c='x')`: ...", ["states b = 3"]),
        ("`f(a, b=2, d=1)`: ...", ["leaves out c='x'", "states d = 1"]),
        ("f(a, b=2)", ["leaves out c='x'"]),
        ("f(b=3), for example", []),
        ("mode=\"y\" (default): the ...", []),
        ("c='y' (default): the ...", ["states c = 'y' by default"]),
        ("c: \"y\" (default); ...", ["states c = \"y\" by default"]),
        ("``b`` (default 4) items", ["states b = 4 by default"]),
        ("``b`` (default: 2) items; ``c`` (default: one per core)", []),
        ("b defaults to 1.5.", ["states b = 1.5 by default"]),
        ("b defaults to its rows", []),
        ("with f(q) evaluated at b=5 elsewhere", []),
    ],
)
def test_the_parser_finds_what_it_should(doc: str, expected: list[str]):
    def f(a: int, b: int = 2, c: str = "x") -> None: ...

    f.__doc__ = doc
    found = list(mismatches("module.f", f))
    assert len(found) == len(expected), found
    for message, part in zip(found, expected):
        assert part in message, (message, part)


def test_documented_defaults_equal_the_signatures():
    stated = sum(1 for dotted, function in CALLABLES.items() for _ in stated_defaults(dotted, function))
    assert stated > 10, f"only {stated} stated defaults found: the patterns no longer match the docstrings"
    found = [message for dotted, function in CALLABLES.items() for message in mismatches(dotted, function)]
    assert not found, "\n".join(found)
