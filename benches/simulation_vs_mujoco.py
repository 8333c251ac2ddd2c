"""Side-by-side step time of lk.Simulation (legkit's tree engine and the Rapier reference) and MuJoCo.

Scenes, each built twice from the same numbers (a `legkit.Model` and an MJCF string):

* ``tree-N``: a SuperBot-like modular tree of N modules (default 21, 51, 101). Modules of four bodies (end
  block, two links, end block) on three revolute joints (pitch, roll about the module's long axis, pitch); a
  vertical root module fixed to the ground and four branches of (N - 1) / 4 modules (the remainder spread
  over the first branches) leaving its top block horizontally, sagging onto a ground plane. Every joint has
  a position servo holding zero (kp, kd, torque limit); self-collision is off and every body (a box)
  collides with the ground.
* ``quadruped-stand`` / ``quadruped-trot``: a 12-DoF floating-base quadruped (torso box; per leg a hip roll,
  a hip pitch and a knee, box links, a sphere foot: the only leg geometry touching the ground) with PD
  position servos on every joint. Standing holds a crouched pose; trotting is an open-loop gait whose joint
  targets vary sinusoidally in time (diagonal legs in phase), at every step in both engines (legkit: the
  block's targets in one ``sim.step(targets=...)`` call; MuJoCo, which has no such entry point: ``data.ctrl``
  and ``mj_step`` per step from Python).
* ``go1-stand`` / ``go1-fall`` / ``anymal-stand`` / ``anymal-fall``: Go1 and ANYmal C from example-robot-data's
  URDFs, loaded by both engines from the same file (a copy whose placeholder inertias are made physical:
  MuJoCo refuses them; MuJoCo also told not to infer masses from geometry), with the URDFs' own collision
  shapes touching the ground (no self-collision). Standing: PD servos hold a crouch. Falling: released
  rolled by 0.7 rad at 0.45 m with limp, damped joints, it tips over onto its side. See the behaviour table
  for the poses each engine ends in: with MuJoCo's default pyramidal cone a diagonal friction force is
  bounded by μ/√2, which standing ANYmal's feet exceed (|f_t|/f_n = 0.58 diagonally), so it sags.
* ``dog-fall``: the dm_control suite's dog (85 DoF, with its ball: two free bodies, each on three slides and a ball
  joint in legkit) from one MJCF file, dropped limp from qpos0 (limited joints at mid-range) onto a plane, where it
  lies on its belly; MuJoCo without what legkit does not model (joint stiffness, springdamper, frictionloss, tendons,
  margins, actuators) and ellipsoid geoms colliding in neither. Rapier is left out (its multibody has no ball joint).

Each engine runs in this one process at dt = 1 ms with its default solver (MuJoCo: Euler for the trees,
``implicitfast`` for the quadruped, whose stiff light-legged servos the explicit damping of Euler would
not hold; legkit integrates servos implicitly). MuJoCo runs twice: with the elliptic friction cone and
impratio 100 (as MuJoCo Menagerie's ANYmal C sets them: the like-for-like row, legkit's friction being
elliptic Coulomb), and with its default pyramidal cone beside it. Each first settles untimed (0.3 s), then
is timed in blocks of 100 steps, legkit's and the two MuJoCo runs' blocks interleaved (one block of each in
turn); the reported step time is the median of the block means, in CPU time of the stepping thread
(`time.thread_time`: every engine steps a single simulation on the calling thread), so that other work on
this shared machine, which takes the core away from one engine's blocks and not another's, does not skew
the ratios. The batch section, which runs on all cores, is timed in wall time. Also reported: contact points
(legkit ``len(sim.contacts()["body"])``, MuJoCo ``data.ncon``; median over the blocks), the real-time
factor dt / step time, and the ratios legkit / MuJoCo and legkit / Rapier (below 1: legkit is faster).
Rapier is slow on large trees (0.2-0.7 s per step at 101 modules): when its settling would take longer than
``--budget`` seconds it starts instead from the state legkit's tree engine settled to (plus a few settling
steps of its own) and uses short blocks; ``--skip-rapier`` leaves it out altogether.

The batch section steps 12 copies of the 21-module tree three ways: a Python loop calling ``sim.step(tau)``
for every simulation every step, a loop of ``sim.step(None, n)`` per simulation, and
``lk.SimulationBatch(sims).step(None, n)`` (all cores, GIL released), and prints simulation-steps per second
and the ratios (MuJoCo stepping 12 ``MjData`` in a loop for reference).

Run: ``python benches/simulation_vs_mujoco.py [--modules 21 51 101] [--seconds 1.0] [--skip-rapier]
[--quick] [--settle 0.3] [--budget 10] [--solver-iterations N] [--no-quadruped] [--no-robots] [--no-dog] [--no-batch]``. ``--seconds`` is the
simulated time timed per engine and scene (1.0: ten blocks of 100 steps); ``--quick`` is a smoke test
(21 modules, five blocks of 50 steps, ~10 s); a full run takes about 3 minutes on 2 cores, most of it
MuJoCo and legkit on the 101-module tree and Rapier within its budget. ``--solver-iterations`` sets the
tree engine's most contact-solver (Newton) iterations per step.
At the default 0.3 s of settling the trees are still sagging and swaying (they come to rest after ~2 s
in every engine); legkit's iterative contact solver stops early once converged, so its tree step time
varies with the motion far more than MuJoCo's (see the block min-max); ``--settle 2`` times the resting
regime instead. Prints Markdown tables (step times, quadruped behaviour, batch throughput) and the load average: other
work on the machine inflates the times, and the batch speed-up needs idle cores.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import legkit as lk

DT = 1e-3
GRAVITY = f"0 0 {-lk.STANDARD_GRAVITY}"  # MJCF <option gravity>: the legkit Models' default
FRICTION = 0.8
SETTLE_SECONDS = 0.3
SOLVER_ITERATIONS: int | None = None  # None: legkit's default; --solver-iterations overrides


# MuJoCo's friction cone for the runner being built: ("elliptic", impratio) or ("pyramidal", 1.0). The
# elliptic cone with impratio 100 is how MuJoCo Menagerie's ANYmal C (anybotics_anymal_c/scene.xml) sets it; the
# pyramid, MuJoCo's default, bounds a diagonal friction force by mu / sqrt(2) only.
MUJOCO_CONE: tuple[str, float] = ("pyramidal", 1.0)
ELLIPTIC_IMPRATIO = 100.0


def set_cone(m) -> None:
    """Applies MUJOCO_CONE to the compiled MjModel `m`."""
    import mujoco

    cone, impratio = MUJOCO_CONE
    m.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC if cone == "elliptic" else mujoco.mjtCone.mjCONE_PYRAMIDAL
    m.opt.impratio = impratio


FRICTION_LAW = "coulomb"  # legkit's tree engine: Coulomb's law (its default), elliptic; --friction-law cone for the relaxation


def solver_options() -> dict:
    options = {"friction_law": FRICTION_LAW}
    return options if SOLVER_ITERATIONS is None else {**options, "solver_iterations": SOLVER_ITERATIONS}


BLOCK_STEPS = 100

# ------------------------------------------------------------------------------------------------------
# The modular tree
# ------------------------------------------------------------------------------------------------------

MODULE_LENGTH = 0.17  # m, end face to end face (SuperBot modules are about 17 cm long)
MODULE_MASS = 0.05  # kg: 10% of a real module's ~0.5 kg, as in the seed experiments
PART_MASS = MODULE_MASS / 4
PART_SIZE = np.array([0.06, 0.06, MODULE_LENGTH / 4])  # each of the 4 bodies, stacked along the module axis
KP, KD, TORQUE_LIMIT = 0.5, 0.002, 0.5  # N m/rad, N m s/rad, N m


@dataclass(frozen=True)
class Part:
    """One body: its parent part (-1: the world), joint axis in the parent frame (None: fixed), and the
    placement of its frame in the parent frame (R, t)."""

    parent: int
    axis: tuple[float, float, float] | None
    rotation: np.ndarray
    translation: np.ndarray


def rotation_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rotation_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def module_tree(n_modules: int) -> list[Part]:
    """Parts of the tree, parent first. Each module runs along its local +z: end block, pitch (y), link,
    roll (z, the long axis), link, pitch (y), end block; part frames sit at each part's lower face.
    The n_modules - 1 branch modules are spread over four branches, the first ones one longer when they
    do not divide evenly (51 modules: branches of 13, 13, 12, 12)."""
    step = np.array([0.0, 0.0, MODULE_LENGTH / 4])
    parts: list[Part] = []

    def add_module(parent: int, rotation: np.ndarray, translation: np.ndarray) -> int:
        parts.append(Part(parent, None, rotation, translation))
        for axis in ((0, 1, 0), (0, 0, 1), (0, 1, 0)):
            parts.append(Part(len(parts) - 1, axis, np.eye(3), step))
        return len(parts) - 1  # the top end block

    top = add_module(-1, np.eye(3), np.array([0.0, 0.0, 0.05]))
    per_branch, extra = divmod(n_modules - 1, 4)
    for branch in range(4):
        # Leave the top block sideways: turn about z to the branch direction, then tip the axis horizontal.
        parent, rotation = top, rotation_z(branch * np.pi / 2) @ rotation_y(np.pi / 2)
        translation = step
        for _ in range(per_branch + (branch < extra)):
            parent = add_module(parent, rotation, translation)
            rotation, translation = np.eye(3), step
    return parts


def legkit_model(parts: list[Part]) -> lk.Model:
    inertia = lk.MassProperties.solid_box(PART_MASS, PART_SIZE, center=[0, 0, PART_SIZE[2] / 2])
    model = lk.Model(floating_base=False, base=None)
    for index, part in enumerate(parts):
        parent = part.parent + 1  # body 0 is the world-fixed base
        placement = (part.rotation, part.translation)
        if part.axis is None:
            model.add_fixed(parent, placement, inertia, f"part{index}")
        else:
            model.add_revolute(parent, part.axis, placement, inertia, f"part{index}")
    return model


def quaternion_wxyz(r: np.ndarray) -> str:
    w = np.sqrt(max(0.0, 1 + np.trace(r))) / 2
    if w > 1e-6:
        q = [w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)]
    else:  # a half turn: axis from the diagonal
        axis = np.sqrt(np.maximum(0.0, (np.diag(r) + 1) / 2))
        q = [0.0, *axis]
    return " ".join(f"{x:.12g}" for x in q)


def vec(x) -> str:
    return " ".join(f"{float(v):.12g}" for v in x)


def mujoco_xml(parts: list[Part]) -> str:
    children: dict[int, list[int]] = {}
    for index, part in enumerate(parts):
        children.setdefault(part.parent, []).append(index)
    half = PART_SIZE / 2
    inertia = PART_MASS / 12 * np.array(
        [PART_SIZE[1] ** 2 + PART_SIZE[2] ** 2, PART_SIZE[0] ** 2 + PART_SIZE[2] ** 2, PART_SIZE[0] ** 2 + PART_SIZE[1] ** 2]
    )

    def body(index: int) -> str:
        part = parts[index]
        joint = "" if part.axis is None else f'<joint name="j{index}" type="hinge" axis="{vec(part.axis)}"/>'
        inner = "".join(body(c) for c in children.get(index, []))
        return (
            f'<body name="b{index}" pos="{vec(part.translation)}" quat="{quaternion_wxyz(part.rotation)}">'
            f"{joint}"
            f'<inertial pos="0 0 {half[2]:.12g}" mass="{PART_MASS}" diaginertia="{vec(inertia)}"/>'
            f'<geom type="box" size="{vec(half)}" pos="0 0 {half[2]:.12g}" contype="1" conaffinity="2" friction="{FRICTION}"/>'
            f"{inner}</body>"
        )

    actuators = "".join(
        f'<position joint="j{i}" kp="{KP}" kv="{KD}" forcerange="{-TORQUE_LIMIT} {TORQUE_LIMIT}" forcelimited="true"/>'
        for i, part in enumerate(parts)
        if part.axis is not None
    )
    return (
        f'<mujoco><option timestep="{DT}" gravity="{GRAVITY}"/>'
        f'<worldbody><geom type="plane" size="5 5 0.1" contype="2" conaffinity="1" friction="{FRICTION}"/>'
        f'{"".join(body(c) for c in children.get(-1, []))}</worldbody>'
        f"<actuator>{actuators}</actuator></mujoco>"
    )


# ------------------------------------------------------------------------------------------------------
# The quadruped
# ------------------------------------------------------------------------------------------------------

LEGS = ("lf", "rf", "lh", "rh")
TORSO_MASS, TORSO_SIZE = 4.0, np.array([0.36, 0.16, 0.08])
HIP_MASS, HIP_SIZE = 0.3, np.array([0.06, 0.05, 0.05])  # the hip-roll body, a small box at the hip point
THIGH_MASS, SHANK_MASS = 0.5, 0.15
LINK_LENGTH, LINK_WIDTH = 0.15, 0.03  # thigh and shank
FOOT_RADIUS = 0.02  # sphere centred at the shank's end
HIP_X, HIP_Y, HIP_Z = 0.15, 0.10, -0.02  # hip points in the torso frame (torso frame at its centre)
STAND_PITCH, STAND_KNEE = 0.6, -1.2  # rad: feet below the hips in x, knees pointing backwards
Q_KP, Q_KD, Q_TORQUE_LIMIT = 60.0, 1.0, 30.0  # N m/rad, N m s/rad, N m
TROT_HZ, TROT_HIP, TROT_KNEE = 2.5, 0.15, 0.3  # gait frequency, hip pitch and knee lift amplitudes (rad)
TROT_PHASE = {"lf": 0.0, "rh": 0.0, "rf": np.pi, "lh": np.pi}
SPLAY = 0.1  # rad of hip roll putting the feet outside the hips (left legs +, right legs -): without it
# the trot tips the robot over sideways within ~2 s in all three engines


def stand_height() -> float:
    """Torso-centre height at the standing pose with the feet on the ground."""
    return -HIP_Z + 2 * LINK_LENGTH * np.cos(STAND_PITCH) * np.cos(SPLAY) + FOOT_RADIUS


def hip_position(leg: str) -> np.ndarray:
    return np.array([HIP_X if leg[1] == "f" else -HIP_X, HIP_Y if leg[0] == "l" else -HIP_Y, HIP_Z])


def quadruped_joint_targets(t: float | np.ndarray, trot: bool) -> np.ndarray:
    """(..., 12) joint targets at time t, leg by leg (hip roll, hip pitch, knee). Positive pitch swings the
    foot backwards; the knee bends further (lifting the foot) while the foot swings forwards."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros(t.shape + (12,))
    for k, leg in enumerate(LEGS):
        out[..., 3 * k] = SPLAY if leg[0] == "l" else -SPLAY
        out[..., 3 * k + 1] = STAND_PITCH
        out[..., 3 * k + 2] = STAND_KNEE
        if trot:
            phase = 2 * np.pi * TROT_HZ * t + TROT_PHASE[leg]
            out[..., 3 * k + 1] += TROT_HIP * np.sin(phase)
            out[..., 3 * k + 2] -= TROT_KNEE * np.maximum(0.0, -np.cos(phase))  # swing: pitch decreasing
    return out


