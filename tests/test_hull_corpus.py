"""Convex hulls and mesh masses against MuJoCo's compiler over the existing mesh corpus (issue 53, item 1): every STL
and OBJ file shipped by example-robot-data (`cmeel.prefix/share/example-robot-data/robots/*/meshes/`), dm_control
and gymnasium, sorted by path (MuJoCo's MSH files are left out). Each file is one MJCF `<mesh>` asset under one
free body's `<geom type="mesh" density="1000">`, compiled by `lk.Model.from_mjcf` and `mujoco.MjModel.from_xml_string`:

- the default (`inertia="legacy"`): the body's mass and principal moments against `body_mass` / `body_inertia`;
- `inertia="convex"`, which legkit does not compute (a documented warning; the mass is left out): the mass
  properties of legkit's collision hull (`Model.colliders()`, tetrahedra from its centroid, at the geom's density)
  against MuJoCo's convex mass and moments, and against two brute-force references, scipy's `ConvexHull` volume of
  MuJoCo's own hull vertices (`mesh_graph`) and of all of MuJoCo's mesh vertices.

Every 20th file (34 of 665), ALX02_01_A03_NeckLink.obj and the ASCII STL are in the fast tier (`-m 'not slow'`, 2 s);
the rest is `slow` (all: 35 s on 2 busy cores).
Tolerances (largest differences measured over the corpus in brackets):

- mass and hull volume: 1e-9 relative (legacy mass 0 exactly; hull 1.3e-11: the hull's points are nudged inwards
  by < 1e-9 of their distance from the centroid before quickhull, which moves its volume by < 3e-9);
- principal moments: 1.5e-6 of the largest. MuJoCo's Jacobi iteration stops with off-diagonal terms up to that
  (test_mjcf.MESH_AXES), which moves each eigenvalue by at most as much (Weyl) [legacy 8.3e-9, hull 6.9e-9];
- beyond 25,000 distinct vertices legkit takes the hull of a grid-thinned subset, with a warning (4 files): their
  hull's mass to 1e-3 relative [3.1e-4, dog_assets/BONERibcage.stl, 35,386 vertices], moments to 2e-3 [6.3e-4].

Meshes MuJoCo refuses are refused by legkit too (the refusals themselves are tested in test_hostile_meshes.py).
Where MuJoCo reads a file otherwise, legkit takes the whole mesh and says so, an `lk.MjcfWarning` (a ValueError
under strict=True) naming the file: OBJ files of several groups (`g`/`o` lines, FIRST_GROUP: 21 files), whose faces
MuJoCo 4.0 takes from the first group only (and refuses nub.obj, whose first group's volume is too small), the mass
of each checked against a brute-force sum over all its faces (legkit's) and over the first group's (MuJoCo's); and
an ASCII STL, which MuJoCo refuses (ASCII_STL). One mismatch is kept as a strict xfail: a flat mesh whose hull
MuJoCo refuses under inertia="convex" and legkit loads with warnings (HULL_REFUSED).
"""

from __future__ import annotations

import glob
import importlib.util
import os
import re
import warnings

import numpy as np
import pytest

import legkit as lk

mujoco = pytest.importorskip("mujoco")
ConvexHull = pytest.importorskip("scipy.spatial").ConvexHull

DENSITY = 1000.0
MASS = 1e-9
MOMENTS = 1.5e-6
FLOAT32 = 1e-6
THINNED_MASS, THINNED_MOMENTS = 1e-3, 2e-3
THINNED = "convex hull is taken over"
FAST_EVERY = 20


def corpus() -> list[str]:
    """The STL and OBJ files of example-robot-data, dm_control and gymnasium (those installed), sorted."""
    site = os.path.dirname(os.path.dirname(mujoco.__file__))
    roots = glob.glob(os.path.join(site, "cmeel.prefix", "share", "example-robot-data", "robots", "*", "meshes"))
    for package in ("dm_control", "gymnasium"):
        spec = importlib.util.find_spec(package)
        if spec is not None and spec.origin is not None:
            roots.append(os.path.dirname(spec.origin))
    files = {f for root in roots for f in glob.glob(os.path.join(root, "**", "*"), recursive=True)}
    return sorted(f for f in files if f.lower().endswith((".stl", ".obj")))


def short(path: str) -> str:
    return path.split("site-packages/")[-1].removeprefix("cmeel.prefix/share/example-robot-data/robots/")


