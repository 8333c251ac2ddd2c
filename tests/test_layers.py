"""The package's layers, read from its source: the library does not import the command-line experiments, the
optimiser's modules import each other downward only (no import circle, not even one only type checkers see), and no
file of the optimiser is over `MAX_FILE_LINES` lines, no class over `MAX_CLASS_LINES` (issue 52, item 4)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "legkit"


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


#: The longest file and the longest class of `legkit.optimize` (a file of the optimiser's house is one room).
MAX_FILE_LINES, MAX_CLASS_LINES = 600, 400


def imports(path: Path, type_checking: bool = False) -> set[str]:
    """Every legkit module `path` imports when it runs, at any depth of its code (function-level imports included;
    those under `if TYPE_CHECKING:`, which only type checkers read, with type_checking only)."""
    tree = ast.parse(path.read_text())
    typing_only = set() if type_checking else {
        id(n) for block in ast.walk(tree) if isinstance(block, ast.If) and ast.unparse(block.test).endswith("TYPE_CHECKING")
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
    assert imports(module, type_checking=True) == {"legkit.experiments.gait", "legkit.experiments.gait.main"}


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
    """Its modules, subpackages' included, and their imports for type checkers too (a circle a type checker sees is
    one the code's readers see: a Protocol or a type moved down breaks it). The package's own `__init__`, which only
    gathers the public names, is left out."""
    paths = [p for p in sorted((PACKAGE / package).rglob("*.py")) if p.parent != PACKAGE / package or p.name != "__init__.py"]
    names = {module_name(p) for p in paths}
    graph = {module_name(p): {n for n in imports(p, type_checking=True) if n in names} for p in paths}
    assert cycle(graph) is None


def optimiser_sizes() -> tuple[dict[str, int], dict[str, int]]:
    """The lines of every file of `legkit.optimize` and of every class in them (by its qualified name)."""
    files, classes = {}, {}
    for path in sorted((PACKAGE / "optimize").rglob("*.py")):
        text = path.read_text()
        files[module_name(path)] = len(text.splitlines())
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                assert node.end_lineno is not None
                classes[f"{module_name(path)}.{node.name}"] = node.end_lineno - node.lineno + 1
    return files, classes


def test_no_optimiser_file_or_class_is_too_long():
    files, classes = optimiser_sizes()
    assert "legkit.optimize.problem.MultiphaseProblem" in classes and "legkit.optimize.constraints.stance" in files
    assert {name: lines for name, lines in files.items() if lines > MAX_FILE_LINES} == {}
    assert {name: lines for name, lines in classes.items() if lines > MAX_CLASS_LINES} == {}


def test_the_cycle_finder_finds_a_cycle():
    assert cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


# The Rust crates: a module is a file (or an inline `mod x { ... }`), named by its path from the crate root
# ("crate::sim::tree"); it imports a module when it names an item defined there, through `use` or a path in its
# code, re-exports (`pub use`) followed to the item's own module. A module naming its own descendants is the
# package's composition (`mod` + `use child::...`), not an edge.
CRATES = Path(__file__).resolve().parents[1] / "crates"
_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.S)
_STRING = re.compile(r'\bb?r(#*)".*?"\1|b?"(?:\\.|[^"\\])*"|\'(?:\\.|[^\'\\])\'', re.S)
_USE = re.compile(r"\buse\s+([^;]+);")
_INLINE_MOD = re.compile(r"\bmod\s+(\w+)\s*\{")
_DEFINED = re.compile(r"\b(?:fn|struct|enum|trait|const|static|type|union|macro_rules!)\s+(\w+)")
_PATH = re.compile(r"\b(crate|super|self)((?:\s*::\s*\w+)+)")


def _split_tree(tree: str) -> list[tuple[list[str], str]]:
    """The leaves of a use tree ("a::{b, c::d as e, f::*}") as (path, bound name); a glob's name is "*"."""
    tree = re.sub(r"\s*(::|\{|\}|,)\s*", r"\1", tree.strip())
    brace = tree.find("{")
    if brace < 0:
        head, _, alias = tree.partition(" as ")
        segments = head.split("::")
        if segments[-1] == "self":  # `a::{self, b}`: the module a, named by the caller
            return [(segments[:-1], alias or "self")]
        return [(segments, "*" if segments[-1] == "*" else alias or segments[-1])]
    prefix, inner = tree[:brace].split("::")[:-1], tree[brace + 1 : tree.rindex("}")]
    depth, start, parts = 0, 0, []
    for i, char in enumerate(inner + ","):
        depth += {"{": 1, "}": -1}.get(char, 0)
        if char == "," and depth == 0:
            parts.append(inner[start:i])
            start = i + 1
    leaves = [(prefix + path, name) for part in parts if part for path, name in _split_tree(part)]
    return [(path, path[-1] if name == "self" else name) for path, name in leaves]


