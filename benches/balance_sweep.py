"""Throughput of balance sweeps (legkit.sweeps): scaling from 1 to 2 local workers, and a 1,000-run sweep.

    PYTHONPATH=python python3 benches/balance_sweep.py                         # scaling, 3 repeats (~5 min idle)
    PYTHONPATH=python python3 benches/balance_sweep.py --thousand             # and 1,000 runs with the defaults
    PYTHONPATH=python python3 benches/balance_sweep.py --repeats 0 --batch-sizes 12 24 48   # one batch per size

Runs are the sweep target's: 20-module random trees (4 branches), each under one scheme, ``--duration`` s of
closed loop at 1 kHz (plus the 0.5 s of posing every batch starts with).

* Part 1 (``--batch-sizes``): one batch of each size in this process (the agents and controller in Python on
  one core, the plants stepped by ``lk.SimulationBatch`` on every core).
* Part 2, scaling: the same ``--runs`` runs (batches of ``--sweep-batch``) with ``run_sweep`` on 1 worker
  process with one physics thread, and on 2 worker processes with one physics thread each: the comparison
  counted per core (a worker whose physics used both cores would already use part of the second core).
  The two alternate, ``--repeats`` times, so that the other work on the machine weighs on both alike; the
  medians and the ratio of the median rates are printed.
* Part 3 (``--thousand``): 1,002 runs (334 trees x 3 schemes) with ``run_sweep``'s defaults (one worker per
  core, physics on cores // workers threads each). On Linux a thread samples, every 50 ms, whether each
  worker has work (any of its threads running or runnable, from /proc) and how many runs are written; it
  prints the share of worker-time with work until 95 % of the runs are written (the tail excluded), which
  does not depend on how much CPU the other jobs on the machine leave the workers.

Printed per line: wall time, runs per minute, CPU seconds per run (this process and its workers), the cores
the sweep got on average (CPU time / wall time), the load average before and after, and the time 1,000 runs
would take at that rate. CPU seconds per run depend little on the other work on the machine; the wall time,
the rate and the cores the sweep gets do: a speed-up is the ratio of cores got times the ratio of CPU
seconds per run.
"""

from __future__ import annotations

import argparse
import glob
import multiprocessing
import os
import resource
import statistics
import tempfile
import threading
import time
from pathlib import Path

from legkit.sweeps import SweepSpec, run_batch, run_sweep


