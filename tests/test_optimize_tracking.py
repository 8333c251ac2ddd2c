"""legkit.optimize.tracking: the plan's linearisation against the nonlinear contact model, the swing feet's rise,
and the MPC's contact constraints against the unconstrained LQR's correction."""

from __future__ import annotations

import numpy as np
import pytest

from legkit.experiments.gait import AMBLE_QUADRUPED, QUADRUPED_MOTOR, build_quadruped
from legkit.optimize import effort
from legkit.optimize.gaits import amble_problem, amble_reference, guess_from_reference
from legkit.optimize.replay import phase_of
from legkit.optimize.shooting import tangent_add, tangent_difference
from legkit.optimize.tracking import MPC, TrackingModel, _pyramid, held_step, sampled_reference

DT = 0.01  # a coarse control period keeps the linearisation short


@pytest.fixture(scope="module")
def amble():
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [effort()], 0.67, 1.25, 2, QUADRUPED_MOTOR, max_impulse=0.0)
    trajectory = problem.unpack(problem.pack(guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 2))))
    return problem, trajectory, TrackingModel.build(problem, trajectory, DT, progress=False)


def test_the_linearisation_predicts_the_contact_model_to_second_order(amble):
    problem, _, model = amble
    rng = np.random.default_rng(0)
    nv, nu = problem.nv, problem.nu
    for i in (3, 40, 62, 100):  # 62: the step onto a touchdown (the impact map is part of it)
        direction, du = rng.normal(size=2 * nv), rng.normal(size=nu)
        errors = []
        for scale in (1e-3, 5e-4):
            e = scale * direction
            q = tangent_add(problem, model.q[i][None], e[None, :nv])
            tau = np.zeros((1, nv))
            tau[0, problem.actuated] = model.u[i] + scale * du
            q1, v1, _ = held_step(problem, model.phase[i], model.phase[i + 1], q, model.v[i][None] + e[nv:], tau, model.dt, 4)
            actual = np.concatenate([tangent_difference(problem, problem.configuration(q1), model.q[i + 1][None])[0], v1[0] - model.v[i + 1]])
            predicted = model.residual[i] + model.A[i] @ e + model.B[i] @ (scale * du)
            errors.append(np.linalg.norm(actual - predicted))
        assert errors[1] < 0.35 * errors[0], (i, errors)  # halving the deviation quarters the error: linear to second order


def test_swing_feet_rise_by_the_clearance_at_mid_swing_and_stance_feet_stay(amble):
    problem, trajectory, _ = amble
    t = np.linspace(0.0, 1.25, 251)
    plain, _, _ = sampled_reference(problem, trajectory, t, 0.0)
    raised, _, _ = sampled_reference(problem, trajectory, t, 0.01)
    names = list(problem.feet)
    rise = problem.foot_positions(problem.configuration(raised), names)[..., 2] - problem.foot_positions(problem.configuration(plain), names)[..., 2]
    phase = phase_of(trajectory, t)
    stance = np.array([[name in problem.phases[k].contacts for name in names] for k in phase])
    assert np.max(np.abs(rise[stance])) < 1e-12
    assert 0.008 < np.max(rise[~stance]) <= 0.0101  # damped least squares reaches most of the 1 cm at mid-swing
    assert np.min(rise[~stance]) > -1e-6


def test_pyramid_rows_accept_forces_inside_the_cone_and_reject_the_rest():
    rows = _pyramid(2, 0.6)
    inside = np.array([0.2, -0.3, 1.0, 0.0, 0.0, 5.0])
    assert np.all(rows @ inside >= np.tile([0.0, 0.0, 0.0, 0.0, 0.0], 2))
    assert np.any(rows @ np.array([0.7, 0.0, 1.0, 0.0, 0.0, 5.0]) < 0.0)  # sliding sideways
    assert (rows @ np.array([0.0, 0.0, -1.0, 0.0, 0.0, 5.0]))[0] < 0.0  # pulling


