"""Ball (spherical) joints: `Model.add_spherical`, its coordinates and what refuses it.

The dynamics and their derivatives are checked against Pinocchio's `JointModelSpherical` by every differential test
on random trees (tests/robots.py draws trees with spherical joints in `twins()`), and against MuJoCo by
tests/test_mjcf.py; this file checks what those do not: the configuration bookkeeping, a closed form, the viewer's
poses and the clear refusals (the simulation: tests/test_ball_simulation.py).
"""

from __future__ import annotations

import numpy as np
import pytest

import legkit as lk
from legkit.viewer._geometry import collision_shapes, shape_poses

BODY = lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1])


def ball_on_a_hinge() -> lk.Model:
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 0.0, 1.0], None, BODY, "turntable")
    placement = np.eye(4)
    placement[:3, 3] = [0.1, 0.0, 0.5]
    model.add_spherical("turntable", placement, BODY, "ball")
    return model


def quaternion(axis, angle: float) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.array([*np.sin(angle / 2) * axis, np.cos(angle / 2)])


def rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_layout_neutral_and_kind() -> None:
    model = ball_on_a_hinge()
    assert (model.nq, model.nv) == (5, 4)
    assert (model.idx_q[2], model.idx_v[2]) == (1, 1)
    assert model.joint_type("ball") == "spherical" and model.joint_axis("ball") is None
    assert np.array_equal(model.neutral(), [0.0, 0.0, 0.0, 0.0, 1.0])


def test_the_body_turns_by_the_quaternion_about_the_joint_origin() -> None:
    model = ball_on_a_hinge()
    q = np.array([0.4, *quaternion([1.0, -2.0, 0.5], 1.1)])
    pose = lk.forward_kinematics(model, q)[2]
    turn = rotation(quaternion([0.0, 0.0, 1.0], 0.4))
    np.testing.assert_allclose(pose[:3, :3], turn @ rotation(q[1:]), atol=1e-15)
    np.testing.assert_allclose(pose[:3, 3], turn @ [0.1, 0.0, 0.5], atol=1e-15)
    # The viewer draws the body where forward kinematics puts it.
    shapes = collision_shapes(model)
    poses = shape_poses(model, q, shapes)
    for shape, drawn in zip(shapes, poses):
        np.testing.assert_allclose(drawn, lk.forward_kinematics(model, q)[shape.body] @ shape.placement, atol=1e-15)


def test_a_lone_ball_joint_has_the_bodys_rotational_inertia_about_the_joint() -> None:
    """M = I_O in the body frame (v is the body-frame angular velocity), whatever the orientation; the bias forces
    are gravity's moment and ω x I_O ω."""
    model = lk.Model(floating_base=False)
    body = lk.MassProperties(1.5, [0.1, -0.2, 0.3], np.diag([0.2, 0.3, 0.4]))
    model.add_spherical(0, None, body, "ball")
    q, w = quaternion([0.3, 1.0, -0.2], 2.0), np.array([0.5, -1.0, 2.0])
    com = np.array([0.1, -0.2, 0.3])
    inertia = np.diag([0.2, 0.3, 0.4]) + 1.5 * (com @ com * np.eye(3) - np.outer(com, com))
    np.testing.assert_allclose(lk.crba(model, q), inertia, rtol=1e-14)
    gravity_in_body = rotation(q).T @ np.asarray(model.gravity)
    expected = -np.cross(com, 1.5 * gravity_in_body) + np.cross(w, inertia @ w)
    np.testing.assert_allclose(lk.rnea(model, q, w, np.zeros(3)), expected, rtol=1e-13)


def test_integrate_turns_in_the_body_frame_and_keeps_the_quaternion_unit() -> None:
    model = ball_on_a_hinge()
    q = np.array([0.0, *quaternion([0.0, 1.0, 0.0], 0.7)])
    v = np.array([0.0, 0.3, 0.0, 0.0])
    moved = lk.integrate(model, q, v, 2.0)
    np.testing.assert_allclose(moved[1:], _product(q[1:], quaternion([1.0, 0.0, 0.0], 0.6)), atol=1e-15)
    assert abs(np.linalg.norm(moved[1:]) - 1.0) < 1e-15
    np.testing.assert_allclose(lk.difference(model, q, moved), v * 2.0, atol=1e-15)


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions [x, y, z, w]."""
    (ax, ay, az, aw), (bx, by, bz, bw) = a, b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def test_a_quaternion_off_the_unit_sphere_is_refused_naming_the_joint() -> None:
    model = ball_on_a_hinge()
    with pytest.raises(ValueError, match=r"q: the quaternion of ball joint 'ball' q\[1:5\] must have unit norm"):
        lk.crba(model, [0.0, 0.0, 0.0, 0.0, 2.0])


def test_the_rapier_backend_refuses_ball_joints_clearly() -> None:
    # The tree engine simulates them (tests/test_ball_simulation.py).
    with pytest.raises(RuntimeError, match="Rapier's multibody has no spherical joint"):
        lk.Simulation(ball_on_a_hinge(), backend="rapier")
