"""A small software renderer for pictures of a Scene (GIF, PNG): the same shapes and camera as the meshcat view,
tessellated into polygons, projected in perspective, sorted far to near and filled by matplotlib's Agg
backend with Lambert shading. Every frame's geometry is computed for all frames at once in NumPy."""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from legkit._extras import require
from legkit.viewer._geometry import Shape

if TYPE_CHECKING:
    from legkit.viewer._scene import Scene

BACKGROUND = (0.96, 0.97, 0.98)
GROUND = (0.86, 0.87, 0.88)
LIGHT = np.array([0.35, 0.25, 0.9]) / np.linalg.norm([0.35, 0.25, 0.9])


def _sphere_polygons(
    radius: float, z0: float = 0.0, lat: tuple[float, float] = (-math.pi / 2, math.pi / 2), rings: int = 6, segments: int = 12
) -> np.ndarray:
    """Quads (n, 4, 3) of a sphere (or a band of it between latitudes ``lat``) centred at (0, 0, z0), outward."""
    phi = np.linspace(lat[0], lat[1], rings + 1)
    theta = np.linspace(0, 2 * math.pi, segments + 1)
    p0, p1 = phi[:-1, None], phi[1:, None]
    t0, t1 = theta[None, :-1], theta[None, 1:]

    def point(p: np.ndarray, t: np.ndarray) -> np.ndarray:
        p, t = np.broadcast_arrays(p, t)
        return np.stack([radius * np.cos(p) * np.cos(t), radius * np.cos(p) * np.sin(t), z0 + radius * np.sin(p)], axis=-1)

    quads = np.stack([point(p0, t0), point(p0, t1), point(p1, t1), point(p1, t0)], axis=-2)
    return quads.reshape(-1, 4, 3)


def _cylinder_polygons(half: float, radius: float, caps: bool = True, segments: int = 12) -> np.ndarray:
    theta = np.linspace(0, 2 * math.pi, segments + 1)
    c, s = radius * np.cos(theta), radius * np.sin(theta)
    lo = np.stack([c, s, np.full_like(c, -half)], axis=-1)
    hi = np.stack([c, s, np.full_like(c, half)], axis=-1)
    polygons = [np.stack([lo[:-1], lo[1:], hi[1:], hi[:-1]], axis=1)]
    if caps:
        centre_hi = np.broadcast_to([0.0, 0.0, half], (segments, 3))
        centre_lo = np.broadcast_to([0.0, 0.0, -half], (segments, 3))
        polygons.append(np.stack([centre_hi, hi[:-1], hi[1:], hi[1:]], axis=1))
        polygons.append(np.stack([centre_lo, lo[1:], lo[:-1], lo[:-1]], axis=1))
    return np.concatenate(polygons)


def _box_polygons(size: tuple[float, ...]) -> np.ndarray:
    h = 0.5 * np.asarray(size)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * h
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]  # -x +x -y +y -z +z
    return corners[np.array(faces)]


def _stl_polygons(path: Path, scale: tuple[float, ...]) -> np.ndarray:
    """Triangles (as degenerate quads) of an STL file, binary or ASCII."""
    data = path.read_bytes()
    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if count >= 0 and len(data) == 84 + 50 * count:
        records = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), count=count, offset=84)
        triangles = records["v"].astype(float)
    else:
        numbers = [line.split()[1:] for line in data.decode("ascii", "replace").splitlines() if line.strip().startswith("vertex")]
        triangles = np.array(numbers, dtype=float).reshape(-1, 3, 3)
    triangles = triangles * np.asarray(scale)
    return np.concatenate([triangles, triangles[:, 2:3]], axis=1)


def shape_polygons(shape: Shape) -> np.ndarray | None:
    """Polygons (n, 4, 3) in the shape's frame, counter-clockwise seen from outside; None for a mesh format
    the renderer does not read (DAE, OBJ)."""
    if shape.kind == "box":
        return _box_polygons(shape.size)
    if shape.kind == "sphere":
        return _sphere_polygons(shape.size[0])
    if shape.kind == "cylinder":
        half, radius = shape.size
        return _cylinder_polygons(half, radius)
    if shape.kind == "capsule":
        half, radius = shape.size
        return np.concatenate([
            _cylinder_polygons(half, radius, caps=False),
            _sphere_polygons(radius, half, (0.0, math.pi / 2), rings=3),
            _sphere_polygons(radius, -half, (-math.pi / 2, 0.0), rings=3),
        ])
    if shape.kind == "convex":
        assert shape.vertices is not None
        triangles = shape.vertices[shape.hull_faces()]
        return np.concatenate([triangles, triangles[:, 2:3]], axis=1)
    assert shape.mesh is not None
    if shape.mesh.suffix.lower() == ".stl":
        return _stl_polygons(shape.mesh, shape.size)
    return None


