"""The compiled balance kernel (``legkit.control.BalanceKernel``: the agents on the synchronous bus and the
balancing controller in Rust) against the Python ``AgentNetwork`` and ``BalanceController`` it reimplements:
the same messages in the same rounds, the same estimates, poses and torques, on random trees with several
ground modules (an election), leaders standing on either block, moving and resting joints."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import examples
from legkit.agents import AgentNetwork, BusConfig, GroundContact
from legkit.control import SCHEMES, BalanceController, BalanceKernel, GainSchedule
from legkit.robots import superbot as sb


def rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def twins(seed: int, n_trees: int = 2, grounded: int = 3) -> tuple[BalanceController, BalanceKernel, np.ndarray]:
    """A Python controller and a kernel built from an identical twin of it: random trees, each with up to
    ``grounded`` ground modules on random blocks and poses, one gain schedule per module, random angles."""
    rng = np.random.default_rng(seed)
    trees = [sb.random_tree(int(rng.integers(3, 12)), int(rng.integers(1, 4)), int(rng.integers(1000))) for _ in range(n_trees)]
    offsets = np.cumsum([0] + [t.n_modules for t in trees])
    modules = [int(m) for t, o in zip(trees, offsets) for m in o + rng.choice(t.n_modules, min(grounded, t.n_modules), replace=False)]
    line_direction = rng.standard_normal(3)
    ground = [
        GroundContact(m, int(rng.integers(2)), rotation(rng), rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3), line_direction)
        for m in modules
    ]
    schedules = [GainSchedule.paper(SCHEMES[int(rng.integers(3))]) for _ in range(offsets[-1])]
    angles = rng.uniform(-1.2, 1.2, (offsets[-1], 3))

    def controller() -> BalanceController:
        network = AgentNetwork(trees, bus=BusConfig(seed=seed), ground=ground, angles=angles)
        return BalanceController(network, schedules)

    return controller(), BalanceKernel(controller()), angles


def sent(network: AgentNetwork) -> np.ndarray:
    return sum(channel.sent_by_module for channel in network.channels)


@pytest.mark.parametrize("grounded", [3, 0])  # 0: building the kernel was a NumPy shape error
@examples(12)
@given(st.integers(0, 2**31))
def test_the_kernel_sends_the_same_messages_and_computes_the_same_torques(grounded, seed):
    controller, kernel, angles = twins(seed, grounded=grounded)
    network = controller.network
    assert kernel.run_until_quiescent() == network.run_until_quiescent()
    assert np.array_equal(kernel.sent_by_module, sent(network))
    assert np.allclose(kernel.connector_estimates(), network.current_connector_estimates(), rtol=0, atol=1e-12)
    for mine, theirs in zip(kernel.world_poses(), network.world_poses()):
        assert np.allclose(mine, theirs, rtol=0, atol=1e-12)
    rng = np.random.default_rng(seed)
    dt = 1e-3
    for step in range(40):
        # Moving joints (every agent busy), then some at rest (a partial round), then all at rest (silence).
        if step < 15:
            angles = angles + rng.normal(0, 0.02, angles.shape)
        elif step < 30:
            angles = angles.copy()
            moving = rng.random(angles.shape[0]) < 0.2
            angles[moving] += rng.normal(0, 0.02, (int(moving.sum()), 3))
        network.observe(angles)
        network.run(1)
        expected, _ = controller.torques(dt)
        torques = kernel.step(angles, dt)
        assert np.array_equal(kernel.sent_by_module, sent(network)), f"step {step}"
        scale = max(1.0, float(np.abs(expected).max()))
        assert np.allclose(torques, expected, rtol=0, atol=1e-9 * scale), f"step {step}"
    assert np.allclose(kernel.connector_estimates(), network.current_connector_estimates(), rtol=0, atol=1e-12)
    before = kernel.sent_by_module.copy()
    kernel.step(angles, dt)
    assert np.array_equal(kernel.sent_by_module, before), "agents at rest send nothing"


def test_several_rounds_per_step_and_deterministic_reruns():
    controller, kernel, angles = twins(7)
    _, again, _ = twins(7)
    network = controller.network
    for k in (kernel, again):
        k.run_until_quiescent()
    network.run_until_quiescent()
    for _ in range(5):
        angles = angles + 0.01
        network.observe(angles)
        network.run(3)
        expected, _ = controller.torques(2e-3)
        torques = kernel.step(angles, 2e-3, rounds=3)
        assert np.allclose(torques, expected, rtol=0, atol=1e-9 * max(1.0, float(np.abs(expected).max())))
        assert np.array_equal(again.step(angles, 2e-3, rounds=3), torques)
    assert np.array_equal(kernel.sent_by_module, sent(network))


def test_bad_input_is_refused_and_leaves_the_kernel_unchanged():
    controller, kernel, angles = twins(3)
    _, twin, _ = twins(3)
    n = angles.shape[0]
    with pytest.raises(ValueError, match="angles"):
        kernel.step(np.zeros((n + 1, 3)), 1e-3)
    bad = angles.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="angles"):
        kernel.step(bad, 1e-3)
    with pytest.raises(ValueError, match="dt"):
        kernel.step(angles, 0.0)
    with pytest.raises(ValueError, match="rounds"):
        kernel.step(angles, 1e-3, rounds=-1)
    with pytest.raises(TypeError, match="controller"):
        BalanceKernel(controller.network)  # type: ignore[arg-type]
    assert np.array_equal(kernel.step(angles + 0.1, 1e-3), twin.step(angles + 0.1, 1e-3))
    assert np.array_equal(kernel.sent_by_module, twin.sent_by_module)


def test_only_a_fresh_synchronous_network_is_taken():
    tree = sb.random_tree(4, 2, 0)
    ground = [GroundContact(0, 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0]))]
    network = AgentNetwork(tree, bus=BusConfig(mode="async", loss=0.1), ground=ground)
    with pytest.raises(ValueError, match="synchronous"):
        BalanceKernel(BalanceController(network, GainSchedule()))
    network = AgentNetwork(tree, ground=ground)
    network.run(1)
    with pytest.raises(ValueError, match="fresh"):
        BalanceKernel(BalanceController(network, GainSchedule()))
