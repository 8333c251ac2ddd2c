"""Gait optimisation benchmark: the Fig. 3 amble of [Hardt 2002] (0.67 m/s, period 1.25 s, duty 0.5,
full 3D model, 19 configuration states) maximising the worst-case S_H (J_s2) on IPOPT, or (--gait walk) the
biped walk of Sect. 6 at 1.8 km/h minimising J_e1. By default the amble's half cycle is transcribed, the other
half its mirror image, and the walk's whole cycle (`AMBLE_MIRROR`, `WALK_MIRROR`; --mirror / --no-mirror).

Prints, for a cold start (from `legkit gait`'s hand-built reference, feasibility first, then J_s2 with the exact
Hessian, or with --derivatives legkit L-BFGS polished with the exact Hessian, durations held then free; --no-polish:
L-BFGS only) and a warm start (the exact
Hessian from the point and multipliers of the solve at a neighbouring speed, its travel stretched to the new
speed: `problem.solve(problem.continued(result, speed))`): IPOPT status, iterations, IPOPT's wall time, the
share of it spent evaluating the functions and their derivatives (the Hessian's included), the largest constraint
violation re-evaluated
by legkit's kernels, p1, the worst published S_H (eq. 10) and the largest stance-foot acceleration at the
midpoints (`MultiphaseProblem.stance_accelerations`; the knots hold it at 0, docs/optimize.md).

    PYTHONPATH=python python3 benches/gait_optimisation.py [--intervals 4] [--max-iter 300] [--neighbour 0.6] [--no-mirror] [--no-polish]
    PYTHONPATH=python python3 benches/gait_optimisation.py --compare --intervals 16   # solver settings side by side
    PYTHONPATH=python python3 benches/gait_optimisation.py --split --intervals 16     # where an iteration's CPU goes, cold and warm
    PYTHONPATH=python python3 benches/gait_optimisation.py --bounds --intervals 16    # which bound holds S_H
    PYTHONPATH=python python3 benches/gait_optimisation.py --sequence --intervals 16  # warm starts across speeds

The walk (cold, from `legkit gait`'s hand-built walk, constraints first by `solve_walk`): status, iterations,
wall and CPU time of the solve, the evaluation share, the violation re-evaluated by legkit's kernels, J_e1
and the largest RNEA residual recomputed by `lk.rnea`.

    PYTHONPATH=python python3 benches/gait_optimisation.py --gait walk [--intervals 4] [--max-iter 600]
"""

from __future__ import annotations

import argparse
import gc
import re
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

import legkit.optimize as lo
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize.assembly import DERIVATIVES
from legkit.optimize.checks import inverse_dynamics_residuals, midpoint_stance_acceleration
from legkit.optimize.gaits import (
    AMBLE_DERIVATIVES,
    AMBLE_IPOPT,
    AMBLE_MIRROR,
    AMBLE_REGULARISED_FIRST,
    AMBLE_WARM_IPOPT,
    WALK_DERIVATIVES,
    WALK_MIRROR,
    AmbleOptions,
    amble_plan_problem,
    amble_problem,
    amble_reference,
    guess_from_reference,
    solve_walk,
    walk_problem,
    walk_reference,
)
from legkit.robots.biped import build_biped
from legkit.robots.motors import BIPED_MOTOR, QUADRUPED_MOTOR
from legkit.robots.quadruped import DIAGONAL_PAIRS, build_quadruped


def worst_s_h(problem: lo.MultiphaseProblem, x: np.ndarray) -> float:
    """The worst published S_H (eq. 10) over the points of x."""
    return min(s.min() for s in problem.stability_index(x))


def warm_solve(target: lo.MultiphaseProblem, last: lo.SolveResult, speed: float, args: argparse.Namespace, ipopt: dict) -> lo.SolveResult:
    """`target` solved from `last`, an optimum at `speed` [m/s] (`continued`), with the exact Hessian and `ipopt`'s options."""
    return target.solve(target.continued(last, speed), derivatives="exact", tol=args.tol, max_iter=args.polish_max_iter,
                        options=ipopt, regularised_first=AMBLE_REGULARISED_FIRST)[1]


