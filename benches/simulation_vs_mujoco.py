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
  rolled by 0.7 rad with limp, damped joints, its lowest point 1 mm above the ground (Go1 at 0.45 m, ANYmal at
  0.596 m), it tips over onto its side. See the behaviour table
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
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import simulation_scenes
from simulation_robots import ROBOTS, dog_scene, robot_scene
from simulation_scenes import (
    DT,
    FRICTION,
    KD,
    KP,
    TORQUE_LIMIT,
    Runner,
    Scene,
    legkit_model,
    module_tree,
    mujoco_xml,
    quadruped_scene,
    stand_height,
    tree_scene,
)

import legkit as lk

SETTLE_SECONDS = 0.3
BLOCK_STEPS = 100

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


def measure(
    runner: Runner, settle_steps: int, blocks: int, block_steps: int, budget: float, handoff: tuple[np.ndarray, np.ndarray, int] | None = None
) -> Result:
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
        return Result(
            statistics.median(means),
            (min(means), max(means)),
            int(statistics.median(contacts)),
            blocks,
            block_steps,
            settle_steps + (0 if used_handoff else 10),
            used_handoff,
            runner.base() if runner.base else None,
            base_start,
        )
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
        out[name] = Result(
            statistics.median(means[name]),
            (min(means[name]), max(means[name])),
            int(statistics.median(contacts[name])),
            blocks,
            block_steps,
            settle_steps,
            False,
            runner.base() if runner.base else None,
            bases[name],
        )
    return out


def run_scene(scene: Scene, args: argparse.Namespace) -> dict[str, Result | None]:
    settle = int(round(args.settle / DT))
    blocks = max(1, int(round(args.seconds / (args.block_steps * DT))))
    ours = scene.legkit("tree")
    runners = {"legkit": ours}
    try:
        import mujoco  # noqa: F401

        for name, cone in (("MuJoCo elliptic", ("elliptic", simulation_scenes.ELLIPTIC_IMPRATIO)), ("MuJoCo pyramid", ("pyramidal", 1.0))):
            simulation_scenes.MUJOCO_CONE = cone
            runners[name] = scene.mujoco()
        simulation_scenes.MUJOCO_CONE = ("pyramidal", 1.0)
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
    print(
        "| scene | DoF | legkit µs/step | MuJoCo elliptic µs/step | MuJoCo pyramid µs/step | Rapier µs/step "
        "| legkit × real time | contacts legkit / MuJoCo ell. / pyr. / Rapier | legkit / MuJoCo elliptic "
        "| legkit / MuJoCo pyramid | legkit / Rapier |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | :---: | ---: | ---: | ---: |")
    for scene, r in rows:
        engines = ("legkit", "MuJoCo elliptic", "MuJoCo pyramid", "Rapier")
        contacts = " / ".join("–" if r[e] is None or r[e].error else str(r[e].contacts) for e in engines)
        rapier = fmt_us(r["Rapier"]) + ("*" if r["Rapier"] is not None and r["Rapier"].handoff else "")
        print(
            f"| {scene.name} | {scene.dof} | {fmt_us(r['legkit'])} | {fmt_us(r['MuJoCo elliptic'])} | {fmt_us(r['MuJoCo pyramid'])} "
            f"| {rapier} | {fmt_rtf(r['legkit'])} | {contacts} | {fmt_ratio(r['legkit'], r['MuJoCo elliptic'])} "
            f"| {fmt_ratio(r['legkit'], r['MuJoCo pyramid'])} | {fmt_ratio(r['legkit'], r['Rapier'])} |"
        )


def print_details(rows: list[tuple[Scene, dict[str, Result | None]]]) -> None:
    print("\nMeasurement details (blocks x steps timed after settling; min-max of the block means; * = Rapier started from legkit's settled state):")
    for scene, r in rows:
        for engine, res in r.items():
            if res is None:
                continue
            if res.error:
                print(f"  {scene.name:16} {engine:15} ERROR {res.error}")
                continue
            print(
                f"  {scene.name:16} {engine:15} settle {res.settle_steps:4d}{'*' if res.handoff else ' '} steps, "
                f"{res.blocks:2d} x {res.block_steps:3d} steps, block means {res.spread[0] * 1e6:.1f}-{res.spread[1] * 1e6:.1f} µs"
            )


