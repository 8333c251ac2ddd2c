"""legkit.optimize.kinematics: the transcription's contact kinematics and their derivatives in the raw variables
(a free-flyer's quaternion of any norm), from the core's analytic derivatives, against central differences of the
kernels' values written here."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

import legkit as lk
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import kinematics as kin
from legkit.optimize.collocation import complex_step_jacobian
from legkit.optimize.gaits import amble_plan_problem, amble_reference, guess_from_reference
from legkit.robots.biped import build_biped
from legkit.robots.quadruped import build_quadruped

STEP = 1e-6  # central differences: truncation ~STEP^2, rounding ~1e-16 / STEP; both far below the tolerance
TOLERANCE = 1e-7


def central(function: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """(B, ..., n): d function / dx column by column, each row of the batch x (B, n) on its own."""
    columns = []
    for j in range(x.shape[1]):
        plus, minus = x.copy(), x.copy()
        plus[:, j] += STEP
        minus[:, j] -= STEP
        columns.append((function(plus) - function(minus)) / (2.0 * STEP))
    return np.stack(columns, axis=-1)


@pytest.fixture(scope="module", params=["quadruped", "biped"])
def case(request):
    robot = build_quadruped() if request.param == "quadruped" else build_biped()
    model = robot.model
    rng = np.random.default_rng(7)
    q = np.tile(np.asarray(model.neutral(), dtype=np.float64), (3, 1)) + rng.normal(0.0, 0.2, (3, model.nq))
    q[:, 3:7] *= 1.4  # the raw quaternion's norm is not 1
    v, a = rng.normal(0.0, 1.0, (3, model.nv)), rng.normal(0.0, 1.0, (3, model.nv))
    body = model.nbodies - 1
    return model, q, v, a, body, np.array([0.02, -0.01, -0.05]), rng


def test_tangent_map_turns_kernel_derivatives_into_raw_ones(case):
    model, q, v, a, body, point, _ = case

    def position(raw: np.ndarray) -> np.ndarray:
        pose = np.asarray(lk.forward_kinematics(model, kin.unit(model, raw)))[:, body]
        return pose[:, :3, :3] @ point + pose[:, :3, 3]

    jac = kin.point_jacobians(model, kin.unit(model, q), [(body, point)])[:, 0, :3]
    np.testing.assert_allclose(kin.raw(model, q, jac), central(position, q), atol=TOLERANCE)
    # the quaternion's norm is invisible: its radial direction maps to zero
    radial = np.zeros_like(q)
    radial[:, 3:7] = q[:, 3:7]
    np.testing.assert_allclose(np.einsum("bij,bj->bi", kin.tangent_map(model, q), radial), 0.0, atol=1e-14)


def test_q_rate_derivatives_match_central_differences(case):
    model, q, v, *_ = case
    by_q, by_v = kin.q_rate_derivatives(model, q, v)
    np.testing.assert_allclose(by_q, central(lambda x: kin.q_rate(model, x, v), q), atol=TOLERANCE)
    np.testing.assert_allclose(by_v, central(lambda x: kin.q_rate(model, q, x), v), atol=TOLERANCE)


def test_q_rate_hessian_matches_central_differences_of_its_slopes(case):
    model, q, v, _, _, _, rng = case
    weights = rng.normal(size=q.shape)
    state = np.concatenate([q, v], axis=1)

    def slopes(x: np.ndarray) -> np.ndarray:
        by_q, by_v = kin.q_rate_derivatives(model, x[:, : model.nq], x[:, model.nq :])
        return np.concatenate([kin.vecmat(weights, by_q), kin.vecmat(weights, by_v)], axis=1)

    hessian = kin.q_rate_hessian(model, q, v, weights)
    np.testing.assert_allclose(hessian, central(slopes, state), atol=TOLERANCE)
    np.testing.assert_allclose(hessian, np.swapaxes(hessian, 1, 2), atol=1e-14)


def test_raw_position_curvature_matches_central_differences_of_the_raw_gradient(case):
    """`position_curvature` (the core's kinematic Hessian through `raw_hessian`) against differences of the raw
    gradient w . J_lin (tangent_map), the quaternion of any norm."""
    model, q, _, _, body, point, rng = case
    points, weights = [(body, point), (1, -point)], rng.normal(size=(len(q), 2, 3))

    def gradient(raw: np.ndarray) -> np.ndarray:
        linear = kin.point_jacobians(model, kin.unit(model, raw), points)[:, :, :3]
        return kin.raw(model, raw, np.einsum("bcr,bcra->ba", weights, linear)[:, None])[:, 0]

    hessian, slope = kin.position_curvature(model, q, points, weights)
    np.testing.assert_allclose(slope, gradient(q), atol=1e-14)
    np.testing.assert_allclose(hessian, central(gradient, q), atol=TOLERANCE)
    np.testing.assert_allclose(hessian, np.swapaxes(hessian, 1, 2), atol=1e-12)


def test_point_velocity_and_acceleration_derivatives_match_central_differences(case):
    model, q, v, a, body, point, _ = case
    unit = kin.unit(model, q)

    def velocity(raw: np.ndarray, speed: np.ndarray = v) -> np.ndarray:
        return np.einsum("bij,bj->bi", np.asarray(lk.jacobian(model, kin.unit(model, raw), body, point))[:, :3], speed)

    def acceleration(raw: np.ndarray, speed: np.ndarray = v, rate: np.ndarray = a) -> np.ndarray:
        return np.asarray(lk.point_accelerations(model, kin.unit(model, raw), speed, rate, [(body, point)]))[:, 0]

    by_q, by_v = kin.point_velocity_derivatives(model, unit, v, body, point)
    np.testing.assert_allclose(kin.raw(model, q, by_q), central(velocity, q), atol=TOLERANCE)
    np.testing.assert_allclose(by_v, central(lambda x: velocity(q, x), v), atol=TOLERANCE)
    by_q, by_v, by_a = kin.point_acceleration_derivatives(model, unit, v, a, body, point)
    np.testing.assert_allclose(kin.raw(model, q, by_q), central(acceleration, q), atol=TOLERANCE)
    np.testing.assert_allclose(by_v, central(lambda x: acceleration(q, x), v), atol=TOLERANCE)
    np.testing.assert_allclose(by_a, central(lambda x: acceleration(q, v, x), a), atol=TOLERANCE)


def test_force_and_mass_slopes_match_central_differences(case):
    model, q, _, _, body, point, rng = case
    points = [(body, point), (1, np.array([0.1, 0.0, 0.0]))]
    forces, w = rng.normal(0.0, 5.0, (len(q), 2, 3)), rng.normal(0.0, 1.0, (len(q), model.nv))

    def generalized(raw: np.ndarray) -> np.ndarray:  # sum_c J_c^T F_c with F_c held in world axes
        return np.einsum("bcki,bck->bi", kin.point_jacobians(model, kin.unit(model, raw), points)[:, :, :3], forces)

    def momentum(raw: np.ndarray) -> np.ndarray:
        return np.einsum("bij,bj->bi", np.asarray(lk.crba(model, kin.unit(model, raw))), w)

    unit = kin.unit(model, q)
    np.testing.assert_allclose(kin.raw(model, q, kin.force_slope(model, unit, points, forces)), central(generalized, q),
                               atol=TOLERANCE * 10)  # forces of ~5 N scale the rounding
    np.testing.assert_allclose(kin.raw(model, q, kin.mass_slope(model, unit, w)), central(momentum, q), atol=TOLERANCE)


def test_complex_steps_differentiate_closed_form_algebra_exactly():
    # f(z) = (sqrt(z0^2 + z1^2), z0 z2 / z1) and its Jacobian written here; no difference is taken, so rounding alone.
    z = np.random.default_rng(4).uniform(0.5, 2.0, (7, 3))

    def f(z: np.ndarray) -> np.ndarray:
        return np.stack([np.sqrt(z[:, 0] ** 2 + z[:, 1] ** 2), z[:, 0] * z[:, 2] / z[:, 1]], axis=1)

    r = np.hypot(z[:, 0], z[:, 1])
    expected = np.zeros((7, 2, 3))
    expected[:, 0, 0], expected[:, 0, 1] = z[:, 0] / r, z[:, 1] / r
    expected[:, 1, 0], expected[:, 1, 1], expected[:, 1, 2] = z[:, 2] / z[:, 1], -z[:, 0] * z[:, 2] / z[:, 1] ** 2, z[:, 0] / z[:, 1]
    np.testing.assert_allclose(complex_step_jacobian(f, z, np.arange(3)), expected, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(complex_step_jacobian(f, z, np.array([2, 0])), expected[:, :, [2, 0]], rtol=1e-14, atol=1e-15)


@pytest.fixture(scope="module")
def amble():
    """The 16-interval amble `legkit gait --optimize` solves, and its reference's variables."""
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_plan_problem(robot, 16)
    return problem, problem.pack(guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 16)))