#: The most frames a rendered motion takes: at 15 frames per second, 1.85 hours of GIF (each frame is drawn by
#: matplotlib, tens of milliseconds apiece).
MAX_FRAMES = 100_000


def frame_times(scene: Scene, fps: float, speed: float) -> np.ndarray:
    """Motion times of the frames: every 1 / fps s of GIF, ``speed`` s of motion per s; one frame if nothing moves."""
    if not (isinstance(fps, (int, float)) and 0 < fps < math.inf):
        raise ValueError(f"fps: must be a finite number > 0, got {fps!r}")
    if not (isinstance(speed, (int, float)) and 0 < speed < math.inf):
        raise ValueError(f"speed: must be a finite number > 0, got {speed!r}")
    duration = scene.duration
    frames = math.floor(duration * fps / speed + 1e-9) + 1
    if frames > MAX_FRAMES:
        raise ValueError(f"fps: {duration:g} s of motion at {fps:g} frames per second and speed {speed:g} make {frames:g} frames, "
                         f"more than {MAX_FRAMES}: lower fps or raise speed")
    return np.arange(frames) * (speed / fps)


def _size_argument(size: tuple[int, int]) -> tuple[int, int]:
    if not (isinstance(size, (tuple, list)) and len(size) == 2 and all(isinstance(s, int) and 16 <= s <= 8192 for s in size)):
        raise ValueError(f"size: must be (width, height) in pixels, integers in [16, 8192], got {size!r}")
    return int(size[0]), int(size[1])


