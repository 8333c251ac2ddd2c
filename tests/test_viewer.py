"""legkit.viewer: the shapes' poses against a brute-force kinematic chain, the meshcat scene graph and animation
they become, URDF <visual> parsing and package:// resolution, bad input, the GIF, and the HTML rendered by
headless Chromium showing the robot where it projects."""

from __future__ import annotations

import importlib.metadata
import math
import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
import umsgpack
from PIL import Image

import legkit as lk
from legkit import viewer
from legkit.viewer import Scene, Shape
from legkit.viewer._render import render_frames

ROBOTS = Path(str(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots")))
SOLO = ROBOTS / "solo_description" / "robots" / "solo12.urdf"


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def transform(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = r, t
    return out


def random_transform(rng: np.random.Generator) -> np.ndarray:
    return transform(rotation(rng.normal(size=3), rng.uniform(-math.pi, math.pi)), rng.normal(scale=0.2, size=3))


def chain(rng: np.random.Generator) -> tuple[lk.Model, list[tuple[int, np.ndarray, np.ndarray]]]:
    """A fixed-base tree of four revolute bodies (one a branch) at random placements and axes, with its
    definition (parent, placement, axis) for the brute-force reference."""
    model = lk.Model(floating_base=False)
    joints = []
    for body, parent in enumerate([0, 1, 2, 1], start=1):
        placement, axis = random_transform(rng), rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        model.add_revolute(parent, axis, placement, lk.MassProperties.solid_box(1.0, [0.1, 0.2, 0.3]), f"b{body}")
        joints.append((parent, placement, axis))
    return model, joints


def brute_force_body_pose(joints: list[tuple[int, np.ndarray, np.ndarray]], q: np.ndarray, body: int) -> np.ndarray:
    """World pose of ``body``: the product, root to body, of each joint's placement and rotation about its axis."""
    if body == 0:
        return np.eye(4)
    parent, placement, axis = joints[body - 1]
    return brute_force_body_pose(joints, q, parent) @ placement @ transform(rotation(axis, q[body - 1]), np.zeros(3))


def random_shapes(rng: np.random.Generator, nbodies: int) -> list[Shape]:
    sizes = {"box": lambda: tuple(rng.uniform(0.05, 0.2, 3)), "sphere": lambda: (rng.uniform(0.02, 0.1),),
             "capsule": lambda: tuple(rng.uniform(0.02, 0.1, 2)), "cylinder": lambda: tuple(rng.uniform(0.02, 0.1, 2))}
    return [Shape(int(rng.integers(0, nbodies)), kind, sizes[kind](), random_transform(rng))
            for kind in ("box", "sphere", "capsule", "cylinder") for _ in range(2)]


def test_shape_poses_are_the_body_chain_times_the_placement():
    rng = np.random.default_rng(1)
    model, joints = chain(rng)
    shapes = random_shapes(rng, model.nbodies)
    q = rng.uniform(-3, 3, size=(2, 3, model.nq))  # batched over leading dimensions
    poses = viewer.shape_poses(model, q, shapes)
    assert poses.shape == (2, 3, len(shapes), 4, 4)
    for index in np.ndindex(2, 3):
        for k, shape in enumerate(shapes):
            expected = brute_force_body_pose(joints, q[index], shape.body) @ shape.placement
            np.testing.assert_allclose(poses[index][k], expected, atol=1e-12)


def decode(commands: list[dict]) -> tuple[dict[str, np.ndarray], list[dict]]:
    """The transforms meshcat would hold (path -> 4x4, the last one set) and the animations."""
    transforms, animations = {}, []
    for command in commands:
        command = umsgpack.unpackb(umsgpack.packb(command))  # as the page receives it
        if command["type"] == "set_transform":
            matrix = command["matrix"]
            values = np.frombuffer(matrix.data, dtype="<f4") if isinstance(matrix, umsgpack.Ext) else np.asarray(matrix)
            transforms[command["path"]] = values.astype(float).reshape(4, 4).T  # column-major
        elif command["type"] == "set_animation":
            animations += command["animations"]
    return transforms, animations


def world_of(transforms: dict[str, np.ndarray], path: str) -> np.ndarray:
    """The composed transform of a meshcat path: every prefix's transform, root first."""
    parts = path.strip("/").split("/")
    pose = np.eye(4)
    for n in range(1, len(parts) + 1):
        pose = pose @ transforms.get("/" + "/".join(parts[:n]), np.eye(4))
    return pose


def test_meshcat_scene_graph_puts_every_piece_on_its_shape():
    """Composing the meshcat transforms down each path gives the shape's world pose from the brute-force
    chain (the scene is shifted so that the camera's orbit centre is the origin); a cylinder's and a
    capsule's meshcat axis (y) is the shape's z axis; each piece has the shape's size."""
    rng = np.random.default_rng(2)
    model, joints = chain(rng)
    shapes = random_shapes(rng, model.nbodies)
    q = rng.uniform(-2, 2, model.nq)
    offset = np.array([0.5, -0.25, 0.1])
    scene = Scene()
    scene.add_robot(model, q, geometry=shapes, offset=offset, name="chain")
    commands = scene.commands()
    transforms, animations = decode(commands)
    assert animations == []
    shift = transforms["/legkit"]
    np.testing.assert_allclose(shift[:3, :3], np.eye(3))
    objects = {c["path"]: c["object"] for c in commands if c["type"] == "set_object"}
    for k, shape in enumerate(shapes):
        expected = transform(np.eye(3), offset) @ brute_force_body_pose(joints, q, shape.body) @ shape.placement
        pieces = [p for p in objects if p.startswith(f"/legkit/chain/{shape.body}_b{shape.body}/{k}/")] if shape.body else \
            [p for p in objects if p.startswith(f"/legkit/chain/0_{model.names[0]}/{k}/")]
        assert len(pieces) == (3 if shape.kind == "capsule" else 1), (shape.kind, pieces)
        for path in pieces:
            world = np.linalg.inv(shift) @ world_of(transforms, path)
            geometry = objects[path]["geometries"][0]
            if geometry["type"] == "CylinderGeometry":
                np.testing.assert_allclose(world[:3, 3], expected[:3, 3], atol=1e-6)
                np.testing.assert_allclose(world[:3, 1], expected[:3, 2], atol=1e-6)  # meshcat's y = the shape's z
                assert geometry["height"] == pytest.approx(2 * shape.size[0]) and geometry["radiusTop"] == pytest.approx(shape.size[1])
            elif geometry["type"] == "SphereGeometry" and shape.kind == "capsule":
                end = expected[:3, 3] + np.array([-1, 1])[:, None] * shape.size[0] * expected[:3, 2]
                assert min(np.linalg.norm(world[:3, 3] - e) for e in end) < 1e-6
                assert geometry["radius"] == pytest.approx(shape.size[1])
            else:
                np.testing.assert_allclose(world, expected, atol=1e-6)
                if shape.kind == "box":
                    assert [geometry["width"], geometry["height"], geometry["depth"]] == pytest.approx(list(shape.size))
                else:
                    assert geometry["radius"] == pytest.approx(shape.size[0])


def test_animation_keyframes_follow_the_motion():
    """Each moving body gets position and quaternion tracks (float32) whose keyframes are the body's pose
    from forward kinematics at the kept samples, at most max_fps per second, first and last kept."""
    rng = np.random.default_rng(3)
    model, joints = chain(rng)
    times = np.arange(101) * 0.01
    q = np.sin(np.outer(times, [1.0, 2.0, 3.0, 4.0]))
    scene = Scene()
    scene.add_robot(model, q, times, geometry=[Shape(b, "box", (0.1, 0.1, 0.1)) for b in range(1, model.nbodies)], name="m")
    _, animations = decode(scene.commands(max_fps=20))
    assert len(animations) == 4
    for animation in animations:
        body = int(animation["path"].split("/")[-1].split("_")[0])
        tracks = {t["name"]: t for t in animation["clip"]["tracks"]}
        key_times = np.frombuffer(tracks[".position"]["times"].data, dtype="<f4")
        assert key_times[0] == 0 and key_times[-1] == pytest.approx(1.0) and 20 <= len(key_times) <= 22
        np.testing.assert_allclose(np.diff(key_times), 0.05, atol=1e-6)  # samples nearest to a 20 per second grid
        positions = np.frombuffer(tracks[".position"]["values"].data, dtype="<f4").reshape(-1, 3)
        quaternions = np.frombuffer(tracks[".quaternion"]["values"].data, dtype="<f4").reshape(-1, 4)
        for t, p, quat in zip(key_times, positions, quaternions):
            sample = int(round(t / 0.01))
            expected = brute_force_body_pose(joints, q[sample], body)
            np.testing.assert_allclose(p, expected[:3, 3], atol=1e-5)
            x, y, z, w = quat
            r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                          [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                          [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            np.testing.assert_allclose(r, expected[:3, :3], atol=1e-5)
        assert np.all(np.sum(quaternions[1:] * quaternions[:-1], axis=1) > 0)  # no sign flips between keys


def test_collision_shapes_are_the_models_colliders():
    """By default the viewer draws what the simulation collides with: Go1's URDF spheres and boxes, a
    built model's inertia boxes, and lk.Simulation's overrides (a sphere instead, None for nothing)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)  # Go1's inertias are non-physical by round-off
        go1 = lk.Model.from_urdf(ROBOTS / "go1_description" / "urdf" / "go1.urdf")
    rng = np.random.default_rng(4)
    chain_model, _ = chain(rng)
    assert {kind for _, kind, _, _ in go1.colliders()} >= {"sphere", "box"}
    for m in (chain_model, go1):
        shapes = viewer.collision_shapes(m)
        colliders = m.colliders()
        assert len(shapes) == len(colliders) > 0
        for shape, (body, kind, size, placement) in zip(shapes, colliders):
            assert (shape.body, shape.kind) == (body, kind)
            np.testing.assert_allclose(shape.size, size)
            np.testing.assert_allclose(shape.placement, placement)
    overridden = viewer.collision_shapes(chain_model, shapes={"b2": ("sphere", 0.07), 3: None})
    assert [s.size for s in overridden if s.body == 2] == [(0.07,)]
    assert not [s for s in overridden if s.body == 3]


def test_visual_shapes_of_solo12_resolve_package_paths(tmp_path):
    model = lk.Model.from_urdf(SOLO)
    shapes = viewer.visual_shapes(SOLO, model)
    assert len(shapes) == SOLO.read_text().count("<visual>")
    assert all(s.kind == "mesh" and s.mesh is not None and s.mesh.is_file() and s.mesh.suffix == ".stl" for s in shapes)
    assert {model.names[s.body] for s in shapes} == set(model.names)
    # The same URDF elsewhere: its package is found only through package_dirs.
    copy = tmp_path / "solo12.urdf"
    shutil.copy(SOLO, copy)
    with pytest.raises(FileNotFoundError, match="package_dirs"):
        viewer.visual_shapes(copy, model)
    found = viewer.visual_shapes(copy, model, package_dirs=[ROBOTS.parent.parent])
    assert [s.mesh for s in found] == [s.mesh for s in shapes]
    assert viewer.resolve_mesh("package://solo_description/meshes/cube.obj", copy, [ROBOTS]) == ROBOTS / "solo_description" / "meshes" / "cube.obj"


def test_visual_primitives_origins_and_colours(tmp_path):
    urdf = tmp_path / "two.urdf"
    urdf.write_text("""<robot name="two">
  <material name="red"><color rgba="1 0 0 1"/></material>
  <link name="base"><visual><origin xyz="0 0 0.1" rpy="0 0 1.5707963267948966"/><geometry><box size="0.1 0.2 0.3"/></geometry>
    <material name="red"/></visual></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/><origin xyz="0 0 0.3"/>
    <limit effort="1" velocity="1" lower="-1" upper="1"/></joint>
  <link name="arm"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 0.2" rpy="1.5707963267948966 0 0"/><geometry><cylinder length="0.4" radius="0.02"/></geometry>
    <material name="blue"><color rgba="0 0 1 0.5"/></material></visual>
    <visual><geometry><sphere radius="0.05"/></geometry></visual></link>
</robot>""")
    model = lk.Model.from_urdf(urdf)
    box, cylinder, sphere = viewer.visual_shapes(urdf, model)
    assert (box.kind, box.size, box.color, model.names[box.body]) == ("box", (0.1, 0.2, 0.3), (1, 0, 0, 1), "base")
    np.testing.assert_allclose(box.placement, transform(rotation([0, 0, 1], math.pi / 2), [0, 0, 0.1]), atol=1e-12)
    assert (cylinder.kind, cylinder.size, cylinder.color) == ("cylinder", (0.2, 0.02), (0, 0, 1, 0.5))
    np.testing.assert_allclose(cylinder.placement, transform(rotation([1, 0, 0], math.pi / 2), [0, 0, 0.2]), atol=1e-12)
    assert (sphere.kind, sphere.size, sphere.color) == ("sphere", (0.05,), None)


def test_bad_input_names_the_argument(tmp_path):
    rng = np.random.default_rng(5)
    model, _ = chain(rng)
    scene = Scene()
    with pytest.raises(TypeError, match="model"):
        scene.add_robot("robot", np.zeros(4))
    with pytest.raises(ValueError, match="q"):
        scene.add_robot(model, np.zeros(3))
    with pytest.raises(ValueError, match="times"):
        scene.add_robot(model, np.zeros((5, 4)))
    with pytest.raises(ValueError, match="times"):
        scene.add_robot(model, np.zeros((5, 4)), times=np.arange(4.0))
    with pytest.raises(ValueError, match="times"):
        scene.add_robot(model, np.zeros((3, 4)), times=[0.0, 0.2, 0.1])
    with pytest.raises(ValueError, match="q"):
        scene.add_robot(model, np.full(4, np.nan))
    with pytest.raises(ValueError, match="color"):
        scene.add_robot(model, np.zeros(4), color=(2.0, 0, 0))
    with pytest.raises(ValueError, match="offset"):
        scene.add_robot(model, np.zeros(4), offset=(1.0, 2.0))
    with pytest.raises(ValueError, match="shapes"):
        scene.add_robot(model, np.zeros(4), shapes={1: ("sphere", 0.1)}, geometry=[Shape(1, "sphere", (0.1,))])
    with pytest.raises(TypeError, match="geometry"):
        scene.add_robot(model, np.zeros(4), geometry=[("sphere", 0.1)])
    with pytest.raises(ValueError, match="geometry"):
        scene.add_robot(model, np.zeros(4), geometry=[Shape(9, "sphere", (0.1,))])
    with pytest.raises(TypeError, match="shapes"):
        viewer.collision_shapes(model, shapes=[("sphere", 0.1)])
    with pytest.raises(ValueError, match="kind"):
        Shape(0, "cone", (0.1,))
    with pytest.raises(ValueError, match="size"):
        Shape(0, "box", (0.1, -0.1, 0.1))
    with pytest.raises(ValueError, match="placement"):
        Shape(0, "box", (0.1, 0.1, 0.1), np.eye(3))
    with pytest.raises(ValueError, match="convex shape needs its vertices"):
        Shape(0, "convex", ())
    with pytest.raises(ValueError, match="view"):
        Scene(view=(0.0, 90.0))
    with pytest.raises(ValueError, match="scene"):
        Scene().html()
    scene.add_robot(model, np.zeros(4), name="a")
    with pytest.raises(ValueError, match="name"):
        scene.add_robot(model, np.zeros(4), name="a")
    with pytest.raises(ValueError, match="max_fps"):
        scene.commands(max_fps=0)
    with pytest.raises(ValueError, match="fps"):
        scene.write_gif(tmp_path / "a.gif", fps=-1)
    with pytest.raises(ValueError, match="size"):
        scene.write_png(tmp_path / "a.png", size=(10.5, 20))
    with pytest.raises(FileNotFoundError, match="urdf"):
        viewer.visual_shapes(tmp_path / "missing.urdf", model)


def test_sizes_beyond_what_the_viewer_can_draw_are_refused_by_name(tmp_path):
    # Each of these ran out of memory (a keyframe grid or GIF frames over 1e12 s) or drew inf (float32 poses).
    rng = np.random.default_rng(5)
    model, _ = chain(rng)
    with pytest.raises(ValueError, match=r"q must lie within \+-1e\+30"):
        Scene().add_robot(model, np.full(4, 1e200))
    with pytest.raises(ValueError, match=r"poses must lie within"):
        Scene().add_rigid([Shape(0, "sphere", (0.1,))], np.full((4, 4), 1e40), name="marker")
    long = Scene()
    long.add_robot(model, np.zeros((2, 4)), times=[0.0, 1e12])
    with pytest.raises(ValueError, match=r"max_fps: 1e\+12 s of motion at 30 keyframes per second is more than 1000000"):
        long.commands()
    with pytest.raises(ValueError, match=r"fps: 1e\+12 s of motion at 15 frames per second and speed 1 make 1\.5e\+13 frames"):
        long.write_gif(tmp_path / "long.gif")
    with pytest.raises(ValueError, match="fps: must be a finite number"):
        long.write_gif(tmp_path / "long.gif", fps=math.inf)
    long.write_gif(tmp_path / "fast.gif", fps=1, speed=1e11, size=(32, 32))  # 11 frames: drawn
    assert (tmp_path / "fast.gif").stat().st_size > 0


def test_write_animation_html_is_self_contained_and_gif_moves(tmp_path):
    rng = np.random.default_rng(6)
    model, _ = chain(rng)
    times = np.linspace(0.0, 1.0, 51)
    q = np.outer(np.sin(2 * math.pi * times), [1.0, -1.0, 0.5, 2.0])
    scene = viewer.write_animation(model, times, q, tmp_path / "m.html", tmp_path / "m.gif", title="chain <&>", gif_fps=10, gif_size=(160, 90))
    page = (tmp_path / "m.html").read_text()
    assert "<script src" not in page and "http://" not in page.split("<script>")[0] and "chain &lt;&amp;&gt;" in page
    assert "MeshCat.Viewer" in page and page.count('"') > 10
    gif = Image.open(tmp_path / "m.gif")
    assert gif.n_frames == 11 and gif.size == (160, 90)
    frames = render_frames(scene, np.array([0.0, 0.25]), (160, 90))
    assert np.abs(frames[0].astype(int) - frames[1].astype(int)).sum() > 0  # the motion shows


def test_live_viewer_sends_the_scene_to_meshcat_server():
    """Viewer starts meshcat's server (a local process), and display/play reach it: the server's own static
    page holds one drawing command per object, transform and the animation."""
    rng = np.random.default_rng(7)
    model, _ = chain(rng)
    shapes = [Shape(b, "box", (0.1, 0.1, 0.1)) for b in range(1, model.nbodies)]
    live = viewer.Viewer(model, shapes={b: ("box", (0.1, 0.1, 0.1)) for b in range(1, model.nbodies)})
    try:
        assert live.url.startswith("http://127.0.0.1:")
        with pytest.raises(ValueError, match="display"):
            live.static_html()
        live.display(np.zeros(model.nq))
        assert len(live.geometry) == len(shapes)
        page = live.visualizer.static_html()
        assert page.count("data:application/octet-binary;base64") >= 2 * len(shapes)
        live.play(np.linspace(0, 1, 11), np.zeros((11, model.nq)) + np.linspace(0, 1, 11)[:, None])
        assert len(live.visualizer.static_html()) > len(page)
        assert "MeshCat.Viewer" in live.static_html()
    finally:
        live.close()


def chromium_screenshot(page: Path, picture: Path, size: tuple[int, int]) -> np.ndarray:
    chromium = shutil.which("chromium")
    assert chromium, "chromium (Debian package) is needed: scripts/test.sh installs it"
    subprocess.run(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
         "--hide-scrollbars", f"--window-size={size[0]},{size[1]}", "--virtual-time-budget=3000",
         f"--screenshot={picture}", page.as_uri()],
        check=True, capture_output=True, timeout=120,
    )
    return np.asarray(Image.open(picture).convert("RGB")).astype(int)


@pytest.mark.slow
@pytest.mark.browser
def test_chromium_shows_the_robot_where_it_projects(tmp_path):
    """Solo-12 (its collision shapes) exported to HTML and rendered by headless Chromium (WebGL on
    SwiftShader), against the same page with the robot hidden: the pixels differ where the software
    renderer, with the same camera, projects the robot, and hardly anywhere else."""
    model = lk.Model.from_urdf(SOLO)
    q = model.neutral()
    q[2] = 0.3
    scene = Scene(view=(30.0, 20.0))
    scene.add_robot(model, q, name="solo", color=(0.8, 0.3, 0.1))
    size = (480, 270)
    page = scene.write_html(tmp_path / "solo.html")
    hidden = tmp_path / "hidden.html"
    hidden.write_text(page.read_text().replace("</body>", '<script>viewer.set_property(["legkit"], "visible", false);</script>\n</body>'))
    shown = chromium_screenshot(page, tmp_path / "shown.png", size)
    empty = chromium_screenshot(hidden, tmp_path / "hidden.png", size)
    assert shown.shape == (size[1], size[0], 3)
    differs = np.abs(shown - empty).sum(axis=2) > 30
    # Where the robot projects: the software render against its own background.
    render = render_frames(scene, np.array([0.0]), size)[0].astype(int)
    robot = (render[..., 0] - render[..., 2] > 60) & (render[..., 0] - render[..., 1] > 30)  # its orange, shaded
    assert robot.mean() > 0.01, "the software render shows the robot"
    assert differs[robot].mean() > 0.8, "Chromium draws the robot where it projects"
    assert differs[~dilate(robot, 6)].mean() < 0.02, "and little elsewhere"


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    out = mask.copy()
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            out |= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
    return out
