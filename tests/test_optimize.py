"""legkit.optimize: Hermite–Simpson collocation [Hardt 2002, Sect. 4.1, eq. 14], its Jacobians, and small
optimal control problems whose optima are derived here by hand."""

from __future__ import annotations

import gc
import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_bvp
from scipy.spatial.transform import Rotation

import legkit as lk
from legkit.optimize import (
    InputPower,
    MinMaxStability,
    MultiphaseProblem,
    Phase,
    TorqueSpeedLine,
    Trajectory,
    effort,
    hermite_simpson_defects,
    joule_loss,
    specific_resistance,
)
from legkit.optimize.checks import execution_check
from legkit.optimize.constraints.limits import yaw_blocks
from legkit.optimize.mirror import side_mirror
from legkit.optimize.replay import periodic_samples, phase_of, replay
from legkit.optimize.shooting import interval_drift
from legkit.optimize.solver import solve
from legkit.robots.quadruped import LEGS, build_quadruped
from reference import central_jacobian

G = lk.STANDARD_GRAVITY
MASS, LENGTH = 1.0, 0.5  # pendulum: point mass on a massless rod, inertia m l^2 about the pivot


def pendulum(gravity: float) -> lk.Model:
    model = lk.Model(floating_base=False, gravity=[0.0, 0.0, -gravity])
    model.add_revolute(0, [0.0, 1.0, 0.0], None, lk.MassProperties.point(MASS, [0.0, 0.0, -LENGTH]), "rod")
    return model


#: IPOPT iterations per run in the polish test: too few for L-BFGS, enough for the exact Hessian.
POLISH_BUDGET = 3


def swing_up(model: lk.Model, intervals: int, duration: float) -> MultiphaseProblem:
    return MultiphaseProblem(model, [Phase((), intervals, (duration, duration))], objectives=[effort()], periodic=False,
                             initial=([0.0], [0.0]), final=([np.pi], [0.0]))


def single_phase(t: np.ndarray, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> Trajectory:
    return Trajectory([t], [q], [v], [u], [np.zeros((len(t), 0, 3))], np.array([t[-1] - t[0]]))


def test_defects_vanish_for_cubics_and_converge_at_the_method_order():
    # A cubic is reproduced exactly by both defects.
    t = np.linspace(0.0, 1.0, 9)
    def x(s: np.ndarray) -> np.ndarray:
        return (1.0 + 2.0 * s - 3.0 * s**2 + 0.5 * s**3)[:, None]

    def f(s: np.ndarray) -> np.ndarray:
        return (2.0 - 6.0 * s + 1.5 * s**2)[:, None]

    mid = 0.5 * (t[:-1] + t[1:])
    interpolation, simpson = hermite_simpson_defects(x(t), x(mid), f(t), f(mid), t[1] - t[0])
    assert np.max(np.abs(interpolation)) < 1e-14 and np.max(np.abs(simpson)) < 1e-14
    # The pendulum's own dynamics along theta(t) = sin(2t), torques by inverse dynamics: halving h divides the
    # interpolation defect by 2^4 (Hermite midpoint error) and the Simpson defect by 2^5 (Simpson's rule).
    model = pendulum(G)
    worst = []
    for intervals in (8, 16):
        problem = swing_up(model, intervals, 1.0)
        s = np.linspace(0.0, 1.0, 2 * intervals + 1)
        q, v, a = np.sin(2 * s)[:, None], 2 * np.cos(2 * s)[:, None], -4 * np.sin(2 * s)[:, None]
        u = np.asarray(lk.rnea(model, q, v, a))
        defects = problem.blocks[0].values(problem.pack(single_phase(s, q, v, u))).reshape(intervals, 2, 2)
        worst.append(np.max(np.abs(defects), axis=(0, 2)))
    ratio = worst[0] / worst[1]
    assert 13.0 < ratio[0] < 19.0, ratio
    assert 26.0 < ratio[1] < 38.0, ratio


def quadruped_problem(objectives) -> tuple[MultiphaseProblem, np.ndarray]:
    robot = build_quadruped()
    feet = {leg: robot.feet[leg] for leg in LEGS}
    phases = [Phase(("lf", "lh"), 1, (0.1, 0.5)), Phase(("lf", "rh"), 1, (0.1, 0.5)), Phase(("rf", "rh"), 1, (0.1, 0.5))]
    problem = MultiphaseProblem(robot.model, phases, feet, objectives, speed=0.3)
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 0.3, problem.n)
    for index in problem.point_index:
        x[index[:, 2]] = 0.2
        x[index[:, 3:7]] = [0.05, -0.03, 0.02, 1.0]
        x[index[:, problem.nq]] = 0.3  # forward body velocity, so J_e2's 1 / v stays finite
        x[index[:, problem.nx + problem.nu :: 3] ] = 0.1
        x[index[:, problem.nx + problem.nu + 2 :: 3]] = 5.0
    for k, index in enumerate(problem.point_index):  # the slack: zero at the knots (its bounds), small at the midpoints
        slack = index[:, problem.slack_columns[k]]
        x[slack[0::2]] = 0.0
        x[slack[1::2]] = rng.normal(0.0, 0.05, slack[1::2].shape)
    x[problem.duration_index] = 0.25
    return problem, x