def quadruped_start() -> np.ndarray:
    """legkit q (19,): torso 5 mm above its standing height, upright, joints at the standing pose."""
    return np.concatenate([[0.0, 0.0, stand_height() + 0.005, 0.0, 0.0, 0.0, 1.0], quadruped_joint_targets(0.0, False)])


def link_inertia() -> tuple[lk.MassProperties, lk.MassProperties]:
    size = [LINK_WIDTH, LINK_WIDTH, LINK_LENGTH]
    centre = [0.0, 0.0, -LINK_LENGTH / 2]
    return lk.MassProperties.solid_box(THIGH_MASS, size, center=centre), lk.MassProperties.solid_box(SHANK_MASS, size, center=centre)


def quadruped_legkit() -> tuple[lk.Model, dict]:
    """The model and its `shapes`: the sphere foot replaces the shank's default box; every other body keeps
    its default box (torso, hip block and thigh: the same boxes as the MJCF geoms)."""
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(TORSO_MASS, TORSO_SIZE), base_name="torso")
    thigh, shank = link_inertia()
    foot = np.eye(4)
    foot[2, 3] = -LINK_LENGTH
    shapes: dict = {}
    hip_inertia = lk.MassProperties.solid_box(HIP_MASS, HIP_SIZE)
    for leg in LEGS:
        hip = model.add_revolute("torso", [1.0, 0.0, 0.0], (np.eye(3), hip_position(leg)), hip_inertia, f"{leg}_hip")
        upper = model.add_revolute(hip, [0.0, 1.0, 0.0], None, thigh, f"{leg}_thigh")
        model.add_revolute(upper, [0.0, 1.0, 0.0], (np.eye(3), [0.0, 0.0, -LINK_LENGTH]), shank, f"{leg}_shank")
        shapes[f"{leg}_shank"] = ("sphere", FOOT_RADIUS, foot)
    return model, shapes


