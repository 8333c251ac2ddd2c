"""The per-joint balancing controller: closed-form targets, the paper's special cases, a brute-force optimum,
the gain schedules and the PID."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from legkit.agents import AgentNetwork, GroundContact
from legkit.control import PID, BalanceController, GainSchedule
from legkit.robots import superbot as sb

W = sb.MODULE_WIDTH


def converged(tree, q, line_point=(0.0, 0.0, 0.0), line_direction=(0.0, 0.0, 1.0)):
    model, layout = tree.to_model()
    ground = [GroundContact(0, 0, np.eye(3), np.zeros(3), np.array(line_point, float), np.array(line_direction, float))]
    network = AgentNetwork(tree, ground=ground, angles=layout.module_angles(q))
    network.run_until_quiescent()
    return model, layout, network


def single_module_decisions(angles, line_point=(0.0, 0.0, 0.0)):
    tree = sb.ModuleTree(1, [])
    _, _, network = converged(tree, np.asarray(angles, float), line_point)
    return BalanceController(network, GainSchedule.paper("constant")).decide()


def test_line_beside_the_module_pitches_the_com_toward_it():
    # A straight module, support line vertical through (0, 1, 0): both pitch joints swing the COM (above
    # them, on the z axis) to the +y side, i.e. theta = -pi/2 about +x; the target is clipped at the limit.
    decisions = single_module_decisions([0, 0, 0], line_point=(0.0, 1.0, 0.0))
    assert np.allclose(decisions.theta[0, [0, 2]], -np.pi / 2, atol=1e-12)
    assert np.allclose(decisions.target[0, [0, 2]], -sb.JOINT_LIMIT, atol=1e-12)
    # Pitch 1: the total COM circles the pivot with radius (m2/M)|p2 - q|, closest to the line at y = r.
    parts = sb.ModuleParameters().part_mass_properties()
    m2 = sum(p.mass for p in parts[1:])
    p2 = sum(p.mass * p.com[2] for p in parts[1:]) / m2
    radius = m2 / sb.MODULE_MASS * (p2 - 0.75 * W)
    assert np.isclose(decisions.distance[0, 0], 1.0 - radius, atol=1e-12)


def test_special_case_axis_is_the_support_line_holds_the_joint():
    # The roll joint's axis is the module's long axis, here the support line itself: every angle is as
    # good, so the joint holds its angle (theta = 0).
    decisions = single_module_decisions([0.0, 0.4, 0.0])
    assert decisions.theta[0, 1] == 0.0
    assert decisions.target[0, 1] == pytest.approx(0.4)


def test_special_case_com_on_the_axis_holds_the_joint():
    # Line beside the module: the moving part of the roll joint has its COM on the roll axis, so rotating
    # it does not move the COM: theta = 0.
    decisions = single_module_decisions([0.0, 0.7, 0.0], line_point=(0.0, 1.0, 0.0))
    assert decisions.theta[0, 1] == 0.0
    assert decisions.target[0, 1] == pytest.approx(0.7)


def test_tie_rule_picks_the_lowest_com():
    # Upright module, line through it: the COM circle of pitch 1 crosses the vertical line at its top (the
    # current COM) and at its bottom. Both are at distance 0; the lowest-z rule picks the bottom, theta = pi.
    decisions = single_module_decisions([0.3, 0.0, 0.0])
    assert np.isclose(decisions.theta[0, 0], np.pi - 0.3, atol=1e-12)
    assert decisions.distance[0, 0] < 1e-12
    assert decisions.target[0, 0] == pytest.approx(sb.JOINT_LIMIT)  # pi clipped to the limit


@examples(25)
@given(st.integers(1, 6), st.integers(0, 10_000), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5))
def test_every_joint_target_is_the_brute_force_optimum(n_modules, seed, line_x, line_y):
    tree = sb.random_tree(n_modules, min(n_modules, 3), seed)
    q = np.random.default_rng(seed).uniform(-1.2, 1.2, 3 * tree.n_modules)
    model, layout, network = converged(tree, q, (line_x, line_y, 0.0))
    decisions = BalanceController(network, GainSchedule.paper("constant")).decide()
    grid = np.linspace(-np.pi, np.pi, 721)
    for n in range(tree.n_modules):
        for k in range(3):
            index = layout.joint_q[n, k]
            trial = np.repeat(q[None], grid.size + 1, axis=0)
            trial[:-1, index] = q[index] + grid
            sign = 1.0 if network.fixed_block()[n] == 0 else -1.0
            trial[-1, index] = q[index] + sign * decisions.theta[n, k]  # what the joint chose
            com = lk.center_of_mass(model, trial)
            distance = np.hypot(com[:, 0] - line_x, com[:, 1] - line_y)
            assert distance[-1] <= distance[:-1].min() + 1e-9
            assert np.isclose(distance[-1], decisions.distance[n, k], atol=1e-9)


def test_gain_schedules_follow_the_paper():
    assert GainSchedule.paper("constant").gains(5.0, 3.0) == (10.0, 0.1, 1e-4)
    kp, ki, kd = GainSchedule.paper("distance").gains(np.array([2.0]), np.array([7.0]))
    assert np.allclose([kp[0], ki[0], kd[0]], [0.1 * 2 * 10, 0.1 * 2 * 0.1, 0.1 * 2 * 1e-4])
    kp, _, _ = GainSchedule.paper("momentum").gains(np.array([2.0]), np.array([0.3]))
    assert np.isclose(kp[0], 0.3 * 10)
    with pytest.raises(ValueError, match="scheme"):
        GainSchedule.paper("adaptive")
    with pytest.raises(ValueError, match="c1"):
        GainSchedule("distance", 0.0, -1.0)


def test_controller_gain_factors_from_its_own_estimates():
    # Upright module, line beside it at (1, 0): support distance 1 m; pitch 1 moves parts 1..3 about x at
    # z = 0.75 w: mass moment m2 |p2z - 0.75 w|.
    tree = sb.ModuleTree(1, [])
    _, _, network = converged(tree, np.zeros(3), (1.0, 0.0, 0.0))
    parts = sb.ModuleParameters().part_mass_properties()
    m2 = sum(p.mass for p in parts[1:])
    moment = abs(sum(p.mass * p.com[2] for p in parts[1:]) - m2 * 0.75 * W)
    for scheme, expected in (("constant", 1.0), ("distance", 0.1 * 1.0 / W), ("momentum", moment)):
        controller = BalanceController(network, GainSchedule.paper(scheme))
        decisions = controller.decide()
        assert np.isclose(controller.gain_factors(decisions)[0, 0], expected, rtol=1e-12)


def test_controller_evaluates_each_modules_own_schedule():
    # Mixed schedules, one per module, with non-paper constants and base gains: the controller's (N, 3)
    # factors and gains are, row by row, exactly what each module's GainSchedule gives for its estimates.
    tree = sb.random_tree(5, 2, 3)
    _, _, network = converged(tree, np.random.default_rng(3).uniform(-0.4, 0.4, 3 * tree.n_modules), (0.05, -0.02, 0.0))
    schedules = [
        GainSchedule("constant", 1.7, 0.4, 12.0, 0.2, 2e-4), GainSchedule("distance", 0.3, 0.7, 8.0, 0.05, 3e-4),
        GainSchedule("momentum", 0.25, 1.5), GainSchedule.paper("distance"), GainSchedule.paper("momentum"),
        GainSchedule.paper("constant"),
    ]
    controller = BalanceController(network, schedules)
    decisions = controller.decide()
    factors = controller.gain_factors(decisions)
    assert np.all(decisions.mass_moment > 0) and np.all(decisions.support_distance > 0)
    torques = []
    for n, schedule in enumerate(schedules):
        d, m = decisions.support_distance[n] / W, decisions.mass_moment[n]
        assert np.array_equal(factors[n], schedule.factor(d, m))
        torques.append(PID((3,))(decisions.target[n] - network.angles[n], 1e-3, *schedule.gains(d, m)))
    assert np.array_equal(controller.torques(1e-3)[0], np.array(torques))


def test_pid_arithmetic():
    pid = PID((2,))
    first = pid(np.array([1.0, -2.0]), 0.5, 10.0, 0.1, 1e-4)
    assert np.allclose(first, [10 + 0.1 * 0.5, -20 - 0.1 * 1.0])  # no derivative on the first call
    second = pid(np.array([0.5, -2.0]), 0.5, 10.0, 0.1, 1e-4)
    assert np.allclose(second, [5 + 0.1 * 0.75 + 1e-4 * (-1.0), -20 - 0.1 * 2.0])
    with pytest.raises(ValueError, match="error"):
        pid(np.array([np.nan, 0.0]), 0.5, 1, 1, 1)
    with pytest.raises(ValueError, match="dt"):
        pid(np.zeros(2), 0.0, 1, 1, 1)
    assert np.allclose(pid.integral, [0.75, -2.0])  # unchanged by the rejected calls


def test_joint_without_a_leader_holds():
    tree = sb.random_tree(4, 2, 0)
    network = AgentNetwork(tree, angles=np.full((tree.n_modules, 3), 0.2))  # nobody touches the ground
    network.run_until_quiescent()
    decisions = BalanceController(network, GainSchedule.paper("momentum")).decide()
    assert np.all(decisions.theta == 0) and np.allclose(decisions.target, 0.2)


@pytest.mark.parametrize(("gains", "argument"), [((np.nan, 0.0, 0.0), "kp"), ((1.0, np.ones(4), 0.0), "ki"), ((1.0, 0.0, [np.inf] * 3), "kd")])
def test_pid_refuses_non_finite_or_misshaped_gains_and_keeps_its_state(gains, argument):
    pid = PID((3,))
    pid(np.ones(3), 1e-3, 1.0, 1.0, 1.0)
    integral, previous = pid.integral.copy(), pid.previous_error.copy()
    with pytest.raises(ValueError, match=argument):
        pid(np.ones(3), 1e-3, *gains)
    assert np.array_equal(pid.integral, integral) and np.array_equal(pid.previous_error, previous)
