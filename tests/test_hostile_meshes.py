"""Hostile mesh files, as URDF collision meshes and as MJCF mesh assets (whose triangles give the geoms' mass):
lying headers, truncated files, faces naming no vertex, non-finite vertices, sizes beyond memory, degenerate and
open meshes under each inertia mode, mirroring and overflowing scales. Each file case runs in a child process with
a timeout and a memory limit (`test_hostile.outcome`); what MuJoCo compiles is compared with MuJoCo.
"""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

import legkit as lk
from test_hostile import binary_stl, interrupted_load, outcome, raises

CUBE = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
# Outward (counter-clockwise seen from outside) triangles of the unit cube.
CUBE_FACES = np.array(
    [[0, 3, 2], [0, 1, 3], [4, 7, 5], [4, 6, 7], [0, 5, 1], [0, 4, 5], [2, 7, 6], [2, 3, 7], [0, 6, 4], [0, 2, 6], [1, 7, 3], [1, 5, 7]]
)


def obj_text(vertices: np.ndarray, faces: list | np.ndarray, extra: str = "") -> str:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += ["f " + " ".join(str(i) for i in face) for face in faces]
    return "\n".join(lines) + "\n" + extra


def stl_bytes(vertices: np.ndarray, faces: np.ndarray, count: int | None = None) -> bytes:
    records = np.zeros(len(faces), dtype=[("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    records["corners"] = vertices[faces]
    return b"\0" * 80 + struct.pack("<I", len(faces) if count is None else count) + records.tobytes()


def msh_bytes(counts: tuple[int, int, int, int], faces: np.ndarray = CUBE_FACES) -> bytes:
    return struct.pack("<4i", *counts) + CUBE.astype("<f4").tobytes() + faces.astype("<i4").tobytes()


CUBE_OBJ = obj_text(CUBE, CUBE_FACES + 1)

# name: (file name, contents, what the warning says). Each is refused as a mesh (a warning), never a crash.
BROKEN = {
    "stl-count-lies": ("m.stl", stl_bytes(CUBE, CUBE_FACES, count=10**8), "neither binary STL (wrong length) nor ASCII STL"),
    "stl-truncated": ("m.stl", stl_bytes(CUBE, CUBE_FACES)[:-7], "neither binary STL (wrong length) nor ASCII STL"),
    "stl-ascii-short-vertex": ("m.stl", b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 1 2\nendloop\nendfacet\nendsolid s\n",
                               "a vertex without three numbers"),
    "obj-index-zero": ("m.obj", CUBE_OBJ + "f 0 1 2\n", 'face corner "0" names no vertex'),
    "obj-index-beyond": ("m.obj", CUBE_OBJ + "f 1 2 100\n", 'face corner "100" names no vertex'),
    "obj-negative-beyond": ("m.obj", CUBE_OBJ + "f -1 -2 -9\n", 'face corner "-9" names no vertex'),
    "obj-two-corners": ("m.obj", CUBE_OBJ + "f 1 2\n", "a face with fewer than three corners"),
    "obj-nan-vertex": ("m.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n", "a vertex is not finite"),
    "obj-inf-vertex": ("m.obj", "v 1e999 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n", "a vertex is not finite"),
    "msh-faces-lie": ("m.msh", msh_bytes((8, 0, 0, 10**8)), "an MSH file of 256 bytes for 8 vertices"),
    "msh-negative-count": ("m.msh", msh_bytes((-1, 0, 0, 12)), "an MSH file of 256 bytes"),
    "msh-counts-overflow": ("m.msh", msh_bytes((2**31 - 1,) * 4), "an MSH file of 256 bytes for 2147483647 vertices"),
    "msh-face-beyond": ("m.msh", msh_bytes((8, 0, 0, 12), np.vstack([CUBE_FACES[:-1], [[0, 1, -5]]])), "face 11 names no vertex"),
    "msh-header-cut": ("m.msh", b"\x08\x00\x00", "shorter than its header"),
}

URDF = (
    '<robot name="r"><link name="base"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
    '</inertial><collision><geometry><mesh filename="{file}" scale="{scale}"/></geometry></collision></link></robot>'
)
MJCF = (
    '<mujoco><asset><mesh name="m" file="{file}" scale="{scale}" inertia="{inertia}"/></asset><worldbody><body name="b">'
    '<freejoint/><geom type="mesh" mesh="m"/><geom size="0.1"/></body></worldbody></mujoco>'
)

LOAD = """
import warnings
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    model = {load}
report(raised=None, warnings=[str(w.message) for w in caught], mass=model.body(0).mass)
"""


def load(kind: str, path: Path, scale: str = "1 1 1", inertia: str = "legacy") -> str:
    if kind == "urdf":
        return f"lk.Model.from_urdf({URDF.format(file=path, scale=scale)!r})"
    return f"lk.Model.from_mjcf({MJCF.format(file=path, scale=scale, inertia=inertia)!r})"


@pytest.mark.parametrize("kind", ["urdf", "mjcf"])
@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_mesh_file_is_a_warning_naming_what_is_wrong(tmp_path, case, kind):
    name, contents, reason = BROKEN[case]
    path = tmp_path / name
    path.write_bytes(contents if isinstance(contents, bytes) else contents.encode())
    result = outcome(LOAD.format(load=load(kind, path)))
    assert result["raised"] is None and any(reason in w and str(path) in w for w in result["warnings"]), result


def write(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """The mesh as OBJ, binary STL or MSH by the suffix."""
    if path.suffix == ".obj":
        path.write_text(obj_text(vertices, faces + 1))
    elif path.suffix == ".stl":
        path.write_bytes(stl_bytes(vertices, faces))
    else:
        path.write_bytes(struct.pack("<4i", len(vertices), 0, 0, len(faces)) + vertices.astype("<f4").tobytes() + faces.astype("<i4").tobytes())
    return path


def mujoco_mass(xml: str) -> tuple[float, np.ndarray] | str:
    """The free body's mass and principal moments as MuJoCo compiles them, or its error."""
    mujoco = pytest.importorskip("mujoco")
    try:
        m = mujoco.MjModel.from_xml_string(xml)
    except ValueError as error:
        return str(error)
    return float(m.body_mass[1]), np.sort(m.body_inertia[1])


FLIPPED_ONE = CUBE_FACES.copy()
FLIPPED_ONE[3] = FLIPPED_ONE[3][::-1]
# The cube with a ninth vertex equal to the first, which the flipped triangle names in its place: an OBJ or MSH keeps
# the two apart (its faces are then consistently oriented), an STL's corners equal to the bit are one vertex.
TWIN = np.vstack([CUBE, CUBE[:1]])
TWIN_FACES = CUBE_FACES.copy()
TWIN_FACES[0] = [8, 2, 3]
MESHES = {
    "cube": (CUBE, CUBE_FACES),
    "open": (CUBE, CUBE_FACES[:-2]),  # two triangles missing: MuJoCo computes it all the same
    "inside-out": (CUBE, CUBE_FACES[:, ::-1]),
    "one-flipped": (CUBE, FLIPPED_ONE),
    "open-one-flipped": (CUBE, FLIPPED_ONE[:-2]),
    "twice": (CUBE, np.vstack([CUBE_FACES, CUBE_FACES])),
    "twin-vertex": (TWIN, TWIN_FACES),
}


def assert_as_mujoco(xml: str) -> None:
    """legkit loads `xml` with the free body's mass and principal moments MuJoCo gives it, or refuses it (a
    ValueError) for the reason MuJoCo does."""
    expected = mujoco_mass(xml)
    if isinstance(expected, str):
        reason = "inconsistent orientation" if "inconsistent orientation" in expected else "volume is negative"
        assert reason in expected, expected
        with pytest.raises(ValueError, match=reason) as refused:
            lk.Model.from_mjcf(xml)
        assert "<mesh name=\"m\">" in str(refused.value) and "MuJoCo refuses" in str(refused.value), refused.value
        return
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ours = lk.Model.from_mjcf(xml).body(0)
    assert [str(w.message) for w in caught] == []
    mass, moments = expected
    assert ours.mass == pytest.approx(mass, rel=1e-9)
    np.testing.assert_allclose(np.linalg.eigvalsh(ours.inertia), moments, rtol=1e-6)


@pytest.mark.parametrize("scale", ["1 1 1", "-1 1 1", "-1 -2 0.5", "-1 -1 -1"])
@pytest.mark.parametrize("inertia", ["legacy", "exact", "shell"])
@pytest.mark.parametrize("mesh", sorted(MESHES))
@pytest.mark.parametrize("suffix", [".obj", ".stl", ".msh"])
def test_mesh_mass_under_each_inertia_mode_and_mirroring_scale_as_mujoco(tmp_path, suffix, mesh, inertia, scale):
    # A mirroring scale (a negative product) turns the faces inside out, and MuJoCo turns them back: "exact" was left
    # out as a negative volume. Under "exact", MuJoCo refuses a mesh whose faces run along an edge in the same
    # direction twice (one flipped, or listed twice) and one whose volume is negative (inside out): so does legkit,
    # where it computed a mass without a word for the first.
    vertices, faces = MESHES[mesh]
    assert_as_mujoco(MJCF.format(file=write(tmp_path / f"m{suffix}", vertices, faces), scale=scale, inertia=inertia))


@pytest.mark.parametrize("scale", ["1e200 1 1", "1e308 1e308 1e308"])
def test_a_scale_whose_mass_overflows_is_a_warning_and_refused_when_strict(tmp_path, scale):
    # The overflow made the volume NaN, and a NaN mass failed every test that would have reported it: the geom's
    # mass was left out without a word (MuJoCo leaves it out without a word).
    path = write(tmp_path / "m.obj", CUBE, CUBE_FACES)
    xml = MJCF.format(file=path, scale=scale, inertia="exact")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        lk.Model.from_mjcf(xml)
    assert any("overflows float64" in str(w.message) for w in caught), [str(w.message) for w in caught]
    with pytest.raises(ValueError, match="overflows float64"):
        lk.Model.from_mjcf(xml, strict=True)


def test_an_obj_face_of_millions_of_corners_loads_as_a_collision_mesh_without_cutting_it(tmp_path):
    # 18 MB of text: one face of 9 million corners, which a URDF's hull does not need cut into triangles (it was
    # refused beyond 1024 corners).
    path = tmp_path / "m.obj"
    path.write_text(obj_text(CUBE, [], extra="f " + "1 2 3 " * 3_000_000 + "\n"))
    result = outcome(LOAD.format(load=load("urdf", path)))
    assert result == {"raised": None, "warnings": [], "mass": 1.0}, result


@pytest.mark.slow
@pytest.mark.serial
def test_an_interrupted_cut_of_an_obj_face_of_a_million_corners_stops_its_worker(tmp_path):
    # Ear clipping takes time growing with the square of the corners (0.7 s of CPU for 16,384, so about an hour for a
    # million): it checks for Ctrl-C about every millisecond of work, so the load stops within a second of it.
    n = 1_000_000
    t = 2 * np.pi * np.arange(n) / n
    (tmp_path / "m.obj").write_text(obj_text(np.c_[np.cos(t), np.sin(t), np.zeros(n)], [np.arange(1, n + 1)]))
    path = tmp_path / "model.mjcf"
    path.write_text(MJCF.format(file=tmp_path / "m.obj", scale="1 1 1", inertia="shell"))
    result = interrupted_load(path, "mjcf", whole=4.0)
    assert result["worker_cpu_after"] < 1.0, result


def prism(n: int) -> tuple[np.ndarray, list]:
    """A regular prism of `n` sides (unit circumradius, unit height): two OBJ faces of n corners (1-based) and n
    quadrilaterals, outward."""
    t = 2 * np.pi * np.arange(n) / n
    ring = np.c_[np.cos(t), np.sin(t), np.zeros(n)]
    side = [[k + 1, (k + 1) % n + 1, (k + 1) % n + n + 1, k + n + 1] for k in range(n)]
    return np.vstack([ring, ring + [0, 0, 1]]), [list(range(n, 0, -1)), list(range(n + 1, 2 * n + 1)), *side]


@pytest.mark.parametrize("inertia", ["legacy", "exact", "shell"])
@pytest.mark.parametrize("corners", [100, 101, 2000])
def test_obj_faces_of_many_corners_are_cut_whole_and_a_warning_says_where_mujoco_differs(tmp_path, corners, inertia):
    # Up to 100 corners, MuJoCo's mass; beyond, MuJoCo leaves part or all of the face out (all, here), where legkit
    # takes the whole face: the exact prism's mass, with a warning naming the line (an error when strict).
    vertices, faces = prism(corners)
    path = tmp_path / "m.obj"
    path.write_text(obj_text(vertices, faces))
    xml = MJCF.format(file=path, scale="1 1 1", inertia=inertia)
    if corners <= 100:
        assert_as_mujoco(xml)
        return
    with pytest.warns(lk.MjcfWarning, match=f"line {2 * corners + 1}: a face of {corners} corners, whose mass MuJoCo takes otherwise"):
        ours = lk.Model.from_mjcf(xml).body(0)
    area = corners / 2 * np.sin(2 * np.pi / corners)  # of each end face
    measure = 2 * area + corners * 2 * np.sin(np.pi / corners) if inertia == "shell" else area
    assert ours.mass == pytest.approx(1000 * measure + 4 / 3 * np.pi * 0.1**3 * 1000, rel=1e-6)
    assert mujoco_mass(xml)[0] < ours.mass - 500  # MuJoCo's leaves the end faces out
    with pytest.raises(ValueError, match="whose mass MuJoCo takes otherwise"):
        lk.Model.from_mjcf(xml, strict=True)


# The unit cube's six faces as quadrilaterals (1-based), and polygons that replace the first: each is cut into
# triangles as MuJoCo cuts it (tinyobjloader's triangulation), whatever its shape.
CUBE_QUADS = ["1 3 7 5", "2 6 8 4", "1 5 6 2", "3 4 8 7", "1 2 4 3", "5 7 8 6"]
EXTRA = np.array([[0.5, 0.0, 0.0], [0.5, 0.5, -0.3], [0.5, 0.5, 0.2]])  # 9 on an edge of the first, 10 below it, 11 above
POLYGONS = {
    "repeated": ["1 3 7 5 1 3 7 5"],
    "repeated-thrice": ["1 3 7 5 1 3 7 5 1 3 7 5"],
    "repeated-corner": ["1 3 3 7 5 5"],
    "collinear": ["1 3 7 5 9"],
    "non-planar": ["10 1 3 7 5"],
    "concave": ["1 3 7 11 5"],
    "self-crossing-quad": ["1 7 3 5"],
    "all-collinear": ["1 9 5", "1 3 7 5"],
}


@pytest.mark.parametrize("inertia", ["legacy", "exact", "shell"])
@pytest.mark.parametrize("polygon", sorted(POLYGONS))
def test_obj_polygons_are_cut_into_triangles_as_mujoco_cuts_them(tmp_path, polygon, inertia):
    # The fan from the first corner gave a polygon repeating its corners a shell mass of 1.5e9 (MuJoCo: 6000).
    # Where the triangles cut run along an edge twice in one direction (a polygon repeating itself, a self-crossing
    # quadrilateral), MuJoCo refuses "exact", and so does legkit.
    path = tmp_path / "m.obj"
    path.write_text(obj_text(np.vstack([CUBE, EXTRA]), [], extra="\n".join(["f " + f for f in POLYGONS[polygon] + CUBE_QUADS[1:]]) + "\n"))
    assert_as_mujoco(MJCF.format(file=path, scale="1 1 1", inertia=inertia))


def test_an_mjcf_mesh_too_large_for_memory_is_a_memory_error(tmp_path):
    # As for a URDF's: the load fails, where the mesh was left out with a warning.
    binary_stl(tmp_path / "m.stl", 4_000_000)
    raises(
        f"""
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 350 * 2**20, vm + 350 * 2**20))
{load("mjcf", tmp_path / "m.stl")}
""",
        "MemoryError",
        "mesh",
        "m.stl",
        "bytes",
        memory=0,
    )