def box_diaginertia(mass: float, size) -> np.ndarray:
    s = np.asarray(size, dtype=np.float64) ** 2
    return mass / 12 * np.array([s[1] + s[2], s[0] + s[2], s[0] + s[1]])


def quadruped_xml() -> str:
    collide = f'contype="1" conaffinity="2" friction="{FRICTION}"'
    link_size = np.array([LINK_WIDTH, LINK_WIDTH, LINK_LENGTH])
    legs = []
    for leg in LEGS:
        legs.append(
            f'<body name="{leg}_hip" pos="{vec(hip_position(leg))}"><joint name="{leg}_roll" type="hinge" axis="1 0 0"/>'
            f'<inertial pos="0 0 0" mass="{HIP_MASS}" diaginertia="{vec(box_diaginertia(HIP_MASS, HIP_SIZE))}"/>'
            f'<geom type="box" size="{vec(HIP_SIZE / 2)}" {collide}/>'
            f'<body name="{leg}_thigh"><joint name="{leg}_pitch" type="hinge" axis="0 1 0"/>'
            f'<inertial pos="0 0 {-LINK_LENGTH / 2}" mass="{THIGH_MASS}" diaginertia="{vec(box_diaginertia(THIGH_MASS, link_size))}"/>'
            f'<geom type="box" size="{vec(link_size / 2)}" pos="0 0 {-LINK_LENGTH / 2}" {collide}/>'
            f'<body name="{leg}_shank" pos="0 0 {-LINK_LENGTH}"><joint name="{leg}_knee" type="hinge" axis="0 1 0"/>'
            f'<inertial pos="0 0 {-LINK_LENGTH / 2}" mass="{SHANK_MASS}" diaginertia="{vec(box_diaginertia(SHANK_MASS, link_size))}"/>'
            f'<geom type="box" size="{vec(link_size / 2)}" pos="0 0 {-LINK_LENGTH / 2}" contype="0" conaffinity="0"/>'
            f'<geom name="{leg}_foot" type="sphere" size="{FOOT_RADIUS}" pos="0 0 {-LINK_LENGTH}" {collide}/>'
            f"</body></body></body>"
        )
    actuators = "".join(
        f'<position joint="{leg}_{j}" kp="{Q_KP}" kv="{Q_KD}" forcerange="{-Q_TORQUE_LIMIT} {Q_TORQUE_LIMIT}" forcelimited="true"/>'
        for leg in LEGS
        for j in ("roll", "pitch", "knee")
    )
    return (
        f'<mujoco><option timestep="{DT}" gravity="{GRAVITY}" integrator="implicitfast"/>'
        f'<worldbody><geom type="plane" size="5 5 0.1" contype="2" conaffinity="1" friction="{FRICTION}"/>'
        f'<body name="torso" pos="0 0 {stand_height() + 0.005}"><freejoint/>'
        f'<inertial pos="0 0 0" mass="{TORSO_MASS}" diaginertia="{vec(box_diaginertia(TORSO_MASS, TORSO_SIZE))}"/>'
        f'<geom type="box" size="{vec(TORSO_SIZE / 2)}" {collide}/>'
        f'{"".join(legs)}</body></worldbody>'
        f"<actuator>{actuators}</actuator></mujoco>"
    )


