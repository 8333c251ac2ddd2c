"""Trajectories of the locomotion models of dm_control and gymnasium: `lk.Simulation` against MuJoCo's `mj_step`.

The scene: each model from its qpos0 with its limited joints at mid-range and small random joint velocities, falling
and moving for 0.5 s without contacts. MuJoCo runs with its semi-implicit Euler integrator (legkit's scheme: v then q,
damping implicit) and without joint stiffness, springdamper, frictionloss, tendons' stiffness, damping and limits,
equality constraints and actuators, which legkit does not model (`from_mjcf` warns of them); mid-range starts keep the joints off their
limits, which MuJoCo makes soft and legkit hard. The suite's dog and quadruped (each with its ball) move on several
free bodies, whose slides and ball joints are MuJoCo's own free-joint coordinates, updated alike (a quaternion by the
exp of dt times the body-frame angular velocity in both).

Tolerances: a model without a free joint integrates every coordinate by the same update in both, so the trajectories
agree to rounding (1e-9 relative over 0.5 s). A free joint is integrated differently: MuJoCo adds dt v_world to its
position, legkit moves along the screw exp(v dt) of its body-frame twist, whose translation differs by
dt^2 (w x v) / 2 per step; summed over the horizon that bounds the base's drift by T dt max|w| max|v| / 2, which the
whole configuration is held to (the drift couples into the joints through the dynamics).
"""

from __future__ import annotations

import os
import warnings

import mujoco
import numpy as np
import pytest

import legkit as lk
from mjcf_compare import corpus, joint_ids, mapped

LOCOMOTION = {"ant.xml", "hopper.xml", "walker2d.xml", "half_cheetah.xml", "humanoid.xml", "cheetah.xml", "walker.xml"}
SEVERAL_FREE_BODIES = ("dm_control/suite/dog.xml", "dm_control/suite/quadruped.xml")
FILES = [p for p in corpus() if (os.path.basename(p) in LOCOMOTION and "/testing/" not in p) or p.endswith(SEVERAL_FREE_BODIES)]
HORIZON = 0.5


def like_for_like(path: str, rng: np.random.Generator) -> tuple[mujoco.MjModel, mujoco.MjData]:
    spec = mujoco.MjSpec.from_file(path)
    for joint in spec.joints:  # the dog's tail: legkit reads its `damping`, MuJoCo derives one from springdamper
        joint.springdamper = [0.0, 0.0]
    m = spec.compile()
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.jnt_stiffness[:] = 0.0
    m.dof_frictionloss[:] = 0.0
    # No actuators (a position actuator pulls at ctrl = 0, and lk.Simulation applies none unless asked) and no
    # equality constraints.
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EQUALITY | mujoco.mjtDisableBit.mjDSBL_ACTUATION
    m.tendon_stiffness[:], m.tendon_damping[:], m.tendon_limited[:] = 0.0, 0.0, 0
    d = mujoco.MjData(m)
    for j in range(m.njnt):
        # (numpy's integers are not `in` a tuple of MuJoCo's enums)
        if m.jnt_limited[j] and int(m.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            d.qpos[m.jnt_qposadr[j]] = m.jnt_range[j].mean()
    d.qvel[:] = rng.normal(scale=0.1, size=m.nv)
    mujoco.mj_forward(m, d)
    return m, d


@pytest.mark.skipif(not FILES, reason="dm_control and gymnasium are not installed")
@pytest.mark.parametrize("path", FILES, ids=[p.split("site-packages/")[-1] for p in FILES])
def test_a_contact_free_trajectory_follows_mujocos(path: str) -> None:
    m, d = like_for_like(path, np.random.default_rng(0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)  # stiffness, sensors, ...: zeroed or irrelevant here
        loaded = lk.load_mjcf(path)
    ids = joint_ids(m, loaded)
    sim = lk.Simulation(loaded.model, dt=m.opt.timestep)
    sim.q, sim.v = mapped(m, d, loaded, ids)[:2]
    steps = round(HORIZON / m.opt.timestep)
    spin, speed = 0.0, 0.0
    for _ in range(steps):
        mujoco.mj_step(m, d)
        if loaded.model.floating_base:
            a = m.jnt_dofadr[ids[0]]
            speed, spin = max(speed, np.linalg.norm(d.qvel[a : a + 3])), max(spin, np.linalg.norm(d.qvel[a + 3 : a + 6]))
    sim.step(None, steps)
    q, v = mapped(m, d, loaded, ids)[:2]
    tolerance = 1e-9 * (1.0 + np.abs(q).max())
    if loaded.model.floating_base:
        tolerance = HORIZON * m.opt.timestep * spin * speed / 2
    error = np.abs(sim.q - q).max()
    assert error <= tolerance, f"q differs by {error:.2e} > {tolerance:.2e} after {HORIZON} s"


# Scenes whose rest both engines reach: the gymnasium ant dropped with its ankles at the limits its weight presses
# them against (its stance is then set by geometry), the suite's cheetah and gymnasium's hopper falling onto their
# sides. MuJoCo without its contact margins (it holds geoms `margin` apart: the ant's 0.01 + 0.01 m lifts it by
# 2 cm), joint stiffness and frictionloss (not modelled by legkit). Elsewhere the two part by design: under a
# sustained sideways load MuJoCo's soft friction creeps where Coulomb's law holds (the gymnasium ant from
# mid-range ankles sinks from 0.53 m to its limits at 0.38 m over 7 s in MuJoCo and stands at 0.51 m in legkit),
# and a fall's final pose depends on the path.
REST = {"gymnasium/envs/mujoco/assets/ant.xml", "dm_control/suite/cheetah.xml", "gymnasium/envs/mujoco/assets/hopper.xml"}
REST_FILES = [p for p in corpus() if any(p.endswith(name) for name in REST)]
REST_TOLERANCE = 3e-3  # m: MuJoCo's soft contacts sink by its solref/solimp penetration, legkit's hardly


def dropped(path: str, m: mujoco.MjModel, d: mujoco.MjData, seconds: float) -> tuple[lk.Mjcf, lk.Simulation]:
    """`path` loaded and simulated on a plane from MuJoCo's state `d` for `seconds`, and MuJoCo stepped alike."""
    mujoco.mj_forward(m, d)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.MjcfWarning)
        loaded = lk.load_mjcf(path)
    sim = loaded.simulation()  # on the file's floor, at its timestep
    sim.q, sim.v = mapped(m, d, loaded, joint_ids(m, loaded))[:2]
    steps = round(seconds / m.opt.timestep)
    mujoco.mj_step(m, d, steps)
    sim.step(None, steps)
    return loaded, sim


@pytest.mark.skipif(not REST_FILES, reason="dm_control and gymnasium are not installed")
@pytest.mark.parametrize("path", REST_FILES, ids=[p.split("site-packages/")[-1] for p in REST_FILES])
def test_a_drop_comes_to_rest_at_mujocos_height(path: str) -> None:
    m = mujoco.MjModel.from_xml_path(path)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.geom_margin[:] = 0.0
    m.jnt_stiffness[:] = 0.0
    m.dof_frictionloss[:] = 0.0
    d = mujoco.MjData(m)
    ant = path.endswith("ant.xml")
    for j in range(m.njnt):
        if m.jnt_limited[j] and int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE):
            lo, hi = m.jnt_range[j]
            # the ant's ankles at the limit nearer zero, its hips (range about zero) at zero
            d.qpos[m.jnt_qposadr[j]] = (0.0 if lo < 0 < hi else min(lo, hi, key=abs)) if ant else (lo + hi) / 2
    loaded, sim = dropped(path, m, d, 3.0)
    height, ours = d.subtree_com[0][2], lk.center_of_mass(loaded.model, sim.q)[2]
    assert abs(ours - height) < REST_TOLERANCE, f"the COM rests at {ours:.4f} m, MuJoCo's at {height:.4f} m"


