"""Replay benchmark of issue 13: the Fig. 3 amble (0.67 m/s, period 1.25 s, mirrored half cycle, J_s2 with the
exact-Hessian polish; with --coarse-intervals solved on that mesh, then refined onto --intervals by
`MultiphaseProblem.refine`) planned on a mesh fine enough to be a motion of its model (--intervals 16: every interval's
drift under 1 deg, `legkit.optimize.interval_drift`) with a floor on the stance normal forces (--min-normal-force)
against a narrower friction cone than the simulation's (--mu) and within (1 - --torque-margin) of the motors' torque,
then simulated in `lk.Simulation` for --cycles cycles
(2 mm sphere feet, friction 0.8) under joint PD + feed-forward (kp 50, kd 1) and under the contact-constrained
model-predictive tracking of `legkit.optimize.tracking`, from the plan's start and from starts with the joint
angles perturbed (--perturbations of --perturbation rad, normal). Prints the solve, the drift of the mesh, and per
run: upright, when it fell, and the base drift as a share of the distance.

    PYTHONPATH=python python3 benches/gait_tracking.py [--intervals 16] [--coarse-intervals 4] [--min-normal-force 3] [--mu 0.6]
        [--torque-margin 0] [--cycles 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import interval_drift
from legkit.optimize.gaits import AmbleOptions, plan_amble, stall_torque_bounds
from legkit.optimize.replay import replay
from legkit.optimize.tracking import TrackingModel, track
from legkit.robots.motors import QUADRUPED_MOTOR
from legkit.robots.quadruped import build_quadruped


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--intervals", type=int, default=16)
    parser.add_argument("--coarse-intervals", type=int, default=None, help="solve on this mesh first, then refine onto --intervals")
    parser.add_argument("--min-normal-force", type=float, default=3.0)
    parser.add_argument("--mu", type=float, default=0.6)
    parser.add_argument("--torque-margin", type=float, default=0.0)
    parser.add_argument("--cycles", type=int, default=5)
    parser.add_argument("--perturbations", type=int, default=2)
    parser.add_argument("--perturbation", type=float, default=0.01)
    args = parser.parse_args()

    robot = build_quadruped(AMBLE_QUADRUPED)

    start = time.perf_counter()
    options = AmbleOptions(friction=args.mu, min_normal_force=args.min_normal_force, torque_margin=args.torque_margin)
    plan = plan_amble(robot, intervals=args.intervals, coarse_intervals=args.coarse_intervals or 0, options=options)
    total = time.perf_counter() - start
    result = plan.result
    problem, x = plan.problem.whole_cycle(result.best()[0])
    trajectory = problem.unpack(x)
    drift = interval_drift(problem, x).worst(True)
    refined = f" (refined from {args.coarse_intervals})" if args.coarse_intervals else ""
    print(f"plan: {args.intervals} intervals per phase{refined}, stance force >= {args.min_normal_force} N, mu {args.mu}, "
          f"torque margin {args.torque_margin}: {result.status}, "
          f"{result.iterations} iterations, {result.wall_time:.1f} s ({total:.1f} s in all), violation {problem.nlp().violation(x):.1e}, "
          f"S_H min {min(np.concatenate(problem.stability_index(x))):.3f}, durations {np.round(trajectory.durations[:2], 3)} s")
    print(f"largest drift over one interval: {drift['attitude [deg]']:.2f} deg, {drift['joints']:.3f} rad, {drift['joint rates']:.2f} rad/s")

    pd = replay(problem, trajectory, args.cycles, kp=50.0, kd=1.0, control_every=1)
    print(f"PD + feed-forward (kp 50, kd 1): upright {pd.upright}, fell at {pd.fell_at:.3f} s, drift {100 * pd.drift_fraction:.1f} %")
    start = time.perf_counter()
    model = TrackingModel.build(problem, trajectory)
    print(f"tracking model: {len(model.A)} samples linearised in {time.perf_counter() - start:.1f} s")
    rng = np.random.default_rng(0)
    offsets = [None] + [rng.normal(0.0, args.perturbation, problem.nu) for _ in range(args.perturbations)]
    motors = stall_torque_bounds(QUADRUPED_MOTOR, problem.nu)  # the plan keeps torque_margin of them to the MPC
    for offset in offsets:
        start = time.perf_counter()
        run = track(problem, trajectory, args.cycles, model=model, joint_offset=offset, torque_bounds=motors)
        label = "plan's start" if offset is None else f"joints perturbed by {np.abs(offset).max():.4f} rad at most"
        print(f"MPC tracking, {label}: upright {run.upright}, fell at {run.fell_at:.3f} s, drift {100 * run.drift_fraction:.1f} % "
              f"of {run.distance:.2f} m, {time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
