"""Synthetic RHex walking streams from a kinematic, quasi-static model of the alternating-tripod gait.

This generator is the fast, contact-free source; any function with the signature of ``WalkingSource`` --
(speed m/s, duration s, seed) -> ``WalkingStream`` -- can replace ``kinematic_walk`` in the experiment, as
``legkit.strain.simulated.simulated_walk`` does: it drives ``legkit.robots.rhex.rhex_model()`` in the contact
simulation and reads strain from the simulated leg deflections.

The model
---------
* Clock (Buehler clock with duty factor 1/2). Tripod A = legs (2, 0, 4), tripod B = (5, 3, 1), half a
  period apart. A leg in stance turns at constant rate from theta_0 - phi_s/2 to theta_0 + phi_s/2 (phi_s
  the stance sweep, theta_0 the stance centre: slightly ahead of vertical, so that the backward deflection of
  loaded legs does not carry the toes behind the centre of mass late in stance); in swing it turns the
  remaining 2 pi - phi_s, also at constant rate and in the same direction. At duty
  factor 1/2 exactly one tripod is in stance at any time (no double support). The period is set by the
  speed: over a stance the body advances the chord 2 L0 sin(phi_s/2) of a rigid leg, so
  T = 4 L0 sin(phi_s/2) / speed.
* Loads (quasi-static). The ground pushes each stance toe vertically (no tangential ground force: steady
  walking with no drag). The three vertical forces carry the weight m g and balance its moments about the
  centre of mass: [1 1 1; x_i; y_i] F = [m g; m g c_x; m g c_y], with (x_i, y_i) the toes' horizontal
  positions relative to the centre of mass. Swing legs carry no load. Inertial forces are neglected, so
  speed enters only through the clock timing.
* Legs. Each stance load, expressed along the deflected leg (angle theta + d), deforms the compliant
  four-bar (``benchtop.CompliantFourBarLeg``) and sets the true gauge strain; swing legs are unloaded
  (l = L0, d = 0, zero strain). The measured strain adds sensor noise and a 6-bit ADC at 300 Hz.
* Body pose. The stance toes rest on the flat ground z = 0, which fixes height, roll and pitch: with n the
  unit normal of the toe plane in body coordinates (pointing toward the body), the third row of the body
  rotation is n^T, so roll = atan2(n_y, n_z), pitch = atan2(-n_x, hypot(n_y, n_z)), height = -n . s_0.
  Horizontal motion is prescribed (x = speed t, y = 0, yaw = 0); the small horizontal toe slip this implies
  is not modelled. Loads, leg deformation and pose depend on one another and are solved by fixed-point
  iteration, run until no leg length or deflection changes by more than 1e-13.
Lateral leg compliance, swing-leg dynamics, impacts and double support are outside this model.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from legkit import STANDARD_GRAVITY
from legkit._validation import positive_scalar, real_numbers
from legkit.robots.rhex import LEG_LENGTH, TOTAL_MASS, TRIPODS
from legkit.strain.benchtop import CompliantFourBarLeg, StrainSensor
from legkit.strain.model import LegModel
from legkit.strain.pose import TripodPose, euler_zyx, toe_in_body, tripod_pose

LEGS = np.arange(6)
TRIPOD_LEGS = np.array(TRIPODS)  # (2, 3)
STANCE_CENTRE = -0.1  # rad, default centre theta_0 of the stance sweep


@dataclass(frozen=True)
class WalkingStream:
    """A walking record: measured signals plus ground truth, sampled at a fixed rate (T samples).

    Attributes:
        time: (T,) s.
        hip_angle: (T, 6) rad, wrapped to [-pi, pi) (the hip encoders; exact).
        strain: (T, 6) microstrain, as measured (noise, quantisation).
        length, deflection: (T, 6) true leg configuration (m, rad).
        stance: (T, 6) bool, true ground contact.
        normal_force: (T, 6) N, true vertical ground force on each toe.
        toes: (T, 6, 3) true toe positions in the body frame (m).
        body_position: (T, 3) m, world; body_rotation: (T, 3, 3) body -> world.
        roll, pitch, yaw: (T,) rad, Z-Y-X angles of body_rotation.
        speed: commanded speed (m/s); period: gait period (s); stance_sweep: phi_s (rad);
        stance_centre: theta_0 (rad).
        toe_radius: radius (m) of the spherical toes whose centres ``toes``, ``length`` and ``deflection``
            describe; 0 for point toes (a robot parameter the estimator uses, like the clock's).
    """

    time: np.ndarray
    hip_angle: np.ndarray
    strain: np.ndarray
    length: np.ndarray
    deflection: np.ndarray
    stance: np.ndarray
    normal_force: np.ndarray
    toes: np.ndarray
    body_position: np.ndarray
    body_rotation: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    speed: float
    period: float
    stance_sweep: float
    stance_centre: float
    toe_radius: float = 0.0

    @property
    def height(self) -> np.ndarray:
        """True body height above the ground, (T,) m."""
        return self.body_position[:, 2]


class WalkingSource(Protocol):
    """A producer of walking streams: ``kinematic_walk`` now, a simulation-backed source later."""

    def __call__(self, speed: float, duration: float, seed: int) -> WalkingStream: ...


class GaitClock(Protocol):
    """A walking source's clock (``ClockGait``, ``simulated.BuehlerClock``), as ``start_record`` uses it."""

    def period(self, speed: float) -> float: ...


@dataclass(frozen=True)
class ClockGait:
    """Alternating-tripod Buehler clock at duty factor 1/2 (see the module docstring)."""

    stance_sweep: float = 0.6  # phi_s, rad
    stance_centre: float = STANCE_CENTRE  # theta_0, rad

    def __post_init__(self) -> None:
        if not 0.0 < self.stance_sweep < np.pi:
            raise ValueError(f"stance_sweep must be in (0, pi) rad, got {self.stance_sweep}")
        if not abs(self.stance_centre) < np.pi / 2:
            raise ValueError(f"stance_centre must be in (-pi/2, pi/2) rad, got {self.stance_centre}")

    def period(self, speed: float) -> float:
        """Gait period (s) for a forward speed (m/s): T = 4 L0 sin(phi_s / 2) / speed."""
        positive_scalar(speed, "speed")
        return 4.0 * LEG_LENGTH * np.sin(self.stance_sweep / 2) / speed

    def hip_angles(self, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(hip angles (T, 6) wrapped to [-pi, pi), stance (T, 6) bool) at gait phase (T,) in cycles."""
        leg_phase = np.zeros(6)
        leg_phase[TRIPOD_LEGS[1]] = 0.5
        within = np.mod(np.asarray(phase, dtype=np.float64)[:, None] + leg_phase, 1.0)
        stance = within < 0.5
        half = self.stance_sweep / 2
        theta = self.stance_centre + np.where(
            stance,
            -half + self.stance_sweep * (within / 0.5),
            half + (2 * np.pi - self.stance_sweep) * ((within - 0.5) / 0.5),
        )
        return np.mod(theta + np.pi, 2 * np.pi) - np.pi, stance


#: The most samples a walking record holds, checked before allocating: 1.85 h at the sensor's 300 Hz (the CLI's longest
#: run is 1 h), about 1 GB of per-leg arrays.
MAX_SAMPLES = 2 * 10**6


def record_samples(duration: float, rate: float) -> int:
    """Samples in a record of ``duration`` s at ``rate`` Hz: ValueError unless the duration is finite, > 0 and
    holds at least one sample and at most ``MAX_SAMPLES``."""
    samples = round(positive_scalar(duration, "duration") * rate)
    if samples < 1:
        raise ValueError(f"duration {duration} s is shorter than one sample at {rate} Hz")
    if samples > MAX_SAMPLES:
        raise ValueError(f"duration: {duration} s at {rate} Hz is {samples:.3g} samples, more than {MAX_SAMPLES:.0e}")
    return samples


def start_record(
    speed: float, duration: float, seed: int, rate: float, gait: GaitClock
) -> tuple[int, float, np.random.Generator, float]:
    """(samples, gait period s, generator seeded with ``seed``, start phase: its first draw) of a walking record."""
    samples = record_samples(duration, rate)
    period = gait.period(speed)
    rng = np.random.default_rng(seed)
    return samples, period, rng, rng.uniform(0.0, 1.0)


def support_pose_truth(stance_toes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(height, roll, pitch) of a body resting on stance toes (T, 3, 3) on flat ground z = 0.

    From the toe-plane normal n (body frame, toward the body): roll = atan2(n_y, n_z),
    pitch = atan2(-n_x, hypot(n_y, n_z)), height = -n . s_0.
    """
    normal = np.cross(stance_toes[:, 1] - stance_toes[:, 0], stance_toes[:, 2] - stance_toes[:, 0])
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal *= np.where(np.sum(normal * stance_toes[:, 0], -1) > 0, -1.0, 1.0)[:, None]
    height = -np.sum(normal * stance_toes[:, 0], -1)
    roll = np.arctan2(normal[:, 1], normal[:, 2])
    pitch = np.arctan2(-normal[:, 0], np.hypot(normal[:, 1], normal[:, 2]))
    return height, roll, pitch


def kinematic_walk(
    speed: float,
    duration: float,
    seed: int = 0,
    leg: CompliantFourBarLeg | None = None,
    sensor: StrainSensor | None = None,
    gait: ClockGait | None = None,
    com_offset: tuple[float, float] | None = None,
    max_iterations: int = 100,
) -> WalkingStream:
    """A synthetic walking stream from the kinematic, quasi-static tripod-gait model (module docstring).

    Args:
        speed: forward speed (m/s).
        duration: length of the record (s), sampled at ``sensor.rate``.
        seed: seeds the initial gait phase, the centre-of-mass offset (when not given) and the sensor noise.
        leg: the compliant leg (all six legs identical); sensor: strain acquisition; gait: the clock.
        com_offset: horizontal centre-of-mass offset (c_x, c_y) from the body origin (m); by default drawn
            uniformly within +-1 cm from the seed (a run-to-run payload variation). Offsets beyond about 2 cm
            can tip the quasi-static robot late in stance: the loaded legs deflect backwards, carrying the
            support triangle's front edge toward the centre of mass (a ValueError is raised).
        max_iterations: cap on the fixed-point iterations of the load / deformation / pose coupling, which
            stop once no leg length or deflection changes by more than 1e-13 (m, rad).

    Raises:
        ValueError: non-positive speed or duration, or a centre of mass outside a support tripod.
        RuntimeError: the fixed-point iteration did not converge within max_iterations.
    """
    leg = leg or CompliantFourBarLeg()
    sensor = sensor or StrainSensor()
    gait = gait or ClockGait()
    samples, period, rng, start_phase = start_record(speed, duration, seed, sensor.rate, gait)
    offset = rng.uniform(-0.01, 0.01, 2) if com_offset is None else np.asarray(com_offset, dtype=np.float64)
    if offset.shape != (2,) or not np.all(np.isfinite(offset)):
        raise ValueError(f"com_offset must be two finite numbers (c_x, c_y), got {com_offset}")

    time = np.arange(samples) / sensor.rate
    theta, stance = gait.hip_angles(start_phase + time / period)
    # Tripod A is in stance during the first half of its cycle.
    support = TRIPOD_LEGS[np.where(stance[:, TRIPOD_LEGS[0, 0]], 0, 1)]  # (T, 3) stance leg indices
    rows = np.arange(time.size)[:, None]
    weight = TOTAL_MASS * STANDARD_GRAVITY

    length = np.full(theta.shape, leg.nominal_length)
    deflection = np.zeros(theta.shape)
    rotation = np.broadcast_to(np.eye(3), (time.size, 3, 3))
    for _ in range(max_iterations):
        stance_toes = toe_in_body(theta, length, deflection, LEGS)[rows, support]
        # Horizontal toe positions relative to the centre of mass, in world-aligned axes.
        relative = np.einsum("tij,tkj->tki", rotation, stance_toes - np.append(offset, 0.0))
        statics = np.stack([np.ones((time.size, 3)), relative[..., 0], relative[..., 1]], -2)
        forces = np.linalg.solve(statics, np.broadcast_to([weight, 0.0, 0.0], (time.size, 3))[..., None])[..., 0]
        if np.any(forces <= 0):
            raise ValueError(f"com_offset {tuple(offset)} puts the centre of mass outside a support tripod")
        normal_force = np.zeros(theta.shape)
        normal_force[rows, support] = forces
        # Vertical world force in body coordinates is F R^T e_z = F * (third row of R).
        vertical = rotation[:, 2, :]
        sine, cosine = np.sin(theta + deflection), np.cos(theta + deflection)
        radial = normal_force * (vertical[:, None, 0] * sine + vertical[:, None, 2] * cosine)
        tangential = normal_force * (vertical[:, None, 2] * sine - vertical[:, None, 0] * cosine)
        previous = (length, deflection)
        length, deflection, true_strain = leg.deform(radial, tangential * leg.nominal_length)
        height, roll, pitch = support_pose_truth(toe_in_body(theta, length, deflection, LEGS)[rows, support])
        rotation = euler_zyx(roll, pitch, np.zeros_like(roll))
        change = max(np.max(np.abs(length - previous[0])), np.max(np.abs(deflection - previous[1])))
        if change <= 1e-13:
            break
    else:
        raise RuntimeError(f"load / deformation / pose iteration did not converge in {max_iterations} iterations")

    toes = toe_in_body(theta, length, deflection, LEGS)
    body_position = np.column_stack([speed * time, np.zeros_like(time), height])
    return WalkingStream(
        time=time,
        hip_angle=theta,
        strain=sensor.measure(true_strain, rng),
        length=length,
        deflection=deflection,
        stance=stance,
        normal_force=normal_force,
        toes=toes,
        body_position=body_position,
        body_rotation=rotation,
        roll=roll,
        pitch=pitch,
        yaw=np.zeros_like(roll),
        speed=float(speed),
        period=float(period),
        stance_sweep=float(gait.stance_sweep),
        stance_centre=float(gait.stance_centre),
    )


def tripod_clock_signal(hip_angle: object, stance_centre: float = STANCE_CENTRE) -> np.ndarray:
    """Per-tripod stance signal (T, 2): the largest |hip angle - theta_0| (rad, wrapped) among the tripod's legs.

    A tripod is in its stance sweep while the signal is at most phi_s / 2; feed a column to
    ``pose.stance_intervals`` to get its support phases.
    """
    theta = real_numbers(hip_angle, "hip_angle")
    if theta.ndim != 2 or theta.shape[1] != 6:
        raise ValueError(f"hip_angle must have shape (T, 6), got {theta.shape}")
    wrapped = np.abs(np.mod(theta - stance_centre + np.pi, 2 * np.pi) - np.pi)
    return wrapped[:, TRIPOD_LEGS].max(axis=-1)


@dataclass(frozen=True)
class PoseEstimate:
    """Body pose estimated from strain and hip angles through the leg model and the stance tripod.

    Attributes: support (T,) index of the tripod used (0 = A, 1 = B); toes (T, 6, 3) estimated toes in the
    body frame; length, deflection (T, 6) model outputs; pose: ``TripodPose`` of the support tripod.
    """

    support: np.ndarray
    toes: np.ndarray
    length: np.ndarray
    deflection: np.ndarray
    pose: TripodPose


def estimate_body_pose(
    hip_angle: object,
    strain: object,
    model: LegModel,
    stance_centre: float = STANCE_CENTRE,
    toe_radius: float = 0.0,
) -> PoseEstimate:
    """The paper's estimator: strain -> (l, d) by the leg model, toes by h_i^theta, pose by ``tripod_pose``.

    The support tripod at each sample is the one deeper in its stance sweep (smaller ``tripod_clock_signal``).
    The leg model gives toe centres; spherical toes of radius ``toe_radius`` (m) touch flat ground that far
    below their centres along the support normal, so the returned pose's support plane (its ``origin`` and
    ``position``, hence ``height``) is the ground, toe_radius below the plane of the toe centres.

    Raises:
        ValueError: hip_angle and strain not both (T, 6); toe_radius negative or not finite.
    """
    theta = real_numbers(hip_angle, "hip_angle")
    sigma = real_numbers(strain, "strain")
    if theta.shape != sigma.shape or theta.ndim != 2 or theta.shape[1] != 6:
        raise ValueError(f"hip_angle and strain must both have shape (T, 6), got {theta.shape} and {sigma.shape}")
    positive_scalar(toe_radius, "toe_radius", allow_zero=True)
    length, deflection = model.predict(sigma)
    toes = toe_in_body(theta, length, deflection, LEGS)
    support = np.argmin(tripod_clock_signal(theta, stance_centre), axis=1)
    stance_toes = toes[np.arange(theta.shape[0])[:, None], TRIPOD_LEGS[support]]
    centres = tripod_pose(stance_toes, orientation="body_side")  # tripod A runs clockwise: its eq.-2 normal points down
    # Move the support frame from the toe-centre plane down to the ground along its own z axis (the normal).
    ground = replace(
        centres,
        position=centres.position + np.array([0.0, 0.0, toe_radius]),
        origin=centres.origin - toe_radius * centres.support_frame[..., :, 2],
    )
    return PoseEstimate(support, toes, length, deflection, ground)