# legkit's and MuJoCo's mass (kg, density 1000) of the OBJ files of several groups: legkit's of all the faces, MuJoCo's
# of the first group's (ALX02_01_A03_NeckLink.obj: 362 of 721); MuJoCo refuses nub.obj (None).
FIRST_GROUP: dict[str, tuple[float, float | None]] = {
    "alex_description/meshes/ALX02_01_A03_NeckLink.obj": (0.753814, 0.219815),
    "alex_description/meshes/ALX02_02_A01_BaseLink.obj": (1.40723, 0.276177),
    "alex_description/meshes/ALX02_02_A04_BaseDiffLink.obj": (1.15587, 0.408525),
    "alex_description/meshes/Head.obj": (8.51726, 3.47765),
    "alex_description/meshes/SakePalmLink.obj": (0.265057, 0.0273969),
    "alex_description/meshes/Torso.obj": (18.4751, 5.89846),
    "alex_description/meshes/cycloidal_arm/LeftElbowPitchLink.obj": (0.636834, 0.16233),
    "alex_description/meshes/cycloidal_arm/LeftShoulderPitchLink.obj": (1.93519, 0.444904),
    "alex_description/meshes/cycloidal_arm/LeftShoulderRollLink.obj": (1.02365, 0.0385781),
    "alex_description/meshes/cycloidal_arm/LeftShoulderYawLink.obj": (1.27907, 0.0164472),
    "alex_description/meshes/cycloidal_arm/LeftWristRollLink.obj": (0.625366, 0.0321142),
    "alex_description/meshes/cycloidal_arm/LeftWristYawLink.obj": (1.65782, 0.0271161),
    "alex_description/meshes/cycloidal_arm/RightElbowPitchLink.obj": (0.636834, 0.16233),
    "alex_description/meshes/cycloidal_arm/RightShoulderPitchLink.obj": (1.93603, 0.445078),
    "alex_description/meshes/cycloidal_arm/RightShoulderRollLink.obj": (1.02317, 0.0385117),
    "alex_description/meshes/cycloidal_arm/RightShoulderYawLink.obj": (1.27888, 0.0164204),
    "alex_description/meshes/cycloidal_arm/RightWristRollLink.obj": (0.625366, 0.0321142),
    "alex_description/meshes/cycloidal_arm/RightWristYawLink.obj": (1.65782, 0.0271161),
    "alex_description/meshes/cycloidal_arm/nub.obj": (0.393278, None),
    "alex_description/meshes/sake_finger_knuckle_and_tip.obj": (0.0699347, 0.0308104),
    "laikago_description/meshes/trunk.obj": (22.6384, 20.7395),
}
TABLE = 1e-5  # FIRST_GROUP's six digits
# MuJoCo refuses an ASCII STL ('perhaps this is an ASCII file?'); legkit reads it, with a warning.
ASCII_STL = {"simple_humanoid_description/meshes/box.stl"}
# With inertia="convex": a flat mesh, whose hull MuJoCo refuses ('has coplanar vertices, cannot compute convex hull'),
# legkit loads with warnings (the mass left out, the geom without a collision shape).
HULL_REFUSED = {
    "solo_description/meshes/plane.obj": "a flat square: MuJoCo refuses its hull under inertia='convex', legkit loads it with warnings",
}


def cases(mismatches: dict[str, str], leave_out=frozenset(), only=None, fast=frozenset()) -> list:
    """The corpus as parameters (`only` those, if given; without `leave_out`): every FAST_EVERY-th file of the corpus
    and those in `fast` unmarked, the rest slow; `mismatches` strict xfails."""
    params = []
    for k, path in enumerate(CORPUS):
        if short(path) in leave_out or (only is not None and short(path) not in only):
            continue
        marks = [] if k % FAST_EVERY == 0 or short(path) in fast else [pytest.mark.slow]
        reason = mismatches.get(short(path))
        if reason is not None:
            marks.append(pytest.mark.xfail(strict=True, reason=f"{short(path)}: {reason}"))
        params.append(pytest.param(path, id=short(path), marks=marks))
    return params


def mjcf(path: str, inertia: str = "") -> str:
    attribute = f' inertia="{inertia}"' if inertia else ""
    return (
        f'<mujoco><asset><mesh name="m" file="{path}"{attribute}/></asset><worldbody><body name="b"><freejoint/>'
        f'<geom type="mesh" mesh="m" density="{DENSITY}"/></body></worldbody></mujoco>'
    )


def both(path: str, inertia: str = ""):
    """MuJoCo's model (None if it refuses the file) and legkit's with the warnings it gave; legkit must refuse with a
    ValueError what MuJoCo refuses."""
    xml = mjcf(path, inertia)
    try:
        m = mujoco.MjModel.from_xml_string(xml)
    except ValueError:
        with pytest.raises(ValueError):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                lk.Model.from_mjcf(xml)
        return None, None, []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = lk.Model.from_mjcf(xml)
    return m, model, [str(w.message) for w in caught]


