"""legkit.viewer: see a model, a recorded motion or an experiment's runs in meshcat, as Pinocchio and Drake
users do; write a self-contained HTML file (opens offline) or a GIF.

    import legkit as lk
    from legkit import viewer
    viewer.write_html(model, q, "robot.html")                     # a configuration
    viewer.write_animation(model, times, qs, "motion.html", gif_path="motion.gif")   # a motion (T, nq)
    v = viewer.Viewer(model); v.display(q); v.play(times, qs); print(v.url)          # live, in a browser

What is drawn: by default the shapes the simulation collides with (``Model.colliders``: the ``shapes``
overrides ``lk.Simulation`` takes, the URDF's <collision> shapes, else the box of each body's inertia);
or a URDF's <visual> shapes and meshes (``visual_shapes``; ``package://`` resolved against the URDF's
folder, its ancestors and ``package_dirs``). Several robots side by side: ``Scene``.

meshcat is imported only when HTML is written or a viewer starts (``import legkit`` stays fast).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy.typing as npt

import legkit as lk
from legkit.viewer._geometry import (
    Shape,
    collision_shapes,
    resolve_mesh,
    shape_poses,
    visual_shapes,
)
from legkit.viewer._scene import RobotTrack, Scene, Viewer

__all__ = [
    "Shape",
    "Scene",
    "RobotTrack",
    "Viewer",
    "collision_shapes",
    "visual_shapes",
    "shape_poses",
    "resolve_mesh",
    "write_html",
    "write_animation",
]


def _single_robot_scene(
    model: lk.Model, q: npt.ArrayLike, times: npt.ArrayLike | None, shapes: dict[int | str, Any] | None,
    urdf: str | os.PathLike[str] | None, package_dirs: Iterable[str | os.PathLike[str]], title: str | None,
) -> Scene:
    scene = Scene(title=title)
    geometry = visual_shapes(urdf, model, package_dirs) if urdf is not None else None
    scene.add_robot(model, q, times, shapes=shapes, geometry=geometry, name="robot")
    return scene


def write_html(
    model: lk.Model, q: npt.ArrayLike, html_path: str | os.PathLike[str], *, shapes: dict[int | str, Any] | None = None,
    urdf: str | os.PathLike[str] | None = None, package_dirs: Iterable[str | os.PathLike[str]] = (), title: str | None = None,
) -> Path:
    """A self-contained HTML file showing ``model`` at configuration ``q`` (nq,): its collision shapes (with
    ``shapes`` as ``lk.Simulation`` takes), or the <visual> geometry of ``urdf``. Returns the path."""
    return _single_robot_scene(model, q, None, shapes, urdf, package_dirs, title).write_html(html_path)


def write_animation(
    model: lk.Model, times: npt.ArrayLike, q: npt.ArrayLike, html_path: str | os.PathLike[str] | None,
    gif_path: str | os.PathLike[str] | None = None, *, shapes: dict[int | str, Any] | None = None,
    urdf: str | os.PathLike[str] | None = None, package_dirs: Iterable[str | os.PathLike[str]] = (),
    title: str | None = None, max_fps: float = 30.0, gif_fps: float = 15.0, gif_size: tuple[int, int] = (640, 360),
) -> Scene:
    """The motion ``q`` (T, nq) sampled at ``times`` (T,) s as a meshcat animation in a self-contained HTML
    file (``html_path``; keyframes at most ``max_fps`` per second) and, if ``gif_path`` is given, as a GIF
    rendered by matplotlib (``gif_fps``, ``gif_size`` pixels; primitives and STL meshes). Returns the
    ``Scene``, to write more from."""
    scene = _single_robot_scene(model, q, times, shapes, urdf, package_dirs, title)
    if html_path is not None:
        scene.write_html(html_path, max_fps=max_fps, loop=True)
    if gif_path is not None:
        scene.write_gif(gif_path, fps=gif_fps, size=gif_size)
    return scene
