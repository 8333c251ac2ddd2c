"""Mesh refinement (`MultiphaseProblem.refined`, `refine`): a coarse optimum carried onto a finer mesh."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import MinMaxStability, SolveResult
from legkit.optimize.gaits import AMBLE_IPOPT, amble_problem, amble_reference, guess_from_reference
from legkit.robots.motors import QUADRUPED_MOTOR
from legkit.robots.quadruped import DIAGONAL_PAIRS, build_quadruped

ROBOT = build_quadruped(AMBLE_QUADRUPED)


def amble(intervals: int, **options):
    return amble_problem(ROBOT, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, intervals, QUADRUPED_MOTOR, **options)


def test_refined_interpolates_every_point_variable_and_copies_the_rest():
    coarse, fine = amble(2), amble(4)
    rng = np.random.default_rng(5)
    x = coarse.gauged(coarse.pack(guess_from_reference(coarse, amble_reference(ROBOT, 0.67, 1.25, 2))) + 0.01 * rng.normal(size=coarse.n))
    refined = fine.refined(coarse, x)
    for fine_index, coarse_index in zip(fine.point_index, coarse.point_index):
        # Twice the intervals: every other fine point is a coarse point, the ones between are their means.
        np.testing.assert_array_equal(refined[fine_index[::2]], x[coarse_index])
        np.testing.assert_allclose(refined[fine_index[1::2]], 0.5 * (x[coarse_index[:-1]] + x[coarse_index[1:]]), rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(refined[fine.duration_index], x[coarse.duration_index])
    assert refined[fine.p1_index] == x[coarse.p1_index]
    for k, index in coarse.impulse_index.items():
        np.testing.assert_array_equal(refined[fine.impulse_index[k]], x[index])
    np.testing.assert_array_equal(coarse.refined(coarse, x), x)  # onto its own mesh: unchanged


def test_refined_refuses_another_problem_or_a_wrong_point():
    coarse, fine = amble(2), amble(4)
    x = np.zeros(coarse.n)
    with pytest.raises(ValueError, match="coarse must be"):
        fine.refined(amble(2, mirror=True), np.zeros(amble(2, mirror=True).n))  # half the phases
    normal_only = dataclasses.replace(coarse, force_dims=1)  # fewer force variables per point
    with pytest.raises(ValueError, match="coarse must be"):
        fine.refined(normal_only, np.zeros(normal_only.n))
    with pytest.raises(ValueError, match="x must have"):
        fine.refined(coarse, x[:-1])
    result = SolveResult(x, 0.0, "Solve_Succeeded", True, 0, 0.0, 0.0, 0.0)
    for fraction in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="stability_fraction"):
            fine.refine(coarse, result, stability_fraction=fraction)


@pytest.mark.slow
def test_refine_makes_the_coarse_optimum_a_solution_of_the_fine_mesh_holding_its_stability_fraction():
    coarse, fine = (amble(n, friction=0.6, max_impulse=0.0, mirror=True, min_normal_force=3.0) for n in (2, 4))
    _, result = coarse.solve(guess_from_reference(coarse, amble_reference(ROBOT, 0.67, 1.25, 2)), derivatives="legkit",
                             feasibility_first=True, polish=True, max_iter=300, options=AMBLE_IPOPT)
    assert result.success
    coarse_s_h = result.x[coarse.p1_index]
    # REFINE_STABILITY's 0.2: with the amble's execution bounds, holding half the coarse optimum on the finer mesh
    # needed more than 300 iterations (0.2: 28).
    _, refined = fine.refine(coarse, result, stability_fraction=0.2, max_iter=300, options=AMBLE_IPOPT)
    assert refined.success and refined.iterations > result.iterations
    x = refined.x
    # Re-evaluated by legkit's own dynamics, and the published worst-case S_H, not the held bound.
    assert fine.nlp().violation(x) < 1e-6
    assert x[fine.p1_index] == 0.2 * coarse_s_h
    assert min(s.min() for s in fine.stability_index(x)) >= 0.2 * coarse_s_h - 1e-6
