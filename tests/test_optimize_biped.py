"""legkit.optimize on the biped: flat feet with the foot-torque limits of eq. 6, J_s1 (eq. 9) as an objective, and
the walk of [Hardt 2002, Sect. 6], each against a reference written here."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import nnls

import legkit as lk
import legkit.stability as st
from legkit.experiments import gait
from legkit.optimize import FlatFoot, MultiphaseProblem, Phase, fri_deviation, joule_loss
from legkit.optimize.constraints.rates import dense_rate_blocks
from legkit.optimize.constraints.stance import foot_torque_blocks
from legkit.optimize.gaits import SOLE_TORSION, WALK_SUPPORT, guess_from_reference, walk_problem, walk_reference
from legkit.optimize.solver import solve
from legkit.robots.biped import SIDES, build_biped
from legkit.robots.motors import BIPED_MOTOR
from test_optimize import lagrangian_hessian_error

COARSE = (1, 1)  # intervals per double- and single-support phase: 12 collocation points per cycle
SPEED = 0.5  # [m/s], the paper's 1.8 km/h


@pytest.fixture(scope="module")
def robot():
    return build_biped()


@pytest.fixture(scope="module")
def walk(robot):
    """The coarse walk with J_e1 + J_s1 and its guess from the hand-built reference."""
    terms = [joule_loss(BIPED_MOTOR.resistance, BIPED_MOTOR.gear_ratio, BIPED_MOTOR.torque_constant), fri_deviation(0.5)]
    problem = walk_problem(robot, SPEED, BIPED_MOTOR, COARSE, objectives=terms)
    return problem, problem.gauged(problem.pack(guess_from_reference(problem, walk_reference(robot, SPEED, COARSE))))


@pytest.fixture(scope="module")
def feasible(walk):
    """The coarse walk after the constraint stage of `solve_walk`: a point that meets every constraint."""
    problem, x0 = walk
    return problem, solve(problem.nlp("legkit", objective=False), x0, max_iter=200)


@pytest.mark.parametrize("support", [1.0, 0.8])
def test_foot_torque_rows_are_eq6_and_keep_the_centre_of_pressure_on_the_sole(robot, support):
    """support 1: eq. 6 as published; below 1, its bounds scaled (`FlatFoot.support`): the centre of pressure on the
    sole shrunk by that factor."""
    problem = walk_problem(robot, SPEED, BIPED_MOTOR, COARSE, sole_support=support)
    k = WALK_SUPPORT.index(("l", "r"))  # both soles down
    index = problem.point_index[k]
    forces = index[:, problem.force_columns[k]].reshape(len(index), 2, 3)
    torques = index[:, problem.torque_columns[k]].reshape(len(index), 2, 3)
    rng = np.random.default_rng(11)
    samples = []
    for _ in range(40):
        x = np.zeros(problem.n)
        x[forces] = rng.normal(0.0, 50.0, forces.shape)
        x[forces[..., 2]] = rng.uniform(0.0, 400.0, forces[..., 2].shape)
        x[torques] = rng.normal(0.0, 12.0, torques.shape)
        values = np.concatenate([b.values(x) for b in foot_torque_blocks(problem, k)])
        # Eq. 6 per foot: c F_z - s T >= 0 for s = +1 then -1, c = support x (0.5 l_y, 0.5 l_x, mu_d).
        expected = []
        for foot in range(2):
            sole = problem.flat_feet[SIDES[foot]]
            limit = support * np.array([0.5 * sole.width, 0.5 * sole.length, sole.torsion])
            for sign in (1.0, -1.0):
                expected.append((limit * x[forces[:, foot, 2:]] - sign * x[torques[:, foot]]).ravel())
        np.testing.assert_allclose(values, np.concatenate(expected), atol=1e-12)
        # The x and y rows hold iff nonnegative pressure at the sole's corners produces (F_z, T_x, T_y).
        for foot in range(2):
            sole = problem.flat_feet[SIDES[foot]]
            corners = support * np.array([[sx * 0.5 * sole.length, sy * 0.5 * sole.width] for sx in (-1, 1) for sy in (-1, 1)])
            wrench = np.stack([np.ones(4), corners[:, 1], -corners[:, 0]])  # unit normal forces -> (F_z, T_x, T_y)
            for point in range(len(index)):
                target = np.r_[x[forces[point, foot, 2]], x[torques[point, foot, :2]]]
                producible = nnls(wrench, target)[1] < 1e-9 * max(1.0, np.abs(target).max())
                rows = [x[forces[point, foot, 2]] * support * 0.5 * sole.width - s * x[torques[point, foot, 0]] for s in (1, -1)]
                rows += [x[forces[point, foot, 2]] * support * 0.5 * sole.length - s * x[torques[point, foot, 1]] for s in (1, -1)]
                samples.append((producible, min(rows) >= 0.0))
    assert all(a == b for a, b in samples)
    assert {True, False} <= {a for a, _ in samples}  # both cases met


def test_bad_flat_feet_fail_naming_the_argument(robot):
    feet = {"l": ("l_foot", [0.05, 0.0, -0.06]), "r": ("r_foot", [0.05, 0.0, -0.06])}
    phases = [Phase(("l",)), Phase(("r",))]
    with pytest.raises(ValueError, match=r"flat_feet names unknown feet \['x'\]"):
        MultiphaseProblem(robot.model, phases, feet, flat_feet={"x": FlatFoot(0.2, 0.1, 0.04)})
    with pytest.raises(ValueError, match="flat_feet need force_dims 3"):
        MultiphaseProblem(robot.model, phases, feet, force_dims=1, flat_feet={"l": FlatFoot(0.2, 0.1, 0.04)})
    with pytest.raises(ValueError, match="FlatFoot.width must be > 0"):
        FlatFoot(0.2, 0.0, 0.04)
    flight = MultiphaseProblem(robot.model, [Phase(("l",)), Phase(())], feet, periodic=False,
                               initial=(robot.model.neutral(), np.zeros(robot.model.nv)))
    with pytest.raises(ValueError, match=r"fri_deviation \(J_s1, eq. 9\) needs a foot on the ground in every phase; phases\[1\] has none"):
        fri_deviation().integrand(flight, np.ones((1, flight.point_index[1].shape[1])), 1)


def _rest_model(model: lk.Model, feet: list[int]) -> lk.Model:
    """The model with the bodies `feet` massless (eq. 8's "remainder of the robot"), rebuilt joint by joint."""
    copy = lk.Model(floating_base=True, base=model.body(0), base_name=model.names[0], gravity=model.gravity)
    for i in range(1, model.nbodies):
        mass = lk.MassProperties.zero() if i in feet else model.body(i)
        if model.joint_type(i) == "revolute":
            copy.add_revolute(model.parents[i], model.joint_axis(i), model.placement(i), mass, model.names[i])
        else:
            copy.add_fixed(model.parents[i], model.placement(i), mass, model.names[i])
    return copy


def test_j_s1_is_eq9_of_the_fri_found_from_the_momentum_balance_of_the_rest(robot, walk):
    problem, x = walk
    model = problem.model
    g = np.asarray(model.gravity)
    total = 0.0
    for k, (phase, index) in enumerate(zip(problem.phases, problem.point_index)):
        feet = sorted({problem.foot_body[name] for name in phase.contacts})
        rest = _rest_model(model, feet)
        z = x[index]
        q, v, a = problem.configuration(z[:, : problem.nq]), z[:, problem.nq : problem.nx], z[:, problem.a_columns[k]]
        # d/dt of the rest's centroidal momentum by central differences along (dq/dt, a).
        step = 1e-6
        rate = (np.asarray(lk.centroidal_momentum(rest, problem.configuration(q + step * problem.q_rate(q, v)), v + step * a))
                - np.asarray(lk.centroidal_momentum(rest, problem.configuration(q - step * problem.q_rate(q, v)), v - step * a))) / (2 * step)
        com = np.asarray(lk.center_of_mass(rest, q))
        m_rest = model.total_mass - sum(model.body(i).mass for i in feet)
        # Moments about the origin of what the feet must get from the ground to stay still (weights downwards).
        moment = rate[:, 3:] + np.cross(com, rate[:, :3] - m_rest * g)
        poses = np.asarray(lk.forward_kinematics(model, q))
        for i in feet:
            foot_com = np.einsum("pij,j->pi", poses[:, i, :3, :3], model.body(i).com) + poses[:, i, :3, 3]
            moment -= np.cross(foot_com, model.body(i).mass * g)
        normal = rate[:, 2] - model.total_mass * g[2]
        fri = np.stack([-moment[:, 1] / normal, moment[:, 0] / normal], axis=1)
        gcom = np.asarray(lk.center_of_mass(model, q))[:, :2]
        squared = np.sum((gcom - fri) ** 2, axis=1)
        weights = np.ones(len(z))
        weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0  # Simpson over the phase's knots and midpoints
        total += x[problem.duration_index[k]] / (6.0 * phase.intervals) * (weights @ squared)
    j_e1 = problem.objective(x) - 0.5 * total
    only_j_e1 = walk_problem(robot, SPEED, BIPED_MOTOR, COARSE)
    assert j_e1 == pytest.approx(only_j_e1.objective(x), rel=1e-6)
    assert total > 1e-4  # S and the GCoM differ on the reference (the check is not 0 = 0)


def test_derivatives_of_flat_feet_and_j_s1_match_central_differences(walk):
    problem, x = walk
    rng = np.random.default_rng(2)
    x = x + rng.normal(0.0, 1e-3, problem.n)
    dense = np.zeros((problem.m, problem.n))
    dense[problem.jac_rows, problem.jac_cols] = problem.jacobian(x)
    gradient = problem.gradient(x)
    k = WALK_SUPPORT.index(("l",))
    index = problem.point_index[k]
    # The columns of the new rows: a stance point's q, the torque and force variables, durations, impulses.
    columns = np.r_[index[2, : problem.nq], index[1, problem.torque_columns[k]], index[1, problem.force_columns[k]],
                    problem.duration_index, np.concatenate(list(problem.impulse_index.values()))[:8],
                    rng.choice(problem.n, 30, replace=False)]
    for j in columns:
        step = 1e-6 * max(1.0, abs(x[j]))
        plus, minus = x.copy(), x.copy()
        plus[j] += step
        minus[j] -= step
        reference = (problem.constraints(plus) - problem.constraints(minus)) / (2 * step)
        assert np.max(np.abs(dense[:, j] - reference) / np.maximum(1.0, np.abs(reference))) < 1e-5, j
        assert gradient[j] == pytest.approx((problem.objective(plus) - problem.objective(minus)) / (2 * step), rel=1e-5, abs=1e-7)


def test_dense_rates_bound_the_joint_rates_on_the_whole_velocity_cubic_between_the_points(robot):
    # The rows, recomputed here: the inner Bernstein control points of v(s) = b0 v_k + b1 h a_k + b2 v_k+1 + b3 h a_k+1.
    plain = walk_problem(robot, SPEED, BIPED_MOTOR, COARSE, dense_rates=False)
    problem = replace(plain, dense_rates=True)
    x = problem.gauged(problem.pack(guess_from_reference(problem, walk_reference(robot, SPEED, COARSE))))
    x += 0.1 * np.random.default_rng(3).normal(size=problem.n)
    trajectory = problem.unpack(x)
    expected, cubics = [], []
    s = np.linspace(0.0, 1.0, 1001)[:, None]
    for k, phase in enumerate(problem.phases):
        h = trajectory.durations[k] / phase.intervals
        v, a = trajectory.v[k][:, 6:], trajectory.a[k][:, 6:]
        for i in range(phase.intervals):
            v0, v1, a0, a1 = v[2 * i], v[2 * i + 2], a[2 * i], a[2 * i + 2]
            expected.append(np.concatenate([v0 + h * a0 / 3.0, v1 - h * a1 / 3.0]))
            cubics.append((2 * s**3 - 3 * s**2 + 1) * v0 + (s**3 - 2 * s**2 + s) * h * a0 + (-2 * s**3 + 3 * s**2) * v1 + (s**3 - s**2) * h * a1)
    blocks = dense_rate_blocks(problem)
    assert problem.m == plain.m + sum(b.size for b in blocks)
    rows = np.concatenate([b.values(x) for b in blocks])
    np.testing.assert_allclose(rows, np.concatenate(expected), rtol=1e-12, atol=1e-12)
    lower, upper = np.concatenate([b.lower for b in blocks]), np.concatenate([b.upper for b in blocks])
    np.testing.assert_allclose(upper, BIPED_MOTOR.joint_max_speed)
    np.testing.assert_allclose(lower, -BIPED_MOTOR.joint_max_speed)
    # The convex hull: the cubic, sampled finely, never leaves the range of its ends and the two rows.
    for cubic, inner in zip(cubics, np.split(rows, len(cubics))):
        ends = np.stack([cubic[0], cubic[-1], inner[: problem.nu], inner[problem.nu :]])
        assert np.all(cubic.max(axis=0) <= ends.max(axis=0) + 1e-12) and np.all(cubic.min(axis=0) >= ends.min(axis=0) - 1e-12)
    with pytest.raises(ValueError, match="dense_rates needs a torque_speed"):
        replace(plain, dense_rates=True, torque_speed=None)


@pytest.mark.slow
def test_hessian_of_flat_feet_j_s1_and_input_power_matches_central_differences(robot):
    # The sole's rows, eq. 6's torques, J_s1 (its gradient differenced algebra of kernels: ~1e-5), the input power and
    # the joint rates between the points.
    terms = [joule_loss(BIPED_MOTOR.resistance, BIPED_MOTOR.gear_ratio, BIPED_MOTOR.torque_constant), fri_deviation(0.5)]
    problem = replace(walk_problem(robot, SPEED, BIPED_MOTOR, COARSE, objectives=terms, mirror=True, max_input_power=200.0),
                      dense_rates=True)
    rng = np.random.default_rng(2)
    x = problem.gauged(problem.pack(guess_from_reference(problem, walk_reference(robot, SPEED, COARSE)))) + 0.01 * rng.normal(size=problem.n)
    assert lagrangian_hessian_error(problem, x, rng) < 1e-4


def test_walk_solution_meets_dynamics_feet_and_motor_limits_in_legkit_kernels(robot, feasible):
    problem, result = feasible
    p = robot.parameters
    half_length, half_width = 0.5 * (p.foot_toe + p.foot_heel), p.foot_half_width
    assert result.success and result.violation < 1e-6
    trajectory = problem.unpack(result.x)
    model = problem.model
    for accelerations in problem.stance_accelerations(result.x):  # the stance soles at rest at the knots
        np.testing.assert_allclose(accelerations[0::2], 0.0, atol=1e-6)
    for k, phase in enumerate(problem.phases):  # and the plan's accelerations there are its torques' motion
        held = [(body, point) for body, point, _ in problem.contact_rows(phase.contacts)]
        knots = problem.configuration(trajectory.q[k][0::2]), trajectory.v[k][0::2]
        driven, _ = lk.contact_dynamics(problem.model, *knots, problem.tau(trajectory.u[k][0::2]), held)
        np.testing.assert_allclose(trajectory.a[k][0::2], driven, atol=1e-4 * np.abs(driven).max())
    for k, phase in enumerate(problem.phases):
        q, v, a, u = problem.configuration(trajectory.q[k]), trajectory.v[k], trajectory.a[k], trajectory.u[k]
        poses = np.asarray(lk.forward_kinematics(model, q))
        f_ext = np.zeros((len(q), model.nbodies, 6))
        for c, side in enumerate(phase.contacts):
            body = model.names.index(f"{side}_foot")
            rotation = poses[:, body, :3, :3]
            local = np.einsum("pji,pj->pi", rotation, trajectory.forces[k][:, c])
            centre = problem.foot_point[side]
            f_ext[:, body, :3] += local
            f_ext[:, body, 3:] += np.cross(centre, local) + trajectory.torques[k][:, c]
            # The sole's four corners on the ground and the sole at rest at the knots (the midpoints lie on the
            # collocation cubics, which the slack frees from the ground: `MultiphaseProblem.rate`); the wrench
            # within eq. 6 and the friction cone (eq. 5).
            for corner in (centre + [sx * half_length, sy * half_width, 0.0] for sx in (-1, 1) for sy in (-1, 1)):
                height = np.einsum("pij,j->pi", rotation, corner)[:, 2] + poses[:, body, 2, 3]
                np.testing.assert_allclose(height[0::2], 0.0, atol=1e-6)
            sole_motion = np.asarray(lk.jacobian(model, q[0::2], body, centre, "local_world_aligned"))
            np.testing.assert_allclose(np.einsum("pij,pj->pi", sole_motion, v[0::2]), 0.0, atol=1e-6)
            torque = trajectory.torques[k][:, c]  # foot frame, about the sole's centre
            sole = (-half_length, half_length, -half_width, half_width)
            assert np.min(st.foot_torque_margin(local, torque, sole)) > -1e-6
            assert np.max(np.abs(torque[:, 2]) - SOLE_TORSION * local[:, 2]) < 1e-6
            assert np.min(st.friction_cone_margin(trajectory.forces[k][:, c], [0.0, 0.0, 1.0], 0.8)) > -1e-6
        tau = np.zeros((len(q), model.nv))
        tau[:, 6:] = u
        np.testing.assert_allclose(np.asarray(lk.rnea(model, q, v, a, f_ext)), tau, atol=1e-5)
        margin = st.torque_speed_margin(u, v[:, 6:], BIPED_MOTOR.joint_max_speed, BIPED_MOTOR.gear_ratio, BIPED_MOTOR.efficiency, BIPED_MOTOR.slope)
        assert np.min(margin) > -1e-6
    assert np.sum(trajectory.durations) == pytest.approx(1.6)


@pytest.mark.slow
def test_cli_optimize_walks_the_biped_printing_each_stage_and_writing_csv_and_figure(tmp_path, capsys):
    iterations = 2
    assert gait.main(["--robot", "biped", "--optimize", "--biped-intervals", "1", "--biped-max-iter", str(iterations), "--replay-cycles", "1",
                      "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    progress = [line.strip().rpartition(": ") for line in out.splitlines() if " iterations, objective " in line]  # one per stage
    assert [label for label, _, _ in progress] == ["constraints", "J_e1"]
    assert all(0 < int(figures.split()[0]) <= iterations for _, _, figures in progress)
    assert "J_e1 (eq. 12) [J/m]" in out and "max |rnea - B u| (lk.rnea)" in out
    with (tmp_path / "gait_biped_optimized.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 4 * 3 and [rows[3 * k]["support"] for k in range(4)] == ["+".join(p).upper() for p in WALK_SUPPORT]
    assert "l_Tx" in rows[0] and float(rows[3]["r_Fz"]) == 0.0  # the right foot is in the air in phase 1
    assert (tmp_path / "gait_biped_torque_speed.png").stat().st_size > 10_000
    # Replayed under the MPC (two iterations are no walk: only the outputs are checked here).
    assert "replaying 1 cycles in lk.Simulation under the contact-constrained MPC" in out and "replay: stayed upright" in out
    assert "the walk replayed in simulation" in (tmp_path / "gait_biped_optimized.html").read_text()
