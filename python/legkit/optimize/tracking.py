"""Tracking an optimised gait in `lk.Simulation` with a linear time-varying model-predictive controller.

Joint PD + feed-forward cannot hold the amble's two-point supports: linearised around the plan, the
simulation's one-cycle multiplier under PD is in the hundreds to thousands (docs/optimize.md). A time-varying LQR
on the optimiser's contact model holds the model, but by pulling on stance feet, which the simulation cannot do.

`TrackingModel.build` linearises that contact model (the phase's feet held, `lk.contact_dynamics`; touchdowns by
`lk.impact`; semi-implicit Euler substeps under a zero-order hold) around the plan sampled every control period
over one cycle, by central differences in the tangent space (`shooting.tangent_difference`), together with the
stance forces and the swing feet's heights, and the periodic LQR cost-to-go. The reference raises each swing foot
by `swing_clearance` x sin(pi s) over its swing (s its fraction) through its leg's joints: planned soft
touchdowns and lift-offs skim the ground, and a tipping error of a degree puts a skimming foot on it.
`MPC` then solves, every control period, a dense QP over a short horizon (qpOASES from the casadi wheel; the
correction held over blocks of control periods): the predicted deviation's quadratic cost, the cost-to-go at
the horizon's end, subject to each stance normal force above a floor and inside the friction pyramid and to the
swing feet above the ground (softly, through slacks: the linear model knows no ground), within the torque bounds.
The first correction is applied. `track` runs it in `lk.Simulation`, the PD servo off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from tqdm import tqdm

import legkit as lk
from legkit.optimize.problem import MultiphaseProblem, Trajectory
from legkit.optimize.replay import Replay, clear_of_ground, foot_shapes, outcome, periodic_samples, phase_of
from legkit.optimize.shooting import tangent_add, tangent_difference

#: Deviation weights of the LQR cost: the free-flyer base's position and attitude (rotation vector), each joint
#: angle, the base's linear and angular velocity, each joint rate; and each joint torque correction.
BASE_WEIGHTS = (10.0, 10.0, 10.0, 100.0, 100.0, 10.0)
JOINT_WEIGHT = 10.0
BASE_RATE_WEIGHTS = (0.1, 0.1, 1.0, 1.0, 1.0, 1.0)
JOINT_RATE_WEIGHT = 0.1
TORQUE_WEIGHT = 0.1


def state_weights(problem: MultiphaseProblem) -> np.ndarray:
    """(2 nv,) the diagonal of the LQR's state cost on a free-flyer robot."""
    joints = problem.nv - 6
    return np.concatenate([BASE_WEIGHTS, np.full(joints, JOINT_WEIGHT), BASE_RATE_WEIGHTS, np.full(joints, JOINT_RATE_WEIGHT)])


