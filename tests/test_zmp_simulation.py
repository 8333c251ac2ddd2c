"""The ZMP from the dynamics equals the CoP of the simulated contact forces (tree engine) within 5 mm.

A robot stands on a plane with position servos holding a pose, settles, then sways its torso over
planted feet. At every step the ZMP comes from `legkit.stability.zmp` (centroidal momentum rate of the
legkit model at the simulated q, v, with the acceleration from central differences of the simulated v)
and the CoP from the ground contact forces the simulation reports (normal plus friction). Both the model's
gravity and its mass properties are the simulation's own (the Simulation is built from the same Model).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from legkit.robots.biped import SIDES, build_biped
from legkit.robots.quadruped import LEGS, build_quadruped
from legkit.stability import ground_point, zmp
from legkit.stability.simulated import ground_contact_wrench, simulated_center_of_pressure

DT = 1e-3
ZMP_COP_BOUND = 5e-3  # m, the target
FRICTION = 0.8
QUADRUPED_FOOT_RADIUS = 0.01


@dataclass
class Foot:
    """A foot's contact: its body, a point of it (the sphere centre or the sole centre, body frame [m]) and
    how far below that point the ground contact lies (the sphere radius; 0 for a sole point)."""

    body: int
    point: np.ndarray
    drop: float


@dataclass
class Trajectory:
    """Simulated states after 0..n steps and the ground wrench of each step (step j takes state j to j+1)."""

    model: lk.Model
    qs: np.ndarray  # (n + 1, nq)
    vs: np.ndarray  # (n + 1, nv)
    forces: np.ndarray  # (n, 3) ground force on the robot during step j [N]
    moments: np.ndarray  # (n, 3) its moment about the origin [N m]
    foot_load: np.ndarray  # (n, feet) normal force on each foot during step j [N]
    foot_friction: np.ndarray  # (n, feet) |resultant friction| / normal force of each foot
    sway_start: int  # first step with moving servo targets


def static_joint_torques(model: lk.Model, q: np.ndarray, support: list[tuple[int, np.ndarray]]) -> np.ndarray:
    """Generalized forces (nv,) that hold the robot at rest in q on the support points (body, point in
    body frame) with purely vertical contact forces of least norm (no internal horizontal force between
    the feet); the base rows vanish because such forces balance the whole robot's weight exactly."""
    com = lk.center_of_mass(model, q)
    poses = lk.forward_kinematics(model, q)
    points = np.array([poses[body, :3, :3] @ point + poses[body, :3, 3] for body, point in support])
    balance = np.vstack([np.ones(len(support)), points[:, 1] - com[1], points[:, 0] - com[0]])
    vertical = np.linalg.lstsq(balance, [-model.total_mass * model.gravity[2], 0.0, 0.0], rcond=None)[0]
    tau = lk.rnea(model, q, np.zeros(model.nv), np.zeros(model.nv))
    for (body, point), fz in zip(support, vertical):
        tau -= lk.jacobian(model, q, body, point)[:3].T @ np.array([0.0, 0.0, fz])
    assert np.abs(tau[:6]).max() < 1e-8 * model.total_mass, "vertical forces must balance the weight"
    tau[:6] = 0.0
    return tau


def stand_and_sway(
    model: lk.Model,
    shapes: dict,
    support: list[tuple[int, np.ndarray]],
    feet: list[Foot],
    stand: np.ndarray,
    sway: Callable[[float], np.ndarray],
    kp: np.ndarray,
    kd: np.ndarray,
    retarget_time: float,
    sway_time: float,
    end_time: float,
) -> Trajectory:
    """Stand `model` at q = `stand` (feet just touching z = 0) under position servos, then sway.

    `support` are the contact points the feed-forward torques assume (`static_joint_torques`); `feet` are
    the feet whose load and friction are recorded.

    The feet stick where they land, and the servos' small errors from the landing then squeeze them
    against friction (internal horizontal forces up to a third of the normal force). At retarget_time the
    servo targets are reset to the settled pose, with the static joint torques as feed-forward, which
    releases that preload. From sway_time on the targets follow sway(t - sway_time) - stand + settled (the
    feed-forward follows the target pose), so the torso moves while the feet stay planted.
    One substep per 1 ms step suffices: the momentum balance closes on each step's own impulses, so
    substeps (tried: 4) change the ZMP-CoP gap only in the hundredths of a millimetre.
    """
    sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), shapes=shapes, substeps=1)
    sim.q = stand
    feed_forward = static_joint_torques(model, stand, support)
    sim.set_servo(kp=kp, kd=kd, target_q=stand)
    n = round(end_time / DT)
    retarget, sway_start = round(retarget_time / DT), round(sway_time / DT)
    foot_bodies = np.array([f.body for f in feet])
    qs, vs = [sim.q], [sim.v]
    forces, moments, loads, frictions = [], [], [], []
    settled = stand
    for step in range(n):
        if step == retarget:
            settled = sim.q
            feed_forward = static_joint_torques(model, settled, support)
            sim.set_servo(kp=kp, kd=kd, target_q=settled)
        if step >= sway_start:
            target = sway((step - sway_start) * DT) - stand + settled
            target[:7] = settled[:7]  # base coordinates are not servoed; the static torques assume a level torso
            sim.set_servo(kp=kp, kd=kd, target_q=target)
            feed_forward = static_joint_torques(model, target, support)
        sim.step(feed_forward)
        qs.append(sim.q)
        vs.append(sim.v)
        contacts = sim.contacts()
        force, moment = ground_contact_wrench(contacts)
        forces.append(force)
        moments.append(moment)
        # Per-foot resultants (a box sole has several contact points).
        on_foot = contacts["body"][None, :] == foot_bodies[:, None]
        normal = on_foot @ contacts["normal_force"]
        friction = on_foot @ contacts["tangential_force"]
        loads.append(normal)
        frictions.append(np.linalg.norm(friction, axis=1) / np.maximum(normal, 1e-12))
    return Trajectory(model, np.array(qs), np.array(vs), np.array(forces), np.array(moments), np.array(loads), np.array(frictions), sway_start)


