"""The scenes of benches/simulation_vs_mujoco.py loaded from files (see its docstring): Go1 and ANYmal C from
example-robot-data's URDFs and the dm_control suite's dog from its MJCF, each loaded by both engines.
"""

from __future__ import annotations

import importlib.util
import os
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import simulation_scenes
from simulation_scenes import DT, FRICTION, Runner, Scene, mujoco_jacobians, set_cone, stepping_runner

import legkit as lk

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
FALL_ROLL = 0.7  # rad: released rolled, so it tips onto its side
# Base heights (m) that put the rolled robot's lowest point at least 1 mm above the ground: released at 0.45 m, ANYmal's
# right shanks started 0.145 m into it (MuJoCo's contacts at the start), which each engine resolved its own way (MuJoCo's
# lay on its side with 8-12 contacts, legkit's righted itself and lay on its belly with 24).
FALL_HEIGHT = {"go1": 0.45, "anymal": 0.596}


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
    child_of = {
        j.get("name"): j.find("child").get("link") for j in ET.parse(urdf).getroot().findall("joint") if j.get("type") in ("revolute", "continuous")
    }
    # Front legs (FL, FR, LF, RF) take the first angle, hind legs the second.
    angles = {name: pair[0 if "F" in name[:2] else 1] for name in child_of for suffix, pair in crouch.items() if name.endswith(suffix)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)
        model = lk.Model.from_urdf(urdf, floating_base=True)
    start = model.neutral()
    for joint, angle in angles.items():
        start[model.idx_q[model.names.index(child_of[joint])]] = angle
    roll = FALL_ROLL if fall else 0.0
    start[2] = FALL_HEIGHT[robot] if fall else stand_height
    start[3:7] = [np.sin(roll / 2), 0.0, 0.0, np.cos(roll / 2)]
    kp, kd = (0.0, FALL_KD) if fall else (ROBOT_KP, ROBOT_KD)

    def legkit_runner(backend: str) -> Runner:
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), backend=backend, **simulation_scenes.solver_options())
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
        spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1], contype=0, conaffinity=1, friction=[FRICTION, 0.005, 0.0001])
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
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), backend=backend, **simulation_scenes.solver_options())
        sim.reset(start, np.zeros(model.nv))
        return stepping_runner(sim, simulation=sim)

    def mujoco_runner() -> Runner:
        m, d = compiled()
        set_cone(m)
        mujoco.mj_forward(m, d)
        return Runner(lambda n: mujoco.mj_step(m, d, nstep=n), lambda: int(d.ncon))

    return Scene("dog-fall", model.nv, legkit_runner, mujoco_runner, rapier=False)