def sampled_reference(problem: MultiphaseProblem, trajectory: Trajectory, t: np.ndarray,
                      swing_clearance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, v, u) of the plan at t (`periodic_samples`) with every swing foot raised by swing_clearance x sin(pi s)
    over its swing (s its fraction) through its leg's joints (damped least squares), v by the rise's rate."""
    q, v, u = periodic_samples(problem, trajectory, t)
    if swing_clearance == 0.0:
        return q, v, u
    durations = np.asarray(trajectory.durations)
    period, starts, count = float(np.sum(durations)), np.concatenate([[0.0], np.cumsum(durations)]), len(problem.phases)
    raised = q.copy()
    for name in problem.feet:
        swing = [k for k in range(count) if name not in problem.phases[k].contacts]
        if not swing:
            continue
        first = next(k for k in swing if (k - 1) % count not in swing)
        s = np.mod(t - starts[first], period) / float(np.sum(durations[swing]))
        swinging = np.flatnonzero(s < 1.0)
        if not len(swinging):
            continue
        jac = np.asarray(lk.jacobian(problem.model, q[swinging], problem.foot_body[name], problem.foot_point[name], "local_world_aligned"))[:, :3]
        columns = np.asarray(problem.actuated)[np.any(jac[..., problem.actuated] != 0.0, axis=(0, 1))]  # the foot's leg
        block = jac[..., columns]
        rise = np.zeros((len(swinging), 3, 1))
        rise[:, 2, 0] = swing_clearance * np.sin(np.pi * s[swinging])
        # Damped least squares: swing legs pass near full extension.
        step = np.swapaxes(block, 1, 2) @ np.linalg.solve(block @ np.swapaxes(block, 1, 2) + 1e-3 * np.eye(3), rise)
        raised[swinging[:, None], columns + (problem.nq - problem.nv)] += step[..., 0]
    actuated = np.asarray(problem.actuated)
    v = v.copy()
    v[:, actuated] += np.gradient(raised[:, actuated + (problem.nq - problem.nv)] - q[:, actuated + (problem.nq - problem.nv)], t, axis=0)
    return raised, v, u


@dataclass
class TrackingModel:
    """One cycle of the plan, linearised every control period (module docstring). Deviations are tangent-space
    configurations (`tangent_difference`) then velocities: e (2 nv). Per sample i of N: e_{i+1} = A_i e_i +
    B_i du_i + residual_i (the reference is not exactly a motion of the stepped model); the stance forces
    forces_i + force_state_i e_i + force_input_i du_i (world axes, 3 per held foot); the feet's heights
    heights_i + height_state_i e_i, `swing_i` marking the feet in the air; cost_to_go (N + 1) the periodic
    LQR's."""

    problem: MultiphaseProblem
    trajectory: Trajectory
    dt: float
    swing_clearance: float
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    u: np.ndarray
    phase: np.ndarray
    A: np.ndarray
    B: np.ndarray
    residual: np.ndarray
    forces: list[np.ndarray]
    force_state: list[np.ndarray]
    force_input: list[np.ndarray]
    heights: np.ndarray
    height_state: np.ndarray
    swing: np.ndarray
    state_weights: np.ndarray
    torque_weights: np.ndarray
    cost_to_go: np.ndarray

    @classmethod
    def build(cls, problem: MultiphaseProblem, trajectory: Trajectory, dt: float = 2e-3, swing_clearance: float = 0.01,
              substeps: int = 4, step: float = 1e-6, progress: bool = True) -> TrackingModel:
        if not problem.model.floating_base or not problem.periodic:
            raise ValueError("TrackingModel needs a periodic free-flyer gait")
        if not dt > 0.0 or substeps < 1:
            raise ValueError(f"dt must be > 0 and substeps >= 1, got {dt}, {substeps}")
        period = float(np.sum(trajectory.durations))
        count = int(round(period / dt))
        if not np.isclose(count * dt, period, rtol=0.0, atol=1e-9 * period + 1e-12):
            dt = period / count  # whole control periods per cycle, so the linearisation wraps around
        t = np.arange(count + 1) * dt
        q, v, u = sampled_reference(problem, trajectory, t, swing_clearance)
        phase = phase_of(trajectory, t)
        nv, nu = problem.nv, problem.nu
        n = 2 * nv
        names = list(problem.feet)
        perturb = np.concatenate([np.zeros((1, n + nu)), step * np.eye(n + nu), -step * np.eye(n + nu)])
        moved = np.concatenate([np.zeros((1, nv)), step * np.eye(nv), -step * np.eye(nv)])
        A, B, residual = np.empty((count, n, n)), np.empty((count, n, nu)), np.empty((count, n))
        forces: list[np.ndarray] = [np.empty(0)] * count
        force_state: list[np.ndarray] = [np.empty(0)] * count
        force_input: list[np.ndarray] = [np.empty(0)] * count
        swing = np.array([[name not in problem.phases[phase[i]].contacts for name in names] for i in range(count)])
        # One batched step per run of samples with the same (phase, next phase): every perturbation of every sample.
        runs = np.flatnonzero((np.diff(phase[:count]) != 0) | (np.diff(phase[1:]) != 0)) + 1
        for samples in tqdm(np.split(np.arange(count), runs), desc="linearising the plan", unit="run", leave=False, disable=not progress):
            rows = len(perturb)
            qi = tangent_add(problem, np.repeat(q[samples], rows, axis=0), np.tile(perturb[:, :nv], (len(samples), 1)))
            vi = np.repeat(v[samples], rows, axis=0) + np.tile(perturb[:, nv:n], (len(samples), 1))
            tau = np.zeros((len(qi), nv))
            tau[:, problem.actuated] = np.repeat(u[samples], rows, axis=0) + np.tile(perturb[:, n:], (len(samples), 1))
            qi, vi, f = held_step(problem, phase[samples[0]], phase[samples[0] + 1], qi, vi, tau, dt, substeps)
            after = np.repeat(q[samples + 1], rows, axis=0)
            e = np.concatenate([tangent_difference(problem, problem.configuration(qi), after), vi - np.repeat(v[samples + 1], rows, axis=0)], axis=1)
            e, f = e.reshape(len(samples), rows, n), f.reshape(len(samples), rows, -1)
            residual[samples] = e[:, 0]
            central = np.swapaxes(e[:, 1 : 1 + n + nu] - e[:, 1 + n + nu :], 1, 2) / (2.0 * step)
            A[samples], B[samples] = central[..., :n], central[..., n:]
            central = np.swapaxes(f[:, 1 : 1 + n + nu] - f[:, 1 + n + nu :], 1, 2) / (2.0 * step)
            for j, i in enumerate(samples):
                forces[i], force_state[i], force_input[i] = f[j, 0], central[j, :, :n], central[j, :, n:]
        moved_q = tangent_add(problem, np.repeat(q[:count], len(moved), axis=0), np.tile(moved, (count, 1)))
        z = problem.foot_positions(problem.configuration(moved_q), names)[..., 2].reshape(count, len(moved), len(names))
        heights = z[:, 0]
        height_state = np.zeros((count, len(names), n))
        height_state[..., :nv] = np.swapaxes(z[:, 1 : 1 + nv] - z[:, 1 + nv :], 1, 2) / (2.0 * step)
        weights, torque_weights = state_weights(problem), np.full(nu, TORQUE_WEIGHT)
        return cls(problem, trajectory, dt, swing_clearance, t, q, v, u, phase, A, B, residual, forces, force_state, force_input,
                   heights, height_state, swing, weights, torque_weights, periodic_cost_to_go(A, B, weights, torque_weights))

    def gains(self) -> np.ndarray:
        """(N, nu, 2 nv) the periodic LQR's feedback gains (du = -K e), from the cost-to-go."""
        R = np.diag(self.torque_weights)
        return np.stack([np.linalg.solve(R + b.T @ p @ b, b.T @ p @ a) for a, b, p in zip(self.A, self.B, self.cost_to_go[1:])])


