"""Side-by-side time of one step's transition Jacobians: legkit's ``Simulation.transition_jacobians`` (analytic
through the tree engine's converged contact solve) and MuJoCo's ``mjd_transitionFD`` (finite differences of its
step: forward, eps = 1e-6, its default), on scenes of benches/simulation_vs_mujoco.py built from the same numbers:
Go1 standing on servos (example-robot-data's URDF) and the 21-module SuperBot-like tree sagging onto the ground
(``--scenes`` adds ``quadruped-stand``, ``anymal-stand`` or larger trees such as ``tree-51``).

Each engine settles its scene untimed (``--settle`` s), then computes the Jacobians at that state in
``--blocks`` blocks of ``--calls`` calls; reported: the median over blocks of the mean call time (CPU time of
the calling thread), the ratio legkit / MuJoCo, the sizes (A is 2 nv square in both; B is 2 nv x 3 nv in legkit,
whose controls are the feed-forward torques and the servos' position and velocity targets, and 2 nv x nu in
MuJoCo, whose are its actuators' controls), the contact points, and the spectral radius of each A (a step's
stability: just below 1 for a robot at rest). The two engines' contact models differ (MuJoCo's soft contacts,
legkit's regularised Coulomb cone), so their A and B are not expected to agree entry by entry.

``--substeps 1 4 10`` times legkit's Jacobians of the same step cut into that many substeps (each substep linearised
and the chain composed, its warm starts followed: docs/derivatives.md) against MuJoCo's of its one step of the
same length.

``--rollout 100`` adds, per scene and substep count, one rollout of that many steps with every step's Jacobians:
legkit's ``Simulation.rollout(controls, jacobians=True)`` (one call) against that many MuJoCo steps each with
``mjd_transitionFD`` at its start (``mj_step`` after it), both from the settled state, restored before each call.

``--check`` also measures legkit's A and B's feed-forward columns against central differences of its own step
(each displaced step replayed from a freshly settled scene, contact history included; displacement 1e-7 /
substeps², as the tests: a resting contact settles within about ε g h² of its law's bend, docs/derivatives.md), the
accuracy figure of docs/derivatives.md; slow on the tree (6 nv settled replays).

Run: ``python benches/transition_vs_mujoco.py [--scenes go1-stand tree-21] [--substeps 1] [--settle 0.3]
[--blocks 7] [--calls 20] [--check]``. Prints a Markdown table and the load average.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
import simulation_scenes
from simulation_robots import robot_scene
from simulation_scenes import DT, Runner, Scene, quadruped_scene, tree_scene
from simulation_vs_mujoco import load_average

import legkit as lk

# The figures in docs/derivatives.md were measured on the default (cone) friction law; the step bench runs
# Coulomb's, against MuJoCo's elliptic cone.
simulation_scenes.FRICTION_LAW = "cone"

CHECK_STEP = 1e-7
SOLVER_OPTIONS = simulation_scenes.solver_options


def use_substeps(substeps: int) -> None:
    """Builds legkit's scenes with each step cut into `substeps` (the step, dt, unchanged)."""
    simulation_scenes.solver_options = lambda: {**SOLVER_OPTIONS(), "substeps": substeps}


def scene(name: str) -> Scene:
    if name.startswith("tree-"):
        return tree_scene(int(name.split("-")[1]))
    if name == "quadruped-stand":
        return quadruped_scene(trot=False)
    robot, _, kind = name.partition("-")
    return robot_scene(robot, fall=kind == "fall")


def settled(scene: Scene, engine: str, settle: float) -> Runner:
    runner = scene.legkit("tree") if engine == "legkit" else scene.mujoco()
    runner.advance(int(round(settle / DT)))
    return runner


def time_calls(call: Callable[[], object], blocks: int, calls: int) -> float:
    """Median over blocks of the mean time of one call (s, CPU time of the process: a long call of legkit's runs on a
    worker thread, where Ctrl-C can stop it, which the calling thread's time would miss)."""
    means = []
    for _ in range(blocks):
        start = time.process_time()
        for _ in range(calls):
            call()
        means.append((time.process_time() - start) / calls)
    return statistics.median(means)


def spectral_radius(a: np.ndarray) -> float:
    return float(np.abs(np.linalg.eigvals(a)).max())


def central_differences(build: Callable[[], lk.Simulation], substeps: int) -> tuple[float, float]:
    """Largest |[A B_tau] − central differences of the step| and largest |[A B_tau]| (B_tau: B's feed-forward
    columns; the servo-target columns are checked in tests/), the displaced steps replayed from `build`."""
    delta = CHECK_STEP / substeps**2
    sim = build()
    a, b = sim.transition_jacobians()
    nv, model = sim.model.nv, sim.model
    analytic = np.hstack([a, b[:, :nv]])
    q, v = sim.q.copy(), sim.v.copy()

    def step(column: int, offset: float) -> tuple[np.ndarray, np.ndarray]:
        displaced = build()
        d = np.zeros(3 * nv)
        d[column] = offset
        displaced.q = lk.integrate(model, q, d[:nv], 1.0)
        displaced.v = v + d[nv : 2 * nv]
        displaced.step(d[2 * nv :])
        return displaced.q, displaced.v

    q_next, _ = step(0, 0.0)
    numeric = np.zeros_like(analytic)
    for column in range(3 * nv):
        (q_plus, v_plus), (q_minus, v_minus) = step(column, delta), step(column, -delta)
        numeric[:nv, column] = (lk.difference(model, q_next, q_plus) - lk.difference(model, q_next, q_minus)) / (2 * delta)
        numeric[nv:, column] = (v_plus - v_minus) / (2 * delta)
    return float(np.abs(analytic - numeric).max()), float(np.abs(analytic).max())


