"""The MJCF's floor is the simulation's ground: `Mjcf.ground`, placed where MuJoCo places the plane geom, with its
friction, and `Mjcf.simulation()` on it at the file's timestep.

The locomotion models of dm_control and gymnasium dropped from MuJoCo's qpos0 on their own floor follow, bit for bit,
the same drop on a hand-added `lk.Ground.plane`; a tilted, offset plane is MuJoCo's (its frame and contact normal from
MuJoCo in-process), and a box released on it slides down as Coulomb's law says, a = g (sin θ - μ cos θ).
"""

from __future__ import annotations

import re
import warnings

import mujoco
import numpy as np
import pytest

import legkit as lk
from mjcf_compare import corpus, joint_ids, mapped

OWN_FLOOR = ("gymnasium/envs/mujoco/assets/ant.xml", "gymnasium/envs/mujoco/assets/humanoid.xml", "dm_control/suite/quadruped.xml")
DROP_SECONDS = 1.0


def quiet_load(path: str) -> lk.Mjcf:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)  # sensors, tendons, ...: not what is compared here
        return lk.load_mjcf(path)


def lowest_point(sim: lk.Simulation) -> float:
    """The lowest contact point's height (m), +inf without contacts."""
    points = sim.contacts()["point"]
    return float(points[:, 2].min()) if len(points) else np.inf


@pytest.mark.parametrize("name", OWN_FLOOR)
def test_a_model_falls_on_its_own_floor_exactly_as_on_a_hand_added_ground(name: str) -> None:
    path = next((p for p in corpus() if p.endswith(name)), None)
    assert path is not None, f"{name} is not in the corpus (dm_control and gymnasium, test dependencies, ship it)"
    m = mujoco.MjModel.from_xml_path(path)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    loaded = quiet_load(path)
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    assert loaded.ground is not None and loaded.ground.kind == "plane"
    assert loaded.ground.friction == m.geom_friction[floor][0]
    start = mapped(m, d, loaded, joint_ids(m, loaded))[:2]
    own = loaded.simulation()
    assert own.dt == m.opt.timestep
    hand = lk.Simulation(loaded.model, dt=m.opt.timestep, ground=lk.Ground.plane(friction=float(m.geom_friction[floor][0])))
    none = lk.Simulation(loaded.model, dt=m.opt.timestep)
    steps = round(DROP_SECONDS / m.opt.timestep)
    for sim in (own, hand, none):
        sim.q, sim.v = start
        sim.step(None, steps)
    np.testing.assert_array_equal(own.q, hand.q)
    np.testing.assert_array_equal(own.v, hand.v)
    # On the floor: touching it, nothing more than a millimetre into it; with no ground it falls through the world.
    assert -1e-3 < lowest_point(own) < 1e-3
    assert lk.center_of_mass(loaded.model, own.q)[2] > 0.0
    assert lk.center_of_mass(loaded.model, none.q)[2] < lk.center_of_mass(loaded.model, start[0])[2] - 4.0


def test_the_quadrupeds_heightfield_is_named_in_a_warning() -> None:
    path = next((p for p in corpus() if p.endswith("dm_control/suite/quadruped.xml")), None)
    assert path is not None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", lk.MjcfWarning)
        loaded = lk.load_mjcf(path)
    assert any(re.search(r'<geom name="terrain">.*\(hfield\)', str(w.message)) for w in caught)
    assert loaded.ground is not None and loaded.ground.kind == "plane"


TILTED = """<mujoco><compiler angle="radian"/><option timestep="0.001"/>
  <worldbody>
    <frame pos="0.1 0 0" euler="0 0 0.4">
      <geom name="floor" type="plane" size="5 5 .1" pos="0.3 -0.2 0.5" euler="0.2 -0.15 0.3" friction="{friction} 0.005 0.0001"/>
    </frame>
    <geom name="wall" type="plane" size="1 1 .1" pos="0 3 0" zaxis="0 -1 0"/>
    <body name="box" pos="0 0 3"><freejoint/><geom type="box" size=".1 .1 .1" mass="1"/></body>
  </worldbody>
</mujoco>"""


def placed(xml: str) -> tuple[np.ndarray, np.ndarray, float]:
    """MuJoCo's frame of the geom `floor`: (R (3, 3), origin (3,)), and its sliding friction."""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    return d.geom_xmat[floor].reshape(3, 3).copy(), d.geom_xpos[floor].copy(), float(m.geom_friction[floor][0])


def test_a_tilted_offset_plane_is_placed_where_mujoco_places_it() -> None:
    xml = TILTED.format(friction=0.1)
    rotation, origin, friction = placed(xml)
    with pytest.warns(lk.MjcfWarning, match=r'<geom name="wall">.*a plane besides the floor'):
        loaded = lk.load_mjcf(xml)
    ground = loaded.ground
    assert ground is not None and ground.friction == friction
    np.testing.assert_allclose(ground.placement[:3, :3], rotation, atol=1e-12)
    np.testing.assert_allclose(ground.placement[:3, 3], origin, atol=1e-12)
    np.testing.assert_array_equal(ground.placement[3], [0, 0, 0, 1])