def held_step(problem: MultiphaseProblem, phase: int, next_phase: int, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float,
              substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, v, forces) after dt of the optimiser's contact model from (q, v) (B, .) under torques tau (B, nv) held
    over it: `phase`'s feet held (`lk.contact_dynamics`), semi-implicit Euler substeps, then the touchdown (eq. 7,
    `lk.impact`) of `next_phase`'s feet if it differs; forces (B, 3 x held feet) at the start."""
    feet = [(problem.foot_body[name], problem.foot_point[name]) for name in problem.phases[phase].contacts]
    start = np.zeros((len(q), 3 * len(feet)))
    for sub in range(substeps):
        a, f = lk.contact_dynamics(problem.model, q, v, tau, feet)
        if sub == 0:
            start = np.asarray(f).reshape(len(q), -1)
        v = v + np.asarray(a) * (dt / substeps)
        q = np.asarray(lk.integrate(problem.model, q, v, dt / substeps))
    if next_phase != phase:
        landing = [(problem.foot_body[name], problem.foot_point[name]) for name in problem.phases[next_phase].contacts]
        v = np.asarray(lk.impact(problem.model, q, v, landing)[0])
    return q, v, start


def periodic_cost_to_go(A: np.ndarray, B: np.ndarray, weights: np.ndarray, torque_weights: np.ndarray, sweeps: int = 4) -> np.ndarray:
    """(N + 1, n, n) the discrete Riccati recursion run backwards over the cycle `sweeps` times, each sweep starting
    from the last one's first value (the periodic solution, to within its convergence)."""
    Q, R = np.diag(weights), np.diag(torque_weights)
    P = np.empty((len(A) + 1, A.shape[1], A.shape[1]))
    P[-1] = Q
    for _ in range(sweeps):
        for i in reversed(range(len(A))):
            bp = B[i].T @ P[i + 1]
            gain = np.linalg.solve(R + bp @ B[i], bp @ A[i])
            closed = A[i] - B[i] @ gain
            P[i] = Q + gain.T @ R @ gain + closed.T @ P[i + 1] @ closed
            P[i] = 0.5 * (P[i] + P[i].T)
        P[-1] = P[0]
    return P


