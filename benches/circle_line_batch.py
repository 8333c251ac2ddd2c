"""The Python batch call of lk.circle_line over 1M queries against the Rust loop measured by criterion.

Run `cargo bench -p legkit-dynamics --bench circle_line` first to get the Rust figures; this script reads
criterion's estimates and prints the ratios (target: <= 1.5 against the loop that does the same job:
validate raw inputs, solve, write fresh output arrays).
"""

from __future__ import annotations

import json
import pathlib
import time

import numpy as np

import legkit as lk

N = 1_000_000
REPEATS = 7


def random_queries(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    return {
        "center": rng.uniform(-2, 2, (n, 3)),
        "normal": rng.normal(size=(n, 3)),
        "radius": rng.uniform(0, 2, n),
        "line_point": rng.uniform(-2, 2, (n, 3)),
        "line_direction": rng.normal(size=(n, 3)),
    }


def rust_loop_ns(name: str) -> float | None:
    estimate = pathlib.Path(__file__).resolve().parents[1] / "target" / "criterion" / "circle_line" / name / "new" / "estimates.json"
    if not estimate.is_file():
        return None
    return json.loads(estimate.read_text())["median"]["point_estimate"] / N


def main() -> None:
    queries = random_queries(np.random.default_rng(0), N)
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        lk.circle_line(**queries)
        times.append(time.perf_counter() - start)
    python_ns = float(np.median(times)) / N * 1e9
    print(f"lk.circle_line, batch of {N:,}: median {python_ns:.1f} ns per query ({REPEATS} runs)")
    for name, what in (("random_1m_from_raw", "the same job in Rust"), ("random_1m", "the solve alone")):
        rust_ns = rust_loop_ns(name)
        if rust_ns is None:
            print(f"no criterion estimate for {name}: run `cargo bench -p legkit-dynamics --bench circle_line` first")
        else:
            print(f"Rust loop, {what} (criterion median): {rust_ns:.1f} ns per query; Python/Rust = {python_ns / rust_ns:.2f}")


if __name__ == "__main__":
    main()
