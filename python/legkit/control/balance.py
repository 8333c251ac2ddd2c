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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from legkit import _core
from legkit._validation import count, float_array, positive_scalar
from legkit.agents import moments
from legkit.agents.network import AgentNetwork
from legkit.control.gains import GainSchedule, gain_factor, scaled_gains
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
        # Every module's schedule as an (N, 1) column, evaluated for all joints at once by `gain_factor`.
        self._scheme, self._c0, self._c1, self._kp0, self._ki0, self._kd0 = (
            np.array([getattr(s, name) for s in schedules])[:, None] for name in ("scheme_index", "c0", "c1", "kp0", "ki0", "kd0")
        )
        self.pid = PID((n, 3))
        parameters = network.parameters
        self.limit = parameters.joint_limit
        self.width = parameters.width
        # Joint k's point (0, 0, z_k) and axis (a coordinate axis) in the zero-angle module frame.
        self._joint_height = (JOINT_Z * parameters.width)[:, None]
        # Joint k's axis is column argmax(u_k) of part k + 1's rotation: entry (column, part) of (3, 3 x 4 parts).
        self._joint_axis_entries = 4 * np.argmax(JOINT_AXES, axis=1) + np.arange(1, 4)

    def decide(self) -> JointDecisions:
        """Every joint's rotation toward the support line and its target (see the module docstring)."""
        # Component-major throughout (components first, modules last): every operation runs over all modules.
        net = self.network
        n = net.n_modules
        # Only masses and first moments are needed, (4, ..., N): m, h_x, h_y, h_z (module frames).
        side_a_connectors, side_b_connectors = net.block_estimates()[..., :4].transpose(1, 2, 0)  # (4, N) each
        parts = net.part_moments[..., :4].transpose(2, 1, 0)  # (4, 4, N)
        # Joint k separates parts 0..k (A side) from parts k+1..3 (B side); the side away from the ground moves.
        fixed = net.fixed_block()
        side_a = np.empty((4, 3, n))
        side_a[:, 0] = parts[:, 0]
        np.add(side_a[:, 0], parts[:, 1], out=side_a[:, 1])
        np.add(side_a[:, 1], parts[:, 2], out=side_a[:, 2])
        side_a += side_a_connectors[:, None]
        side_b = np.empty((4, 3, n))
        side_b[:, 2] = parts[:, 3]
        np.add(parts[:, 3], parts[:, 2], out=side_b[:, 1])
        np.add(side_b[:, 1], parts[:, 1], out=side_b[:, 0])
        side_b += side_b_connectors[:, None]
        moving = np.where(fixed == 1, side_a, side_b)
        total = net.own[:, :4].T + side_a_connectors + side_b_connectors
        m2 = moving[0]  # (3, N)

        # Points and directions in the module frame, then all turned into the world at once (c_world = R c + t):
        # joint k's point and axis (fixed in part k + 1), p2, the COM. The axis is a coordinate axis and the
        # point lies on the z axis, so R u and R p are a column of part k + 1's rotation (times the point's z;
        # +0.0 as the sum R p from +0 gives).
        part_rotation = net.part_rotation.transpose(2, 3, 1, 0)  # (3, 3, 4 parts, N)
        local = np.empty((3, 10, n))
        np.multiply(part_rotation[:, 2, 1:], self._joint_height, out=local[:, 0:3])
        local[:, 0:3] += 0.0
        local[:, 0:3] += net.part_translation[:, 1:].transpose(2, 1, 0)
        np.divide(moving[1:], m2, out=local[:, 3:6])
        np.divide(total[1:], total[0], out=local[:, 6])
        np.add(part_rotation.reshape(3, 12, n).take(self._joint_axis_entries, axis=1), 0.0, out=local[:, 7:10])
        rotation, translation = net.world_poses()
        world = moments.rotate_components(np.ascontiguousarray(rotation.transpose(1, 2, 0))[:, :, None], local)
        world[:, 0:7] += translation.T[:, None]
        axis_point, p2, com, axis_direction = world[:, 0:3], world[:, 3:6], world[:, 6], world[:, 7:10]
        lever = p2 - axis_point
        pivot = np.empty((n, 3, 3))  # (N, joint, 3), as the kernel below reads it
        np.subtract(com[:, None], (m2 / total[0]) * lever, out=pivot.transpose(2, 1, 0))

        known = fixed >= 0
        theta = np.zeros((n, 3))
        distance = np.zeros((n, 3))
        if known.any():
            rows = slice(None) if known.all() else known.nonzero()[0]  # every joint at once: no copies
            # Each query a contiguous row (the kernel reads contiguous same-shape batches directly).
            theta[rows], distance[rows] = rotation_toward_line(
                pivot[rows], np.ascontiguousarray(axis_direction.T[rows]),
                com.T[rows, None].repeat(3, axis=1), net.line[rows, None, :3].repeat(3, axis=1), net.line[rows, None, 3:].repeat(3, axis=1),
            )
        offset = com - net.line[:, :3].T
        direction = net.line[:, 3:].T
        along = offset * direction
        along = along[0] + along[1] + along[2]
        along += 0.0
        support_distance = _norm(offset - along * direction)
        target = np.minimum(np.maximum(net.angles + np.where(fixed == 1, -1.0, 1.0)[:, None] * theta, -self.limit), self.limit)
        target = np.where(known[:, None], target, net.angles)
        # |m2 u x (p2 - q)|, the cross product as numpy's np.cross computes it: u_{i+1} r_{i+2} - u_{i+2} r_{i+1}.
        u, r = np.concatenate([axis_direction, axis_direction[:2]]), np.concatenate([lever, lever[:2]])
        cross = u[1:4] * r[2:5]
        cross -= u[2:5] * r[1:4]
        mass_moment = _norm(m2 * cross).T
        support_distance = np.where(known, support_distance, 0.0)
        return JointDecisions(theta, target, distance, np.broadcast_to(support_distance[:, None], (n, 3)), np.where(known[:, None], mass_moment, 0.0))

    def gain_factors(self, decisions: JointDecisions) -> np.ndarray:
        """(N, 3) gain factors from each module's schedule (`legkit.control.gains.gain_factor`), with the
        support distance in module widths and the mass moment |m2 u x (p2 - q)|."""
        return gain_factor(self._scheme, self._c0, self._c1, decisions.support_distance / self.width, decisions.mass_moment)

    def torques(self, dt: float) -> tuple[np.ndarray, JointDecisions]:
        """Joint torques (N, 3) N m for the agents' current state, after a control period ``dt`` s, and the decisions."""
        decisions = self.decide()
        factor = self.gain_factors(decisions)
        error = decisions.target - self.network.angles
        return self.pid(error, dt, *scaled_gains(factor, self._kp0, self._ki0, self._kd0)), decisions