class MPC:
    """The controller of the module docstring: `correction(i, e)` is the torque correction (nu,) at control instant
    i (any cycle) for the deviation e (2 nv) from the reference there."""

    def __init__(self, model: TrackingModel, horizon: int = 60, block: int = 6, min_normal_force: float = 0.5,
                 friction: float = 0.6, min_swing_height: float = 0.003, slack_weight: float = 1e6,
                 torque_bounds: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """torque_bounds (lower, upper), each (nu,): the actuators' torques, which bound plan + correction; default the
        plan's (`problem.u_bounds`). A plan kept inside its motors (`amble_problem(torque_margin=)`) leaves the
        difference to the correction."""
        import casadi as ca

        if horizon < 1 or block < 1 or horizon % block:
            raise ValueError(f"horizon must be a positive multiple of block, got horizon {horizon}, block {block}")
        if not friction > 0.0 or not min_normal_force >= 0.0:
            raise ValueError(f"friction must be > 0 and min_normal_force >= 0, got {friction}, {min_normal_force}")
        self.model, self.horizon, self.block = model, horizon, block
        self.min_normal_force, self.friction, self.min_swing_height, self.slack_weight = min_normal_force, friction, min_swing_height, slack_weight
        self.count = len(model.A)
        nu = model.B.shape[2]
        self.variables = horizon // block * nu
        # The row counts vary with the instant only through the number of held feet and swing feet: size the QP for
        # the largest window and pad unused rows with -inf bounds.
        feet = [len(f) // 3 for f in model.forces]
        swing = model.swing.sum(axis=1)
        self.force_rows = max(sum(5 * feet[(i + j) % self.count] for j in range(horizon)) for i in range(self.count))
        self.slacks = max(int(sum(swing[(i + j) % self.count] for j in range(horizon))) for i in range(self.count))
        rows, columns = self.force_rows + self.slacks, self.variables + self.slacks
        self.solver = ca.conic("tracking", "qpoases", {"h": ca.Sparsity.dense(columns, columns), "a": ca.Sparsity.dense(rows, columns)},
                               {"printLevel": "none", "error_on_fail": False})
        self.gains = model.gains()
        self.state_cost, self.torque_cost = np.diag(model.state_weights), np.diag(model.torque_weights)
        self.failures = 0
        planned = (np.full(nu, -np.inf), np.full(nu, np.inf)) if model.problem.u_bounds is None else model.problem.u_bounds
        lower, upper = (np.asarray(b, dtype=np.float64) for b in (torque_bounds if torque_bounds is not None else planned))
        if lower.shape != (nu,) or upper.shape != (nu,) or not np.all(lower < upper):
            raise ValueError(f"torque_bounds must be two ({nu},) arrays with lower < upper, got shapes {lower.shape}, {upper.shape}")
        self.torque_lower, self.torque_upper = lower, upper

    def correction(self, i: int, e: np.ndarray) -> np.ndarray:
        m = self.model
        nu, n = m.B.shape[2], m.A.shape[1]
        Q, R = self.state_cost, self.torque_cost
        S, T, c = np.eye(n), np.zeros((n, self.variables)), np.zeros(n)  # e_j = S e + T U + c
        hessian, gradient = np.zeros((self.variables, self.variables)), np.zeros(self.variables)
        force_a, force_b, height_a, height_b = [], [], [], []
        for j in range(self.horizon):
            k = (i + j) % self.count
            select = np.zeros((nu, self.variables))
            select[:, (j // self.block) * nu : (j // self.block + 1) * nu] = np.eye(nu)
            predicted = S @ e + c
            held = len(m.forces[k]) // 3
            pyramid = _pyramid(held, self.friction)
            force_a.append(pyramid @ (m.force_state[k] @ T + m.force_input[k] @ select))
            force_b.append(np.tile([self.min_normal_force, 0.0, 0.0, 0.0, 0.0], held) - pyramid @ (m.forces[k] + m.force_state[k] @ predicted))
            sw = m.swing[k]
            height_a.append(m.height_state[k][sw] @ T)
            height_b.append(np.minimum(self.min_swing_height, m.heights[k][sw]) - m.heights[k][sw] - m.height_state[k][sw] @ predicted)
            hessian += select.T @ R @ select
            S, T, c = m.A[k] @ S, m.A[k] @ T + m.B[k] @ select, m.A[k] @ c + m.residual[k]
            W = m.cost_to_go[k + 1] if j == self.horizon - 1 else Q
            hessian += T.T @ W @ T
            gradient += T.T @ W @ (S @ e + c)
        rows, columns = self.force_rows + self.slacks, self.variables + self.slacks
        a, lower = np.zeros((rows, columns)), np.full(rows, -np.inf)
        forces = np.concatenate(force_a)
        a[: len(forces), : self.variables], lower[: len(forces)] = forces, np.concatenate(force_b)
        heights = np.concatenate(height_a)
        a[self.force_rows : self.force_rows + len(heights), : self.variables] = heights
        a[self.force_rows : self.force_rows + len(heights), self.variables : self.variables + len(heights)] = np.eye(len(heights))
        lower[self.force_rows : self.force_rows + len(heights)] = np.concatenate(height_b)
        h = np.zeros((columns, columns))
        h[: self.variables, : self.variables] = 0.5 * (hessian + hessian.T)
        h[self.variables :, self.variables :] = self.slack_weight * np.eye(self.slacks)
        u = m.u[i % self.count]
        lo, hi = self.torque_lower, self.torque_upper
        solution = self.solver(h=h, g=np.concatenate([gradient, np.zeros(self.slacks)]), a=a, lba=lower, uba=np.full(rows, np.inf),
                               lbx=np.concatenate([np.tile(lo - u, self.variables // nu), np.zeros(self.slacks)]),
                               ubx=np.concatenate([np.tile(hi - u, self.variables // nu), np.full(self.slacks, np.inf)]))
        if not self.solver.stats()["success"]:  # the LQR's correction, unconstrained
            self.failures += 1
            return -self.gains[i % self.count] @ e
        return np.asarray(solution["x"]).ravel()[:nu]


def _pyramid(feet: int, friction: float) -> np.ndarray:
    """(5 feet, 3 feet): rows r with r . f >= (floor, 0, 0, 0, 0) per foot: f_z, then mu f_z -+ f_x, mu f_z -+ f_y."""
    rows = np.zeros((5 * feet, 3 * feet))
    for foot in range(feet):
        x, y, z = 3 * foot, 3 * foot + 1, 3 * foot + 2
        r = rows[5 * foot : 5 * foot + 5]
        r[:, z] = [1.0, friction, friction, friction, friction]
        r[1, x], r[2, x], r[3, y], r[4, y] = -1.0, 1.0, -1.0, 1.0
    return rows


def track(problem: MultiphaseProblem, trajectory: Trajectory, cycles: int = 5, foot_radius: float = 0.002, dt: float = 1e-3,
          control_every: int = 2, friction: float = 0.8, swing_clearance: float = 0.01, model: TrackingModel | None = None,
          joint_offset: np.ndarray | None = None, progress: bool = True, **mpc: Any) -> Replay:
    """Simulate `cycles` cycles under `MPC` (its keyword arguments in **mpc), from the plan's first state with the
    base raised clear of the ground (`clear_of_ground`); the feet as in `replay`. model: a `TrackingModel` built
    for this plan and control period (built here otherwise). joint_offset (nu,): added to the first state's joint
    angles, a perturbed start. progress: progress bars (linearisation, simulation). Stops stepping once the robot
    has fallen."""
    model = model if model is not None else TrackingModel.build(problem, trajectory, dt * control_every, swing_clearance, progress=progress)
    if not np.isclose(model.dt, dt * control_every):
        raise ValueError(f"the TrackingModel's control period {model.dt} differs from dt x control_every = {dt * control_every}")
    controller = MPC(model, **mpc)
    sim = lk.Simulation(problem.model, dt=dt, ground=lk.Ground.plane(friction), shapes=foot_shapes(problem, foot_radius))
    steps = cycles * len(model.A)
    t = np.arange(steps + 1) * model.dt
    planned_q, planned_v, _ = sampled_reference(problem, trajectory, t, model.swing_clearance)
    start = planned_q[0].copy()
    if joint_offset is not None:
        start[np.asarray(problem.actuated) + (problem.nq - problem.nv)] += np.asarray(joint_offset, dtype=np.float64)
    sim.reset(clear_of_ground(problem, start, foot_radius), planned_v[0])
    simulated = np.empty_like(planned_q)
    simulated[0] = sim.q
    tau = np.zeros(problem.nv)
    for i in tqdm(range(steps), desc="tracking in simulation", unit="step", leave=False, disable=not progress, mininterval=0.5):
        e = np.concatenate([tangent_difference(problem, sim.q[None], planned_q[i][None])[0], sim.v - planned_v[i]])
        tau[problem.actuated] = model.u[i % len(model.A)] + controller.correction(i, e)
        try:
            sim.step(tau, control_every)
        except RuntimeError:  # the simulation diverged: the robot is down
            simulated[i + 1 :] = simulated[i]
            break
        simulated[i + 1] = sim.q
        if not outcome(problem, t[i + 1 : i + 2], simulated[i + 1 : i + 2], planned_q[i + 1 : i + 2]).upright:
            simulated[i + 2 :] = simulated[i + 1]
            break
    return outcome(problem, t, simulated, planned_q)