# ------------------------------------------------------------------------------------------------------
# Runners: one simulation of one scene in one engine, advanced a number of steps with its controller
# ------------------------------------------------------------------------------------------------------


@dataclass
class Runner:
    advance: Callable[[int], None]
    contacts: Callable[[], int]
    base: Callable[[], np.ndarray] | None = None  # quadrupeds: [x, y, z, up_z] of the torso
    state: Callable[[], tuple[np.ndarray, np.ndarray, int]] | None = None  # legkit: (q, v, steps done)
    restore: Callable[[np.ndarray, np.ndarray, int], None] | None = None
    # The transition Jacobians of one step at the current state (legkit's tree engine: `transition_jacobians`;
    # MuJoCo: `mjd_transitionFD`, forward differences), returning (A, B): benches/transition_vs_mujoco.py.
    jacobians: Callable[[], tuple[np.ndarray, np.ndarray]] | None = None
    simulation: lk.Simulation | None = None  # legkit's
    model_data: tuple | None = None  # MuJoCo's (MjModel, MjData), for benches/transition_vs_mujoco.py's rollouts


@dataclass
class Scene:
    name: str
    dof: int
    legkit: Callable[[str], Runner]  # backend -> runner
    mujoco: Callable[[], Runner]
    rapier: bool = True  # False: a model Rapier's multibody refuses (ball joints)


def stepping_runner(sim: lk.Simulation, **extra) -> Runner:
    """A runner stepping `sim` with no torques (its servos as set), restorable to a state."""
    done = [0]

    def advance(n: int) -> None:
        sim.step(None, n)
        done[0] += n

    def restore(q: np.ndarray, v: np.ndarray, steps: int) -> None:
        sim.reset(q, v)
        done[0] = steps

    return Runner(advance, lambda: len(sim.contacts()["body"]), state=lambda: (sim.q, sim.v, done[0]), restore=restore, **extra)


def tree_scene(n_modules: int) -> Scene:
    parts = module_tree(n_modules)
    dof = sum(p.axis is not None for p in parts)
    modules = (len(parts)) // 4

    def legkit_runner(backend: str) -> Runner:
        model = legkit_model(parts)
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), backend=backend, **solver_options())
        sim.set_servo(kp=KP, kd=KD, torque_limit=TORQUE_LIMIT, target_q=model.neutral())
        return stepping_runner(sim, jacobians=sim.transition_jacobians, simulation=sim)

    def mujoco_runner() -> Runner:
        import mujoco

        m = mujoco.MjModel.from_xml_string(mujoco_xml(parts))
        set_cone(m)
        d = mujoco.MjData(m)
        return Runner(lambda n: mujoco.mj_step(m, d, nstep=n), lambda: int(d.ncon), jacobians=mujoco_jacobians(m, d), model_data=(m, d))

    return Scene(f"tree-{modules}", dof, legkit_runner, mujoco_runner)


def quadruped_scene(trot: bool) -> Scene:
    # Targets at every step of one gait period (the gait is periodic in steps: 1 / (TROT_HZ DT) steps).
    period = int(round(1.0 / (TROT_HZ * DT)))
    targets = quadruped_joint_targets(np.arange(period) * DT, trot)

    def legkit_runner(backend: str) -> Runner:
        model, shapes = quadruped_legkit()
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), shapes=shapes, backend=backend,
                            **solver_options())
        start = quadruped_start()
        sim.reset(start, np.zeros(model.nv))
        sim.set_servo(kp=Q_KP, kd=Q_KD, torque_limit=Q_TORQUE_LIMIT, target_q=start)
        done = [0]

        def advance(n: int) -> None:
            if not trot:
                sim.step(None, n)
                done[0] += n
                return
            # The n steps' targets in one call (per velocity coordinate: the base's six unused).
            rows = np.zeros((n, model.nv))
            rows[:, 6:] = targets[(done[0] + np.arange(n)) % period]
            sim.step(targets=rows)
            done[0] += n

        def base() -> np.ndarray:
            q = sim.q
            x, y, _, _ = q[3:7]
            return np.array([q[0], q[1], q[2], 1 - 2 * (x * x + y * y)])

        def restore(q: np.ndarray, v: np.ndarray, steps: int) -> None:
            sim.reset(q, v)
            done[0] = steps

        return Runner(advance, lambda: len(sim.contacts()["body"]), base, lambda: (sim.q, sim.v, done[0]), restore, simulation=sim)

    def mujoco_runner() -> Runner:
        import mujoco

        m = mujoco.MjModel.from_xml_string(quadruped_xml())
        set_cone(m)
        d = mujoco.MjData(m)
        d.qpos[7:] = quadruped_joint_targets(0.0, False)
        d.ctrl[:] = quadruped_joint_targets(0.0, False)
        mujoco.mj_forward(m, d)
        done = [0]

        def advance(n: int) -> None:
            if not trot:
                mujoco.mj_step(m, d, nstep=n)
                done[0] += n
                return
            for _ in range(n):
                d.ctrl[:] = targets[done[0] % period]
                mujoco.mj_step(m, d)
                done[0] += 1

        def base() -> np.ndarray:
            w, x, y, _ = d.qpos[3:7]
            return np.array([d.qpos[0], d.qpos[1], d.qpos[2], 1 - 2 * (x * x + y * y)])

        return Runner(advance, lambda: int(d.ncon), base)

    return Scene("quadruped-trot" if trot else "quadruped-stand", 12, legkit_runner, mujoco_runner)


