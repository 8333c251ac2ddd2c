"""Frame kinematics and their derivatives (``lk.frame_velocity``, ``lk.frame_acceleration``, their ``_derivatives``, and
``lk.jacobian_time_variation``).

Against Pinocchio (``getFrameVelocity``, ``getFrameAcceleration``, ``getFrameAccelerationDerivatives``,
``getFrameJacobianTimeVariation``) on random trees with every joint kind, in the three frames, at 1e-9 relative; in
"local_world_aligned" Pinocchio's q-derivatives hold the frame's origin still, and the test adds back the terms that
its motion contributes (w x J_lin to the velocity's, alpha x J_lin to the acceleration's). Against five-point central
differences of legkit's own kernels, q stepped by ``lk.integrate``; and in closed form on a pendulum.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given

import legkit as lk
from conftest import examples
from robots import Twin, rngs, twins
from test_derivatives import assert_slopes, coordinate_differences, tangent_differences
from test_dynamics_pinocchio import FRAMES, assert_close, note_case, state


def random_frame(tw: Twin, rng: np.random.Generator) -> tuple[int, np.ndarray]:
    return int(rng.integers(tw.nbodies)), rng.uniform(-0.5, 0.5, size=3)


def held_origin(rows: np.ndarray, angular: np.ndarray, jacobian: np.ndarray) -> np.ndarray:
    """Pinocchio's "local_world_aligned" q-derivative with the frame origin's motion added back: + angular x J_lin."""
    out = np.array(rows)
    out[:3] += np.cross(angular, jacobian[:3].T).T
    return out


@examples(60)
@given(tw=twins(), rng=rngs())
def test_frame_kinematics_and_derivatives_match_pinocchio(tw: Twin, rng):
    q, v, a = state(tw, rng)
    body, point = random_frame(tw, rng)
    note_case(tw, q=q, v=v, a=a)
    fid = tw.add_pin_frame(body, point)
    qp, vp, ap = tw.q_pin(q), tw.v_pin(v), tw.v_pin(a)
    data, derivatives, rates = tw.data(), tw.data(), tw.data()
    pin.forwardKinematics(tw.pin_model, data, qp, vp, ap)
    pin.computeForwardKinematicsDerivatives(tw.pin_model, derivatives, qp, vp, ap)
    pin.computeJointJacobiansTimeVariation(tw.pin_model, rates, qp, vp)
    pin.updateFramePlacements(tw.pin_model, rates)
    for name, rf in FRAMES.items():
        args = (tw.model, q, v)
        velocity, acceleration = lk.frame_velocity(*args, body, point, name), lk.frame_acceleration(*args, a, body, point, name)
        assert_close(velocity, pin.getFrameVelocity(tw.pin_model, data, fid, rf).vector, f"velocity, {name}")
        assert_close(acceleration, pin.getFrameAcceleration(tw.pin_model, data, fid, rf).vector, f"acceleration, {name}")
        want = [tw.cols_lk(np.array(x)) for x in pin.getFrameAccelerationDerivatives(tw.pin_model, derivatives, fid, rf)]
        jacobian = lk.jacobian(tw.model, q, body, point, name)
        if name == "local_world_aligned":
            want[0] = held_origin(want[0], velocity[3:], jacobian)
            want[1] = held_origin(want[1], acceleration[3:], jacobian)
        got = lk.frame_acceleration_derivatives(*args, a, body, point, name)
        for g, w, what in zip(got, want, ("dv/dq", "da/dq", "da/dv", "da/da")):
            if what == "da/dq" and name != "local" and tw.quaternions:
                # Pinocchio's WORLD (and so LOCAL_WORLD_ALIGNED) da/dq below a spherical joint is not the slope of its own
                # getFrameAcceleration (off by O(1) where central differences agree with legkit's to 1e-8); the slopes
                # test checks legkit's.
                continue
            assert_close(g, w, f"{what}, {name}")
        v_dq, v_dv = lk.frame_velocity_derivatives(*args, body, point, name)
        assert_close(v_dq, want[0], f"dv/dq alone, {name}")
        assert_close(v_dv, jacobian, f"dv/dv = J, {name}")
        if tw.nv:  # Pinocchio's getFrameJacobianTimeVariation crashes on a model without degrees of freedom
            rate = tw.cols_lk(np.array(pin.getFrameJacobianTimeVariation(tw.pin_model, rates, fid, rf)))
            assert_close(lk.jacobian_time_variation(*args, body, point, name), rate, f"dJ/dt, {name}")


def assert_frame_slopes(m: lk.Model, q, v, a, body: int, point, name: str) -> None:
    v_dq, a_dq, a_dv, a_da = lk.frame_acceleration_derivatives(m, q, v, a, body, point, name)
    assert_slopes(v_dq, tangent_differences(m, lambda x: lk.frame_velocity(m, x, v, body, point, name), q), f"dv/dq, {name}")
    assert_slopes(a_dq, tangent_differences(m, lambda x: lk.frame_acceleration(m, x, v, a, body, point, name), q), f"da/dq, {name}")
    assert_slopes(a_dv, coordinate_differences(lambda x: lk.frame_acceleration(m, q, x, a, body, point, name), v), f"da/dv, {name}")
    assert_slopes(a_da, coordinate_differences(lambda x: lk.frame_acceleration(m, q, v, x, body, point, name), a), f"da/da, {name}")
    # dJ/dt is the Jacobian's slope along q (+) t v.
    rate = coordinate_differences(lambda t: lk.jacobian(m, lk.integrate(m, q, v, t[0]), body, point, name), np.zeros(1))[..., 0]
    assert_slopes(lk.jacobian_time_variation(m, q, v, body, point, name), rate, f"dJ/dt, {name}")


@examples(30)
@given(tw=twins(max_bodies=30), rng=rngs())
def test_frame_derivatives_are_the_slopes_of_the_frame_kinematics(tw: Twin, rng):
    q, v, a = state(tw, rng)
    body, point = random_frame(tw, rng)
    note_case(tw, q=q, v=v, a=a)
    for name in FRAMES:
        assert_frame_slopes(tw.model, q, v, a, body, point, name)


def test_a_pendulum_bob_in_closed_form():
    """A bob at r below a revolute joint about y turning at w: its world position is (-r sin q, 0, -r cos q), its velocity
    r w (-cos q, 0, sin q), its classical acceleration r a (-cos q, 0, sin q) + r w^2 (sin q, 0, cos q)."""
    r, q, w, a = 0.7, 0.4, 1.3, -0.6
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 1.0, 0.0], np.eye(4), lk.MassProperties.point(2.0, [0.0, 0.0, -r]), "bob")
    bob = [0.0, 0.0, -r]
    c, s = np.cos(q), np.sin(q)
    velocity = lk.frame_velocity(model, [q], [w], 1, bob)
    assert np.allclose(velocity, [-r * w * c, 0.0, r * w * s, 0.0, w, 0.0], rtol=0, atol=1e-15)
    spatial = lk.frame_acceleration(model, [q], [w], [a], 1, bob)
    classical = spatial[:3] + np.cross(velocity[3:], velocity[:3])
    assert np.allclose(classical, r * a * np.array([-c, 0.0, s]) + r * w**2 * np.array([s, 0.0, c]), rtol=0, atol=1e-14)
    v_dq, v_dv = lk.frame_velocity_derivatives(model, [q], [w], 1, bob)
    assert np.allclose(v_dq[:3, 0], [r * w * s, 0.0, r * w * c], rtol=0, atol=1e-15)
    assert np.allclose(v_dv[:3, 0], [-r * c, 0.0, r * s], rtol=0, atol=1e-15)
    # J = r (-cos q, 0, sin q): dJ/dt = r w (sin q, 0, cos q).
    assert np.allclose(lk.jacobian_time_variation(model, [q], [w], 1, bob)[:3, 0], [r * w * s, 0.0, r * w * c], rtol=0, atol=1e-15)


def test_shapes_and_bad_arguments():
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1]))
    model.add_revolute(0, [1.0, 0.0, 0.0], np.eye(4), lk.MassProperties.point(1.0, [0.0, 0.0, -0.3]), "leg")
    q = np.tile(np.r_[np.zeros(6), 1.0, 0.0], (4, 1, 1))
    v, a = np.zeros((1, 3, model.nv)), np.zeros(model.nv)
    assert lk.frame_velocity(model, q, v, "leg").shape == (4, 3, 6)
    assert [x.shape for x in lk.frame_acceleration_derivatives(model, q, v, a, "leg")] == [(4, 3, 6, model.nv)] * 4
    assert lk.jacobian_time_variation(model, q, v, 1).shape == (4, 3, 6, model.nv)
    with pytest.raises(IndexError, match="foot"):
        lk.frame_velocity(model, q, v, "foot")
    with pytest.raises(ValueError, match="frame"):
        lk.frame_velocity(model, q, v, 1, frame="base")
    with pytest.raises(ValueError, match="point"):
        lk.frame_velocity_derivatives(model, q, v, 1, point=[np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="a"):
        lk.frame_acceleration(model, q, v, np.zeros(3), 1)
    with pytest.raises(ValueError, match="q"):
        lk.jacobian_time_variation(model, np.zeros(5), v, 1)
