"""Tracking an optimised gait in `lk.Simulation` with a linear time-varying model-predictive controller.

Joint PD + feed-forward cannot hold the amble's two-point supports: linearised around the plan, the
simulation's one-cycle multiplier under PD is in the hundreds to thousands. A time-varying LQR
on the optimiser's contact model holds the model, but by pulling on stance feet, which the simulation cannot do.

`TrackingModel.build` linearises that contact model (the phase's feet held, `lk.contact_dynamics`: point feet as
points, flat soles as frames (dim=6); touchdowns by `lk.impact`; semi-implicit Euler substeps under a zero-order
hold) around the plan sampled every control period over one cycle, analytically: the chain rule through the
substeps and the touchdown from the core's derivatives (`lk.contact_dynamics_derivatives`, `lk.impact_derivatives`,
`lk.integrate_jacobians`, `lk.difference_jacobians`), batched over the samples; with the stance forces, the swing
feet's heights (`lk.jacobian`), and the periodic LQR cost-to-go. Deviations live in the tangent space of the
configuration (`lk.difference`, Pinocchio's convention). The reference raises each swing foot by `swing_clearance`
x sin(pi s) over its swing (s its fraction) through its leg's joints: planned soft touchdowns and lift-offs skim
the ground, and a tipping error of a degree puts a skimming foot on it.

`MPC` solves, every control period, a QP over a 120 ms horizon (the correction held over blocks of control
periods): the predicted deviation's quadratic cost and the cost-to-go at the horizon's end, subject to each stance
normal force above a floor and inside the friction pyramid (a flat sole's torque within eq. 6 too) and to the swing
feet above the ground (softly, through slacks: the linear model knows no ground), within the torque bounds. Every
instant's QP is condensed once for the whole cycle (batched); per control period the unconstrained minimiser is
checked against the rows and, where it violates some, the QP is solved by constraint generation on its dual
(non-negative least squares). The first correction is applied. `track` runs it in `lk.Simulation`, the PD servo
off, optionally on another plant (model mismatch).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any, Literal

import numpy as np
from scipy.optimize import nnls
from threadpoolctl import threadpool_limits

import legkit as lk
from legkit._extras import progress as progress_bar
from legkit.optimize.contact import ContactModel
from legkit.optimize.layout import Trajectory
from legkit.optimize.replay import Replay, clear_of_ground, foot_shapes, outcome, periodic_samples, phase_of

#: Deviation weights of the LQR cost: the free-flyer base's position and attitude (rotation vector), each joint
#: angle, the base's linear and angular velocity, each joint rate; and each joint torque correction.
BASE_WEIGHTS = (10.0, 10.0, 10.0, 100.0, 100.0, 10.0)
JOINT_WEIGHT = 10.0
BASE_RATE_WEIGHTS = (0.1, 0.1, 1.0, 1.0, 1.0, 1.0)
JOINT_RATE_WEIGHT = 0.1
TORQUE_WEIGHT = 0.1


def state_weights(problem: ContactModel) -> np.ndarray:
    """(2 nv,) the diagonal of the LQR's state cost on a free-flyer robot."""
    joints = problem.nv - 6
    return np.concatenate([BASE_WEIGHTS, np.full(joints, JOINT_WEIGHT), BASE_RATE_WEIGHTS, np.full(joints, JOINT_RATE_WEIGHT)])


