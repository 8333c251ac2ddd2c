"""legkit.optimize.tracking: the plan's analytic linearisation against central differences of the nonlinear contact
model, the swing feet's rise, the MPC's solution against a dense QP built and solved independently, its contact
constraints against the unconstrained LQR's correction, and (slow) the MPC holding an optimised amble for 5 cycles,
also with 10 % more mass in the simulated robot than in its model."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import legkit as lk
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import effort
from legkit.optimize.gaits import amble_plan_problem, amble_problem, amble_reference, guess_from_reference, stall_torque_bounds
from legkit.optimize.replay import phase_of
from legkit.optimize.tracking import MPC, TrackingModel, force_rows, heavier, held_step, sampled_reference, track
from legkit.robots.motors import QUADRUPED_MOTOR
from legkit.robots.quadruped import build_quadruped

DT = 0.01  # a coarse control period keeps the linearisation short


@pytest.fixture(scope="module")
def amble():
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [effort()], 0.67, 1.25, 2, QUADRUPED_MOTOR, max_impulse=0.0)
    trajectory = problem.unpack(problem.pack(guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 2))))
    return problem, trajectory, TrackingModel.build(problem, trajectory, DT)


def stepped(problem, model, i, x):
    """(deviation after one control period, forces at its start) of `held_step` from the reference at sample i moved
    by x = (dq, dv, du): the brute-force reference for the linearisation."""
    nv = problem.nv
    q = np.asarray(lk.integrate(problem.model, model.q[i], x[:nv], 1.0))[None]
    tau = np.zeros((1, nv))
    tau[0, problem.actuated] = model.u[i] + x[2 * nv :]
    q1, v1, f = held_step(problem, model.phase[i], model.phase[i + 1], q, model.v[i][None] + x[nv : 2 * nv], tau, model.dt, 4)
    return np.concatenate([np.asarray(lk.difference(problem.model, model.q[i + 1], q1[0])), v1[0] - model.v[i + 1]]), f[0]


def _touchdown(model):
    return int(np.flatnonzero(np.diff(model.phase[:-1]))[0])  # the step onto a touchdown: the impact map is in it


def test_the_analytic_linearisation_equals_central_differences_of_the_contact_model(amble):
    problem, _, model = amble
    n, columns, step = 2 * problem.nv, 2 * problem.nv + problem.nu, 1e-6
    for i in (3, 40, _touchdown(model), 100):
        plus = [stepped(problem, model, i, step * np.eye(columns)[c]) for c in range(columns)]
        minus = [stepped(problem, model, i, -step * np.eye(columns)[c]) for c in range(columns)]
        state = np.stack([(p[0] - m[0]) / (2 * step) for p, m in zip(plus, minus)], axis=1)
        forces = np.stack([(p[1] - m[1]) / (2 * step) for p, m in zip(plus, minus)], axis=1)
        held = 3 * int(np.sum(model.held[i]))
        np.testing.assert_allclose(model.residual[i], stepped(problem, model, i, np.zeros(columns))[0], atol=1e-12)
        np.testing.assert_allclose(np.concatenate([model.A[i], model.B[i]], axis=1), state, atol=1e-6 * max(1.0, np.abs(state).max()))
        np.testing.assert_allclose(np.concatenate([model.force_state[i], model.force_input[i]], axis=1)[:held], forces,
                                   atol=1e-6 * max(1.0, np.abs(forces).max()))
        assert np.all(model.force_state[i][held:] == 0.0) and np.abs(model.A[i]).max() > 1.0
        assert n == model.A.shape[1]


def test_the_linearisation_predicts_the_contact_model_to_second_order(amble):
    problem, _, model = amble
    rng = np.random.default_rng(0)
    for i in (3, 40, _touchdown(model), 100):
        x = rng.normal(size=2 * problem.nv + problem.nu)
        errors = []
        for scale in (1e-3, 5e-4):
            actual, _ = stepped(problem, model, i, scale * x)
            predicted = model.residual[i] + model.A[i] @ (scale * x[: 2 * problem.nv]) + model.B[i] @ (scale * x[2 * problem.nv :])
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


def _cone(feet: int, friction: float) -> np.ndarray:
    """Rows r with r . f >= (floor, 0, 0, 0, 0) per point foot: f_z, then mu f_z -+ f_x, mu f_z -+ f_y."""
    rows = np.zeros((5 * feet, 3 * feet))
    for foot in range(feet):
        x, y, z = 3 * foot, 3 * foot + 1, 3 * foot + 2
        r = rows[5 * foot : 5 * foot + 5]
        r[:, z] = [1.0, friction, friction, friction, friction]
        r[1, x], r[2, x], r[3, y], r[4, y] = -1.0, 1.0, -1.0, 1.0
    return rows


def test_force_rows_of_point_feet_are_the_friction_pyramid_of_each_held_foot(amble):
    _, _, model = amble
    rows, per_foot = force_rows(model, 0.6)
    assert per_foot == 5
    for i in range(len(model.A)):
        held = int(np.sum(model.held[i]))
        np.testing.assert_array_equal(rows[i, : 5 * held, : 3 * held], _cone(held, 0.6))
        assert not np.any(rows[i, 5 * held :]) and not np.any(rows[i, :, 3 * held :])
    inside = np.array([0.2, -0.3, 1.0, 0.0, 0.0, 5.0])
    assert np.all(_cone(2, 0.6) @ inside >= 0.0)
    assert np.any(_cone(2, 0.6) @ np.array([0.7, 0.0, 1.0, 0.0, 0.0, 5.0]) < 0.0)  # sliding sideways
    assert (_cone(2, 0.6) @ np.array([0.0, 0.0, -1.0, 0.0, 0.0, 5.0]))[0] < 0.0  # pulling


def _mul(matrix: np.ndarray, x):
    return ca.mtimes(ca.DM(matrix), x)


def _dense_reference(mpc: MPC, i: int, e: np.ndarray) -> np.ndarray:
    """The MPC's QP at instant i built step by step, states and slacks as variables (no condensing), solved by
    qpOASES: the first block's correction."""
    m, nu, n = mpc.model, mpc.model.B.shape[2], 2 * mpc.model.problem.nv
    opti = ca.Opti("conic")
    U = [opti.variable(nu) for _ in mpc.blocks]
    cost, state, step = 0, ca.DM(e), 0
    for p, length in enumerate(mpc.blocks):
        k = (i + step) % mpc.count
        opti.subject_to(opti.bounded(mpc.torque_lower - m.u[k], U[p], mpc.torque_upper - m.u[k]))
        cost += 0.5 * length * ca.dot(m.torque_weights * U[p], U[p])
        for foot in np.flatnonzero(m.held[k]):
            rows = _cone(1, mpc.friction)
            rows3 = slice(3 * foot, 3 * foot + 3)
            force = m.forces[k, rows3] + _mul(m.force_state[k, rows3], state) + _mul(m.force_input[k, rows3], U[p])
            slack = opti.variable(5)
            opti.subject_to(slack >= 0)
            opti.subject_to(_mul(rows, force) + slack >= np.array([mpc.min_normal_force, 0, 0, 0, 0]))
            cost += 0.5 * mpc.slack_weight * ca.sumsqr(slack)
        for _ in range(length):
            k = (i + step) % mpc.count
            state = _mul(m.A[k], state) + _mul(m.B[k], U[p]) + m.residual[k]
            step += 1
            end = (i + step) % mpc.count
            for foot in np.flatnonzero(m.swing[end]):
                slack = opti.variable()
                opti.subject_to(slack >= 0)
                h = m.heights[end, foot]
                opti.subject_to(h + _mul(m.height_state[end, foot][None], state) + slack >= min(mpc.min_swing_height, h))
                cost += 0.5 * mpc.slack_weight * slack**2
            weights = m.cost_to_go[end] if step == sum(mpc.blocks) else np.diag(m.state_weights)
            cost += 0.5 * ca.dot(state, ca.mtimes(weights, state))
    assert n == len(e)
    opti.minimize(cost)
    opti.solver("qpoases", {"printLevel": "none"})
    return np.asarray(opti.solve().value(U[0])).ravel()