# ------------------------------------------------------------------------------------------------------
# Real robots from example-robot-data's URDFs
# ------------------------------------------------------------------------------------------------------

# URDF file (under example-robot-data's robots folder), a crouch (joint-name suffix -> angle for front and
# hind legs), and the base height (m) that puts the crouched robot's lowest point 1 mm above the ground.
ROBOTS = {
    "go1": ("go1_description/urdf/go1.urdf", {"_thigh_joint": (0.9, 0.9), "_calf_joint": (-1.8, -1.8)}, 0.286),
    "anymal": ("anymal_c_simple_description/urdf/anymal.urdf", {"_HFE": (0.5, -0.5), "_KFE": (-1.0, 1.0)}, 0.516),
}
ROBOT_KP, ROBOT_KD = 60.0, 2.0  # N m/rad, N m s/rad: the servos holding the crouch
FALL_KD = 0.5  # N m s/rad: limp joints while falling over
FALL_ROLL, FALL_HEIGHT = 0.7, 0.45  # rad, m: released rolled, so it tips onto its side


def physical_urdf(path: Path) -> Path:
    """A copy of the URDF whose inertias are physical (eigenvalues floored at 1e-3 of the largest and 1e-8,
    the triangle inequality enforced): MuJoCo refuses the round-off and placeholder inertias these files
    carry (legkit loads them with a warning), so both engines load this copy."""
    tree = ET.parse(path)
    names = ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]
    entries = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    for inertia in tree.iter("inertia"):
        matrix = np.zeros((3, 3))
        for name, (r, c) in zip(names, entries):
            matrix[r, c] = matrix[c, r] = float(inertia.get(name, "0"))
        w, axes = np.linalg.eigh(matrix)
        w = np.maximum(w, max(1e-3 * w.max(), 1e-8))
        w = np.minimum(w, w.sum() - w)  # each moment at most the sum of the other two
        fixed = axes @ np.diag(w) @ axes.T
        for name, (r, c) in zip(names, entries):
            inertia.set(name, repr(float(fixed[r, c])))
    out = Path(tempfile.mkdtemp(prefix="legkit-bench-")) / path.name
    tree.write(out)
    return out


def robot_scene(robot: str, fall: bool) -> Scene:
    """Go1 or ANYmal C from its URDF on a plane: ``stand`` holds a crouch on servos; ``fall`` releases it
    rolled, joints limp (damped only), so it tips over onto its side (trunk, hips and legs on the ground)."""
    import warnings
    from importlib.metadata import distribution

    robots = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
    relative, crouch, stand_height = ROBOTS[robot]
    urdf = physical_urdf(robots / relative)
    child_of = {j.get("name"): j.find("child").get("link") for j in ET.parse(urdf).getroot().findall("joint")
                if j.get("type") in ("revolute", "continuous")}
    # Front legs (FL, FR, LF, RF) take the first angle, hind legs the second.
    angles = {name: pair[0 if "F" in name[:2] else 1] for name in child_of for suffix, pair in crouch.items() if name.endswith(suffix)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)
        model = lk.Model.from_urdf(urdf, floating_base=True)
    start = model.neutral()
    for joint, angle in angles.items():
        start[model.idx_q[model.names.index(child_of[joint])]] = angle
    roll = FALL_ROLL if fall else 0.0
    start[2] = FALL_HEIGHT if fall else stand_height
    start[3:7] = [np.sin(roll / 2), 0.0, 0.0, np.cos(roll / 2)]
    kp, kd = (0.0, FALL_KD) if fall else (ROBOT_KP, ROBOT_KD)

    def legkit_runner(backend: str) -> Runner:
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), backend=backend, **solver_options())
        sim.reset(start, np.zeros(model.nv))
        gains = np.r_[np.zeros(6), np.ones(model.nv - 6)]
        sim.set_servo(kp=kp * gains, kd=kd * gains, target_q=start)

        def base() -> np.ndarray:
            x, y = sim.q[3:5]
            return np.array([*sim.q[:3], 1 - 2 * (x * x + y * y)])

        return stepping_runner(sim, base=base, jacobians=sim.transition_jacobians, simulation=sim)

    def mujoco_runner() -> Runner:
        import mujoco

        spec = mujoco.MjSpec.from_file(str(urdf))
        spec.compiler.discardvisual = True
        spec.compiler.balanceinertia = True
        # Links without <inertial> are massless, as in legkit and Pinocchio.
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
        spec.option.timestep = DT
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.worldbody.first_body().add_freejoint()
        for geom in spec.geoms:  # robot-ground contacts only, as legkit's default (self_collision=False)
            if geom.contype or geom.conaffinity:  # URDF <visual>s come as contype = conaffinity = 0
                geom.contype, geom.conaffinity, geom.friction[0] = 1, 0, FRICTION
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1], contype=0, conaffinity=1,
                                friction=[FRICTION, 0.005, 0.0001])
        for joint in spec.joints:
            if joint.type == mujoco.mjtJoint.mjJNT_HINGE:
                if fall:
                    joint.damping = [kd, 0.0, 0.0]  # MuJoCo 4: linear, quadratic, cubic coefficients
                else:
                    spec.add_actuator(target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT).set_to_position(kp=kp, kv=kd)
        m = spec.compile()
        set_cone(m)
        d = mujoco.MjData(m)
        for joint, angle in angles.items():
            d.qpos[m.jnt_qposadr[m.joint(joint).id]] = angle
        for index in range(m.nu):
            d.ctrl[index] = angles.get(m.joint(m.actuator_trnid[index, 0]).name, 0.0)
        d.qpos[:3] = start[:3]
        d.qpos[3:7] = [start[6], *start[3:6]]
        mujoco.mj_forward(m, d)

        def base() -> np.ndarray:
            _, x, y, _ = d.qpos[3:7]
            return np.array([*d.qpos[:3], 1 - 2 * (x * x + y * y)])

        return Runner(lambda n: mujoco.mj_step(m, d, nstep=n), lambda: int(d.ncon), base, jacobians=mujoco_jacobians(m, d), model_data=(m, d))

    return Scene(f"{robot}-{'fall' if fall else 'stand'}", model.nv - 6, legkit_runner, mujoco_runner)


