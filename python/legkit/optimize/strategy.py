"""How a multiphase transcription is solved (the strategies over `solver.solve`): feasibility first, then the objective;
L-BFGS polished by the exact Hessian (`solve_problem`); mesh refinement from a coarse solution (`refine`, `refined`);
a warm start from a neighbouring speed's solution (`continued`)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from legkit._validation import instance
from legkit.optimize.assembly import Assembly
from legkit.optimize.layout import Trajectory
from legkit.optimize.solver import SolveResult, solve

#: IPOPT's initial barrier parameter for `solve_problem(polish=True)`. From the amble's point after
#: 600 L-BFGS J_s2 iterations the exact Hessian converged in 56 iterations with it; from the constraint
#: stage's point, in 326.
POLISH_MU_INIT = 1e-6


#: `solve_problem(polish=True)` ends the L-BFGS run on the objective once its best point has improved
#: by less than this (second) over this many (first) iterations, and polishes from there: L-BFGS on the amble's
#: J_s2 either climbs quickly and then slowly, or crawls (p1 +1.5e-7 per iteration).
POLISH_SWITCH = (20, 5e-3)

#: `refine` holds J_s2's p1 at this fraction of the coarse optimum's. The 0.67 m/s amble (3 N
#: floor, mu 0.6) from 4 onto 16 intervals per phase: 0.1, 0.2, 0.3 converged in 55, 40, 54 iterations (S_H min
#: 0.042, 0.044, 0.063); 0.5 and 0.8 did not in 300.
REFINE_STABILITY = 0.2


def solve_problem(problem: Assembly, guess: Trajectory | np.ndarray | SolveResult, derivatives: str = "exact", feasibility_first: bool = False,
          polish: bool = False, polish_max_iter: int = 1000, **options: Any) -> tuple[Trajectory, SolveResult]:
    """Solve from a guess (a Trajectory, a variable vector, or the `SolveResult` of a problem with the same
    layout, e.g. the gait at a neighbouring speed: its point and multipliers, a primal-dual warm start
    (`legkit.optimize.solver.WARM_START`)), with the Hessian of the Lagrangian (derivatives="exact", default) or
    IPOPT's L-BFGS approximation of it ("legkit"; `nlp`); options go to `legkit.optimize.solver.solve`.

    feasibility_first (problems with a MinMaxStability term): continuation in two IPOPT runs, first the
    constraints alone with p1 held below every S_H row, then the objective from that feasible point with p1
    at its worst S_H row. polish (with derivatives "legkit"): the L-BFGS run on the objective ends once it
    stalls (`POLISH_SWITCH`; options' stall replaces it, and applies to the objective's run only), then IPOPT
    runs twice more from its best point (its last after a stall), with the exact Hessian and a small initial
    barrier parameter (`POLISH_MU_INIT`), each within polish_max_iter iterations (the L-BFGS runs take options'
    max_iter): first with the phase durations held at that point's, then with them free, from the held run's
    point and multipliers. The durations are the slow variables: released at once, they crept to their
    optimum over ~1000 iterations on the mirrored amble at 0.60 m/s; held first, 116 + 180.
    L-BFGS keeps climbing where the exact Hessian converges.
    The result's iterations, times and history cover every run."""
    if polish and derivatives == "exact":
        raise ValueError("polish follows an L-BFGS solve (derivatives 'legkit'), got derivatives='exact'")
    if isinstance(guess, SolveResult):
        if feasibility_first:
            raise ValueError("feasibility_first does not apply to a warm start from a SolveResult")
        multipliers = guess.multipliers
        guess = guess.x
    else:
        multipliers = None
    x0 = problem.gauged(problem.pack(guess) if isinstance(guess, Trajectory) else problem.point(guess, "guess"))
    nlp = problem.nlp(derivatives)
    stall = options.pop("stall", POLISH_SWITCH if polish else None)  # on the objective's run only
    if polish:
        exact = {**options, "max_iter": polish_max_iter, "options": {**(options.get("options") or {}), "mu_init": POLISH_MU_INIT}}
    if feasibility_first and problem.uses_p1:
        x0 = x0.copy()
        x0[problem.p1_index] = 0.0
        x0[problem.p1_index] = min(b.values(x0).min() for b in problem.stability_blocks) - 1.0
        first = solve(problem.p1_held(derivatives, x0[problem.p1_index]), x0, **options)
        x0 = first.x.copy()
        x0[problem.p1_index] += min(b.values(x0).min() for b in problem.stability_blocks)
        result = solve(nlp, x0, stall=stall, **options)
        result = result.after(first)
    else:
        result = solve(nlp, x0, multipliers=multipliers, stall=stall, **options)
    if polish:
        start = result.x if result.status == "User_Requested_Stop" else result.best()[0]
        held = problem.nlp("exact")  # the phase durations held where L-BFGS left them
        held.x_lower[problem.duration_index] = held.x_upper[problem.duration_index] = start[problem.duration_index]
        result = solve(held, start, **exact).after(result)
        result = solve(problem.nlp("exact"), result.x, multipliers=result.multipliers, **exact).after(result)
    return problem.unpack(result.best()[0]), result