def test_the_mpc_solves_its_qp_as_a_dense_qp_solver_does(amble):
    problem, _, model = amble
    mpc = MPC(model, blocks=(2, 2, 4), slack_weight=1e3, swing_tolerance=0.0, torque_bounds=(-0.3 * np.ones(problem.nu), 0.3 * np.ones(problem.nu)))
    rng = np.random.default_rng(3)
    constrained = 0
    for i in range(0, len(model.A), 9):
        e = 0.05 * rng.normal(size=2 * problem.nv)
        solved = mpc.solved
        correction = mpc.correction(i, e)
        constrained += mpc.solved - solved
        np.testing.assert_allclose(correction, _dense_reference(mpc, i, e), atol=1e-6, err_msg=f"instant {i}")
    assert constrained >= 5  # most of these needed the constrained solve, not just the unconstrained minimiser


def test_mpc_keeps_the_predicted_forces_where_the_lqr_would_pull(amble):
    problem, _, model = amble
    mpc = MPC(model, blocks=(5, 5), min_normal_force=0.5, friction=0.6)
    gains = model.gains()
    rng = np.random.default_rng(1)
    checked = 0
    for i in range(0, len(model.A), 7):
        e = 0.05 * rng.normal(size=2 * problem.nv)
        lqr = -gains[i] @ e
        held = int(np.sum(model.held[i]))
        pyramid = _cone(held, 0.6)
        floor = np.tile([0.5, 0.0, 0.0, 0.0, 0.0], held)

        def predicted(du: np.ndarray, i: int = i, e: np.ndarray = e, pyramid: np.ndarray = pyramid, floor: np.ndarray = floor,
                      rows: int = 3 * held) -> np.ndarray:
            return pyramid @ (model.forces[i, :rows] + model.force_state[i, :rows] @ e + model.force_input[i, :rows] @ du) - floor

        if np.all(predicted(np.zeros(problem.nu)) >= 0.0) and np.any(predicted(lqr) < -1e-3):
            assert np.all(predicted(mpc.correction(i, e)) >= -1e-4), i  # soft rows: slack weight 1e6
            checked += 1
    assert checked >= 3


