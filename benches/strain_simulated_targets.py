"""Issue 6's accuracy targets on the Rapier-simulated RHex walk: measured figures against the targets.

Length NRMSE is asserted in tests/test_strain_simulated.py; deflection NRMSE and the pose errors over a
tripod stride are printed here until the simulated walk meets them (see the notes in the output).
"""

from __future__ import annotations

import numpy as np

from legkit.experiments.strain import calibration_set
from legkit.robots.rhex import TRIPODS
from legkit.strain.benchtop import CompliantFourBarLeg, synthetic_benchtop
from legkit.strain.model import LegModel, nrmse
from legkit.strain.simulated import simulated_walk
from legkit.strain.walking import estimate_body_pose


def main() -> None:
    strain, length, deflection = calibration_set(synthetic_benchtop(CompliantFourBarLeg(), seed=0))
    model = LegModel.fit(strain, length, deflection, order=1)
    tripods = np.array(TRIPODS)
    print("speed  length NRMSE %  deflection NRMSE %  height err mm  roll err deg  pitch err deg")
    print("target      <= 2.0             <= 10.0         <= 5.0         <= 2.0          <= 2.0")
    for speed in (0.2, 0.45):
        walk = simulated_walk(speed, 2.0, seed=3)
        estimate = estimate_body_pose(walk.hip_angle, walk.strain, model, walk.stance_centre)
        rows = np.arange(walk.time.size)[:, None]
        own = walk.stance[rows, tripods[estimate.support]].all(axis=1)
        other = walk.stance[rows, tripods[1 - estimate.support]].any(axis=1)
        stride = (walk.time < walk.time[0] + walk.period) & own & ~other
        errors = [
            nrmse(walk.length[walk.stance], estimate.length[walk.stance]),
            nrmse(walk.deflection[walk.stance], estimate.deflection[walk.stance]),
            1e3 * np.abs(estimate.pose.height - walk.height)[stride].max(),
            np.degrees(np.abs(estimate.pose.roll - walk.roll)[stride].max()),
            np.degrees(np.abs(estimate.pose.pitch - walk.pitch)[stride].max()),
        ]
        print(f"{speed:5.2f}" + "".join(f"{e:16.2f}" for e in errors))


if __name__ == "__main__":
    main()
