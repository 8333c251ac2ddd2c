"""Replaying an optimised periodic gait in `lk.Simulation`: joint PD tracking of the optimised joint angles and
rates plus the optimised torques as feed-forward (the trajectory-following control of file 003, Sect. 5,
Fig. 4), over several cycles; reports the base drift from the plan and whether the robot stayed upright."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

import legkit as lk
from legkit.optimize.problem import MultiphaseProblem, Trajectory, rotation


@dataclass
class Replay:
    t: np.ndarray  # (S,) control instants [s]
    q: np.ndarray  # (S, nq) simulated configuration
    planned_q: np.ndarray  # (S, nq) the optimised configuration at the same instants
    distance: float  # planned forward travel [m]
    drift: float  # |simulated - planned| base xy at the end [m]
    upright: bool  # torso z axis within 45 deg of the planned one and base above a third of its planned height throughout
    fell_at: float  # [s] first control instant that broke `upright` (inf if none)

    @property
    def drift_fraction(self) -> float:
        return self.drift / self.distance if self.distance > 0.0 else np.inf


def periodic_samples(problem: MultiphaseProblem, trajectory: Trajectory, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, v, u) of the periodic optimised gait at times t (any number of cycles), piecewise linear between
    the collocation points (exact for the linear controls); the travel coordinate advances by speed x period."""
    data = trajectory.stacked()
    period = float(np.sum(trajectory.durations))
    # Keep the later of two points sharing a phase-boundary instant: the state after the touchdown.
    keep = np.r_[np.diff(data["t"]) > 0.0, True]
    times = data["t"][keep]
    cycle, phase_t = np.divmod(t, period)
    q = np.stack([np.interp(phase_t, times, column) for column in data["q"][keep].T], axis=1)
    v = np.stack([np.interp(phase_t, times, column) for column in data["v"][keep].T], axis=1)
    u = np.stack([np.interp(phase_t, times, column) for column in data["u"][keep].T], axis=1)
    if problem.travel_index is not None:
        q[:, problem.travel_index] += cycle * problem.speed * period
    if problem.model.floating_base:
        q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    return q, v, u


def replay(problem: MultiphaseProblem, trajectory: Trajectory, cycles: int = 5, kp: float = 20.0, kd: float = 0.5,
           foot_radius: float = 0.005, dt: float = 1e-3, control_every: int = 2, friction: float = 0.8,
           attitude: tuple[Sequence[int], Sequence[int]] | None = None, attitude_gain: float = 1.0) -> Replay:
    """Simulate `cycles` cycles from the optimised initial state; only the feet (spheres of foot_radius whose
    bottoms are the contact points when the leg hangs straight) and the base collide.

    attitude: (roll joints, pitch joints), q indices of joints turning about the torso's x and y axes (a
    quadruped's hip roll and hip pitch). With it, the torso's roll and pitch error from the plan (small angles,
    torso frame) times attitude_gain is added to those joints' targets: a stance leg then turns the torso back,
    a swing leg aims its foot where the plan puts it in the world. Without it (None) the replay is open loop
    in the torso's attitude, and a two-legged support's tipping mode grows from any small error."""
    model = problem.model
    shapes: dict[int | str, tuple | None] = {b: None for b in range(1, model.nbodies)}
    for name in problem.feet:
        frame = np.eye(4)
        frame[:3, 3] = problem.foot_point[name] + [0.0, 0.0, foot_radius]
        shapes[problem.foot_body[name]] = ("sphere", foot_radius, frame)
    sim = lk.Simulation(model, dt=dt, ground=lk.Ground.plane(friction), shapes=shapes)
    period = float(np.sum(trajectory.durations))
    steps = int(round(cycles * period / (dt * control_every)))
    t = np.arange(steps + 1) * dt * control_every
    planned_q, planned_v, planned_u = periodic_samples(problem, trajectory, t)
    sim.reset(planned_q[0], planned_v[0])
    gains = np.zeros(model.nv)
    gains[problem.actuated] = 1.0
    tau = np.zeros((len(t), model.nv))
    tau[:, problem.actuated] = planned_u
    simulated = np.empty_like(planned_q)
    simulated[0] = sim.q
    planned_rotation = rotation(planned_q[:, 3:7]) if model.floating_base else None
    for i in range(steps):  # the targets change every control period; the engine steps in between
        target = planned_q[i]
        if attitude is not None and model.floating_base:
            error = planned_rotation[i].T @ rotation(np.asarray(sim.q)[3:7])
            target = target.copy()
            target[list(attitude[0])] += attitude_gain * 0.5 * (error[2, 1] - error[1, 2])
            target[list(attitude[1])] += attitude_gain * 0.5 * (error[0, 2] - error[2, 0])
        sim.set_servo(kp * gains, kd * gains, target_q=target, target_v=planned_v[i])
        sim.step(tau[i], control_every)
        simulated[i + 1] = sim.q
    standing = np.ones(len(t), dtype=bool)
    if model.floating_base:  # judged against the plan, whose torso may itself lean
        tilt = np.einsum("si,si->s", rotation(simulated[:, 3:7])[:, :, 2], rotation(planned_q[:, 3:7])[:, :, 2])
        standing = (tilt > np.cos(np.radians(45.0))) & (simulated[:, 2] > planned_q[:, 2] / 3.0)
    fell_at = float(t[np.argmin(standing)]) if not np.all(standing) else np.inf
    travel = problem.travel_index if problem.travel_index is not None else 0
    distance = float(planned_q[-1, travel] - planned_q[0, travel])
    drift = float(np.linalg.norm(simulated[-1, :2] - planned_q[-1, :2])) if model.floating_base else 0.0
    return Replay(t, simulated, planned_q, distance, drift, bool(np.all(standing)), fell_at)
