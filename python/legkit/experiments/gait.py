"""`legkit gait`: stability and energy indices over one cycle of a quadruped amble and a biped walk.

Reproduces the gait analysis of Hardt & von Stryk (RoboCup 2002; ../shared/seeds/003_8a51da06d878ba35.txt):
the amble of their Fig. 3 (0.67 m/s, gait period 1.25 s, duty factor 0.5, v_tip_max = 2 m/s, support order
LF+LH, LF+RH, RF+RH, RF+LH), and a biped walking at the 1.8 km/h (0.5 m/s) of their Sect. 6.

The published amble's numbers fix its stride: 0.67 m/s x 1.25 s = 0.84 m per cycle, so each foot sweeps
0.42 m under its hip during a stance (the paper's "gait stride 0.416 m" is this half cycle; 0.416 m per
cycle would mean 0.33 m/s). An AIBO-sized leg (0.145 m, legkit's default quadruped) cannot reach that far,
so the amble runs on the default quadruped with 0.18 m thighs and shanks at a hip height of 0.20 m
(``AMBLE_QUADRUPED``, ``AMBLE_HIP_HEIGHT``); masses and the rest of the body are unchanged.

Pipeline, per robot:
1. Reference motion from foot placements: the base moves at constant speed and height (the biped also sways
   sideways over its stance foot and swings its arms); stance feet stay where they touched down, swing feet
   follow a C2 minimum-jerk arc to the next foothold; joint angles by closed-form leg inverse kinematics;
   joint velocities and accelerations by periodic fourth-order central differences.
2. Inverse dynamics with contacts: rnea gives M a + h; the contact forces f of the stance feet solve the
   six base rows  M_b a + h_b = J_c,b^T f  in the least-squares (minimum-norm) sense, and the joint torques
   follow as tau = (M a + h)_joints - J_c,joints^T f. With two point feet (the quadruped's amble) the six
   rows cannot all be met: point forces cannot produce a moment about the line through the two feet, so the
   residual is the unbalanced tipping moment about the support line, reported as such. `lk.contact_dynamics`
   with those torques then gives the acceleration the constrained robot would really have; its distance
   from the reference is reported too.
3. Indices: S_H as published (definition="paper", the diagonal leg pairs LF-RH and RF-LH, travel along +x)
   and legkit's energy variant (definition="energy", the swing tips as catching legs), static stability margin, ZMP from the centroidal
   momentum rate and its margin to the support polygon, CoP of the contact forces, friction-cone margin,
   torque-speed margin, and the two energy indices over the cycle (J_e2 as the published integral and as
   its time mean, with v the COM's forward speed). The biped also gets the FRI of its feet in contact
   (eq. 8, the point S) and J_s1 (eq. 9) of the GCoM about it.

Outputs in --out: gait_<robot>.csv (one row per sample) and gait_<robot>.png (S_H over the cycle, like the
paper's Fig. 3: the published S_H, with the energy variant overlaid; the static and ZMP margins below). A short table is printed.
Nothing is random: the same arguments give the same files.

`--optimize` replaces the references by optimised gaits (`legkit.optimize`): the amble maximising the
worst-case S_H (J_s2) and the biped walk minimising the Joule loss (J_e1) with a Fig.-6 torque-speed plot
(`run_optimized_amble`, `run_optimized_walk`).
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

import legkit as lk
import legkit.stability as st
from legkit._validation import bounded_int, output_folder_argument
from legkit.robots.biped import JOINT_LABELS, SIDES, Biped, build_biped
from legkit.robots.quadruped import DIAGONAL_PAIRS, LEGS, Quadruped, QuadrupedParameters, build_quadruped

if TYPE_CHECKING:  # legkit.optimize.gaits imports this module
    from legkit.optimize.problem import MultiphaseProblem, Trajectory
    from legkit.optimize.replay import Replay


@dataclass(frozen=True)
class MotorParameters:
    """DC motor and gear of every actuated joint (same for all joints of a robot)."""

    resistance: float  # ohm
    torque_constant: float  # N m / A
    gear_ratio: float  # motor turns per joint turn
    efficiency: float  # gear efficiency in (0, 1]
    no_load_speed: float  # motor no-load speed [rad/s]
    stall_torque: float  # motor stall torque [N m]

    @property
    def joint_max_speed(self) -> float:
        return self.no_load_speed / self.gear_ratio

    @property
    def slope(self) -> float:
        """Motor speed-torque gradient m [rad/s per N m]."""
        return self.no_load_speed / self.stall_torque


QUADRUPED_MOTOR = MotorParameters(resistance=5.0, torque_constant=0.012, gear_ratio=60.0, efficiency=0.7, no_load_speed=1257.0, stall_torque=0.03)
#: The quadruped of the amble: legkit's default with legs long enough for the published 0.42 m stance sweep.
AMBLE_QUADRUPED = QuadrupedParameters(thigh_length=0.18, shank_length=0.18)
AMBLE_HIP_HEIGHT = 0.20  # [m]
BIPED_MOTOR = MotorParameters(resistance=0.5, torque_constant=0.05, gear_ratio=160.0, efficiency=0.8, no_load_speed=838.0, stall_torque=1.2)


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


def quadruped_amble(robot: Quadruped, speed: float, period: float, samples: int, cycles: int, step_height: float, hip_height: float) -> GaitReference:
    """Amble with duty factor 0.5 in the lateral sequence LF, RH, RF, LH (touchdowns a quarter cycle apart):
    the support order of file 003, Sect. 4.2, LF+LH, LF+RH, RF+RH, RF+LH from t = 0, a lateral pair then a
    diagonal one. The published list reads "LF-LB, LR-RR, RF-RR, RF-LR"; its second pair (both rear legs)
    contradicts the same paragraph (lateral and diagonal pairs alternate) and the Fig. 3 caption (the RR leg
    touches down as the left rear lifts, leaving a diagonal pair), so it is read as LF-RR (= LF+RH). The
    torso sways so that the COM follows the periodic LIP whose ZMP is the midpoint of the supporting pair."""
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


# --------------------------------------------------------------------------------------------------
# Dynamics and indices
# --------------------------------------------------------------------------------------------------


@dataclass
class ContactInverseDynamics:
    torques: np.ndarray  # (T, nv - 6) actuated joint torques [N m]
    forces: np.ndarray  # (T, k, 3) contact forces on the robot [N], zero for contacts in the air
    unbalanced: np.ndarray  # (T, 6) base-row residual [N; N m] the contact forces cannot supply
    points: np.ndarray  # (T, k, 3) world contact points


def contact_inverse_dynamics(model: lk.Model, ref: GaitReference) -> ContactInverseDynamics:
    """Least-squares contact forces and joint torques realising the reference accelerations (module docstring)."""
    generalized = np.asarray(lk.rnea(model, ref.q, ref.v, ref.a))  # (T, nv) = M a + h
    poses = np.asarray(lk.forward_kinematics(model, ref.q))
    jacobians = np.stack([np.asarray(lk.jacobian(model, ref.q, body, point))[:, :3, :] for body, point in ref.contacts], axis=1)  # (T, k, 3, nv)
    points = np.stack([np.einsum("tij,j->ti", poses[:, body, :3, :3], point) + poses[:, body, :3, 3] for body, point in ref.contacts], axis=1)
    jacobians = jacobians * ref.active[:, :, None, None]
    samples, k = ref.active.shape
    base_map = np.transpose(jacobians[..., :6], (0, 3, 1, 2)).reshape(samples, 6, 3 * k)  # (T, 6, 3k): J_b^T
    forces = np.einsum("tij,tj->ti", np.linalg.pinv(base_map, rcond=1e-10), generalized[:, :6])
    unbalanced = generalized[:, :6] - np.einsum("tij,tj->ti", base_map, forces)
    forces = forces.reshape(samples, k, 3)
    torques = generalized[:, 6:] - np.einsum("tkcv,tkc->tv", jacobians[..., 6:], forces)
    return ContactInverseDynamics(torques, forces, unbalanced, points)


def constrained_acceleration_gap(model: lk.Model, ref: GaitReference, torques: np.ndarray) -> float:
    """Largest |ddq - a_ref| over the samples, with ddq from `lk.contact_dynamics` under the found torques
    and the stance contacts held (one batched call per distinct support set)."""
    tau = np.concatenate([np.zeros((len(ref.t), 6)), torques], axis=1)
    gap = 0.0
    for support in np.unique(ref.active, axis=0):
        rows = np.all(ref.active == support, axis=1)
        contacts = [c for c, on in zip(ref.contacts, support) if on]
        ddq, _ = lk.contact_dynamics(model, ref.q[rows], ref.v[rows], tau[rows], contacts)
        gap = max(gap, float(np.max(np.abs(np.asarray(ddq) - ref.a[rows]))))
    return gap


@dataclass
class GaitAnalysis:
    robot: str
    ref: GaitReference
    dynamics: ContactInverseDynamics
    columns: dict[str, np.ndarray]
    summary: dict[str, float]


def analyse(name: str, model: lk.Model, ref: GaitReference, motor: MotorParameters, v_tip_max: float, mu: float,
            progress: tqdm, diagonal_pairs: list[tuple[int, int]] | None = None) -> GaitAnalysis:
    """Every index over the reference (see the module docstring). S_H: published (its diagonal edges join the
    contact pairs `diagonal_pairs`, travel along +x) and energy variant (the contact points in the air are the
    swing tips that make support edges diagonal)."""
    dyn = contact_inverse_dynamics(model, ref)
    progress.update()
    gap = constrained_acceleration_gap(model, ref, dyn.torques)
    progress.update()
    com = np.asarray(lk.center_of_mass(model, ref.q))
    s_h = st.angular_momentum_stability_of_model(model, ref.q, ref.v, dyn.points, ref.active, v_tip_max=v_tip_max, diagonal_pairs=diagonal_pairs)
    s_h_energy = st.angular_momentum_stability_of_model(
        model, ref.q, ref.v, dyn.points, ref.active, dyn.points, ~ref.active, v_tip_max, definition="energy"
    )
    forward_speed = np.asarray(lk.centroidal_momentum(model, ref.q, ref.v))[:, 0] / model.total_mass
    static = st.static_stability_margin(com, dyn.points, ref.active)
    zmp = st.zmp(model, ref.q, ref.v, ref.a)
    zmp_margin = st.static_stability_margin(zmp, dyn.points, ref.active)
    cop = st.center_of_pressure(dyn.points, dyn.forces)
    # Friction on each foot's resultant: how a foot's force is split among its sole corners is not determined.
    foot_forces = np.stack([dyn.forces[:, group].sum(axis=1) for group in ref.feet], axis=1)
    foot_on = np.stack([ref.active[:, group[0]] for group in ref.feet], axis=1)
    normals = np.broadcast_to([0.0, 0.0, 1.0], foot_forces.shape)
    friction = np.min(np.where(foot_on, st.friction_cone_margin(foot_forces, normals, mu), np.inf), axis=1)
    joint_v = ref.v[:, 6:]
    torque_speed = np.min(st.torque_speed_margin(dyn.torques, joint_v, motor.joint_max_speed, motor.gear_ratio, motor.efficiency, motor.slope),
                          axis=1)
    joule = st.joule_loss_power(dyn.torques, motor.resistance, motor.gear_ratio, motor.torque_constant)
    mechanical = np.sum(np.abs(dyn.torques * joint_v), axis=1)
    progress.update()
    columns = {
        "t": ref.t, "S_H": s_h, "S_H_energy": s_h_energy, "static_margin": static, "zmp_x": zmp[:, 0], "zmp_y": zmp[:, 1], "zmp_margin": zmp_margin,
        "cop_x": cop[:, 0], "cop_y": cop[:, 1], "com_x": com[:, 0], "com_y": com[:, 1],
        "unbalanced_moment": np.linalg.norm(dyn.unbalanced[:, 3:], axis=1), "friction_margin": friction,
        "torque_speed_margin": torque_speed, "joule_power": joule, "mechanical_power": mechanical,
    }
    worst, worst_t = st.worst_case(s_h, ref.t)
    mass, g = model.total_mass, -model.gravity[2]
    summary = {
        "S_H min [N m s]": worst, "S_H min at [s]": worst_t, "S_H mean [N m s]": float(np.mean(s_h)),
        "S_H energy variant min [N m s]": float(np.min(s_h_energy)),
        "static margin min [m]": float(np.min(static)), "static margin max [m]": float(np.max(static)),
        "ZMP margin min [m]": float(np.min(zmp_margin)), "ZMP margin max [m]": float(np.max(zmp_margin)),
        "planned-ZMP tracking error max [m]": ref.zmp_tracking_error,
        "|CoP - ZMP| max [m]": float(np.max(np.linalg.norm(cop[:, :2] - zmp[:, :2], axis=1))),
        "unbalanced tipping moment max [N m]": float(np.max(columns["unbalanced_moment"])),
        "contact-dynamics |ddq - a_ref| max": gap,
        "friction margin min [N]": float(np.min(friction)), "torque-speed margin min [N m]": float(np.min(torque_speed)),
        "E1 Joule loss [J/m]": st.joule_loss_index(dyn.torques, ref.t, ref.distance, motor.resistance, motor.gear_ratio, motor.torque_constant),
        "J_e2 (eq. 13) [s]": st.specific_resistance(dyn.torques, joint_v, ref.t, forward_speed, mass, g),
        "J_e2 time mean [-]": st.specific_resistance(dyn.torques, joint_v, ref.t, forward_speed, mass, g, definition="mean"),
    }
    return GaitAnalysis(name, ref, dyn, columns, summary)


def _biped_extras(robot: Biped, analysis: GaitAnalysis) -> None:
    """FRI S of the feet in contact (eq. 8) and its margin to the sole in single support, the foot-torque
    margins (eq. 6) of each stance foot's wrench about its sole point below the ankle, and J_s1 (eq. 9) of the
    GCoM about S."""
    ref, model = analysis.ref, robot.model
    poses = np.asarray(lk.forward_kinematics(model, ref.q))
    torque_margin = np.full(len(ref.t), np.inf)
    for side, group in zip(SIDES, ref.feet):
        sole_point = poses[:, model.names.index(f"{side}_foot"), :3, 3] - [0.0, 0.0, robot.parameters.ankle_height]
        forces = analysis.dynamics.forces[:, group]
        moment = np.sum(np.cross(analysis.dynamics.points[:, group] - sole_point[:, None, :], forces), axis=1)
        margins = np.min(st.foot_torque_margin(forces.sum(axis=1), moment, robot.parameters.sole), axis=1)
        torque_margin = np.where(ref.active[:, group[0]], np.minimum(torque_margin, margins), torque_margin)
    analysis.columns["foot_torque_margin"] = torque_margin
    analysis.summary["foot-torque margin min (eq. 6) [N m]"] = float(np.min(torque_margin))
    # S of eq. 8 for the feet in contact (one foot or both); its margin to the sole in single support.
    left, right = ref.active[:, 0], ref.active[:, 4]
    fri = np.zeros((len(ref.t), 3))
    fri_margin = np.full(len(ref.t), np.nan)
    for feet, rows in ((("l_foot",), left & ~right), (("r_foot",), right & ~left), (("l_foot", "r_foot"), left & right)):
        if not np.any(rows):
            continue
        fri[rows] = st.foot_rotation_indicator(model, ref.q[rows], ref.v[rows], ref.a[rows], feet)
        if len(feet) == 1:
            group = ref.feet[SIDES.index(feet[0][0])]
            fri_margin[rows] = st.static_stability_margin(fri[rows], analysis.dynamics.points[rows][:, group])
    analysis.columns.update({"fri_x": fri[:, 0], "fri_y": fri[:, 1], "fri_margin": fri_margin})
    single = ~np.isnan(fri_margin)
    analysis.summary["FRI margin min, single support [m]"] = float(np.min(fri_margin[single]))
    gcom = np.stack([analysis.columns["com_x"], analysis.columns["com_y"]], axis=1)
    analysis.summary["J_s1 (eq. 9) [m^2 s]"] = st.stability_performance_1(gcom, fri, ref.t)


# --------------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------------


def write_csv(path: Path, analysis: GaitAnalysis) -> None:
    names = list(analysis.columns)
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(names + ["support"])
        rows = np.stack([analysis.columns[n] for n in names], axis=1)
        for row, label in zip(rows, analysis.ref.support_label):
            writer.writerow([f"{x:.9g}" for x in row] + [label])


def plot(path: Path, analysis: GaitAnalysis, title: str) -> None:
    """S_H over the cycle (paper Fig. 3) with the support phases shaded, and the static/ZMP margins below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, labels = analysis.ref.t, analysis.ref.support_label
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    starts = [0] + [i for i in range(1, len(labels)) if labels[i] != labels[i - 1]] + [len(labels)]
    shades: dict[str, str] = {}
    for a, b in zip(starts[:-1], starts[1:]):
        colour = shades.setdefault(labels[a], f"C{len(shades) + 2}")
        for axis in (top, bottom):
            axis.axvspan(t[a], t[b - 1], color=colour, alpha=0.12, lw=0)
        top.text(0.5 * (t[a] + t[b - 1]), 1.0, labels[a], transform=top.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
    top.plot(t, analysis.columns["S_H"], color="C0", label="S_H (paper, eq. 10)")
    top.plot(t, analysis.columns["S_H_energy"], color="C1", ls="--", lw=0.9, label="S_H (energy variant)")
    top.legend(loc="lower right", fontsize=8)
    top.axhline(0.0, color="k", lw=0.8)
    top.set_ylabel("S_H [N m s]")
    top.set_title(title, pad=14)
    bottom.plot(t, analysis.columns["static_margin"] * 1e3, color="C1", label="static margin")
    bottom.plot(t, analysis.columns["zmp_margin"] * 1e3, color="C0", ls="--", label="ZMP margin")
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.set_ylabel("margin [mm]")
    bottom.set_xlabel("t [s]")
    bottom.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def print_table(analyses: list[GaitAnalysis]) -> None:
    keys = list(dict.fromkeys(k for a in analyses for k in a.summary))
    width = max(len(k) for k in keys)
    print(f"{'':{width}}  " + "  ".join(f"{a.robot:>12}" for a in analyses))
    for key in keys:
        cells = [f"{a.summary[key]:12.5g}" if key in a.summary else f"{'-':>12}" for a in analyses]
        print(f"{key:{width}}  " + "  ".join(cells))


def run(robot_name: str, args: argparse.Namespace, progress: tqdm) -> GaitAnalysis:
    """Build the robot and its reference, analyse it, and write its CSV and figure."""
    if robot_name == "quadruped":
        quadruped = build_quadruped(AMBLE_QUADRUPED)
        ref = quadruped_amble(quadruped, args.quadruped_speed, args.quadruped_period, args.samples, args.cycles, 0.03, AMBLE_HIP_HEIGHT)
        model, motor, tip_speed = quadruped.model, QUADRUPED_MOTOR, args.quadruped_tip_speed
        diagonal = [(LEGS.index(a), LEGS.index(b)) for a, b in DIAGONAL_PAIRS]
        title = (f"Quadruped amble, duty 0.5, {args.quadruped_speed:g} m/s, period {args.quadruped_period:g} s: "
                 f"S_H over {args.cycles} cycle(s)")
    else:
        biped = build_biped()
        ref = biped_walk(biped, args.biped_speed / 3.6, args.biped_step, args.samples, args.cycles, 0.2, 0.05, 0.82, 0.3)
        model, motor, tip_speed, diagonal = biped.model, BIPED_MOTOR, args.biped_tip_speed, None
        title = f"Biped walk, {args.biped_speed:g} km/h: S_H over {args.cycles} cycle(s)"
    progress.update()
    analysis = analyse(robot_name, model, ref, motor, tip_speed, FRICTION if args.mu is None else args.mu, progress, diagonal)
    if robot_name == "biped":
        _biped_extras(biped, analysis)
    write_csv(args.out / f"gait_{robot_name}.csv", analysis)
    plot(args.out / f"gait_{robot_name}.png", analysis, title)
    progress.update()
    return analysis


def run_optimized_amble(args: argparse.Namespace) -> dict[str, float]:
    """`--optimize`: the Fig. 3 amble optimised by multiphase collocation on IPOPT (`legkit.optimize`), maximising
    the worst-case S_H (J_s2, eq. 11) from the hand-built reference, its touchdown impulses bounded by --max-impulse
    (default 0: the feet land at rest); one labelled progress line per IPOPT stage. With
    --coarse-intervals, J_s2 is solved on that mesh and the optimum refined onto --intervals (`MultiphaseProblem.refine`).
    Writes gait_quadruped_optimized.csv (every collocation point: t, phase, support, q, v, u, S_H) and .png
    (S_H over the period with its worst case marked, beside the reference's), then replays the gait in
    `lk.Simulation` over --replay-cycles cycles under the contact-constrained MPC of `legkit.optimize.tracking` (by
    default; --replay-controller pd: joint PD tracking with --replay-kp, --replay-kd + feed-forward torques), saying
    which, and, unless --no-animation, writes the replay beside the plan as .html (meshcat) and .gif, captioned with
    the controller."""
    from legkit.optimize import MinMaxStability
    from legkit.optimize.gaits import (
        AMBLE_DERIVATIVES,
        AMBLE_IPOPT,
        AMBLE_MIRROR,
        amble_problem,
        amble_reference,
        guess_from_reference,
        stall_torque_bounds,
    )
    from legkit.optimize.replay import replay
    from legkit.optimize.tracking import track

    robot = build_quadruped(AMBLE_QUADRUPED)
    speed, period = args.quadruped_speed, args.quadruped_period

    def amble(intervals: int) -> tuple[MultiphaseProblem, Trajectory]:
        problem = amble_problem(robot, [MinMaxStability(args.quadruped_tip_speed, DIAGONAL_PAIRS)], speed, period,
                                intervals, QUADRUPED_MOTOR, AMBLE_PLAN_FRICTION if args.mu is None else args.mu, max_impulse=args.max_impulse,
                                mirror=AMBLE_MIRROR if args.mirror is None else args.mirror, min_normal_force=args.min_normal_force,
                                torque_margin=args.torque_margin)
        return problem, guess_from_reference(problem, amble_reference(robot, speed, period, intervals))

    problem, guess = amble(args.intervals)
    reference_s_h = np.concatenate(problem.stability_index(problem.pack(guess)))
    print(f"optimising the amble: {problem.n} variables, {problem.m} constraints, {len(problem.jac_rows)} Jacobian nonzeros"
          + (f", from {args.coarse_intervals} intervals per phase" if args.coarse_intervals else ""))

    # The constraints first, then J_s2, optionally polished with the exact Hessian; with --coarse-intervals on the
    # coarse mesh, then refined onto --intervals.
    solved, solved_guess = amble(args.coarse_intervals) if args.coarse_intervals else (problem, guess)
    progress = _StageProgress(["constraints (p1 held below S_H)", "J_s2 (L-BFGS)"]
                              + (["polish: exact Hessian, durations held", "polish: exact Hessian"] if args.polish else []))
    _, result = solved.solve(solved_guess, derivatives=AMBLE_DERIVATIVES, feasibility_first=True, polish=args.polish,
                             polish_max_iter=args.polish_max_iter, tol=args.tol, max_iter=args.max_iter,
                             progress=progress, options=AMBLE_IPOPT)
    progress.close()
    if solved is not problem:
        if not result.success:
            print(f"the {args.coarse_intervals}-interval solve ended with {result.status}; refining its best point")
        progress = _StageProgress([f"refine onto {args.intervals} intervals"])
        _, result = problem.refine(solved, result, tol=args.tol, max_iter=args.max_iter, progress=progress, options=AMBLE_IPOPT)
        progress.close()
    x, _ = result.best()
    if x is result.x:
        kept = result.history[-1][0]
    else:
        assert result.best_feasible is not None  # best() returns another point than IPOPT's only from best_feasible
        kept = result.best_feasible[0]
    problem, x = _whole_cycle(problem, x)
    trajectory = problem.unpack(x)
    data = trajectory.stacked()
    labels = ["+".join(leg.upper() for leg in problem.phases[k].contacts) for k in data["phase"]]
    columns = _write_trajectory_csv(args.out / "gait_quadruped_optimized.csv", trajectory, labels,
                                    {"S_H": np.concatenate(problem.stability_index(x))})
    worst, worst_t = st.worst_case(columns["S_H"], data["t"])
    _plot_optimized(args.out / "gait_quadruped_optimized.png", data["t"], columns["S_H"], guess.stacked()["t"], reference_s_h, labels, worst, worst_t,
                    f"Optimised amble (J_s2), {speed:g} m/s, period {period:g} s: IPOPT {result.status}, iterate {kept} kept"
                    + (f", refined from {args.coarse_intervals} intervals" if args.coarse_intervals else ""))
    if args.replay_controller == "mpc":
        controller = ("the contact-constrained MPC (legkit.optimize.tracking: 2 ms control period, 120 ms horizon, "
                      "stance forces >= 0.5 N in the friction pyramid, swing feet above the ground, the motors' stall torques)")
        print(f"replaying {args.replay_cycles} cycles in lk.Simulation under {controller}")
        simulated = track(problem, trajectory, args.replay_cycles, torque_bounds=stall_torque_bounds(QUADRUPED_MOTOR, problem.nu))
    else:
        controller = f"joint PD tracking (kp {args.replay_kp:g} N m/rad, kd {args.replay_kd:g} N m s/rad) + the planned torques as feed-forward"
        print(f"replaying {args.replay_cycles} cycles in lk.Simulation under {controller}")
        simulated = replay(problem, trajectory, args.replay_cycles, kp=args.replay_kp, kd=args.replay_kd, control_every=1)
    if not args.no_animation:
        _animate_replay(args.out / "gait_quadruped_optimized", problem, simulated,
                        "the contact-constrained MPC (2 ms, 120 ms horizon)" if args.replay_controller == "mpc"
                        else f"joint PD (kp {args.replay_kp:g}, kd {args.replay_kd:g}) + feed-forward")
    return {
        "IPOPT iterations": result.iterations, "solve wall time [s]": result.wall_time,
        "function + Jacobian share of the solve [%]": 100.0 * result.evaluation_time / result.wall_time,
        "kept iterate (IPOPT's last unless a better one within tol)": float(kept),
        "max constraint violation (legkit dynamics)": problem.nlp().violation(x),
        "largest stance-foot acceleration at the midpoints [m/s^2] (the knots hold 0)": midpoint_stance_acceleration(problem, x),
        **interval_drift_summary(problem, x),
        **execution_summary(problem, x),
        "S_H min, optimised [N m s]": worst, "S_H min at [s]": worst_t, "S_H min, reference [N m s]": float(reference_s_h.min()),
        **{f"phase {k} ({'+'.join(p.contacts).upper()}) duration [s]": float(d)
           for k, (p, d) in enumerate(zip(problem.phases, trajectory.durations))},
        f"replay ({args.replay_controller}): drift over {args.replay_cycles} cycles [% of distance]": 100.0 * simulated.drift_fraction,
        "replay: stayed upright (1 = yes)": float(simulated.upright),
        "replay: fell after [s] (inf: never)": simulated.fell_at,
        "solver succeeded (1 = yes)": float(result.success),
    }


def run_optimized_walk(args: argparse.Namespace) -> dict[str, float]:
    """`--optimize`: the biped walk at --biped-speed minimising J_e1 (eq. 12) under the motors' torque-speed lines
    (Sect. 2.3 and 6 of file 003; `legkit.optimize.gaits.walk_problem`), its soles flat with eq. 6's torque
    limits, from the hand-built reference (`biped_walk`); constraints first, then J_e1, one progress line per
    IPOPT iteration. Writes gait_biped_optimized.csv (every collocation point: t, phase, support, q, v, u, the
    feet's forces and torques) and gait_biped_torque_speed.png (Fig. 6: each joint's (speed, torque) points over
    the period against the motor's characteristic lines for several gear ratios)."""
    from legkit.optimize.gaits import WALK_MIRROR, guess_from_reference, solve_walk, walk_problem, walk_reference

    robot = build_biped()
    speed = args.biped_speed / 3.6
    intervals = (max(1, args.biped_intervals // 4), args.biped_intervals)
    problem = walk_problem(robot, speed, BIPED_MOTOR, intervals, FRICTION if args.mu is None else args.mu, max_input_power=args.biped_max_power,
                           mirror=WALK_MIRROR if args.mirror is None else args.mirror)
    guess = guess_from_reference(problem, walk_reference(robot, speed, intervals))
    print(f"optimising the biped walk: {problem.n} variables, {problem.m} constraints, {len(problem.jac_rows)} Jacobian nonzeros")
    cpu = time.process_time()
    progress = _StageProgress(["constraints", "J_e1"])
    _, result = solve_walk(problem, guess, tol=args.tol, max_iter=args.biped_max_iter, progress=progress)
    progress.close()
    cpu = time.process_time() - cpu
    x, objective = result.best()
    problem, x = _whole_cycle(problem, x)
    trajectory = problem.unpack(x)
    data = trajectory.stacked()
    labels = ["+".join(problem.phases[k].contacts).upper() for k in data["phase"]]
    wrenches = {}
    for side in SIDES:  # zero while the foot is in the air
        force, torque = np.zeros((len(data["t"]), 3)), np.zeros((len(data["t"]), 3))
        rows = np.cumsum([0] + [len(t) for t in trajectory.t])
        for k, phase in enumerate(problem.phases):
            if side in phase.contacts:
                force[rows[k] : rows[k + 1]] = trajectory.forces[k][:, phase.contacts.index(side)]
                assert trajectory.torques is not None  # the walk's feet are flat: unpack gives their torques
                torque[rows[k] : rows[k + 1]] = trajectory.torques[k][:, problem.flat_contacts(phase.contacts).index(side)]
        wrenches.update({f"{side}_F{axis}": force[:, i] for i, axis in enumerate("xyz")})
        wrenches.update({f"{side}_T{axis}": torque[:, i] for i, axis in enumerate("xyz")})
    _write_trajectory_csv(args.out / "gait_biped_optimized.csv", trajectory, labels, wrenches)
    joint_speed = data["v"][:, problem.actuated]
    plot_torque_speed(args.out / "gait_biped_torque_speed.png", robot, joint_speed, data["u"], BIPED_MOTOR,
                      f"Optimised biped walk (J_e1), {args.biped_speed:g} km/h: IPOPT {result.status}")
    return {
        "IPOPT iterations (constraints, then J_e1)": result.iterations, "solve wall time [s]": result.wall_time,
        "solve CPU time of this process [s]": cpu, "J_e1 (eq. 12) [J/m]": objective,
        "max constraint violation (legkit dynamics)": problem.nlp().violation(x),
        "max |rnea - B u| (lk.rnea) [N m]": float(np.max(np.abs(np.concatenate(inverse_dynamics_residuals(problem, x))))),
        **interval_drift_summary(problem, x),
        **execution_summary(problem, x),
        "period [s]": float(np.sum(trajectory.durations)), "step length [m]": 0.5 * speed * float(np.sum(trajectory.durations)),
        **{f"phase {k} ({'+'.join(p.contacts).upper()}) duration [s]": float(d)
           for k, (p, d) in enumerate(zip(problem.phases, trajectory.durations))},
        "torque-speed margin min (Sect. 2.3) [N m]": float(np.min(st.torque_speed_margin(
            data["u"], joint_speed, BIPED_MOTOR.joint_max_speed, BIPED_MOTOR.gear_ratio, BIPED_MOTOR.efficiency, BIPED_MOTOR.slope))),
        "solver succeeded (1 = yes)": float(result.success),
    }


def execution_summary(problem: MultiphaseProblem, x: np.ndarray) -> dict[str, float]:
    """`legkit.optimize.checks.execution_check` of a solution as summary rows."""
    from legkit.optimize.checks import execution_check

    check = execution_check(problem, x)
    return {"torso yaw max [deg]": check.yaw, "joint rate max between points / motors' no-load speed": check.joint_rate,
            "torque max / bound": check.torque, "torque rate max [bound per ms]": check.torque_rate,
            "foot load rate max [body weight per ms]": check.force_rate, "swing tip min between points [m]": check.swing_height}


def interval_drift_summary(problem: MultiphaseProblem, x: np.ndarray) -> dict[str, float]:
    """The largest drift of the model's own dynamics over one collocation interval (`legkit.optimize.shooting`):
    how far the mesh is from a motion. Large values (degrees of attitude, tenths of a radian) ask for more
    intervals (--intervals, --biped-intervals)."""
    from legkit.optimize import interval_drift

    worst = interval_drift(problem, x).worst(problem.model.floating_base)
    return {f"largest drift over one interval, {name}": value for name, value in worst.items()
            if name in ("attitude [deg]", "joints", "joint rates")}


def midpoint_stance_acceleration(problem: MultiphaseProblem, x: np.ndarray) -> float:
    """The largest stance-foot acceleration [m/s^2] at the midpoints (`MultiphaseProblem.stance_accelerations`;
    the knots hold it at 0): how far the collocation cubics between the knots are from a motion."""
    return max(float(np.linalg.norm(a[1::2], axis=-1).max(initial=0.0)) for a in problem.stance_accelerations(x))


def _whole_cycle(problem: MultiphaseProblem, x: np.ndarray) -> tuple[MultiphaseProblem, np.ndarray]:
    """A solution as the whole cycle's problem and variables: unrolled if the problem is a mirrored half cycle,
    so that everything after (CSV, figures, the violation re-evaluated, the replay) sees the whole gait."""
    if problem.mirror is None:
        return problem, x
    whole = problem.full_cycle()
    return whole, whole.pack(problem.unroll(problem.unpack(x)))


def inverse_dynamics_residuals(problem: MultiphaseProblem, x: np.ndarray) -> list[np.ndarray]:
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


#: Gear ratios drawn in the torque-speed figure: the paper's choice for its biped (Fig. 6, Sect. 6: 42 V motors with
#: 66:1 gears), one between, and BIPED_MOTOR's own (the constraint).
FIG6_GEAR_RATIOS = (66.0, 100.0, BIPED_MOTOR.gear_ratio)


def plot_torque_speed(path: Path, robot: Biped, joint_speed: np.ndarray, torque: np.ndarray, motor: MotorParameters, title: str) -> None:
    """Fig. 6 of file 003: per joint (left and right together), |torque| against |speed| [rpm] at every collocation
    point, with the characteristic line |u| = (w_max - |w|) G^2 eta / m (Sect. 2.3) of `motor` at each gear ratio
    in FIG6_GEAR_RATIOS (the motor's own ratio bounds the optimisation)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rpm = 60.0 / (2.0 * np.pi)
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(robot.model.names):
        if robot.model.idx_v[i] >= 6 and name[:2] in ("l_", "r_") and robot.model.joint_type(i) == "revolute":
            groups.setdefault(name[2:], []).append(robot.model.idx_v[i] - 6)
    fig, axes = plt.subplots(2, (len(groups) + 1) // 2, figsize=(13, 6), sharex=True)
    top = max(np.max(np.abs(torque)), 1e-9)
    for axis, (name, columns) in zip(axes.ravel(), groups.items()):
        for gear, style in zip(FIG6_GEAR_RATIOS, (":", "--", "-")):
            w_max = motor.no_load_speed / gear
            gain = gear**2 * motor.efficiency / motor.slope
            axis.plot([0.0, w_max * rpm], [w_max * gain, 0.0], color="k", ls=style, lw=0.8, label=f"{gear:g}:1")
        for column, side in zip(columns, ("left", "right")):
            axis.plot(np.abs(joint_speed[:, column]) * rpm, np.abs(torque[:, column]), ".", ms=4, label=side)
        axis.set_title(JOINT_LABELS[name], fontsize=9)
        axis.set_ylim(0.0, 1.3 * top)
        axis.set_xlim(0.0, 1.05 * motor.no_load_speed / min(FIG6_GEAR_RATIOS) * rpm)  # every line's no-load speed
    for axis in axes[-1]:
        axis.set_xlabel("|joint speed| [rpm]")
    for axis in axes[:, 0]:
        axis.set_ylabel("|joint torque| [N m]")
    axes.ravel()[0].legend(fontsize=7, title="motor line, gear", title_fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


class _StageProgress:
    """progress(iteration, objective, violation) printing one labelled line per IPOPT run (a stage of the solve:
    its iterations, objective and largest violation), updated in place on a terminal; `close` ends the last."""

    def __init__(self, labels: Sequence[str]) -> None:
        self.labels, self.stage, self.running, self.last = list(labels), -1, False, (0, 0.0, 0.0)
        self.live = sys.stdout.isatty()

    def __call__(self, iteration: int, objective: float, violation: float) -> None:
        if iteration == 0:  # IPOPT's first iterate: a new run
            self.close()
            self.stage, self.running = self.stage + 1, True
        self.last = (iteration, objective, violation)
        if self.live:
            print("\r" + self.line(), end="", flush=True)

    def line(self) -> str:
        label = self.labels[self.stage] if self.stage < len(self.labels) else f"run {self.stage + 1}"
        iteration, objective, violation = self.last
        return f"  {label}: {iteration} iterations, objective {objective: .6e}, max violation {violation:.2e}"

    def close(self) -> None:
        if self.running:
            print(("\r" if self.live else "") + self.line(), flush=True)
            self.running = False


def _write_trajectory_csv(path: Path, trajectory: Trajectory, labels: list[str], extra: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every collocation point of an optimised trajectory: t, phase, the `extra` columns, q, v, u, and the
    support label; returns the numeric columns."""
    data = trajectory.stacked()
    columns = {"t": data["t"], "phase": data["phase"].astype(float), **extra}
    for name, values in (("q", data["q"]), ("v", data["v"]), ("u", data["u"])):
        columns.update({f"{name}{i}": values[:, i] for i in range(values.shape[1])})
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(list(columns) + ["support"])
        for row, label in zip(np.stack(list(columns.values()), axis=1), labels):
            writer.writerow([f"{x:.9g}" for x in row] + [label])
    return columns


def _animate_replay(stem: Path, problem: MultiphaseProblem, simulated: Replay, controller: str) -> None:
    """stem.html (meshcat) and stem.gif: the replay in simulation (coloured) beside the optimised plan (grey,
    translucent in the HTML, REPLAY_AHEAD m ahead of it), both seen from the side in a frame that moves with the
    plan's travel (so that the robots stay large in the picture and apart), the controller named in the title."""
    from legkit import viewer

    moving = np.zeros(len(simulated.t))
    if problem.travel_index is not None:
        moving = simulated.planned_q[:, problem.travel_index] - simulated.planned_q[0, problem.travel_index]
    simulated_q, planned_q = simulated.q.copy(), simulated.planned_q.copy()
    simulated_q[:, 0] -= moving
    planned_q[:, 0] -= moving
    speed = moving[-1] / simulated.t[-1] if simulated.t[-1] > 0 else 0.0
    scene = viewer.Scene(view=(75.0, 15.0), title=f"the amble replayed in simulation under {controller}",
                         caption=f"legkit gait --optimize. Coloured: simulated; grey: the optimised plan, {REPLAY_AHEAD:g} m ahead; "
                                 f"seen from a frame moving at the plan's {speed:.2f} m/s"
                                 + ("" if simulated.upright else f"; fell at {simulated.fell_at:.2f} s"))
    scene.add_robot(problem.model, planned_q, simulated.t, name="planned", color=(0.55, 0.55, 0.6, 0.35), label="planned",
                    offset=[REPLAY_AHEAD, 0.0, 0.0])
    scene.add_robot(problem.model, simulated_q, simulated.t, name="simulated", label="simulated")
    scene.write_html(stem.with_suffix(".html"))
    scene.write_gif(stem.with_suffix(".gif"), size=(800, 450))


#: [m] how far ahead of the simulated robot the replay's animation shows the plan.
REPLAY_AHEAD = 0.45


def _plot_optimized(path: Path, t: np.ndarray, s_h: np.ndarray, reference_t: np.ndarray, reference: np.ndarray, labels: list[str],
                    worst: float, worst_t: float, title: str) -> None:
    """Fig. 3 of file 003 for the optimised gait: S_H over one period, the worst case marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(8, 4))
    starts = [0] + [i for i in range(1, len(labels)) if labels[i] != labels[i - 1]] + [len(labels)]
    for n, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
        axis.axvspan(t[a], t[b - 1], color=f"C{n % 4 + 2}", alpha=0.12, lw=0)
        axis.text(0.5 * (t[a] + t[b - 1]), 1.0, labels[a], transform=axis.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
    axis.plot(reference_t, reference, color="C1", ls="--", lw=0.9, label="hand-built reference")
    axis.plot(t, s_h, color="C0", marker=".", label="optimised (J_s2)")
    axis.plot([worst_t], [worst], "rv", label=f"worst case {worst:.3g} N m s")
    axis.axhline(0.0, color="k", lw=0.8)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("S_H (eq. 10) [N m s]")
    axis.set_title(title, pad=14, fontsize=9)
    axis.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """`legkit gait`: analyse the quadruped amble and/or the biped walk; writes CSVs and figures to --out."""
    parser = argparse.ArgumentParser(prog="legkit gait", description=__doc__.splitlines()[0])
    parser.add_argument("--robot", choices=["quadruped", "biped", "both"], default="both")
    parser.add_argument("--out", type=output_folder_argument, default="gait_results", help="output folder (created)")
    parser.add_argument("--cycles", type=_positive_int, default=1, help="gait cycles to analyse")
    parser.add_argument("--samples", type=_positive_int, default=400, help="samples per cycle (>= 8)")
    parser.add_argument("--mu", type=float, default=None,
                        help="friction coefficient: of the friction-cone margin (default 0.8) and of the optimised amble's plan (default 0.6, "
                             "the tracking MPC's friction pyramid)")
    parser.add_argument("--quadruped-speed", type=float, default=0.67, help="amble speed [m/s] (Fig. 3: 0.67)")
    parser.add_argument("--quadruped-period", type=float, default=1.25, help="amble cycle time [s] (Fig. 3: 1.25)")
    parser.add_argument("--quadruped-tip-speed", type=float, default=2.0, help="swing-leg tip speed limit v_tip_max [m/s] (Fig. 3: 2)")
    parser.add_argument("--biped-speed", type=float, default=1.8, help="walking speed [km/h]")
    parser.add_argument("--biped-step", type=float, default=0.4, help="step length [m]")
    parser.add_argument("--biped-tip-speed", type=float, default=3.0, help="swing-foot speed limit v_tip_max [m/s]")
    parser.add_argument("--optimize", action="store_true", help="optimise the quadruped amble for the worst-case S_H "
                        "(J_s2) on IPOPT, write its CSV/figure and replay it in simulation, and the biped walk for the "
                        "Joule loss (J_e1), writing its CSV and torque-speed figure (--robot picks one or both)")
    parser.add_argument("--intervals", type=_positive_int, default=16,
                        help="--optimize: collocation intervals per amble phase (16: a plan that is a motion of the model)")
    parser.add_argument("--coarse-intervals", type=_non_negative_int, default=None,
                        help="--optimize: solve the amble on this many intervals per phase first, then refine it onto --intervals with its "
                             "worst-case S_H held at a fraction of the coarse optimum's (MultiphaseProblem.refine; default 4 when --intervals "
                             "is more, 0: solve on --intervals directly)")
    parser.add_argument("--biped-intervals", type=_positive_int, default=4,
                        help="--optimize: collocation intervals per biped single-support phase (a quarter, at least 1, per double support)")
    parser.add_argument("--max-iter", type=_positive_int, default=300,
                        help="--optimize: IPOPT iteration limit for the amble (per continuation stage)")
    parser.add_argument("--biped-max-iter", type=_positive_int, default=1000,
                        help="--optimize: IPOPT iteration limit for the biped walk (per stage; J_e1 still falls slowly after 1000)")
    parser.add_argument("--tol", type=float, default=1e-6, help="--optimize: IPOPT tolerance")
    parser.add_argument("--biped-max-power", type=float, default=None,
                        help="--optimize: each biped motor's input power limit [W] (Sect. 6; default: none)")
    parser.add_argument("--replay-cycles", type=_positive_int, default=5, help="--optimize: cycles replayed in simulation")
    parser.add_argument("--replay-kp", type=float, default=50.0, help="--optimize: joint PD stiffness of the replay [N m/rad]")
    parser.add_argument("--replay-kd", type=float, default=1.0, help="--optimize: joint PD damping of the replay [N m s/rad]")
    parser.add_argument("--replay-controller", choices=("mpc", "pd"), default="mpc",
                        help="--optimize: the amble's replay: the contact-constrained model-predictive tracking of legkit.optimize.tracking "
                             "(mpc, the default: faster than real time; it holds plans that are motions of their model with a force floor, "
                             "as the defaults make them), or joint PD + feed-forward (pd, which holds none of them)")
    parser.add_argument("--min-normal-force", type=float, default=3.0,
                        help="--optimize: floor on every stance normal force of the amble's plan [N] (0: eq. 5 as published; the tracking "
                             "MPC needs one)")
    parser.add_argument("--torque-margin", type=float, default=0.0,
                        help="--optimize: fraction of the motors' torque the amble's plan leaves to feedback (0: the full line)")
    parser.add_argument("--max-impulse", type=float, default=0.0,
                        help="--optimize: bound on the amble's touchdown impulses [N s] (0: feet land at rest; inf: eq. 7 unbounded)")
    parser.add_argument("--no-animation", action="store_true", help="--optimize: do not write the replay's .html and .gif")
    parser.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                        help="--optimize: transcribe half of each gait's cycle, the other half its mirror image (mirror periodicity), "
                             "or (--no-mirror) the whole cycle; default: the amble's half (AMBLE_MIRROR), the walk's whole cycle (WALK_MIRROR)")
    parser.add_argument("--polish", action=argparse.BooleanOptionalAction, default=True,
                        help="--optimize: after the amble's L-BFGS runs (J_s2's ended once it stalls), IPOPT with the exact Hessian "
                             "from their best point, first with the phase durations held, then free, which converges J_s2")
    parser.add_argument("--polish-max-iter", type=_positive_int, default=1000, help="--optimize: IPOPT iteration limit of the amble's polish")
    args = parser.parse_args(argv)
    if args.coarse_intervals is None:
        args.coarse_intervals = 4 if args.intervals > 4 else 0
    if args.samples < 8:
        parser.error("--samples must be at least 8")
    if args.mu is not None and not (np.isfinite(args.mu) and args.mu > 0.0):
        parser.error("--mu must be a positive number")
    for name in ("quadruped_speed", "quadruped_period", "quadruped_tip_speed", "biped_speed", "biped_step", "biped_tip_speed"):
        if not np.isfinite(getattr(args, name)) or getattr(args, name) <= 0.0:
            parser.error(f"--{name.replace('_', '-')} must be a positive number")
    if args.biped_max_power is not None and not (np.isfinite(args.biped_max_power) and args.biped_max_power > 0.0):
        parser.error("--biped-max-power must be a positive number")
    if not (np.isfinite(args.min_normal_force) and args.min_normal_force >= 0.0):
        parser.error("--min-normal-force must be a non-negative number")
    if args.coarse_intervals and args.coarse_intervals >= args.intervals:
        parser.error(f"--coarse-intervals must be fewer than --intervals ({args.intervals})")
    if not 0.0 <= args.torque_margin < 1.0:
        parser.error("--torque-margin must be in [0, 1)")
    robots = ["quadruped", "biped"] if args.robot == "both" else [args.robot]
    if args.optimize:
        for name in robots:
            summary = run_optimized_amble(args) if name == "quadruped" else run_optimized_walk(args)
            width = max(len(k) for k in summary)
            for key, value in summary.items():
                print(f"{key:{width}}  {value:12.5g}")
            if name == "quadruped":
                print(f"wrote gait_quadruped_optimized.csv/.png{'' if args.no_animation else '/.html/.gif'} to {args.out}")
            else:
                print(f"wrote gait_biped_optimized.csv and gait_biped_torque_speed.png to {args.out}")
        return 0
    with tqdm(total=5 * len(robots), desc="gait analysis", unit="stage") as progress:
        analyses = [run(name, args, progress) for name in robots]
    print_table(analyses)
    print(f"wrote {', '.join(f'gait_{n}.csv/.png' for n in robots)} to {args.out}")
    return 0


#: The friction coefficient of the analyses and of the walk's plan, and of the optimised amble's plan: the tracking
#: MPC's friction pyramid, within which it holds the plan.
FRICTION, AMBLE_PLAN_FRICTION = 0.8, 0.6

#: Counts (cycles, samples, intervals, iterations) the command takes: far beyond what a run needs.
_positive_int = bounded_int(1, 1_000_000)
_non_negative_int = bounded_int(0, 1_000_000)