def _modules(src: Path) -> dict[str, str]:
    """Every module of the crate rooted at `src` (lib.rs) with its code, comments and strings removed; an inline
    module's code is its own, not its file's."""
    modules: dict[str, str] = {}
    for path in sorted(src.rglob("*.rs")):
        parts = path.relative_to(src).with_suffix("").parts
        parts = parts[:-1] if parts[-1] in {"mod", "lib"} else parts
        code = _STRING.sub('""', _COMMENT.sub("", path.read_text()))
        pending = [("::".join(("crate",) + parts), code)]
        while pending:
            name, code = pending.pop()
            while (found := _INLINE_MOD.search(code)) is not None:
                depth, end = 0, found.end() - 1
                for end in range(found.end() - 1, len(code)):
                    depth += {"{": 1, "}": -1}.get(code[end], 0)
                    if depth == 0:
                        break
                pending.append((f"{name}::{found.group(1)}", code[found.end() : end]))
                code = code[: found.start()] + code[end + 1 :]
            modules[name] = code
    return modules


def rust_imports(src: Path) -> dict[str, set[str]]:
    """The module graph of the crate rooted at `src`: module -> the modules whose items it names."""
    modules = _modules(src)
    bindings: dict[str, dict[str, list[str]]] = {}  # module -> name it brings in scope -> absolute path
    globs: dict[str, list[list[str]]] = {m: [] for m in modules}
    defined = {m: set(_DEFINED.findall(code)) for m, code in modules.items()}

    def absolute(module: str, segments: list[str]) -> list[str] | None:
        here, relative = module.split("::"), segments[0] in {"super", "self"}
        while segments and segments[0] in {"super", "self"}:
            here = here[:-1] if segments[0] == "super" else here
            segments = segments[1:]
        if segments and segments[0] == "crate":
            return segments
        if relative or "::".join(here + segments[:1]) in modules:
            return here + segments
        return None  # an external crate

    for module, code in modules.items():
        bindings[module] = {}
        for tree in _USE.findall(code):
            for segments, name in _split_tree(tree):
                path = absolute(module, segments if name != "*" else segments[:-1])
                if path is None:
                    continue
                if name == "*":
                    globs[module].append(path)
                elif name:
                    bindings[module][name] = path

    def resolve(path: list[str], seen: int = 0) -> str | None:
        here = path[0]
        for i, segment in enumerate(path[1:], start=1):
            if f"{here}::{segment}" in modules:
                here = f"{here}::{segment}"
            elif segment in defined[here] or seen > 20:
                return here
            elif segment in bindings[here]:
                return resolve(bindings[here][segment] + path[i + 1 :], seen + 1)
            else:
                for glob in globs[here]:
                    target = resolve(glob + path[i:], seen + 1)
                    if target is not None and target != "::".join(glob):
                        return target
                return here
        return here

    graph: dict[str, set[str]] = {}
    for module, code in modules.items():
        paths = [absolute(module, [m.group(1)] + re.sub(r"\s", "", m.group(2)).split("::")[1:]) for m in _PATH.finditer(_USE.sub("", code))]
        for name, target in bindings[module].items():  # a module brought in scope, then named: `algorithms::aba`
            if "::".join(target) in modules:
                paths += [target + m.group(1).split("::") for m in re.finditer(rf"(?<![\w:]){name}::(\w+)", code)]
        paths += list(bindings[module].values()) + globs[module]
        targets = {resolve(p) for p in paths if p}
        graph[module] = {t for t in targets if t is not None and t != module and not t.startswith(module + "::")}
    return graph


@pytest.mark.parametrize("crate", ["dynamics", "pybind"])
def test_a_rust_crate_has_no_import_circle(crate):
    assert cycle(rust_imports(CRATES / crate / "src")) is None


def test_the_rust_checker_finds_a_planted_cycle(tmp_path):
    (tmp_path / "lib.rs").write_text("mod a;\nmod b;\npub use a::A;\n")
    (tmp_path / "a.rs").write_text("pub struct A;\n// use crate::b::B;\nfn f() {}\n")
    (tmp_path / "b.rs").write_text("use crate::{A, c};\npub struct B;\n")
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "mod.rs").write_text("pub(crate) use d::D;\nmod d;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n")
    (tmp_path / "c" / "d.rs").write_text("pub struct D;\n")
    graph = rust_imports(tmp_path)
    assert graph["crate::b"] == {"crate::a", "crate::c"}
    assert graph["crate::c::tests"] == {"crate::c"}
    assert cycle(graph) is None, "the comment and the root's re-export of its child make no cycle"
    (tmp_path / "a.rs").write_text("pub struct A;\nfn f() -> Option<super::b::B> {\n    None\n}\n")
    assert cycle(rust_imports(tmp_path)) == ["crate::a", "crate::b", "crate::a"]
    (tmp_path / "a.rs").write_text("use crate::c;\npub struct A;\nfn f() { c::D; }\n")
    (tmp_path / "c" / "d.rs").write_text("use crate::b::{self, B};\npub struct D;\n")
    assert cycle(rust_imports(tmp_path)) == ["crate::a", "crate::c::d", "crate::b", "crate::a"]