def test_mpc_corrections_stay_within_the_actuators_torque_bounds_not_the_plans(amble):
    """A plan kept to 70 % of the motors (amble_problem(torque_margin=0.3)) at its bounds: the correction may use the
    motors' remaining 30 % and no more."""
    problem, _, model = amble
    lower, upper = problem.u_bounds
    motors = (lower / 0.7, upper / 0.7)
    mpc = MPC(model, blocks=(5, 5), torque_bounds=motors)
    plain = MPC(model, blocks=(5, 5))
    rng = np.random.default_rng(2)
    beyond = 0
    for i in range(0, len(model.A), 5):
        e = 0.2 * rng.normal(size=2 * problem.nv)
        torque, planned = model.u[i] + mpc.correction(i, e), model.u[i] + plain.correction(i, e)
        assert np.all(torque >= motors[0] - 1e-9) and np.all(torque <= motors[1] + 1e-9), i
        assert np.all(planned >= lower - 1e-9) and np.all(planned <= upper + 1e-9), i
        beyond += int(np.any((torque < lower - 1e-3) | (torque > upper + 1e-3)))
    assert beyond >= 3, beyond


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


def test_heavier_scales_every_body_and_nothing_else(amble):
    problem, _, _ = amble
    plant = heavier(problem.model, 1.1)
    assert plant.total_mass == pytest.approx(1.1 * problem.model.total_mass, rel=1e-12)
    body = next(b for b in range(problem.model.nbodies) if problem.model.body(b).mass > 0.0)
    np.testing.assert_allclose(plant.body(body).inertia, 1.1 * np.asarray(problem.model.body(body).inertia), rtol=1e-12)
    np.testing.assert_allclose(plant.body(body).com, problem.model.body(body).com)
    assert problem.model.total_mass == pytest.approx(1.58)  # the model itself unchanged
    with pytest.raises(ValueError, match="factor"):
        heavier(problem.model, 0.0)


