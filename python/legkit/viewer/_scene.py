"""A scene of robots (static or animated) and its meshcat commands: a self-contained HTML file, or a live viewer."""

from __future__ import annotations

import base64
import html
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._extras import require
from legkit._validation import float_array
from legkit.viewer._geometry import Shape, check_model, collision_shapes, visual_shapes

# Colours of successive robots (RGB in [0, 1]): matplotlib's tab10, which the experiments' plots use too.
PALETTE = (
    (0.122, 0.467, 0.706), (1.000, 0.498, 0.055), (0.173, 0.627, 0.173), (0.839, 0.153, 0.157),
    (0.580, 0.404, 0.741), (0.549, 0.337, 0.294), (0.890, 0.467, 0.761), (0.498, 0.498, 0.498),
    (0.737, 0.741, 0.133), (0.090, 0.745, 0.812),
)
BACKGROUND_TOP = (0.97, 0.98, 0.99)  # a light gradient: meshcat's dark grey grid and coloured robots stand out
BACKGROUND_BOTTOM = (0.78, 0.81, 0.85)
FIELD_OF_VIEW = 75.0  # degrees, vertical: meshcat's default camera


def import_meshcat() -> Any:
    """meshcat, imported without the DeprecationWarning its server module raises on import (pyzmq's ioloop)."""
    import warnings

    require("meshcat")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
        import meshcat.geometry  # noqa: F401
    return meshcat


def color_argument(value: Any, name: str) -> tuple[float, float, float, float]:
    """An RGB or RGBA colour in [0, 1] as an RGBA tuple."""
    array = float_array(value, name).reshape(-1)
    if array.size not in (3, 4) or np.any(array < 0) or np.any(array > 1):
        raise ValueError(f"{name}: must be 3 or 4 numbers in [0, 1] (RGB or RGBA), got {value!r}")
    return tuple(float(x) for x in array) + ((1.0,) if array.size == 3 else ())  # type: ignore[return-value]


def transform_argument(value: Any, name: str) -> np.ndarray:
    """A 4x4 rigid transform, or a translation (3,)."""
    array = float_array(value, name)
    if array.shape == (3,):
        transform = np.eye(4)
        transform[:3, 3] = array
        return transform
    if array.shape != (4, 4):
        raise ValueError(f"{name}: must be a translation (3,) or a 4x4 transform, got shape {array.shape}")
    return array.copy()


#: The largest coordinate the viewer draws: meshcat takes float32 poses, which end at 3.4e38 (beyond it, inf).
MAX_COORDINATE = 1e30


