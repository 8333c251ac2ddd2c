"""The synthetic scenes of benches/simulation_vs_mujoco.py (see its docstring): the SuperBot-like modular tree and
the 12-DoF quadruped, each built twice from the same numbers (a `legkit.Model` and an MJCF string), the `Runner` and
`Scene` every scene returns, and the engine settings shared by all scenes (the benches set them before building).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

import legkit as lk

DT = 1e-3
GRAVITY = f"0 0 {-lk.STANDARD_GRAVITY}"  # MJCF <option gravity>: the legkit Models' default
FRICTION = 0.8
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
    """The tree engine's options for every scene's `lk.Simulation`. Scenes call it as `simulation_scenes.solver_options`
    when built, so the settings above and benches/transition_vs_mujoco.py's substeps (it replaces this function) apply."""
    options = {"friction_law": FRICTION_LAW}
    return options if SOLVER_ITERATIONS is None else {**options, "solver_iterations": SOLVER_ITERATIONS}


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
    inertia = (
        PART_MASS
        / 12
        * np.array([PART_SIZE[1] ** 2 + PART_SIZE[2] ** 2, PART_SIZE[0] ** 2 + PART_SIZE[2] ** 2, PART_SIZE[0] ** 2 + PART_SIZE[1] ** 2])
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
        f"{''.join(body(c) for c in children.get(-1, []))}</worldbody>"
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
        f"{''.join(legs)}</body></worldbody>"
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
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), shapes=shapes, backend=backend, **solver_options())
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

        return Runner(advance, lambda: len(sim.contacts()["body"]), base, lambda: (sim.q, sim.v, done[0]), restore,
                      jacobians=sim.transition_jacobians, simulation=sim)

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

        return Runner(advance, lambda: int(d.ncon), base, jacobians=mujoco_jacobians(m, d), model_data=(m, d))

    return Scene("quadruped-trot" if trot else "quadruped-stand", 12, legkit_runner, mujoco_runner)


def mujoco_jacobians(m, d) -> Callable[[], tuple[np.ndarray, np.ndarray]]:
    """MuJoCo's `mjd_transitionFD` at the current state: forward differences (its default) with eps = 1e-6."""
    import mujoco

    a = np.zeros((2 * m.nv + m.na, 2 * m.nv + m.na))
    b = np.zeros((2 * m.nv + m.na, m.nu))

    def jacobians() -> tuple[np.ndarray, np.ndarray]:
        mujoco.mjd_transitionFD(m, d, 1e-6, False, a, b, None, None)
        return a, b

    return jacobians
