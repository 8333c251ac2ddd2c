"""`legkit gait --optimize`: the amble transcription, its progress output, CSV, figure and simulation replay."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from legkit.experiments import gait
from legkit.experiments.gait import AMBLE_QUADRUPED, QUADRUPED_MOTOR
from legkit.optimize import MinMaxStability
from legkit.optimize.gaits import AMBLE_SUPPORT, amble_problem, amble_reference, guess_from_reference
from legkit.optimize.replay import periodic_samples
from legkit.robots.quadruped import DIAGONAL_PAIRS, build_quadruped


def test_amble_guess_lies_on_the_reference_and_wraps_around_by_one_stride():
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 2, QUADRUPED_MOTOR)
    guess = guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 2))
    assert [p.contacts for p in problem.phases] == list(AMBLE_SUPPORT)
    np.testing.assert_allclose(guess.durations, 1.25 / 4)
    # The feet on the ground in each phase are on the ground in the guess.
    for k, phase in enumerate(problem.phases):
        np.testing.assert_allclose(problem.foot_positions(guess.q[k], phase.contacts)[..., 2], 0.0, atol=1e-9)
    # Sampled over two cycles, the base advances by speed x period and repeats otherwise.
    t = np.array([0.1, 0.1 + 1.25])
    q, _, u = periodic_samples(problem, guess, t)
    assert abs(q[1, 0] - q[0, 0] - 0.67 * 1.25) < 1e-12
    np.testing.assert_allclose(q[1, 1:], q[0, 1:], atol=1e-12)
    np.testing.assert_allclose(u[1], u[0], atol=1e-12)


@pytest.mark.slow
def test_cli_optimize_prints_each_iteration_and_writes_csv_and_figure(tmp_path, capsys):
    iterations = 3
    assert gait.main(["--robot", "quadruped", "--optimize", "--intervals", "1", "--max-iter", str(iterations),
                      "--replay-cycles", "1", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    # Two continuation stages (constraints first, then J_s2), each with IPOPT's iterate 0 too.
    assert sum(line.strip().startswith("iter ") for line in out.splitlines()) == 2 * (iterations + 1)
    assert "replay: stayed upright" in out and "S_H min, reference" in out
    with (tmp_path / "gait_quadruped_optimized.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 4 * 3  # four phases of three collocation points
    assert [rows[3 * k]["support"] for k in range(4)] == ["+".join(p).upper() for p in AMBLE_SUPPORT]
    assert (tmp_path / "gait_quadruped_optimized.png").stat().st_size > 10_000
    # The replay's animation: meshcat's self-contained page, and a GIF of several frames.
    page = (tmp_path / "gait_quadruped_optimized.html").read_text()
    assert "the amble replayed in simulation" in page and len(page) > 500_000
    from PIL import Image

    with Image.open(tmp_path / "gait_quadruped_optimized.gif") as gif:
        assert gif.n_frames > 5


def test_smooth_stability_rows_bound_the_published_s_h_and_equal_it_before_a_diagonal_edge():
    # The smooth J_s2 rows (objectives.py docstring) against S_H as published (eq. 10) along the reference amble:
    # never above it, and equal wherever the published index takes the branch the smooth rows continue.
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 4, QUADRUPED_MOTOR)
    x = problem.pack(guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 4)))
    x[problem.p1_index] = 0.0
    published = problem.stability_index(x)
    equal = 0
    for k, block in enumerate(problem.stability_blocks):
        rows = block.values(x).reshape(len(published[k]), -1)
        lateral = set(problem.phases[k].contacts) not in [set(p) for p in DIAGONAL_PAIRS]
        if lateral:  # second row: d >= 0, the GCoM inside the lateral support line
            assert np.all(rows[:, 1] > 0.0)
        smooth = rows[:, 0] if lateral else rows.min(axis=1)
        assert np.all(smooth <= published[k] + 1e-12)
        equal += int(np.sum(np.isclose(smooth, published[k], rtol=1e-12, atol=1e-12)))
        if lateral:
            np.testing.assert_allclose(smooth, published[k], rtol=1e-12, atol=1e-12)  # lateral pairs: the same index
    # Diagonal phases: equal for the first points (GCoM before the edge), a strict bound after it passes.
    assert 18 + 2 * 4 <= equal < 36