def hull_mass(vertices: np.ndarray) -> tuple[float, np.ndarray]:
    """The volume and the principal moments (ascending, unit density) of the convex hull of `vertices`."""
    hull = ConvexHull(vertices)
    tetrahedra = np.concatenate([np.broadcast_to(vertices[hull.vertices].mean(0), (len(hull.simplices), 1, 3)), vertices[hull.simplices]], axis=1)
    volumes = np.abs(np.linalg.det(tetrahedra[:, 1:] - tetrahedra[:, :1])) / 6
    tetrahedra = tetrahedra - (volumes[:, None] * tetrahedra.mean(1)).sum(0) / volumes.sum()
    corners = tetrahedra.sum(1)  # ∫ x xᵀ over a tetrahedron: V/20 (Σ pᵢ pᵢᵀ + (Σ pᵢ)(Σ pᵢ)ᵀ)
    second = (volumes[:, None, None] / 20 * (np.einsum("nki,nkj->nij", tetrahedra, tetrahedra) + np.einsum("ni,nj->nij", corners, corners))).sum(0)
    return float(volumes.sum()), np.linalg.eigvalsh(np.trace(second) * np.eye(3) - second)


def assert_mass_as_mujocos(m, mass: float, moments: np.ndarray, rtol: float = MASS, moments_rtol: float = MOMENTS) -> None:
    theirs = np.sort(m.body_inertia[1])
    assert mass == pytest.approx(m.body_mass[1], rel=rtol)
    np.testing.assert_allclose(np.sort(moments), theirs, rtol=0, atol=moments_rtol * theirs.max())


CORPUS = corpus()
pytestmark = pytest.mark.skipif(not CORPUS, reason="example-robot-data, dm_control and gymnasium are not installed")


def obj_groups(path: str) -> tuple[np.ndarray, list[np.ndarray]]:
    """An OBJ file's vertices (in float32, as MuJoCo keeps them) and the triangles of each group of its faces, read as
    tinyobjloader reads them for MuJoCo: a `g` or `o` line followed by a space or tab, after faces, begins a new
    group. The files in FIRST_GROUP hold triangles only."""
    vertices: list[list[float]] = []
    groups: list[list[list[int]]] = [[]]
    with open(path, encoding="utf-8", errors="replace", newline="") as file:
        for line in file.read().split("\n"):
            words = line.split()
            if line.lstrip(" \t")[:2] in ("g ", "g\t", "o ", "o\t"):
                if groups[-1]:
                    groups.append([])
            elif words and words[0] == "v":
                vertices.append([float(x) for x in words[1:4]])
            elif words and words[0] == "f":
                corners = [int(w.split("/")[0]) for w in words[1:]]
                assert len(corners) == 3, line
                groups[-1].append([c - 1 if c > 0 else len(vertices) + c for c in corners])
    return np.asarray(vertices, dtype=np.float32).astype(float), [np.asarray(g) for g in groups if g]


def ascii_stl_triangles(path: str) -> tuple[np.ndarray, np.ndarray]:
    with open(path) as file:
        corners = [[float(x) for x in line.split()[1:4]] for line in file if line.split()[:1] == ["vertex"]]
    return np.asarray(corners, dtype=np.float32).astype(float), np.arange(len(corners)).reshape(-1, 3)


def legacy_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """A mesh's volume as MuJoCo's default inertia="legacy" takes it, by brute force over its triangles: the pyramids
    from the faces' area-weighted centroid to each face give the centre of mass, then the pyramids from the centre of
    mass to each face the volume, each counted positive. (The signed volume Σ a·(b×c)/6 is not it: these meshes are
    open surfaces or overlapping shells, and legacy volumes differ from it by up to 17 times.)"""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    areas = np.linalg.norm(np.cross(b - a, c - a), axis=1) / 2
    centres = (a + b + c) / 3
    centroid = (areas[:, None] * centres).sum(0) / areas.sum()

    def pyramids(apex: np.ndarray) -> np.ndarray:
        return np.abs(np.einsum("ij,ij->i", a - apex, np.cross(b - apex, c - apex))) / 6

    around = pyramids(centroid)
    com = (around[:, None] * (0.75 * centres + 0.25 * centroid)).sum(0) / around.sum()
    return float(pyramids(com).sum())


