"""`legkit gait --optimize`: the amble transcription, its progress output, CSV, figure and simulation replay."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import legkit as lk
from legkit.experiments import gait
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import MinMaxStability, MultiphaseProblem, Phase, SolveResult, Trajectory, effort
from legkit.optimize.constraints.swing import CLEARANCE_FRACTIONS, clearance_blocks
from legkit.optimize.gaits import AMBLE_SUPPORT, amble_problem, amble_reference, guess_from_reference
from legkit.optimize.replay import clear_of_ground, foot_bottoms, foot_shapes, periodic_samples
from legkit.robots.motors import QUADRUPED_MOTOR
from legkit.robots.quadruped import DIAGONAL_PAIRS, LEGS, build_quadruped


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
@pytest.mark.parametrize("mode", ["whole_cycle", "mirrored_half", "l_bfgs", "l_bfgs_no_polish", "refined"])
def test_cli_optimize_prints_each_stage_and_writes_csv_and_figure(tmp_path, capsys, mode):
    # By default (--mirror) the half cycle is optimised and everything after sees the whole cycle, unrolled.
    iterations, intervals = 3, 2 if mode == "refined" else 1
    flags = {"whole_cycle": ["--no-mirror"], "mirrored_half": ["--no-animation"], "l_bfgs": ["--derivatives", "legkit", "--no-animation"],
             "l_bfgs_no_polish": ["--derivatives", "legkit", "--no-polish", "--no-animation"],
             "refined": ["--coarse-intervals", "1", "--no-animation"]}[mode]
    assert gait.main(["--robot", "quadruped", "--optimize", "--intervals", str(intervals), "--max-iter", str(iterations), "--polish-max-iter",
                      str(iterations), "--replay-cycles", "1", "--out", str(tmp_path)] + flags) == 0
    out = capsys.readouterr().out
    # Two continuation stages (constraints first, then J_s2), with L-BFGS two more (the exact-Hessian polish with the phase
    # durations held, then free) unless --no-polish, with --coarse-intervals one more (the refinement), each with IPOPT's
    # iterate 0 too. The stages on the coarse mesh name it.
    coarse = " on 1 interval" if mode == "refined" else ""
    stages = [f"constraints{coarse} (p1 held below S_H)", f"J_s2{coarse} ({'L-BFGS' if mode.startswith('l_bfgs') else 'exact Hessian'})"]
    stages += [f"polish{coarse}: exact Hessian, durations held", f"polish{coarse}: exact Hessian"] if mode == "l_bfgs" else []
    stages += [f"refine onto {intervals} intervals"] if mode == "refined" else []
    progress = [line.strip().rpartition(": ") for line in out.splitlines() if " iterations, objective " in line]  # one per stage
    assert [label for label, _, _ in progress] == stages
    assert all(0 < int(figures.split()[0]) <= iterations for _, _, figures in progress)
    assert "torso yaw max [deg]" in out and "foot load rate max" in out
    assert "replay: stayed upright" in out and "S_H min, reference" in out and "largest stance-foot acceleration" in out
    assert "largest drift over one interval, attitude [deg]" in out
    with (tmp_path / "gait_quadruped_optimized.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 4 * (2 * intervals + 1)  # four phases of their knots and midpoints
    assert [rows[(2 * intervals + 1) * k]["support"] for k in range(4)] == ["+".join(p).upper() for p in AMBLE_SUPPORT]
    assert (tmp_path / "gait_quadruped_optimized.png").stat().st_size > 10_000
    if mode != "whole_cycle":
        return
    # The replay's animation: meshcat's self-contained page, and a GIF of several frames.
    page = (tmp_path / "gait_quadruped_optimized.html").read_text()
    assert "the amble replayed in simulation" in page and len(page) > 500_000
    from PIL import Image

    with Image.open(tmp_path / "gait_quadruped_optimized.gif") as gif:
        assert gif.n_frames > 5


def test_swing_clearance_rows_are_the_swing_heights_on_the_replayed_cubics():
    # The rows of eq. 4 between the collocation points against the swing tips' heights where `periodic_samples`
    # (the replay's own interpolation) puts them, on the reference amble.
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 2, QUADRUPED_MOTOR)
    guess = guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 2))
    x = problem.pack(guess)
    fractions = np.array(CLEARANCE_FRACTIONS)
    start = 0.0
    for k, phase in enumerate(problem.phases):
        (block,) = clearance_blocks(problem, k)
        swing = [leg for leg in LEGS if leg not in phase.contacts]
        h = guess.durations[k] / phase.intervals
        t = start + h * (np.arange(phase.intervals)[:, None] + fractions[None, :])
        q, _, _ = periodic_samples(problem, guess, t.ravel())
        expected = problem.foot_positions(q, swing)[..., 2].reshape(phase.intervals, -1)
        np.testing.assert_allclose(block.values(x).reshape(phase.intervals, -1), expected, atol=1e-12)
        start += guess.durations[k]


def test_continued_stretches_the_travel_and_keeps_the_multipliers():
    robot = build_quadruped(AMBLE_QUADRUPED)
    slow, fast = (amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], speed, 1.25, 2, QUADRUPED_MOTOR) for speed in (0.6, 0.75))
    x = slow.pack(guess_from_reference(slow, amble_reference(robot, 0.6, 1.25, 2)))
    multipliers = (np.arange(slow.n, dtype=float), np.arange(slow.m, dtype=float))
    result = SolveResult(x, 0.0, "Solve_Succeeded", True, 0, 0.0, 0.0, 0.0, multipliers=multipliers)
    moved = fast.continued(result, 0.6)
    stretched = np.zeros(fast.n, dtype=bool)
    for index in fast.point_index:
        stretched[index[:, [0, fast.nq]]] = True  # base x and its body-frame rate
    np.testing.assert_allclose(moved.x[stretched], 1.25 * x[stretched], rtol=1e-15)
    np.testing.assert_array_equal(moved.x[~stretched], x[~stretched])
    assert moved.multipliers is multipliers and result.x is x
    with pytest.raises(ValueError, match="speed"):
        fast.continued(result, 0.0)


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


def test_periodic_samples_follow_the_collocation_cubic_and_keep_the_touchdown_jump():
    # Brute-force reference: a pendulum trajectory whose angle is a cubic of time, its rate and acceleration the
    # cubic's derivatives, given at the knots and midpoints; the samples between them are the cubic itself (the
    # Hermite–Simpson interpolant is exact for cubic states, and v, a quadratic, is exact too).
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 1.0, 0.0], None, lk.MassProperties.point(1.0, [0.0, 0.0, -0.5]), "rod")
    problem = MultiphaseProblem(model, [Phase((), 3, (0.9, 0.9))], objectives=[effort()], periodic=False,
                                initial=([0.0], [0.0]), final=([1.0], [0.0]))
    c = np.array([0.3, -1.2, 2.5, -0.7])

    def angle(s: np.ndarray) -> np.ndarray:
        return c[0] + c[1] * s + c[2] * s**2 + c[3] * s**3

    def rate(s: np.ndarray) -> np.ndarray:
        return c[1] + 2 * c[2] * s + 3 * c[3] * s**2

    t = np.linspace(0.0, 0.9, 7)
    trajectory = Trajectory([t], [angle(t)[:, None]], [rate(t)[:, None]], [np.sin(t)[:, None]], [np.zeros((7, 0, 3))],
                            np.array([0.9]), a=[(2 * c[2] + 6 * c[3] * t)[:, None]])
    s = np.linspace(0.0, 0.9, 101)[:-1]
    q, v, u = periodic_samples(problem, trajectory, s)
    np.testing.assert_allclose(q[:, 0], angle(s), atol=1e-12)
    np.testing.assert_allclose(v[:, 0], rate(s), atol=1e-12)
    np.testing.assert_allclose(u[:, 0], np.interp(s, t, np.sin(t)), atol=1e-12)  # linear controls
    # The amble's guess: an instant on a phase boundary is the state after the touchdown, an instant just
    # before it is the state before (the jump is not spread over the preceding interval).
    robot = build_quadruped(AMBLE_QUADRUPED)
    amble = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 2, QUADRUPED_MOTOR)
    guess = guess_from_reference(amble, amble_reference(robot, 0.67, 1.25, 2))
    guess.v[1][0] = guess.v[0][-1] + 1.0  # a velocity jump at the first touchdown
    boundary = guess.t[1][0]
    _, v, _ = periodic_samples(amble, guess, np.array([boundary - 1e-9, boundary]))
    np.testing.assert_allclose(v[0], guess.v[0][-1], atol=1e-6)
    np.testing.assert_allclose(v[1], guess.v[1][0], atol=1e-12)


def test_replay_start_puts_the_lowest_foot_sphere_on_the_ground():
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 2, QUADRUPED_MOTOR)
    q = amble_reference(robot, 0.67, 1.25, 2).q[0]
    radius = 0.005
    lifted = clear_of_ground(problem, q, radius)
    np.testing.assert_array_equal(np.delete(lifted, 2), np.delete(q, 2))  # only the base height changes
    # Brute force: points all over each sphere's surface, placed by forward kinematics.
    directions = np.random.default_rng(0).normal(size=(20_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for config, lowest in ((q, None), (lifted, 0.0)):
        poses = np.asarray(lk.forward_kinematics(problem.model, config))
        heights = [np.min((poses[problem.foot_body[n], :3, :3] @ (problem.foot_point[n] + [0.0, 0.0, radius])
                           + poses[problem.foot_body[n], :3, 3])[2] + radius * directions[:, 2]) for n in problem.feet]
        np.testing.assert_allclose(foot_bottoms(problem, config, radius), heights, atol=1e-6)
        if lowest is None:
            assert min(heights) < -1e-4  # the tilted stance legs' spheres start below the ground
        else:
            assert abs(min(heights) - lowest) < 1e-6


def test_max_impulse_bounds_every_touchdown_impulse():
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 1, QUADRUPED_MOTOR, max_impulse=0.05)
    lower, upper = problem.bounds()
    index = np.concatenate(list(problem.impulse_index.values()))
    assert len(index) == 4 * 2 * 3  # four touchdowns, two feet, three components
    np.testing.assert_array_equal(lower[index], -0.05)
    np.testing.assert_array_equal(upper[index], 0.05)
    with pytest.raises(ValueError, match="max_impulse"):
        amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 1, QUADRUPED_MOTOR, max_impulse=-1.0)


def test_replay_soles_are_boxes_whose_lowest_corner_starts_on_the_ground():
    # The biped's flat feet collide as boxes under their soles; against brute force: points all over each
    # box's bottom face placed by forward kinematics, the walk's first point tilted so a sole starts below.
    from legkit.optimize.gaits import walk_problem
    from legkit.robots.biped import build_biped
    from legkit.robots.motors import BIPED_MOTOR

    robot = build_biped()
    problem = walk_problem(robot, 0.5, BIPED_MOTOR, (1, 1))
    shapes = foot_shapes(problem, 0.002)
    q = robot.model.neutral()
    q[2] = 0.9
    q[3:7] = [np.sin(0.05), 0.0, 0.0, np.cos(0.05)]  # rolled by 0.1 rad
    grid = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, 41), np.linspace(-0.5, 0.5, 41)), axis=-1).reshape(-1, 2)
    for config in (q, clear_of_ground(problem, q, 0.002)):
        poses = np.asarray(lk.forward_kinematics(problem.model, config))
        heights = []
        for name in problem.feet:
            kind, size, frame = shapes[problem.foot_body[name]]
            assert kind == "box" and np.isclose(size[0], problem.flat_feet[name].length)
            bottom = frame[:3, 3] + np.c_[grid[:, 0] * size[0], grid[:, 1] * size[1], np.full(len(grid), -0.5 * size[2])]
            pose = poses[problem.foot_body[name]]
            heights.append(np.min((bottom @ pose[:3, :3].T + pose[:3, 3])[:, 2]))
        np.testing.assert_allclose(foot_bottoms(problem, config, 0.002), heights, atol=1e-12)
    assert min(heights) == pytest.approx(0.0, abs=1e-12)


def test_stance_accelerations_are_the_feet_second_derivatives_along_the_points_motion():
    # Brute force: each stance foot's world position along q(t) = q (+) (v t + a t^2 / 2), whose velocity and
    # acceleration at t = 0 are the point's v and a, differentiated twice by central differences.
    robot = build_quadruped(AMBLE_QUADRUPED)
    problem = amble_problem(robot, [MinMaxStability(2.0, DIAGONAL_PAIRS)], 0.67, 1.25, 2, QUADRUPED_MOTOR)
    x = problem.pack(guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 2)))
    rng = np.random.default_rng(3)
    for k, index in enumerate(problem.point_index):
        x[index[:, problem.a_columns[k]]] += rng.normal(scale=20.0, size=(len(index), problem.nv))
    step = 1e-4
    for k, (phase, accelerations) in enumerate(zip(problem.phases, problem.stance_accelerations(x))):
        z = x[problem.point_index[k]]
        q, v, a = problem.configuration(z[:, : problem.nq]), z[:, problem.nq : problem.nx], z[:, problem.a_columns[k]]
        feet = [problem.foot_positions(lk.integrate(problem.model, q, v * t + 0.5 * a * t * t, 1.0), phase.contacts) for t in (-step, 0.0, step)]
        expected = (feet[0] - 2.0 * feet[1] + feet[2]) / step**2
        assert np.abs(expected).max() > 10.0
        np.testing.assert_allclose(accelerations, expected, atol=1e-4 * np.abs(expected).max())


def test_stage_progress_writes_a_line_per_block_of_iterations_to_a_log(capsys):
    # Captured output is not a terminal: each stage gets a flushed line every BLOCK iterations and one when it ends.
    progress = gait._StageProgress(["constraints", "J_s2"])
    for stage_iterations in (25, 4):
        for iteration in range(stage_iterations + 1):
            progress(iteration, -0.1 * iteration, 1e-3)
    progress.close()
    lines = capsys.readouterr().out.splitlines()
    block = gait._StageProgress.BLOCK
    assert [line.split(":")[0].strip() for line in lines] == ["constraints"] * (25 // block + 1) + ["J_s2"]
    assert [line.split(": ")[1].split(",")[0] for line in lines] == [f"at iteration {i}" for i in range(block, 26, block)] + ["25 iterations",
                                                                                                                           "4 iterations"]
    assert all(line.endswith("s of CPU") for line in lines)


def test_verdict_says_plainly_when_a_plan_is_not_a_motion_or_the_replay_fell():
    summary = {"solver succeeded (1 = yes)": 1.0, "largest drift over one interval, attitude [deg]": 0.4,
               "largest drift over one interval, joints": 0.01, "replay: stayed upright (1 = yes)": 1.0,
               "replay: fell after [s] (inf: never)": np.inf}
    good = gait.verdict(summary, 1)
    assert good == ["verdict: IPOPT converged", "verdict: a motion of the model (drift over one interval within 2 deg of attitude and "
                    "0.1 rad at the joints)", "verdict: the replay stayed upright over 1 cycle"]
    bad = gait.verdict({**summary, "solver succeeded (1 = yes)": 0.0, "largest drift over one interval, attitude [deg]": 3.0,
                        "replay: stayed upright (1 = yes)": 0.0, "replay: fell after [s] (inf: never)": 1.234}, 5)
    assert "did NOT converge" in bad[0]
    assert bad[1].startswith("verdict: NOT a motion of the model") and "attitude [deg] 3 > 2" in bad[1]
    assert bad[2] == "verdict: the replay FELL after 1.23 s"