def _norm(vectors: np.ndarray) -> np.ndarray:
    """Euclidean norms of component-major vectors (3, ...), summed as ``np.linalg.norm`` sums them."""
    squares = vectors * vectors
    return np.sqrt(squares[0] + squares[1] + squares[2])


class BalanceKernel:
    """``controller`` and its ``AgentNetwork`` on the synchronous bus as one compiled kernel
    (``legkit._core.BalanceKernel``, Rust): a control step (the agents read their angles, run their rounds,
    and every joint computes its torque) is one call, over every module of every tree at once.

    The same algorithms as the Python network and controller, message for message (the same messages are
    sent, in the same rounds); the arithmetic is in another order, so values agree to rounding, not bit for
    bit. Built from a network on which no round has run yet (it starts from the same state: round 0's
    messages on the wire); the Python objects are not advanced by the kernel. The asynchronous bus is only
    in the Python network."""

    def __init__(self, controller: BalanceController):
        if not isinstance(controller, BalanceController):
            raise TypeError(f"controller: must be a BalanceController, got {type(controller).__name__}")
        net = controller.network
        if net.bus.mode != "sync":
            raise ValueError(f"controller: the kernel runs the synchronous bus only, the network's is {net.bus.mode!r}")
        if net.now != 0:
            raise ValueError("controller: the network has run rounds already; build the kernel from a fresh one")
        parameters = net.parameters
        parts = parameters.part_mass_properties()
        connector_rotation, connector_position = parameters.connector_frames()
        modules = [c.module for c in net.ground]
        rotations = np.array([c.rotation for c in net.ground]).reshape(-1, 3, 3)
        ground_pose = np.concatenate([rotations, np.array([c.translation for c in net.ground]).reshape(-1, 3, 1)], axis=-1)
        schedules = controller.schedules
        self.n_modules = net.n_modules
        self._core = _core.BalanceKernel(
            np.where(net.partner >= 0, net.partner * 6 + net.partner_slot, -1).ravel().tolist(), net.mate.reshape(-1, 3, 3),
            moments.pack(np.array([p.mass for p in parts]), np.array([p.com for p in parts]), np.array([p.inertia for p in parts])),
            connector_rotation, connector_position, np.argmax(JOINT_AXES, axis=1).tolist(), (JOINT_Z * parameters.width).tolist(),
            modules, [c.block for c in net.ground], ground_pose.reshape(-1, 3, 4), net.line[modules].reshape(-1, 6),
            net.leader_key[modules].tolist(), net.angles, [s.scheme_index for s in schedules],
            [[s.c0, s.c1, s.kp0, s.ki0, s.kd0] for s in schedules], parameters.joint_limit, parameters.width,
        )

    def run_until_quiescent(self, max_rounds: int = 100_000) -> int:
        """Run rounds until nothing is pending or on the wire; returns the rounds run (RuntimeError after
        ``max_rounds``), as ``AgentNetwork.run_until_quiescent``."""
        return int(self._core.run_until_quiescent(count(max_rounds, "max_rounds", 0)))

    def step(self, angles: np.ndarray, dt: float, rounds: int = 1) -> np.ndarray:
        """One control step: every agent reads its joint angles (N, 3) rad (``AgentNetwork.observe``), the
        network runs ``rounds`` rounds, and every joint computes its torque after ``dt`` s
        (``BalanceController.torques``). Returns the torques (N, 3) N m."""
        angles = float_array(angles, "angles", shape=(self.n_modules, 3))
        return self._core.step(angles, positive_scalar(dt, "dt"), count(rounds, "rounds", 0))

    @property
    def sent_by_module(self) -> np.ndarray:
        """(N,) data messages sent by each module so far, all channels (as the channels' ``sent_by_module``)."""
        return self._core.sent_by_module

    def connector_estimates(self) -> np.ndarray:
        """(N, 6, 13) as ``AgentNetwork.current_connector_estimates``."""
        return self._core.estimates()

    def world_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """(rotations (N, 3, 3), translations (N, 3)) as ``AgentNetwork.world_poses``."""
        return self._core.world_poses()
