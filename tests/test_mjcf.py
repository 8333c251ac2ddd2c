"""`lk.Model.from_mjcf` / `lk.load_mjcf` against MuJoCo's own compiler: hand-written MJCF exercising each
orientation form, angle units, default classes, includes, multi-joint bodies and inertias inferred from geoms
(body mass, COM and inertia against `body_mass`, `body_ipos`, `body_iquat`/`body_inertia`), and every model file
of the dm_control and gymnasium wheels (mass matrix and bias forces against `mj_fullM` and `qfrc_bias`)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import legkit as lk

mujoco = pytest.importorskip("mujoco")
from mjcf_compare import RTOL, compare, corpus  # noqa: E402 (needs mujoco)


def mj_inertia(m, b: int) -> tuple[float, np.ndarray, np.ndarray]:
    """MuJoCo's compiled mass, COM and inertia tensor (about the COM) of body b, in its body frame."""
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, m.body_iquat[b])
    r = r.reshape(3, 3)
    return float(m.body_mass[b]), m.body_ipos[b].copy(), r @ np.diag(m.body_inertia[b]) @ r.T


def assert_bodies_match(xml: str, **kwargs) -> lk.Mjcf:
    """Every named MuJoCo body's mass properties equal legkit's body of that name (joints at pos 0), and the
    dynamics match at random states."""
    m = mujoco.MjModel.from_xml_string(xml)
    loaded = lk.load_mjcf(xml, **kwargs)
    model = loaded.model
    for b in range(1, m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        mass, com, inertia = mj_inertia(m, b)
        ours = model.body(name)
        scale = max(mass, 1e-12)
        assert ours.mass == pytest.approx(mass, rel=RTOL, abs=1e-15), name
        np.testing.assert_allclose(ours.com, com, rtol=0, atol=RTOL * (1 + np.abs(com).max()), err_msg=name)
        np.testing.assert_allclose(ours.inertia, inertia, rtol=0, atol=RTOL * max(np.abs(inertia).max(), 1e-12 * scale), err_msg=name)
    assert compare(xml, m, np.random.default_rng(1)) is None
    return loaded


def one_body(body_attrs: str, compiler: str = "", geom: str = '<geom type="box" size=".1 .2 .3" pos=".1 0 0"/>') -> str:
    return f"""<mujoco><compiler {compiler}/><worldbody>
      <body name="a" pos="0 0 1"><joint name="j0" axis="1 0 0"/><geom type="capsule" size=".05 .2"/>
        <body name="b" pos=".3 .1 0" {body_attrs}><joint name="j1" axis="0 1 1"/>{geom}
          <body name="c" pos="0 0 -.4"><joint name="j2"/><geom size=".07"/></body></body></body>
    </worldbody></mujoco>"""


ORIENTATIONS = [
    ('quat="0.9 0.1 -0.3 0.2"', ""),
    ('axisangle="1 2 3 40"', ""),
    ('axisangle="1 2 3 0.7"', 'angle="radian"'),
    ('euler="10 20 30"', ""),
    ('euler="10 20 30"', 'eulerseq="XYZ"'),
    ('euler="0.3 -0.5 1.1"', 'angle="radian" eulerseq="zyx"'),
    ('euler="15 -25 35"', 'eulerseq="zXy"'),
    ('xyaxes="1 1 0 -1 2 0.5"', ""),
    ('zaxis="0.2 -0.3 0.9"', ""),
    ('zaxis="0 0 -1"', ""),
]


@pytest.mark.parametrize("orientation, compiler", ORIENTATIONS)
def test_each_orientation_form_as_mujoco(orientation: str, compiler: str) -> None:
    assert_bodies_match(one_body(orientation, compiler))
    # The same form on a geom and an inertial.
    assert_bodies_match(one_body("", compiler, f'<geom type="box" size=".1 .2 .3" pos=".1 0 0" {orientation}/>'))
    inertial = f'<inertial pos=".1 .2 .3" {orientation} mass="2" diaginertia=".1 .2 .25"/>'
    assert_bodies_match(one_body("", compiler, inertial))


GEOMS = [
    '<geom type="sphere" size=".1"/>',
    '<geom type="capsule" size=".05 .2" pos=".1 0 0"/>',
    '<geom type="capsule" fromto="0 0 0 .3 .1 -.2" size=".04"/>',
    '<geom type="cylinder" size=".05 .2" euler="30 0 10"/>',
    '<geom type="cylinder" fromto="0 0 0 0 0 -.3" size=".04" mass="3"/>',
    '<geom type="ellipsoid" size=".1 .2 .3" density="300"/>',
    '<geom type="ellipsoid" fromto="0 0 0 .2 .2 0" size=".05"/>',
    '<geom type="box" size=".1 .2 .3" quat="1 1 0 0"/>',
    '<geom type="box" fromto="0 0 0 .1 .3 0" size=".05"/>',
    '<geom type="box" size=".1 .2 .3"/><geom type="sphere" size=".1" pos="0 .3 0" mass="0.5"/>'
    '<geom type="sphere" size=".2" mass="0"/><geom type="sphere" size=".2" group="4" density="10"/>',
    '<inertial pos=".1 0 0" mass="2" fullinertia=".3 .2 .25 .01 -.02 .03"/><geom type="box" size="1 1 1"/>',
]


@pytest.mark.parametrize("geom", GEOMS)
def test_inertia_from_geoms_as_mujoco(geom: str) -> None:
    assert_bodies_match(one_body("", "", geom))


@pytest.mark.parametrize(
    "compiler, moments",
    [
        ('inertiafromgeom="true"', ".01 .02 .025"),
        ('inertiafromgeom="false"', ".01 .02 .025"),
        ('boundmass="5" boundinertia="0.5"', ".01 .02 .025"),
        ('balanceinertia="true"', ".01 .01 .05"),
        ('settotalmass="10"', ".01 .02 .025"),
        ('inertiagrouprange="1 3"', ".01 .02 .025"),
        ('inertiagrouprange="2 4" inertiafromgeom="true"', ".01 .02 .025"),
    ],
)
def test_compiler_mass_options_as_mujoco(compiler: str, moments: str) -> None:
    inertial = f'<inertial pos=".1 0 0" mass="0.3" diaginertia="{moments}"/>'
    xml = f"""<mujoco><compiler {compiler}/><worldbody>
      <body name="a">{inertial}<joint name="j0"/><geom type="capsule" size=".05 .2" group="2"/>
        <body name="b" pos=".3 0 0">{inertial}<joint name="j1" axis="1 0 0"/><geom type="box" size=".1 .2 .3" group="2"/>
          <body name="c" pos="0 0 -.4">{inertial}<joint name="j2" axis="0 1 0"/><geom size=".1" group="2"/>
            <geom size=".05" pos=".1 0 0" group="4"/><geom size=".05" pos="0 .1 0" group="1"/></body></body></body>
    </worldbody></mujoco>"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)  # the unbalanced inertia, which MuJoCo balances
        assert_bodies_match(xml)


def test_default_classes_childclass_and_angles_as_mujoco() -> None:
    xml = """<mujoco><compiler angle="degree"/>
      <default><geom density="500"/><joint damping="0.1" armature="0.02"/>
        <default class="heavy"><geom density="3000" type="box" size=".1 .1 .1"/>
          <default class="heavier"><geom density="9000"/><joint axis="0 1 0" range="-30 60" armature="0.5"/></default>
        </default>
        <default class="slider"><joint type="slide" axis="1 0 0"/></default>
      </default>
      <worldbody>
        <body name="a" childclass="heavy"><joint name="j0" class="slider" ref="0.2"/><geom/>
          <body name="b" pos="0 0 -.5"><joint name="j1" class="heavier" ref="10"/><geom class="heavier" size=".2 .1 .05"/>
            <body name="c" pos="0 0 -.5" childclass="heavier"><joint name="j2"/><geom type="sphere" size=".1" class="main"/></body>
          </body>
        </body>
      </worldbody></mujoco>"""
    loaded = assert_bodies_match(xml)
    m = mujoco.MjModel.from_xml_string(xml)
    for joint in loaded.joints:
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint["name"])
        assert loaded.model.armature[joint["idx_v"]] == pytest.approx(m.dof_armature[m.jnt_dofadr[j]])
        assert loaded.model.damping[joint["idx_v"]] == pytest.approx(m.dof_damping[m.jnt_dofadr[j]])
        limits = loaded.model.limits(joint["body"])
        if m.jnt_limited[j]:
            assert [limits["lower"], limits["upper"]] == pytest.approx(m.jnt_range[j])
        else:
            assert limits is None


MULTI_JOINT = """<mujoco><compiler angle="radian"/><worldbody>
  <body name="torso" pos="0 0 1.3" euler="0.1 0.2 0.3">
    <joint name="rootx" type="slide" axis="1 0 0"/><joint name="rootz" type="slide" axis="0 0 1" ref="1.3"/>
    <joint name="rooty" type="hinge" axis="0 1 0" pos="0 0 -.2" ref="0.3"/>
    <geom type="capsule" fromto="0 0 -.3 0 0 .3" size=".05"/>
    <body name="thigh" pos="0 0 -.3"><joint name="hip_x" pos=".05 0 .02" axis="1 0 0" range="-1 1"/>
      <joint name="hip_y" pos="0 .03 0" axis="0 1 0" ref="-0.4"/><joint name="hip_z" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".04"/>
      <body name="shin" pos="0 0 -.4"><joint name="knee" pos="0 0 .01" axis="0 -1 0"/><geom type="box" size=".05 .05 .2" pos="0 0 -.2"/></body>
    </body>
  </body></worldbody></mujoco>"""


def test_several_joints_in_one_body_compose_as_mujoco() -> None:
    m = mujoco.MjModel.from_xml_string(MULTI_JOINT)
    assert compare(MULTI_JOINT, m, np.random.default_rng(2), states=6) is None
    loaded = lk.load_mjcf(MULTI_JOINT)
    names = loaded.model.names
    assert names[:4] == ["world", "torso/rootx", "torso/rootz", "torso"]
    assert [j["name"] for j in loaded.joints] == ["rootx", "rootz", "rooty", "hip_x", "hip_y", "hip_z", "knee"]
    assert [j["idx_v"] for j in loaded.joints] == list(range(7))  # MuJoCo's dof order


FREE = """<mujoco><option gravity="0 1 -5" timestep="0.005"/><worldbody><geom type="plane" size="5 5 .1"/>
  <body name="base" pos="0 0 .5" quat="0.9 0 0.2 0.1"><freejoint name="root"/><geom type="box" size=".3 .2 .1"/>
    <body name="leg" pos=".3 0 0"><joint name="hip" axis="0 1 0" armature="0.1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -.3" size=".03"/></body></body></worldbody></mujoco>"""


def test_free_joint_is_the_floating_base_with_mujocos_velocity_convention() -> None:
    m = mujoco.MjModel.from_xml_string(FREE)
    assert compare(FREE, m, np.random.default_rng(3), states=6) is None
    loaded = lk.load_mjcf(FREE)
    assert loaded.model.floating_base and loaded.model.nq == 8 and loaded.model.nv == 7
    assert loaded.timestep == 0.005
    np.testing.assert_array_equal(loaded.gravity, [0, 1, -5])
    np.testing.assert_array_equal(loaded.model.gravity, [0, 1, -5])
    welded = lk.Model.from_mjcf(FREE, floating_base=False)
    assert not welded.floating_base and welded.nv == 1 and welded.names[:2] == ["world", "base"]


def irregular_mesh(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A closed, star-shaped (not convex) triangle mesh: a subdivided octahedron's vertices pushed out by random
    radii, with every third face turned inside out (which MuJoCo's default `inertia="legacy"` does not see)."""
    v = [np.array(x, float) for x in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1))]
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    fine, middle = [], {}
    for a, b, c in faces:  # each face into four, through the middles of its edges
        for i, j in ((a, b), (b, c), (c, a)):
            if (j, i) not in middle:
                v.append((v[i] + v[j]) / 2)
                middle[i, j] = len(v) - 1
        ab, bc, ca = (middle.get((i, j), middle.get((j, i))) for i, j in ((a, b), (b, c), (c, a)))
        fine += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
    vertices = np.array([x / np.linalg.norm(x) * rng.uniform(0.05, 0.12) for x in v]) * [1.0, 0.7, 1.3] + [0.02, -0.03, 0.05]
    faces = np.array([f if k % 3 else f[::-1] for k, f in enumerate(fine)])
    return vertices, faces


