"""URDF `floating` and `spherical` joints in `Model.from_urdf`, against Pinocchio and legkit's own ball joint.

A `floating` joint loads as three slides along the joint frame's axes and a ball joint: q equals Pinocchio's
`JointModelFreeFlyer` q, and v differs only in the linear rate, which legkit keeps in the joint frame (ṗ) where
Pinocchio has it in the child frame (Rᵀṗ). The tests map v = T v_legkit (T the identity but for Rᵀ on those
three rows) and compare M = Tᵀ M_pin T, RNEA and ABA. `spherical` (an extension Pinocchio's URDF parser refuses)
is compared with Pinocchio's `JointModelSpherical` built by hand and with `Model.add_spherical`.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import legkit as lk

TOL = 1e-10

INERTIAS = {
    "base": (3.0, [0.02, -0.01, 0.03], [0.05, 0.06, 0.07, 0.001, -0.002, 0.003]),
    "thigh": (1.5, [0.0, 0.05, -0.15], [0.02, 0.025, 0.015, 0.0, 0.001, -0.001]),
    "torso": (4.0, [0.1, 0.02, 0.05], [0.1, 0.2, 0.15, 0.01, 0.0, 0.02]),
    "arm": (0.8, [0.0, 0.0, -0.2], [0.01, 0.012, 0.004, 0.0, 0.0, 0.0]),
}


def link(name: str) -> str:
    m, c, (ixx, iyy, izz, ixy, ixz, iyz) = INERTIAS[name]
    return (
        f'<link name="{name}"><inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="0.3 -0.2 0.1"/><mass value="{m}"/>'
        f'<inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="{ixy}" ixz="{ixz}" iyz="{iyz}"/></inertial></link>'
    )


def joint(name: str, kind: str, parent: str, child: str, xyz: str, rpy: str, axis: str = "") -> str:
    axis = f'<axis xyz="{axis}"/>' if axis else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/>{axis}<limit lower="-2" upper="2" effort="10" velocity="5"/></joint>'
    )


def robot(middle: str) -> str:
    """A chain base -> thigh -> torso -> arm, torso moved by a joint of type `middle`."""
    return (
        '<robot name="r">'
        + "".join(link(n) for n in INERTIAS)
        + joint("hip", "revolute", "base", "thigh", "0.1 0 0.2", "0.2 0.1 -0.3", "0.3 1 -0.2")
        + joint("free", middle, "thigh", "torso", "0.05 -0.1 -0.3", "-0.4 0.3 0.2")
        + joint("shoulder", "prismatic", "torso", "arm", "0 0.2 0.1", "0.1 0 0.5", "1 0.2 0.4")
        + "</robot>"
    )


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def rotation(xyzw: np.ndarray) -> np.ndarray:
    x, y, z, w = xyzw
    return pin.Quaternion(w, x, y, z).toRotationMatrix()


def random_state(model: lk.Model, rng: np.random.Generator, quaternions: list[int]):
    q = rng.uniform(-1.0, 1.0, model.nq)
    for k in quaternions:
        q[k : k + 4] = unit(rng.normal(size=4))
    return q, rng.normal(size=model.nv), rng.normal(size=model.nv)


def floating_pair(floating_base: bool):
    xml = robot("floating")
    model = lk.Model.from_urdf(xml, floating_base=floating_base)
    pin_model = pin.buildModelFromXML(xml, pin.JointModelFreeFlyer()) if floating_base else pin.buildModelFromXML(xml)
    pin_model.gravity = pin.Motion(np.asarray(model.gravity), np.zeros(3))
    return model, pin_model


@pytest.mark.parametrize("floating_base", [False, True])
def test_a_mid_tree_floating_joint_matches_pinocchios_free_flyer(floating_base: bool) -> None:
    model, pin_model = floating_pair(floating_base)
    assert (model.nq, model.nv) == (pin_model.nq, pin_model.nv)
    slides = ["torso/free:x", "torso/free:y", "torso/free:z"]
    assert [model.joint_type(n) for n in [*slides, "torso"]] == ["prismatic"] * 3 + ["spherical"]
    iq, iv = model.idx_q[model.names.index(slides[0])], model.idx_v[model.names.index(slides[0])]
    assert (iq, iv) == ((7 if floating_base else 0) + 1, (6 if floating_base else 0) + 1)
    pin_data = pin_model.createData()
    rng = np.random.default_rng(7)
    for _ in range(20):
        q, v, a = random_state(model, rng, ([3] if floating_base else []) + [iq + 3])
        # v_pin = T v (the linear rate in the child frame); d/dt(Rᵀ ṗ) = Rᵀ p̈ - ω x Rᵀ ṗ.
        rt = rotation(q[iq + 3 : iq + 7]).T
        t = np.eye(model.nv)
        t[iv : iv + 3, iv : iv + 3] = rt
        v_pin, a_pin = t @ v, t @ a
        a_pin[iv : iv + 3] -= np.cross(v[iv + 3 : iv + 6], rt @ v[iv : iv + 3])
        # The same q puts the body at the same pose.
        pin.forwardKinematics(pin_model, pin_data, q)
        pose = lk.forward_kinematics(model, q)[model.names.index("torso")]
        np.testing.assert_allclose(pose, pin_data.oMi[pin_model.getJointId("free")].homogeneous, atol=TOL)

        mass = pin.crba(pin_model, pin_data, q)
        mass = np.triu(mass) + np.triu(mass, 1).T
        np.testing.assert_allclose(lk.crba(model, q), t.T @ mass @ t, atol=TOL, rtol=TOL)
        tau = t.T @ pin.rnea(pin_model, pin_data, q, v_pin, a_pin)
        np.testing.assert_allclose(lk.rnea(model, q, v, a), tau, atol=TOL, rtol=TOL)
        # T is orthogonal, so the generalised forces map by T as the rates do.
        np.testing.assert_allclose(lk.aba(model, q, v, tau), a, atol=TOL, rtol=TOL)
        np.testing.assert_allclose(pin.aba(pin_model, pin_data, q, v_pin, t @ tau), a_pin, atol=TOL, rtol=TOL)


def test_a_floating_joint_out_of_the_root_link_refuses_a_second_free_base() -> None:
    xml = robot("revolute").replace('type="revolute"', 'type="floating"', 1)
    model = lk.Model.from_urdf(xml)
    assert (model.nv, model.floating_base) == (6 + 1 + 1, False)
    with pytest.raises(ValueError, match=r'joint "hip": a floating joint out of the root link "base" with floating_base'):
        lk.Model.from_urdf(xml, floating_base=True)


def load_spherical(xml: str, joint: str = "free") -> lk.Model:
    with pytest.warns(lk.UrdfWarning, match=f'joint "{joint}": type "spherical" is not in the URDF specification'):
        return lk.Model.from_urdf(xml)


def test_spherical_is_a_ball_joint_with_a_warning_and_strict_refuses_it() -> None:
    model = load_spherical(robot("spherical"))
    assert (model.nq, model.nv) == (1 + 4 + 1, 1 + 3 + 1)
    assert model.joint_type("torso") == "spherical" and model.limits("torso") is None
    with pytest.raises(ValueError, match=r'joint "free": type "spherical" .*\(strict\)'):
        lk.Model.from_urdf(robot("spherical"), strict=True)


def test_planar_stays_refused_naming_the_joint() -> None:
    with pytest.raises(ValueError, match=r'joint "free": unsupported type "planar"'):
        lk.Model.from_urdf(robot("planar"))


def spherical_twins():
    """The `spherical` URDF, the same chain built with `Model.add_spherical`, and in Pinocchio with a
    `JointModelSpherical`, from the loaded model's placements, axes and inertias."""
    loaded = load_spherical(robot("spherical"))
    built = lk.Model(floating_base=False, base=loaded.body(0), base_name="base")
    pin_model = pin.Model()
    pin_model.gravity = pin.Motion(np.asarray(loaded.gravity), np.zeros(3))
    for body, name in enumerate(loaded.names[1:], start=1):
        placement, mass = loaded.placement(body), loaded.body(body)
        kind, axis = loaded.joint_type(body), loaded.joint_axis(body)
        if kind == "spherical":
            built.add_spherical(body - 1, placement, mass, name)
            jm = pin.JointModelSpherical()
        elif kind == "revolute":
            built.add_revolute(body - 1, axis, placement, mass, name)
            jm = pin.JointModelRevoluteUnaligned(axis)
        else:
            built.add_prismatic(body - 1, axis, placement, mass, name)
            jm = pin.JointModelPrismaticUnaligned(axis)
        j = pin_model.addJoint(body - 1, jm, pin.SE3(placement[:3, :3].copy(), placement[:3, 3].copy()), name)
        pin_model.appendBodyToJoint(j, pin.Inertia(mass.mass, np.asarray(mass.com), np.asarray(mass.inertia)), pin.SE3.Identity())
    return loaded, built, pin_model