def refined(problem: Assembly, coarse: Assembly, x: np.ndarray) -> np.ndarray:
    """`x`, a point of `coarse` (the same problem on other intervals per phase), on this problem's mesh: each
    phase's point variables (knots and midpoints, evenly spaced in the phase's time) interpolated linearly, the
    durations, p1 and touchdown impulses copied, gauged (`gauged`)."""
    same = (len(coarse.phases) == len(problem.phases) and coarse.n - coarse.p1_index == problem.n - problem.p1_index
            and all(a.contacts == b.contacts for a, b in zip(coarse.phases, problem.phases))
            and all(a.shape[1] == b.shape[1] for a, b in zip(coarse.point_index, problem.point_index)))
    if not same:
        raise ValueError("coarse must be this problem with other intervals per phase (the same phases, contacts and variables per point)")
    x = coarse.point(x)
    fine = np.empty(problem.n)
    for index, coarse_index in zip(problem.point_index, coarse.point_index):
        s, s_coarse = np.linspace(0.0, 1.0, len(index)), np.linspace(0.0, 1.0, len(coarse_index))
        values = x[coarse_index]
        fine[index] = np.stack([np.interp(s, s_coarse, column) for column in values.T], axis=1)
    fine[problem.duration_index[0]:] = x[coarse.duration_index[0]:]  # durations, p1, impulses: the same layout
    return problem.gauged(fine)


def refine(problem: Assembly, coarse: Assembly, result: SolveResult, stability_fraction: float = REFINE_STABILITY,
           derivatives: str = "exact", **options: Any) -> tuple[Trajectory, SolveResult]:
    """Mesh refinement: `result`, solved on `coarse` (this problem on fewer intervals per phase), made a
    solution of this problem from its interpolation (`refined`). With J_s2 (MinMaxStability) p1 is held at
    stability_fraction x the coarse optimum's, so the worst-case S_H stays at least that and the run is a
    feasibility problem; other objective terms are minimised. J_s2 itself on the fine mesh took as many
    iterations from the interpolation as from the reference (16 intervals per phase: 709 against 712, ~2 min;
    `REFINE_STABILITY`). Options go to `legkit.optimize.solver.solve`; the result covers
    both solves."""
    instance(result, SolveResult, "result")
    if not 0.0 <= stability_fraction <= 1.0:
        raise ValueError(f"stability_fraction must be in [0, 1], got {stability_fraction}")
    x0 = refined(problem, coarse, result.best()[0])
    if problem.uses_p1:
        x0[problem.p1_index] *= stability_fraction
        nlp = problem.p1_held(derivatives, x0[problem.p1_index])
    else:
        nlp = problem.nlp(derivatives)
    fine = solve(nlp, x0, **options).after(result)
    return problem.unpack(fine.best()[0]), fine


def continued(problem: Assembly, result: SolveResult, speed: float) -> SolveResult:
    """`result`, solved at `speed` [m/s], as a warm start at this problem's speed (`solve(problem.continued(
    result, speed))`): the travel coordinate and its rate stretched by problem.speed / speed at every point, the
    multipliers kept (`legkit.optimize.solver.WARM_START`; for the amble, options=`legkit.optimize.gaits.AMBLE_WARM_IPOPT`:
    the 16-interval plan from 0.55 to 0.60 m/s in 53 iterations, against 102 cold at 0.55)."""
    if problem.travel_index is None or not problem.speed > 0.0:
        raise ValueError("continued needs a problem with a travel coordinate and a positive speed")
    if not speed > 0.0:
        raise ValueError(f"speed must be > 0, got {speed}")
    if result.x.shape != (problem.n,):
        raise ValueError(f"result.x must have shape ({problem.n},), got {result.x.shape}")
    travel = problem.travel_index
    rate = travel - 1 if problem.model.floating_base and travel >= 7 else travel  # a free-flyer's x, y: its body-frame rate
    x = result.x.copy()
    for index in problem.point_index:
        x[index[:, [travel, problem.nq + rate]]] *= problem.speed / speed
    return replace(result, x=x)