MESH_AXES = 1.5e-6


def write_mesh(path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """STL (binary) or MuJoCo's MSH by the suffix."""
    if path.suffix == ".stl":
        records = np.zeros(len(faces), dtype=[("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
        records["corners"] = vertices[faces]
        path.write_bytes(b"\0" * 80 + np.uint32(len(faces)).tobytes() + records.tobytes())
    else:
        header = np.array([len(vertices), 0, 0, len(faces)], "<i4").tobytes()
        path.write_bytes(header + vertices.astype("<f4").tobytes() + faces.astype("<i4").tobytes())


@pytest.mark.parametrize("suffix", [".stl", ".msh"])
@pytest.mark.parametrize(
    ("mesh_attrs", "geom_attrs"),
    [("", ""), ('scale="1.5 0.5 2"', 'density="300"'), ('inertia="exact"', 'mass="0.7" pos=".1 0 0" euler="10 20 30"'), ('inertia="shell"', "")],
)
def test_mesh_mass_as_mujocos_compiler(tmp_path, suffix: str, mesh_attrs: str, geom_attrs: str) -> None:
    vertices, faces = irregular_mesh(np.random.default_rng(7))
    if "exact" in mesh_attrs:  # signed volumes need outward faces
        outward = [np.dot(np.cross(*(vertices[f[1:]] - vertices[f[0]])), vertices[f].mean(0) - vertices.mean(0)) > 0 for f in faces]
        faces = np.array([f if out else f[::-1] for f, out in zip(faces, outward)])
    write_mesh(tmp_path / f"rock{suffix}", vertices, faces)
    xml = tmp_path / "robot.xml"
    xml.write_text(
        f'<mujoco><asset><mesh name="rock" file="rock{suffix}" {mesh_attrs}/></asset><worldbody><body name="a" pos="0 0 1">'
        f'<joint name="j" axis="1 0 0"/><geom type="mesh" mesh="rock" {geom_attrs}/><geom size=".03" pos="0 .1 0"/>'
        f'<body name="b" pos="0 .3 0"><joint name="k" type="ball"/><geom type="mesh" mesh="rock"/></body></body></worldbody></mujoco>'
    )
    text = xml.read_text().replace('file="rock', f'file="{tmp_path}/rock')
    assert_mesh_bodies_match(mujoco.MjModel.from_xml_string(text), lk.Model.from_mjcf(text))


def assert_mesh_bodies_match(m, model: lk.Model) -> None:
    """Each MuJoCo body's mass and COM equal those of legkit's body of that name to RTOL, its inertia to MESH_AXES.

    MuJoCo keeps a mesh's principal moments and axes as its Jacobi iteration reaches them (mjuu_eig3 stops at a
    rotation below 1.4e-6 rad), dropping what is left off the diagonal: at most 1.5e-6 of the largest moment. legkit
    keeps the exact tensor."""
    for b in range(1, m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        mass, com, inertia = mj_inertia(m, b)
        ours = model.body(name)
        assert ours.mass == pytest.approx(mass, rel=RTOL), name
        np.testing.assert_allclose(ours.com, com, rtol=0, atol=RTOL * (1 + np.abs(com).max()), err_msg=name)
        np.testing.assert_allclose(ours.inertia, inertia, rtol=0, atol=MESH_AXES * np.abs(inertia).max(), err_msg=name)


def test_several_free_bodies_keep_mujocos_free_joint_coordinates() -> None:
    xml = """<mujoco><worldbody><body name="robot" pos="0 0 1"><freejoint/><geom size=".1"/>
        <body name="leg" pos=".2 0 0"><joint name="hip" axis="0 1 0"/><geom type="capsule" size=".03" fromto="0 0 0 0 0 -.3"/></body></body>
      <body name="ball" pos="1 0 .2" euler="10 20 30"><joint name="ball_free" type="free" damping=".1"/><geom size=".2" mass="2"/></body>
    </worldbody></mujoco>"""
    loaded = assert_bodies_match(xml)
    model = loaded.model
    assert not model.floating_base and (model.nq, model.nv) == (15, 13)
    assert [j["name"] for j in loaded.joints] == ["joint0", "hip", "ball_free"]
    np.testing.assert_array_equal(model.damping[7:13], 0.1)
    m = mujoco.MjModel.from_xml_string(xml)
    assert compare(xml, m, np.random.default_rng(5), states=6) is None


def test_include_files_and_meshdir(tmp_path) -> None:
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "leg.xml").write_text(
        '<mujoco><body name="leg" pos=".3 0 0"><joint name="hip" axis="0 1 0"/><geom type="sphere" size=".1"/></body></mujoco>'
    )
    (tmp_path / "defaults.xml").write_text('<mujoco><default><geom density="200"/></default></mujoco>')
    main = tmp_path / "robot.xml"
    main.write_text(
        '<mujoco><include file="defaults.xml"/><worldbody><body name="base"><joint name="slide" type="slide"/>'
        '<geom type="box" size=".1 .1 .1"/><include file="parts/leg.xml"/></body></worldbody></mujoco>'
    )
    m = mujoco.MjModel.from_xml_path(str(main))
    assert compare(str(main), m, np.random.default_rng(4)) is None
    assert lk.Model.from_mjcf(main).names == ["world", "base", "leg"]  # a path object works too


def test_actuator_torques_equal_mujocos_qfrc_actuator() -> None:
    xml = """<mujoco><worldbody><body name="a"><joint name="j0" axis="0 1 0" range="-90 90"/><geom size=".1"/>
        <body name="b" pos="0 0 -.5"><joint name="j1" type="slide"/><geom size=".1"/></body></body></worldbody>
      <actuator><motor joint="j0" gear="20" ctrlrange="-1 1"/><position joint="j1" kp="50" kv="3" forcerange="-4 4"/>
        <velocity joint="j0" kv="2" gear="3"/>
        <general joint="j1" gaintype="affine" gainprm="2 0.5 -0.1" biastype="affine" biasprm="1 -2 -0.3" gear="1.5"/>
      </actuator></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    loaded = lk.load_mjcf(xml)
    rng = np.random.default_rng(5)
    for _ in range(10):
        d.qpos[:] = rng.uniform(-1, 1, 2)
        d.qvel[:] = rng.normal(size=2)
        d.ctrl[:] = rng.uniform(-2, 2, 4)
        mujoco.mj_forward(m, d)
        np.testing.assert_allclose(loaded.actuator_torques(d.qpos, d.qvel, d.ctrl), d.qfrc_actuator, rtol=1e-12, atol=1e-12)
    assert [a["joint"] for a in loaded.actuators] == ["j0", "j1", "j0", "j1"]
    with pytest.raises(ValueError, match="ctrl"):
        loaded.actuator_torques(d.qpos, d.qvel, [1.0])


BALLS = """<mujoco><compiler angle="radian"/><worldbody>
  <body name="torso" pos="0 0 1"><freejoint/><geom type="box" size=".2 .1 .05"/>
    <body name="upper" pos=".2 0 0" euler=".3 -.2 .5"><joint name="shoulder" type="ball" pos=".02 .01 0" ref="0.7"
        damping=".3" armature=".05"/><geom type="capsule" fromto="0 0 0 .3 0 0" size=".04"/>
      <body name="lower" pos=".3 0 0"><joint name="elbow" axis="0 1 0"/><joint name="wrist" type="ball" pos=".01 0 0"/>
        <geom type="ellipsoid" size=".05 .03 .02" pos=".1 0 0"/></body></body>
    <body name="tail" pos="-.2 0 0"><joint name="hip" type="ball"/><geom type="sphere" size=".05" pos="-.1 .02 0"/></body>
  </body></worldbody></mujoco>"""


@pytest.mark.parametrize("floating", [True, False], ids=["free", "welded"])
def test_ball_joints_match_mujocos_mass_matrix_and_bias_forces(floating: bool) -> None:
    """A ball joint below a free joint and beside a hinge in one body (MuJoCo composes them in order); `ref` is
    ignored on a ball joint, as in MuJoCo; damping and armature on each of its three coordinates."""
    xml = BALLS if floating else BALLS.replace("<freejoint/>", "")
    m = mujoco.MjModel.from_xml_string(xml)
    loaded = lk.load_mjcf(xml)
    assert [j["type"] for j in loaded.joints] == (["free"] if floating else []) + ["ball", "hinge", "ball", "ball"]
    assert compare(xml, m, np.random.default_rng(1), states=5) is None
    k = loaded.joints[1 if floating else 0]["idx_v"]
    assert np.array_equal(loaded.model.armature[k : k + 3], [0.05] * 3)
    assert np.array_equal(loaded.model.damping[k : k + 3], [0.3] * 3)


def test_what_legkit_does_not_model_warns_or_is_refused_with_strict() -> None:
    xml = """<mujoco><worldbody><body name="a"><joint name="j" stiffness="3"/><geom size=".1"/><site name="s"/></body></worldbody>
      <tendon><fixed name="t"><joint joint="j" coef="1"/></fixed></tendon><sensor><jointpos joint="j"/></sensor></mujoco>"""
    with pytest.warns(lk.MjcfWarning) as record:
        model = lk.Model.from_mjcf(xml)
    messages = " ".join(str(w.message) for w in record)
    assert "tendon" in messages and '<fixed name="t">' in messages and "sensor" in messages and "stiffness" in messages
    assert model.nv == 1
    with pytest.raises(ValueError, match="strict"):
        lk.Model.from_mjcf(xml, strict=True)


@pytest.mark.parametrize(
    "xml, message",
    [
        ("<robot/>", "root element must be <mujoco>"),
        ("<mujoco><worldbody><body><geom class='nope'/></body></worldbody></mujoco>", "unknown default class"),
        ("<mujoco><worldbody><body quat='1 0 0 0' euler='0 0 0'/></worldbody></mujoco>", "more than one orientation"),
        ("<mujoco><worldbody><body><joint type='hinge' axis='0 0 0'/></body></worldbody></mujoco>", "zero axis"),
        ("<mujoco><include file='/nonexistent/file.xml'/></mujoco>", "include"),
        ("<mujoco><worldbody><body pos='1 2'/></worldbody></mujoco>", "pos needs 3 numbers"),
        ("<mujoco><worldbody><body><joint/><body><freejoint/></body></body></worldbody></mujoco>", "only joint of a top-level body"),
    ],
)
def test_bad_files_are_clear_value_errors(xml: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        lk.Model.from_mjcf(xml)


CORPUS = corpus()
# Files MuJoCo compiles that legkit refuses, with the reason the error gives: none.
REFUSED: dict[str, str] = {}
# Loaded with a warning that the mass of mesh geoms is not computed: MuJoCo's mass differs.
MESH_MASS = "mass of mesh geoms"
# Bodies whose inertia comes from meshes whose principal axes MuJoCo's iteration leaves off by enough to show at
# RTOL in the dynamics: their bodies are held to MESH_AXES (assert_mesh_bodies_match).
MESH_AXES_FILES = ("build_fruitfly/assets/drosophila_fused.xml",)


def compiled(path: str):
    try:
        return mujoco.MjModel.from_xml_path(path)
    except Exception:  # noqa: BLE001 (fragments and broken test assets MuJoCo itself refuses)
        return None


@pytest.mark.skipif(not CORPUS, reason="dm_control and gymnasium are not installed")
@pytest.mark.parametrize("path", CORPUS, ids=[p.split("site-packages/")[-1] for p in CORPUS])
def test_every_shipped_model_mujoco_compiles_loads_and_matches_or_is_refused(path: str) -> None:
    m = compiled(path)
    if m is None:  # a fragment or a broken asset MuJoCo refuses: legkit loads it or refuses it clearly, never crashes
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                lk.Model.from_mjcf(path)
        except (ValueError, OSError) as error:
            assert str(error)
        return
    refused = next((reason for name, reason in REFUSED.items() if path.endswith(name)), None)
    try:
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            result = compare(path, m, np.random.default_rng(0))
    except ValueError as error:
        assert refused is not None, f"refused: {error}"
        assert any(reason in str(error) for reason in refused.split("|")), str(error)
        return
    assert refused is None, "expected a refusal"
    if any(MESH_MASS in str(w.message) for w in record):
        assert result is not None  # documented: the mesh's mass is left out
        return
    if path.endswith(MESH_AXES_FILES):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert_mesh_bodies_match(m, lk.Model.from_mjcf(path))
        return
    assert result is None, result


def test_frames_place_their_bodies_and_geoms_as_mujoco() -> None:
    xml = """<mujoco><default><default class="light"><geom density="100"/></default></default><worldbody>
      <body name="a"><joint name="j0"/><geom size=".1"/>
        <frame pos=".2 0 0" euler="0 30 0" childclass="light">
          <geom type="box" size=".1 .05 .02" pos="0 .1 0"/>
          <frame pos="0 0 -.1" zaxis="1 0 1">
            <body name="b" pos="0 0 -.2"><joint name="j1" axis="1 0 0"/><geom type="capsule" size=".03 .1"/></body></frame>
        </frame></body></worldbody></mujoco>"""
    assert_bodies_match(xml)


def test_collision_shapes_sit_where_mujocos_geoms_are() -> None:
    xml = """<mujoco><worldbody><geom type="plane" size="5 5 .1"/>
      <body name="a" pos="0 0 1" euler="10 20 30"><joint name="j0" pos=".1 .2 .3" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 .3 .1 -.2" size=".04"/><geom type="box" size=".1 .2 .3" pos=".1 0 0" euler="5 6 7"/>
        <geom type="sphere" size=".3" contype="0" conaffinity="0"/>
        <body name="b" pos=".3 0 0"><joint name="j1" type="slide" axis="1 0 0"/><joint name="j2" pos="0 0 .1"/>
          <geom type="cylinder" size=".05 .2" zaxis="1 1 0"/><geom type="sphere" size=".1" pos="0 0 -.3"/></body></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[:] = [0.4, 0.1, -0.7]
    mujoco.mj_forward(m, d)
    with warnings.catch_warnings():
        warnings.simplefilter("error", lk.MjcfWarning)  # the plane is the floor, not a collider
        model = lk.Model.from_mjcf(xml)
    poses = lk.forward_kinematics(model, d.qpos)
    colliders = model.colliders()
    solid = [g for g in range(m.ngeom) if m.geom_contype[g] or m.geom_conaffinity[g]][1:]  # not the plane
    assert [kind for _, kind, _, _ in colliders] == ["capsule", "box", "cylinder", "sphere"]
    for (body, kind, size, placement), g in zip(colliders, solid):
        a, b, c = m.geom_size[g]
        expected = {"capsule": (b, a), "cylinder": (b, a), "sphere": (a,), "box": (2 * a, 2 * b, 2 * c)}[kind]
        np.testing.assert_allclose(size, expected, rtol=1e-15)
        world = poses[body] @ placement
        np.testing.assert_allclose(world[:3, 3], d.geom_xpos[g], atol=1e-12)
        np.testing.assert_allclose(world[:3, :3], d.geom_xmat[g].reshape(3, 3), atol=1e-12)


def test_a_freejoint_takes_no_joint_defaults_as_in_mujoco() -> None:
    xml = """<mujoco><default><joint armature="0.1" damping="2"/></default><worldbody>
      <body name="base" pos="0 0 1"><freejoint name="root"/><geom size=".1"/>
        <body name="leg"><joint name="hip"/><geom type="capsule" fromto="0 0 0 0 0 -.3" size=".02"/></body></body></worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    np.testing.assert_array_equal(m.dof_armature[:6], 0)  # MuJoCo's reading, which legkit's must equal
    with warnings.catch_warnings():
        warnings.simplefilter("error", lk.MjcfWarning)
        loaded = lk.load_mjcf(xml)
    assert compare(xml, m, np.random.default_rng(6)) is None
    np.testing.assert_array_equal(loaded.model.armature, [0, 0, 0, 0, 0, 0, 0.1])
    # A <joint type="free"> does take them: MuJoCo adds the armature to the base, which legkit cannot.
    with pytest.warns(lk.MjcfWarning, match='free joint "root": armature=0.1 is not modelled'):
        lk.load_mjcf(xml.replace('<freejoint name="root"/>', '<joint name="root" type="free"/>'))


REPLICATED = """<mujoco><compiler angle="{angle}" eulerseq="{seq}"/><default><default class="light"><geom density="200"/></default></default>
  <worldbody><geom type="box" size=".1 .1 .1"/>
    <body name="base" pos="0 0 1"><joint name="root" axis="1 0 0"/><geom size=".1"/>
      <replicate count="4" offset=".1 .2 0" euler="{euler}" sep="-">
        <geom type="box" size=".02 .03 .04" pos=".1 0 0"/>
        <body name="leg" pos=".2 0 0" euler="0 15 0"><joint name="hip" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0 .1 -.3" size=".03"/>
          <body name="shin" pos="0 .1 -.3"><joint name="knee" type="slide" axis="1 0 1"/><geom size=".04"/></body></body>
      </replicate></body>
    <frame pos="1 0 0" euler="0 0 20">
      <replicate count="2" offset="0 0 .5" childclass="light">
        <replicate count="11" offset=".3 0 0" euler="{euler}">
          <body name="link" pos="0 0 2"><joint name="j" axis="0 1 0"/><geom type="box" size=".05 .06 .07" pos="0 0 -.1"/></body>
        </replicate></replicate></frame>
    <replicate count="3" offset="0 -1 0" sep="_"><geom type="capsule" size=".05 .3" pos="0 0 .2"/></replicate>
  </worldbody></mujoco>"""


@pytest.mark.parametrize(("angle", "seq", "euler"), [("degree", "xyz", "10 20 30"), ("radian", "ZYX", "0.1 -0.4 0.3")])
def test_replicate_expands_as_mujoco(angle: str, seq: str, euler: str) -> None:
    # <replicate> was left out with a warning. Copies inside a body, in the world, in a frame, nested (an inner copy's
    # suffix first), with a childclass: MuJoCo's body names, poses, masses and dynamics; joints by name; geoms where
    # MuJoCo's are.
    xml = REPLICATED.format(angle=angle, seq=seq, euler=euler)
    m = mujoco.MjModel.from_xml_string(xml)
    with warnings.catch_warnings():
        warnings.simplefilter("error", lk.MjcfWarning)
        loaded = assert_bodies_match(xml)
    model = loaded.model
    names = [m.body(b).name for b in range(1, m.nbody)]
    assert "leg-0" in names and "shin-3" in names and "link000" in names and "link101" in names and len(names) == 31
    assert model.names == ["world", *names] and model.nq == m.nq == 31
    assert [j["name"] for j in loaded.joints] == [m.joint(j).name for j in range(m.njnt)]
    d = mujoco.MjData(m)
    d.qpos[:] = np.random.default_rng(3).uniform(-1, 1, m.nq)
    mujoco.mj_forward(m, d)
    poses = lk.forward_kinematics(model, d.qpos)
    np.testing.assert_allclose(poses[1:, :3, 3], d.xpos[1:], atol=1e-12)
    np.testing.assert_allclose(poses[1:, :3, :3], d.xmat[1:].reshape(-1, 3, 3), atol=1e-12)
    colliders = model.colliders()
    assert len(colliders) == m.ngeom
    for body, _, _, placement in colliders:
        world = poses[body] @ placement
        g = int(np.argmin(np.linalg.norm(d.geom_xpos - world[:3, 3], axis=1)))
        np.testing.assert_allclose(world[:3, 3], d.geom_xpos[g], atol=1e-12)
        np.testing.assert_allclose(world[:3, :3], d.geom_xmat[g].reshape(3, 3), atol=1e-12)