def resting_box_state(rotation: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """q of the box (half size 0.1) lying flat on the plane (rotation, origin), 1 mm above it."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rotation.reshape(-1))
    w, x, y, z = quat
    return np.array([*(origin + rotation[:, 2] * 0.101), x, y, z, w])


@pytest.mark.parametrize("friction", [0.0, 0.1, 0.6])
def test_a_box_on_the_tilted_floor_slides_as_coulombs_law_says(friction: float) -> None:
    xml = TILTED.format(friction=friction)
    rotation, origin, _ = placed(xml)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)  # the wall
        loaded = lk.load_mjcf(xml)
    sim = loaded.simulation()
    sim.q = resting_box_state(rotation, origin)
    normal = rotation[:, 2]
    downhill = np.array([0.0, 0.0, -1.0]) - normal * -normal[2]
    sin, cos = np.linalg.norm(downhill), normal[2]
    downhill /= sin
    # a = g (sin θ - μ cos θ) when it slides (tan θ = 0.36 here), 0 when friction holds it.
    a = 9.81 * max(sin - friction * cos, 0.0)
    settle = 0.05  # s, onto the plane from 1 mm above it
    sim.step(None, round(settle / sim.dt))
    start, t0 = sim.q[:3].copy(), sim.time
    sim.step(None, round(0.5 / sim.dt))
    moved, t = sim.q[:3] - start, sim.time - t0
    # On the plane, moving downhill only, the distance v0 t + a t^2 / 2 (v0 = a settle: sliding from the start).
    assert abs((sim.q[:3] - origin) @ normal - 0.1) < 1e-3
    assert np.linalg.norm(moved - downhill * (moved @ downhill)) < 1e-4
    assert moved @ downhill == pytest.approx(a * settle * t + 0.5 * a * t**2, rel=2e-2, abs=1e-4)
    contacts = sim.contacts()
    assert len(contacts["normal"]) == 4
    np.testing.assert_allclose(contacts["normal"], np.broadcast_to(normal, contacts["normal"].shape), atol=1e-12)


def test_the_contact_normal_is_mujocos() -> None:
    xml = TILTED.format(friction=0.6)
    rotation, origin, _ = placed(xml)
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    q = resting_box_state(rotation, origin)
    q[:3] -= rotation[:, 2] * 0.0015  # half a millimetre into the plane: MuJoCo reports the contact
    d.qpos[:3], d.qpos[3:] = q[:3], [q[6], *q[3:6]]
    mujoco.mj_forward(m, d)
    floor = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    theirs = [d.contact[i].frame[:3] for i in range(d.ncon) if floor in (d.contact[i].geom1, d.contact[i].geom2)]
    assert theirs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)
        sim = lk.load_mjcf(xml).simulation()
    sim.q = q
    sim.step()
    ours = sim.contacts()["normal"]
    assert len(ours) > 0
    np.testing.assert_allclose(ours, np.broadcast_to(theirs[0], ours.shape), atol=1e-9)


def test_rapier_takes_the_placed_plane_too() -> None:
    xml = TILTED.format(friction=0.6)
    rotation, origin, _ = placed(xml)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)
        sim = lk.load_mjcf(xml).simulation(backend="rapier")
    sim.q = resting_box_state(rotation, origin)
    sim.step(None, 500)
    assert abs((sim.q[:3] - origin) @ rotation[:, 2] - 0.1) < 2e-3


def test_without_a_plane_there_is_no_ground_and_options_override_the_files() -> None:
    loaded = lk.load_mjcf('<mujoco><option timestep="0.004"/><worldbody><body><freejoint/><geom size=".1"/></body></worldbody></mujoco>')
    assert loaded.ground is None
    sim = loaded.simulation(substeps=2)
    assert sim.dt == 0.004
    sim.step(None, 100)
    assert sim.q[2] < -0.1  # no floor: it falls
    assert loaded.simulation(dt=0.01, ground=lk.Ground.plane()).dt == 0.01


def test_a_bad_placement_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="placement"):
        lk.Ground.plane(placement=np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="placement"):
        lk.Ground.plane(placement=(np.eye(3), [np.inf, 0.0, 0.0]))
    np.testing.assert_array_equal(lk.Ground.plane().placement, np.eye(4))
    assert lk.Ground.heightfield(np.zeros((2, 2)), 0.1).placement is None


@pytest.mark.parametrize(("name", "floating_base"), [(name, None) for name in OWN_FLOOR] + [(name, True) for name in OWN_FLOOR[:2]])
def test_joint_names_are_mujocos_in_its_order(name: str, floating_base: bool | None) -> None:
    """A free joint off a floating base is four legkit joints: its name (where its coordinates start), then :y, :z
    and :rotation. (The quadruped's ball is a second free body: it has no floating base.)"""
    path = next(f for f in corpus() if f.endswith(name))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)
        loaded = lk.load_mjcf(path, floating_base=floating_base)
    m = mujoco.MjModel.from_xml_path(path)
    model, want = loaded.model, []
    for j in range(m.njnt):
        named = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
        chain = m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and not (j == 0 and model.floating_base)
        want += [named + suffix for suffix in ("", ":y", ":z", ":rotation")] if chain else [named]
    assert model.joint_names == want
    for joint in loaded.joints:
        assert model.idx_q[model.joint_index(joint["name"])] == joint["idx_q"]


def test_a_second_free_body_is_named_as_its_four_joints() -> None:
    xml = """<mujoco><worldbody>
      <body name="a"><freejoint name="first"/><geom size="0.1"/></body>
      <body name="b" pos="1 0 0"><freejoint name="second"/><geom size="0.1"/></body>
    </worldbody></mujoco>"""
    loaded = quiet_load(xml)
    second = next(joint for joint in loaded.joints if joint["name"] == "second")
    assert loaded.model.joint_names[-4:] == ["second", "second:y", "second:z", "second:rotation"]
    assert loaded.model.idx_q[loaded.model.joint_index("second")] == second["idx_q"]
