"""Reference gaits built from foot placements: the quadruped amble of [Hardt 2002, Fig. 3] and a biped walk.

The base moves at constant speed and height (the biped also sways sideways over its stance foot, its COM on the
periodic linear-inverted-pendulum path of a planned ZMP, and swings its arms); stance feet stay where they touched
down, swing feet follow a C2 minimum-jerk arc to the next foothold; joint angles by closed-form leg inverse
kinematics; joint velocities and accelerations by periodic fourth-order central differences.

The published amble's numbers fix its stride: 0.67 m/s x 1.25 s = 0.84 m per cycle, so each foot sweeps 0.42 m under
its hip during a stance (the paper's "gait stride 0.416 m" is this half cycle). An AIBO-sized leg (0.145 m, legkit's
default quadruped) cannot reach that far, so the amble runs on `AMBLE_QUADRUPED` (0.18 m thighs and shanks) at a hip
height of `AMBLE_HIP_HEIGHT`; masses and the rest of the body are unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import legkit as lk
import legkit.stability as st
from legkit._validation import float_array, integer, positive_scalar
from legkit.robots.biped import SIDES, Biped
from legkit.robots.quadruped import LEGS, Quadruped, QuadrupedParameters

#: The quadruped of the amble: legkit's default with legs long enough for the published 0.42 m stance sweep.
AMBLE_QUADRUPED = QuadrupedParameters(thigh_length=0.18, shank_length=0.18)
AMBLE_HIP_HEIGHT = 0.20  # [m]


@dataclass
class GaitReference:
    """Sampled reference motion of a whole-body gait."""

    t: np.ndarray  # (T,)
    q: np.ndarray  # (T, nq)
    v: np.ndarray  # (T, nv)
    a: np.ndarray  # (T, nv)
    contacts: list[tuple[int, np.ndarray]]  # every possible contact point (body, point in body frame)
    active: np.ndarray  # (T, k) bool: which contact points are on the ground
    support_label: list[str]  # (T,) human-readable support set
    distance: float  # metres travelled over t
    feet: list[list[int]]  # contact indices of each foot
    zmp_tracking_error: float  # largest distance [m] of the whole-body ZMP from the planned ZMP


# --------------------------------------------------------------------------------------------------
# Reference motions
# --------------------------------------------------------------------------------------------------


def _min_jerk(s: np.ndarray) -> np.ndarray:
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


def _bump(s: np.ndarray) -> np.ndarray:
    """C2 lift profile with value 1 at s = 1/2 and zero value, slope and curvature at s = 0 and 1."""
    return 64.0 * (s * (1.0 - s)) ** 3


def _foot_track(samples: int, touchdown: int, stance_samples: int, dt: float, speed: float,
                step_height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World foot x (relative to where the body's nominal frame was at t = 0), lift and stance flag over one
    cycle of `samples` steps of dt. The foot touches down at sample `touchdown` half a stance ahead of its
    hip, stays put for `stance_samples`, then swings one stride (speed x cycle time) forward along a
    minimum-jerk arc; all in integer sample arithmetic, so support sets switch exactly at sample boundaries."""
    i = np.arange(samples)
    phase = (i - touchdown) % samples
    stance = phase < stance_samples
    s = np.clip((phase - stance_samples) / (samples - stance_samples), 0.0, 1.0)
    half_stance = 0.5 * speed * stance_samples * dt
    x = speed * (i - phase) * dt + half_stance + np.where(stance, 0.0, speed * samples * dt * _min_jerk(s))
    z = np.where(stance, 0.0, step_height * _bump(s))
    return x, z, stance