def zmp_and_cop(run: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ZMP, CoP, COM) (n - 1, 3) at the states k = 1..n-1.

    Time alignment. The simulation's step j solves the contact impulses at state (q_j, v_j) and updates
    v_{j+1} = v_j + dt (free acceleration + contact impulse / dt), then q_{j+1}; contacts() read after step
    j reports that impulse / dt. So (v_{j+1} - v_j) / dt is exactly the acceleration produced by step j's
    forces, and the central difference a_k = (v_{k+1} - v_{k-1}) / (2 dt) at state k is the mean of the
    accelerations of steps k-1 and k. The consistent CoP at state k is therefore that of the mean ground
    wrench of steps k-1 and k (averaging wrenches, not CoPs, keeps it linear like the momentum rate).
    Pairing a_k with one step's forces alone leaves the solver's step-to-step force ripple unmatched: that
    misses by up to 7.5 mm while the biped lands, against ~0.01 mm with the mean.
    """
    k = np.arange(1, len(run.qs) - 1)
    acceleration = (run.vs[k + 1] - run.vs[k - 1]) / (2.0 * DT)
    dynamic = zmp(run.model, run.qs[k], run.vs[k], acceleration)
    cop = ground_point(0.5 * (run.forces[k - 1] + run.forces[k]), 0.5 * (run.moments[k - 1] + run.moments[k]))
    return dynamic, cop, lk.center_of_mass(run.model, run.qs[k])


def foot_slip_speed(run: Trajectory, feet: list[Foot]) -> np.ndarray:
    """(n + 1, feet) horizontal speed [m/s] of each foot's material point at the ground contact (zero while
    it sticks; a rolling sphere's contact point is momentarily at rest too)."""
    speeds = []
    for foot in feet:
        twist = np.einsum("tij,tj->ti", lk.jacobian(run.model, run.qs, foot.body, foot.point), run.vs)
        velocity = twist[:, :3] + np.cross(twist[:, 3:], [0.0, 0.0, -foot.drop])
        speeds.append(np.linalg.norm(velocity[:, :2], axis=1))
    return np.stack(speeds, axis=1)


def check_zmp_equals_cop(run: Trajectory, feet: list[Foot], min_foot_load: float, settle_time: float) -> dict[str, float]:
    """Assert the target over every state (standing: landing, settling and still; swaying) and
    the premises of the experiment once settled; return the measured figures [m]."""
    dynamic, cop, com = zmp_and_cop(run)
    error = np.linalg.norm((dynamic - cop)[:, :2], axis=1)
    standing, swaying = slice(0, run.sway_start - 1), slice(run.sway_start - 1, None)  # sample i is state i + 1
    settled = round(settle_time / DT)
    # Premises: every foot carries load and sticks (rolling is not slipping: the material point at the
    # contact stays still while the torso moves at ~0.1 m/s), and the sway is dynamic enough that the
    # COM's ground projection (the ZMP with a = 0) misses the CoP by more than the 5 mm target.
    assert run.foot_load[settled:].min() > min_foot_load
    assert run.foot_friction[settled:].max() < 0.5 * FRICTION
    assert foot_slip_speed(run, feet)[settled:].max() < 2e-3
    static_miss = np.linalg.norm((com - cop)[swaying, :2], axis=1).max()
    assert static_miss > ZMP_COP_BOUND
    figures = {"standing": error[standing].max(), "swaying": error[swaying].max(), "static_miss": static_miss}
    assert figures["standing"] <= ZMP_COP_BOUND and figures["swaying"] <= ZMP_COP_BOUND, figures
    return figures


