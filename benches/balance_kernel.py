"""The balance experiment's control step: the compiled ``BalanceKernel`` against the Python ``AgentNetwork`` and
``BalanceController`` it reimplements, side by side in one process, on the default experiment's agents (4
random trees of 21 modules x 3 gain schedules: 252 agents, 756 joints) with every joint moving.

One control step = the agents read their angles, run one synchronous round, and every joint computes its
torque. Prints the median of blocks of steps for each, their ratio, and the largest torque difference.

Run: python benches/balance_kernel.py [--steps 2000] [--block 100]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from legkit.agents import AgentNetwork, GroundContact
from legkit.control import SCHEMES, BalanceController, BalanceKernel, GainSchedule
from legkit.robots.superbot import random_tree


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=2000, help="control steps timed per implementation (default 2000)")
    parser.add_argument("--block", type=int, default=100, help="steps per timed block (default 100)")
    args = parser.parse_args()

    trees = [random_tree(20, 4, seed) for seed in range(4) for _ in SCHEMES]
    first = np.cumsum([0] + [t.n_modules for t in trees])[:-1]
    ground = [GroundContact(int(m), 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0])) for m in first]
    schedules = [GainSchedule.paper(SCHEMES[i % 3]) for i, t in enumerate(trees) for _ in range(t.n_modules)]
    n = len(schedules)
    start = np.random.default_rng(0).uniform(-0.5, 0.5, (n, 3))

    def controller() -> BalanceController:
        return BalanceController(AgentNetwork(trees, ground=ground, angles=start), schedules)

    python, kernel = controller(), BalanceKernel(controller())
    python.network.run_until_quiescent()
    kernel.run_until_quiescent()
    dt = 1e-3
    phases = np.arange(3)

    def python_step(angles: np.ndarray) -> np.ndarray:
        python.network.observe(angles)
        python.network.run(1)
        return python.torques(dt)[0]

    blocks: dict[str, list[float]] = {"python": [], "kernel": []}
    worst = 0.0
    for block in range(args.steps // args.block):
        trajectory = [start + 0.2 * np.sin(1e-3 * (block * args.block + k) + phases) for k in range(args.block)]
        torques = {}
        for name, step in (("python", python_step), ("kernel", lambda a: kernel.step(a, dt))):
            began = time.perf_counter()
            torques[name] = [step(a) for a in trajectory]
            blocks[name].append((time.perf_counter() - began) / args.block)
        worst = max(worst, max(float(np.abs(a - b).max()) for a, b in zip(torques["python"], torques["kernel"])))
    median = {name: float(np.median(times)) for name, times in blocks.items()}
    print(f"{n} agents, {3 * n} joints, {args.steps} steps in blocks of {args.block} (median of block means)")
    print(f"Python AgentNetwork + BalanceController: {1e6 * median['python']:8.1f} µs per step")
    print(f"BalanceKernel (Rust):                    {1e6 * median['kernel']:8.1f} µs per step")
    print(f"kernel / Python: {median['kernel'] / median['python']:.3f} ({median['python'] / median['kernel']:.1f}x faster)")
    print(f"largest torque difference: {worst:.2e} N m; messages: {int(kernel.sent_by_module.sum())} (kernel), "
          f"{int(sum(c.sent_by_module.sum() for c in python.network.channels))} (Python)")


if __name__ == "__main__":
    main()
