"""Tracking MPC benchmark (issue 37): the README's amble (0.67 m/s, period 1.25 s; J_s2 solved on 4 intervals per
phase with a 3 N stance-force floor at mu 0.6 and refined onto 16) replayed in `lk.Simulation` under
`legkit.optimize.tracking` for --cycles cycles, on one core (BLAS limited to one thread), with the plant's masses
exact and scaled by each --mass factor (model mismatch: the controller's model keeps the plan's masses). Prints the
linearisation's and the MPC's build times, the median and 90th-percentile time of one control step (the MPC's
correction; the simulation's two 1 ms steps apart), the wall time of each whole replay (MPC build included) and its
real-time factor (wall / simulated time), whether the robot stayed upright, and the base drift as a share of the
distance.

    PYTHONPATH=python python3 benches/mpc.py [--cycles 5] [--mass 1.1 0.9] [--plan /tmp/amble.npz]

--plan: the solved plan is saved there on the first run and loaded on later ones (the solve takes 30-60 s).
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
from legkit.optimize.gaits import amble_plan_problem, plan_amble, stall_torque_bounds  # noqa: E402
from legkit.optimize.tracking import MPC, TrackingModel, heavier, track  # noqa: E402
from legkit.robots.motors import QUADRUPED_MOTOR  # noqa: E402
from legkit.robots.quadruped import build_quadruped  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cycles", type=int, default=5)
    parser.add_argument("--mass", type=float, nargs="*", default=[1.1, 0.9], help="plant mass factors besides 1")
    parser.add_argument("--plan", type=Path, default=None, help="npz file to save the solved plan to, or load it from")
    args = parser.parse_args()

    robot = build_quadruped(AMBLE_QUADRUPED)
    if args.plan is not None and args.plan.exists():
        fine = amble_plan_problem(robot)
        x = np.load(args.plan)["x"]
        print(f"plan loaded from {args.plan}")
    else:
        start = time.perf_counter()
        plan = plan_amble(robot)
        fine, result = plan.problem, plan.result
        x = result.best()[0]
        print(f"plan solved: {result.status}, {time.perf_counter() - start:.1f} s")
        if args.plan is not None:
            np.savez(args.plan, x=x)
    problem, x = fine.whole_cycle(x)
    trajectory = problem.unpack(x)
    motors = stall_torque_bounds(QUADRUPED_MOTOR, problem.nu)

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


if __name__ == "__main__":
    main()
