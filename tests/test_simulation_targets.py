"""Simulation.step(targets=...): servo position targets for many steps in one call.

A controller that tracks a trajectory at the simulation's rate passes the trajectory instead of calling
set_servo and step once per step. The reference is that Python loop itself: the two must be bit-identical.
"""

import math

import numpy as np
import pytest

import legkit as lk
from test_simulation import FOOT_RADIUS, LEG_LENGTH, quadruped

KP, KD, LIMIT = 40.0, 0.5, 20.0


def standing():
    model, shapes = quadruped()
    sim = lk.Simulation(model, dt=1e-3, ground=lk.Ground.plane(0.8), shapes=shapes)
    q = model.neutral()
    q[2] = 0.03 + 2 * LEG_LENGTH + FOOT_RADIUS + 0.002
    sim.q = q
    sim.set_servo(kp=KP, kd=KD, torque_limit=LIMIT, target_q=model.neutral())
    sim.step(n=100)
    return model, sim


def trajectory(model, steps):
    """A trot-like swing of every joint: (steps, nv) targets per velocity coordinate, base entries zero."""
    t = np.arange(1, steps + 1)[:, None] * 1e-3
    phase = np.arange(model.nv)[None, :]
    targets = 0.3 * np.sin(2 * math.pi * 2.0 * t + phase)
    targets[:, :6] = 0.0
    return targets


def configuration(model, row):
    """The configuration whose joint coordinates are `row`'s (what set_servo's target_q takes)."""
    q = model.neutral()
    q[7:] = row[6:]
    return q


def test_targets_match_a_python_loop_bit_for_bit_and_the_servos_keep_the_last_row():
    model, looped = standing()
    _, batched = standing()
    targets = trajectory(model, 300)
    tau = np.zeros(model.nv)
    tau[6:] = 0.05
    for row in targets:
        looped.set_servo(kp=KP, kd=KD, torque_limit=LIMIT, target_q=configuration(model, row))
        looped.step(tau)
    batched.step(tau, targets=targets)
    np.testing.assert_array_equal(batched.q, looped.q)
    np.testing.assert_array_equal(batched.v, looped.v)
    np.testing.assert_array_equal(batched.applied_tau, looped.applied_tau)
    assert batched.time == looped.time
    # The servos aim at the last row afterwards.
    looped.step(n=50)
    batched.step(n=50)
    np.testing.assert_array_equal(batched.q, looped.q)


def test_targets_in_pieces_equal_targets_at_once():
    model, whole = standing()
    _, pieces = standing()
    targets = trajectory(model, 200)
    whole.step(targets=targets)
    for chunk in np.array_split(targets, 7):
        pieces.step(targets=chunk)
    np.testing.assert_array_equal(whole.q, pieces.q)


def test_n_may_repeat_the_rows_count_and_zero_rows_take_no_step():
    model, sim = standing()
    targets = trajectory(model, 20)
    sim.step(n=20, targets=targets)
    assert sim.time == pytest.approx(0.12)
    q = sim.q.copy()
    sim.step(targets=np.zeros((0, model.nv)))
    np.testing.assert_array_equal(sim.q, q)


@pytest.mark.parametrize(
    "targets, n, name",
    [
        (np.zeros((5, 3)), None, "targets"),  # wrong width
        (np.zeros(14), None, "targets"),  # one row, not (n, nv)
        (np.full((5, 14), np.nan), None, "targets"),
        (np.zeros((5, 14)), 4, "n"),  # n disagrees with the rows
        ([["a"] * 14], None, "targets"),
    ],
)
def test_bad_targets_raise_naming_the_argument_and_change_nothing(targets, n, name):
    model, sim = standing()
    assert model.nv == 14
    before = (sim.q.copy(), sim.v.copy(), sim.time)
    with pytest.raises((ValueError, TypeError), match=name):
        sim.step(n=n, targets=targets)
    np.testing.assert_array_equal(sim.q, before[0])
    np.testing.assert_array_equal(sim.v, before[1])
    assert sim.time == before[2]
    # Nothing was half-applied: the next steps equal a twin's that never saw the bad call.
    _, twin = standing()
    sim.step(n=30)
    twin.step(n=30)
    np.testing.assert_array_equal(sim.q, twin.q)


def test_a_non_finite_row_late_in_the_trajectory_is_refused_before_any_step():
    model, sim = standing()
    targets = trajectory(model, 100)
    targets[90, 8] = np.inf
    q = sim.q.copy()
    with pytest.raises(ValueError, match=r"targets: row 90"):
        sim.step(targets=targets)
    np.testing.assert_array_equal(sim.q, q)
