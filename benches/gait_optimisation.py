"""Gait optimisation benchmark (issue 13): the Fig. 3 amble of file 003 (0.67 m/s, period 1.25 s, duty 0.5,
full 3D model, 19 configuration states) maximising the worst-case S_H (J_s2) on IPOPT.

Prints, for a cold start (from `legkit gait`'s hand-built reference) and a warm start (from the optimum at a
neighbouring speed): IPOPT status, iterations, wall time, the share of it spent in legkit's function and
Jacobian evaluations, the largest constraint violation re-evaluated by legkit's dynamics, and the worst S_H.

    PYTHONPATH=python python3 benches/gait_optimisation.py [--intervals 4] [--max-iter 1000] [--neighbour 0.6]
"""

from __future__ import annotations

import argparse

import legkit.optimize as lo
from legkit.experiments.gait import AMBLE_QUADRUPED, QUADRUPED_MOTOR
from legkit.optimize.gaits import amble_problem, amble_reference, guess_from_reference
from legkit.robots.quadruped import DIAGONAL_PAIRS, build_quadruped


def report(label: str, problem: lo.MultiphaseProblem, result: lo.SolveResult) -> None:
    """One row; violation and S_H min of the kept point (`SolveResult.best`), re-evaluated by legkit."""
    share = 100.0 * result.evaluation_time / result.wall_time
    x, objective = result.best()
    print(f"{label:<34} {result.status:<28} {result.iterations:6d} {result.wall_time:9.2f} {share:8.1f} "
          f"{problem.nlp().violation(x):10.2e} {-objective:10.4g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--intervals", type=int, default=4, help="collocation intervals per phase")
    parser.add_argument("--max-iter", type=int, default=1000)
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--speed", type=float, default=0.67)
    parser.add_argument("--neighbour", type=float, default=0.60, help="speed [m/s] whose optimum warm-starts --speed")
    args = parser.parse_args()
    robot = build_quadruped(AMBLE_QUADRUPED)
    objective = [lo.MinMaxStability(2.0, DIAGONAL_PAIRS)]

    def problem(speed: float) -> lo.MultiphaseProblem:
        return amble_problem(robot, objective, speed, 1.25, args.intervals, QUADRUPED_MOTOR)

    def cold(speed: float) -> tuple[lo.MultiphaseProblem, lo.SolveResult]:
        p = problem(speed)
        x0 = p.pack(guess_from_reference(p, amble_reference(robot, speed, 1.25, args.intervals)))
        x0[p.p1_index] = min(s.min() for s in p.stability_index(x0))
        return p, p.solve(x0, tol=args.tol, max_iter=args.max_iter)[1]

    print(f"amble, {args.intervals} intervals per phase, tol {args.tol:g}; IPOPT (casadi {__import__('casadi').__version__}) "
          "with L-BFGS and MUMPS")
    print(f"{'run':<34} {'status':<28} {'iter':>6} {'wall [s]':>9} {'f+J [%]':>8} {'violation':>10} {'S_H min':>10}")
    target, result = cold(args.speed)
    print(f"  ({target.n} variables, {target.m} constraints, {len(target.jac_rows)} Jacobian nonzeros)")
    report(f"cold, {args.speed:g} m/s", target, result)
    other, neighbour = cold(args.neighbour)
    report(f"cold, {args.neighbour:g} m/s (the neighbour)", other, neighbour)
    warm = target.solve(neighbour.best()[0], tol=args.tol, max_iter=args.max_iter)[1]  # primal start only
    report(f"warm from {args.neighbour:g} m/s", target, warm)


if __name__ == "__main__":
    main()