def report(label: str, problem: lo.MultiphaseProblem, result: lo.SolveResult, cpu: float | None = None) -> None:
    """One row; violation and S_H min (published, eq. 10) of the kept point (`SolveResult.best`), re-evaluated
    by legkit's kernels; the solve's wall time, or its CPU time when given."""
    share = 100.0 * result.evaluation_time / result.wall_time
    x, objective = result.best()
    s_h = worst_s_h(problem, x)
    stance = midpoint_stance_acceleration(problem, x)
    print(f"{label:<{44 if cpu is not None else 30}} {result.status:<28} {result.iterations:6d} "
          f"{result.wall_time if cpu is None else cpu:{8 if cpu is not None else 9}.2f} {share:8.1f} "
          f"{problem.nlp().violation(x):10.2e} {-objective:9.4g} {s_h:9.4g} {stance:10.3g}", flush=True)


#: IPOPT's timing statistics (`print_timing_statistics`) that `split` reads: CPU seconds of the whole solve, of its
#: linear algebra (the KKT factorisations and solves; the adaptive barrier update's among them), of the barrier update
#: (its solves included), and of legkit's Hessian and of its values, gradient and Jacobian (one call computes the
#: gradient with the Jacobian, charged to whichever IPOPT asks for first).
TIMINGS = {"whole solve": "OverallAlgorithm", "KKT factorisations and solves": "PDSystemSolverTotal",
           "barrier update (its solves included)": "UpdateBarrierParameter",
           "Lagrangian Hessian": "Lagrangian Hessian",
           "values, gradient and Jacobian": "(?:Objective function|Objective function gradient|Equality constraints|Inequality constraints|"
                                            "Equality constraint Jacobian|Inequality constraint Jacobian)"}


def components(solve: Callable[[dict], lo.SolveResult], ipopt: dict) -> tuple[lo.SolveResult, float, int, dict[str, float]]:
    """One solve under IPOPT's timing statistics: its result, its CPU time, and its last IPOPT stage's iterations and
    CPU seconds by component (`TIMINGS`)."""
    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "ipopt.txt"
        cpu = time.process_time()
        result = solve({**ipopt, "print_timing_statistics": "yes", "output_file": str(log), "file_print_level": 5})
        cpu = time.process_time() - cpu
        gc.collect()  # IPOPT's journal writes its file out when the solver is freed
        text = log.read_text()
    count = re.search(r"Number of Iterations\.*:\s*(\d+)", text)
    if count is None:
        raise RuntimeError(f"no iteration count in IPOPT's output:\n{text[-2000:]}")
    seconds = {label: sum(float(m) for m in re.findall(rf"^ *{pattern}\.*: *([0-9.]+)", text, flags=re.MULTILINE))
               for label, pattern in TIMINGS.items()}
    return result, cpu, int(count.group(1)), seconds


def print_components(seconds: dict[str, float], iterations: int) -> None:
    print(f"  {'component':<34} {'[s]':>8} {'per iteration [s]':>18}")
    for label, value in seconds.items():
        print(f"  {label:<34} {value:8.2f} {value / iterations:18.4f}")


