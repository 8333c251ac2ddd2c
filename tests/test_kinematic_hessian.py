"""The kinematic Hessian (``lk.kinematic_hessian``: d/dq of a frame's Jacobian), the curvature of a point's velocity
(``lk.point_velocity_hessian``: the q-Hessian of F . J(q) v) and of its acceleration (``lk.point_acceleration_hessian``:
the (q, v, a) Hessian of F . a_p).

Against Pinocchio's getJointKinematicHessian in "world" at joint origins, on random trees with every joint kind; against
central differences of legkit's own first-order kernels (``lk.jacobian``, ``lk.frame_velocity_derivatives``), q stepped
by ``lk.integrate``, at any frame point; and in closed form on a pendulum.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given

import legkit as lk
from conftest import examples
from legkit.optimize.kinematics import point_acceleration_derivatives
from robots import Twin, rngs, twins
from test_derivatives import assert_hessian_of_slope, assert_slopes, coordinate_differences, tangent_differences
from test_dynamics_pinocchio import assert_close, note_case, state

ALIGNED_FRAMES = ("world", "local_world_aligned")


def random_frame(tw: Twin, rng: np.random.Generator) -> tuple[int, np.ndarray]:
    return int(rng.integers(tw.nbodies)), rng.uniform(-0.5, 0.5, size=3)


@examples(40)
@given(tw=twins(), rng=rngs())
def test_kinematic_hessian_is_the_slope_of_the_jacobian(tw: Twin, rng):
    q, _, _ = state(tw, rng)
    body, point = random_frame(tw, rng)
    note_case(tw, q=q)
    for frame in ALIGNED_FRAMES:
        want = tangent_differences(tw.model, lambda x, frame=frame: lk.jacobian(tw.model, x, body, point, frame), q)  # [r, a, d]
        assert_slopes(lk.kinematic_hessian(tw.model, q, body, point, frame), want, f"dJ/dq, {frame}")


@examples(30)
@given(tw=twins(), rng=rngs())
def test_kinematic_hessian_matches_pinocchio_at_joint_origins(tw: Twin, rng):
    q, _, _ = state(tw, rng)
    body = int(rng.integers(tw.nbodies))
    note_case(tw, q=q)
    data = tw.data()
    pin.computeJointKinematicHessians(tw.pin_model, data, tw.q_pin(q))
    joint = tw.body_joint[body]
    # eigenpy hands back the column-major 6 x nv x nv tensor's memory as it is: [r, a, d] in Pinocchio's coordinate order.
    flat = np.asarray(pin.getJointKinematicHessian(tw.pin_model, data, joint, pin.ReferenceFrame.WORLD)).reshape(-1)
    pinocchio = flat.reshape((6, tw.nv, tw.nv), order="F")
    want = np.empty_like(pinocchio)
    want[:, tw.perm_v[:, None], tw.perm_v] = pinocchio
    # The world Jacobian, and so its slope, does not depend on the point.
    assert_close(lk.kinematic_hessian(tw.model, q, body, None, "world"), want, "kinematic Hessian, world")


@examples(40)
@given(tw=twins(), rng=rngs())
def test_point_velocity_hessian_is_the_slope_of_the_velocity_derivative(tw: Twin, rng):
    q, v, _ = state(tw, rng)
    body, point = random_frame(tw, rng)
    weights = rng.normal(size=3)
    note_case(tw, q=q, v=v)

    def slope(x: np.ndarray) -> np.ndarray:
        return weights @ np.asarray(lk.frame_velocity_derivatives(tw.model, x, v, body, point)[0])[:3]

    assert_hessian_of_slope(tw.model, lk.point_velocity_hessian(tw.model, q, v, body, point, weights), slope, q, "d2(F . J v)/dq2")


@examples(40)
@given(tw=twins(max_bodies=40), rng=rngs())
def test_point_acceleration_hessian_is_the_slope_of_the_acceleration_derivatives(tw: Twin, rng):
    assume(tw.nv > 0)  # the stacked differences below need a coordinate
    q, v, a = state(tw, rng)
    body, point = random_frame(tw, rng)
    weights = rng.normal(size=3)
    note_case(tw, q=q, v=v, a=a)

    def slopes(x: np.ndarray, u: np.ndarray = v) -> list[np.ndarray]:  # weights . (d/dq, d/dv, d/da) of a_p
        return [weights @ d[0] for d in point_acceleration_derivatives(tw.model, x[None], u[None], a[None], body, point)]

    def value(x: np.ndarray) -> np.ndarray:
        return weights @ np.asarray(lk.point_accelerations(tw.model, x, v, a, [(body, point)]))[0]

    qq, qv, vv, qa, gradient = lk.point_acceleration_hessian(tw.model, q, v, a, body, point, weights)
    assert_close(gradient, slopes(q)[0], "gradient")
    assert_slopes(gradient, tangent_differences(tw.model, value, q), "d(F . a_p)/dq")
    by_q = tangent_differences(tw.model, lambda x: np.stack(slopes(x)), q)  # [which, e, d]
    assert_slopes(qq, by_q[0], "d2/dq2")
    assert_slopes(qv, by_q[1].T, "d2/dq dv")
    assert_slopes(qa, by_q[2].T, "d2/dq da")
    assert_slopes(vv, coordinate_differences(lambda u: slopes(q, u)[1], v), "d2/dv2")


def test_a_pendulum_bob_in_closed_form():
    """A bob at r below a revolute joint about y: J = r (-cos q, 0, sin q), so dJ/dq = r (sin q, 0, cos q); at joint rate
    w its velocity is w J, and F . w J has second derivative F . w r (cos q, 0, -sin q)."""
    r, q, w = 0.7, 0.4, 1.3
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 1.0, 0.0], np.eye(4), lk.MassProperties.point(2.0, [0.0, 0.0, -r]), "bob")
    bob, force = [0.0, 0.0, -r], np.array([0.3, -0.2, 0.9])
    c, s = np.cos(q), np.sin(q)
    hessian = lk.kinematic_hessian(model, [q], 1, bob)
    assert np.allclose(hessian[:, 0, 0], [r * s, 0.0, r * c, 0.0, 0.0, 0.0], rtol=0, atol=1e-15)
    curvature, gradient = lk.point_velocity_hessian(model, [q], [w], 1, bob, force)
    assert np.allclose(gradient, [force @ (w * r * np.array([s, 0.0, c]))], rtol=0, atol=1e-15)
    assert np.allclose(curvature, [[force @ (w * r * np.array([c, 0.0, -s]))]], rtol=0, atol=1e-15)
    # Its acceleration J a + dJ/dq w^2; F . of it: its slopes in q, in w and in a.
    alpha, turned, bent = 0.8, r * np.array([s, 0.0, c]), r * np.array([c, 0.0, -s])
    qq, qv, vv, qa, gradient = lk.point_acceleration_hessian(model, [q], [w], [alpha], 1, bob, force)
    assert np.allclose(gradient, [force @ (turned * alpha + bent * w**2)], rtol=0, atol=1e-15)
    assert np.allclose(qq, [[force @ (bent * alpha - turned * w**2)]], rtol=0, atol=1e-15)
    assert np.allclose(qv, [[force @ (2.0 * bent * w)]], rtol=0, atol=1e-15)
    assert np.allclose(vv, [[force @ (2.0 * turned)]], rtol=0, atol=1e-15)
    assert np.allclose(qa, [[force @ turned]], rtol=0, atol=1e-15)


def test_shapes_and_bad_arguments():
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1]))
    model.add_revolute(0, [1.0, 0.0, 0.0], np.eye(4), lk.MassProperties.point(1.0, [0.0, 0.0, -0.3]), "leg")
    q = np.tile(np.r_[np.zeros(6), 1.0, 0.0], (4, 1, 1))
    v = np.zeros((1, 3, model.nv))
    assert lk.kinematic_hessian(model, q, "leg").shape == (4, 1, 6, model.nv, model.nv)
    hessian, gradient = lk.point_velocity_hessian(model, q, v, "leg", None, [0.0, 0.0, 1.0])
    assert hessian.shape == (4, 3, model.nv, model.nv) and gradient.shape == (4, 3, model.nv)
    with pytest.raises(ValueError, match="frame"):
        lk.kinematic_hessian(model, q, 1, frame="local")
    with pytest.raises(IndexError, match="foot"):
        lk.kinematic_hessian(model, q, "foot")
    with pytest.raises(ValueError, match="weights"):
        lk.point_velocity_hessian(model, q, v, 1, None, [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="weights"):
        lk.point_velocity_hessian(model, q, v, 1, None, [1.0, 0.0])
    with pytest.raises(ValueError, match="q"):
        lk.kinematic_hessian(model, np.zeros(5), 1)
    parts = lk.point_acceleration_hessian(model, q, v, v, "leg", None, [0.0, 0.0, 1.0])
    assert [p.shape for p in parts] == [(4, 3, model.nv, model.nv)] * 4 + [(4, 3, model.nv)]
    with pytest.raises(ValueError, match="weights"):
        lk.point_acceleration_hessian(model, q, v, v, 1, None, [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="weights"):
        lk.point_acceleration_hessian(model, q, v, v, 1, None, [1.0, 0.0])
    with pytest.raises(ValueError, match=r"^a\b"):
        lk.point_acceleration_hessian(model, q, v, np.zeros(model.nv + 1), 1, None, [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"^a\b"):
        lk.point_acceleration_hessian(model, q, v, np.full(model.nv, np.inf), 1, None, [1.0, 0.0, 0.0])
    with pytest.raises(IndexError, match="body"):
        lk.point_acceleration_hessian(model, q, v, v, 7, None, [1.0, 0.0, 0.0])
