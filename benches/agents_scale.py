"""Scale of the mass-property agents alone (no simulation): a random 10,000-module SuperBot tree.

Checks that the synchronous agents converge in exactly `diameter` rounds (exact one round later is not
enough: one round earlier some estimate must still be wrong), that the network is silent afterwards, and
measures throughput against the target of 200,000 module-updates per second:

* module-updates/s = modules x rounds / wall time of the rounds (every agent takes part in every round);
* RecomputeMass calls/s = the agents that actually re-ran Algorithm 2 (their inputs changed) / wall time.

Run: python benches/agents_scale.py [--modules 10000] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from legkit.agents import AgentNetwork, GroundContact
from legkit.robots.superbot import random_tree

TARGET = 200_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--modules", type=int, default=10_000, help="modules including the root (default 10000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    start = time.perf_counter()
    tree = random_tree(args.modules - 1, 1, args.seed)
    model, layout = tree.to_model()
    diameter = tree.diameter()
    q = np.random.default_rng(args.seed).uniform(-np.pi / 2, np.pi / 2, model.nq)
    print(f"tree: {tree.n_modules} modules, diameter {diameter}, built in {time.perf_counter() - start:.1f} s")

    ground = [GroundContact(0, 0, np.eye(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, 1.0]))]
    start = time.perf_counter()
    network = AgentNetwork(tree, ground=ground, angles=layout.module_angles(q))
    setup = time.perf_counter() - start

    start = time.perf_counter()
    network.run(diameter - 1)
    before_last = time.perf_counter() - start
    early = network.estimate_errors(model, layout, q)
    start = time.perf_counter()
    network.run(1)
    elapsed = before_last + time.perf_counter() - start
    errors = network.estimate_errors(model, layout, q)
    silent = network.quiescent and network.run(3) == 0

    updates = tree.n_modules * diameter / elapsed
    recomputations = network.recomputations / (elapsed + setup)
    print(f"setup (round 0, every agent sends its own mass): {setup:.2f} s")
    print(f"{diameter} rounds in {elapsed:.2f} s ({1e3 * elapsed / diameter:.1f} ms per round)")
    print(f"largest error after {diameter - 1} rounds: {early.largest:.3e} (must be wrong); after {diameter}: "
          f"mass {errors.mass:.2e} kg, COM {errors.com:.2e} m, inertia {errors.inertia:.2e} kg m^2")
    print(f"silent after convergence: {silent}; data messages: {network.transmissions}")
    print(f"module-updates per second: {updates:,.0f} (target {TARGET:,}: {'met' if updates >= TARGET else 'NOT met'})")
    print(f"RecomputeMass calls per second: {recomputations:,.0f} ({network.recomputations} calls)")


if __name__ == "__main__":
    main()
