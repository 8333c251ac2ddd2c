"""legkit.optimize.shooting: each collocation interval integrated from its knot against the next knot, checked
against legkit's independent kernels (`lk.contact_dynamics`, `lk.point_accelerations`), a motion integrated here
by scipy, and the convergence order of an analytic pendulum motion."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import legkit as lk
from legkit.optimize import MultiphaseProblem, Phase, Trajectory, effort
from legkit.optimize.gaits import walk_problem
from legkit.optimize.kinematics import rotation
from legkit.optimize.shooting import constrained_accelerations, interval_drift
from legkit.robots.biped import build_biped
from legkit.robots.motors import BIPED_MOTOR
from legkit.robots.quadruped import LEGS, build_quadruped

G = lk.STANDARD_GRAVITY


def quadruped_phase(intervals: int, duration: float) -> MultiphaseProblem:
    robot = build_quadruped()
    return MultiphaseProblem(robot.model, [Phase(("lf", "rh"), intervals, (duration, duration))], {leg: robot.feet[leg] for leg in LEGS},
                             [effort()])


def random_states(problem: MultiphaseProblem, count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    q = np.tile(np.asarray(problem.model.neutral(), dtype=np.float64), (count, 1))
    q[:, 7:] = rng.normal(0.0, 0.4, (count, problem.nq - 7))
    q[:, 3:7] = rng.normal(0.0, 0.1, (count, 4)) + [0.0, 0.0, 0.0, 1.0]
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    return q, rng.normal(0.0, 1.0, (count, problem.nv)), rng.normal(0.0, 1.0, (count, problem.nu))


def test_constrained_accelerations_match_contact_dynamics_on_point_feet():
    problem = quadruped_phase(2, 0.2)
    q, v, u = random_states(problem, 6, 0)
    tau = np.zeros((len(q), problem.nv))
    tau[:, problem.actuated] = u
    feet = [(problem.foot_body[name], problem.foot_point[name]) for name in problem.phases[0].contacts]
    expected, _ = lk.contact_dynamics(problem.model, q, v, tau, feet)
    np.testing.assert_allclose(constrained_accelerations(problem, 0, q, v, u), expected, rtol=1e-8, atol=1e-8)


def test_constrained_accelerations_hold_flat_soles_and_balance_the_forces():
    # The biped's flat sole is held by partial rows (centre xyz, toe yz, side z): no kernel holds exactly those, so
    # check the two defining properties with independent kernels: the held rows do not accelerate, and
    # M a + h - tau lies in the span of the held rows' Jacobian (the contact forces).
    problem = walk_problem(build_biped(), 0.5, BIPED_MOTOR, (1, 2))
    k = next(k for k, phase in enumerate(problem.phases) if len(phase.contacts) == 1)
    q, v, u = random_states(problem, 4, 1)
    a = constrained_accelerations(problem, k, q, v, u)
    for body, point, axes in problem.contact_rows(problem.phases[k].contacts):
        held = np.asarray(lk.point_accelerations(problem.model, q, v, a, [(body, point)]))[:, 0, axes]
        np.testing.assert_allclose(held, 0.0, atol=1e-8)
    tau = np.zeros_like(v)
    tau[:, problem.actuated] = u
    residual = np.asarray(lk.rnea(problem.model, q, v, a)) - tau
    jac = problem.contact_jacobian(q, problem.phases[k].contacts)
    for r, j in zip(residual, jac):
        forces, *_ = np.linalg.lstsq(j.T, r, rcond=None)
        np.testing.assert_allclose(j.T @ forces, r, atol=1e-8 * max(1.0, np.abs(r).max()))


def test_a_motion_of_the_model_does_not_drift():
    # A motion with two feet held, integrated here by scipy (quaternion kinematics written out, accelerations from
    # lk.contact_dynamics) under constant torques and sampled at the collocation points: it meets every knot.
    duration, intervals = 0.06, 3
    problem = quadruped_phase(intervals, duration)
    q0, v0, u = random_states(problem, 1, 2)
    feet = [(problem.foot_body[name], problem.foot_point[name]) for name in problem.phases[0].contacts]
    jac = problem.contact_jacobian(q0, problem.phases[0].contacts)[0]
    v0 = v0[0] - np.linalg.pinv(jac) @ (jac @ v0[0])  # the held feet start at rest
    tau = np.zeros(problem.nv)
    tau[problem.actuated] = 0.1 * u[0]
    nq = problem.nq

    def rate(_: float, state: np.ndarray) -> np.ndarray:
        q, v = state[:nq].copy(), state[nq:]
        q[3:7] /= np.linalg.norm(q[3:7])
        x, y, z, w = q[3:7]
        wx, wy, wz = v[3:6]
        quaternion_rate = 0.5 * np.array([w * wx + y * wz - z * wy, w * wy + z * wx - x * wz, w * wz + x * wy - y * wx, -x * wx - y * wy - z * wz])
        a, _ = lk.contact_dynamics(problem.model, q, v, tau, feet)
        return np.concatenate([rotation(q[3:7]) @ v[:3], quaternion_rate, v[6:], a])

    t = np.linspace(0.0, duration, 2 * intervals + 1)
    motion = solve_ivp(rate, (0.0, duration), np.concatenate([q0[0], v0]), t_eval=t, rtol=1e-11, atol=1e-12, method="DOP853")
    states = motion.y.T
    forces = np.zeros((len(t), 2, 3))
    x = problem.pack(Trajectory([t], [states[:, :nq]], [states[:, nq:]], [np.tile(tau[problem.actuated], (len(t), 1))], [forces],
                                np.array([duration])))
    drift = interval_drift(problem, x, substeps=256)  # light legs under random torques: fast, RK4 needs the steps
    assert np.max(np.abs(np.concatenate(drift.configuration))) < 1e-8
    assert np.max(np.abs(np.concatenate(drift.velocity))) < 1e-6
    # A wrong torque over the same knots drifts by what it accelerates.
    x_wrong = x.copy()
    x_wrong[problem.point_index[0][:, problem.nx]] += 1.0
    assert np.max(np.abs(np.concatenate(interval_drift(problem, x_wrong).velocity))) > 1e-3


def pendulum() -> lk.Model:
    model = lk.Model(floating_base=False, gravity=[0.0, 0.0, -G])
    model.add_revolute(0, [0.0, 1.0, 0.0], None, lk.MassProperties.point(1.0, [0.0, 0.0, -0.5]), "rod")
    return model


def test_drift_of_an_exact_trajectory_converges_at_the_order_of_linear_controls():
    # theta(t) = sin(2t) with its inverse-dynamics torques at the points: the knots are exact, so the drift is the
    # controls' linear interpolation alone, whose error is O(h^2) over each half interval: integrated once, the rate
    # drifts by O(h^3) per interval, the angle by O(h^4); halving h divides them by about 8 and 16.
    model = pendulum()
    worst = []
    for intervals in (8, 16):
        problem = MultiphaseProblem(model, [Phase((), intervals, (1.0, 1.0))], objectives=[effort()])
        s = np.linspace(0.0, 1.0, 2 * intervals + 1)
        q, v, a = np.sin(2 * s)[:, None], 2 * np.cos(2 * s)[:, None], -4 * np.sin(2 * s)[:, None]
        u = np.asarray(lk.rnea(model, q, v, a))
        x = problem.pack(Trajectory([s], [q], [v], [u], [np.zeros((len(s), 0, 3))], np.array([1.0])))
        drift = interval_drift(problem, x, substeps=64)
        worst.append([np.max(np.abs(drift.configuration[0])), np.max(np.abs(drift.velocity[0]))])
    ratio = np.array(worst[0]) / np.array(worst[1])
    assert worst[0][1] > 1e-6  # the check below measures something
    assert 12.0 < ratio[0] < 20.0, ratio
    assert 6.0 < ratio[1] < 10.0, ratio


def test_bad_substeps_fail_naming_the_argument():
    problem = quadruped_phase(1, 0.1)
    with pytest.raises(ValueError, match="substeps"):
        interval_drift(problem, np.zeros(problem.n), substeps=0)


def test_an_interval_that_blows_up_drifts_by_inf_without_warnings():
    problem = MultiphaseProblem(pendulum(), [Phase((), 2, (1.0, 1.0))], objectives=[effort()])
    s = np.linspace(0.0, 1.0, 5)
    u = np.array([[0.0], [0.0], [0.0], [1e9], [1e9]])  # the second interval's torque spins the rod past any rate
    x = problem.pack(Trajectory([s], [np.zeros((5, 1))], [np.zeros((5, 1))], [u], [np.zeros((5, 0, 3))], np.array([1.0])))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        drift = interval_drift(problem, x)
    assert np.all(np.isfinite(drift.velocity[0][0])) and np.all(np.isinf(drift.velocity[0][1]))
    assert np.isinf(drift.worst(False)["joint rates"])
