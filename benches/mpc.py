"""Tracking MPC benchmark (issue 37): the amble of docs/experiments.md (0.67 m/s, period 1.25 s; J_s2 solved on 4 intervals per
phase with a 3 N stance-force floor at mu 0.6 and refined onto 16) replayed in `lk.Simulation` under
`legkit.optimize.tracking` for --cycles cycles, on one core (BLAS limited to one thread), with the plant's masses
exact and scaled by each --mass factor (model mismatch: the controller's model keeps the plan's masses). Prints the
linearisation's and the MPC's build times, the median and 90th-percentile time of one control step (the MPC's
correction; the simulation's two 1 ms steps apart), the wall time of each whole replay (MPC build included) and its
real-time factor (wall / simulated time), whether the robot stayed upright, and the base drift as a share of the
distance.

    PYTHONPATH=python python3 benches/mpc.py [--cycles 5] [--mass 1.1 0.9] [--plan /tmp/amble.npz]
    PYTHONPATH=python python3 benches/mpc.py --gait walk --plan tests/data/optimised_walk.npz --mass 0.9

--plan: the solved plan is saved there on the first run and loaded on later ones (the amble's solve takes a minute or
two, the walk's (`walk_problem`'s defaults, `solve_walk`) about five). --gait walk: the biped walk at 1.8 km/h, its
soles held as frames by the MPC.
"""

from __future__ import annotations

import os

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before NumPy loads BLAS
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from legkit.gaits import AMBLE_QUADRUPED  # noqa: E402
from legkit.optimize.gaits import (  # noqa: E402
    amble_plan_problem,
    guess_from_reference,
    plan_amble,
    solve_walk,
    stall_torque_bounds,
    walk_problem,
    walk_reference,
)
from legkit.optimize.tracking import MPC, TrackingModel, heavier, track  # noqa: E402
from legkit.robots.biped import build_biped  # noqa: E402
from legkit.robots.motors import BIPED_MOTOR, QUADRUPED_MOTOR  # noqa: E402
from legkit.robots.quadruped import build_quadruped  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--gait", choices=("amble", "walk"), default="amble")
    parser.add_argument("--cycles", type=int, default=5)
    parser.add_argument("--mass", type=float, nargs="*", default=[1.1, 0.9], help="plant mass factors besides 1")
    parser.add_argument("--plan", type=Path, default=None, help="npz file to save the solved plan to, or load it from")
    args = parser.parse_args()

    problem, trajectory, motor = plan(args)
    motors = stall_torque_bounds(motor, problem.nu)

    start = time.perf_counter()
    model = TrackingModel.build(problem, trajectory)
    print(f"linearisation (analytic, {len(model.A)} samples of {1e3 * model.dt:.1f} ms): {time.perf_counter() - start:.2f} s")
    start = time.perf_counter()
    MPC(model, torque_bounds=motors)
    print(f"MPC build (every instant's QP condensed): {time.perf_counter() - start:.2f} s")

    timings: list[float] = []
    controllers: list[MPC] = []
    correction = MPC.correction

    def timed(self: MPC, i: int, e: np.ndarray) -> np.ndarray:
        begin = time.perf_counter()
        result = correction(self, i, e)
        timings.append(time.perf_counter() - begin)
        controllers[-1:] = [self]
        return result

    MPC.correction = timed  # type: ignore[method-assign]
    print(f"{'plant mass':>10} {'wall [s]':>9} {'simulated [s]':>13} {'real-time factor':>16} {'step median [ms]':>16} "
          f"{'step p90 [ms]':>13} {'QP solved':>11} {'upright':>7} {'drift [%]':>9}")
    for factor in [1.0, *args.mass]:
        timings.clear()
        begin = time.perf_counter()
        run = track(problem, trajectory, args.cycles, model=model, plant=heavier(problem.model, factor), torque_bounds=motors, progress=False)
        wall = time.perf_counter() - begin
        steps, solved = np.array(timings) * 1e3, controllers[-1].solved / len(timings)
        print(f"{factor:>10.2f} {wall:>9.2f} {run.t[-1]:>13.2f} {wall / run.t[-1]:>16.2f} {np.median(steps):>16.3f} "
              f"{np.percentile(steps, 90):>13.3f} {solved:>11.0%} {str(run.upright):>7} {100 * run.drift_fraction:>9.2f}")


def plan(args: argparse.Namespace) -> tuple:
    """(whole-cycle problem, trajectory, motor) of the gait, loaded from --plan if it exists, else solved (and saved there)."""
    if args.gait == "walk":
        biped = build_biped()
        fine, motor = walk_problem(biped, 0.5, BIPED_MOTOR), BIPED_MOTOR
    else:
        quadruped = build_quadruped(AMBLE_QUADRUPED)
        fine, motor = amble_plan_problem(quadruped), QUADRUPED_MOTOR
    if args.plan is not None and args.plan.exists():
        x = np.load(args.plan)["x"]
        print(f"plan loaded from {args.plan}")
    else:
        start = time.perf_counter()
        if args.gait == "walk":
            _, result = solve_walk(fine, guess_from_reference(fine, walk_reference(biped, 0.5)))
        else:
            solved = plan_amble(quadruped)
            fine, result = solved.problem, solved.result
        x = result.best()[0]
        print(f"plan solved: {result.status}, {time.perf_counter() - start:.1f} s")
        if args.plan is not None:
            np.savez(args.plan, x=x)
    problem, x = fine.whole_cycle(x)
    return problem, problem.unpack(x), motor


if __name__ == "__main__":
    main()
