"""Model.colliders: what a Simulation collides with, as the viewer and users see it."""

import numpy as np
import pytest

import legkit as lk

URDF = """<robot name="r">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.5" rpy="0 0 0"/><geometry><sphere radius="0.1"/></geometry></collision>
    <collision><origin xyz="0.2 0 0" rpy="0 1.5707963267948966 0"/><geometry><cylinder radius="0.05" length="0.4"/></geometry></collision>
  </link>
</robot>"""


def test_default_boxes_have_the_bodys_inertia():
    # A uniform box's inertia gives back its edges, centred on its COM, with the body's axes.
    model = lk.Model()
    model.add_revolute(0, [0, 0, 1], body=lk.MassProperties.solid_box(2.0, [0.1, 0.2, 0.3], center=[0.0, 0.0, 0.4]))
    [(body, kind, size, placement)] = model.colliders()
    assert (body, kind) == (1, "box")
    np.testing.assert_allclose(size, [0.1, 0.2, 0.3], rtol=1e-12)
    expected = np.eye(4)
    expected[:3, 3] = [0.0, 0.0, 0.4]
    np.testing.assert_allclose(placement, expected, atol=1e-15)


def test_urdf_collisions_and_overrides():
    model = lk.Model.from_urdf(URDF)
    (b0, k0, s0, p0), (b1, k1, s1, p1) = model.colliders()
    assert (b0, k0, b1, k1) == (0, "sphere", 0, "cylinder")
    assert s0 == (0.1,) and s1 == pytest.approx((0.2, 0.05))
    np.testing.assert_allclose(p0[:3, 3], [0.0, 0.0, 0.5])
    # The cylinder's axis (z of its frame) lies along the body's x after the 90 deg pitch.
    np.testing.assert_allclose(p1[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)
    assert model.colliders({"base": ("box", (0.1, 0.1, 0.1))})[0][1] == "box"
    assert model.colliders({0: None}) == []


def test_bad_overrides_name_the_argument():
    model = lk.Model.from_urdf(URDF)
    with pytest.raises(IndexError, match="shapes"):
        model.colliders({3: ("sphere", 0.1)})
    with pytest.raises(ValueError, match="shapes"):
        model.colliders({0: ("cone", 0.1)})


def test_convex_shapes_keep_their_hull_and_urdf_meshes_resolve_through_package_dirs(tmp_path):
    corners = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.05, 0.05) for z in (0.0, 0.2)])
    points = np.vstack([corners, [[0.0, 0.0, 0.1]]])  # an interior point is no hull vertex
    model = lk.Model()
    model.add_revolute(0, [0, 0, 1], body=lk.MassProperties.solid_box(1.0, [0.2, 0.1, 0.2]))
    [(_, kind, vertices, _)] = model.colliders({1: ("convex", points)})
    assert kind == "convex"
    assert sorted(map(tuple, np.round(vertices, 12))) == sorted(map(tuple, corners))
    with pytest.raises(ValueError, match="no volume"):
        model.colliders({1: ("convex", corners[:4])})
    # A mesh named by package, in a folder only package_dirs knows.
    (tmp_path / "parts" / "meshes").mkdir(parents=True)
    (tmp_path / "parts" / "meshes" / "block.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in points))
    urdf = URDF.replace('<sphere radius="0.1"/>', '<mesh filename="package://parts/meshes/block.obj" scale="2 2 2"/>')
    with pytest.warns(lk.UrdfWarning, match="block.obj"):
        unresolved = lk.Model.from_urdf(urdf)
    assert [c[1] for c in unresolved.colliders()] == ["cylinder", "box"]  # not found: the link's inertia box
    resolved = lk.Model.from_urdf(urdf, package_dirs=[tmp_path])
    kind, vertices = resolved.colliders()[0][1:3]
    assert kind == "convex"
    assert sorted(map(tuple, np.round(vertices, 12))) == sorted(map(tuple, np.round(2 * corners, 12)))


def test_resolve_mesh_finds_package_files_as_the_urdf_loader_does(tmp_path):
    mesh = tmp_path / "robots" / "bot_description" / "meshes" / "leg.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_text("solid\nendsolid\n")
    urdf = tmp_path / "robots" / "bot_description" / "urdf" / "bot.urdf"
    urdf.parent.mkdir()
    name = "package://bot_description/meshes/leg.stl"
    assert lk.resolve_mesh(name, urdf) == mesh  # the folders above the URDF
    assert lk.resolve_mesh(name, package_dirs=[tmp_path / "robots"]) == mesh  # a folder holding packages
    assert lk.resolve_mesh(name, package_dirs=[mesh.parent.parent]) == mesh  # the package itself
    assert lk.resolve_mesh("../meshes/leg.stl", urdf) == urdf.parent / "../meshes/leg.stl"
    with pytest.raises(FileNotFoundError, match="package_dirs"):
        lk.resolve_mesh("package://other/meshes/leg.stl", urdf)