def cpu_seconds() -> float:
    """CPU time of this process and of its children that have ended (a sweep's workers end with it)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def spec_for(runs: int, duration: float, batch_size: int) -> SweepSpec:
    trees = -(-runs // 3)
    return SweepSpec(trees=trees, modules=20, branches=4, duration=duration, batch_size=batch_size)


def measure(label: str, action) -> dict[str, float]:
    """Run ``action`` (returns the number of runs), print its line and return its figures."""
    load_before, cpu, start = os.getloadavg()[0], cpu_seconds(), time.perf_counter()
    runs = action()
    figures = {
        "runs": runs, "wall": time.perf_counter() - start, "cpu": cpu_seconds() - cpu,
        "load_before": load_before, "load_after": os.getloadavg()[0],
    }
    print(line(label, figures), flush=True)
    return figures


def line(label: str, f: dict[str, float]) -> str:
    rate = 60.0 * f["runs"] / f["wall"]
    return (f"{label:<34} {f['runs']:>5.0f} runs {f['wall']:>7.1f} s {rate:>7.1f} runs/min {f['cpu'] / f['runs']:>6.2f} CPU s/run "
            f"{f['cpu'] / f['wall']:>5.2f} cores  load {f['load_before']:>4.1f}-{f['load_after']:<4.1f}  1,000 runs: {1000 / rate:>5.1f} min")


def sweep(spec: SweepSpec, workers: int | None, threads: int | None):
    def action() -> int:
        with tempfile.TemporaryDirectory() as out:
            return run_sweep(spec, out, workers=workers, threads=threads, progress=False, figures=False).num_rows
    return action


def sample_workers(spec: SweepSpec, out: Path, samples: list[tuple[float, int, int, int]], stop: threading.Event) -> None:
    """Every 50 ms: (time, runs written, workers with work, workers) into ``samples``. A worker has work when
    any of its threads (the interpreter's, the physics pool's) is running or runnable (/proc state R)."""
    sizes = [len(b) for b in spec.batches()]
    start = time.perf_counter()
    while not stop.wait(0.05):
        workers = multiprocessing.active_children()
        busy = 0
        for worker in workers:
            try:
                states = [(Path(task) / "stat").read_text().rsplit(")", 1)[1].split()[0] for task in glob.glob(f"/proc/{worker.pid}/task/*")]
            except OSError:
                continue
            busy += any(state == "R" for state in states)
        written = sum(sizes[int(p.stem.split("-")[1])] for p in (out / "parts").glob("batch-*.parquet"))
        samples.append((time.perf_counter() - start, written, busy, len(workers)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=96, help="runs of part 2 (default 96)")
    parser.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run (default 2)")
    parser.add_argument("--batch-sizes", type=int, nargs="*", default=[], help="part 1's batch sizes (default none)")
    parser.add_argument("--sweep-batch", type=int, default=24, help="batch size of parts 2 and 3 (default 24)")
    parser.add_argument("--repeats", type=int, default=3, help="repeats of part 2 (default 3; 0 skips it)")
    parser.add_argument("--thousand", action="store_true", help="part 3: 1,002 runs with run_sweep's defaults (~10 min)")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores; load average {os.getloadavg()[0]:.2f}")
    for size in args.batch_sizes:
        spec = spec_for(size, args.duration, size)
        measure(f"part 1: one batch of {size}", lambda spec=spec, size=size: len(run_batch(spec.to_dict(), spec.runs()[:size])))

    spec = spec_for(args.runs, args.duration, args.sweep_batch)
    configurations = {"1 worker x 1 thread": 1, "2 workers x 1 thread": 2}
    results: dict[str, list[dict[str, float]]] = {label: [] for label in configurations}
    for repeat in range(args.repeats):
        for label, workers in configurations.items():
            results[label].append(measure(f"part 2 #{repeat + 1}: {label}", sweep(spec, workers, 1)))
    if args.repeats:
        rates = {}
        for label, runs in results.items():
            rates[label] = statistics.median(60.0 * f["runs"] / f["wall"] for f in runs)
            cpu = statistics.median(f["cpu"] / f["runs"] for f in runs)
            cores = statistics.median(f["cpu"] / f["wall"] for f in runs)
            load = statistics.median(0.5 * (f["load_before"] + f["load_after"]) for f in runs)
            print(f"median {label:<27} {rates[label]:>7.1f} runs/min {cpu:>6.2f} CPU s/run {cores:>5.2f} cores  load {load:.1f}")
        pairs = [60.0 * b["runs"] / b["wall"] / (60.0 * a["runs"] / a["wall"]) for a, b in zip(*results.values())]
        print(f"speed-up 1 -> 2 workers (1 physics thread each): {rates['2 workers x 1 thread'] / rates['1 worker x 1 thread']:.2f}x "
              f"of the median rates; per repeat {', '.join(f'{p:.2f}x' for p in pairs)}")

    if args.thousand:
        spec = spec_for(1000, args.duration, args.sweep_batch)
        with tempfile.TemporaryDirectory() as out:
            samples: list[tuple[float, int, int, int]] = []
            stop = threading.Event()
            sampler = threading.Thread(target=sample_workers, args=(spec, Path(out), samples, stop), daemon=True)
            sampler.start()

            def thousand() -> int:
                return run_sweep(spec, out, progress=False, figures=False).num_rows

            try:
                measure("part 3: 1,002 runs, defaults", thousand)
            finally:
                stop.set()
                sampler.join()
        total = len(spec.runs())
        until = [s for s in samples if s[1] < 0.95 * total and s[3] > 0]
        if until:
            share = sum(s[2] for s in until) / sum(s[3] for s in until)
            print(f"part 3: workers had work {100 * share:.1f} % of the time until 95 % of the runs were written "
                  f"({len(until)} samples over {until[-1][0]:.0f} s)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