def legkit_rollout(runner: Runner, steps: int) -> Callable[[], object]:
    """One `Simulation.rollout` of `steps` zero feed-forward steps with their Jacobians, from the runner's state now."""
    sim = runner.simulation
    assert sim is not None
    q, v, controls = sim.q.copy(), sim.v.copy(), np.zeros((steps, sim.model.nv))

    def call() -> object:
        sim.q, sim.v = q, v
        return sim.rollout(controls, jacobians=True)

    return call


def mujoco_rollout(name: str, settle: float, steps: int) -> Callable[[], object]:
    """`steps` MuJoCo steps, each after `mjd_transitionFD` at its start, from the settled scene's state."""
    import mujoco

    runner = settled(scene(name), "mujoco", settle)
    m, d = runner.model_data
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    start = np.zeros(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, start, spec)
    assert runner.jacobians is not None
    jacobians = runner.jacobians

    def call() -> object:
        mujoco.mj_setState(m, d, start, spec)
        for _ in range(steps):
            jacobians()
            mujoco.mj_step(m, d)
        return d

    return call


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["go1-stand", "tree-21"])
    parser.add_argument("--substeps", type=int, nargs="+", default=[1])
    parser.add_argument("--settle", type=float, default=0.3)
    parser.add_argument("--blocks", type=int, default=7)
    parser.add_argument("--calls", type=int, default=20)
    parser.add_argument("--check", action="store_true")
    parser.add_argument("--rollout", type=int, default=0, help="steps of a rollout with Jacobians to time (0: none)")
    args = parser.parse_args()
    rows, rollouts = [], []
    for name in args.scenes:
        theirs = settled(scene(name), "mujoco", args.settle)
        assert theirs.jacobians is not None
        a_mj, b_mj = theirs.jacobians()
        t_theirs = time_calls(theirs.jacobians, args.blocks, args.calls)
        rollout_calls = max(1, args.calls // 10)
        t_theirs_rollout = time_calls(mujoco_rollout(name, args.settle, args.rollout), args.blocks, rollout_calls) if args.rollout else 0.0
        for substeps in args.substeps:
            use_substeps(substeps)
            s = scene(name)
            ours = settled(s, "legkit", args.settle)
            assert ours.jacobians is not None
            a, b = ours.jacobians()
            contacts = ours.contacts()  # at the settled state (a rollout moves the simulation on)
            t_ours = time_calls(ours.jacobians, args.blocks, args.calls)
            check = ""
            if args.check:
                error, scale = central_differences(lambda scene=s: settled(scene, "legkit", args.settle).simulation, substeps)
                check = f"{error / scale:.1e}"
            if args.rollout:
                t_ours_rollout = time_calls(legkit_rollout(ours, args.rollout), args.blocks, rollout_calls)
                rollouts.append((name, substeps, t_ours_rollout, t_theirs_rollout))
            rows.append(
                (
                    name,
                    substeps,
                    a.shape[0] // 2,
                    contacts,
                    theirs.contacts(),
                    f"{b.shape[1]} / {b_mj.shape[1]}",
                    t_ours,
                    t_theirs,
                    spectral_radius(a),
                    spectral_radius(a_mj),
                    check,
                )
            )
        print(f"{name}: done", flush=True)
    print()
    print(
        "| scene | substeps | nv | contacts legkit / MuJoCo | B columns legkit / MuJoCo | legkit (µs) | MuJoCo FD (µs) | ratio |"
        " spectral radius of A legkit / MuJoCo |" + (" legkit vs central differences (relative) |" if args.check else "")
    )
    print("|---|---|---|---|---|---|---|---|---|" + ("---|" if args.check else ""))
    for name, substeps, nv, c_ours, c_theirs, columns, t_ours, t_theirs, rho, rho_mj, check in rows:
        print(
            f"| {name} | {substeps} | {nv} | {c_ours} / {c_theirs} | {columns} | {t_ours * 1e6:.0f} | {t_theirs * 1e6:.0f} | "
            f"{t_ours / t_theirs:.2f}x | {rho:.4f} / {rho_mj:.4f} |" + (f" {check} |" if args.check else "")
        )
    if rollouts:
        print(
            f"\n| scene | substeps | legkit rollout of {args.rollout} steps with Jacobians (ms) |"
            f" MuJoCo {args.rollout} x (mjd_transitionFD + mj_step) (ms) | ratio |"
        )
        print("|---|---|---|---|---|")
        for name, substeps, t_ours, t_theirs in rollouts:
            print(f"| {name} | {substeps} | {t_ours * 1e3:.1f} | {t_theirs * 1e3:.1f} | {t_ours / t_theirs:.2f}x |")
    print(f"\nload average {load_average()}, {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