@pytest.mark.slow
def test_constraint_jacobian_and_gradient_match_central_differences():
    terms = [joule_loss(5.0, 60.0, 0.012), specific_resistance(0.1),
             MinMaxStability(2.0, diagonal_pairs=(("lf", "rh"), ("rf", "lh")))]
    problem, x = quadruped_problem(terms)
    dense = np.zeros((problem.m, problem.n))
    dense[problem.jac_rows, problem.jac_cols] = problem.jacobian(x)
    reference = np.zeros_like(dense)
    for j in range(problem.n):  # plain central differences, column by column (at 1e-6 the forward rows' large
        step = 1e-5 * max(1.0, abs(x[j]))  # accelerations put ~2e-5 of rounding into the reference itself)
        plus, minus = x.copy(), x.copy()
        plus[j] += step
        minus[j] -= step
        reference[:, j] = (problem.constraints(plus) - problem.constraints(minus)) / (2 * step)
    scale = np.maximum(1.0, np.abs(reference))
    assert np.max(np.abs(dense - reference) / scale) < 1e-5
    outside = np.ones_like(dense, dtype=bool)
    outside[problem.jac_rows, problem.jac_cols] = False
    assert np.max(np.abs(reference[outside])) < 1e-7  # the fixed pattern holds every nonzero
    gradient = problem.gradient(x)
    for j in np.linspace(0, problem.n - 1, 40).astype(int).tolist() + list(problem.duration_index) + [problem.p1_index]:
        step = 1e-6 * max(1.0, abs(x[j]))
        plus, minus = x.copy(), x.copy()
        plus[j] += step
        minus[j] -= step
        expected = (problem.objective(plus) - problem.objective(minus)) / (2 * step)
        assert gradient[j] == pytest.approx(expected, rel=1e-5, abs=1e-7)


def lagrangian_hessian_error(problem: MultiphaseProblem, x: np.ndarray, rng: np.random.Generator, columns: int = 160) -> float:
    """Largest entry of |H - reference| / max(1, |reference|) over `columns` random columns and every duration's: the
    problem's Hessian of the Lagrangian against central differences of its exact gradient (objective factor and
    multipliers random); checks too that its pattern is a lower triangle holding every nonzero of the reference."""
    sigma, multipliers = 0.7, rng.normal(0.0, 1.0, problem.m)
    assert np.all(problem.hess_rows >= problem.hess_cols)
    lower = np.zeros((problem.n, problem.n))
    lower[problem.hess_rows, problem.hess_cols] = problem.hessian(x, sigma, multipliers)
    hessian = lower + np.tril(lower, -1).T
    chosen = np.unique(np.r_[rng.choice(problem.n, columns, replace=False), problem.duration_index])

    def gradient(part: np.ndarray) -> np.ndarray:
        point = x.copy()
        point[chosen] = part
        transposed = np.bincount(problem.jac_cols, problem.jacobian(point) * multipliers[problem.jac_rows], minlength=problem.n)
        return sigma * problem.gradient(point) + transposed

    reference = central_jacobian(gradient, x[chosen])  # (n, chosen): the Hessian's chosen columns
    outside = np.ones((problem.n, problem.n), dtype=bool)
    outside[problem.hess_rows, problem.hess_cols] = outside[problem.hess_cols, problem.hess_rows] = False
    assert np.max(np.abs(reference[outside[:, chosen]]), initial=0.0) < 1e-6  # the fixed pattern holds every nonzero
    return float(np.max(np.abs(hessian[:, chosen] - reference) / np.maximum(1.0, np.abs(reference))))


@pytest.mark.slow
def test_hessian_of_the_lagrangian_matches_central_differences_of_the_exact_gradient():
    # Curvature of every block and objective term (J_e1, J_e2, the S_H rows, touchdowns, stance and swing feet):
    # forward differences of exact Jacobians (~1e-7; the S_H rows' geometry by complex steps) except where a gradient
    # is itself differenced algebra (J_e2's: central differences of differences, ~1e-6).
    terms = [joule_loss(5.0, 60.0, 0.012), specific_resistance(0.1),
             MinMaxStability(2.0, diagonal_pairs=(("lf", "rh"), ("rf", "lh")))]
    problem, x = quadruped_problem(terms)
    problem = replace(problem, max_yaw=0.2, max_force_rate=500.0, max_torque_rate=100.0)
    assert lagrangian_hessian_error(problem, x, np.random.default_rng(5)) < 1e-5
    problem, x = quadruped_problem([joule_loss(5.0, 60.0, 0.012)])
    assert lagrangian_hessian_error(problem, x, np.random.default_rng(6)) < 1e-6


def pendulum_guess(intervals: int, duration: float) -> Trajectory:
    s = np.linspace(0.0, duration, 2 * intervals + 1)
    return single_phase(s, np.pi * s[:, None] / duration, np.full((len(s), 1), np.pi / duration), np.zeros((len(s), 1)))


