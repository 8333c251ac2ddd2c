"""RHex walking an alternating-tripod gait in the contact simulation (``lk.Simulation``): strain streams with ground truth.

``simulated_walk`` is a ``WalkingSource`` (same signature and ``WalkingStream`` fields as
``legkit.strain.walking.kinematic_walk``) backed by ``lk.Simulation`` instead of the quasi-static model.

The robot (``legkit.robots.rhex.rhex_compliant_model``)
-------------------------------------------------------
A free-flying 6.52 kg body and six compliant legs. Each leg is a hip motor (revolute about +y, angle
theta), a deflection joint d_f (revolute about +y at the hip) and a compression slider s (prismatic along a
fixed unit axis u in the deflected leg frame) ending in a small spherical toe. The hips are position
servos tracking the clock; the deflection joint and the slider are held at zero by stiff PD servos that
*are* the leg springs (torsional k_flex, linear k_slide) with light damping.

Matching the compliant four-bar leg. ``benchtop.CompliantFourBarLeg`` maps the generalised loads (radial
force f_r, hip-axis torque tau = f_t L0) to (compression c, deflection d) through its 2x2 compliance
C = a a^T / k_link + diag(1 / k_axial, 1 / k_clamp). For small motions the slider moves the toe by s u,
i.e. (c, d) = w s with w = (u_z, -u_x / L0), and is loaded by the generalised force w . (f_r, tau); the
deflection joint adds d_f. The simulated leg's compliance is therefore w w^T / k_slide + diag(0, 1/k_flex),
which equals C exactly when (``leg_springs``)
    u  ∝ (-L0 C_01 / C_00, 0, 1),   k_slide = u_z^2 / C_00,   k_flex = 1 / (C_11 - C_01^2 / C_00).
For the default leg (a_r = 0.04 m/rad, a_d = 0.2, k_link = 4 N m/rad, k_axial = 3e4 N/m,
k_clamp = 1000 N m/rad): u = (-0.617, 0, 0.787), k_slide = 1.43e3 N/m along u, k_flex = 565 N m/rad
(radial stiffness with the leg free to deflect 1 / C_00 = 2.31e3 N/m).

Ground truth and strain
-----------------------
Recorded at the strain sensor's rate (300 Hz by default) from the simulated state: the hip angle theta
(wrapped), the leg length l and deflection d as the polar coordinates of the toe centre in the hip frame
(toe = Ry(d_f) (s u + (0, 0, -L0)), l = |toe|, d = atan2(-toe_x, -toe_z)), so that
``pose.toe_in_body(theta, l, d)`` is exactly the simulated toe; the body pose from sim.q; ground contact
and the vertical ground force on each toe from sim.contacts(). The strain is the four-bar gauge reading
for the leg's state, ``CompliantFourBarLeg.strain_from_displacement(l, d)``, then sensor noise and the
6-bit ADC (``StrainSensor.measure``).

Toe contact
-----------
The toe is a sphere of radius ``TOE_RADIUS`` = 6 mm and the "toe" of the leg model is its centre; the
estimator (``walking.estimate_body_pose(..., toe_radius=stream.toe_radius)``) puts the ground that far below
the plane of the stance toe centres. On the default tree engine a resting toe settles within the
contact tolerance (0.2 mm). Rapier's contacts (``backend="rapier"``) are soft: a resting toe sinks until the
contact spring, whose stiffness is the contact's effective mass times a fixed (2 pi 60 Hz)^2, carries the
load, so the penetration (the residual error of the height estimate) scales with load / effective mass and
is further reduced by shorter solver substeps. Two choices, made on Rapier, keep it small there:
  * the leg's mass sits where a four-bar leg has it, mostly in the rigid shin and toe that ride on the
    compression spring (``legkit.robots.rhex.COMPLIANT_LEG_MASSES``: clamp 0.02, members 0.02, shin and toe
    0.04 kg). With a 0.01 kg toe the toe's effective mass was four times smaller and stance toes sank up to
    13 mm (centres from -7 to +6 mm);
  * ``SimulationSettings.substeps`` = 16 (substep 1/48000 s at the default 300 Hz x 10 steps): stance toe
    centres then stay between about +2 and +6 mm (penetration below 4 mm, about 2 mm typical), against +1 mm
    (5 mm) at 4 substeps.

Gait
----
``BuehlerClock``: the clock of ``walking.ClockGait`` (slow stance sweep phi_s about theta_0, fast
recirculation through the top) with a duty factor above 1/2, unwrapped so the hip joints turn continuously;
the hip servo gets the clock angle and rate at the middle of each sample interval. Defaults (phi_s = 0.8
rad, theta_0 = -0.15 rad, duty 0.6) were chosen by simulation so that toes touch down and lift off inside
the slow sweep: the robot rides with its legs compressed, so a leg reaches the ground only within about
0.3 rad of vertical. With the earlier phi_s = 0.6, theta_0 = -0.2 the sweep ended at +0.1 rad, while the
departing legs were still loaded; they then accelerated into recirculation on the ground, kicking the body
forward (+25 to +37 % over the commanded speed) and yawing it (up to 10 degrees over 2 s at 0.45 m/s).
With the wider, less forward-shifted sweep the robot walks 11 % (0.2 m/s) and 15 % (0.45 m/s) faster than
the rigid-leg chord model of ``BuehlerClock.period`` predicts, and straight (yaw drift under 2 degrees).
At duty 1/2 the arriving tripod, unloaded and so longer than the compressed departing one, touches down
during its fast recirculation and kicks the robot. The simulation stands for ``settle_time``, then walks
``warmup_periods`` gait periods before recording, so the stream starts in steady walking.

Accuracy (the strain models' targets; ``benches/strain_simulated_targets.py``, seeds 3-5, worst case)
-------------------------------------------------------------------------------------
Length NRMSE 0.45 % (<= 2), deflection NRMSE 5.3 % (<= 10), body height 3.3 mm (<= 5), roll 1.0 deg and
pitch 0.5 deg (<= 2); seeds 0, 1, 2 and 7 give the same figures within 0.4 mm and 0.2 %. The deflection
error comes from the clamp's share of the deflection, which the gauge cannot see (``benchtop`` module
docstring): it is invisible in walking and, in calibration, correlated with strain in a way that depends on
the benchtop's load distribution. With the earlier, soft k_clamp = 250 N m/rad (seed 3, this gait and leg)
the deflection NRMSE is 10.7 % (0.2 m/s) and 12.3 % (0.45 m/s), and even the best linear map fitted on the
walking data itself reaches only 5.4 %; at k_clamp = 1000 N m/rad it is 4.8 % and 5.3 %.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import legkit as lk
from legkit.robots.rhex import LEG_LENGTH, rhex_compliant_model
from legkit.strain.benchtop import CompliantFourBarLeg, StrainSensor
from legkit.strain.pose import toe_in_body
from legkit.strain.walking import TRIPOD_LEGS, ClockGait, WalkingStream, start_record

TOE_RADIUS = 0.006  # m, toe sphere; the leg model's toe is its centre (module docstring)
HIP_BODIES = 1 + 3 * np.arange(6)  # body (and joint) index of each hip motor
FLEX_BODIES = HIP_BODIES + 1
TOE_BODIES = HIP_BODIES + 2


@dataclass(frozen=True)
class LegSprings:
    """The simulated leg's springs matched to a four-bar leg (module docstring).

    Attributes: axis, unit slider axis u (3,) in the flex frame; slide_stiffness k_slide (N/m);
    flex_stiffness k_flex (N m/rad).
    """

    axis: np.ndarray
    slide_stiffness: float
    flex_stiffness: float


def leg_springs(leg: CompliantFourBarLeg) -> LegSprings:
    """Slider axis and spring constants whose small-motion compliance equals ``leg.compliance()`` exactly."""
    c = leg.compliance()
    direction = np.array([-leg.nominal_length * c[0, 1] / c[0, 0], 0.0, 1.0])
    axis = direction / np.linalg.norm(direction)
    return LegSprings(
        axis=axis,
        slide_stiffness=float(axis[2] ** 2 / c[0, 0]),
        flex_stiffness=float(1.0 / (c[1, 1] - c[0, 1] ** 2 / c[0, 0])),
    )


@dataclass(frozen=True)
class SimulationSettings:
    """Numerical and actuation settings of ``simulated_walk`` (SI units).

    Attributes:
        steps_per_sample: simulation steps per strain sample (dt = 1 / (rate * steps_per_sample)).
        substeps: simulation substeps per step; on Rapier shorter substeps stiffen its soft toe contacts
            (module docstring, Toe contact), 16 keeps stance penetration under about 4 mm there.
        hip_stiffness, hip_damping, hip_torque_limit: hip position servo (N m/rad, N m s/rad, N m).
        spring_damping_ratio: damping of the leg springs (fraction of critical for the free leg).
        friction: ground friction coefficient.
        settle_time: time (s) standing still before the clock starts.
        warmup_periods: gait periods walked before recording starts.
    """

    steps_per_sample: int = 10
    substeps: int = 16
    hip_stiffness: float = 100.0
    hip_damping: float = 0.5
    hip_torque_limit: float = 20.0
    spring_damping_ratio: float = 0.7
    friction: float = 1.0
    settle_time: float = 0.3
    warmup_periods: float = 2.0


@dataclass(frozen=True)
class BuehlerClock:
    """RHex's Buehler clock for the alternating tripod, with a duty factor (fraction of a cycle in stance).

    Tripod A = legs (2, 0, 4) starts its stance at phase 0, tripod B = (5, 3, 1) half a cycle later. In
    stance a leg turns at constant rate from theta_0 - phi_s/2 to theta_0 + phi_s/2 over duty_factor of the
    period; it recirculates through the remaining 2 pi - phi_s in the rest of the cycle, in the same
    direction. A duty factor above 1/2 overlaps the tripods' slow phases, so the arriving tripod touches down
    while turning slowly; at exactly 1/2 the clock is ``walking.ClockGait``'s.
    """

    stance_sweep: float = 0.8  # phi_s, rad
    stance_centre: float = -0.15  # theta_0, rad
    duty_factor: float = 0.6

    def __post_init__(self) -> None:
        ClockGait(self.stance_sweep, self.stance_centre)  # validates sweep and centre
        if not 0.5 <= self.duty_factor < 1.0:
            raise ValueError(f"duty_factor must be in [0.5, 1), got {self.duty_factor}")

    def period(self, speed: float) -> float:
        """Gait period (s): the body advances a rigid leg's chord 2 L0 sin(phi_s/2) per stance, duty * T long.

        T = 2 L0 sin(phi_s / 2) / (duty_factor * speed); at duty 1/2 this is ``ClockGait.period``.
        """
        return ClockGait(self.stance_sweep, self.stance_centre).period(speed) / (2.0 * self.duty_factor)

    def hip_targets(self, phase: object, period: float) -> tuple[np.ndarray, np.ndarray]:
        """(hip angle (..., 6) rad, unwrapped and continuous; hip rate (..., 6) rad/s) at phase (...,) cycles.

        Wrapped to [-pi, pi), the angle at duty factor 1/2 is ``ClockGait.hip_angles(phase)[0]``.
        """
        leg_phase = np.zeros(6)
        leg_phase[TRIPOD_LEGS[1]] = 0.5
        total = np.asarray(phase, dtype=np.float64)[..., None] + leg_phase
        cycles = np.floor(total)
        within = total - cycles
        stance = within < self.duty_factor
        half = self.stance_sweep / 2
        swing_sweep = 2 * np.pi - self.stance_sweep
        swing = 1.0 - self.duty_factor
        angle = self.stance_centre + 2 * np.pi * cycles + np.where(
            stance,
            -half + self.stance_sweep * (within / self.duty_factor),
            half + swing_sweep * ((within - self.duty_factor) / swing),
        )
        rate = np.where(stance, self.stance_sweep / self.duty_factor, swing_sweep / swing) / period
        return angle, rate


def leg_polar(flex: np.ndarray, slide: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(length m, deflection rad) of the toe centre in the hip frame, from flex angles and slider coordinates.

    toe = Ry(flex) (slide * axis + (0, 0, -L0)); l = |toe|; d = atan2(-toe_x, -toe_z). Shapes broadcast.
    """
    x = slide * axis[0]
    z = slide * axis[2] - LEG_LENGTH
    # A rotation about y adds to the polar angle of the toe measured from -z.
    return np.hypot(x, z), flex + np.arctan2(-x, -z)