def split(problem: lo.MultiphaseProblem, solve: Callable[[dict], lo.SolveResult], target: lo.MultiphaseProblem,
          warm: Callable[[dict, lo.SolveResult], lo.SolveResult]) -> None:
    """--split: one cold solve's last IPOPT stage (J_s2), then `warm` (a solve of `target` from the cold optimum), by
    component per iteration from IPOPT's timing statistics; then the Lagrangian Hessian by block at the cold optimum
    (CPU, median of 5 evaluations)."""
    result, cpu, iterations, seconds = components(solve, AMBLE_IPOPT)
    x, objective = result.best()
    print(f"cold solve: {result.status}, {result.iterations} IPOPT iterations in all, {cpu:.1f} s of CPU, p1 {-objective:.5f}, "
          f"S_H min {worst_s_h(problem, x):.5f} N m s; its J_s2 stage, {iterations} iterations, by component (CPU):")
    print_components(seconds, iterations)
    warmed, cpu, iterations, seconds = components(lambda ipopt: warm(ipopt, result), AMBLE_WARM_IPOPT)
    x_warm, objective_warm = warmed.best()
    print(f"warm start at {target.speed:g} m/s from that optimum (`continued`, AMBLE_WARM_IPOPT): {warmed.status}, {iterations} "
          f"iterations, {cpu:.1f} s of CPU, p1 {-objective_warm:.5f}, S_H min {worst_s_h(target, x_warm):.5f} "
          "N m s; by component (CPU):")
    print_components(seconds, iterations)
    lam = np.random.default_rng(0).normal(size=problem.m)
    timed: dict[str, float] = {}
    for block, start, stop in zip(problem.blocks, problem._offsets, problem._offsets[1:]):
        name = type(block).__name__
        function = getattr(block, "function", None)
        if function is not None:
            name += " " + function.__qualname__.replace(".<locals>", "")
        runs = []
        for _ in range(5):
            begin = time.process_time()
            block.hessian(x, lam[start:stop])
            runs.append(time.process_time() - begin)
        timed[name] = timed.get(name, 0.0) + float(np.median(runs))
    whole = []
    for _ in range(5):
        begin = time.process_time()
        problem.hessian(x, 1.0, lam)
        whole.append(time.process_time() - begin)
    print(f"the Lagrangian Hessian at the optimum: {1e3 * np.median(whole):.1f} ms (median of 5); by block [ms]:")
    for name, block_seconds in sorted(timed.items(), key=lambda item: -item[1])[:8]:
        print(f"  {1e3 * block_seconds:7.2f}  {name}")