@pytest.mark.parametrize("derivatives", ["legkit"])
def test_polish_finishes_an_l_bfgs_run_with_the_exact_hessian(derivatives):
    # Without gravity the swing-up's optimum is J = 12 I^2 pi^2 / T^3. A few L-BFGS iterations (on differenced or
    # exact first derivatives) stop short of it; polished from their best point with the exact Hessian, the same
    # budget reaches it.
    duration, inertia = 2.0, MASS * LENGTH**2
    problem = swing_up(pendulum(0.0), 10, duration)
    optimum = 12.0 * inertia**2 * np.pi**2 / duration**3
    _, short = problem.solve(pendulum_guess(10, duration), derivatives=derivatives, max_iter=POLISH_BUDGET)
    assert not short.success and short.objective > optimum * (1.0 + 1e-5)
    _, polished = problem.solve(pendulum_guess(10, duration), derivatives=derivatives, polish=True, max_iter=POLISH_BUDGET)
    assert polished.success
    assert polished.objective == pytest.approx(optimum, rel=1e-7)
    assert polished.iterations > short.iterations  # the result covers both runs
    with pytest.raises(ValueError, match="polish"):
        problem.solve(pendulum_guess(10, duration), derivatives="exact", polish=True)


def test_warm_start_from_a_solve_result_carries_its_multipliers():
    # The gravity-free swing-up with |u| <= 1 N m (binding: the free optimum peaks at 1.18 N m) at T = 2.0 s, then
    # at T = 2.1 s from that optimum: with its multipliers IPOPT keeps the active bounds' multipliers and the
    # point on its bounds, and converges in fewer iterations than from the point alone, to the same optimum; from
    # the optimum of the same problem with its multipliers, in at most two.
    def bounded(duration: float) -> MultiphaseProblem:
        return replace(swing_up(pendulum(0.0), 10, duration), u_bounds=(np.array([-1.0]), np.array([1.0])))

    near, far = bounded(2.0), bounded(2.1)
    _, neighbour = near.solve(pendulum_guess(10, 2.0))
    assert neighbour.success and neighbour.multipliers is not None
    assert max(np.abs(u).max() for u in near.unpack(neighbour.x).u) == pytest.approx(1.0, abs=1e-6)
    _, primal = far.solve(neighbour.x)
    _, warm = far.solve(neighbour)
    assert primal.success and warm.success
    assert warm.objective == pytest.approx(primal.objective, rel=1e-6)
    assert warm.iterations < primal.iterations
    _, unmoved = near.solve(neighbour, max_iter=0)  # IPOPT returns its start: the multipliers given, bounds' pushed by 1e-6
    np.testing.assert_allclose(unmoved.multipliers[1], neighbour.multipliers[1], atol=1e-12)
    np.testing.assert_allclose(unmoved.multipliers[0], neighbour.multipliers[0], atol=2e-6)
    _, again = near.solve(neighbour)
    assert again.success and again.iterations <= 2
    assert again.objective == pytest.approx(neighbour.objective, rel=1e-6)
    with pytest.raises(ValueError, match="feasibility_first"):
        far.solve(neighbour, feasibility_first=True)
    lam_x, lam_g = neighbour.multipliers
    with pytest.raises(ValueError, match="multipliers"):
        solve(far.nlp("exact"), neighbour.x, multipliers=(lam_x, lam_g[:-1]))


def test_regularised_first_factorises_every_system_regularised_to_the_same_optimum(tmp_path):
    # IPOPT's journal: lg(rg) is "-" for a system factorised unregularised. With regularised_first the idle variable
    # makes the first systems singular, so every later one starts from the last regularisation; the optimum, the
    # point's and multipliers' sizes are those of the problem given.
    problem = replace(swing_up(pendulum(0.0), 10, 2.0), u_bounds=(np.array([-1.0]), np.array([1.0])))
    nlp, x0 = problem.nlp("exact"), problem.pack(pendulum_guess(10, 2.0))
    runs, logs = {}, {}
    for flag in (False, True):
        log = tmp_path / f"ipopt-{flag}.txt"
        runs[flag] = solve(nlp, x0, regularised_first=flag, options={"output_file": str(log), "file_print_level": 5})
        gc.collect()  # IPOPT's journal is written out when the solver is freed
    for flag in (False, True):
        text = (tmp_path / f"ipopt-{flag}.txt").read_text()
        logs[flag] = [line.split()[6] for line in text.splitlines() if re.match(r"^ *\d+ ", line)]
    assert runs[True].success and runs[False].success
    assert set(logs[False]) == {"-"}
    assert len(logs[True]) == runs[True].iterations + 1 and "-" not in logs[True][1:]
    assert runs[True].objective == pytest.approx(runs[False].objective, rel=1e-7)
    assert runs[True].x.shape == (nlp.n,) and [m.shape for m in runs[True].multipliers] == [(nlp.n,), (nlp.m,)]
    assert nlp.violation(runs[True].x) <= 1e-6
    warm = solve(nlp, runs[True].x, multipliers=runs[True].multipliers, regularised_first=True)
    assert warm.success and warm.iterations <= 2 and warm.x.shape == (nlp.n,)


def test_stall_ends_a_run_once_its_objective_stops_improving():
    problem = swing_up(pendulum(0.0), 10, 2.0)
    nlp, x0 = problem.nlp("legkit"), problem.pack(pendulum_guess(10, 2.0))
    full = solve(nlp, x0)
    assert full.success and full.iterations > 3
    stopped = solve(nlp, x0, stall=(3, np.inf))  # every gain falls short of an infinite one: stop at the first chance
    assert stopped.status == "User_Requested_Stop" and stopped.iterations == 3 and len(stopped.history) == 4
    never = solve(nlp, x0, stall=(3, -np.inf))
    assert never.success and never.iterations == full.iterations