def _rotation_from_quaternion(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrices (T, 3, 3) from unit quaternions (T, 4) ordered (x, y, z, w)."""
    x, y, z, w = np.moveaxis(quaternion / np.linalg.norm(quaternion, axis=-1, keepdims=True), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def build_simulation(
    leg: CompliantFourBarLeg, settings: SimulationSettings, dt: float
) -> tuple[lk.Simulation, LegSprings, np.ndarray, np.ndarray]:
    """(simulation, springs, kp (nv,), kd (nv,)) of RHex with four-bar-matched leg springs on a flat plane."""
    springs = leg_springs(leg)
    model = rhex_compliant_model(springs.axis)
    # Only the toes touch the ground (and the body box, should it fall).
    shapes: dict[int | str, tuple[object, ...] | None] = {int(b): None for b in np.concatenate([HIP_BODIES, FLEX_BODIES])}
    toe_frame = np.eye(4)
    toe_frame[2, 3] = -LEG_LENGTH
    shapes.update({int(b): ("sphere", TOE_RADIUS, toe_frame) for b in TOE_BODIES})
    sim = lk.Simulation(model, dt=dt, ground=lk.Ground.plane(settings.friction), shapes=shapes, substeps=settings.substeps)

    idx_v = np.array(model.idx_v)
    kp = np.zeros(model.nv)
    kd = np.zeros(model.nv)
    kp[idx_v[HIP_BODIES]] = settings.hip_stiffness
    kd[idx_v[HIP_BODIES]] = settings.hip_damping
    # Spring damping as a fraction of critical for the unloaded leg: the flex joint swings the members and
    # toe about the hip, the slider moves the toe mass.
    flex_inertia = np.array(lk.crba(model, model.neutral()))[idx_v[FLEX_BODIES[0]], idx_v[FLEX_BODIES[0]]]
    toe_mass = model.body(int(TOE_BODIES[0])).mass
    kp[idx_v[FLEX_BODIES]] = springs.flex_stiffness
    kd[idx_v[FLEX_BODIES]] = 2 * settings.spring_damping_ratio * np.sqrt(springs.flex_stiffness * flex_inertia)
    kp[idx_v[TOE_BODIES]] = springs.slide_stiffness
    kd[idx_v[TOE_BODIES]] = 2 * settings.spring_damping_ratio * np.sqrt(springs.slide_stiffness * toe_mass)
    return sim, springs, kp, kd


def simulated_walk(
    speed: float,
    duration: float,
    seed: int = 0,
    leg: CompliantFourBarLeg | None = None,
    sensor: StrainSensor | None = None,
    gait: BuehlerClock | None = None,
    settings: SimulationSettings | None = None,
    ticks: Callable[[float], object] | None = None,
) -> WalkingStream:
    """A walking stream of RHex in the contact simulation (module docstring); a ``WalkingSource``.

    Args:
        speed: commanded forward speed (m/s); sets the clock period ``gait.period(speed)``.
        duration: length of the record (s), sampled at ``sensor.rate``, after settling and warm-up.
        seed: seeds the initial gait phase and the sensor noise.
        leg: the compliant four-bar leg the springs and the strain gauge follow; sensor: strain acquisition;
        gait: the clock (default ``BuehlerClock()``); settings: simulation settings.
        ticks: called after each strain sample (warm-up included) with the fraction of the walk simulated so
            far, in (0, 1] (a progress bar's ticks: a 4 s walk takes seconds).

    Returns:
        A ``WalkingStream`` with the fields and units of ``kinematic_walk``'s; ``stance`` is true ground
        contact of each toe, ``normal_force`` its vertical ground force, ``body_position`` world (the record
        starts wherever the warm-up left the robot).

    Raises:
        ValueError: non-positive speed or duration, or a duration shorter than one sample.
        RuntimeError: the robot fell (body box touching the ground) or the state became non-finite.
    """
    leg = leg or CompliantFourBarLeg()
    sensor = sensor or StrainSensor()
    gait = gait or BuehlerClock()
    settings = settings or SimulationSettings()
    samples, period, rng, start_phase = start_record(speed, duration, seed, sensor.rate, gait)

    sample_time = 1.0 / sensor.rate
    dt = sample_time / settings.steps_per_sample
    sim, springs, kp, kd = build_simulation(leg, settings, dt)
    model_nv = kp.size
    hip_v = 6 + 3 * np.arange(6)  # velocity index of each hip; hip q index is one more (quaternion)
    limit = np.full(model_nv, np.inf)
    limit[hip_v] = settings.hip_torque_limit

    def command(phase: float) -> None:
        angle, rate = gait.hip_targets(phase, period)
        target_q = np.zeros(model_nv + 1)
        target_v = np.zeros(model_nv)
        target_q[hip_v + 1], target_v[hip_v] = angle, rate
        sim.set_servo(kp, kd, limit, target_q, target_v)

    # Stand on the clock's initial hip angles, toes just clear of the ground, then settle.
    first_phase = start_phase - settings.warmup_periods
    angle0, _ = gait.hip_targets(first_phase, period)
    q0 = np.zeros(kp.size + 1)
    q0[6] = 1.0
    q0[7 + 3 * np.arange(6)] = angle0
    q0[2] = LEG_LENGTH * np.cos(angle0).max() + TOE_RADIUS + 1e-3
    sim.reset(q0, np.zeros(model_nv))
    command(first_phase)
    sim.step(n=int(round(settings.settle_time / dt)))

    warmup_samples = int(round(settings.warmup_periods * period * sensor.rate))
    total = warmup_samples + samples
    qs = np.empty((samples, q0.size))
    vertical_force = np.zeros((samples, 6))
    in_contact = np.zeros((samples, 6), dtype=bool)
    toe_slot = np.full(3 * 6 + 1, -1)
    toe_slot[TOE_BODIES] = np.arange(6)
    body_contact = False
    for k in range(total):
        phase = first_phase + (k + 0.5) * sample_time / period
        if k >= warmup_samples:
            row = k - warmup_samples
            qs[row] = sim.q
            contacts = sim.contacts()
            ground = contacts["other"] == -1
            slot = toe_slot[contacts["body"]]
            force_z = contacts["normal"][:, 2] * contacts["normal_force"] + contacts["tangential_force"][:, 2]
            toe = ground & (slot >= 0)
            np.add.at(vertical_force[row], slot[toe], force_z[toe])
            in_contact[row, slot[toe & (contacts["normal_force"] > 0)]] = True
            body_contact |= bool(np.any(ground & (contacts["body"] == 0) & (contacts["normal_force"] > 0)))
        command(phase)
        sim.step(n=settings.steps_per_sample)
        if ticks is not None:
            ticks((k + 1) / total)
    if not np.all(np.isfinite(qs)):
        raise RuntimeError("the simulation state became non-finite")
    if body_contact:
        raise RuntimeError("the robot fell: its body touched the ground")

    hip = qs[:, 7 + 3 * np.arange(6)]
    flex = qs[:, 8 + 3 * np.arange(6)]
    slide = qs[:, 9 + 3 * np.arange(6)]
    length, deflection = leg_polar(flex, slide, springs.axis)
    theta = np.mod(hip + np.pi, 2 * np.pi) - np.pi
    rotation = _rotation_from_quaternion(qs[:, 3:7])
    roll = np.arctan2(rotation[:, 2, 1], rotation[:, 2, 2])
    pitch = np.arctan2(-rotation[:, 2, 0], np.hypot(rotation[:, 2, 1], rotation[:, 2, 2]))
    yaw = np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0])
    true_strain = leg.strain_from_displacement(length, deflection)
    return WalkingStream(
        time=np.arange(samples) * sample_time,
        hip_angle=theta,
        strain=sensor.measure(true_strain, rng),
        length=length,
        deflection=deflection,
        stance=in_contact,
        normal_force=vertical_force,
        toes=toe_in_body(theta, length, deflection, np.arange(6)),
        body_position=qs[:, :3].copy(),
        body_rotation=rotation,
        roll=roll,
        pitch=pitch,
        yaw=yaw,
        speed=float(speed),
        period=float(period),
        stance_sweep=float(gait.stance_sweep),
        stance_centre=float(gait.stance_centre),
        toe_radius=TOE_RADIUS,
    )