@pytest.mark.parametrize("name", ["_smooth_margin.<locals>.margin", "stance_blocks.<locals>.accelerations",
                                  "velocity_transition.<locals>.<lambda>"])
def test_block_curvature_matches_central_differences_of_its_jacobian(amble, name):
    """A block's exact curvature (`Point.curvature`, from the core's second-order kernels) against central differences
    of its exact Jacobian, weighted, and that Jacobian against differences of its values, at random points near the
    amble's reference (the quaternion of any norm)."""
    problem, x = amble
    rng = np.random.default_rng(11)
    blocks = [b for b in problem.blocks if getattr(getattr(b, "function", None), "__qualname__", "") == name]
    assert blocks, name
    for block in blocks:
        z = x[block.index][rng.choice(len(block.index), min(3, len(block.index)), replace=False)]
        z = z + rng.normal(0.0, 0.05, z.shape)
        weights = rng.normal(size=(len(z), block.outputs))
        slope_differences = central(lambda zz, w=weights, b=block: np.einsum("br,brk->bk", w, b.derivative(zz)), z)
        for got, want in [(block.curvature(z, weights), slope_differences), (block.derivative(z), central(block.function, z))]:
            scale = max(1.0, float(np.abs(want).max()))
            assert np.abs(got - want).max() <= TOLERANCE * scale, (name, np.abs(got - want).max(), scale)
