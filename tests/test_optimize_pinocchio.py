"""The stored plan of `legkit gait --optimize` (the amble the MPC tests track) checked at every collocation point by
Pinocchio, an implementation independent of legkit's: the robot rebuilt by `pin` from its URDF, its inverse dynamics
with the plan's foot forces as external wrenches equal to the plan's joint torques, the base unactuated, and the
stance feet on the ground at the knots."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import MultiphaseProblem, Trajectory
from legkit.optimize.gaits import amble_plan_problem
from legkit.robots.quadruped import Quadruped, build_quadruped

PLAN = Path(__file__).parent / "data" / "replayable_amble.npz"


@pytest.fixture(scope="module")
def plan():
    robot = build_quadruped(AMBLE_QUADRUPED)
    half = amble_plan_problem(robot)
    problem, x = half.whole_cycle(np.load(PLAN)["x"])
    return robot, problem, problem.unpack(x)


def pinocchio_residual(robot: Quadruped, problem: MultiphaseProblem, trajectory: Trajectory) -> tuple[float, float, float]:
    """(largest |rnea_pin(q, v, a, f_feet) - [0, u]|, largest |u|) over every point, and the largest |stance foot
    height| over the knots."""
    model = robot.model
    reference = pin.buildModelFromXML(robot.to_urdf(), pin.JointModelFreeFlyer())
    data = reference.createData()
    # legkit's coordinates in pin's order, by the URDF's joint names ("<body>_joint"); fixed links have no pin joint.
    order_q, order_v = np.arange(reference.nq), np.arange(reference.nv)
    for body in range(1, model.nbodies):
        joint = reference.getJointId(f"{model.names[body]}_joint")
        if joint < reference.njoints:
            order_q[reference.joints[joint].idx_q] = model.idx_q[body]
            order_v[reference.joints[joint].idx_v] = model.idx_v[body]
    assert sorted(order_v) == list(range(model.nv))
    residual = height = torque = 0.0
    for k, phase in enumerate(problem.phases):
        q, v, a = trajectory.q[k].copy(), trajectory.v[k], trajectory.a[k]
        q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)  # the raw quaternion's direction
        for p in range(len(q)):
            q_pin = q[p, order_q]
            pin.framesForwardKinematics(reference, data, q_pin)
            forces = [pin.Force.Zero() for _ in range(reference.njoints)]
            for c, name in enumerate(phase.contacts):
                link = reference.getFrameId(model.names[problem.foot_body[name]], pin.BODY)
                frame, pose = reference.frames[link], data.oMf[link]
                point = np.asarray(problem.foot_point[name], dtype=float)
                if p % 2 == 0:  # the knots; the midpoints lie on the collocation cubics (DIRCON's slack)
                    height = max(height, abs(pose.act(point)[2]))
                local = pose.rotation.T @ trajectory.forces[k][p, c]  # in the foot link's frame, at the point
                forces[frame.parentJoint] += frame.placement.act(pin.Force(local, np.cross(point, local)))
            f_ext = pin.StdVec_Force()
            for f in forces:
                f_ext.append(f)
            tau = pin.rnea(reference, data, q_pin, v[p, order_v], a[p, order_v], f_ext)
            expected = np.zeros(model.nv)
            expected[problem.actuated] = trajectory.u[k][p]
            residual = max(residual, float(np.max(np.abs(tau - expected[order_v]))))
            torque = max(torque, float(np.max(np.abs(trajectory.u[k][p]))))
    return residual, torque, height


def test_the_stored_plan_meets_pinocchios_dynamics_at_every_point(plan):
    residual, torque, height = pinocchio_residual(*plan)
    assert torque > 0.1  # the plan carries load
    assert residual < 1e-6 * max(1.0, torque)
    assert height < 1e-6


def test_the_check_sees_a_torque_off_by_a_milli_newton_metre(plan):
    robot, problem, trajectory = plan
    u = [part.copy() for part in trajectory.u]
    u[1][3, 2] += 1e-3
    residual, _, _ = pinocchio_residual(robot, problem, Trajectory(trajectory.t, trajectory.q, trajectory.v, u, trajectory.forces,
                                                                   trajectory.durations, a=trajectory.a, torques=trajectory.torques))
    assert residual == pytest.approx(1e-3, rel=1e-3)
