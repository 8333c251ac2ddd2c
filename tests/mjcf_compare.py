"""Differential check of `lk.load_mjcf` against MuJoCo's own compiler and dynamics (used by test_mjcf.py and
benches/mjcf_load.py): joint coordinates mapped by name, MuJoCo's free-joint velocity convention converted on a
floating base (several free bodies keep MuJoCo's coordinates)."""

from __future__ import annotations

import glob
import importlib.util
import os

import mujoco
import numpy as np

import legkit as lk

RTOL = 1e-9


def corpus() -> list[str]:
    """The MJCF files the dm_control and gymnasium wheels ship (those installed), sorted."""
    files: list[str] = []
    for package in ("dm_control", "gymnasium"):
        spec = importlib.util.find_spec(package)
        if spec is None or spec.origin is None:
            continue
        files += glob.glob(os.path.join(os.path.dirname(spec.origin), "**", "*.xml"), recursive=True)
    return sorted(files)


def joint_ids(m: mujoco.MjModel, loaded: lk.Mjcf) -> list[int]:
    """MuJoCo's id of each joint legkit kept (legkit names unnamed joints joint<i>, i MuJoCo's id)."""
    ids = []
    for joint in loaded.joints:
        i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint["name"])
        ids.append(i if i >= 0 else int(joint["name"].removeprefix("joint")))
    return ids


def random_state(m: mujoco.MjModel, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    qpos = m.qpos0.copy()
    for j in range(m.njnt):
        a = m.jnt_qposadr[j]
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE or m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                qpos[a : a + 3] = rng.uniform(-1, 1, 3)
                a += 3
            quat = rng.normal(size=4)
            qpos[a : a + 4] = quat / np.linalg.norm(quat)
        elif m.jnt_limited[j]:
            qpos[a] = rng.uniform(*m.jnt_range[j])
        else:
            qpos[a] = rng.uniform(-1, 1)
    return qpos, rng.normal(size=m.nv)


def mapped(m: mujoco.MjModel, d: mujoco.MjData, loaded: lk.Mjcf, ids: list[int]) -> tuple[np.ndarray, ...]:
    """legkit's q, v and MuJoCo's mass matrix and bias forces in legkit's coordinates: v_mj = T v_lk (a free
    joint's linear velocity is in the world frame in MuJoCo, in the body frame in legkit) and a_mj = T a_lk + c,
    so M_lk = Tᵀ M T and b_lk = Tᵀ (b + M c)."""
    model = loaded.model
    q, v = np.zeros(model.nq), np.zeros(model.nv)
    t = np.zeros((m.nv, model.nv))
    c = np.zeros(m.nv)
    for joint, j in zip(loaded.joints, ids):
        qa, da, iq, iv = m.jnt_qposadr[j], m.jnt_dofadr[j], joint["idx_q"], joint["idx_v"]
        if joint["type"] == "free" and not model.floating_base:  # three slides and a ball: MuJoCo's coordinates
            w, x, y, z = d.qpos[qa + 3 : qa + 7]
            q[iq : iq + 7] = [*d.qpos[qa : qa + 3], x, y, z, w]
            v[iv : iv + 6] = d.qvel[da : da + 6]
            t[da : da + 6, iv : iv + 6] = np.eye(6)
        elif joint["type"] == "free":
            w, x, y, z = d.qpos[qa + 3 : qa + 7]
            rotation = np.zeros(9)
            mujoco.mju_quat2Mat(rotation, d.qpos[qa + 3 : qa + 7])
            r = rotation.reshape(3, 3)
            q[iq : iq + 7] = [*d.qpos[qa : qa + 3], x, y, z, w]
            v[iv : iv + 3] = r.T @ d.qvel[da : da + 3]
            v[iv + 3 : iv + 6] = d.qvel[da + 3 : da + 6]
            t[da : da + 3, iv : iv + 3] = r
            t[da + 3 : da + 6, iv + 3 : iv + 6] = np.eye(3)
            c[da : da + 3] = r @ np.cross(v[iv + 3 : iv + 6], v[iv : iv + 3])
        elif joint["type"] == "ball":  # the angular velocity in the body frame in both; w first in MuJoCo
            w, x, y, z = d.qpos[qa : qa + 4]
            q[iq : iq + 4] = [x, y, z, w]
            v[iv : iv + 3] = d.qvel[da : da + 3]
            t[da : da + 3, iv : iv + 3] = np.eye(3)
        else:
            q[iq], v[iv], t[da, iv] = d.qpos[qa], d.qvel[da], 1.0
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    return q, v, t.T @ full @ t, t.T @ (d.qfrc_bias + full @ c)


def moving_mass(m: mujoco.MjModel, d: mujoco.MjData, floating: bool) -> tuple[float, np.ndarray]:
    """MuJoCo's total mass and COM of what a legkit model holds: every body for a fixed base, the free body's
    tree for a floating one."""
    if not floating:
        return float(m.body_mass.sum()), d.subtree_com[0].copy()
    root = next(b for b in range(1, m.nbody) if m.body_jntnum[b] and m.jnt_type[m.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_FREE)
    return float(m.body_mass[root == m.body_rootid].sum()), d.subtree_com[root].copy()


def compare(path: str, m: mujoco.MjModel, rng: np.random.Generator, states: int = 3) -> str | None:
    """None if legkit's model of `path` matches MuJoCo's `m` (mass matrix, bias forces, total mass and COM at
    random states, to RTOL), else what differs. Raises what `load_mjcf` raises."""
    loaded = lk.load_mjcf(path)
    model = loaded.model
    ids = joint_ids(m, loaded)
    if model.nv != m.nv:
        return f"nv {model.nv} != MuJoCo's {m.nv}"
    d = mujoco.MjData(m)
    for _ in range(states):
        d.qpos[:], d.qvel[:] = random_state(m, rng)
        mujoco.mj_forward(m, d)
        q, v, mass_matrix, bias = mapped(m, d, loaded, ids)
        total, com = moving_mass(m, d, model.floating_base)
        if abs(model.total_mass - total) > RTOL * total:
            return f"total mass {model.total_mass} != MuJoCo's {total}"
        if total > 0 and np.abs(lk.center_of_mass(model, q) - com).max() > RTOL * (1 + np.abs(com).max()):
            return "COM differs"
        if model.nv == 0:
            continue
        ours = lk.crba(model, q)
        scale = max(np.abs(mass_matrix).max(), 1e-300)
        if np.abs(ours - mass_matrix).max() > RTOL * scale:
            return f"mass matrix differs by {np.abs(ours - mass_matrix).max() / scale:.2e} (relative)"
        b = lk.rnea(model, q, v, np.zeros(model.nv))
        bscale = max(np.abs(bias).max(), scale * 1e-3)
        if np.abs(b - bias).max() > RTOL * bscale:
            return f"bias forces differ by {np.abs(b - bias).max() / bscale:.2e} (relative)"
    return None