def dog_scene() -> Scene:
    """The dm_control suite's dog and its ball (two free bodies: in legkit each on three slides and a ball joint) from
    one file, dropped limp from qpos0 with its limited joints at mid-range: it falls and lies on its belly. MuJoCo
    without what legkit does not model (joint stiffness and springdamper, frictionloss, tendons, contact margins,
    actuators) and with the ellipsoid geoms, which have no collision shape in legkit, colliding in neither."""
    import warnings

    import mujoco

    spec = importlib.util.find_spec("dm_control")
    assert spec is not None and spec.origin is not None, "the dog scene needs dm_control"
    path = os.path.join(os.path.dirname(spec.origin), "suite", "dog.xml")

    def compiled():
        spec = mujoco.MjSpec.from_file(path)
        for joint in spec.joints:
            joint.springdamper = [0.0, 0.0]
        m = spec.compile()
        m.opt.timestep = DT
        m.jnt_stiffness[:], m.dof_frictionloss[:], m.geom_margin[:] = 0.0, 0.0, 0.0
        m.tendon_stiffness[:], m.tendon_damping[:], m.tendon_limited[:] = 0.0, 0.0, 0
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
        ellipsoid = m.geom_type == mujoco.mjtGeom.mjGEOM_ELLIPSOID
        m.geom_contype[ellipsoid], m.geom_conaffinity[ellipsoid] = 0, 0
        m.geom_friction[:, 0] = FRICTION
        d = mujoco.MjData(m)
        for j in range(m.njnt):
            if m.jnt_limited[j] and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
                d.qpos[m.jnt_qposadr[j]] = m.jnt_range[j].mean()
        return m, d

    m, d = compiled()
    # legkit's q is MuJoCo's qpos with each free joint's quaternion w last.
    start = d.qpos.copy()
    for j in np.flatnonzero(m.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
        a = m.jnt_qposadr[j] + 3
        start[a : a + 4] = [*d.qpos[a + 1 : a + 4], d.qpos[a]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)
        model = lk.Model.from_mjcf(path)
    assert model.nq == m.nq and model.nv == m.nv

    def legkit_runner(backend: str) -> Runner:
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), backend=backend, **solver_options())
        sim.reset(start, np.zeros(model.nv))
        return stepping_runner(sim, simulation=sim)

    def mujoco_runner() -> Runner:
        m, d = compiled()
        set_cone(m)
        mujoco.mj_forward(m, d)
        return Runner(lambda n: mujoco.mj_step(m, d, nstep=n), lambda: int(d.ncon))

    return Scene("dog-fall", model.nv, legkit_runner, mujoco_runner, rapier=False)


def mujoco_jacobians(m, d) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
    """MuJoCo's `mjd_transitionFD` at the current state: forward differences (its default) with eps = 1e-6."""
    import mujoco

    a = np.zeros((2 * m.nv + m.na, 2 * m.nv + m.na))
    b = np.zeros((2 * m.nv + m.na, m.nu))

    def jacobians() -> tuple[np.ndarray, np.ndarray]:
        mujoco.mjd_transitionFD(m, d, 1e-6, False, a, b, None, None)
        return a, b

    return jacobians


# ------------------------------------------------------------------------------------------------------
# Measurement
# ------------------------------------------------------------------------------------------------------


@dataclass
class Result:
    step_s: float  # median over blocks of the mean step time
    spread: tuple[float, float]  # min and max block means
    contacts: int  # median over blocks
    blocks: int
    block_steps: int
    settle_steps: int
    handoff: bool = False  # started from legkit's settled state
    base: np.ndarray | None = None
    base_start: np.ndarray | None = None
    error: str | None = None


def measure(runner: Runner, settle_steps: int, blocks: int, block_steps: int, budget: float,
            handoff: tuple[np.ndarray, np.ndarray, int] | None = None) -> Result:
    """Settle, then time `blocks` blocks of `block_steps`. When a 10-step probe says settling or timing would
    take longer than `budget` seconds, shorten both (settling from `handoff` if given)."""
    used_handoff = False
    try:
        start = time.perf_counter()
        runner.advance(10)
        probe = (time.perf_counter() - start) / 10
        if probe * settle_steps > budget:
            if handoff is not None and runner.restore is not None:
                runner.restore(*handoff)
                used_handoff = True
            settle_steps = max(10, int(budget / probe))
        else:
            settle_steps = max(0, settle_steps - 10)
        if probe * blocks * block_steps > budget:
            block_steps = max(5, int(budget / (probe * blocks)))
        runner.advance(settle_steps)
        base_start = runner.base() if runner.base else None
        means, contacts = [], []
        for _ in range(blocks):
            start = time.thread_time()
            runner.advance(block_steps)
            means.append((time.thread_time() - start) / block_steps)
            contacts.append(runner.contacts())
        return Result(statistics.median(means), (min(means), max(means)), int(statistics.median(contacts)), blocks,
                      block_steps, settle_steps + (0 if used_handoff else 10), used_handoff,
                      runner.base() if runner.base else None, base_start)
    except Exception as error:  # noqa: BLE001 - reported in the table, the other engines still run
        return Result(float("nan"), (float("nan"),) * 2, -1, 0, 0, settle_steps, used_handoff, error=f"{type(error).__name__}: {error}")


def measure_interleaved(runners: dict[str, Runner], settle_steps: int, blocks: int, block_steps: int) -> dict[str, Result]:
    """Settle each runner, then time `blocks` blocks of `block_steps` per runner, the runners' blocks taken in
    turn (engine A's first block, B's first, ..., A's second, ...), so that a change in the machine's load
    falls on every engine alike."""
    errors: dict[str, str] = {}
    bases: dict[str, np.ndarray | None] = {}
    for name, runner in runners.items():
        try:
            runner.advance(settle_steps)
            bases[name] = runner.base() if runner.base else None
        except Exception as error:  # noqa: BLE001 - reported in the table, the other engines still run
            errors[name] = f"{type(error).__name__}: {error}"
    means: dict[str, list[float]] = {name: [] for name in runners}
    contacts: dict[str, list[int]] = {name: [] for name in runners}
    for _ in range(blocks):
        for name, runner in runners.items():
            if name in errors:
                continue
            try:
                start = time.thread_time()
                runner.advance(block_steps)
                means[name].append((time.thread_time() - start) / block_steps)
                contacts[name].append(runner.contacts())
            except Exception as error:  # noqa: BLE001
                errors[name] = f"{type(error).__name__}: {error}"
    out = {}
    for name, runner in runners.items():
        if name in errors:
            out[name] = Result(float("nan"), (float("nan"),) * 2, -1, 0, 0, settle_steps, error=errors[name])
            continue
        out[name] = Result(statistics.median(means[name]), (min(means[name]), max(means[name])), int(statistics.median(contacts[name])),
                           blocks, block_steps, settle_steps, False, runner.base() if runner.base else None, bases[name])
    return out


