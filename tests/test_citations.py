"""The code and docs cite papers by the keys of docs/references.md ("[Hardt 2002, eq. 10]"), never by a path
outside the repository, which a reader of the checkout or of the installed package does not have.

Covers python/, docs/, README.md, scripts/, benches/, tests/ and the Rust crates."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
COVERED = ["python", "docs", "README.md", "scripts", "benches", "tests", "crates"]
SUFFIXES = {".py", ".pyi", ".md", ".sh", ".toml", ".txt", ".rst", ".cfg", ".json", ".yaml", ".yml", ".rs"}
# Spelled in pieces so that this file does not match itself.
FORBIDDEN = [
    re.compile(re.escape("shared" + "/seeds")),
    re.compile(re.escape("DESIGN" + ".md")),
    re.compile(r"\bfile " + r"00\d\b"),  # the seed texts' file numbers
    re.compile(re.escape("/" + "work/")),
    re.compile(re.escape("../" + "shared") + r"\b"),  # the folder beside the checkout that holds them
]
KEYS = re.compile(r"\[(Moll 2006|Lin 2003|Hardt 2002|Featherstone 2008|Carpentier 2018|Posa 2016|Ferrolho 2021)[],]")


def _files() -> list[Path]:
    files: list[Path] = []
    for entry in COVERED:
        path = ROOT / entry
        candidates = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
        files += [p for p in candidates if p.suffix in SUFFIXES and "__pycache__" not in p.parts]
    return files


def outside_references(text: str) -> list[str]:
    """The names in ``text`` of places outside the repository (the seed texts, a design note, a home folder)."""
    return [m.group(0) for pattern in FORBIDDEN for m in pattern.finditer(text)]


def test_no_file_names_a_path_outside_the_repository() -> None:
    offenders = {}
    for path in _files():
        found = outside_references(path.read_text(encoding="utf-8", errors="replace"))
        if found:
            offenders[str(path.relative_to(ROOT))] = found
    assert not offenders, offenders


@pytest.mark.parametrize(
    ("text", "bad"),
    [
        ("see ../" + "shared/" + "seeds/003_x.txt, eq. 10", True),
        ("as in " + "DESIGN" + ".md", True),
        ("eq. 8 of " + "file 00" + "3", True),
        ("a link [guide](../README.md) from docs", False),
        ("[Hardt 2002, eq. 10]", False),
        ("a mesh at ../meshes/leg.stl", False),
    ],
)
def test_the_check_tells_outside_paths_from_citations(text: str, bad: bool) -> None:
    assert bool(outside_references(text)) is bad


def test_the_cited_keys_are_listed_in_references() -> None:
    listed = (ROOT / "docs" / "references.md").read_text(encoding="utf-8")
    cited = {m.group(1) for path in _files() for m in KEYS.finditer(path.read_text(encoding="utf-8", errors="replace"))}
    assert cited, "no citation found"
    assert all(f"| {key} |" in listed for key in cited), cited
