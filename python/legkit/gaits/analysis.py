"""A gait's dynamics and indices: contact inverse dynamics and every stability and energy index of
[Hardt 2002] over a sampled reference (`legkit.gaits.references`).

Inverse dynamics with contacts: rnea gives M a + h; the contact forces f of the stance feet solve the six base rows
M_b a + h_b = J_c,b^T f in the least-squares (minimum-norm) sense, and the joint torques follow as
tau = (M a + h)_joints - J_c,joints^T f. With two point feet (the quadruped's amble) the six rows cannot all be met:
point forces cannot produce a moment about the line through the two feet, so the residual is the unbalanced tipping
moment about the support line, reported as such. `lk.contact_dynamics` with those torques then gives the acceleration
the constrained robot would really have; its distance from the reference is reported too.

Indices (`analyse`): S_H as published (definition="paper", the diagonal leg pairs LF-RH and RF-LH, travel along +x)
and legkit's energy variant (definition="energy", the swing tips as catching legs), static stability margin, ZMP from
the centroidal momentum rate and its margin to the support polygon, CoP of the contact forces, friction-cone margin,
torque-speed margin, and the two energy indices over the cycle (J_e2 as the published integral and as its time mean,
with v the COM's forward speed). The biped also gets the FRI of its feet in contact (eq. 8, the point S) and J_s1
(eq. 9) of the GCoM about it (`biped_extras`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import legkit as lk
import legkit.stability as st
from legkit.gaits.references import GaitReference
from legkit.robots.biped import SIDES, Biped
from legkit.robots.motors import MotorParameters


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
            diagonal_pairs: list[tuple[int, int]] | None = None, progress: Callable[[], object] | None = None) -> GaitAnalysis:
    """Every index over the reference (see the module docstring). S_H: published (its diagonal edges join the
    contact pairs `diagonal_pairs`, travel along +x) and energy variant (the contact points in the air are the
    swing tips that make support edges diagonal). progress: called after each of its three stages."""
    if progress is not None and not callable(progress):
        raise TypeError(f"progress: must be a callable or None, got {type(progress).__name__}")
    dyn = contact_inverse_dynamics(model, ref)
    if progress is not None:
        progress()
    gap = constrained_acceleration_gap(model, ref, dyn.torques)
    if progress is not None:
        progress()
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
    if progress is not None:
        progress()
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


def biped_extras(robot: Biped, analysis: GaitAnalysis) -> None:
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