@pytest.mark.slow
def test_quadruped_zmp_equals_simulated_cop_standing_and_swaying():
    robot = build_quadruped()
    model, p = robot.model, robot.parameters
    tip = np.array([0.0, 0.0, -p.shank_length])
    # Ball feet at the foot contact points; no other collider (the torso box would otherwise get one).
    shapes: dict = {name: None for name in model.names}
    placement = np.eye(4)
    placement[:3, 3] = tip
    for leg in LEGS:
        shapes[f"{leg}_shank"] = ("sphere", QUADRUPED_FOOT_RADIUS, placement)
    feet = [Foot(body, point, QUADRUPED_FOOT_RADIUS) for body, point in robot.contacts()]
    leg_height = 0.12

    def pose(shift: np.ndarray) -> np.ndarray:
        """Joint angles that put every foot leg_height below its hip, the torso displaced by `shift`."""
        q = model.neutral()
        for leg in LEGS:
            joints = robot.joint_slice(leg)
            q[joints.start + 1 : joints.stop + 1] = robot.leg_angles(leg, p.hip_position(leg) - [0.0, 0.0, leg_height] - shift)
        return q

    stand = pose(np.zeros(3))
    stand[2] = QUADRUPED_FOOT_RADIUS + leg_height - p.hip_z  # balls just touching the ground
    omega = 2.0 * math.pi * 1.0  # 1 Hz circling sway, 12 mm radius, centre 15 mm back (the head is heavy)

    def sway(t: float) -> np.ndarray:
        ramp = 0.5 * (1.0 - math.cos(math.pi * min(t / 0.5, 1.0)))
        return pose(ramp * np.array([-0.015 + 0.012 * math.sin(omega * t), 0.012 * math.cos(omega * t), 0.0]))

    # Shank inertia about the knee is ~7.5e-5 kg m^2: the explicit servo damping needs kd dt / I < 1.
    kp = np.r_[np.zeros(6), np.full(12, 20.0)]
    kd = np.r_[np.zeros(6), np.full(12, 0.02)]
    run = stand_and_sway(model, shapes, robot.contacts(), feet, stand, sway, kp, kd, retarget_time=0.3, sway_time=0.6, end_time=2.6)
    figures = check_zmp_equals_cop(run, feet, min_foot_load=0.1 * model.total_mass * -model.gravity[2] / 4, settle_time=0.4)
    print(f"quadruped max |ZMP - CoP|: standing {1e3 * figures['standing']:.4f} mm, swaying {1e3 * figures['swaying']:.4f} mm")


@pytest.mark.slow
def test_biped_zmp_equals_simulated_cop_standing_and_swaying():
    robot = build_biped()
    model, p = robot.model, robot.parameters
    # Box soles exactly as the feet's mass boxes (their bottoms are the sole rectangles); nothing else collides.
    sole_size = (p.foot_toe + p.foot_heel, 2.0 * p.foot_half_width, p.ankle_height)
    sole_centre = np.array([0.5 * (p.foot_toe - p.foot_heel), 0.0, -0.5 * p.ankle_height])
    placement = np.eye(4)
    placement[:3, 3] = sole_centre
    shapes: dict = {name: None for name in model.names}
    for side in SIDES:
        shapes[f"{side}_foot"] = ("box", sole_size, placement)
    sole_point = sole_centre - [0.0, 0.0, 0.5 * p.ankle_height]
    feet = [Foot(model.names.index(f"{side}_foot"), sole_point, 0.0) for side in SIDES]
    ankle_depth = 0.80  # ankles this far below the hips: knees slightly bent

    def pose(shift: np.ndarray) -> np.ndarray:
        """Leg angles that put the ankles below the hips with flat soles, the pelvis displaced by `shift`."""
        q = model.neutral()
        for side in SIDES:
            joints = robot.joint_slice(side)
            hip = np.array([0.0, p.hip_y if side == "l" else -p.hip_y, 0.0])
            q[joints.start + 1 : joints.stop + 1] = robot.leg_angles(side, hip - [0.0, 0.0, ankle_depth] - shift)
        return q

    stand = pose(np.zeros(3))
    stand[2] = ankle_depth + p.ankle_height  # soles just touching the ground
    omega = 2.0 * math.pi * 0.4  # 0.4 Hz lateral sway of 15 mm: the ZMP leads the COM by ~1 cm

    def sway(t: float) -> np.ndarray:
        ramp = 0.5 * (1.0 - math.cos(math.pi * min(t / 0.5, 1.0)))
        return pose(np.array([0.0, ramp * 0.015 * math.sin(omega * t), 0.0]))

    # Heavy leg joints get real damping; the ankle joints carry only the 1 kg foot when unloaded, whose
    # ~2e-3 kg m^2 inertia bounds their explicit damping (kd dt / I < 1); arms are held loosely.
    kp, kd = np.zeros(model.nv), np.zeros(model.nv)
    for side in SIDES:
        kp[robot.joint_slice(side)] = 3000.0
        kd[robot.joint_slice(side)] = [50.0, 50.0, 50.0, 50.0, 1.0, 1.0]
        kp[robot.joint_slice(side, "arm")] = 300.0
        kd[robot.joint_slice(side, "arm")] = 5.0

    run = stand_and_sway(model, shapes, robot.contacts(), feet, stand, sway, kp, kd, retarget_time=0.3, sway_time=0.6, end_time=3.1)
    figures = check_zmp_equals_cop(run, feet, min_foot_load=0.1 * model.total_mass * -model.gravity[2] / 2, settle_time=0.4)
    print(f"biped max |ZMP - CoP|: standing {1e3 * figures['standing']:.4f} mm, swaying {1e3 * figures['swaying']:.4f} mm")


