"""Can a robot execute a plan? Its bounds checked densely between the collocation points, and its loads' rates.

Collocation states the bounds at the knots and midpoints; between them the plan is the states' Hermite cubics
and the controls' lines [Hardt 2002, eq. 14], which the replay and the tracking controllers sample. `execution_check`
samples every interval of the whole cycle and reports the largest torso yaw, joint rate (against the motors'
no-load speed), torque (against the bounds), how fast a foot's load and a joint's torque change (support switches
included: a lifting foot unloads to zero, a landing foot loads from zero) and the lowest swing tip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import legkit as lk
from legkit._validation import count
from legkit.optimize.collocation import hermite_basis
from legkit.optimize.contact import ContactModel

#: The most samples per interval `execution_check` takes (its arrays grow with samples x points).
MAX_SAMPLES = 10_000


@dataclass(frozen=True)
class ExecutionCheck:
    """The worst case over the whole cycle (`execution_check`)."""

    yaw: float  # [deg] largest |torso yaw| at the points (free-flyer robots)
    joint_rate: float  # largest |joint rate| on the cubics between the points / the motors' no-load joint speed
    torque: float  # largest |u| / its bound (the controls are linear between the points: the largest is at one)
    torque_rate: float  # largest |du/dt| [bound per ms]: between neighbouring points and across support switches
    force_rate: float  # largest |dF_i/dt| of a component of a foot's force [body weights per ms], switches included
    swing_height: float  # [m] the lowest swing tip on the cubics between the points (negative: below the ground)

    def lines(self) -> list[str]:
        """One labelled line per figure, for a report."""
        return [f"torso yaw max [deg]               {self.yaw:10.3g}",
                f"joint rate max / no-load speed    {self.joint_rate:10.3g}",
                f"torque max / bound                {self.torque:10.3g}",
                f"torque rate max [bound per ms]    {self.torque_rate:10.3g}",
                f"foot load rate max [weight / ms]  {self.force_rate:10.3g}",
                f"swing tip min between points [m]  {self.swing_height:10.3g}"]


def execution_check(problem: ContactModel, x: np.ndarray, samples: int = 16) -> ExecutionCheck:
    """`ExecutionCheck` of the point x of `problem` (its mirrored half unrolled into the whole cycle), each interval
    sampled at `samples` fractions. The joint-rate figure needs a torque-speed line (`MultiphaseProblem.
    torque_speed`; nan without), the torque figures bounds on u (`u_bounds`; nan without)."""
    count(samples, "samples", 2, MAX_SAMPLES)
    x = problem.point(x)
    whole = problem.full_cycle()
    trajectory = problem.unroll(problem.unpack(x))
    phases, model = whole.phases, problem.model
    basis = np.stack([np.stack(hermite_basis(s)) for s in np.linspace(0.0, 1.0, samples)])  # (samples, 4)
    yaw, joint_rate, swing_height, force_rate, torque_rate, torque = 0.0, 0.0, np.inf, 0.0, 0.0, 0.0
    bound = None if problem.u_bounds is None else np.maximum(np.abs(problem.u_bounds[0]), np.abs(problem.u_bounds[1]))
    speed = np.nan if problem.torque_speed is None else np.broadcast_to(np.asarray(problem.torque_speed.max_speed), (problem.nu,))
    weight = model.total_mass * float(np.linalg.norm(model.gravity))
    for k, phase in enumerate(phases):
        assert trajectory.a is not None  # `unpack` gives the accelerations
        q, v, a, u = trajectory.q[k], trajectory.v[k], trajectory.a[k], trajectory.u[k]
        h = trajectory.durations[k] / phase.intervals
        step = 0.5 * h  # between neighbouring points
        if model.floating_base:
            qx, qy, qz, qw = (q[:, 3:7] / np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)).T
            yaw = max(yaw, float(np.max(np.abs(np.degrees(np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))))))
        knots = slice(0, None, 2)
        q0, q1, v0, v1, a0, a1 = q[knots][:-1], q[knots][1:], v[knots][:-1], v[knots][1:], a[knots][:-1], a[knots][1:]
        rate0, rate1 = problem.q_rate(q0, v0), problem.q_rate(q1, v1)
        dense_q = np.einsum("sj,jin->sin", basis, np.stack([q0, h * rate0, q1, h * rate1]))  # (samples, intervals, nq)
        dense_v = np.einsum("sj,jin->sin", basis, np.stack([v0, h * a0, v1, h * a1]))
        if np.all(np.isfinite(speed)):
            joint_rate = max(joint_rate, float(np.max(np.abs(dense_v[..., problem.actuated]) / speed)))
        swing = [name for name in problem.foot_names if name not in phase.contacts]
        if swing:
            heights = whole.foot_positions(dense_q.reshape(-1, problem.nq), swing)[..., 2]
            swing_height = min(swing_height, float(heights.min()))
        if bound is not None:
            torque = max(torque, float(np.max(np.abs(u) / bound)))
            following = trajectory.u[(k + 1) % len(phases)][0] if problem.periodic or k + 1 < len(phases) else u[-1]
            changes = np.abs(np.concatenate([np.diff(u, axis=0), (following - u[-1])[None]]))
            torque_rate = max(torque_rate, float(np.max(changes / bound)) / (1e3 * step))
        later = phases[(k + 1) % len(phases)]
        later_step = 0.5 * trajectory.durations[(k + 1) % len(phases)] / later.intervals
        for c, name in enumerate(phase.contacts):
            force = trajectory.forces[k][:, c]
            changes = [np.max(np.abs(np.diff(force, axis=0)), initial=0.0) / step]
            if problem.periodic or k + 1 < len(phases):
                after = {n: trajectory.forces[(k + 1) % len(phases)][0, i] for i, n in enumerate(later.contacts)}
                changes.append(np.max(np.abs(after.get(name, 0.0) - force[-1])) / step)
            force_rate = max(force_rate, max(changes) / (1e3 * weight))
        if problem.periodic or k + 1 < len(phases):
            for i, name in enumerate(later.contacts):
                if name not in phase.contacts:  # landing: loads from zero
                    force_rate = max(force_rate, float(np.max(np.abs(trajectory.forces[(k + 1) % len(phases)][0, i]))) / later_step / (1e3 * weight))
    return ExecutionCheck(yaw if model.floating_base else np.nan, joint_rate if np.all(np.isfinite(speed)) else np.nan,
                          torque if bound is not None else np.nan, torque_rate if bound is not None else np.nan, force_rate,
                          swing_height if np.isfinite(swing_height) else np.nan)


def midpoint_stance_acceleration(problem: ContactModel, x: np.ndarray) -> float:
    """The largest stance-foot acceleration [m/s^2] at the midpoints (`ContactModel.stance_accelerations`;
    the knots hold it at 0): how far the collocation cubics between the knots are from a motion."""
    return max(float(np.linalg.norm(a[1::2], axis=-1).max(initial=0.0)) for a in problem.stance_accelerations(x))


def inverse_dynamics_residuals(problem: ContactModel, x: np.ndarray) -> list[np.ndarray]:
    """Per phase (P, nv): rnea(q, v, a, f_ext) - B u recomputed from the solution by `lk.rnea`, the feet's forces
    and flat feet's torques applied as body wrenches (eq. 1 in inverse form; zero for an exact solution)."""
    trajectory = problem.unpack(x)
    assert trajectory.a is not None and trajectory.torques is not None  # unpack gives both
    residuals = []
    for k, phase in enumerate(problem.phases):
        q = problem.configuration(trajectory.q[k])
        forces = trajectory.forces[k].reshape(len(q), -1)
        f_ext = problem.external_wrenches(q, forces, phase.contacts, trajectory.torques[k].reshape(len(q), -1))
        residuals.append(np.asarray(lk.rnea(problem.model, q, trajectory.v[k], trajectory.a[k], f_ext)) - problem.tau(trajectory.u[k]))
    return residuals
