"""The optimiser's problems are the same NLP in every process: its rows, their order and its sparsity do not depend on
Python's string-hash seed (a set of foot names iterated in hash order once permuted the load-rate rows, and IPOPT's
path, hence the plan, then differed from run to run); and IPOPT's path does not depend on the number of BLAS threads
(MUMPS's factorisation summed in a thread-dependent order once gave another plan on a machine with more cores)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

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


SOLVE = """
import hashlib
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize.gaits import AMBLE_IPOPT, amble_plan_problem, amble_reference, guess_from_reference
from legkit.robots.quadruped import build_quadruped

robot = build_quadruped(AMBLE_QUADRUPED)
problem = amble_plan_problem(robot, 4)
guess = guess_from_reference(problem, amble_reference(robot, 0.67, 1.25, 4))
_, result = problem.solve(guess, derivatives="legkit", feasibility_first=True, max_iter=40, options=AMBLE_IPOPT)
print(result.iterations, hashlib.sha256(result.x.tobytes()).hexdigest())
"""


def run_child(code: str, **env: str) -> list[str]:
    import legkit

    path = os.pathsep.join([str(Path(legkit.__file__).parent.parent), os.environ.get("PYTHONPATH", "")])
    done = subprocess.run([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": path, **env}, capture_output=True, text=True,
                          timeout=600, check=True)
    return done.stdout.split()


def run_with_hash_seed(seed: int) -> list[str]:
    return run_child(CHILD, PYTHONHASHSEED=str(seed))


def test_amble_and_walk_nlps_do_not_depend_on_the_hash_seed():
    digests = [run_with_hash_seed(seed) for seed in (0, 1, 2, 3)]
    assert len(digests[0]) == 2
    assert all(d == digests[0] for d in digests[1:]), digests


@pytest.mark.slow
def test_an_ipopt_solve_does_not_depend_on_the_blas_thread_count():
    # Without the solver's pin to one thread, 40 iterations of the 4-interval amble end at another point on 4 threads.
    runs = [run_child(SOLVE, OPENBLAS_NUM_THREADS=threads, OMP_NUM_THREADS=threads) for threads in ("1", "4")]
    assert runs[0] == runs[1], runs
