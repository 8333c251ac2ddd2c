"""Side-by-side step time of lk.Simulation (Rapier) and MuJoCo on the same modular robot.

The robot is a SuperBot-like tree: modules of four bodies (end block, two links, end block) on three
revolute joints (pitch, roll about the module's long axis, pitch); a vertical root module fixed to the
ground and four branches of (n_modules - 1) / 4 modules leaving its top block horizontally, sagging onto a
ground plane. Every joint has a position servo (kp, kd, torque limit); self-collision is off and every body
collides with the ground. Both engines step at 1 kHz with their default solvers.

Run: ``python benches/simulation_vs_mujoco.py [--modules 21 100] [--seconds 1.0]``. Prints µs per step,
real-time factor and the ratio legkit / MuJoCo.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

import legkit as lk

MODULE_LENGTH = 0.17  # m, end face to end face (SuperBot modules are about 17 cm long)
MODULE_MASS = 0.05  # kg: 10% of a real module's ~0.5 kg, as in the seed experiments
PART_MASS = MODULE_MASS / 4
PART_SIZE = np.array([0.06, 0.06, MODULE_LENGTH / 4])  # each of the 4 bodies, stacked along the module axis
KP, KD, TORQUE_LIMIT = 0.5, 0.002, 0.5  # N m/rad, N m s/rad, N m
DT = 1e-3


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
    roll (z, the long axis), link, pitch (y), end block; part frames sit at each part's lower face."""
    step = np.array([0.0, 0.0, MODULE_LENGTH / 4])
    parts: list[Part] = []

    def add_module(parent: int, rotation: np.ndarray, translation: np.ndarray) -> int:
        parts.append(Part(parent, None, rotation, translation))
        for axis in ((0, 1, 0), (0, 0, 1), (0, 1, 0)):
            parts.append(Part(len(parts) - 1, axis, np.eye(3), step))
        return len(parts) - 1  # the top end block

    top = add_module(-1, np.eye(3), np.array([0.0, 0.0, 0.05]))
    per_branch = (n_modules - 1) // 4
    for branch in range(4):
        # Leave the top block sideways: turn about z to the branch direction, then tip the axis horizontal.
        parent, rotation = top, rotation_z(branch * np.pi / 2) @ rotation_y(np.pi / 2)
        translation = step
        for _ in range(per_branch):
            parent = add_module(parent, rotation, translation)
            rotation, translation = np.eye(3), step
    return parts


def legkit_model(parts: list[Part]) -> lk.Model:
    inertia = lk.MassProperties.box(PART_MASS, PART_SIZE, center=[0, 0, PART_SIZE[2] / 2])
    model = lk.Model(floating_base=False, base=None)
    for index, part in enumerate(parts):
        parent = part.parent + 1  # body 0 is the world-fixed base
        placement = (part.rotation, part.translation)
        if part.axis is None:
            model.add_fixed(parent, placement, inertia, f"part{index}")
        else:
            model.add_revolute(parent, part.axis, placement, inertia, f"part{index}")
    return model