def test_pendulum_swing_up_reaches_the_known_optimum():
    duration, inertia = 2.0, MASS * LENGTH**2
    # Without gravity the swing-up is a double integrator: u(t) = I (6 pi / T^2)(1 - 2 t / T), J = 12 I^2 pi^2 / T^3.
    trajectory, result = swing_up(pendulum(0.0), 10, duration).solve(pendulum_guess(10, duration))
    assert result.success
    assert result.objective == pytest.approx(12.0 * inertia**2 * np.pi**2 / duration**3, rel=1e-7)
    t = trajectory.t[0]
    np.testing.assert_allclose(trajectory.u[0][:, 0], inertia * 6.0 * np.pi / duration**2 * (1.0 - 2.0 * t / duration), atol=1e-5)
    # With gravity, the optimum of int u^2 for I th'' = u - m g l sin(th) satisfies the Euler-Lagrange equation
    # of the squared residual: I u'' = -m g l cos(th) u, solved here as a boundary-value problem.
    k = MASS * G * LENGTH

    def rhs(_, y):
        return np.vstack([y[1], (y[2] - k * np.sin(y[0])) / inertia, y[3], -k * np.cos(y[0]) * y[2] / inertia])

    def ends(ya, yb):
        return np.array([ya[0], ya[1], yb[0] - np.pi, yb[1]])

    # Started from one backward pump (the torque-cheap way up; the monotone extremal costs more), with the
    # guess's torques by the dynamics.
    s = np.linspace(0.0, duration, 50)
    tau = s / duration
    theta = np.pi * tau**2 * (3.0 - 2.0 * tau) - 4.0 * np.sin(np.pi * tau) ** 2 * (1.0 - tau)
    rate = np.gradient(theta, s)
    torque = inertia * np.gradient(rate, s) + k * np.sin(theta)
    guess = np.vstack([theta, rate, torque, np.gradient(torque, s)])
    bvp = solve_bvp(rhs, ends, s, guess, tol=1e-6, max_nodes=20000)
    assert bvp.success
    fine = np.linspace(0.0, duration, 4001)
    optimum = np.trapezoid(bvp.sol(fine)[2] ** 2, fine)
    trajectory, result = swing_up(pendulum(G), 24, duration).solve(pendulum_guess(24, duration))
    assert result.success and result.violation < 1e-6
    assert result.objective == pytest.approx(optimum, rel=2e-3)
    np.testing.assert_allclose(trajectory.u[0][:, 0], bvp.sol(trajectory.t[0])[2], atol=0.02 * np.max(np.abs(bvp.sol(fine)[2])))


@pytest.mark.parametrize("derivatives", ["exact", "legkit"])
def test_input_power_limit_holds_binds_and_costs_effort(derivatives):
    # The gravity-free swing-up's optimum, u = I (6 pi / T^2)(1 - 2 t / T) at w = (6 pi / T^2)(t - t^2 / T), draws
    # R (u / (G K))^2 + u w of up to 1.69 W from these motor constants; a 1.2 W limit must bind and cost effort.
    duration, inertia, limit = 2.0, MASS * LENGTH**2, 1.2
    resistance, gear, constant = 1.0, 10.0, 0.1
    problem = swing_up(pendulum(0.0), 16, duration)
    limited = MultiphaseProblem(problem.model, problem.phases, objectives=[effort()], periodic=False,
                                initial=([0.0], [0.0]), final=([np.pi], [0.0]),
                                input_power=InputPower(limit, resistance, gear, constant))
    trajectory, result = limited.solve(pendulum_guess(16, duration), derivatives=derivatives)
    assert result.success and result.violation < 1e-6
    u, w = trajectory.u[0][:, 0], trajectory.v[0][:, 0]
    power = resistance * (u / (gear * constant)) ** 2 + u * w
    assert power.max() <= limit + 1e-6
    assert power.max() >= limit - 1e-4  # the limit binds
    assert result.objective > 1.01 * 12.0 * inertia**2 * np.pi**2 / duration**3  # above the free optimum
    # Its rows' Jacobian against central differences at a random point.
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 1.0, limited.n)
    rows = slice(limited.m - sum(b.size for b in limited.blocks[-1:]), limited.m)
    dense = np.zeros((limited.m, limited.n))
    dense[limited.jac_rows, limited.jac_cols] = limited.jacobian(x)
    for j in range(limited.n):
        step = 1e-6 * max(1.0, abs(x[j]))
        plus, minus = x.copy(), x.copy()
        plus[j] += step
        minus[j] -= step
        expected = (limited.constraints(plus)[rows] - limited.constraints(minus)[rows]) / (2 * step)
        np.testing.assert_allclose(dense[rows, j], expected, rtol=1e-6, atol=1e-7)


def test_input_power_rejects_bad_motor_constants():
    model = pendulum(0.0)
    with pytest.raises(ValueError, match="input_power.limit"):
        MultiphaseProblem(model, [Phase((), 2, (1.0, 1.0))], objectives=[effort()], periodic=False,
                          input_power=InputPower(0.0, 1.0, 10.0, 0.1))
    with pytest.raises(ValueError, match="input_power.resistance"):
        MultiphaseProblem(model, [Phase((), 2, (1.0, 1.0))], objectives=[effort()], periodic=False,
                          input_power=InputPower(1.0, -1.0, 10.0, 0.1))


