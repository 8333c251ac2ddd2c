"""The per-joint centre-of-mass balancing controller (Moll et al., IROS 2006, §IV–V).

Every joint decides on its own, from its own agent's estimates only (``legkit.agents.AgentNetwork``):

1. Split the robot at the joint. The *fixed* side holds the ground (the leader's side: the module's block
   on its uplink connector, or the grounded block for the leader); the other side, of mass m2 and COM p2,
   is the *moving* part, built from the module's own parts on that side plus its estimates of everything
   beyond that block's connectors.
2. Rotating the moving part by theta about the joint axis (point q, unit direction u) moves its COM on a
   circle, hence the total COM c (mass M) on the circle of the point c about the parallel axis through
   ``a = c - (m2 / M) (p2 - q)``. ``lk.rotation_toward_line(a, u, c, line)`` gives the theta that brings c
   closest to the support line, with the paper's special cases: theta = 0 when c is on that axis or the axis
   is the support line (every angle is as good: the joint holds), and the lowest-z solution when two tie.
3. Target = current angle + theta (signed for the joint's own direction), clipped to the joint limits;
   torque from a PID with gains scaled by the joint's gain schedule (``legkit.control.gains``).

All of this is vectorised over every joint of the robot (or of several robots side by side); a joint whose
agent does not know its world pose yet (no leader heard of) holds its current angle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from legkit.agents import moments
from legkit.agents.network import AgentNetwork
from legkit.control.gains import SCHEMES, GainSchedule
from legkit.control.pid import PID
from legkit.geometry import rotation_toward_line
from legkit.robots.superbot import JOINT_AXES, JOINT_Z


@dataclass
class JointDecisions:
    """What every joint (N, 3) decided this step, all from its own agent's estimates.

    ``theta`` (rad) the rotation of the moving part toward the support line, ``target`` (rad) the clipped
    joint target, ``distance`` (m) the estimated COM–support-line distance after the rotation, ``support_distance``
    (m) the estimated current COM–support-line distance, ``mass_moment`` (kg m) = |m2 u x (p2 - q)|."""

    theta: np.ndarray
    target: np.ndarray
    distance: np.ndarray
    support_distance: np.ndarray
    mass_moment: np.ndarray


class BalanceController:
    """Per-joint COM balancing for the agents of ``network``; ``schedules`` is one ``GainSchedule`` for every
    joint, or one per module (N,)."""

    def __init__(self, network: AgentNetwork, schedules: GainSchedule | Sequence[GainSchedule]):
        if not isinstance(network, AgentNetwork):
            raise TypeError(f"network: must be an AgentNetwork, got {type(network).__name__}")
        n = network.n_modules
        if isinstance(schedules, GainSchedule):
            schedules = [schedules] * n
        schedules = list(schedules)
        if len(schedules) != n or not all(isinstance(s, GainSchedule) for s in schedules):
            raise ValueError(f"schedules: must be a GainSchedule or {n} of them (one per module)")
        self.network = network
        self.schedules = schedules
        scheme = np.array([SCHEMES.index(s.scheme) for s in schedules])[:, None]
        self._distance_scheme, self._momentum_scheme = scheme == 1, scheme == 2
        self._c = np.array([[s.c0, s.c1] for s in schedules])
        self._k0 = np.array([[s.kp0, s.ki0, s.kd0] for s in schedules])
        self.pid = PID((n, 3))
        parameters = network.parameters
        self.limit = parameters.joint_limit
        self.width = parameters.width
        # Joint k's point and axis in the zero-angle module frame, (3 joints, 2, 3): both fixed in part k + 1.
        self._joint_point_axis = np.stack([np.outer(JOINT_Z, [0.0, 0.0, parameters.width]), JOINT_AXES], axis=1)

    def decide(self) -> JointDecisions:
        """Every joint's rotation toward the support line and its target (see the module docstring)."""
        net = self.network
        n = net.n_modules
        # Only masses and first moments are needed: the moving parts' masses and COMs.
        estimates = net.current_connector_estimates()[..., :4]  # (N, 6, 4), module frames
        parts = net.part_moments[..., :4]  # (N, 4, 4)
        side_a_connectors = estimates[:, 0] + estimates[:, 1] + estimates[:, 2]
        side_a_connectors += 0.0  # sums from +0, as numpy's reduction does
        side_b_connectors = estimates[:, 3] + estimates[:, 4] + estimates[:, 5]
        side_b_connectors += 0.0
        # Joint k separates parts 0..k (A side) from parts k+1..3 (B side); the fixed side holds the ground.
        fixed = net.fixed_block()
        moving = np.empty((n, 3, 4))
        moving[:, 0] = parts[:, 3] + parts[:, 2] + parts[:, 1]
        moving[:, 1] = parts[:, 3] + parts[:, 2]
        moving[:, 2] = parts[:, 3]
        moving += side_b_connectors[:, None]
        fixed_b = np.flatnonzero(fixed == 1)
        side_a = np.empty((fixed_b.size, 3, 4))
        side_a[:, 0] = parts[fixed_b, 0]
        side_a[:, 1] = side_a[:, 0] + parts[fixed_b, 1]
        side_a[:, 2] = side_a[:, 1] + parts[fixed_b, 2]
        moving[fixed_b] = side_a + side_a_connectors[fixed_b, None]
        total = net.own[:, :4] + side_a_connectors + side_b_connectors
        sign = np.where(fixed == 1, -1.0, 1.0)[:, None]

        # Module-frame points and directions, then all turned into the world at once (c_world = R c + t):
        # joint k's point and axis move with part k + 1 (they are fixed on both of its sides).
        m2 = moving[..., 0]
        local = np.empty((n, 10, 3))
        joint_point_axis = moments.rotate(net.part_rotation[:, 1:, None], self._joint_point_axis)
        np.add(net.part_translation[:, 1:], joint_point_axis[:, :, 0], out=local[:, 0:3])
        local[:, 3:6] = joint_point_axis[:, :, 1]
        np.divide(moving[..., 1:4], m2[..., None], out=local[:, 6:9])
        np.divide(total[:, 1:4], total[:, :1], out=local[:, 9])
        rotation, translation = net.world_poses()
        world = moments.rotate(rotation[:, None], local)
        world[:, [0, 1, 2, 6, 7, 8, 9]] += translation[:, None]
        axis_point, axis_direction, p2, com = world[:, 0:3], world[:, 3:6], world[:, 6:9], world[:, 9]
        pivot = com[:, None] - (m2 / total[:, :1])[..., None] * (p2 - axis_point)
        known = fixed >= 0
        rows = np.flatnonzero(known)
        if rows.size == n:
            rows = slice(None)  # every joint: no copies
        theta = np.zeros((n, 3))
        distance = np.zeros((n, 3))
        if np.any(known):
            theta[rows], distance[rows] = rotation_toward_line(
                pivot[rows], axis_direction[rows], com[rows, None], net.line[rows, None, :3], net.line[rows, None, 3:]
            )
        offset = com - net.line[:, :3]
        direction = net.line[:, 3:]
        support_distance = np.linalg.norm(offset - np.sum(offset * direction, axis=-1, keepdims=True) * direction, axis=-1)
        target = np.clip(net.angles + sign * theta, -self.limit, self.limit)
        target = np.where(known[:, None], target, net.angles)
        lever = p2 - axis_point
        cross = axis_direction[..., [1, 2, 0]] * lever[..., [2, 0, 1]] - axis_direction[..., [2, 0, 1]] * lever[..., [1, 2, 0]]
        mass_moment = np.linalg.norm(m2[..., None] * cross, axis=-1)
        support_distance = np.where(known, support_distance, 0.0)
        return JointDecisions(theta, target, distance, np.broadcast_to(support_distance[:, None], (n, 3)), np.where(known[:, None], mass_moment, 0.0))

    def gain_factors(self, decisions: JointDecisions) -> np.ndarray:
        """(N, 3) gain factors from each module's schedule: constant c0, distance c0 + c1 d / width,
        momentum c0 + c1 |m2 u x (p2 - q)|."""
        variable = np.where(self._distance_scheme, decisions.support_distance / self.width, np.where(self._momentum_scheme, decisions.mass_moment, 0.0))
        return self._c[:, :1] + self._c[:, 1:] * variable

    def torques(self, dt: float) -> tuple[np.ndarray, JointDecisions]:
        """Joint torques (N, 3) N m for the agents' current state, after a control period ``dt`` s, and the decisions."""
        decisions = self.decide()
        factor = self.gain_factors(decisions)
        return self.pid(decisions.target - self.network.angles, dt, factor * self._k0[:, 0:1], factor * self._k0[:, 1:2], factor * self._k0[:, 2:3]), decisions
