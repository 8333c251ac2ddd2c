"""`Simulation.rollout` and `SimulationBatch.rollout`: N steps (and every step's transition Jacobians) in one call, as
MuJoCo's `rollout` module steps a batch of states: its states are those of N single steps bit for bit, its Jacobians
each step's `transition_jacobians`, a batch the same as its members rolled out one by one; refusals change nothing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from test_simulation import standing_quadruped


def settled_quadruped(substeps: int = 1, push: float = 0.0) -> lk.Simulation:
    sim = standing_quadruped(lk.Ground.plane(0.8), substeps=substeps, friction_law="cone")
    sim.step(None, 150)
    sim.v = sim.v + np.r_[push, np.zeros(sim.model.nv - 1)]
    return sim


def controls(nv: int, steps: int, seed: int, scale: float = 0.3) -> np.ndarray:
    """Feed-forward torques on the joints, none on the base."""
    tau = scale * np.random.default_rng(seed).standard_normal((steps, nv))
    tau[:, :6] = 0.0
    return tau


def stepped(sim: lk.Simulation, tau: np.ndarray, jacobians: bool) -> tuple[np.ndarray, ...]:
    """What a rollout should give, by single steps (each after its Jacobians, if asked)."""
    qs, vs, a_s, b_s = [], [], [], []
    for row in tau:
        if jacobians:
            a, b = sim.transition_jacobians(row)
            a_s.append(a)
            b_s.append(b)
        sim.step(row)
        qs.append(sim.q.copy())
        vs.append(sim.v.copy())
    out = (np.array(qs), np.array(vs))
    return out + ((np.array(a_s), np.array(b_s)) if jacobians else ())


@pytest.mark.parametrize("substeps", [1, 2, 4])
def test_states_and_jacobians_equal_single_steps_bit_for_bit(substeps):
    tau = controls(settled_quadruped().model.nv, 25, substeps)
    ours, theirs = settled_quadruped(substeps, push=0.2), settled_quadruped(substeps, push=0.2)
    rolled = ours.rollout(tau, jacobians=True)
    expected = stepped(theirs, tau, jacobians=True)
    assert len(rolled) == 4
    for got, want in zip(rolled, expected):
        assert got.shape == want.shape
        np.testing.assert_array_equal(got, want)
    # The simulation advanced as the steps did: state, time, contacts.
    np.testing.assert_array_equal(ours.q, theirs.q)
    np.testing.assert_array_equal(ours.v, theirs.v)
    assert ours.time == theirs.time
    for key, value in ours.contacts().items():
        np.testing.assert_array_equal(value, theirs.contacts()[key])


def test_without_jacobians_only_the_states():
    tau = controls(settled_quadruped().model.nv, 10, 3)
    q, v = settled_quadruped().rollout(tau)
    q_ref, v_ref = stepped(settled_quadruped(), tau, jacobians=False)
    np.testing.assert_array_equal(q, q_ref)
    np.testing.assert_array_equal(v, v_ref)


@given(steps=st.integers(1, 12), seed=st.integers(0, 2**16), scale=st.floats(0.0, 2.0))
@examples(6)
def test_any_control_sequence_rolls_out_as_its_steps(steps, seed, scale):
    nv = settled_quadruped().model.nv
    tau = controls(nv, steps, seed, scale)
    q, v = settled_quadruped().rollout(tau)
    q_ref, v_ref = stepped(settled_quadruped(), tau, jacobians=False)
    np.testing.assert_array_equal(q, q_ref)
    np.testing.assert_array_equal(v, v_ref)


def test_deterministic():
    tau = controls(settled_quadruped().model.nv, 15, 7)
    first = settled_quadruped(2, push=0.2).rollout(tau, jacobians=True)
    second = settled_quadruped(2, push=0.2).rollout(tau, jacobians=True)
    for x, y in zip(first, second):
        np.testing.assert_array_equal(x, y)


def test_a_batch_equals_its_members_rolled_out_one_by_one():
    pushes = [0.0, 0.2, -0.15]
    nv = settled_quadruped().model.nv
    per_member = np.stack([controls(nv, 12, seed) for seed in range(len(pushes))])
    batch = lk.SimulationBatch([settled_quadruped(2, p) for p in pushes])
    rolled = batch.rollout(per_member, jacobians=True)
    assert rolled[0].shape == (3, 12, batch.simulations[0].model.nq)
    assert rolled[2].shape == (3, 12, 2 * nv, 2 * nv) and rolled[3].shape == (3, 12, 2 * nv, 3 * nv)
    for i, push in enumerate(pushes):
        serial = settled_quadruped(2, push).rollout(per_member[i], jacobians=True)
        for got, want in zip(rolled, serial):
            np.testing.assert_array_equal(got[i], want)
    # One sequence (N, nv) for all.
    shared = lk.SimulationBatch([settled_quadruped(1, p) for p in pushes]).rollout(per_member[0])
    for i, push in enumerate(pushes):
        for got, want in zip(shared, settled_quadruped(1, push).rollout(per_member[0])):
            np.testing.assert_array_equal(got[i], want)


def snapshot(sim: lk.Simulation) -> tuple:
    return sim.q.copy(), sim.v.copy(), sim.time, {k: v.copy() for k, v in sim.contacts().items()}


def assert_unchanged(sim: lk.Simulation, before: tuple) -> None:
    q, v, time, contacts = before
    np.testing.assert_array_equal(sim.q, q)
    np.testing.assert_array_equal(sim.v, v)
    assert sim.time == time
    for key, value in contacts.items():
        np.testing.assert_array_equal(sim.contacts()[key], value)


@pytest.mark.parametrize("bad", ["no rows", "one dimension", "wrong width", "three dimensions", "nan", "inf"])
def test_bad_controls_are_refused_naming_them_and_nothing_moves(bad):
    sim = settled_quadruped()
    nv = sim.model.nv
    tau = {
        "no rows": np.zeros((0, nv)),
        "one dimension": np.zeros(nv),
        "wrong width": np.zeros((3, nv + 1)),
        "three dimensions": np.zeros((1, 3, nv)),
        "nan": np.r_[np.zeros((2, nv)), np.full((1, nv), np.nan)],
        "inf": np.r_[np.zeros((1, nv)), np.full((1, nv), np.inf)],
    }[bad]
    before = snapshot(sim)
    with pytest.raises(ValueError, match="controls"):
        sim.rollout(tau, jacobians=True)
    assert_unchanged(sim, before)
    batch = lk.SimulationBatch([sim, settled_quadruped()])
    batched = tau if bad == "three dimensions" else np.stack([tau, tau]) if tau.ndim == 2 else tau
    with pytest.raises(ValueError, match="controls"):
        batch.rollout(batched if bad != "three dimensions" else np.zeros((3, 2, nv)))
    assert_unchanged(sim, before)


def test_a_batch_of_different_sizes_is_refused():
    model = lk.Model(True, lk.MassProperties.solid_box(1.0, [0.1, 0.1, 0.1]))
    box = lk.Simulation(model, dt=1e-3, ground=lk.Ground.plane(0.8))
    sim = settled_quadruped()
    before = snapshot(sim)
    with pytest.raises(ValueError, match="simulations"):
        lk.SimulationBatch([sim, box]).rollout(np.zeros((2, 6)))
    assert_unchanged(sim, before)


def test_a_diverging_step_stops_at_the_last_good_state():
    """A step the simulation refuses (an actuation beyond 1e12 N) raises RuntimeError as `step` does, the steps before it
    taken."""
    sim = settled_quadruped()
    nv = sim.model.nv
    tau = np.zeros((4, nv))
    tau[2, 2] = 1e13  # a force on the base, which no effort bound clips
    reference = settled_quadruped()
    reference.step(tau[0])
    reference.step(tau[1])
    with pytest.raises(RuntimeError):
        sim.rollout(tau)
    np.testing.assert_array_equal(sim.q, reference.q)
    np.testing.assert_array_equal(sim.v, reference.v)