def run_scene(scene: Scene, args: argparse.Namespace) -> dict[str, Result | None]:
    global MUJOCO_CONE
    settle = int(round(args.settle / DT))
    blocks = max(1, int(round(args.seconds / (args.block_steps * DT))))
    ours = scene.legkit("tree")
    runners = {"legkit": ours}
    try:
        import mujoco  # noqa: F401

        for name, cone in (("MuJoCo elliptic", ("elliptic", ELLIPTIC_IMPRATIO)), ("MuJoCo pyramid", ("pyramidal", 1.0))):
            MUJOCO_CONE = cone
            runners[name] = scene.mujoco()
        MUJOCO_CONE = ("pyramidal", 1.0)
    except ImportError:
        pass
    out: dict[str, Result | None] = {"MuJoCo elliptic": None, "MuJoCo pyramid": None}
    out.update(measure_interleaved(runners, settle, blocks, args.block_steps))
    handoff = ours.state() if ours.state and out["legkit"].error is None else None
    if args.skip_rapier or not scene.rapier:
        out["Rapier"] = None
    else:
        out["Rapier"] = measure(scene.legkit("rapier"), settle, blocks, args.block_steps, args.budget, handoff)
    return out


def fmt_us(r: Result | None) -> str:
    if r is None:
        return "–"
    if r.error:
        return "error"
    return f"{r.step_s * 1e6:.1f}" if r.step_s < 1e-2 else f"{r.step_s * 1e6:.0f}"


def fmt_rtf(r: Result | None) -> str:
    if r is None or r.error:
        return "–"
    x = DT / r.step_s
    return f"{x:.1f}" if x >= 1 else f"{x:.3f}"


def fmt_ratio(a: Result | None, b: Result | None) -> str:
    if a is None or b is None or a.error or b.error:
        return "–"
    return f"{a.step_s / b.step_s:.2f}"


def print_scene_table(rows: list[tuple[Scene, dict[str, Result | None]]]) -> None:
    print("| scene | DoF | legkit µs/step | MuJoCo elliptic µs/step | MuJoCo pyramid µs/step | Rapier µs/step "
          "| legkit × real time | contacts legkit / MuJoCo ell. / pyr. / Rapier | legkit / MuJoCo elliptic "
          "| legkit / MuJoCo pyramid | legkit / Rapier |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | :---: | ---: | ---: | ---: |")
    for scene, r in rows:
        engines = ("legkit", "MuJoCo elliptic", "MuJoCo pyramid", "Rapier")
        contacts = " / ".join("–" if r[e] is None or r[e].error else str(r[e].contacts) for e in engines)
        rapier = fmt_us(r["Rapier"]) + ("*" if r["Rapier"] is not None and r["Rapier"].handoff else "")
        print(f"| {scene.name} | {scene.dof} | {fmt_us(r['legkit'])} | {fmt_us(r['MuJoCo elliptic'])} | {fmt_us(r['MuJoCo pyramid'])} "
              f"| {rapier} | {fmt_rtf(r['legkit'])} | {contacts} | {fmt_ratio(r['legkit'], r['MuJoCo elliptic'])} "
              f"| {fmt_ratio(r['legkit'], r['MuJoCo pyramid'])} | {fmt_ratio(r['legkit'], r['Rapier'])} |")


def print_details(rows: list[tuple[Scene, dict[str, Result | None]]]) -> None:
    print("\nMeasurement details (blocks x steps timed after settling; min-max of the block means; * = Rapier "
          "started from legkit's settled state):")
    for scene, r in rows:
        for engine, res in r.items():
            if res is None:
                continue
            if res.error:
                print(f"  {scene.name:16} {engine:15} ERROR {res.error}")
                continue
            print(f"  {scene.name:16} {engine:15} settle {res.settle_steps:4d}{'*' if res.handoff else ' '} steps, "
                  f"{res.blocks:2d} x {res.block_steps:3d} steps, block means {res.spread[0] * 1e6:.1f}-{res.spread[1] * 1e6:.1f} µs")


