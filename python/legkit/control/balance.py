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
        self._scheme = np.array([SCHEMES.index(s.scheme) for s in schedules])[:, None]
        self._c = np.array([[s.c0, s.c1] for s in schedules])
        self._k0 = np.array([[s.kp0, s.ki0, s.kd0] for s in schedules])
        self.pid = PID((n, 3))
        parameters = network.parameters
        self.limit = parameters.joint_limit
        self.width = parameters.width
        self._joint_points = np.outer(JOINT_Z, [0.0, 0.0, parameters.width])

    def decide(self) -> JointDecisions:
        """Every joint's rotation toward the support line and its target (see the module docstring)."""
        net = self.network
        n = net.n_modules
        estimates = net.current_connector_estimates()  # (N, 6, 13), module frames
        parts = net.part_moments  # (N, 4, 13)
        side_a_connectors = estimates[:, :3].sum(axis=1)
        side_b_connectors = estimates[:, 3:].sum(axis=1)
        # Joint k separates parts 0..k (A side) from parts k+1..3 (B side).
        side_a = np.cumsum(parts, axis=1)[:, :3] + side_a_connectors[:, None]
        side_b = np.cumsum(parts[:, ::-1], axis=1)[:, ::-1][:, 1:] + side_b_connectors[:, None]
        total = net.own + side_a_connectors + side_b_connectors
        fixed = net.fixed_block()
        moving = np.where((fixed == 1)[:, None, None], side_a, side_b)
        sign = np.where(fixed == 1, -1.0, 1.0)[:, None]

        rotation, translation = net.world_poses()
        # Joint k's point and axis move with part k + 1 (they are fixed on both of its sides).
        part_rotation, part_translation = net.part_rotation[:, 1:], net.part_translation[:, 1:]
        axis_point = part_translation + np.einsum("nkij,kj->nki", part_rotation, self._joint_points)
        axis_direction = np.einsum("nkij,kj->nki", part_rotation, JOINT_AXES)
        axis_point = translation[:, None] + np.einsum("nij,nkj->nki", rotation, axis_point)
        axis_direction = np.einsum("nij,nkj->nki", rotation, axis_direction)
        # Only masses and COMs are needed here: c_world = R c + t.
        m2 = moving[..., 0]
        p2 = translation[:, None] + np.einsum("nij,nkj->nki", rotation, moving[..., 1:4] / m2[..., None])
        total_mass = total[:, :1]
        com = np.repeat((translation + np.einsum("nij,nj->ni", rotation, total[:, 1:4] / total_mass))[:, None], 3, axis=1)
        pivot = com - (m2 / total_mass)[..., None] * (p2 - axis_point)
        line_point = np.broadcast_to(net.line[:, None, :3], (n, 3, 3))
        line_direction = np.broadcast_to(net.line[:, None, 3:], (n, 3, 3))
        known = (fixed >= 0)[:, None] & np.ones((1, 3), dtype=bool)
        theta = np.zeros((n, 3))
        distance = np.zeros((n, 3))
        if known.any():
            theta[known], distance[known] = rotation_toward_line(
                pivot[known], axis_direction[known], com[known], line_point[known], line_direction[known]
            )
        offset = com[:, 0] - net.line[:, :3]
        direction = net.line[:, 3:]
        support_distance = np.linalg.norm(offset - np.sum(offset * direction, axis=-1, keepdims=True) * direction, axis=-1)
        target = np.clip(net.angles + sign * theta, -self.limit, self.limit)
        target = np.where(known, target, net.angles)
        mass_moment = np.linalg.norm(m2[..., None] * np.cross(axis_direction, p2 - axis_point), axis=-1)
        support_distance = np.where(fixed >= 0, support_distance, 0.0)
        return JointDecisions(theta, target, distance, np.broadcast_to(support_distance[:, None], (n, 3)), np.where(known, mass_moment, 0.0))

    def gain_factors(self, decisions: JointDecisions) -> np.ndarray:
        """(N, 3) gain factors from each module's schedule: constant c0, distance c0 + c1 d / width,
        momentum c0 + c1 |m2 u x (p2 - q)|."""
        variable = np.select(
            [self._scheme == 1, self._scheme == 2], [decisions.support_distance / self.width, decisions.mass_moment], 0.0
        )
        return self._c[:, :1] + self._c[:, 1:] * variable

    def torques(self, dt: float) -> tuple[np.ndarray, JointDecisions]:
        """Joint torques (N, 3) N m for the agents' current state, after a control period ``dt`` s, and the decisions."""
        decisions = self.decide()
        factor = self.gain_factors(decisions)
        kp, ki, kd = (factor * self._k0[:, i : i + 1] for i in range(3))
        return self.pid(decisions.target - self.network.angles, dt, kp, ki, kd), decisions