def walk(args: argparse.Namespace) -> None:
    """The biped walk at 0.5 m/s minimising J_e1, cold (module docstring)."""
    derivatives = args.derivatives or WALK_DERIVATIVES
    robot = build_biped()
    intervals = (max(1, args.intervals // 4), args.intervals)
    problem = walk_problem(robot, 0.5, BIPED_MOTOR, intervals, mirror=args.mirror)
    guess = guess_from_reference(problem, walk_reference(robot, 0.5, intervals))
    print(f"biped walk, 1.8 km/h, intervals {intervals} per (double, single) support, tol {args.tol:g}: {problem.n} variables, "
          f"{problem.m} constraints, {len(problem.jac_rows)} Jacobian nonzeros ({'mirrored half' if args.mirror else 'whole'} cycle); "
          f"constraints (legkit, L-BFGS), then J_e1 ({derivatives})")
    cpu = time.process_time()
    _, result = solve_walk(problem, guess, derivatives, tol=args.tol, max_iter=args.max_iter)
    cpu = time.process_time() - cpu
    x, objective = result.best()
    residual = max(np.abs(r).max() for r in inverse_dynamics_residuals(problem, x))
    print(f"{'status':<28} {'iter':>6} {'wall [s]':>9} {'CPU [s]':>8} {'f+J [%]':>8} {'violation':>10} {'J_e1 [J/m]':>11} {'|rnea - Bu|':>12}")
    print(f"{result.status:<28} {result.iterations:6d} {result.wall_time:9.2f} {cpu:8.2f} {100.0 * result.evaluation_time / result.wall_time:8.1f} "
          f"{problem.nlp().violation(x):10.2e} {objective:11.5g} {residual:12.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gait", choices=("amble", "walk"), default="amble")
    parser.add_argument("--intervals", type=int, default=4, help="collocation intervals per (amble / single-support) phase")
    parser.add_argument("--max-iter", type=int, default=300, help="IPOPT iteration limit (per continuation stage)")
    parser.add_argument("--tol", type=float, default=1e-6)
    parser.add_argument("--speed", type=float, default=0.67)
    parser.add_argument("--neighbour", type=float, default=0.60, help="speed [m/s] whose optimum warm-starts --speed")
    parser.add_argument("--derivatives", choices=DERIVATIVES, help="default: the gait's (AMBLE_ / WALK_DERIVATIVES)")
    parser.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                        help="transcribe half the cycle, the other half its mirror image (--no-mirror: the whole cycle); default: the gait's "
                             "(AMBLE_ / WALK_MIRROR)")
    parser.add_argument("--polish", action=argparse.BooleanOptionalAction, default=True,
                        help="amble, --derivatives legkit: after the L-BFGS runs, an exact-Hessian polish (durations held, then free)")
    parser.add_argument("--polish-max-iter", type=int, default=1000, help="amble: IPOPT iteration limit of the polish and of the warm start")
    parser.add_argument("--split", action="store_true", help="amble: one cold solve's CPU by component per iteration, a warm start's "
                        "from its optimum at --neighbour, and the Lagrangian Hessian's by block")
    parser.add_argument("--bounds", action="store_true", help="amble: the plan's problem with each execution bound and the "
                        "force floor switched off in turn (what holds S_H)")
    parser.add_argument("--sequence", action="store_true", help="amble: the plan's problem at 0.55 to 0.75 m/s, the first "
                        "cold, each next warm from the last, under the adaptive and the monotone barrier update")
    parser.add_argument("--compare", action="store_true",
                        help="amble: the cold solve under each solver setting side by side (exact Hessian with and without "
                             "perturb_always_cd, L-BFGS with the polish), CPU time per row")
    args = parser.parse_args()
    if args.gait == "walk":
        args.mirror = WALK_MIRROR if args.mirror is None else args.mirror
        walk(args)
        return
    args.derivatives = args.derivatives or AMBLE_DERIVATIVES
    args.mirror = AMBLE_MIRROR if args.mirror is None else args.mirror
    robot = build_quadruped(AMBLE_QUADRUPED)
    objective = [lo.MinMaxStability(2.0, DIAGONAL_PAIRS)]
    args.polish = args.polish and args.derivatives == "legkit"  # the polish follows an L-BFGS run
    options = {"tol": args.tol, "max_iter": args.max_iter, "derivatives": args.derivatives, "options": AMBLE_IPOPT,
               "regularised_first": AMBLE_REGULARISED_FIRST, "polish": args.polish,
               "polish_max_iter": args.polish_max_iter}

    def cold(speed: float, **variant: object) -> tuple[lo.MultiphaseProblem, lo.SolveResult]:
        # Soft touchdowns, as `legkit gait --optimize` solves it (its --max-impulse default).
        p = amble_problem(robot, objective, speed, 1.25, args.intervals, QUADRUPED_MOTOR, max_impulse=0.0, mirror=args.mirror)
        guess = guess_from_reference(p, amble_reference(robot, speed, 1.25, args.intervals))
        return p, p.solve(guess, feasibility_first=True, **{**options, **variant})[1]

    if args.split:
        # The problem `legkit gait --optimize` solves (`amble_plan_problem`: a stance-force floor, the plan's friction).
        problem = amble_plan_problem(robot, args.intervals, args.speed, 1.25, AmbleOptions(mirror=args.mirror))
        guess = guess_from_reference(problem, amble_reference(robot, args.speed, 1.25, args.intervals))
        print(f"amble plan, {args.intervals} intervals per phase, {'mirrored half' if args.mirror else 'whole'} cycle, {args.speed:g} m/s: "
              f"{problem.n} variables, {problem.m} constraints, {len(problem.jac_rows)} Jacobian and {len(problem.hess_rows)} Hessian nonzeros")
        target = amble_plan_problem(robot, args.intervals, args.neighbour, 1.25, AmbleOptions(mirror=args.mirror))

        split(problem, lambda ipopt: problem.solve(guess, feasibility_first=True, **{**options, "options": ipopt})[1], target,
              lambda ipopt, last: warm_solve(target, last, args.speed, args, ipopt))
        return

    if args.bounds or args.sequence:
        plan = AmbleOptions(mirror=args.mirror)
        print(f"amble plan (`amble_plan_problem`), {args.intervals} intervals per phase, "
              f"{'mirrored half' if args.mirror else 'whole'} cycle, tol {args.tol:g}:")
        print(f"{'run':<44} {'status':<28} {'iter':>6} {'CPU [s]':>8} {'f+J+H [%]':>9} {'violation':>10} {'p1':>9} "
              f"{'S_H min':>9} {'foot acc':>10}")
    if args.bounds:
        execution = {"max_yaw": np.inf, "max_load_rate": np.inf, "dense_rates": False, "torque_rise": 0.0}
        floorless = replace(plan, min_normal_force=0.0)
        variants = [("none off (the CLI's problem)", plan, {})] + [(f"{key} off", plan, {key: value}) for key, value in execution.items()]
        variants += [("min_normal_force off", floorless, {}), ("the four execution bounds off", plan, execution),
                     ("those and the force floor off", floorless, execution)]
        for label, settings, off in variants:
            problem = amble_plan_problem(robot, args.intervals, args.speed, 1.25, settings, **off)
            cpu = time.process_time()
            result = problem.solve(guess_from_reference(problem, amble_reference(robot, args.speed, 1.25, args.intervals)),
                                   feasibility_first=True, **options)[1]
            report(label, problem, result, time.process_time() - cpu)
        return
    if args.sequence:
        # The first speed cold, then each next from the last under each barrier update; and the first speed's optimum
        # restarted on itself and on a speed 0.01 m/s faster: what a warm start costs when there is almost nothing to do.
        speeds = (0.55, 0.60, 0.65, 0.70, 0.75)
        problem = amble_plan_problem(robot, args.intervals, speeds[0], 1.25, plan)
        cpu = time.process_time()
        first = problem.solve(guess_from_reference(problem, amble_reference(robot, speeds[0], 1.25, args.intervals)),
                              feasibility_first=True, **options)[1]
        report(f"{speeds[0]:g} m/s, cold", problem, first, time.process_time() - cpu)
        def warm(speed: float, last: tuple[float, lo.SolveResult], update: str, warm_options: dict) -> lo.SolveResult:
            target = amble_plan_problem(robot, args.intervals, speed, 1.25, plan)
            cpu = time.process_time()
            result = warm_solve(target, last[1], last[0], args, warm_options)
            report(f"{speed:g} m/s, warm from {last[0]:g}, {update}", target, result, time.process_time() - cpu)
            return result

        for update, warm_options in (("adaptive", AMBLE_WARM_IPOPT), ("monotone", AMBLE_IPOPT)):
            for speed in (speeds[0], speeds[0] + 0.01):
                warm(speed, (speeds[0], first), update, warm_options)
            last = (speeds[0], first)
            for speed in speeds[1:]:
                last = (speed, warm(speed, last, update, warm_options))
        return

    if args.compare:
        print(f"amble, {args.intervals} intervals per phase, {'mirrored half' if args.mirror else 'whole'} cycle, tol {args.tol:g}, "
              "cold (feasibility first, then J_s2); IPOPT with MUMPS; the same problem for each solver setting:")
        print(f"{'solver setting':<44} {'status':<28} {'iter':>6} {'CPU [s]':>8} {'f+J+H [%]':>9} {'violation':>10} {'p1':>9} "
              f"{'S_H min':>9} {'foot acc':>10}")
        without = {key: value for key, value in AMBLE_IPOPT.items() if key != "perturb_always_cd"}
        for label, variant in (("exact Hessian, perturb_always_cd (default)", {"derivatives": "exact", "polish": False}),
                               ("exact Hessian, IPOPT's default perturbation", {"derivatives": "exact", "polish": False, "options": without}),
                               ("L-BFGS, then the exact-Hessian polish", {"derivatives": "legkit", "polish": True})):
            cpu = time.process_time()
            problem, result = cold(args.speed, **variant)
            report(label, problem, result, time.process_time() - cpu)
        return

    print(f"amble, {args.intervals} intervals per phase, tol {args.tol:g}; IPOPT (casadi {__import__('casadi').__version__}), "
          f"MUMPS, {args.derivatives} derivatives, {'mirrored half' if args.mirror else 'whole'} cycle; cold: feasibility first, then J_s2"
          + (", then an exact-Hessian polish" if args.polish else ""))
    print(f"{'run':<30} {'status':<28} {'iter':>6} {'wall [s]':>9} {'f+J+H [%]':>9} {'violation':>10} "
          f"{'p1':>9} {'S_H min':>9} {'foot acc':>10}")
    target, result = cold(args.speed)
    print(f"  ({target.n} variables, {target.m} constraints, {len(target.jac_rows)} Jacobian and {len(target.hess_rows)} Hessian nonzeros)")
    report(f"cold, {args.speed:g} m/s", target, result)
    other, neighbour = cold(args.neighbour)
    report(f"cold, {args.neighbour:g} m/s (the neighbour)", other, neighbour)
    warmed = warm_solve(target, neighbour, args.neighbour, args, AMBLE_WARM_IPOPT)
    report(f"warm from {args.neighbour:g} m/s, exact", target, warmed)


if __name__ == "__main__":
    main()
