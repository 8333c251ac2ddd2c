"""The Python batch call of lk.circle_line over 1M queries against the Rust loop measured by criterion.

Run `cargo bench -p legkit-dynamics --bench circle_line` first to get the Rust figure; this script reads
criterion's estimate and prints the ratio (target: <= 1.5).
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


def rust_loop_ns() -> float | None:
    root = pathlib.Path(__file__).resolve().parents[1] / "target" / "criterion"
    estimates = sorted(root.glob("circle_line*/**/new/estimates.json"))
    if not estimates:
        return None
    median_ns = json.loads(estimates[0].read_text())["median"]["point_estimate"]
    return median_ns / N


def main() -> None:
    queries = random_queries(np.random.default_rng(0), N)
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        lk.circle_line(**queries)
        times.append(time.perf_counter() - start)
    python_ns = float(np.median(times)) / N * 1e9
    print(f"lk.circle_line, batch of {N:,}: median {python_ns:.1f} ns per query ({REPEATS} runs)")
    rust_ns = rust_loop_ns()
    if rust_ns is None:
        print("no criterion estimate found: run `cargo bench -p legkit-dynamics --bench circle_line` first")
    else:
        print(f"Rust loop (criterion median): {rust_ns:.1f} ns per query; Python/Rust = {python_ns / rust_ns:.2f}")


if __name__ == "__main__":
    main()