def trajectory_arguments(model: lk.Model, q: Any, times: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """(q (T, nq), times (T,)) of a motion, or (q (1, nq), None) of a single configuration."""
    q = float_array(q, "q", last=model.nq, min_ndim=1, bound=MAX_COORDINATE)
    if times is None:
        if q.ndim != 1:
            raise ValueError(f"times: needed with a trajectory q of shape {q.shape} (one time per row)")
        return q[None, :], None
    times = float_array(times, "times")
    if q.ndim != 2:
        raise ValueError(f"q: a motion takes shape (T, {model.nq}), got {q.shape}")
    if times.shape != (q.shape[0],):
        raise ValueError(f"times: must have shape ({q.shape[0]},) to match q {q.shape}, got {times.shape}")
    if q.shape[0] < 1 or np.any(np.diff(times) <= 0):
        raise ValueError("times: must be strictly increasing, with at least one sample")
    return q, times


def _node_name(text: str) -> str:
    """A meshcat path component: no slashes."""
    return text.replace("/", "_") or "_"


@dataclass
class RobotTrack:
    """One robot of a ``Scene``: its shapes, the world poses of the bodies carrying them (T, nbodies, 4, 4)
    and the sample times (T,) or None for a still pose."""

    name: str
    names: list[str]  # of the bodies, indexed by body
    shapes: list[Shape]
    bodies: np.ndarray  # indices of the bodies with shapes
    body_poses: np.ndarray  # (T, len(bodies), 4, 4), robot frame
    times: np.ndarray | None
    offset: np.ndarray  # (4, 4), robot frame in the world
    color: tuple[float, float, float, float]
    label: str | None

    def world_poses(self) -> np.ndarray:
        """(T, len(bodies), 4, 4) body poses in the world (the offset applied)."""
        return self.offset @ self.body_poses

    def shape_world_poses(self) -> np.ndarray:
        """(T, len(shapes), 4, 4) shape poses in the world."""
        index = {int(b): k for k, b in enumerate(self.bodies)}
        rows = np.array([index[s.body] for s in self.shapes], dtype=int)
        placements = np.array([s.placement for s in self.shapes]).reshape(-1, 4, 4)
        return self.world_poses()[:, rows] @ placements


class Scene:
    """Robots, each at a configuration or along a recorded motion, for meshcat (HTML file or live viewer) and
    for the software renderer (GIF, PNG).

    ``view`` = (azimuth, elevation) in degrees of the camera's direction from the scene's centre (azimuth
    from +x toward +y); ``title`` and ``caption`` are shown over the HTML view and the pictures."""

    def __init__(self, view: tuple[float, float] = (35.0, 25.0), title: str | None = None, caption: str | None = None):
        view_array = float_array(view, "view")
        if view_array.shape != (2,) or not -90 < view_array[1] < 90:
            raise ValueError(f"view: must be (azimuth, elevation) in degrees, elevation in (-90, 90), got {view!r}")
        for name, text in (("title", title), ("caption", caption)):
            if text is not None and not isinstance(text, str):
                raise TypeError(f"{name}: must be a string or None, got {type(text).__name__}")
        self.view = (float(view_array[0]), float(view_array[1]))
        self.title = title
        self.caption = caption
        self.robots: list[RobotTrack] = []
        self.labels: list[tuple[str, np.ndarray]] = []
        self._bounds: tuple[int, np.ndarray, np.ndarray] | None = None  # (robots counted, centres, radii)

    def add_label(self, text: str, position: npt.ArrayLike) -> None:
        """A text drawn in pictures (GIF, PNG) centred under the world point ``position`` (3,)."""
        if not isinstance(text, str):
            raise TypeError(f"text: must be a string, got {type(text).__name__}")
        self.labels.append((text, float_array(position, "position", shape=(3,))))

    def add_robot(
        self, model: lk.Model, q: npt.ArrayLike, times: npt.ArrayLike | None = None, *, name: str | None = None,
        shapes: dict[int | str, Any] | None = None, geometry: Sequence[Shape] | None = None,
        offset: npt.ArrayLike | None = None, color: npt.ArrayLike | None = None, label: str | None = None,
    ) -> RobotTrack:
        """Adds ``model`` at configuration ``q`` (nq,), or along the motion ``q`` (T, nq) sampled at ``times``
        (T,) s. Drawn with ``geometry`` (a list of ``Shape``: e.g. ``visual_shapes``) if given, else the
        simulation's collision shapes (``collision_shapes(model, shapes)``). ``offset`` (a translation or
        4x4 transform) places the robot's world frame in the scene; ``color`` (RGB(A) in [0, 1]) paints
        shapes without a colour of their own; ``label`` names it in pictures."""
        check_model(model)
        q, times = trajectory_arguments(model, q, times)
        if geometry is None:
            geometry = collision_shapes(model, shapes)
        elif shapes is not None:
            raise ValueError("shapes: give either shapes (collision overrides) or geometry, not both")
        geometry = list(geometry)
        if not all(isinstance(s, Shape) for s in geometry):
            raise TypeError("geometry: must be a list of legkit.viewer.Shape")
        if not geometry:
            raise ValueError("geometry: the robot has no shapes to draw")
        name = _node_name(name if name is not None else f"robot{len(self.robots)}")
        if any(r.name == name for r in self.robots):
            raise ValueError(f"name: the scene already has a robot named {name!r}")
        if label is not None and not isinstance(label, str):
            raise TypeError(f"label: must be a string or None, got {type(label).__name__}")
        bodies = np.unique([s.body for s in geometry])
        if bodies.min() < 0 or bodies.max() >= model.nbodies:
            raise ValueError(f"geometry: body indices must be in [0, {model.nbodies})")
        poses = lk.forward_kinematics(model, q)[:, bodies]  # one batched call for the whole motion
        rgba = color_argument(color, "color") if color is not None else PALETTE[len(self.robots) % len(PALETTE)] + (1.0,)
        track = RobotTrack(
            name, list(model.names), geometry, bodies, poses, times,
            np.eye(4) if offset is None else transform_argument(offset, "offset"), rgba, label,
        )
        self.robots.append(track)
        return track

    def add_rigid(
        self, shapes: Sequence[Shape], poses: npt.ArrayLike, times: npt.ArrayLike | None = None, *, name: str,
        color: npt.ArrayLike | None = None, label: str | None = None,
    ) -> RobotTrack:
        """Adds one rigid body (markers: a point, a line) drawn with ``shapes`` (their ``body`` 0), at the world
        pose ``poses`` (4, 4), or along ``poses`` (T, 4, 4) sampled at ``times`` (T,) s."""
        shapes = list(shapes)
        if not shapes or not all(isinstance(s, Shape) and s.body == 0 for s in shapes):
            raise ValueError("shapes: must be a non-empty list of legkit.viewer.Shape on body 0")
        poses = float_array(poses, "poses", min_ndim=2, bound=MAX_COORDINATE)
        if times is None:
            if poses.shape != (4, 4):
                raise ValueError(f"poses: a still body takes one 4x4 pose, got shape {poses.shape}")
            poses = poses[None]
        else:
            times = float_array(times, "times")
            if poses.ndim != 3 or poses.shape[1:] != (4, 4) or times.shape != (poses.shape[0],):
                raise ValueError(f"poses: must have shape (T, 4, 4) with times (T,), got {poses.shape} and {times.shape}")
            if np.any(np.diff(times) <= 0):
                raise ValueError("times: must be strictly increasing")
        name = _node_name(name)
        if any(r.name == name for r in self.robots):
            raise ValueError(f"name: the scene already has a robot named {name!r}")
        rgba = color_argument(color, "color") if color is not None else (0.2, 0.2, 0.2, 1.0)
        track = RobotTrack(name, ["body"], shapes, np.array([0]), poses[:, None].copy(), times, np.eye(4), rgba, label)
        self.robots.append(track)
        return track

    # ------------------------------------------------------------------------------------------ framing

    @property
    def duration(self) -> float:
        """The last sample time over all animated robots (0 if none moves)."""
        return max((float(r.times[-1]) for r in self.robots if r.times is not None), default=0.0)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) corners (3,) of a box holding every shape over the whole motion."""
        if not self.robots:
            raise ValueError("scene: add a robot first")
        centres, radii = self._extent()
        return (centres - radii[:, None]).min(axis=0), (centres + radii[:, None]).max(axis=0)

    def _extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Centres (N, 3) and enclosing radii (N,) of every shape at up to 64 samples of each motion."""
        if self._bounds is not None and self._bounds[0] == len(self.robots):
            return self._bounds[1], self._bounds[2]
        centres, radii = [], []
        for robot in self.robots:
            poses = robot.shape_world_poses()
            poses = poses[np.unique(np.linspace(0, len(poses) - 1, min(len(poses), 64)).round().astype(int))]
            centres.append(poses[..., :3, 3].reshape(-1, 3))
            radii.append(np.tile([s.radius for s in robot.shapes], len(poses)))
        self._bounds = (len(self.robots), np.concatenate(centres), np.concatenate(radii))
        return self._bounds[1], self._bounds[2]

    def grid_step(self) -> float:
        """The ground grid's cell (m): a power of ten, a quarter of the scene's horizontal span or less."""
        low, high = self.bounds()
        span = max(high[0] - low[0], high[1] - low[1], 0.1)
        return float(10 ** math.floor(math.log10(span / 4 * 1.2 + 1e-12)))

    def camera(self, aspect: float = 16 / 9) -> tuple[np.ndarray, np.ndarray]:
        """(target, position) (3,) each, world: the camera looks at the centre of ``bounds`` from the
        direction ``view``, far enough that the bounding sphere fits meshcat's 75-degree vertical field
        of view at the given width / height ``aspect``."""
        low, high = self.bounds()
        centre = 0.5 * (low + high)
        azimuth, elevation = (math.radians(a) for a in self.view)
        direction = np.array([math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
        right = np.array([-math.sin(azimuth), math.cos(azimuth), 0.0])
        up = np.cross(direction, right)
        # The nearest camera that has every shape within 90 % of the picture: a point p (from the centre)
        # projects to focal * (p.right, p.up) / (distance - p.direction); a shape is its enclosing sphere.
        centres, radii = self._extent()
        points = centres - centre
        focal = 1.0 / math.tan(math.radians(FIELD_OF_VIEW / 2))
        along = points @ direction + radii
        need = along + focal / 0.9 * np.maximum((np.abs(points @ right) + radii) / aspect, np.abs(points @ up) + radii)
        distance = max(float(need.max()), float(along.max()) + 1e-2, 1e-2)
        return centre, centre + distance * direction

    # ----------------------------------------------------------------------------------------- meshcat

    def commands(self, max_fps: float = 30.0, loop: bool = True, aspect: float = 16 / 9) -> list[dict[str, Any]]:
        """The scene as meshcat commands (lowered dicts, in order): objects, their transforms, the camera,
        and one animation of every moving robot with keyframes at most ``max_fps`` per second of motion
        (float32), looping if ``loop``."""
        mg = import_meshcat().geometry
        import umsgpack

        if not (isinstance(max_fps, (int, float)) and max_fps > 0):
            raise ValueError(f"max_fps: must be a number > 0, got {max_fps!r}")
        target, position = self.camera(aspect)
        shift = np.eye(4)
        shift[:3, 3] = -target  # meshcat's camera orbits the world origin: the scene is moved to put its centre there
        out: list[dict[str, Any]] = []

        def set_transform(path: str, matrix: np.ndarray) -> None:
            out.append({"type": "set_transform", "path": path, "matrix": _f32(np.asarray(matrix).T, umsgpack)})  # column-major

        def set_object(path: str, geometry: Any, rgba: tuple[float, ...]) -> None:
            material = mg.MeshLambertMaterial(
                color=int(round(rgba[0] * 255)) << 16 | int(round(rgba[1] * 255)) << 8 | int(round(rgba[2] * 255)),
                opacity=float(rgba[3]), transparent=bool(rgba[3] < 1),
            )
            out.append({"type": "set_object", "path": path, "object": mg.Mesh(geometry, material).lower()})

        grid = np.diag([self.grid_step() / 0.5] * 3 + [1.0])  # meshcat's grid: 40 cells of 0.5 m, centred
        grid[2, 3] = -target[2]
        set_transform("/Grid", grid)
        out.append({"type": "set_property", "path": "/Axes", "property": "visible", "value": False})
        set_transform("/legkit", shift)
        for key, value in (("top_color", BACKGROUND_TOP), ("bottom_color", BACKGROUND_BOTTOM)):
            out.append({"type": "set_property", "path": "/Background", "property": key, "value": list(value)})
        rotated = [float(x) for x in (position - target)[[0, 2, 1]] * np.array([1, 1, -1])]  # world -> camera's y-up frame
        out.append({"type": "set_property", "path": "/Cameras/default/rotated/<object>", "property": "position", "value": rotated})
        animations = []
        for robot in self.robots:
            root = f"/legkit/{robot.name}"
            set_transform(root, robot.offset)
            body_path = {int(b): f"{root}/{b}_{_node_name(robot.names[int(b)])}" for b in robot.bodies}
            for k, shape in enumerate(robot.shapes):
                rgba = shape.color if shape.color is not None else robot.color
                path = f"{body_path[shape.body]}/{k}"
                for sub, geometry, local in _meshcat_pieces(shape):
                    set_object(path + sub, geometry, rgba)
                    if not np.array_equal(local, np.eye(4)):
                        set_transform(path + sub, local)
                set_transform(path, shape.placement)
            for j, b in enumerate(robot.bodies):
                set_transform(body_path[int(b)], robot.body_poses[0, j])
            if robot.times is not None and robot.times.size > 1:
                keep = _keyframes(robot.times, max_fps)
                times = robot.times[keep] - robot.times[0]
                poses = robot.body_poses[keep]
                quaternions = _quaternions(poses[..., :3, :3])  # (K, nb, 4) x, y, z, w
                moving = np.any(np.abs(poses - poses[:1]) > 1e-9, axis=(0, 2, 3))
                for j, b in enumerate(robot.bodies):
                    if not moving[j]:
                        continue  # its still pose is set above
                    tracks = [
                        {"name": ".position", "type": "vector3", "times": _f32(times, umsgpack), "values": _f32(poses[:, j, :3, 3], umsgpack)},
                        {"name": ".quaternion", "type": "quaternion", "times": _f32(times, umsgpack), "values": _f32(quaternions[:, j], umsgpack)},
                    ]
                    animations.append({"path": body_path[int(b)], "clip": {"fps": 1, "name": "default", "tracks": tracks}})
        if animations:
            out.append({
                "type": "set_animation", "path": "", "animations": animations,
                "options": {"play": True, "repetitions": math.inf if loop else 1},
            })
        return out

    def html(self, max_fps: float = 30.0, loop: bool = True) -> str:
        """A self-contained HTML page (meshcat's viewer script inlined, no network) showing the scene; see
        ``commands``."""
        meshcat = import_meshcat()
        import umsgpack

        script = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text(encoding="utf-8")
        blobs = [base64.b64encode(umsgpack.packb(c)).decode("ascii") for c in self.commands(max_fps, loop)]
        overlay = ""
        if self.title or self.caption:
            overlay = '<div id="legkit-caption">' + (f"<b>{html.escape(self.title)}</b>" if self.title else "")
            overlay += (("<br>" if self.title else "") + html.escape(self.caption).replace("\n", "<br>")) if self.caption else ""
            overlay += "</div>"
        return _TEMPLATE.format(
            title=html.escape(self.title or "legkit viewer"), script=script.replace("</script", "<\\/script"),
            commands=",\n".join(f'"{b}"' for b in blobs), overlay=overlay,
        )

    def write_html(self, path: str | os.PathLike[str], max_fps: float = 30.0, loop: bool = True) -> Path:
        """Writes ``html()`` to ``path`` (folders created); returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.html(max_fps, loop), encoding="utf-8")
        return path

    # ---------------------------------------------------------------------------------------- pictures

    def write_gif(self, path: str | os.PathLike[str], fps: float = 15.0, size: tuple[int, int] = (640, 360), speed: float = 1.0) -> Path:
        """Renders the motion (matplotlib Agg, the same shapes and camera) to an animated GIF: ``fps``
        frames per second of the GIF, ``speed`` seconds of motion per second of GIF. See ``legkit.viewer.render``."""
        from legkit.viewer._render import write_gif

        return write_gif(self, Path(path), fps=fps, size=size, speed=speed)

    def write_png(self, path: str | os.PathLike[str], time: float = 0.0, size: tuple[int, int] = (640, 360)) -> Path:
        """Renders the scene at ``time`` s (matplotlib Agg) to a PNG."""
        from legkit.viewer._render import write_png

        return write_png(self, Path(path), time=time, size=size)


def _meshcat_pieces(shape: Shape) -> list[tuple[str, Any, np.ndarray]]:
    """(sub-path, meshcat geometry, transform in the shape's frame) of each piece drawing ``shape``:
    meshcat's cylinders run along y, so they are turned onto z; a capsule is a cylinder and two spheres."""
    mg = import_meshcat().geometry
    turn = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # y -> z
    if shape.kind == "box":
        return [("/box", mg.Box(list(shape.size)), np.eye(4))]
    if shape.kind == "sphere":
        return [("/sphere", mg.Sphere(shape.size[0]), np.eye(4))]
    if shape.kind == "cylinder":
        return [("/cylinder", mg.Cylinder(2 * shape.size[0], shape.size[1]), turn)]
    if shape.kind == "capsule":
        half, radius = shape.size
        ends = []
        for sub, z in (("/top", half), ("/bottom", -half)):
            at = np.eye(4)
            at[2, 3] = z
            ends.append((sub, mg.Sphere(radius), at))
        return [("/body", mg.Cylinder(2 * half, radius), turn), *ends]
    if shape.kind == "convex":
        return [("/hull", mg.TriangularMeshGeometry(shape.vertices, shape.hull_faces()), np.eye(4))]
    assert shape.mesh is not None
    suffix = shape.mesh.suffix.lower()
    reader = {".stl": mg.StlMeshGeometry, ".dae": mg.DaeMeshGeometry, ".obj": mg.ObjMeshGeometry}[suffix]
    return [("/mesh", reader.from_file(str(shape.mesh)), np.diag([*shape.size, 1.0]))]


#: The most keyframes an HTML animation takes: nine hours of motion at 30 per second, each a pose per body.
MAX_KEYFRAMES = 1_000_000


def _keyframes(times: np.ndarray, max_fps: float) -> np.ndarray:
    """Indices of the samples nearest to a grid of 1 / max_fps s, first and last kept."""
    span = float(times[-1] - times[0])
    if span * max_fps > MAX_KEYFRAMES:
        raise ValueError(f"max_fps: {span:g} s of motion at {max_fps:g} keyframes per second is more than {MAX_KEYFRAMES} keyframes; "
                         "lower max_fps")
    grid = np.arange(times[0], times[-1], 1.0 / max_fps)
    after = np.clip(np.searchsorted(times, grid), 1, times.size - 1)
    index = np.where(times[after] - grid < grid - times[after - 1], after, after - 1)
    return np.unique(np.concatenate([[0], index, [times.size - 1]]))


def _quaternions(rotations: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3) (Shepperd's method: from the
    largest of w, x, y, z), sign kept continuous along axis 0 (q and -q are the same rotation; interpolating
    between opposite signs would spin the long way round)."""
    r = rotations
    trace = r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2]
    candidates = np.stack([
        np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1], 1 + trace], -1),
        np.stack([1 + 2 * r[..., 0, 0] - trace, r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0], r[..., 2, 1] - r[..., 1, 2]], -1),
        np.stack([r[..., 0, 1] + r[..., 1, 0], 1 + 2 * r[..., 1, 1] - trace, r[..., 1, 2] + r[..., 2, 1], r[..., 0, 2] - r[..., 2, 0]], -1),
        np.stack([r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1], 1 + 2 * r[..., 2, 2] - trace, r[..., 1, 0] - r[..., 0, 1]], -1),
    ], -2)  # each row is 4 q_k times (x, y, z, w) for k = w, x, y, z
    diagonal = np.stack([1 + trace, 1 + 2 * r[..., 0, 0] - trace, 1 + 2 * r[..., 1, 1] - trace, 1 + 2 * r[..., 2, 2] - trace], -1)
    best = np.argmax(diagonal, axis=-1)
    quaternions = np.take_along_axis(candidates, best[..., None, None], axis=-2)[..., 0, :]
    quaternions /= np.linalg.norm(quaternions, axis=-1, keepdims=True)
    if quaternions.ndim >= 2 and quaternions.shape[0] > 1:
        flips = np.sum(quaternions[1:] * quaternions[:-1], axis=-1) < 0
        sign = np.concatenate([np.ones((1, *flips.shape[1:])), np.cumprod(np.where(flips, -1.0, 1.0), axis=0)])
        quaternions = quaternions * sign[..., None]
    return quaternions


def _f32(array: np.ndarray, umsgpack: Any) -> Any:
    """A float32 typed array for meshcat's msgpack decoder (extension 0x17 = Float32Array)."""
    return umsgpack.Ext(0x17, np.ascontiguousarray(array, dtype="<f4").tobytes())


class _Command:
    """A lowered meshcat command, sendable through ``meshcat.Visualizer.window.send``."""

    def __init__(self, data: dict[str, Any]):
        self.data = data

    def lower(self) -> dict[str, Any]:
        return self.data


_TEMPLATE = """<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#legkit-caption {{ position: absolute; left: 10px; top: 8px; color: #222; font: 14px sans-serif;
  text-shadow: 0 0 3px #fff; pointer-events: none; }}
</style></head>
<body>
<div id="meshcat-pane"></div>
{overlay}
<script>
{script}
</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{
  var commands = [
{commands}
  ];
  for (var i = 0; i < commands.length; i++) {{
    var text = atob(commands[i]);
    var bytes = new Uint8Array(text.length);
    for (var j = 0; j < text.length; j++) bytes[j] = text.charCodeAt(j);
    viewer.handle_command_bytearray(bytes);
  }}
}})();
</script>
</body>
</html>
"""


class Viewer:
    """A live meshcat viewer of one model, as Pinocchio's ``MeshcatVisualizer``: ``display(q)`` shows a
    configuration, ``play(times, q)`` a motion, ``url`` is where a browser shows it.

    It starts meshcat's server (a local process) unless ``zmq_url`` names a running one. Geometry: the
    simulation's collision shapes (``shapes`` as ``lk.Simulation`` takes), or with ``urdf`` given the
    URDF's <visual> shapes and meshes (``package_dirs``: where ``package://`` files are looked for)."""

    def __init__(
        self, model: lk.Model, *, shapes: dict[int | str, Any] | None = None, urdf: str | os.PathLike[str] | None = None,
        package_dirs: Iterable[str | os.PathLike[str]] = (), zmq_url: str | None = None, view: tuple[float, float] = (35.0, 25.0),
        color: npt.ArrayLike | None = None,
    ):
        meshcat = import_meshcat()
        check_model(model)
        self.model = model
        self.geometry = visual_shapes(urdf, model, package_dirs) if urdf is not None else collision_shapes(model, shapes)
        self.view = view
        self.color = color
        self.visualizer = meshcat.Visualizer(zmq_url=zmq_url)
        self._scene: Scene | None = None

    @property
    def url(self) -> str:
        """The viewer's address, for a browser."""
        return str(self.visualizer.url())

    def _send(self, scene: Scene, **options: Any) -> None:
        self.visualizer.window.send(_Command({"type": "delete", "path": "/legkit"}))
        for command in scene.commands(**options):
            self.visualizer.window.send(_Command(command))
        self._scene = scene

    def _scene_of(self, q: npt.ArrayLike, times: npt.ArrayLike | None) -> Scene:
        scene = Scene(view=self.view)
        scene.add_robot(self.model, q, times, geometry=self.geometry, name="robot", color=self.color)
        return scene

    def display(self, q: npt.ArrayLike) -> None:
        """Shows the model at configuration ``q`` (nq,)."""
        self._send(self._scene_of(q, None))

    def play(self, times: npt.ArrayLike, q: npt.ArrayLike, max_fps: float = 30.0, loop: bool = False) -> None:
        """Plays the motion ``q`` (T, nq) sampled at ``times`` (T,) s as a meshcat animation."""
        self._send(self._scene_of(q, times), max_fps=max_fps, loop=loop)

    def static_html(self) -> str:
        """The shown scene as a self-contained HTML page."""
        if self._scene is None:
            raise ValueError("viewer: display or play something first")
        return self._scene.html()

    def close(self) -> None:
        """Stops the meshcat server this viewer started."""
        process = getattr(self.visualizer.window, "server_proc", None)
        if process is not None and process.poll() is None:
            process.kill()
            process.wait()
