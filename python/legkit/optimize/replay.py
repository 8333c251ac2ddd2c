"""Replaying an optimised periodic gait in `lk.Simulation`: joint PD tracking of the optimised joint angles and
rates plus the optimised torques as feed-forward (the trajectory-following control of [Hardt 2002] Sect. 5,
Fig. 4), over several cycles; reports the base drift from the plan and whether the robot stayed upright.

Every finding below was measured on plans whose stance forces rang between knots and midpoints
(`ContactModel.stance_accelerations`): their torques did not produce their motion.
The transcription now holds the stance feet in DIRCON's form; its amble plans still fall in the first
diagonal support at every gain tried. At the default 4 intervals per phase the amble's long
supports are not motions of the model at all (`legkit.optimize.shooting.interval_drift`: 60 deg of attitude within
one 0.117 s interval); 16 intervals per phase bring that under 1 deg, and those plans fall too (0.6-1.2 s).
`legkit.optimize.tracking` tracks such a plan (with a stance-force floor) 5 cycles upright by a contact-constrained
MPC instead.

What the amble's replay showed (measured on the Fig. 3 amble, 4 intervals per phase, 300 + 300 IPOPT iterations):

* The start: sphere feet on tilted legs begin below the ground (r (1 - cos theta); 1.2 mm for 5 mm spheres at
  40 deg), and the soft contacts pushed them out with ~140 N each in the first step: `clear_of_ground`.
* The samples: interpolating across a touchdown spread its velocity jump (up to 23 rad/s) over the interval
  before it: `periodic_samples` interpolates each phase on its own Hermite-Simpson cubics.
* The impacts: with eq. 7 unbounded, J_s2 lands with impulses of ~1 N s (the robot's whole momentum) and
  replays fell within 0.3-1.5 s at every gain tried (0 of 30 settings); with soft touchdowns
  (`MultiphaseProblem.max_impulse` = 0) kp 50, kd 1 walks 5 cycles upright with 3.3 % drift (10 cycles: 5.6 %),
  but only 14 of 135 (kp, kd) settings from kp 20-150, kd 0.25-2 pass, and at kp 50, kd 1 a 0.5 ms step,
  friction 0.7 or 1.0, or 1 or 5 mm spheres each make it fall after 3.2-5.5 s.
* The tipping mode: two point feet put no moment on the robot about their line, and joint tracking fixes its
  shape, so it tips about that line as an unactuated inverted pendulum. On the optimiser's own contact model
  (feet held bilaterally by `lk.contact_dynamics`, touchdowns by `lk.impact`, the same PD + feed-forward) the
  torso's tilt from the plan still grows from 0.1 to 3.0 deg in one 0.33 s diagonal support. Feeding the
  torso's attitude error (and rate) to the hip targets, capture-point placement of the swing feet,
  world-height tracking of the swing feet and stiffer swing legs were each tried at several gains on the
  soft-touchdown amble; none widened the passing set, most fell sooner, so the default stays the issue's plain
  PD + feed-forward.
* The biped walk (`walk_problem`, 1 + 4 intervals, 1000 J_e1 iterations) falls within its first cycle at kp
  100-3000 (also with soft touchdowns). Its joint rates obey the torque-speed line (<= 5.2 rad/s) at the
  collocation points, but its accelerations there reach 1000-2700 rad/s^2, and on the collocation's own cubics
  the rates reach 38-48 rad/s between the points: the mesh is too coarse for the plan to be a motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import legkit as lk
from legkit._validation import check_allocation, count, float_array
from legkit.optimize.collocation import hermite_basis
from legkit.optimize.contact import ContactModel
from legkit.optimize.kinematics import rotation
from legkit.optimize.layout import Trajectory


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


def phase_of(trajectory: Trajectory, t: np.ndarray) -> np.ndarray:
    """(S,) the phase each instant t (any number of cycles) belongs to; an instant on a boundary to the later phase."""
    t = float_array(t, "t")
    durations = np.asarray(trajectory.durations)
    starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
    return np.clip(np.searchsorted(starts, np.mod(t, np.sum(durations)), side="right") - 1, 0, len(durations) - 1)


def periodic_samples(problem: ContactModel, trajectory: Trajectory, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, v, u) of the periodic optimised gait at times t (any number of cycles), as the collocation itself
    interpolates them: on each Hermite–Simpson interval (knot, midpoint, knot) the state is the cubic through
    the knots with the collocated rates [dq/dt, a] there, the controls are linear. Each phase is interpolated on
    its own, so an instant on a phase boundary belongs to the later phase: the state after the touchdown, whose
    velocity jump (eq. 7) stays a jump instead of being spread over the interval before it. The travel
    coordinate advances by speed x period. A mirrored half cycle is sampled as its whole cycle (`whole_trajectory`)."""
    problem, trajectory = problem.whole_trajectory(trajectory)
    t = float_array(t, "t")
    check_allocation(8 * t.size * (problem.nq + problem.nv + problem.nu), "t")
    period = float(np.sum(trajectory.durations))
    cycle, phase_t = np.divmod(t, period)
    x = problem.pack(trajectory)
    nq, nx, nu = problem.nq, problem.nx, problem.nu
    q, v, u = np.empty((len(t), nq)), np.empty((len(t), problem.nv)), np.empty((len(t), nu))
    which = phase_of(trajectory, t)
    for k in range(len(problem.phases)):
        mine = which == k
        if not np.any(mine):
            continue
        z = x[problem.point_index[k]]
        rates = problem.rate(z, k)
        times = trajectory.t[k]
        knots = times[::2]
        interval = np.clip(np.searchsorted(knots, phase_t[mine], side="right") - 1, 0, len(knots) - 2)
        h = knots[interval + 1] - knots[interval]
        s = ((phase_t[mine] - knots[interval]) / h)[:, None]
        first, last = z[2 * interval, :nx], z[2 * interval + 2, :nx]
        slope0, slope1 = h[:, None] * rates[2 * interval], h[:, None] * rates[2 * interval + 2]
        w0, w1, w2, w3 = hermite_basis(s)
        state = w0 * first + w1 * slope0 + w2 * last + w3 * slope1
        q[mine], v[mine] = state[:, :nq], state[:, nq:]
        controls = z[:, nx : nx + nu]
        u[mine] = np.stack([np.interp(phase_t[mine], times, column) for column in controls.T], axis=1)
    if problem.travel_index is not None:
        q[:, problem.travel_index] += cycle * problem.speed * period
    if problem.model.floating_base:
        q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    return q, v, u

