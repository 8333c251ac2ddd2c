"""Time ``legkit.strain.tripod_pose`` on a batch of 1M tripods (target: under 1 s).

Run: python benches/tripod_pose.py   (prints the best and median of REPEATS timings)
"""

from __future__ import annotations

import time

import numpy as np

from legkit.robots.rhex import HIP_POSITIONS, LEG_LENGTH, TRIPODS
from legkit.strain.pose import tripod_pose

N = 1_000_000
REPEATS = 7


def rhex_like_tripods(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3, 3) stance toes in the body frame: the tripod-A hips, legs swept +-0.4 rad, 0.14-0.17 m long."""
    hips = HIP_POSITIONS[list(TRIPODS[0])]
    angle = rng.uniform(-0.4, 0.4, (n, 3))
    length = rng.uniform(0.14, LEG_LENGTH, (n, 3))
    toes = np.broadcast_to(hips, (n, 3, 3)).copy()
    toes[..., 0] -= length * np.sin(angle)
    toes[..., 2] -= length * np.cos(angle)
    return toes


def main() -> None:
    toes = rhex_like_tripods(np.random.default_rng(0), N)
    tripod_pose(toes[:1000])  # warm up
    timings = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        tripod_pose(toes)
        timings.append(time.perf_counter() - start)
    print(f"tripod_pose, {N:,} tripods: best {min(timings):.3f} s, median {np.median(timings):.3f} s (target < 1 s)")


if __name__ == "__main__":
    main()
