"""What the viewer draws: shapes attached to bodies, from the simulation's colliders or the URDF's <visual>."""

from __future__ import annotations

import math
import os
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array

PRIMITIVES = ("box", "sphere", "capsule", "cylinder")
MESH_FORMATS = ("stl", "dae", "obj")


@dataclass(frozen=True, eq=False)
class Shape:
    """One piece of geometry fixed to a body.

    ``kind`` is "box" (``size`` = full edge lengths sx, sy, sz), "sphere" (radius,), "capsule" or "cylinder"
    (half_height, radius) along the shape's z axis, "convex" (``vertices`` (n, 3), the convex hull's; ``size``
    empty), or "mesh" (``mesh`` a file meshcat reads: STL, DAE or OBJ; ``size`` = the scale along x, y, z).
    ``placement`` (4, 4) maps shape to body coordinates.
    ``color`` is an RGBA tuple in [0, 1], or None for the robot's colour."""

    body: int
    kind: str
    size: tuple[float, ...]
    placement: np.ndarray = field(default_factory=lambda: np.eye(4))
    mesh: Path | None = None
    color: tuple[float, float, float, float] | None = None
    vertices: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.kind not in PRIMITIVES + ("convex", "mesh"):
            raise ValueError(f"kind: must be one of {PRIMITIVES + ('convex', 'mesh')}, got {self.kind!r}")
        expected = {"box": 3, "sphere": 1, "capsule": 2, "cylinder": 2, "convex": 0, "mesh": 3}[self.kind]
        size = tuple(float(s) for s in float_array(self.size, "size").reshape(-1))
        if len(size) != expected or not all(s > 0 for s in size):
            raise ValueError(f"size: a {self.kind} takes {expected} positive number(s), got {self.size!r}")
        placement = float_array(self.placement, "placement")
        if placement.shape != (4, 4):
            raise ValueError(f"placement: must be a 4x4 matrix, got shape {placement.shape}")
        if self.kind == "mesh" and self.mesh is None:
            raise ValueError("mesh: a mesh shape needs its file")
        if self.kind == "convex":
            if self.vertices is None:
                raise ValueError("vertices: a convex shape needs its vertices")
            vertices = float_array(self.vertices, "vertices")
            if vertices.ndim != 2 or vertices.shape[1] != 3 or vertices.shape[0] < 4:
                raise ValueError(f"vertices: a convex shape takes (n >= 4, 3) vertices, got shape {vertices.shape}")
            object.__setattr__(self, "vertices", vertices.copy())
        if self.color is not None:
            color = float_array(self.color, "color").reshape(-1)
            if color.size != 4 or np.any(color < 0) or np.any(color > 1):
                raise ValueError(f"color: must be RGBA, 4 numbers in [0, 1], got {self.color!r}")
            object.__setattr__(self, "color", tuple(float(c) for c in color))
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "placement", placement.copy())
        if self.mesh is not None:
            object.__setattr__(self, "mesh", Path(self.mesh))

    @property
    def radius(self) -> float:
        """Radius of a sphere about the shape's origin that encloses it (a mesh: of its scale only, a guess)."""
        if self.kind == "box":
            return 0.5 * math.sqrt(sum(s * s for s in self.size))
        if self.kind == "sphere":
            return self.size[0]
        if self.kind == "capsule":
            return self.size[0] + self.size[1]
        if self.kind == "cylinder":
            return math.hypot(self.size[0], self.size[1])
        if self.kind == "convex":
            assert self.vertices is not None
            return float(np.linalg.norm(self.vertices, axis=1).max())
        return 0.1 * max(self.size)

    def hull_faces(self) -> np.ndarray:
        """A convex shape's hull triangles (m, 3) as vertex indices, counter-clockwise seen from outside."""
        from scipy.spatial import ConvexHull

        assert self.vertices is not None
        hull = ConvexHull(self.vertices)
        faces = hull.simplices.copy()
        # Qhull's facet normals point outward; orient each triangle's winding along its facet's normal.
        a, b, c = (self.vertices[faces[:, k]] for k in range(3))
        inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
        faces[inward] = faces[inward][:, ::-1]
        return faces


def check_model(model: Any) -> lk.Model:
    if not isinstance(model, lk.Model):
        raise TypeError(f"model: must be a legkit.Model, got {type(model).__name__}")
    return model


def collision_shapes(model: lk.Model, shapes: dict[int | str, Any] | None = None) -> list[Shape]:
    """The shapes ``lk.Simulation(model, shapes=shapes)`` collides with, as ``Shape`` s (from
    ``Model.colliders``: the overrides in ``shapes``, else the URDF's <collision> shapes, else the box of each
    body's inertia)."""
    check_model(model)
    if shapes is not None and not isinstance(shapes, dict):
        raise TypeError(f"shapes: must be a dict like lk.Simulation's or None, got {type(shapes).__name__}")
    return [
        Shape(int(body), "convex", (), np.asarray(placement, dtype=float), vertices=np.asarray(size)) if kind == "convex"
        else Shape(int(body), str(kind), tuple(size), np.asarray(placement, dtype=float))
        for body, kind, size, placement in model.colliders(shapes)
    ]


def shape_poses(model: lk.Model, q: npt.ArrayLike, shapes: Sequence[Shape]) -> np.ndarray:
    """World poses (..., len(shapes), 4, 4) of ``shapes`` at configurations ``q`` (..., nq): one batched
    ``lk.forward_kinematics`` call, then each body's pose times the shape's placement."""
    check_model(model)
    q = float_array(q, "q", last=model.nq, min_ndim=1)
    bodies = np.array([s.body for s in shapes], dtype=int)
    if bodies.size and (bodies.min() < 0 or bodies.max() >= model.nbodies):
        raise ValueError(f"shapes: body indices must be in [0, {model.nbodies}), got {bodies.min()}..{bodies.max()}")
    placements = np.array([s.placement for s in shapes]).reshape(-1, 4, 4)
    world = lk.forward_kinematics(model, q)
    return world[..., bodies, :, :] @ placements