#: Thickness [m] of the box a flat foot (`FlatFoot`) collides as in `foot_shapes`.
SOLE_THICKNESS = 0.01


def foot_shapes(problem: ContactModel, radius: float) -> dict[int | str, tuple | None]:
    """`lk.Simulation` shapes: each point foot a sphere of `radius` whose bottom is the foot's point when its body
    hangs straight (centre `radius` above the point along the body's z axis); each flat foot (`FlatFoot`) a box
    of its sole's length and width, SOLE_THICKNESS thick, whose bottom face is the sole (centred on the foot's
    point); of the other bodies only the base collides (its default box)."""
    shapes: dict[int | str, tuple | None] = {b: None for b in range(1, problem.model.nbodies)}
    for name in problem.feet:
        frame = np.eye(4)
        if name in problem.flat_feet:
            sole = problem.flat_feet[name]
            frame[:3, 3] = problem.foot_point[name] + [0.0, 0.0, 0.5 * SOLE_THICKNESS]
            shapes[problem.foot_body[name]] = ("box", [sole.length, sole.width, SOLE_THICKNESS], frame)
        else:
            frame[:3, 3] = problem.foot_point[name] + [0.0, 0.0, radius]
            shapes[problem.foot_body[name]] = ("sphere", radius, frame)
    return shapes


def foot_bottoms(problem: ContactModel, q: np.ndarray, radius: float) -> np.ndarray:
    """(..., feet) world height of the lowest point of each foot's shape (`foot_shapes`) at configuration q: a
    sphere's centre height minus its radius, a sole's lowest corner."""
    poses = np.asarray(lk.forward_kinematics(problem.model, q))
    lowest = []
    for name in problem.feet:
        rotation_z, height = poses[..., problem.foot_body[name], 2, :3], poses[..., problem.foot_body[name], 2, 3]
        if name in problem.flat_feet:
            sole = problem.flat_feet[name]
            corners = problem.foot_point[name] + 0.5 * np.array([[sx * sole.length, sy * sole.width, 0.0]
                                                                   for sx in (-1, 1) for sy in (-1, 1)])
            lowest.append(np.min(rotation_z @ corners.T, axis=-1) + height)
        else:
            lowest.append(rotation_z @ (problem.foot_point[name] + [0.0, 0.0, radius]) + height - radius)
    return np.stack(lowest, axis=-1)