def test_bad_arguments_fail_naming_them(amble):
    problem, trajectory, model = amble
    for kwargs, name in (({"blocks": (3, 0)}, "blocks"), ({"blocks": ()}, "blocks"), ({"blocks": 5}, "blocks"), ({"blocks": "66"}, "blocks"),
                         ({"friction": 0.0}, "friction"),
                         ({"min_normal_force": -1.0}, "min_normal_force"), ({"slack_weight": np.nan}, "slack_weight"),
                         ({"swing_tolerance": -1e-3}, "swing_tolerance"),
                         ({"torque_bounds": (np.ones(problem.nu), -np.ones(problem.nu))}, "torque_bounds"),
                         ({"torque_bounds": (-np.ones(3), np.ones(3))}, "torque_bounds")):
        with pytest.raises(ValueError, match=name):
            MPC(model, **kwargs)
    for kwargs, name in (({"dt": -1.0}, "dt"), ({"substeps": 0}, "substeps"), ({"swing_clearance": -0.1}, "swing_clearance")):
        with pytest.raises(ValueError, match=name):
            TrackingModel.build(problem, trajectory, **kwargs)
    with pytest.raises(ValueError, match="model"):
        track(problem, trajectory, 1, model=model, control_every=3)
    with pytest.raises(ValueError, match="plant"):
        track(problem, trajectory, 1, model=model, control_every=10, plant=lk.Model(floating_base=True))
    with pytest.raises(ValueError, match="cycles"):
        track(problem, trajectory, 0, model=model, control_every=10)
    with pytest.raises(ValueError, match="joint_offset"):
        track(problem, trajectory, 1, model=model, control_every=10, joint_offset=np.zeros(3))


#: The plan `plan_amble` gives (mirrored half, 16 intervals per phase; `benches/mpc.py --plan` writes it), stored
#: because solving it takes a minute or more. The solve is deterministic (tests/test_optimize_determinism.py), so a
#: re-solve reproduces this file.
PLAN = Path(__file__).parent / "data" / "replayable_amble.npz"


@pytest.fixture(scope="module")
def optimised_amble():
    """The stored plan of `legkit gait --optimize`'s default recipe, checked to be a solution of today's problem."""
    fine = amble_plan_problem(build_quadruped(AMBLE_QUADRUPED))
    x = np.load(PLAN)["x"]
    assert x.shape == (fine.n,) and fine.nlp().violation(x) < 1e-6  # stale if the transcription changed: re-solve it
    problem, x = fine.whole_cycle(x)
    trajectory = problem.unpack(x)
    return problem, trajectory, TrackingModel.build(problem, trajectory)


@pytest.mark.slow
@pytest.mark.parametrize("mass", [1.0, 1.1, 0.9])
def test_the_mpc_holds_the_optimised_amble_five_cycles(optimised_amble, mass):
    problem, trajectory, model = optimised_amble
    run = track(problem, trajectory, 5, model=model, plant=heavier(problem.model, mass), progress=False,
                torque_bounds=stall_torque_bounds(QUADRUPED_MOTOR, problem.nu))
    assert run.upright, run.fell_at
    assert run.drift_fraction < 0.1, run.drift_fraction


def _blas_threads() -> int:
    return max(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")


def test_tracking_runs_blas_on_one_thread_and_gives_the_threads_back(amble, monkeypatch):
    problem, trajectory, model = amble
    seen: list[int] = []
    condense = MPC.condense

    def recorded(self, *args, **kwargs):
        seen.append(_blas_threads())
        return condense(self, *args, **kwargs)

    monkeypatch.setattr(MPC, "condense", recorded)
    with threadpool_limits(limits=2, user_api="blas"):
        track(problem, trajectory, cycles=1, control_every=int(round(DT / 1e-3)), model=model, progress=False)
        after = _blas_threads()
    assert seen and set(seen) == {1}
    assert after == 2