# ---------------------------------------------------------------------------------------------- URDF <visual>

def _floats(text: str | None, count: int, default: Sequence[float], what: str) -> np.ndarray:
    if text is None:
        return np.array(default, dtype=float)
    try:
        values = np.array([float(x) for x in text.split()], dtype=float)
    except ValueError as error:
        raise ValueError(f"urdf: {what}: not numbers: {text!r}") from error
    if values.size != count:
        raise ValueError(f"urdf: {what}: expected {count} numbers, got {text!r}")
    return values


def _rgba(text: str | None, what: str) -> tuple[float, float, float, float]:
    r, g, b, a = (float(x) for x in _floats(text, 4, (1, 1, 1, 1), what))
    return r, g, b, a


def _origin(element: ET.Element | None, what: str) -> np.ndarray:
    """The 4x4 transform of a URDF <origin xyz rpy> (fixed-axis roll, pitch, yaw: R = Rz(y) Ry(p) Rx(r))."""
    transform = np.eye(4)
    if element is None:
        return transform
    x, y, z = _floats(element.get("xyz"), 3, (0, 0, 0), f"{what} origin xyz")
    roll, pitch, yaw = _floats(element.get("rpy"), 3, (0, 0, 0), f"{what} origin rpy")
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    transform[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    transform[:3, 3] = (x, y, z)
    return transform


def resolve_mesh(filename: str, urdf: str | os.PathLike[str], package_dirs: Iterable[str | os.PathLike[str]] = ()) -> Path:
    """The file a URDF mesh ``filename`` names, found as ``lk.Model.from_urdf`` finds collision meshes
    (``lk.resolve_mesh``: ``package_dirs``, then ROS_PACKAGE_PATH, then the folders above ``urdf``).
    FileNotFoundError naming where it looked."""
    if isinstance(package_dirs, (str, os.PathLike)):
        package_dirs = [package_dirs]
    return Path(lk.resolve_mesh(filename, Path(urdf).resolve(), list(package_dirs)))


def visual_shapes(
    urdf: str | os.PathLike[str], model: lk.Model, package_dirs: Iterable[str | os.PathLike[str]] = (),
) -> list[Shape]:
    """The <visual> geometry of the URDF file ``urdf`` as ``Shape`` s of ``model`` (loaded from the same
    file: links are matched to bodies by name). Meshes are resolved with ``resolve_mesh``; colours come from
    the visual's <material> (inline or named at the top level). Links that are not bodies of ``model`` are
    skipped with a warning."""
    check_model(model)
    path = Path(urdf)
    if not path.is_file():
        raise FileNotFoundError(f"urdf: no such file {str(urdf)!r}")
    root = ET.parse(path).getroot()
    colors: dict[str, tuple[float, float, float, float]] = {}
    for named in root.findall("material"):
        rgba = named.find("color")
        if named.get("name") and rgba is not None:
            colors[named.get("name", "")] = _rgba(rgba.get("rgba"), "material color")
    bodies = {name: i for i, name in enumerate(model.names)}
    result: list[Shape] = []
    for link in root.findall("link"):
        name = link.get("name", "")
        visuals = link.findall("visual")
        if not visuals:
            continue
        if name not in bodies:
            warnings.warn(f"urdf: link {name!r} is not a body of the model; its <visual> is not shown", stacklevel=2)
            continue
        for visual in visuals:
            what = f"link {name!r} <visual>"
            placement = _origin(visual.find("origin"), what)
            color: tuple[float, float, float, float] | None = None
            material = visual.find("material")
            if material is not None:
                rgba = material.find("color")
                if rgba is not None:
                    color = _rgba(rgba.get("rgba"), f"{what} material color")
                else:
                    color = colors.get(material.get("name", ""))
            geometry = visual.find("geometry")
            element = None if geometry is None else next(iter(geometry), None)
            if element is None:
                raise ValueError(f"urdf: {what} has no <geometry>")
            body = bodies[name]
            if element.tag == "box":
                shape = Shape(body, "box", tuple(_floats(element.get("size"), 3, (), f"{what} box size")), placement, color=color)
            elif element.tag == "sphere":
                shape = Shape(body, "sphere", (float(element.get("radius", "nan")),), placement, color=color)
            elif element.tag in ("cylinder", "capsule"):
                length, radius = float(element.get("length", "nan")), float(element.get("radius", "nan"))
                shape = Shape(body, element.tag, (0.5 * length, radius), placement, color=color)
            elif element.tag == "mesh":
                filename = element.get("filename")
                if not filename:
                    raise ValueError(f"urdf: {what} <mesh> has no filename")
                mesh = resolve_mesh(filename, path, package_dirs)
                if mesh.suffix.lower().lstrip(".") not in MESH_FORMATS:
                    raise ValueError(f"urdf: {what}: mesh {filename!r} is not one of {MESH_FORMATS}")
                scale = tuple(_floats(element.get("scale"), 3, (1, 1, 1), f"{what} mesh scale"))
                shape = Shape(body, "mesh", scale, placement, mesh=mesh, color=color)
            else:
                raise ValueError(f"urdf: {what}: unknown geometry <{element.tag}>")
            result.append(shape)
    return result