def print_quadruped_table(rows: list[tuple[Scene, dict[str, Result | None]]]) -> None:
    quads = [(s, r) for s, r in rows if s.name.startswith(("quadruped", *ROBOTS))]
    if not quads:
        return
    print("\nQuadruped behaviour over the timed steps (torso: start -> end; up = world z of the torso's z axis; "
          f"the synthetic quadruped's standing height {stand_height():.3f} m):\n")
    print("| scene | engine | torso z (m) | up | distance travelled (m) | timed steps |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for scene, r in quads:
        for engine, res in r.items():
            if res is None or res.error or res.base is None:
                continue
            b0, b1 = res.base_start, res.base
            print(f"| {scene.name} | {engine} | {b0[2]:.3f} -> {b1[2]:.3f} | {b1[3]:.3f} | {np.hypot(*(b1[:2] - b0[:2])):.3f} "
                  f"(dx {b1[0] - b0[0]:+.3f}) | {res.blocks * res.block_steps} |")


# ------------------------------------------------------------------------------------------------------
# Batch throughput
# ------------------------------------------------------------------------------------------------------


def batch_section(n_sims: int, modules: int, steps: int, repeats: int, settle: int) -> None:
    parts = module_tree(modules)
    model = legkit_model(parts)
    rng = np.random.default_rng(0)
    sims = []
    for _ in range(n_sims):
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), **solver_options())
        q = model.neutral() + rng.normal(0.0, 0.02, model.nq)  # not identical copies
        sim.reset(q, np.zeros(model.nv))
        sim.set_servo(kp=KP, kd=KD, torque_limit=TORQUE_LIMIT, target_q=model.neutral())
        sims.append(sim)
    batch = lk.SimulationBatch(sims)
    batch.step(None, settle)
    tau = np.zeros(model.nv)

    def per_step_loop() -> None:
        for _ in range(steps):
            for sim in sims:
                sim.step(tau)

    def per_sim_loop() -> None:
        for sim in sims:
            sim.step(None, steps)

    def batched() -> None:
        batch.step(None, steps)

    ways: list[tuple[str, Callable[[], None]]] = [
        ("Python loop, sim.step(tau) per sim per step", per_step_loop),
        ("Python loop, sim.step(None, n) per sim", per_sim_loop),
        ("SimulationBatch(sims).step(None, n)", batched),
    ]
    try:
        import mujoco

        m = mujoco.MjModel.from_xml_string(mujoco_xml(parts))
        datas = [mujoco.MjData(m) for _ in range(n_sims)]
        for d in datas:
            mujoco.mj_step(m, d, nstep=settle)

        def mujoco_loop() -> None:
            for d in datas:
                mujoco.mj_step(m, d, nstep=steps)

        ways.append(("MuJoCo (reference): mj_step(m, d, nstep=n) per MjData", mujoco_loop))
    except ImportError:
        pass

    times: list[list[float]] = [[] for _ in ways]
    for _ in range(repeats):  # interleaved, so slow drifts of the state or of the machine hit every way alike
        for k, (_, fn) in enumerate(ways):
            start = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - start)
    results = [(name, statistics.median(t)) for (name, _), t in zip(ways, times)]
    base = results[0][1]
    print(f"\nBatch throughput: {n_sims} simulations of the {len(parts) // 4}-module tree ({model.nv} DoF), {steps} steps "
          f"per call, median of {repeats} repeats, after {settle} settling steps:\n")
    print("| how | sim-steps / s | µs per sim-step | vs per-step loop |")
    print("| --- | ---: | ---: | ---: |")
    for name, t in results:
        rate = n_sims * steps / t
        print(f"| {name} | {rate:,.0f} | {t / (n_sims * steps) * 1e6:.1f} | {base / t:.2f}x |")
    print(f"\nSimulationBatch / per-simulation loop throughput: {results[1][1] / results[2][1]:.2f}x; "
          f"SimulationBatch / per-step loop: {results[0][1] / results[2][1]:.2f}x")


# ------------------------------------------------------------------------------------------------------


def extension_time() -> str:
    """Modification time of the compiled extension (which build was measured)."""
    try:
        return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(os.path.getmtime(lk._core.__file__)))
    except (AttributeError, OSError):
        return "?"


EXTENSION_BUILT = extension_time()  # at import: the build this process loaded


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def mujoco_version() -> str:
    try:
        import mujoco

        return mujoco.__version__
    except ImportError:
        return "(not installed)"


def main(argv: list[str] | None = None) -> int:
    global SOLVER_ITERATIONS, FRICTION_LAW
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modules", type=int, nargs="+", default=None, help="modules per tree (default 21 51 101)")
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time timed per engine and scene (blocks of 100 steps)")
    parser.add_argument("--skip-rapier", action="store_true", help="leave the Rapier backend out")
    parser.add_argument("--quick", action="store_true", help="smoke test: 21 modules, 5 blocks of 50 steps, short batch")
    parser.add_argument("--no-quadruped", action="store_true", help="trees only")
    parser.add_argument("--no-robots", action="store_true", help="leave out Go1 and ANYmal from their URDFs")
    parser.add_argument("--no-dog", action="store_true", help="leave out the dm_control suite's dog (ball joints)")
    parser.add_argument("--no-batch", action="store_true", help="skip the batch throughput section")
    parser.add_argument("--budget", type=float, default=10.0, help="wall seconds Rapier may spend settling, and timing, per scene")
    parser.add_argument("--settle", type=float, default=SETTLE_SECONDS,
                        help="untimed simulated seconds before timing (0.3: the trees are still sagging and swaying; "
                             "about 2 s brings them to rest)")
    parser.add_argument("--solver-iterations", type=int, default=SOLVER_ITERATIONS,
                        help="legkit tree engine's most contact-solver iterations per step (default: legkit's)")
    parser.add_argument("--friction-law", choices=("coulomb", "cone"), default=FRICTION_LAW,
                        help="legkit tree engine's friction law (default coulomb: the like-for-like row with MuJoCo's elliptic cone)")
    args = parser.parse_args(argv)
    SOLVER_ITERATIONS = args.solver_iterations
    FRICTION_LAW = args.friction_law
    args.block_steps = BLOCK_STEPS
    if args.quick:
        args.modules = args.modules or [21]
        args.seconds, args.block_steps, args.budget = 0.25, 50, min(args.budget, 3.0)
    args.modules = args.modules or [21, 51, 101]

    scenes = [tree_scene(n) for n in args.modules]
    if not args.no_quadruped:
        scenes += [quadruped_scene(False), quadruped_scene(True)]
    if not args.no_robots:
        scenes += [robot_scene(robot, fall) for robot in ROBOTS for fall in (False, True)]
    if not args.no_dog and importlib.util.find_spec("dm_control") is not None:
        scenes.append(dog_scene())
    rows = []
    wall = time.perf_counter()
    load_start = load_average()
    for scene in scenes:
        print(f"... {scene.name}", flush=True)
        rows.append((scene, run_scene(scene, args)))
    print(f"\nStep time at dt = {DT * 1e3:g} ms, median of block means ({'quick' if args.quick else 'full'} run), "
          f"legkit's tree engine (friction_law={FRICTION_LAW}, solver_iterations={SOLVER_ITERATIONS or 'default'}) "
          f"vs MuJoCo {mujoco_version()} and Rapier "
          f"(backend=\"rapier\"); legkit extension built {EXTENSION_BUILT}:\n")
    print_scene_table(rows)
    print_details(rows)
    print_quadruped_table(rows)
    if not args.no_batch:
        if args.quick:
            batch_section(12, 21, steps=50, repeats=3, settle=300)
        else:
            batch_section(12, 21, steps=100, repeats=5, settle=300)
    print(f"\ntotal wall time {time.perf_counter() - wall:.0f} s; load average at the start {load_start}, at the end "
          f"{load_average()} on {os.cpu_count()} cores (other work on the machine inflates the times, the batch's most)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
