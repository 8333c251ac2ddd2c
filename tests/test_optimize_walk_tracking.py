"""legkit.optimize.tracking on the biped's flat feet: each stance sole held as a frame (`lk.contact_dynamics(dim=6)`),
its wrench kept within eq. 6 [Hardt 2002] by the MPC's rows (against the inequalities written out here), the
linearisation against central differences of the contact model, and (slow) the MPC walking the optimised walk for
5 cycles in `lk.Simulation` on box soles."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import legkit as lk
from legkit.optimize.gaits import stall_torque_bounds, walk_problem
from legkit.optimize.tracking import TrackingModel, contact_width, force_rows, track
from legkit.robots.biped import build_biped
from legkit.robots.motors import BIPED_MOTOR
from test_optimize_tracking import stepped

#: The walk `solve_walk` gives for `walk_problem`'s defaults at 1.8 km/h (J_e1, 2 + 8 intervals per double/single
#: support, whole cycle, friction and sole margins), stored because it takes minutes to solve; the solve is
#: deterministic, so a re-solve reproduces it.
PLAN = Path(__file__).parent / "data" / "optimised_walk.npz"


@pytest.fixture(scope="module")
def walk():
    problem = walk_problem(build_biped(), 0.5, BIPED_MOTOR)
    x = np.load(PLAN)["x"]
    assert x.shape == (problem.n,) and problem.nlp().violation(x) < 1e-6  # stale if the transcription changed: re-solve it
    trajectory = problem.unpack(x)
    return problem, trajectory, TrackingModel.build(problem, trajectory)


def test_flat_feet_are_held_as_frames(walk):
    problem, trajectory, model = walk
    assert contact_width(problem) == 6
    assert model.forces.shape[1] == 6 * model.held.shape[1]
    # At the cycle's first knot (both soles down) the held soles' wrenches are the plan's: its forces, and its torques
    # (sole axes) in world axes.
    assert problem.phases[model.phase[0]].contacts == ("l", "r")
    poses = np.asarray(lk.forward_kinematics(problem.model, model.q[0]))
    expected = []
    for foot, name in enumerate(("l", "r")):
        axes = poses[problem.foot_body[name], :3, :3]
        expected += [trajectory.forces[0][0, foot], axes @ trajectory.torques[0][0, foot]]
    expected = np.concatenate(expected)
    np.testing.assert_allclose(model.forces[0], expected, atol=1e-6 * np.abs(expected).max())
    assert np.abs(expected[[3, 4, 5, 9, 10, 11]]).max() > 1e-2  # a sole, not a point: its torques are not zero


def test_sole_rows_are_eq_6_in_the_soles_axes(walk):
    problem, _, model = walk
    mu, rng = 0.6, np.random.default_rng(4)
    rows, per_foot = force_rows(model, mu)
    assert per_foot == 11
    poses = np.asarray(lk.forward_kinematics(problem.model, model.q[: len(model.A)]))
    checked = 0
    for i in rng.choice(len(model.A), 40, replace=False):
        for slot, name in enumerate(problem.phases[model.phase[i]].contacts):
            sole, axes = problem.flat_feet[name], poses[i, problem.foot_body[name], :3, :3]
            block = rows[i, 11 * slot : 11 * slot + 11, 6 * slot : 6 * slot + 6]
            for _ in range(50):
                wrench = rng.normal(size=6) * [1.0, 1.0, 1.0, 0.05, 0.05, 0.02] + [0.0, 0.0, 1.5, 0.0, 0.0, 0.0]
                f, torque = wrench[:3], axes.T @ wrench[3:]
                expected = [f[2], mu * f[2] - f[0], mu * f[2] + f[0], mu * f[2] - f[1], mu * f[2] + f[1],
                            0.5 * sole.width * f[2] - torque[0], 0.5 * sole.width * f[2] + torque[0],
                            0.5 * sole.length * f[2] - torque[1], 0.5 * sole.length * f[2] + torque[1],
                            sole.torsion * f[2] - torque[2], sole.torsion * f[2] + torque[2]]
                np.testing.assert_allclose(block @ wrench, expected, atol=1e-12)
                checked += 1
    assert checked > 1000


def test_the_linearisation_on_soles_equals_central_differences(walk):
    problem, _, model = walk
    columns, step = 2 * problem.nv + problem.nu, 1e-6
    touchdown = int(np.flatnonzero(np.diff(model.phase[:-1]))[0])
    for i in (5, touchdown, len(model.A) // 2 + 7):
        plus = [stepped(problem, model, i, step * np.eye(columns)[c]) for c in range(columns)]
        minus = [stepped(problem, model, i, -step * np.eye(columns)[c]) for c in range(columns)]
        state = np.stack([(p[0] - m[0]) / (2 * step) for p, m in zip(plus, minus)], axis=1)
        forces = np.stack([(p[1] - m[1]) / (2 * step) for p, m in zip(plus, minus)], axis=1)
        held = 6 * int(np.sum(model.held[i]))
        np.testing.assert_allclose(np.concatenate([model.A[i], model.B[i]], axis=1), state, atol=1e-6 * max(1.0, np.abs(state).max()))
        np.testing.assert_allclose(np.concatenate([model.force_state[i], model.force_input[i]], axis=1)[:held], forces,
                                   atol=1e-6 * max(1.0, np.abs(forces).max()))


def test_mixed_point_and_flat_feet_are_refused(walk):
    problem, _, _ = walk
    one_sole = replace(problem, flat_feet={"l": problem.flat_feet["l"]})
    with pytest.raises(ValueError, match="flat"):
        contact_width(one_sole)


@pytest.mark.slow
def test_the_mpc_walks_the_optimised_walk_five_cycles(walk):
    problem, trajectory, model = walk
    run = track(problem, trajectory, 5, model=model, progress=False, torque_bounds=stall_torque_bounds(BIPED_MOTOR, problem.nu))
    assert run.upright, run.fell_at
    assert run.drift_fraction < 0.1, run.drift_fraction