def test_a_spherical_joint_matches_add_spherical_and_pinocchios_spherical_joint() -> None:
    loaded, built, pin_model = spherical_twins()
    assert loaded.names == built.names == ["base", "thigh", "torso", "arm"]
    pin_data = pin_model.createData()
    rng = np.random.default_rng(11)
    for _ in range(20):
        q, v, a = random_state(loaded, rng, [1])
        mass = pin.crba(pin_model, pin_data, q)
        mass = np.triu(mass) + np.triu(mass, 1).T
        tau = pin.rnea(pin_model, pin_data, q, v, a)
        for model in (loaded, built):
            np.testing.assert_allclose(lk.crba(model, q), mass, atol=TOL, rtol=TOL)
            np.testing.assert_allclose(lk.rnea(model, q, v, a), tau, atol=TOL, rtol=TOL)
            np.testing.assert_allclose(lk.aba(model, q, v, tau), a, atol=TOL, rtol=TOL)


def test_a_spherical_urdf_pendulum_simulates_as_the_ball_joint_it_is() -> None:
    xml = '<robot name="p"><link name="pivot"/>' + link("arm") + joint("ball", "spherical", "pivot", "arm", "0 0 1", "0 0 0") + "</robot>"
    loaded = load_spherical(xml, "ball")
    built = lk.Model(floating_base=False, base=loaded.body(0), base_name="pivot")
    built.add_spherical(0, loaded.placement(1), loaded.body(1), "arm")
    q0 = unit(np.array([0.3, -0.2, 0.1, 1.0]))
    v0 = np.array([0.5, -1.0, 2.0])
    runs = []
    for model in (loaded, built):
        sim = lk.Simulation(model, dt=1e-3)
        sim.q, sim.v = q0, v0
        sim.step(n=200)
        runs.append((sim.q, sim.v))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    q = runs[0][0]
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12 and not np.allclose(q, q0)