BODY, FOOT, PERIOD = 1.0, 0.1, 0.5  # hopper masses [kg] and cycle time [s]


def hopper() -> lk.Model:
    """A body on a vertical slider and a foot on a vertical slider below it; the leg force u acts between them."""
    model = lk.Model(floating_base=False)
    body = model.add_prismatic(0, [0.0, 0.0, 1.0], None, lk.MassProperties.point(BODY, [0.0, 0.0, 0.0]), "body")
    model.add_prismatic(body, [0.0, 0.0, 1.0], None, lk.MassProperties.point(FOOT, [0.0, 0.0, 0.0]), "foot")
    return model


def test_single_leg_hop_reaches_the_known_optimum():
    # Body: M z_b'' = -u - M g in every phase (the impact stops the foot only). Periodicity: int u = -M g T.
    # Flight of length T_f from rest on the ground back to the ground: int_flight (T - t)(u / m - g) dt = 0.
    # Minimising int u^2 under these two linear conditions: u = a in stance, a + b (T - t) in flight, with
    # a = -(M g T + 3/4 m g T_f) / (T - 3/4 T_f), b = 3 (m g - a) / (2 T_f), and J = a^2 T + a b T_f^2 + b^2 T_f^3 / 3,
    # decreasing in the stance time, so the stance takes its upper bound 0.3 s.
    intervals, stance, flight = 8, 0.3, PERIOD - 0.3
    problem = MultiphaseProblem(hopper(), [Phase(("foot",), intervals, (0.1, stance)), Phase((), intervals, (0.1, 0.45))],
                                {"foot": ("foot", [0.0, 0.0, 0.0])}, [effort()], actuated=[1], period=PERIOD, force_dims=1)
    points = 2 * intervals + 1
    t = [np.linspace(0.0, 0.25, points), np.linspace(0.25, PERIOD, points)]
    standing = np.tile([0.3, -0.3], (points, 1))
    guess = Trajectory(t, [standing, standing], [np.zeros((points, 2))] * 2, [np.full((points, 1), -BODY * G)] * 2,
                       [np.tile([0.0, 0.0, (BODY + FOOT) * G], (points, 1, 1)), np.zeros((points, 0, 3))], np.array([0.25, 0.25]))
    trajectory, result = problem.solve(guess, tol=1e-10)
    a = -(BODY * G * PERIOD + 0.75 * FOOT * G * flight) / (PERIOD - 0.75 * flight)
    b = 1.5 * (FOOT * G - a) / flight
    assert result.success and result.violation < 1e-9
    assert result.objective == pytest.approx(a * a * PERIOD + a * b * flight**2 + b * b * flight**3 / 3.0, rel=1e-9)
    np.testing.assert_allclose(trajectory.durations, [stance, flight], atol=1e-6)
    np.testing.assert_allclose(trajectory.u[0][:, 0], a, atol=1e-6)
    np.testing.assert_allclose(trajectory.u[1][:, 0], a + b * (PERIOD - trajectory.t[1]), atol=1e-6)
    assert np.all(trajectory.forces[0][..., 2] > 0.0) and np.all(trajectory.q[1].sum(axis=1) >= -1e-8)


def test_min_normal_force_bounds_every_stance_normal_force_and_nothing_else():
    problem, _ = quadruped_problem([effort()])
    floored, _ = quadruped_problem([effort()])
    floored = replace(floored, min_normal_force=2.5)
    (lower, upper), (floored_lower, floored_upper) = problem.bounds(), floored.bounds()
    normal = np.concatenate([index[:, problem.force_columns[k]][:, 2::3].ravel() for k, index in enumerate(problem.point_index)])
    assert np.all(lower[normal] == 0.0) and np.all(floored_lower[normal] == 2.5)
    others = np.setdiff1d(np.arange(problem.n), normal)
    np.testing.assert_array_equal(floored_lower[others], lower[others])
    np.testing.assert_array_equal(floored_upper, upper)


def test_yaw_rows_are_the_heading_of_the_base_whatever_the_quaternions_norm():
    problem, x = quadruped_problem([effort()])
    (block,) = yaw_blocks(replace(problem, max_yaw=0.3))
    quaternions = np.random.default_rng(8).normal(size=block.index.shape)  # of any norm
    x = x.copy()
    x[block.index] = quaternions
    heading = Rotation.from_quat(quaternions).as_euler("ZYX")[:, 0]  # intrinsic z-y'-x'': the first angle is the yaw
    np.testing.assert_allclose(block.values(x), heading, atol=1e-12)
    step = 1e-6
    for j in range(4):  # each quaternion component, every point at once (each row sees its own point only)
        plus, minus = quaternions.copy(), quaternions.copy()
        plus[:, j] += step
        minus[:, j] -= step
        expected = (Rotation.from_quat(plus).as_euler("ZYX")[:, 0] - Rotation.from_quat(minus).as_euler("ZYX")[:, 0]) / (2 * step)
        np.testing.assert_allclose(block.slopes(quaternions)[:, 0, j], expected, atol=1e-8)
    np.testing.assert_array_equal(block.lower, -0.3)
    np.testing.assert_array_equal(block.upper, 0.3)
    with pytest.raises(ValueError, match="max_yaw"):
        replace(problem, max_yaw=0.0)


