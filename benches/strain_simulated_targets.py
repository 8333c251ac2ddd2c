"""The strain models' accuracy targets on the simulated RHex walk (tree engine): measured figures against the targets.

For each speed and seed (3, 4, 5) prints the length and deflection NRMSE over all stance samples and the
worst body height, roll and pitch errors over the first stride's single-tripod-support samples, then the
worst over the seeds. tests/test_strain_simulated.py asserts the same targets on seed 3.
"""

from __future__ import annotations

import numpy as np

from legkit.experiments.strain import calibration_set
from legkit.robots.rhex import TRIPODS
from legkit.strain.benchtop import CompliantFourBarLeg, synthetic_benchtop
from legkit.strain.model import LegModel, nrmse
from legkit.strain.simulated import simulated_walk
from legkit.strain.walking import WalkingStream, estimate_body_pose

TARGETS = np.array([2.0, 10.0, 5.0, 2.0, 2.0])  # %, %, mm, deg, deg
SEEDS = (3, 4, 5)


def target_errors(walk: WalkingStream, model: LegModel) -> np.ndarray:
    """(length NRMSE %, deflection NRMSE %, height mm, roll deg, pitch deg) of the estimator on one walk.

    NRMSE over all stance samples; pose errors are the max over the first stride's single-tripod-support
    samples (the estimator's support tripod has all toes down, the other none).
    """
    tripods = np.array(TRIPODS)
    estimate = estimate_body_pose(walk.hip_angle, walk.strain, model, walk.stance_centre, walk.toe_radius)
    rows = np.arange(walk.time.size)[:, None]
    own = walk.stance[rows, tripods[estimate.support]].all(axis=1)
    other = walk.stance[rows, tripods[1 - estimate.support]].any(axis=1)
    stride = (walk.time < walk.time[0] + walk.period) & own & ~other
    return np.array(
        [
            nrmse(walk.length[walk.stance], estimate.length[walk.stance]),
            nrmse(walk.deflection[walk.stance], estimate.deflection[walk.stance]),
            1e3 * np.abs(estimate.pose.height - walk.height)[stride].max(),
            np.degrees(np.abs(estimate.pose.roll - walk.roll)[stride].max()),
            np.degrees(np.abs(estimate.pose.pitch - walk.pitch)[stride].max()),
        ]
    )


def main() -> None:
    strain, length, deflection = calibration_set(synthetic_benchtop(CompliantFourBarLeg(), seed=0))
    model = LegModel.fit(strain, length, deflection, order=1)
    print("speed  seed  length NRMSE %  deflection NRMSE %  height err mm  roll err deg  pitch err deg  speed m/s")
    print("target            <= 2.0             <= 10.0         <= 5.0         <= 2.0          <= 2.0")
    worst = np.zeros(TARGETS.size)
    for speed in (0.2, 0.45):
        for seed in SEEDS:
            walk = simulated_walk(speed, 2.0, seed=seed)
            errors = target_errors(walk, model)
            worst = np.maximum(worst, errors)
            achieved = (walk.body_position[-1, 0] - walk.body_position[0, 0]) / (walk.time[-1] - walk.time[0])
            print(f"{speed:5.2f}  {seed:4d}" + "".join(f"{e:16.2f}" for e in errors) + f"{achieved:11.3f}")
    print("worst      " + "".join(f"{e:16.2f}" for e in worst))
    print("margin %   " + "".join(f"{m:16.0f}" for m in 100 * (1 - worst / TARGETS)))


if __name__ == "__main__":
    main()