@pytest.mark.parametrize("kind, coordinates", [("spherical", 3), ("floating", 6)])
def test_dynamics_damping_damps_every_coordinate_of_a_ball_or_free_joint(kind: str, coordinates: int) -> None:
    # It was dropped without a word: only one-coordinate joints read <dynamics>. MuJoCo damps every coordinate of a
    # ball or free joint by its one damping.
    body = ('<link name="arm"><inertial><mass value="0.8"/>'  # its COM at the joint: translation and rotation decouple
            '<inertia ixx="0.01" iyy="0.012" izz="0.004" ixy="0" ixz="0" iyz="0"/></inertial></link>')
    xml = (f'<robot name="p"><link name="pivot"/>{body}<joint name="ball" type="{kind}"><parent link="pivot"/>'
           '<child link="arm"/><origin xyz="0 0 1"/><dynamics damping="0.4"/></joint></robot>')
    loaded = load_spherical(xml, "ball") if kind == "spherical" else lk.Model.from_urdf(xml)
    np.testing.assert_array_equal(loaded.damping, np.full(coordinates, 0.4))
    with pytest.raises(ValueError, match=r'joint "ball": <dynamics damping> must be >= 0'):
        lk.Model.from_urdf(xml.replace("0.4", "-1"))
    if kind == "floating":
        # Sliding along x (gravity is along z), the body slows as v = v0 exp(-damping t / mass), to first order in dt:
        # over n steps the discrete decay differs by about n (damping dt / mass)^2 / 2 = 6e-5 of it.
        sim = lk.Simulation(loaded, dt=1e-3)
        sim.v = np.r_[0.5, 0.0, 0.0, 0.0, 0.0, 0.0]
        sim.step(n=500)
        assert sim.v[0] == pytest.approx(0.5 * np.exp(-0.4 * 0.5 / 0.8), rel=2e-4)