def hand_made_contacts() -> dict[str, np.ndarray]:
    """Two ground contacts (one 1 mm below the plane, both with friction) and one body-body contact."""
    return {
        "body": np.array([2, 5, 5]),
        "other": np.array([-1, -1, 3]),
        "point": np.array([[0.1, 0.0, 0.0], [-0.2, 0.1, -0.001], [5.0, 5.0, 5.0]]),
        "normal": np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
        "normal_force": np.array([30.0, 10.0, 1000.0]),
        "tangential_force": np.array([[2.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 7.0, 0.0]]),
        "depth": np.array([0.0, 0.001, 0.0]),
    }


def test_simulated_cop_and_wrench_of_hand_made_contacts():
    # By hand: F = (2, -1, 40); about the origin M = (0, -3, 0) + (0.999, 2, 0.2). CoP: x = (0.1*30 - 0.2*10)/40,
    # y = (0.1*10 - (-0.001)(-1))/40 (the buried contact's friction tilts the moment). The body-body
    # contact is ignored.
    contacts = hand_made_contacts()
    np.testing.assert_allclose(simulated_center_of_pressure(contacts), [0.025, 0.999 / 40, 0.0], rtol=0, atol=1e-15)
    force, moment = ground_contact_wrench(contacts, ground_height=0.05)
    np.testing.assert_allclose(force, [2.0, -1.0, 40.0], rtol=0, atol=1e-13)
    # About (0, 0, 0.05): M - (0, 0, 0.05) x F = (0.999 - 0.05, -1 - 0.1, 0.2).
    np.testing.assert_allclose(moment, [0.949, -1.1, 0.2], rtol=0, atol=1e-13)


@examples(60)
@given(st.integers(1, 8), st.integers(0, 2**32 - 1))
def test_simulated_cop_of_contacts_on_the_plane_is_the_load_weighted_mean(count, seed):
    # Points on z = 0 with vertical normals: friction has no horizontal moment about the plane, so the CoP
    # is the mean of the points weighted by normal force (brute force below), whatever the friction.
    rng = np.random.default_rng(seed)
    points = np.c_[rng.uniform(-1, 1, (count, 2)), np.zeros(count)]
    load = rng.uniform(0.1, 100.0, count)
    contacts = {
        "other": np.full(count, -1),
        "point": points,
        "normal": np.tile([0.0, 0.0, 1.0], (count, 1)),
        "normal_force": load,
        "tangential_force": np.c_[rng.normal(size=(count, 2)) * load[:, None], np.zeros(count)],
    }
    expected_x = sum(w * p[0] for w, p in zip(load, points)) / sum(load)
    expected_y = sum(w * p[1] for w, p in zip(load, points)) / sum(load)
    np.testing.assert_allclose(simulated_center_of_pressure(contacts), [expected_x, expected_y, 0.0], rtol=0, atol=1e-12)


def test_simulated_cop_rejects_bad_contacts():
    contacts = hand_made_contacts()
    del contacts["tangential_force"]
    with pytest.raises(ValueError, match="contacts"):
        simulated_center_of_pressure(contacts)
    contacts = hand_made_contacts()
    contacts["normal_force"] = contacts["normal_force"][:2]
    with pytest.raises(ValueError, match="contacts"):
        ground_contact_wrench(contacts)
    contacts = hand_made_contacts()
    contacts["normal_force"][1] = np.nan
    with pytest.raises(ValueError, match="normal_force"):
        simulated_center_of_pressure(contacts)
    contacts = hand_made_contacts()
    contacts["other"] = np.array([1, 2, 3])
    with pytest.raises(ValueError, match="no ground contact"):
        simulated_center_of_pressure(contacts)
    with pytest.raises(TypeError, match="contacts"):
        simulated_center_of_pressure([1, 2, 3])