def render_frames(scene: Scene, times: np.ndarray, size: tuple[int, int] = (640, 360)) -> list[np.ndarray]:
    """RGB frames (height, width, 3) uint8 of ``scene`` at motion ``times`` (each robot holds its sample at
    or before a time, its first sample before it begins)."""
    require("matplotlib", extra="viewer")
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.figure import Figure

    width, height = _size_argument(size)
    times = np.atleast_1d(np.asarray(times, dtype=float))
    aspect = width / height
    target, position = scene.camera(aspect)
    forward = (target - position) / np.linalg.norm(target - position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    focal = 1.0 / math.tan(math.radians(75.0) / 2)  # meshcat's vertical field of view
    near = 1e-2 * float(np.linalg.norm(target - position))

    # Polygons of every shape in world coordinates at every frame: (F, P, 4, 3).
    local, owner, colors = [], [], []
    poses: list[np.ndarray] = []
    skipped = 0
    for robot in scene.robots:
        sample = np.zeros(times.size, dtype=int)
        if robot.times is not None:
            sample = np.clip(np.searchsorted(robot.times, times + 1e-12, side="right") - 1, 0, robot.times.size - 1)
        shape_poses = robot.shape_world_poses()[sample]  # (F, S, 4, 4)
        for k, shape in enumerate(robot.shapes):
            polygons = shape_polygons(shape)
            if polygons is None:
                skipped += 1
                continue
            local.append(polygons)
            owner.append(np.full(len(polygons), len(poses)))
            colors.append(np.broadcast_to((shape.color or robot.color)[:3], (len(polygons), 3)))
            poses.append(shape_poses[:, k])
    if skipped:
        warnings.warn(f"render: {skipped} mesh shape(s) in a format other than STL are not drawn in pictures", stacklevel=3)
    if not local:
        raise ValueError("scene: nothing the renderer can draw")
    polygons = np.concatenate(local)
    owner_index = np.concatenate(owner)
    base_color = np.concatenate(colors)
    pose = np.stack(poses, axis=1)[:, owner_index]  # (F, P, 4, 4)
    world = np.einsum("fpij,pkj->fpki", pose[..., :3, :3], polygons) + pose[:, :, None, :3, 3]
    normal = np.cross(world[:, :, 1] - world[:, :, 0], world[:, :, 2] - world[:, :, 0])
    degenerate = np.linalg.norm(normal, axis=-1) < 1e-15
    normal = np.cross(world[:, :, 2] - world[:, :, 0], world[:, :, 3] - world[:, :, 0]) * degenerate[..., None] + normal * ~degenerate[..., None]
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-300)
    relative = world - position
    depth = relative @ forward  # (F, P, 4)
    screen = np.stack([relative @ right, relative @ up], axis=-1) * (focal / np.maximum(depth, 1e-6))[..., None]
    facing = np.einsum("fpk,fpk->fp", normal, relative.mean(axis=2)) < 0
    shade = 0.5 + 0.5 * np.clip(normal @ LIGHT, 0.0, 1.0)
    order = np.argsort(-depth.mean(axis=2), axis=1, kind="stable")

    # The ground: a grid on z = 0 under the scene.
    low, high = scene.bounds()
    step = scene.grid_step()
    span = 10 * step
    centre = 0.5 * (low + high)
    xs = np.arange(math.floor((centre[0] - span) / step), math.ceil((centre[0] + span) / step) + 1) * step
    ys = np.arange(math.floor((centre[1] - span) / step), math.ceil((centre[1] + span) / step) + 1) * step

    def project(points: np.ndarray) -> np.ndarray:
        relative_points = points - position
        d = np.maximum(relative_points @ forward, near)
        return np.stack([relative_points @ right, relative_points @ up], axis=-1) * (focal / d)[..., None]

    def clip(polygon: np.ndarray) -> np.ndarray:
        """The part of a planar polygon (n, 3) in front of the near plane (Sutherland-Hodgman, one plane)."""
        kept = []
        d = (polygon - position) @ forward - near
        for i in range(len(polygon)):
            a, b, da, db = polygon[i], polygon[(i + 1) % len(polygon)], d[i], d[(i + 1) % len(polygon)]
            if da >= 0:
                kept.append(a)
            if (da >= 0) != (db >= 0):
                kept.append(a + (b - a) * (da / (da - db)))
        return np.array(kept).reshape(-1, 3)

    segments = [np.array([(x, ys[0], 0.0), (x, ys[-1], 0.0)]) for x in xs] + [np.array([(xs[0], y, 0.0), (xs[-1], y, 0.0)]) for y in ys]
    segments = [project(c) for c in (clip(seg) for seg in segments) if len(c) >= 2]
    ground = clip(np.array([[xs[0], ys[0], 0.0], [xs[-1], ys[0], 0.0], [xs[-1], ys[-1], 0.0], [xs[0], ys[-1], 0.0]]))

    figure = Figure(figsize=(width / 100, height / 100), dpi=100, facecolor=BACKGROUND)
    canvas = FigureCanvasAgg(figure)
    axes = figure.add_axes((0, 0, 1, 1))
    axes.set_xlim(-aspect, aspect)
    axes.set_ylim(-1, 1)
    axes.set_axis_off()
    if len(ground) >= 3:
        axes.add_collection(PolyCollection([project(ground)], facecolors=[GROUND], edgecolors="none", zorder=0))
    axes.add_collection(LineCollection([seg[:2] for seg in segments], colors=[(0.7, 0.72, 0.74)], linewidths=0.6, zorder=1))
    solids = PolyCollection([], edgecolors="none", antialiaseds=False, zorder=2)
    axes.add_collection(solids)
    labels = [(robot.label, robot.offset[:3, 3]) for robot in scene.robots if robot.label] + list(scene.labels)
    for label, anchor in labels:
        if (anchor - position) @ forward > near:
            x, y = project(np.asarray(anchor, dtype=float))
            axes.text(x, y - 0.03, label, ha="center", va="top", fontsize=9, color="0.2", zorder=3)
    text = axes.text(-aspect + 0.03, -0.97, "", fontsize=9, color="0.2", va="bottom", zorder=4)
    if scene.title:
        axes.text(-aspect + 0.03, 0.97, scene.title, fontsize=10, color="0.1", va="top", weight="bold", zorder=4)
    if scene.caption:
        axes.text(-aspect + 0.03, 0.90, scene.caption, fontsize=8, color="0.25", va="top", zorder=4)
    # The ground, grid and texts are drawn once; each frame restores them and draws the solids and the time.
    solids.set_animated(True)
    text.set_animated(True)
    canvas.draw()
    still = canvas.copy_from_bbox(figure.bbox)
    frames = []
    for f in range(times.size):
        keep = order[f][facing[f][order[f]] & np.all(depth[f][order[f]] > near, axis=1)]
        solids.set_verts(screen[f, keep])
        solids.set_facecolor(np.clip(base_color[keep] * shade[f, keep, None], 0, 1))
        text.set_text(f"t = {times[f]:.2f} s" if scene.duration > 0 else "")
        canvas.restore_region(still)
        axes.draw_artist(solids)
        axes.draw_artist(text)
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return frames


def write_gif(scene: Scene, path: Path, fps: float = 15.0, size: tuple[int, int] = (640, 360), speed: float = 1.0) -> Path:
    """An animated GIF of the scene's motion (looping), one shared palette so colours do not flicker."""
    require("PIL")
    from PIL import Image

    times = frame_times(scene, fps, speed)
    frames = render_frames(scene, times, size)
    first = Image.fromarray(frames[0]).quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    images = [first] + [Image.fromarray(f).quantize(palette=first, dither=Image.Dither.NONE) for f in frames[1:]]
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0, optimize=False)
    return path


def write_png(scene: Scene, path: Path, time: float = 0.0, size: tuple[int, int] = (640, 360)) -> Path:
    """A PNG of the scene at motion ``time`` s."""
    require("PIL")
    from PIL import Image

    if not (isinstance(time, (int, float)) and math.isfinite(time)):
        raise ValueError(f"time: must be a finite number, got {time!r}")
    frame = render_frames(scene, np.array([float(time)]), size)[0]
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(frame).save(path)
    return path