def _periodic_derivatives(values: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """First and second time derivatives of samples periodic along axis 0 (fourth-order central differences)."""
    p1, m1 = np.roll(values, -1, axis=0), np.roll(values, 1, axis=0)
    p2, m2 = np.roll(values, -2, axis=0), np.roll(values, 2, axis=0)
    first = (-p2 + 8.0 * p1 - 8.0 * m1 + m2) / (12.0 * dt)
    second = (-p2 + 16.0 * p1 - 30.0 * values + 16.0 * m1 - m2) / (12.0 * dt * dt)
    return first, second


def periodic_lip(zmp_offset: np.ndarray, period: float, height: float, gravity: float = lk.STANDARD_GRAVITY) -> np.ndarray:
    """The periodic COM path (N, 2) of the linear inverted pendulum c - (height / g) c'' = p for a periodic
    ZMP reference p (N, 2), both taken relative to the steady progression (speed t, 0).

    In Fourier terms C_k = P_k / (1 + (height / g) (2 pi k / period)^2): the unique periodic solution, so the
    gait's base motion starts and ends in the same state and the ZMP (in the LIP sense) follows p."""
    zmp_offset = float_array(zmp_offset, "zmp_offset")
    if zmp_offset.ndim != 2 or len(zmp_offset) == 0:
        raise ValueError(f"zmp_offset must have shape (N, 2) with N >= 1, got shape {zmp_offset.shape}")
    period, height = positive_scalar(period, "period"), positive_scalar(height, "height")
    gravity = positive_scalar(gravity, "gravity")
    frequency = 2.0 * np.pi * np.fft.rfftfreq(zmp_offset.shape[0], d=period / zmp_offset.shape[0])
    spectrum = np.fft.rfft(zmp_offset, axis=0) / (1.0 + height / gravity * frequency**2)[:, None]
    return np.fft.irfft(spectrum, n=zmp_offset.shape[0], axis=0)


def _base_on_zmp(model: lk.Model, t: np.ndarray, speed: float, zmp_ref: np.ndarray, com_height: float,
                 joints_for: Callable[[np.ndarray], np.ndarray],
                 states: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
                 iterations: int = 8) -> tuple[np.ndarray, np.ndarray, float]:
    """Periodic base xy offsets (N, 2) whose whole-body ZMP follows zmp_ref (N, 2); also the joints (N, nj)
    and the remaining largest ZMP error [m].

    Starts from the periodic LIP path and corrects it by the LIP response to the whole-body ZMP error (legs
    and arms swing and shift the ZMP, which a point-mass model ignores): a fixed-point iteration in the style
    of iterative ZMP compensation. joints_for(base_xy) -> joint angles; states(base_xy, joints) -> (q, v, a)."""
    period = t[1] * len(t)
    progression = np.stack([speed * t, np.zeros_like(t)], axis=1)
    g = -model.gravity[2]
    base = periodic_lip(zmp_ref - progression, period, com_height, g)
    for _ in range(iterations):
        error = zmp_ref - st.zmp(model, *states(base, joints_for(base)))[:, :2]
        base = base + periodic_lip(error, period, com_height, g)
    joints = joints_for(base)
    error = zmp_ref - st.zmp(model, *states(base, joints))[:, :2]
    return base, joints, float(np.max(np.linalg.norm(error, axis=1)))


def _expand(robot_model: lk.Model, dt: float, cycles: int, speed: float, base_xy: np.ndarray, base_z: float,
            joints: np.ndarray, joint_columns: list[slice]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, v, a) over `cycles` cycles from one periodic cycle of base offsets and joint angles; the base
    keeps an identity orientation and moves at `speed` along x plus the periodic offsets."""
    samples = len(base_xy)
    base_v, base_a = _periodic_derivatives(base_xy, dt)
    joint_v, joint_a = _periodic_derivatives(joints, dt)
    t = np.arange(samples * cycles) * dt
    index = np.arange(samples * cycles) % samples
    q = np.zeros((len(t), robot_model.nq))
    q[:, 0], q[:, 1], q[:, 2], q[:, 6] = speed * t + base_xy[index, 0], base_xy[index, 1], base_z, 1.0
    v = np.zeros((len(t), robot_model.nv))
    v[:, 0], v[:, 1] = speed + base_v[index, 0], base_v[index, 1]
    a = np.zeros_like(v)
    a[:, :2] = base_a[index]
    offset = 0
    for cols in joint_columns:
        width = cols.stop - cols.start
        q[:, cols.start + 1 : cols.stop + 1] = joints[index, offset : offset + width]
        v[:, cols] = joint_v[index, offset : offset + width]
        a[:, cols] = joint_a[index, offset : offset + width]
        offset += width
    return t, q, v, a


#: Samples a reference may hold over all its cycles: building one takes about 30 µs and 1.2 kB per sample.
MAX_SAMPLES = 1_000_000


def _sample_counts(samples: object, cycles: object) -> tuple[int, int]:
    """samples per cycle (at least 4: the footfalls are a quarter cycle apart) and cycles (at least 1), checked,
    with at most MAX_SAMPLES samples in all."""
    samples, cycles = integer(samples, "samples"), integer(cycles, "cycles")
    if samples < 4:
        raise ValueError(f"samples must be >= 4, got {samples}")
    if cycles < 1:
        raise ValueError(f"cycles must be >= 1, got {cycles}")
    if samples * cycles > MAX_SAMPLES:
        raise ValueError(f"samples x cycles must be <= {MAX_SAMPLES:,}, got {samples:,} x {cycles:,}")
    return samples, cycles


def quadruped_amble(robot: Quadruped, speed: float, period: float, samples: int, cycles: int, step_height: float, hip_height: float) -> GaitReference:
    """Amble with duty factor 0.5 in the lateral sequence LF, RH, RF, LH (touchdowns a quarter cycle apart):
    the support order of [Hardt 2002] Sect. 4.2, LF+LH, LF+RH, RF+RH, RF+LH from t = 0, a lateral pair then a
    diagonal one. The published list reads "LF-LB, LR-RR, RF-RR, RF-LR"; its second pair (both rear legs)
    contradicts the same paragraph (lateral and diagonal pairs alternate) and the Fig. 3 caption (the RR leg
    touches down as the left rear lifts, leaving a diagonal pair), so it is read as LF-RR (= LF+RH). The
    torso sways so that the COM follows the periodic LIP whose ZMP is the midpoint of the supporting pair."""
    speed, period, hip_height = positive_scalar(speed, "speed"), positive_scalar(period, "period"), positive_scalar(hip_height, "hip_height")
    step_height = positive_scalar(step_height, "step_height", allow_zero=True)
    samples, cycles = _sample_counts(samples, cycles)
    p = robot.parameters
    dt = period / samples
    t = np.arange(samples) * dt
    torso_z = hip_height - p.hip_z
    touchdown = {"lf": 0, "rh": samples // 4, "rf": samples // 2, "lh": (3 * samples) // 4}
    # Footholds at the hip offsets from the COM path, so the supporting pairs' midpoints follow the COM; the
    # torso then runs behind the COM by the head's forward shift.
    _, _, com_up = np.asarray(lk.center_of_mass(robot.model, robot.model.neutral()))
    feet = np.zeros((samples, 4, 3))
    active = np.zeros((samples, 4), dtype=bool)
    for n, leg in enumerate(LEGS):
        x, z, stance = _foot_track(samples, touchdown[leg], samples // 2, dt, speed, step_height)
        hip = p.hip_position(leg)
        feet[:, n] = np.stack([hip[0] + x, np.full(samples, hip[1]), z], axis=-1)
        active[:, n] = stance
    zmp_ref = np.sum(feet[:, :, :2] * active[:, :, None], axis=1) / np.sum(active, axis=1, keepdims=True)
    columns = [robot.joint_slice(leg) for leg in LEGS]

    def joints_for(base_xy: np.ndarray) -> np.ndarray:
        base = np.stack([speed * t + base_xy[:, 0], base_xy[:, 1], np.full(samples, torso_z)], axis=-1)
        return np.concatenate([robot.leg_angles(leg, feet[:, n] - base) for n, leg in enumerate(LEGS)], axis=1)

    def states(base_xy: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _expand(robot.model, dt, 1, speed, base_xy, torso_z, joints, columns)[1:]

    base_xy, joints, zmp_error = _base_on_zmp(robot.model, t, speed, zmp_ref, torso_z + com_up, joints_for, states)
    times, q, v, a = _expand(robot.model, dt, cycles, speed, base_xy, torso_z, joints, columns)
    active = np.tile(active, (cycles, 1))
    labels = ["+".join(leg.upper() for leg, on in zip(LEGS, row) if on) for row in active]
    return GaitReference(times, q, v, a, robot.contacts(), active, labels, speed * len(times) * dt, [[n] for n in range(4)], zmp_error)


def biped_walk(robot: Biped, speed: float, step_length: float, samples: int, cycles: int, double_support: float,
               step_height: float, hip_height: float, arm_swing: float) -> GaitReference:
    """Walk with the left foot touching down at t = 0 and the right half a cycle later; each stance lasts
    (1 + double_support) step times. The pelvis follows the periodic LIP whose ZMP sits at the stance sole's
    centre in single support and moves from the trailing to the leading sole centre in double support; the
    arms swing by `arm_swing` [rad] against the same-side leg."""
    speed, step_length = positive_scalar(speed, "speed"), positive_scalar(step_length, "step_length")
    hip_height = positive_scalar(hip_height, "hip_height")
    double_support = positive_scalar(double_support, "double_support", allow_zero=True)
    step_height = positive_scalar(step_height, "step_height", allow_zero=True)
    if double_support >= 1.0:
        raise ValueError(f"double_support must be in [0, 1), got {double_support}")
    float_array(arm_swing, "arm_swing", shape=())
    samples, cycles = _sample_counts(samples, cycles)
    p = robot.parameters
    period = 2.0 * step_length / speed
    dt = period / samples
    t = np.arange(samples) * dt
    stance_samples = int(round(0.5 * (1.0 + double_support) * samples))
    touchdown = {"l": 0, "r": samples // 2}
    sole_centre = np.array([0.5 * (p.foot_toe - p.foot_heel), 0.0, 0.0])
    ankles = np.zeros((samples, 2, 3))
    active = np.zeros((samples, 8), dtype=bool)
    since_touchdown = np.zeros((samples, 2), dtype=int)
    for n, side in enumerate(SIDES):
        x, z, stance = _foot_track(samples, touchdown[side], stance_samples, dt, speed, step_height)
        ankles[:, n] = np.stack([x, np.full(samples, p.hip_y if side == "l" else -p.hip_y), z + p.ankle_height], axis=-1)
        active[:, 4 * n : 4 * n + 4] = stance[:, None]
        since_touchdown[:, n] = (np.arange(samples) - touchdown[side]) % samples
    centres = ankles[:, :, :2] + sole_centre[:2]
    left_on, right_on = active[:, 0], active[:, 4]
    leading = np.where(since_touchdown[:, 0] < since_touchdown[:, 1], 0, 1)
    weight = np.clip(np.min(since_touchdown, axis=1) / max(stance_samples - samples // 2, 1), 0.0, 1.0)
    rows = np.arange(samples)
    double = (1.0 - weight)[:, None] * centres[rows, 1 - leading] + weight[:, None] * centres[rows, leading]
    zmp_ref = np.where((left_on & right_on)[:, None], double, np.where(left_on[:, None], centres[:, 0], centres[:, 1]))
    arm_phase = 2.0 * np.pi * t / period
    arms = np.stack([arm_swing * np.sin(arm_phase), np.zeros(samples), -arm_swing * np.sin(arm_phase), np.zeros(samples)], axis=-1)
    columns = [robot.joint_slice("l"), robot.joint_slice("r"), robot.joint_slice("l", "arm"), robot.joint_slice("r", "arm")]

    def joints_for(base_xy: np.ndarray) -> np.ndarray:
        base = np.stack([speed * t + base_xy[:, 0], base_xy[:, 1], np.full(samples, hip_height)], axis=-1)
        legs = [robot.leg_angles(side, ankles[:, n] - base) for n, side in enumerate(SIDES)]
        return np.concatenate(legs + [arms], axis=1)

    def states(base_xy: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _expand(robot.model, dt, 1, speed, base_xy, hip_height, joints, columns)[1:]

    com_up = float(np.asarray(lk.center_of_mass(robot.model, robot.model.neutral()))[2])
    base_xy, joints, zmp_error = _base_on_zmp(robot.model, t, speed, zmp_ref, hip_height + com_up, joints_for, states)
    times, q, v, a = _expand(robot.model, dt, cycles, speed, base_xy, hip_height, joints, columns)
    active = np.tile(active, (cycles, 1))
    labels = ["double" if row.all() else ("left" if row[0] else "right") for row in active]
    return GaitReference(times, q, v, a, robot.contacts(), active, labels, speed * len(times) * dt, [[0, 1, 2, 3], [4, 5, 6, 7]], zmp_error)

