"""The optimiser's problems are the same NLP in every process: its rows, their order and its sparsity do not depend on
Python's string-hash seed (a set of foot names iterated in hash order once permuted the load-rate rows, and IPOPT's
path, hence the plan, then differed from run to run)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

CHILD = """
import hashlib
import numpy as np
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize.gaits import amble_plan_problem, amble_reference, guess_from_reference, walk_problem, walk_reference
from legkit.robots.biped import build_biped
from legkit.robots.motors import BIPED_MOTOR
from legkit.robots.quadruped import build_quadruped

def digest(problem, guess):
    nlp = problem.nlp("exact")
    x = problem.gauged(problem.pack(guess))
    x = x + 1e-3 * np.random.default_rng(0).standard_normal(x.shape)
    parts = [nlp.jac_rows, nlp.jac_cols, nlp.hess_rows, nlp.hess_cols, nlp.g_lower, nlp.g_upper, nlp.constraints(x), nlp.jacobian(x)]
    return hashlib.sha256(b"".join(np.ascontiguousarray(p).tobytes() for p in parts)).hexdigest()

quadruped = build_quadruped(AMBLE_QUADRUPED)
amble = amble_plan_problem(quadruped, 2)
biped = build_biped()
walk = walk_problem(biped, 0.5, BIPED_MOTOR, (1, 1))
print(digest(amble, guess_from_reference(amble, amble_reference(quadruped, 0.67, 1.25, 2))))
print(digest(walk, guess_from_reference(walk, walk_reference(biped, 0.5, (1, 1)))))
"""


def run_with_hash_seed(seed: int) -> list[str]:
    import legkit

    path = os.pathsep.join([str(Path(legkit.__file__).parent.parent), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONHASHSEED": str(seed), "PYTHONPATH": path}
    done = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=600, check=True)
    return done.stdout.split()


def test_amble_and_walk_nlps_do_not_depend_on_the_hash_seed():
    digests = [run_with_hash_seed(seed) for seed in (0, 1, 2, 3)]
    assert len(digests[0]) == 2
    assert all(d == digests[0] for d in digests[1:]), digests