@pytest.mark.parametrize("mirrored", [False, True])
def test_load_rate_rows_bound_every_change_of_force_and_torque_and_each_switch(mirrored):
    # The rows |change| - rate x step, recomputed here from the unpacked (mirrored: unrolled) trajectory of a random
    # point: within each phase between neighbouring points (step T / (2 N)); across each boundary for a foot down on
    # both sides and the torques, and from or to zero for a landing or lifting foot (the step of the phase it is down in).
    robot = build_quadruped()
    feet = {leg: robot.feet[leg] for leg in LEGS}
    phases = [Phase(("lf", "lh"), 2, (0.1, 0.5)), Phase(("lf", "rh"), 1, (0.1, 0.5))] if mirrored else \
        [Phase(("lf", "lh"), 2, (0.1, 0.5)), Phase(("lf", "rh"), 1, (0.1, 0.5)), Phase(("rf", "rh"), 2, (0.1, 0.5))]
    mirror = side_mirror(robot.model, {"lf": "rf", "lh": "rh"}) if mirrored else None
    force_rate, torque_rate = 800.0, 300.0
    plain = MultiphaseProblem(robot.model, phases, feet, [effort()], speed=0.3, mirror=mirror)
    problem = replace(plain, max_force_rate=force_rate, max_torque_rate=torque_rate)
    x = np.random.default_rng(4).normal(0.0, 50.0, problem.n)
    x[problem.duration_index] = [0.2, 0.3, 0.25][: len(phases)]
    values = problem.constraints(x)[plain.m :]  # the new rows come after the plain problem's: +change, then -change
    rows = np.maximum(values[: len(values) // 2], values[len(values) // 2 :])
    trajectory = problem.unroll(problem.unpack(x))
    cycle = problem.cycle_phases()
    expected = []
    for k, phase in enumerate(problem.phases):  # a mirrored half's rows: its phases and boundaries, the wrap-around included
        later, after = cycle[(k + 1) % len(cycle)], (k + 1) % len(cycle)
        step, later_step = (trajectory.durations[j] / (2 * cycle[j].intervals) for j in (k, after))
        force = {name: trajectory.forces[k][:, c] for c, name in enumerate(phase.contacts)}
        landing = {name: trajectory.forces[after][0, c] for c, name in enumerate(later.contacts)}
        expected += [np.abs(np.diff(trajectory.u[k], axis=0)).ravel() - torque_rate * step,
                     np.abs(trajectory.u[after][0] - trajectory.u[k][-1]) - torque_rate * step]
        expected += [np.abs(np.diff(f, axis=0)).ravel() - force_rate * step for f in force.values()]
        for name in set(phase.contacts) | set(later.contacts):
            last = force[name][-1] if name in force else 0.0
            expected.append(np.abs(landing.get(name, 0.0) - last) - force_rate * (step if name in force else later_step))
    np.testing.assert_allclose(np.sort(rows), np.sort(np.concatenate([np.ravel(e) for e in expected])), rtol=1e-12, atol=1e-9)
    with pytest.raises(ValueError, match="max_force_rate must be > 0"):
        replace(plain, max_force_rate=0.0)


def test_execution_check_reports_the_worst_yaw_rates_and_torque_of_a_plan():
    # Each figure recomputed here from the unpacked trajectory of a random point: yaw by scipy at the points, torques
    # against their bound, the largest change of a force component or a torque over its step (switches: from or to
    # zero), and the joint rates on the velocity's Hermite cubic sampled as finely as the check samples it.
    robot = build_quadruped()
    feet = {leg: robot.feet[leg] for leg in LEGS}
    phases = [Phase(("lf", "lh"), 2, (0.1, 0.5)), Phase(("lf", "rh"), 1, (0.1, 0.5)), Phase(("rf", "rh"), 2, (0.1, 0.5))]
    nu, stall, speed = robot.model.nv - 6, 2.0, 20.0
    problem = MultiphaseProblem(robot.model, phases, feet, [effort()], speed=0.3, u_bounds=(np.full(nu, -stall), np.full(nu, stall)),
                                torque_speed=TorqueSpeedLine(speed, 0.1))
    x = np.random.default_rng(9).normal(0.0, 1.0, problem.n)
    x[problem.duration_index] = [0.2, 0.3, 0.25]
    check = execution_check(problem, x, samples=9)
    trajectory = problem.unpack(x)
    yaw = np.concatenate([Rotation.from_quat(q[:, 3:7]).as_euler("ZYX")[:, 0] for q in trajectory.q])
    assert check.yaw == pytest.approx(np.degrees(np.abs(yaw).max()), rel=1e-12)
    assert check.torque == pytest.approx(max(np.abs(u).max() for u in trajectory.u) / stall, rel=1e-12)
    force_rates, torque_rates, joint_rates = [], [], []
    for k, phase in enumerate(phases):
        after = (k + 1) % len(phases)
        step, later_step = (trajectory.durations[j] / (2 * phases[j].intervals) for j in (k, after))
        torque_rates += [np.abs(np.diff(trajectory.u[k], axis=0)).max() / step, np.abs(trajectory.u[after][0] - trajectory.u[k][-1]).max() / step]
        landing = {name: trajectory.forces[after][0, c] for c, name in enumerate(phases[after].contacts)}
        for c, name in enumerate(phase.contacts):
            force = trajectory.forces[k][:, c]
            force_rates += [np.abs(np.diff(force, axis=0)).max() / step, np.abs(landing.get(name, 0.0) - force[-1]).max() / step]
        force_rates += [np.abs(f).max() / later_step for name, f in landing.items() if name not in phase.contacts]
        h = 2 * step
        v, a = trajectory.v[k][:, 6:], trajectory.a[k][:, 6:]
        for i in range(phase.intervals):
            for s in np.linspace(0.0, 1.0, 9):
                joint_rates.append(np.abs((2 * s**3 - 3 * s**2 + 1) * v[2 * i] + (s**3 - 2 * s**2 + s) * h * a[2 * i]
                                          + (-2 * s**3 + 3 * s**2) * v[2 * i + 2] + (s**3 - s**2) * h * a[2 * i + 2]).max())
    weight = robot.model.total_mass * lk.STANDARD_GRAVITY
    assert check.force_rate == pytest.approx(max(force_rates) / (1e3 * weight), rel=1e-9)
    assert check.torque_rate == pytest.approx(max(torque_rates) / (1e3 * stall), rel=1e-9)
    assert check.joint_rate == pytest.approx(max(joint_rates) / speed, rel=1e-9)
    assert np.isfinite(check.swing_height) and len(check.lines()) == 6
    with pytest.raises(ValueError, match="samples"):
        execution_check(problem, x, samples=1)


@pytest.mark.parametrize("change, message", [
    ({"phases": []}, "phases must hold"),
    ({"phases": [Phase(("lf", "lh")), Phase(("lf", "lh"))]}, r"phases\[1\] has the same contacts"),
    ({"phases": [Phase(("lf", "xx")), Phase(("rf", "rh"))]}, r"phases\[0\]\.contacts names unknown feet \['xx'\]"),
    ({"phases": [Phase(("lf", "lh"), 0), Phase(("rf", "rh"))]}, r"phases\[0\]\.intervals"),
    ({"phases": [Phase(("lf", "lh"), 2, (0.3, 0.1)), Phase(("rf", "rh"))]}, r"phases\[0\]\.duration"),
    ({"speed": 5.0}, "speed 5.0 m/s is unreachable: foot 'lf' stays down"),
    ({"phases": [Phase(("lf", "lh", "rf")), Phase(("lf", "rh", "rf"))]}, "foot 'lf' never leaves the ground"),
    ({"period": (5.0, 6.0)}, "period .* cannot be met"),
    ({"force_dims": 2}, "force_dims must be 1 or 3"),
    ({"friction": 0.0}, "friction must be finite and > 0"),
    ({"friction": np.inf}, "friction must be finite and > 0"),
    ({"speed": np.nan}, "speed must be finite"),
    ({"phases": [Phase(("lf", "lh"), 10**7), Phase(("rf", "rh"))]}, r"phases\[0\]\.intervals must be in \[1, 1000\]"),
    ({"q_bounds": (np.zeros(3), np.ones(3))}, r"q_bounds must be \(lower, upper\) arrays of shape \(19,\)"),
    ({"u_bounds": (np.full(12, np.nan), np.ones(12))}, r"u_bounds: lower\[0\] = nan must be <= upper\[0\]"),
    ({"v_bounds": (np.ones(18), np.zeros(18))}, r"v_bounds: lower\[0\] = 1.0 must be <= upper\[0\] = 0.0"),
    ({"min_normal_force": -1.0}, "min_normal_force must be in \\[0, 100 x the robot's weight"),
    ({"min_normal_force": 1e308}, "min_normal_force must be in \\[0, 100 x the robot's weight"),  # overflowed in the solve
    ({"actuated": [3, 3]}, "actuated must list distinct"),
    ({"objectives": [MinMaxStability(2.0)], "phases": [Phase(("lf",)), Phase(("rf", "rh"))]}, "MinMaxStability needs two feet"),
])
def test_bad_problem_definitions_fail_fast_naming_the_argument(change, message):
    robot = build_quadruped()
    amble = [Phase(("lf", "lh")), Phase(("lf", "rh")), Phase(("rf", "rh")), Phase(("rf", "lh"))]
    arguments = {"model": robot.model, "phases": amble,
                 "feet": {leg: robot.feet[leg] for leg in LEGS}, "speed": 0.3}
    arguments.update(change)
    with pytest.raises(ValueError, match=message):
        MultiphaseProblem(**arguments)


def test_a_non_integer_interval_count_is_a_type_error_naming_it():
    robot = build_quadruped()
    with pytest.raises(TypeError, match=r"phases\[0\]\.intervals must be an integer, got float"):
        MultiphaseProblem(robot.model, [Phase(("lf", "lh"), 2.5), Phase(("rf", "rh"))], {leg: robot.feet[leg] for leg in LEGS})


@pytest.mark.parametrize("change, error, message", [
    ({"motor": None}, TypeError, "motor must be a legkit.robots.MotorParameters, got NoneType"),
    ({"period": np.nan}, ValueError, "period must be finite and > 0"),
    ({"period": np.inf}, ValueError, "period must be finite and > 0"),
    ({"duration_range": (1.0, 0.5)}, ValueError, "duration_range must satisfy"),
    ({"max_tilt": np.nan}, ValueError, r"max_tilt must be in \(0, pi\]"),
    ({"max_tilt": -0.1}, ValueError, r"max_tilt must be in \(0, pi\]"),
    ({"joint_range": (np.nan, 1.0, 2.0)}, ValueError, "joint_range must be three finite bounds"),
    ({"speed": np.nan}, ValueError, "speed must be finite"),
])
def test_amble_problem_refuses_bad_arguments_by_name(change, error, message):
    from legkit.optimize.gaits import amble_problem
    from legkit.robots import QUADRUPED_MOTOR

    arguments = {"robot": build_quadruped(), "objectives": [effort()], "speed": 0.5, "period": 1.25, "intervals": 2,
                 "motor": QUADRUPED_MOTOR}
    with pytest.raises(error, match=message):
        amble_problem(**{**arguments, **change})


@pytest.mark.parametrize(("call", "error", "message"), [
    # Each was a silent wrong answer, an unnamed error or a hang before.
    (lambda problem, x: problem.unpack(x[:-1]), ValueError, r"x must have shape"),  # unpacked the short vector
    (lambda problem, x: problem.unpack(x + np.nan), ValueError, "x contains a non-finite value"),  # a NaN trajectory
    (lambda problem, x: problem.unpack(x * (1 + 1j)), TypeError, "x must be an array of numbers"),  # a complex trajectory
    (lambda problem, x: problem.solve("x"), TypeError, "guess must be an array of"),
    (lambda problem, x: problem.solve(x, tol=-1.0), ValueError, "tol must be finite and > 0"),  # casadi: invalid IPOPT options
    (lambda problem, x: problem.solve(x, max_iter=-3), ValueError, r"max_iter must be in \[0, inf\]"),
    (lambda problem, x: problem.refine(problem, x), TypeError, "result must be a SolveResult"),  # an AttributeError
    (lambda problem, x: interval_drift(problem, x, substeps=10**9), ValueError, r"substeps must be in \[1, 10000\]"),  # ran for minutes
    (lambda problem, x: interval_drift(problem, x[:-1]), ValueError, r"x must have shape"),  # drifts of the short vector
    (lambda problem, x: execution_check(problem, x, samples=10**9), ValueError, r"samples must be in \[2, 10000\]"),  # NumPy's MemoryError
    (lambda problem, x: execution_check(problem, x, samples=2.5), TypeError, "samples must be an integer"),
    (lambda problem, x: periodic_samples(problem, problem.unpack(x), [np.nan]), ValueError, "t contains a non-finite value"),  # NaN samples
    (lambda problem, x: phase_of(problem.unpack(x), [np.nan]), ValueError, "t contains a non-finite value"),  # phase 2
    (lambda problem, x: replay(problem, problem.unpack(x), cycles=0), ValueError, r"cycles must be in \[1, inf\]"),  # a replay of nothing
    (lambda problem, x: replay(problem, problem.unpack(x), cycles=10**12), MemoryError, "cycles: needs"),  # NumPy's 4.5 TiB message
    (lambda problem, x: replay(problem, problem.unpack(x), kp=[1.0] * 3), ValueError, "kp must be one gain or 12"),  # a broadcast error
])
def test_points_counts_and_times_are_checked_by_name(call, error, message):
    problem, x = quadruped_problem([effort()])
    with pytest.raises(error, match=message):
        call(problem, x)


def test_best_keeps_the_best_iterate_within_tolerance_when_ipopt_stops_on_a_worse_one():
    from legkit.optimize import SolveResult

    last, better = np.array([1.0]), np.array([2.0])
    stopped = SolveResult(last, 0.5, "Maximum_Iterations_Exceeded", False, 10, 1.0, 0.1, 1e-3, [], (4, -0.2, better), 1e-6)
    assert stopped.best()[0] is better and stopped.best()[1] == -0.2
    feasible_and_best = SolveResult(last, -0.3, "Maximum_Iterations_Exceeded", False, 10, 1.0, 0.1, 1e-7, [], (4, -0.2, better), 1e-6)
    assert feasible_and_best.best()[0] is last
    converged = SolveResult(last, 0.5, "Solve_Succeeded", True, 10, 1.0, 0.1, 1e-7, [], (4, -0.2, better), 1e-6)
    assert converged.best()[0] is last


def test_a_spherical_joint_is_refused_by_name():
    # The transcription's configuration maps know a free-flyer's quaternion only: a ball joint's q rate is not its v.
    model = pendulum(9.81)
    model.add_spherical(1, (np.eye(3), [0.0, 0.0, -LENGTH]), lk.MassProperties.point(0.5, [0.0, 0.0, -0.2]), "wrist")
    with pytest.raises(ValueError, match=r"spherical joints.*'wrist'"):
        MultiphaseProblem(model, [Phase(intervals=2, duration=(1.0, 1.0))], objectives=[effort()], periodic=False,
                          initial=(np.zeros(model.nq), np.zeros(model.nv)))