def mujoco_xml(parts: list[Part]) -> str:
    children: dict[int, list[int]] = {}
    for index, part in enumerate(parts):
        children.setdefault(part.parent, []).append(index)
    half = PART_SIZE / 2
    inertia = PART_MASS / 12 * np.array([PART_SIZE[1] ** 2 + PART_SIZE[2] ** 2, PART_SIZE[0] ** 2 + PART_SIZE[2] ** 2, PART_SIZE[0] ** 2 + PART_SIZE[1] ** 2])

    def quaternion(r: np.ndarray) -> str:
        w = np.sqrt(max(0.0, 1 + np.trace(r))) / 2
        if w > 1e-6:
            q = [w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)]
        else:  # a half turn: axis from the diagonal
            axis = np.sqrt(np.maximum(0.0, (np.diag(r) + 1) / 2))
            q = [0.0, *axis]
        return " ".join(f"{x:.12g}" for x in q)

    def body(index: int) -> str:
        part = parts[index]
        joint = "" if part.axis is None else f'<joint name="j{index}" type="hinge" axis="{part.axis[0]} {part.axis[1]} {part.axis[2]}"/>'
        inner = "".join(body(c) for c in children.get(index, []))
        return (
            f'<body name="b{index}" pos="{part.translation[0]:.12g} {part.translation[1]:.12g} {part.translation[2]:.12g}" quat="{quaternion(part.rotation)}">'
            f"{joint}"
            f'<inertial pos="0 0 {half[2]:.12g}" mass="{PART_MASS}" diaginertia="{inertia[0]:.12g} {inertia[1]:.12g} {inertia[2]:.12g}"/>'
            f'<geom type="box" size="{half[0]} {half[1]} {half[2]}" pos="0 0 {half[2]:.12g}" contype="1" conaffinity="2" friction="0.8"/>'
            f"{inner}</body>"
        )

    actuators = "".join(
        f'<position joint="j{i}" kp="{KP}" kv="{KD}" forcerange="{-TORQUE_LIMIT} {TORQUE_LIMIT}" forcelimited="true"/>'
        for i, part in enumerate(parts)
        if part.axis is not None
    )
    return (
        f'<mujoco><option timestep="{DT}" gravity="0 0 -9.81"/>'
        f'<worldbody><geom type="plane" size="5 5 0.1" contype="2" conaffinity="1" friction="0.8"/>'
        f'{"".join(body(c) for c in children.get(-1, []))}</worldbody>'
        f"<actuator>{actuators}</actuator></mujoco>"
    )


def time_legkit(parts: list[Part], steps: int, substeps: int) -> tuple[float, int]:
    """µs per step and the number of contact points at the end."""
    model = legkit_model(parts)
    sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(0.8), substeps=substeps)
    sim.set_servo(kp=KP, kd=KD, torque_limit=TORQUE_LIMIT, target_q=model.neutral())
    sim.step(n=100)  # settle onto the ground first: time the loaded, contacting regime
    start = time.perf_counter()
    sim.step(n=steps)
    elapsed = time.perf_counter() - start
    return elapsed / steps * 1e6, len(sim.contacts()["body"])


def time_mujoco(parts: list[Part], steps: int) -> tuple[float, int] | None:
    try:
        import mujoco
    except ImportError:
        return None
    m = mujoco.MjModel.from_xml_string(mujoco_xml(parts))
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d, nstep=100)
    start = time.perf_counter()
    mujoco.mj_step(m, d, nstep=steps)
    elapsed = time.perf_counter() - start
    return elapsed / steps * 1e6, int(d.ncon)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modules", type=int, nargs="+", default=[21, 101], help="modules per tree (1 + 4 branches)")
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time per measurement")
    parser.add_argument("--substeps", type=int, default=1, help="Rapier substeps per step")
    args = parser.parse_args(argv)
    steps = int(round(args.seconds / DT))
    print(f"{'modules':>7} {'DoF':>5} {'legkit µs/step':>15} {'x real time':>11} {'contacts':>8} {'MuJoCo µs/step':>15} {'x real time':>11} {'contacts':>8} {'legkit/MuJoCo':>13}")
    for n in args.modules:
        parts = module_tree(n)
        dof = sum(p.axis is not None for p in parts)
        ours, our_contacts = time_legkit(parts, steps, args.substeps)
        theirs = time_mujoco(parts, steps)
        row = f"{n:>7} {dof:>5} {ours:>15.1f} {DT * 1e6 / ours:>11.2f} {our_contacts:>8}"
        if theirs is None:
            row += f" {'(pip install mujoco)':>36}"
        else:
            row += f" {theirs[0]:>15.1f} {DT * 1e6 / theirs[0]:>11.2f} {theirs[1]:>8} {ours / theirs[0]:>13.2f}"
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