def sampled_reference(problem: ContactModel, trajectory: Trajectory, t: np.ndarray,
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


#: `TrackingModel.build` and `track` (the MPC's condensation and its per-period solves) run numpy's and scipy's BLAS on
#: one thread: these products are small and batched, and OpenBLAS's default thread per core made them up to 40x slower in
#: CPU on a loaded 2-core machine (`legkit gait --robot biped --optimize`'s one-cycle replay: 44 s of CPU, 4 s on one
#: thread).
ONE_BLAS_THREAD = threadpool_limits.wrap(limits=1, user_api="blas")


@dataclass
class TrackingModel:
    """One cycle of the plan, linearised every control period (module docstring). Deviations e (2 nv) are the
    configuration's `lk.difference` from the reference (its tangent space, Pinocchio's convention) then the velocity's.
    Per sample i of N: e_{i+1} = A_i e_i + B_i du_i + residual_i (the reference is not exactly a motion of the
    stepped model); the held feet's forces (world axes, `contact_width` per foot: a point foot's force or a sole's
    force and torque about its centre, padded to the most feet held at once, `held` marking the real ones) forces_i
    + force_state_i e_i + force_input_i du_i; the feet's heights heights_i + height_state_i e_i, `swing_i` marking
    the feet in the air; cost_to_go (N + 1) the periodic LQR's."""

    problem: ContactModel
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
    forces: np.ndarray
    force_state: np.ndarray
    force_input: np.ndarray
    held: np.ndarray
    heights: np.ndarray
    height_state: np.ndarray
    swing: np.ndarray
    state_weights: np.ndarray
    torque_weights: np.ndarray
    cost_to_go: np.ndarray

    @classmethod
    @ONE_BLAS_THREAD
    def build(cls, problem: ContactModel, trajectory: Trajectory, dt: float = 2e-3, swing_clearance: float = 0.01,
              substeps: int = 4) -> TrackingModel:
        """Sample the plan every dt (rounded so that whole control periods make one cycle) and linearise the
        contact model's step (`held_step`) there analytically: the chain rule through its substeps and touchdown
        from the core's derivatives, batched over the samples of each run of one (phase, next phase). A mirrored half
        cycle is tracked as its whole cycle (`ContactModel.whole_trajectory`)."""
        problem, trajectory = problem.whole_trajectory(trajectory)
        if not problem.model.floating_base or not problem.periodic:
            raise ValueError("problem: TrackingModel needs a periodic free-flyer gait")
        if not (np.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be a positive number, got {dt}")
        if not (isinstance(substeps, (int, np.integer)) and substeps >= 1):
            raise ValueError(f"substeps must be an integer >= 1, got {substeps}")
        if not (np.isfinite(swing_clearance) and swing_clearance >= 0.0):
            raise ValueError(f"swing_clearance must be a non-negative number, got {swing_clearance}")
        period = float(np.sum(trajectory.durations))
        count = max(1, int(round(period / dt)))
        dt = period / count  # whole control periods per cycle, so the linearisation wraps around
        t = np.arange(count + 1) * dt
        q, v, u = sampled_reference(problem, trajectory, t, swing_clearance)
        if not np.all(np.isfinite(q)):
            raise ValueError(f"swing_clearance: raising the swing feet by {swing_clearance} m gives no finite joint angles")
        phase = phase_of(trajectory, t)
        nv, nu = problem.nv, problem.nu
        n = 2 * nv
        names = list(problem.feet)
        most, width = max(len(p.contacts) for p in problem.phases), contact_width(problem)
        A, B, residual = np.empty((count, n, n)), np.empty((count, n, nu)), np.empty((count, n))
        forces, force_state, force_input = np.zeros((count, width * most)), np.zeros((count, width * most, n)), np.zeros((count, width * most, nu))
        held = np.zeros((count, most), dtype=bool)
        swing = np.array([[name not in problem.phases[phase[i]].contacts for name in names] for i in range(count)])
        # One batched step per run of samples with the same (phase, next phase).
        runs = np.flatnonzero((np.diff(phase[:count]) != 0) | (np.diff(phase[1:]) != 0)) + 1
        for samples in np.split(np.arange(count), runs):
            tau = np.zeros((len(samples), nv))
            tau[:, problem.actuated] = u[samples]
            k = phase[samples[0]]
            q1, v1, f, state, force = held_step_linearised(problem, k, phase[samples[0] + 1], q[samples], v[samples], tau, dt, substeps)
            d1 = np.asarray(lk.difference_jacobians(problem.model, q[samples + 1], q1)[1])
            residual[samples] = np.concatenate([np.asarray(lk.difference(problem.model, q[samples + 1], q1)), v1 - v[samples + 1]], axis=1)
            A[samples, :nv], B[samples, :nv] = np.split(d1 @ state[:, :nv], [n], axis=2)
            A[samples, nv:], B[samples, nv:] = np.split(state[:, nv:], [n], axis=2)
            rows = f.shape[1]
            forces[samples, :rows] = f
            force_state[samples, :rows], force_input[samples, :rows] = np.split(force, [n], axis=2)
            held[samples, : rows // width] = True
        heights = problem.foot_positions(q[:count], names)[..., 2]
        height_state = np.zeros((count, len(names), n))
        for foot, name in enumerate(names):
            height_state[:, foot, :nv] = np.asarray(lk.jacobian(problem.model, q[:count], problem.foot_body[name], problem.foot_point[name],
                                                             "local_world_aligned"))[:, 2]
        weights, torque_weights = state_weights(problem), np.full(nu, TORQUE_WEIGHT)
        return cls(problem, trajectory, dt, swing_clearance, t, q, v, u, phase, A, B, residual, forces, force_state, force_input,
                   held, heights, height_state, swing, weights, torque_weights, periodic_cost_to_go(A, B, weights, torque_weights))

    def deviation(self, i: int, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(2 nv) the state (q, v) minus the reference at control instant i (any cycle; `reference`)."""
        q_ref, v_ref = self.reference(i)
        return np.concatenate([np.asarray(lk.difference(self.problem.model, q_ref, q)), v - v_ref])

    def reference(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) of the reference at control instant i of any cycle, the travel advanced by whole cycles."""
        cycle, k = divmod(i, len(self.A))
        q = self.q[k].copy()
        if self.problem.travel_index is not None:
            q[self.problem.travel_index] += cycle * (self.q[-1, self.problem.travel_index] - self.q[0, self.problem.travel_index])
        return q, self.v[k]

    def gains(self) -> np.ndarray:
        """(N, nu, 2 nv) the periodic LQR's feedback gains (du = -K e), from the cost-to-go."""
        R = np.diag(self.torque_weights)
        bp = np.swapaxes(self.B, 1, 2) @ self.cost_to_go[1:]
        return np.linalg.solve(R + bp @ self.B, bp @ self.A)


def held_step(problem: ContactModel, phase: int, next_phase: int, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float,
              substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, v, forces) after dt of the optimiser's contact model from (q, v) (B, .) under torques tau (B, nv) held
    over it: `phase`'s feet held (`lk.contact_dynamics`), semi-implicit Euler substeps, then the touchdown (eq. 7,
    `lk.impact`) of `next_phase`'s feet if it differs; forces (B, `contact_width` x held feet) at the start."""
    return _held_step(problem, phase, next_phase, q, v, tau, dt, substeps, False)[:3]


def held_step_linearised(problem: ContactModel, phase: int, next_phase: int, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
                         dt: float, substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`held_step` and its Jacobians by x = (dq on q's tangent space, dv, du on the actuated torques): state
    (B, 2 nv, 2 nv + nu) of (q', v') (q' on its own tangent space) and forces (B, width x held feet, 2 nv + nu). The
    chain rule through the substeps: v' = v + h a(q, v, tau), q' = q (+) h v' (`lk.contact_dynamics_derivatives`,
    `lk.integrate_jacobians`), then v+ = impact(q', v') (`lk.impact_derivatives`)."""
    result = _held_step(problem, phase, next_phase, q, v, tau, dt, substeps, True)
    assert result[3] is not None and result[4] is not None
    return result[0], result[1], result[2], result[3], result[4]


def _held_step(problem: ContactModel, phase: int, next_phase: int, q: np.ndarray, v: np.ndarray, tau: np.ndarray, dt: float,
               substeps: int, jacobians: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    model, nv, batch = problem.model, problem.nv, len(q)
    feet = [(problem.foot_body[name], problem.foot_point[name]) for name in problem.phases[phase].contacts]
    dim = contact_width(problem)
    h = dt / substeps
    # Sensitivities of (q, v) to x = (dq, dv, du): (B, nv, 2 nv + nu) each.
    columns = 2 * nv + problem.nu
    dq, dv = np.zeros((batch, nv, columns)), np.zeros((batch, nv, columns))
    dq[:, :, :nv], dv[:, :, nv : 2 * nv] = np.eye(nv), np.eye(nv)
    dtau = np.zeros((nv, columns))
    dtau[problem.actuated, 2 * nv + np.arange(problem.nu)] = 1.0
    forces, dforces = np.zeros((batch, dim * len(feet))), None
    for sub in range(substeps):
        a, f = lk.contact_dynamics(model, q, v, tau, feet, dim=dim)
        if jacobians:
            a_q, a_v, a_tau, f_q, f_v, f_tau = (np.asarray(d) for d in lk.contact_dynamics_derivatives(model, q, v, tau, feet, dim=dim))
            if sub == 0:
                dforces = (f_q.reshape(batch, -1, nv) @ dq + f_v.reshape(batch, -1, nv) @ dv + f_tau.reshape(batch, -1, nv) @ dtau)
            dv = dv + h * (a_q @ dq + a_v @ dv + a_tau @ dtau)
        if sub == 0:
            forces = np.asarray(f).reshape(batch, -1)
        v = v + np.asarray(a) * h
        if jacobians:
            step_q, step_v = (np.asarray(d) for d in lk.integrate_jacobians(model, q, v, h))
            dq = step_q @ dq + step_v @ dv
        q = np.asarray(lk.integrate(model, q, v, h))
    if next_phase != phase:
        landing = [(problem.foot_body[name], problem.foot_point[name]) for name in problem.phases[next_phase].contacts]
        if jacobians:
            v_q, v_v = (np.asarray(d) for d in lk.impact_derivatives(model, q, v, landing, dim=dim)[:2])
            dv = v_q @ dq + v_v @ dv
        v = np.asarray(lk.impact(model, q, v, landing, dim=dim)[0])
    if not jacobians:
        return q, v, forces, None, None
    return q, v, forces, np.concatenate([dq, dv], axis=1), dforces


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


@dataclass
class CondensedQP:
    """The MPC's quadratic programme at a batch of start instants (B), condensed onto the blocks' corrections z
    (blocks x nu): minimise 1/2 z^T hessian z + (gradient_state e + gradient)^T z + slack_weight/2 |s|^2 subject to
    rows z + row_state e + s >= lower (a slack s >= 0 per row) and lower_u <= z <= upper_u. A padded row (a foot
    not held, or not in the air) has lower = -inf."""

    hessian: np.ndarray  # (B, nz, nz)
    gradient_state: np.ndarray  # (B, nz, 2 nv)
    gradient: np.ndarray  # (B, nz)
    rows: np.ndarray  # (B, r, nz)
    row_state: np.ndarray  # (B, r, 2 nv)
    lower: np.ndarray  # (B, r)
    lower_u: np.ndarray  # (B, nz)
    upper_u: np.ndarray  # (B, nz)
    tolerance: np.ndarray  # (r,) the violation of each row the unconstrained minimiser may leave and still be applied


class MPC:
    """The controller of the module docstring: `correction(i, e)` is the torque correction (nu,) at control instant
    i (any cycle) for the deviation e (2 nv) from the reference there (`TrackingModel.deviation`).

    The horizon is a sequence of blocks (`blocks`: their lengths in control periods), over each of which the
    correction is held (move blocking; short blocks first, where the correction matters most). The cost: the
    deviation's at the end of every control period (`state_weights`; at the horizon's end the periodic LQR's
    cost-to-go) and the corrections' (`torque_weights` per control period). The constraints: every held foot's force
    at each block's start (its first control period) above min_normal_force and inside the friction pyramid, every
    swing foot's height at the end of every control period at least min(min_swing_height, its planned height), both
    soft (a slack per row, weight slack_weight: the QP is always feasible), and plan + correction within the torque
    bounds (hard). The QP is condensed (the deviations eliminated through the linear dynamics; e.g. [Rawlings, Mayne
    & Diehl 2017, Sect. 8.8]): at each instant it depends on the deviation only through its gradient and its rows'
    bounds, both affine in e, so every instant's QP is built once, by one condensation batched over the cycle.

    Per control period: the QP's unconstrained minimiser z(e) = minimiser_state e + minimiser is its solution when it
    satisfies every row and bound (a swing foot may be up to swing_tolerance below its floor), which two
    matrix-vector products check. Otherwise the QP is solved by constraint generation on its dual: the violated rows
    (with the last solve's active ones) form a working set; the dual of the QP on it, min over multipliers l >= 0 of
    1/2 l^T (G H^-1 G^T + I/slack_weight on soft rows) l - l^T (b - G z(e)), is solved as a non-negative least-squares
    problem (`scipy.optimize.nnls`) with z = z(e) + H^-1 G^T l; the rows (and bounds) the new z violates join the set,
    until none does: then z solves the whole QP. `solved` counts the control periods that needed it."""

    def __init__(self, model: TrackingModel, blocks: Sequence[int] = (6, 6, 6, 6, 12, 12, 12), min_normal_force: float = 0.5,
                 friction: float | None = None, min_swing_height: float = 0.003, slack_weight: float = 1e6, swing_tolerance: float = 5e-4,
                 torque_bounds: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """blocks: the blocks' lengths in control periods (the default spans 60, 120 ms at the default 2 ms). friction:
        the pyramid's mu (default the plan's, `problem.friction`). torque_bounds (lower, upper), each (nu,):
        the actuators' torques, which bound plan + correction; default the plan's (`problem.u_bounds`). A plan
        kept inside its motors (`amble_problem(torque_margin=)`) leaves the difference to the correction.
        swing_tolerance [m]: how far below its floor a swing foot may be predicted before its row enters the
        QP."""
        friction = model.problem.friction if friction is None else friction
        sequence = isinstance(blocks, (Sequence, np.ndarray)) and not isinstance(blocks, str)
        lengths = [int(b) for b in blocks] if sequence and all(isinstance(b, (int, np.integer)) for b in blocks) else []
        if not lengths or min(lengths) < 1:
            raise ValueError(f"blocks must be a non-empty sequence of positive integers, got {blocks}")
        for name, value, positive in (("friction", friction, True), ("slack_weight", slack_weight, True),
                                      ("min_normal_force", min_normal_force, False), ("min_swing_height", min_swing_height, False),
                                      ("swing_tolerance", swing_tolerance, False)):
            if not (np.isfinite(value) and (value > 0.0 if positive else value >= 0.0)):
                raise ValueError(f"{name} must be a {'positive' if positive else 'non-negative'} number, got {value}")
        nu = model.B.shape[2]
        planned = (np.full(nu, -np.inf), np.full(nu, np.inf)) if model.problem.u_bounds is None else model.problem.u_bounds
        lower, upper = (np.asarray(b, dtype=np.float64) for b in (torque_bounds if torque_bounds is not None else planned))
        if lower.shape != (nu,) or upper.shape != (nu,) or not np.all(lower < upper):
            raise ValueError(f"torque_bounds must be two ({nu},) arrays with lower < upper, got shapes {lower.shape}, {upper.shape}")
        self.model, self.blocks, self.count = model, lengths, len(model.A)
        self.min_normal_force, self.friction, self.min_swing_height = min_normal_force, friction, min_swing_height
        self.slack_weight, self.swing_tolerance = slack_weight, swing_tolerance
        self.torque_lower, self.torque_upper = lower, upper
        self.variables = len(lengths) * nu
        self._force_rows, self._rows_per_foot = force_rows(model, friction)
        # Every instant's QP, kept as what the solve needs: H^-1, the unconstrained minimiser, the rows.
        qp = self.condense(np.arange(self.count), chunk=16)
        self.inverse = np.linalg.inv(qp.hessian)
        self.minimiser_state, self.minimiser = -self.inverse @ qp.gradient_state, -np.einsum("bij,bj->bi", self.inverse, qp.gradient)
        self.rows, self.row_state, self.lower, self.tolerance = qp.rows, qp.row_state, qp.lower, qp.tolerance
        self.lower_u, self.upper_u = qp.lower_u, qp.upper_u
        self._working = np.zeros(0, dtype=np.int64)
        self.solved = 0

    def condense(self, instants: np.ndarray, chunk: int | None = None) -> CondensedQP:
        """The QP (`CondensedQP`) at each of the given control instants of the cycle, batched over them (in batches of
        `chunk` instants if given: small enough to stay in the cache)."""
        if chunk is not None and len(instants) > chunk:
            parts = [self.condense(part) for part in np.array_split(instants, -(-len(instants) // chunk))]
            joined: dict[str, Any] = {field.name: np.concatenate([getattr(part, field.name) for part in parts]) for field in fields(CondensedQP)}
            return CondensedQP(**{**joined, "tolerance": parts[0].tolerance})
        m, count = self.model, self.count
        nu, n = m.B.shape[2], m.A.shape[1]
        instants = np.asarray(instants) % count
        batch, nz = len(instants), self.variables
        # e_j = S e + T z + c after j control periods.
        S, T, c = np.broadcast_to(np.eye(n), (batch, n, n)).copy(), np.zeros((batch, n, nz)), np.zeros((batch, n))
        hessian, gradient_state, gradient = np.zeros((batch, nz, nz)), np.zeros((batch, nz, n)), np.zeros((batch, nz))
        R = np.diag(m.torque_weights)
        rows: dict[str, list[np.ndarray]] = {"rows": [], "state": [], "lower": [], "tolerance": []}
        floor = np.tile(np.r_[self.min_normal_force, np.zeros(self._rows_per_foot - 1)], m.held.shape[1])
        swinging = int(np.max(np.sum(m.swing, axis=1), initial=0))  # height rows per period: the most feet in the air
        lower_u, upper_u = np.empty((batch, nz)), np.empty((batch, nz))
        step = 0
        for p, length in enumerate(self.blocks):
            columns = slice(p * nu, (p + 1) * nu)
            s = (instants + step) % count
            lower_u[:, columns], upper_u[:, columns] = self.torque_lower - m.u[s], self.torque_upper - m.u[s]
            hessian[:, columns, columns] += length * R
            # The held feet's forces at the block's start: pyramid (f + F_e e_j + F_u z_p) >= floor.
            F_e = self._force_rows[s] @ m.force_state[s]
            coefficient = F_e @ T
            coefficient[:, :, columns] += self._force_rows[s] @ m.force_input[s]
            constant = np.einsum("brf,bf->br", self._force_rows[s], m.forces[s]) + np.einsum("brn,bn->br", F_e, c)
            held = np.repeat(m.held[s], self._rows_per_foot, axis=1)
            for key, value in zip(rows, (coefficient, F_e @ S, np.where(held, floor - constant, -np.inf),
                                         np.zeros((batch, len(floor))))):
                rows[key].append(value)
            active = slice(0, (p + 1) * nu)  # the corrections so far: later columns of T are still zero
            for _ in range(length):  # the block's control periods
                k = (instants + step) % count
                S, c = m.A[k] @ S, np.einsum("bij,bj->bi", m.A[k], c) + m.residual[k]
                T[:, :, active] = m.A[k] @ T[:, :, active]
                T[:, :, columns] += m.B[k]
                step += 1
                end = (instants + step) % count
                # The swing feet's heights at the period's end: h + H_e e_j >= min(min_swing_height, h).
                feet = np.argsort(~m.swing[end], axis=1, kind="stable")[:, :swinging]
                h, h_e = np.take_along_axis(m.heights[end], feet, axis=1), np.take_along_axis(m.height_state[end], feet[:, :, None], axis=1)
                lower = np.where(np.take_along_axis(m.swing[end], feet, axis=1),
                                 np.minimum(self.min_swing_height, h) - h - np.einsum("bfn,bn->bf", h_e, c), -np.inf)
                for key, value in zip(rows, (h_e @ T, h_e @ S, lower, np.full((batch, swinging), self.swing_tolerance))):
                    rows[key].append(value)
                if p == len(self.blocks) - 1 and step == sum(self.blocks):  # the horizon's end: the cost-to-go
                    WT = m.cost_to_go[end] @ T[:, :, active]
                else:
                    WT = m.state_weights[:, None] * T[:, :, active]
                hessian[:, active, active] += np.einsum("bni,bnj->bij", T[:, :, active], WT, optimize=True)
                gradient_state[:, active] += np.swapaxes(WT, 1, 2) @ S
                gradient[:, active] += np.einsum("bni,bn->bi", WT, c)
        stacked = {key: np.concatenate(value, axis=1) for key, value in rows.items()}
        return CondensedQP(0.5 * (hessian + np.swapaxes(hessian, 1, 2)), gradient_state, gradient, stacked["rows"], stacked["state"],
                           stacked["lower"], lower_u, upper_u, stacked["tolerance"][0])

    def correction(self, i: int, e: np.ndarray) -> np.ndarray:
        k = i % self.count
        nu = self.model.B.shape[2]
        z0 = self.minimiser_state[k] @ e + self.minimiser[k]
        # The rows and bounds as one set G z >= b: the rows, then z >= lower_u, then -z >= -upper_u.
        rows = self.rows[k]
        b = np.concatenate([self.lower[k] - self.row_state[k] @ e, self.lower_u[k], -self.upper_u[k]])
        slack = np.concatenate([self.tolerance, np.zeros(2 * self.variables)])

        def violated(z: np.ndarray, multipliers: np.ndarray | None = None, working: np.ndarray | None = None) -> np.ndarray:
            value = np.concatenate([rows @ z, z, -z])
            if multipliers is not None and working is not None:  # a soft row's slack
                soft = working < len(rows)
                value[working[soft]] += multipliers[soft] / self.slack_weight
            return np.flatnonzero(value < b - slack - 1e-9)

        working = violated(z0)
        if not len(working):
            self._working = working
            return z0[:nu]
        self.solved += 1
        carried = self._working[np.isfinite(b[self._working])]  # last period's active rows that still bind something here
        working = np.union1d(working, carried)
        z = z0
        for _ in range(len(b)):
            G = np.concatenate([rows, np.eye(self.variables), -np.eye(self.variables)])[working]
            HG = self.inverse[k] @ G.T
            dual = G @ HG + np.diag(np.where(working < len(rows), 1.0 / self.slack_weight, 1e-12))
            factor = np.linalg.cholesky(0.5 * (dual + dual.T))
            # min_{l >= 0} 1/2 l^T D l - l^T r  =  min_{l >= 0} 1/2 |L^T l - L^-1 r|^2 + const, D = L L^T.
            multipliers = nnls(factor.T, np.linalg.solve(factor, b[working] - G @ z0), maxiter=50 * len(working))[0]
            z = z0 + HG @ multipliers
            more = np.setdiff1d(violated(z, multipliers, working), working)
            if not len(more):
                break
            working = np.union1d(working, more)
        self._working = working[multipliers > 0.0]
        return np.clip(z[:nu], self.lower_u[k, :nu], self.upper_u[k, :nu])  # hard bounds, to rounding


def contact_width(problem: ContactModel) -> Literal[3, 6]:
    """Rows per held foot of the contact model: 3 (a point foot's force) or 6 (a flat sole held as a frame: force and
    torque about the sole's centre, world axes; `lk.contact_dynamics(dim=6)`). Feet of both kinds in one problem are
    refused."""
    flat = [name in problem.flat_feet for name in problem.feet]
    if any(flat) and not all(flat):
        raise ValueError("problem: tracking needs every foot flat (FlatFoot) or every foot a point")
    return 6 if all(flat) and flat else 3


def force_rows(model: TrackingModel, friction: float) -> tuple[np.ndarray, int]:
    """(rows (N, r x most feet, width x most feet), r): at each control instant, rows R with R . f >= (floor, 0, ...,
    0) per held foot (`TrackingModel.forces`; padded slots unused). A point foot (r = 5): f_z, then mu f_z -+ f_x,
    mu f_z -+ f_y. A flat sole (r = 11) adds eq. 6 [Hardt 2002] on the torque T about its centre in the sole's axes
    (the reference foot's, at that instant): 0.5 l_y f_z -+ T_x, 0.5 l_x f_z -+ T_y, mu_d f_z -+ T_z."""
    problem = model.problem
    width, count, most = contact_width(problem), len(model.A), model.held.shape[1]
    per_foot = 5 if width == 3 else 11
    rows = np.zeros((count, per_foot * most, width * most))
    poses = np.asarray(lk.forward_kinematics(problem.model, model.q[:count])) if width == 6 else None
    for i in range(count):
        for slot, name in enumerate(problem.phases[model.phase[i]].contacts):
            r = rows[i, per_foot * slot : per_foot * (slot + 1), width * slot : width * (slot + 1)]
            r[:5, 2] = [1.0, friction, friction, friction, friction]
            r[1, 0], r[2, 0], r[3, 1], r[4, 1] = -1.0, 1.0, -1.0, 1.0
            if poses is not None:
                sole, axes = problem.flat_feet[name], poses[i, problem.foot_body[name], :3, :3]  # T = axes^T torque
                r[5:, 2] = np.repeat([0.5 * sole.width, 0.5 * sole.length, sole.torsion], 2)
                r[5:, 3:] = np.repeat(axes.T, 2, axis=0) * np.tile([[-1.0], [1.0]], (3, 1))
    return rows, per_foot


@ONE_BLAS_THREAD
def track(problem: ContactModel, trajectory: Trajectory, cycles: int = 5, foot_radius: float = 0.002, dt: float = 1e-3,
          control_every: int = 2, ground_friction: float = 0.8, swing_clearance: float = 0.01, model: TrackingModel | None = None,
          joint_offset: np.ndarray | None = None, plant: lk.Model | None = None, progress: bool = True, **mpc: Any) -> Replay:
    """Simulate `cycles` cycles under `MPC` (its keyword arguments in **mpc), from the plan's first state with the base
    raised clear of the ground (`clear_of_ground`); the feet as in `replay`, on ground of ground_friction. The
    controller acts every control_every simulation steps of dt (the model's control period, dt x control_every
    rounded so that whole periods make one cycle, sets the step). model: a `TrackingModel` built for this plan
    and control period (built here otherwise). joint_offset (nu,): added to the first state's joint angles, a
    perturbed start. plant: the model simulated (default the plan's), e.g. one with other masses (model
    mismatch). progress: a progress bar. Stops stepping once the robot has fallen (checked every 50 control
    periods). A mirrored half cycle is tracked as its whole cycle (`ContactModel.whole_trajectory`)."""
    problem, trajectory = problem.whole_trajectory(trajectory)
    if not (isinstance(control_every, (int, np.integer)) and control_every >= 1):
        raise ValueError(f"control_every must be an integer >= 1, got {control_every}")
    if not (isinstance(cycles, (int, np.integer)) and cycles >= 1):
        raise ValueError(f"cycles must be an integer >= 1, got {cycles}")
    offset = np.zeros(problem.nu) if joint_offset is None else np.asarray(joint_offset, dtype=np.float64)
    if offset.shape != (problem.nu,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"joint_offset must be {problem.nu} finite numbers, got shape {offset.shape}")
    if not 0.0 < dt * control_every <= float(np.sum(trajectory.durations)):
        raise ValueError(f"dt x control_every must be a positive time within the cycle ({float(np.sum(trajectory.durations))} s), "
                         f"got {dt} x {control_every}")
    plant = problem.model if plant is None else plant
    if not isinstance(plant, lk.Model):
        raise TypeError(f"plant must be a legkit.Model, got {type(plant).__name__}")
    model = model if model is not None else TrackingModel.build(problem, trajectory, dt * control_every, swing_clearance)
    if not np.isclose(model.dt, dt * control_every, rtol=1e-2):
        raise ValueError(f"model: the TrackingModel's control period {model.dt} differs from dt x control_every = {dt * control_every}")
    if plant.nq != problem.nq or plant.nv != problem.nv:
        raise ValueError(f"plant must have the plan's coordinates (nq {problem.nq}, nv {problem.nv}), got {plant.nq}, {plant.nv}")
    controller = MPC(model, **mpc)
    sim = lk.Simulation(plant, dt=model.dt / control_every, ground=lk.Ground.plane(ground_friction), shapes=foot_shapes(problem, foot_radius))
    steps = cycles * len(model.A)
    try:
        t = np.arange(steps + 1) * model.dt
        simulated = np.empty((steps + 1, problem.nq))
    except MemoryError:
        raise MemoryError(f"cycles: {cycles} cycles of {len(model.A)} control periods do not fit in memory") from None
    planned_q = np.stack([model.reference(i)[0] for i in range(steps + 1)])
    start, start_v = model.reference(0)
    start = start.copy()
    if joint_offset is not None:
        start[np.asarray(problem.actuated) + (problem.nq - problem.nv)] += offset
    sim.reset(clear_of_ground(problem, start, foot_radius), start_v)
    simulated[0] = sim.q
    tau = np.zeros(problem.nv)
    actuated, count = np.asarray(problem.actuated), len(model.A)
    for i in progress_bar(range(steps), enabled=progress, extra="optimize", desc="tracking in simulation", unit="step", leave=False, mininterval=0.5):
        q = sim.q
        correction = controller.correction(i, model.deviation(i, q, sim.v))
        if not np.all(np.isfinite(correction)):
            raise RuntimeError(f"the MPC's correction at control instant {i} is not finite: the tracked reference "
                               f"(swing_clearance {swing_clearance} m) or the state left the range the model was built for")
        tau[actuated] = model.u[i % count] + correction
        try:
            sim.step(tau, control_every)
        except RuntimeError:  # the simulation diverged: the robot is down
            simulated[i + 1 :] = simulated[i]
            break
        simulated[i + 1] = sim.q
        if (i + 1) % 50 == 0 and not outcome(problem, t[i - 49 : i + 2], simulated[i - 49 : i + 2], planned_q[i - 49 : i + 2]).upright:
            simulated[i + 2 :] = simulated[i + 1]
            break
    return outcome(problem, t, simulated, planned_q)


def heavier(model: lk.Model, factor: float) -> lk.Model:
    """A copy of model with every body's mass and rotational inertia scaled by factor (> 0; its COM kept): a plant
    for `track(plant=)` whose masses the controller's model gets wrong by (factor - 1)."""
    if not (np.isfinite(factor) and factor > 0.0):
        raise ValueError(f"factor must be a positive number, got {factor}")
    for body in range(model.nbodies):
        mass = model.body(body)
        if mass.mass > 0.0:
            model = model.with_body(body, lk.MassProperties(factor * mass.mass, mass.com, factor * np.asarray(mass.inertia)))
    return model
