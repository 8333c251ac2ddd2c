"""The gaits of file 003 (../shared/seeds/003_8a51da06d878ba35.txt, Sect. 4.2) as `MultiphaseProblem`s, started
from `legkit.experiments.gait`'s hand-built references.

The amble: duty factor 0.5, support order LF+LH, LF+RH, RF+RH, RF+LH (Sect. 4.2, read as in
`legkit.experiments.gait.quadruped_amble`), a touchdown and a liftoff at every boundary, so every phase has
two feet down and S_H (eq. 10) is defined throughout; the full cycle is transcribed (no mirror symmetry).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

import legkit as lk
from legkit.experiments.gait import (
    AMBLE_HIP_HEIGHT, GaitReference, MotorParameters, contact_inverse_dynamics, quadruped_amble,
)
from legkit.optimize.problem import MultiphaseProblem, Phase, TorqueSpeedLine, Trajectory
from legkit.robots.quadruped import LEGS, Quadruped

#: IPOPT options for the amble: the monotone barrier update (the adaptive one drove mu to 1e-11 within a few
#: iterations of the J_s2 stage and then crawled along the constraints; docs/optimize.md).
AMBLE_IPOPT = {"mu_strategy": "monotone"}

#: Derivatives for the amble's J_s2: legkit's kernels with L-BFGS reached a higher worst-case S_H per second than
#: the exact Hessian (p1 0.103 vs 0.036 after 150 J_s2 iterations, cold; docs/optimize.md), though the exact
#: Hessian meets the constraints in fewer iterations (20 vs 78).
AMBLE_DERIVATIVES = "legkit"

#: q indices of the quadruped's hip roll and hip pitch joints (leg by leg), for the replay's attitude feedback.
AMBLE_ATTITUDE_JOINTS = ([7 + 3 * leg for leg in range(4)], [8 + 3 * leg for leg in range(4)])

#: The amble's support pairs in time order from t = 0 (file 003, Sect. 4.2).
AMBLE_SUPPORT = (("lf", "lh"), ("lf", "rh"), ("rf", "rh"), ("rf", "lh"))


def torque_speed_line(motor: MotorParameters) -> TorqueSpeedLine:
    """The motor-gear characteristic line of Sect. 2.3: |u| <= (w_max - |w|) G^2 eta / m."""
    return TorqueSpeedLine(motor.joint_max_speed, motor.gear_ratio**2 * motor.efficiency / motor.slope)


def amble_problem(robot: Quadruped, objectives: Sequence, speed: float, period: float, intervals: int,
                  motor: MotorParameters, friction: float = 0.8, duration_range: tuple[float, float] = (0.5, 1.5),
                  max_tilt: float = np.radians(15.0), joint_range: tuple[float, float, float] = (0.35, 1.8, 2.6),
                  max_swing_height: float = 0.06) -> MultiphaseProblem:
    """The amble at `speed` [m/s] over a fixed `period` [s]; each phase lasts between duration_range x period / 4.
    The state bounds of Sect. 2.3 keep the torso above the ground and its roll and pitch within about
    max_tilt [rad] (|q_x|, |q_y| <= sin(max_tilt / 2)): unbounded, J_s2 pitches the torso by ~50 deg; and the
    joints within joint_range [rad] = (|hip roll|, |hip pitch|, knee bent its own way by at most this):
    unbounded, J_s2 swung the legs over the torso (swing feet 0.6 m up) and straightened the knees; and the swing
    tips below max_swing_height [m] (with the joint bounds alone they still rose 0.4 m, swinging the legs for
    angular momentum, which no replay could track)."""
    quarter = period / 4.0
    phases = [Phase(pair, intervals, (duration_range[0] * quarter, duration_range[1] * quarter)) for pair in AMBLE_SUPPORT]
    line = torque_speed_line(motor)
    stall = line.max_speed * line.gain
    nu = robot.model.nv - 6
    upper = np.full(robot.model.nq, np.inf)
    upper[3:5] = np.sin(0.5 * max_tilt)
    lower = -upper
    lower[2] = 0.02
    roll, pitch, knee = joint_range
    for leg_index, leg in enumerate(LEGS):  # joints ordered leg by leg: hip roll, hip pitch, knee
        joints = 7 + 3 * leg_index
        bend = robot.parameters.knee_direction[leg]
        lower[joints : joints + 3] = [-roll, -pitch, min(0.0, bend * knee)]
        upper[joints : joints + 3] = [roll, pitch, max(0.0, bend * knee)]
    return MultiphaseProblem(robot.model, phases, {leg: robot.feet[leg] for leg in LEGS}, objectives, speed=speed, period=period,
                             friction=friction, u_bounds=(np.full(nu, -stall), np.full(nu, stall)), torque_speed=line,
                             q_bounds=(lower, upper), max_swing_height=max_swing_height)


def amble_reference(robot: Quadruped, speed: float, period: float, intervals: int) -> GaitReference:
    """`quadruped_amble` sampled on the collocation points of equal phases (two cycles, so the last point of
    the cycle continues the travel coordinate)."""
    return quadruped_amble(robot, speed, period, 8 * intervals, 2, 0.03, AMBLE_HIP_HEIGHT)


def guess_from_reference(problem: MultiphaseProblem, ref: GaitReference) -> Trajectory:
    """An initial guess on equal phases from a sampled reference whose samples fall on the collocation points:
    states and accelerations as sampled (kinematically consistent, so the defects start small), torques and
    contact forces by `contact_inverse_dynamics` (least squares: the inverse-dynamics residual starts as the
    reference's unbalanced base wrench)."""
    dynamics = contact_inverse_dynamics(problem.model, ref)
    names = list(problem.feet)
    t, q, v, u, forces, a = [], [], [], [], [], []
    start = 0
    for phase in problem.phases:
        rows = start + np.arange(2 * phase.intervals + 1)
        columns = [names.index(c) for c in phase.contacts]
        t.append(ref.t[rows])
        q.append(ref.q[rows])
        v.append(ref.v[rows])
        a.append(ref.a[rows])
        u.append(dynamics.torques[rows])
        forces.append(dynamics.forces[rows][:, columns])
        start = rows[-1]
    durations = np.array([t_k[-1] - t_k[0] for t_k in t])
    return Trajectory(t, q, v, u, forces, durations, a=a)