@pytest.mark.parametrize("path", cases({}, only=FIRST_GROUP.keys(), fast={"alex_description/meshes/ALX02_01_A03_NeckLink.obj"}))
def test_an_obj_of_several_groups_warns_that_mujocos_mass_takes_only_the_first_groups_faces(path: str) -> None:
    # legkit's mass is the whole mesh's (every group's faces), MuJoCo's the first group's: the warning says so.
    vertices, groups = obj_groups(path)
    faces = np.concatenate(groups)
    assert len(groups) > 1
    ours, theirs = FIRST_GROUP[short(path)]
    message = (
        f"{re.escape(path)}: its {len(faces)} faces lie in {len(groups)} groups \\(OBJ `g`/`o` lines\\): MuJoCo's mass takes only "
        f"the first group's {len(groups[0])} faces, legkit's is the whole mesh's"
    )
    with pytest.warns(lk.MjcfWarning, match=message):
        model = lk.Model.from_mjcf(mjcf(path))
    mass = model.body("b").mass
    assert mass == pytest.approx(DENSITY * legacy_volume(vertices, faces), rel=MASS)
    assert mass == pytest.approx(ours, rel=TABLE)
    first = DENSITY * legacy_volume(vertices, groups[0])
    if theirs is None:
        assert first < 1e-9  # MuJoCo's "volume is too small"
        with pytest.raises(ValueError, match="volume is too small"):
            mujoco.MjModel.from_xml_string(mjcf(path))
    else:
        assert mujoco.MjModel.from_xml_string(mjcf(path)).body_mass[1] == pytest.approx(first, rel=MASS)
        assert first == pytest.approx(theirs, rel=TABLE)
    with pytest.raises(ValueError, match=f"{re.escape(path)}: its .* groups .*\\(strict\\)"):
        lk.Model.from_mjcf(mjcf(path), strict=True)
    # Under inertia="convex", the hull is of every vertex in both (test_a_shipped_meshs_hull_and_convex_mass_are_mujocos).
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lk.Model.from_mjcf(mjcf(path, "convex"))
    assert not any("groups" in str(w.message) for w in caught), caught


@pytest.mark.parametrize("inertia", ["", "convex"])
@pytest.mark.parametrize("path", cases({}, only=ASCII_STL, fast=ASCII_STL))
def test_an_ascii_stl_warns_that_mujoco_refuses_it(path: str, inertia: str) -> None:
    with pytest.raises(ValueError, match="ASCII"):
        mujoco.MjModel.from_xml_string(mjcf(path, inertia))
    message = f"{re.escape(path)}: an ASCII STL, which MuJoCo refuses \\(it reads binary STL only\\); legkit reads it"
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "mjcf: body .* is not computed: left out")  # inertia="convex" (documented)
        with pytest.warns(lk.MjcfWarning, match=message):
            model = lk.Model.from_mjcf(mjcf(path, inertia))
    if not inertia:
        assert model.body("b").mass == pytest.approx(DENSITY * legacy_volume(*ascii_stl_triangles(path)), rel=MASS)
    with pytest.raises(ValueError, match=f"{message} \\(strict\\)"):
        lk.Model.from_mjcf(mjcf(path, inertia), strict=True)


@pytest.mark.parametrize("path", cases({}, leave_out=FIRST_GROUP.keys() | ASCII_STL))
def test_a_shipped_meshs_default_mass_is_mujocos(path: str) -> None:
    m, model, _ = both(path)
    if m is not None:
        body = model.body("b")
        assert_mass_as_mujocos(m, body.mass, np.linalg.eigvalsh(body.inertia))


@pytest.mark.parametrize("path", cases(HULL_REFUSED, leave_out=ASCII_STL))
def test_a_shipped_meshs_hull_and_convex_mass_are_mujocos(path: str) -> None:
    m, model, caught = both(path, "convex")
    if m is None:
        return
    assert any("mass of mesh geoms" in w for w in caught), caught  # documented: inertia="convex" is left out
    [(_, kind, vertices, _)] = model.colliders()
    assert kind == "convex"
    volume, moments = hull_mass(np.asarray(vertices))
    thinned = any(THINNED in w for w in caught)
    assert thinned == (m.mesh_vertnum[0] > 25_000), caught
    assert_mass_as_mujocos(m, DENSITY * volume, DENSITY * moments, *((THINNED_MASS, THINNED_MOMENTS) if thinned else (MASS, MOMENTS)))
    # MuJoCo's own hull (mesh_graph: numvert, numface, vert_edgeadr[numvert], vert_globalid[numvert], ...) and the
    # hull of all its vertices, by scipy: each the convex mass MuJoCo took, to the float32 rounding of the
    # vertices MuJoCo keeps (6e-8 of each coordinate) [measured 5.9e-8].
    graph = m.mesh_graph[m.mesh_graphadr[0] :]
    mesh = m.mesh_vert[m.mesh_vertadr[0] : m.mesh_vertadr[0] + m.mesh_vertnum[0]].astype(float)
    for points in (mesh[graph[2 + graph[0] : 2 + 2 * graph[0]]], mesh):
        assert DENSITY * ConvexHull(points).volume == pytest.approx(m.body_mass[1], rel=FLOAT32)