def print_quadruped_table(rows: list[tuple[Scene, dict[str, Result | None]]]) -> None:
    quads = [(s, r) for s, r in rows if s.name.startswith(("quadruped", *ROBOTS))]
    if not quads:
        return
    print(
        "\nQuadruped behaviour over the timed steps (torso: start -> end; up = world z of the torso's z axis; "
        f"the synthetic quadruped's standing height {stand_height():.3f} m):\n"
    )
    print("| scene | engine | torso z (m) | up | distance travelled (m) | timed steps |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for scene, r in quads:
        for engine, res in r.items():
            if res is None or res.error or res.base is None:
                continue
            b0, b1 = res.base_start, res.base
            print(
                f"| {scene.name} | {engine} | {b0[2]:.3f} -> {b1[2]:.3f} | {b1[3]:.3f} | {np.hypot(*(b1[:2] - b0[:2])):.3f} "
                f"(dx {b1[0] - b0[0]:+.3f}) | {res.blocks * res.block_steps} |"
            )


# ------------------------------------------------------------------------------------------------------
# Batch throughput
# ------------------------------------------------------------------------------------------------------


def batch_section(n_sims: int, modules: int, steps: int, repeats: int, settle: int) -> None:
    parts = module_tree(modules)
    model = legkit_model(parts)
    rng = np.random.default_rng(0)
    sims = []
    for _ in range(n_sims):
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(FRICTION), **simulation_scenes.solver_options())
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
    print(
        f"\nBatch throughput: {n_sims} simulations of the {len(parts) // 4}-module tree ({model.nv} DoF), {steps} steps "
        f"per call, median of {repeats} repeats, after {settle} settling steps:\n"
    )
    print("| how | sim-steps / s | µs per sim-step | vs per-step loop |")
    print("| --- | ---: | ---: | ---: |")
    for name, t in results:
        rate = n_sims * steps / t
        print(f"| {name} | {rate:,.0f} | {t / (n_sims * steps) * 1e6:.1f} | {base / t:.2f}x |")
    print(
        f"\nSimulationBatch / per-simulation loop throughput: {results[1][1] / results[2][1]:.2f}x; "
        f"SimulationBatch / per-step loop: {results[0][1] / results[2][1]:.2f}x"
    )


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
    parser.add_argument(
        "--settle",
        type=float,
        default=SETTLE_SECONDS,
        help="untimed simulated seconds before timing (0.3: the trees are still sagging and swaying; about 2 s brings them to rest)",
    )
    parser.add_argument(
        "--solver-iterations",
        type=int,
        default=simulation_scenes.SOLVER_ITERATIONS,
        help="legkit tree engine's most contact-solver iterations per step (default: legkit's)",
    )
    parser.add_argument(
        "--friction-law",
        choices=("coulomb", "cone"),
        default=simulation_scenes.FRICTION_LAW,
        help="legkit tree engine's friction law (default coulomb: the like-for-like row with MuJoCo's elliptic cone)",
    )
    args = parser.parse_args(argv)
    simulation_scenes.SOLVER_ITERATIONS = args.solver_iterations
    simulation_scenes.FRICTION_LAW = args.friction_law
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
    print(
        f"\nStep time at dt = {DT * 1e3:g} ms, median of block means ({'quick' if args.quick else 'full'} run), "
        f"legkit's tree engine (friction_law={args.friction_law}, solver_iterations={args.solver_iterations or 'default'}) "
        f"vs MuJoCo {mujoco_version()} and Rapier "
        f'(backend="rapier"); legkit extension built {EXTENSION_BUILT}:\n'
    )
    print_scene_table(rows)
    print_details(rows)
    print_quadruped_table(rows)
    if not args.no_batch:
        if args.quick:
            batch_section(12, 21, steps=50, repeats=3, settle=300)
        else:
            batch_section(12, 21, steps=100, repeats=5, settle=300)
    print(
        f"\ntotal wall time {time.perf_counter() - wall:.0f} s; load average at the start {load_start}, at the end "
        f"{load_average()} on {os.cpu_count()} cores (other work on the machine inflates the times, the batch's most)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