def test_mpc_keeps_the_predicted_forces_where_the_lqr_would_pull(amble):
    problem, _, model = amble
    mpc = MPC(model, horizon=10, block=5, min_normal_force=0.5, friction=0.6)
    gains = model.gains()
    rng = np.random.default_rng(1)
    checked = 0
    for i in range(0, len(model.A), 7):
        e = 0.05 * rng.normal(size=2 * problem.nv)
        lqr = -gains[i] @ e
        pyramid = _pyramid(len(model.forces[i]) // 3, 0.6)
        floor = np.tile([0.5, 0.0, 0.0, 0.0, 0.0], len(model.forces[i]) // 3)

        def predicted(du: np.ndarray, i: int = i, e: np.ndarray = e, pyramid: np.ndarray = pyramid, floor: np.ndarray = floor) -> np.ndarray:
            return pyramid @ (model.forces[i] + model.force_state[i] @ e + model.force_input[i] @ du) - floor

        if np.all(predicted(np.zeros(problem.nu)) >= 0.0) and np.any(predicted(lqr) < -1e-3):
            assert np.all(predicted(mpc.correction(i, e)) >= -1e-6), i
            checked += 1
    assert checked >= 3 and mpc.failures == 0


def test_mpc_corrections_stay_within_the_actuators_torque_bounds_not_the_plans(amble):
    """A plan kept to 70 % of the motors (amble_problem(torque_margin=0.3)) at its bounds: the correction may use the
    motors' remaining 30 % and no more."""
    problem, _, model = amble
    lower, upper = problem.u_bounds
    motors = (lower / 0.7, upper / 0.7)
    mpc = MPC(model, horizon=10, block=5, torque_bounds=motors)
    plain = MPC(model, horizon=10, block=5)
    rng = np.random.default_rng(2)
    solved = beyond = 0
    for i in range(0, len(model.A), 5):
        e = 0.2 * rng.normal(size=2 * problem.nv)
        failures = (mpc.failures, plain.failures)
        torque, planned = model.u[i] + mpc.correction(i, e), model.u[i] + plain.correction(i, e)
        if (mpc.failures, plain.failures) != failures:  # an infeasible QP falls back to the unconstrained LQR
            continue
        solved += 1
        assert np.all(torque >= motors[0] - 1e-6) and np.all(torque <= motors[1] + 1e-6), i
        assert np.all(planned >= lower - 1e-6) and np.all(planned <= upper + 1e-6), i
        beyond += int(np.any((torque < lower - 1e-3) | (torque > upper + 1e-3)))
    assert solved >= 10 and beyond >= 3, (solved, beyond)


def test_torque_margin_scales_the_plans_bounds_and_characteristic_line():
    robot = build_quadruped(AMBLE_QUADRUPED)
    full = amble_problem(robot, [effort()], 0.67, 1.25, 1, QUADRUPED_MOTOR)
    kept = amble_problem(robot, [effort()], 0.67, 1.25, 1, QUADRUPED_MOTOR, torque_margin=0.25)
    np.testing.assert_allclose(kept.u_bounds[1], 0.75 * full.u_bounds[1], rtol=1e-15)
    np.testing.assert_allclose(kept.torque_speed.gain, 0.75 * full.torque_speed.gain, rtol=1e-15)
    assert kept.torque_speed.max_speed == full.torque_speed.max_speed
    for margin in (-0.1, 1.0):
        with pytest.raises(ValueError, match="torque_margin"):
            amble_problem(robot, [effort()], 0.67, 1.25, 1, QUADRUPED_MOTOR, torque_margin=margin)


def test_bad_arguments_fail_naming_them(amble):
    problem, trajectory, model = amble
    with pytest.raises(ValueError, match="horizon"):
        MPC(model, horizon=12, block=5)
    with pytest.raises(ValueError, match="friction"):
        MPC(model, friction=0.0)
    with pytest.raises(ValueError, match="torque_bounds"):
        MPC(model, torque_bounds=(np.ones(problem.nu), -np.ones(problem.nu)))
    with pytest.raises(ValueError, match="torque_bounds"):
        MPC(model, torque_bounds=(-np.ones(3), np.ones(3)))
    with pytest.raises(ValueError, match="dt"):
        TrackingModel.build(problem, trajectory, -1.0)