# The suite's dog and quadruped, several free bodies each (the robot and its ball on slides and a ball joint), limp
# (no actuators, stiffness or springdamper: the like-for-like of `like_for_like`) and dropped from qpos0 with their
# limited joints at mid-range. Both collapse onto their joint limits, which MuJoCo makes soft: its dog keeps sinking by
# about 1 mm/s after 3 s, and its quadruped, whose legs carry it where the dog lies on its belly, by 2 cm/s (0.26 m at
# 1 s, 0.18 m at 3 s), where legkit's hard limits hold. So the dog's height is compared (5 mm, the measured 3.6 mm
# plus the sink), with its ellipsoid geoms, which have no collision shape in legkit, colliding in neither (its limp legs
# still fold slowly in both), and the quadruped is held to rest on its legs. The robot's COM is compared: the ball bounces and rolls in MuJoCo.
SUITE_DROP_SECONDS = 3.0
DOG_REST_TOLERANCE = 5e-3  # m


def robot_com_height(loaded: lk.Mjcf, q: np.ndarray) -> float:
    """The COM height of the first free body's subtree (the robot; its ball is the second)."""
    first = loaded.joints[0]["idx_v"]
    body = next(i for i in range(1, len(loaded.model.names)) if loaded.model.idx_v[i] == first)
    return float(lk.subtree_mass_properties(loaded.model, q)[1][body][2])


@pytest.mark.parametrize("name", SEVERAL_FREE_BODIES)
def test_the_suites_dog_and_quadruped_fall_and_rest(name: str) -> None:
    path = next((p for p in corpus() if p.endswith(name)), None)
    assert path is not None, f"{name} is not in the corpus (dm_control, a test dependency, ships it)"
    m, d = like_for_like(path, np.random.default_rng(0))
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    m.geom_margin[:] = 0.0
    m.opt.cone, m.opt.impratio = mujoco.mjtCone.mjCONE_ELLIPTIC, 100.0  # legkit's friction is elliptic Coulomb
    ellipsoid = m.geom_type == mujoco.mjtGeom.mjGEOM_ELLIPSOID
    m.geom_contype[ellipsoid], m.geom_conaffinity[ellipsoid] = 0, 0
    d.qvel[:] = 0.0
    loaded, sim = dropped(path, m, d, SUITE_DROP_SECONDS)
    root = m.body_rootid[m.jnt_bodyid[joint_ids(m, loaded)[0]]]
    ours, theirs = robot_com_height(loaded, sim.q), d.subtree_com[root][2]
    assert np.isfinite(sim.q).all() and np.isfinite(sim.v).all()
    if name.endswith("dog.xml"):
        assert abs(ours - theirs) < DOG_REST_TOLERANCE, f"the dog's COM rests at {ours:.4f} m, MuJoCo's at {theirs:.4f} m"
    else:
        # On its legs: above its torso's (ellipsoid's) resting height, MuJoCo's at 1 s.
        assert 0.2 < ours < 0.35, f"the quadruped's COM rests at {ours:.4f} m"
