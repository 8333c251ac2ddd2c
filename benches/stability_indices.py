"""Time every legkit.stability index over one 10,000-sample trajectory (target: under 50 ms in total).

The trajectory is synthetic but shaped like the quadruped amble: four feet, two on the ground at a time,
COM swaying over them. Prints the time per index (best of 5 runs) and the total, as CPU time of this
process (time.process_time), which is less disturbed than wall time when other jobs share the cores.
Run: python benches/stability_indices.py
"""

from __future__ import annotations

import time

import numpy as np

import legkit.stability as ls

SAMPLES = 10_000
JOINTS = 12


def trajectory(rng: np.random.Generator) -> dict[str, np.ndarray]:
    t = np.linspace(0.0, 10.0, SAMPLES)
    feet = np.array([[0.065, 0.055, 0.0], [0.065, -0.055, 0.0], [-0.065, 0.055, 0.0], [-0.065, -0.055, 0.0]])
    points = feet[None] + rng.normal(scale=0.01, size=(SAMPLES, 4, 3)) * [1, 1, 0]
    quarter = (np.floor(t / 0.1).astype(int)) % 4
    pairs = np.array([[1, 0, 0, 1], [1, 0, 1, 0], [0, 1, 1, 0], [0, 1, 0, 1]], dtype=bool)
    com = np.column_stack([0.01 * np.sin(t), 0.01 * np.cos(2 * t), np.full(SAMPLES, 0.13)])
    return {
        "t": t, "points": points, "active": pairs[quarter], "com": com,
        "momentum": rng.normal(scale=0.05, size=(SAMPLES, 3)), "spin": rng.normal(scale=0.005, size=(SAMPLES, 3)),
        "rate": np.column_stack(
            [rng.normal(scale=0.3, size=(SAMPLES, 2)), rng.normal(scale=0.3, size=SAMPLES), rng.normal(scale=0.01, size=(SAMPLES, 3))]
        ),
        "inertia": np.broadcast_to(np.diag([0.004, 0.01, 0.012]), (SAMPLES, 3, 3)),
        "forces": np.abs(rng.normal(size=(SAMPLES, 4, 3))) * [0.2, 0.2, 4.0],
        "torques": rng.normal(scale=0.2, size=(SAMPLES, JOINTS)), "speeds": rng.normal(scale=3.0, size=(SAMPLES, JOINTS)),
    }


def main() -> None:
    data = trajectory(np.random.default_rng(0))
    normals = np.broadcast_to([0.0, 0.0, 1.0], data["forces"].shape)
    indices = {
        "static stability margin": lambda d: ls.static_stability_margin(d["com"], d["points"], d["active"]),
        "S_H (published)": lambda d: ls.angular_momentum_stability(
            d["com"], d["momentum"], d["spin"], None, 1.58, d["points"], d["active"], v_tip_max=2.0, diagonal_pairs=[(0, 3), (1, 2)]),
        "S_H (energy, swing tips)": lambda d: ls.angular_momentum_stability(
            d["com"], d["momentum"], d["spin"], d["inertia"], 1.58, d["points"], d["active"], d["points"], ~d["active"], 1.5,
            definition="energy"),
        "ZMP from momentum rate": lambda d: ls.zmp_from_momentum_rate(d["com"], d["rate"], 1.58),
        "centre of pressure": lambda d: ls.center_of_pressure(d["points"], d["forces"]),
        "support centroid + J_s1": lambda d: ls.stability_performance_1(d["com"], ls.support_polygon_centroid(d["points"], d["active"]), d["t"]),
        "friction-cone margin": lambda d: ls.friction_cone_margin(d["forces"], normals, 0.8),
        "foot-torque margin": lambda d: ls.foot_torque_margin(d["forces"][:, 0], d["rate"][:, 3:], (-0.05, 0.15, -0.04, 0.04)),
        "Joule-loss index": lambda d: ls.joule_loss_index(d["torques"], d["t"], 6.7, 5.0, 60.0, 0.012),
        "specific resistance": lambda d: ls.specific_resistance(d["torques"], d["speeds"], d["t"], 0.67, 1.58),
        "torque-speed margin": lambda d: ls.torque_speed_margin(d["torques"], d["speeds"], 21.0, 60.0, 0.7, 42000.0),
    }
    total = 0.0
    print(f"{SAMPLES} samples, best of 9, CPU time:")
    for name, index in indices.items():
        best = min(_timed(index, data) for _ in range(9))
        total += best
        print(f"  {name:28s} {best * 1e3:7.2f} ms")
    print(f"  {'total':28s} {total * 1e3:7.2f} ms  (target < 50 ms)")


def _timed(function, data) -> float:
    start = time.process_time()
    function(data)
    return time.process_time() - start


if __name__ == "__main__":
    main()