def clear_of_ground(problem: ContactModel, q: np.ndarray, radius: float) -> np.ndarray:
    """q with a free-flyer base raised so that no foot shape (`foot_shapes`) starts below the ground. On a leg
    tilted by theta a sphere's bottom lies radius (1 - cos theta) below the plan's point foot: started on the plan
    itself, the amble's stance spheres (legs tilted ~40 deg) began 1.2 mm deep with radius 5 mm, and the soft
    contacts pushed them out with ~140 N each in the first step (8.5 body weights), throwing the robot off its feet."""
    q = np.array(q, dtype=np.float64)
    if problem.model.floating_base:
        q[2] -= min(0.0, float(np.min(foot_bottoms(problem, q, radius))))
    return q


def replay(problem: ContactModel, trajectory: Trajectory, cycles: int = 5, kp: float | np.ndarray = 20.0, kd: float | np.ndarray = 0.5,
           foot_radius: float = 0.002, dt: float = 1e-3, control_every: int = 2, friction: float = 0.8) -> Replay:
    """Simulate `cycles` cycles from the optimised initial state, its base raised until no foot starts below the
    ground (`clear_of_ground`); only the feet (`foot_shapes`: spheres of foot_radius, flat soles as boxes) and the
    base collide. kp, kd: joint PD gains, one for every actuated joint or one each (nu,). The replay is open
    loop in the torso's attitude: a two-legged support's tipping mode grows from any small error (module
    docstring: feeding the attitude error to the hip targets made the soft-touchdown amble fall sooner). A mirrored
    half cycle is replayed as its whole cycle (`ContactModel.whole_trajectory`)."""
    problem, trajectory = problem.whole_trajectory(trajectory)
    model = problem.model
    count(cycles, "cycles", 1)
    count(control_every, "control_every", 1)
    for gain, name in ((kp, "kp"), (kd, "kd")):
        if float_array(gain, name).shape not in ((), (1,), (problem.nu,)):
            raise ValueError(f"{name} must be one gain or {problem.nu} (one per actuated joint), got shape {np.shape(gain)}")
    sim = lk.Simulation(model, dt=dt, ground=lk.Ground.plane(friction), shapes=foot_shapes(problem, foot_radius))
    period = float(np.sum(trajectory.durations))
    steps = int(round(cycles * period / (dt * control_every)))
    check_allocation(8 * (steps + 1) * (3 * model.nq + 2 * model.nv + problem.nu), "cycles")  # the planned and simulated samples
    t = np.arange(steps + 1) * dt * control_every
    planned_q, planned_v, planned_u = periodic_samples(problem, trajectory, t)
    sim.reset(clear_of_ground(problem, planned_q[0], foot_radius), planned_v[0])
    stiffness, damping = np.zeros(model.nv), np.zeros(model.nv)
    stiffness[problem.actuated], damping[problem.actuated] = kp, kd
    tau = np.zeros((len(t), model.nv))
    tau[:, problem.actuated] = planned_u
    simulated = np.empty_like(planned_q)
    simulated[0] = sim.q
    for i in range(steps):  # the targets change every control period; the engine steps in between
        sim.set_servo(stiffness, damping, target_q=planned_q[i], target_v=planned_v[i])
        sim.step(tau[i], control_every)
        simulated[i + 1] = sim.q
    return outcome(problem, t, simulated, planned_q)


def outcome(problem: ContactModel, t: np.ndarray, simulated: np.ndarray, planned_q: np.ndarray) -> Replay:
    """A simulated run judged against the plan at the same instants (`Replay`)."""
    model = problem.model
    standing = np.ones(len(t), dtype=bool)
    if model.floating_base:  # judged against the plan, whose torso may itself lean
        tilt = np.einsum("si,si->s", rotation(simulated[:, 3:7])[:, :, 2], rotation(planned_q[:, 3:7])[:, :, 2])
        standing = (tilt > np.cos(np.radians(45.0))) & (simulated[:, 2] > planned_q[:, 2] / 3.0)
    fell_at = float(t[np.argmin(standing)]) if not np.all(standing) else np.inf
    travel = problem.travel_index if problem.travel_index is not None else 0
    distance = float(planned_q[-1, travel] - planned_q[0, travel])
    drift = float(np.linalg.norm(simulated[-1, :2] - planned_q[-1, :2])) if model.floating_base else 0.0
    return Replay(t, simulated, planned_q, distance, drift, bool(np.all(standing)), fell_at)
