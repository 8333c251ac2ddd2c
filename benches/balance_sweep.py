"""Throughput of balance sweeps (legkit.sweeps): runs per minute against batch size and worker count.

    PYTHONPATH=python python3 benches/balance_sweep.py                       # defaults below, ~10 min here
    PYTHONPATH=python python3 benches/balance_sweep.py --runs 48 --batch-sizes 12 24 --duration 1.0

Runs are the sweep target's: 20-module random trees (4 branches), each under one scheme, ``--duration`` s of
closed loop at 1 kHz (plus the 0.5 s of posing every batch starts with). Part 1 runs one batch of each size
in this process (the agents and controller in Python on one core, the plants stepped by
``lk.SimulationBatch`` on every core); part 2 runs the same ``--runs`` runs with ``legkit.sweeps.run_sweep``
on 1 worker (this process, physics on every core), on 1 worker process with one physics thread, and on
2 workers (2 processes, physics on cores // 2 threads each). Printed per line: wall time, runs per minute, CPU seconds per run (all processes;
the wall time the machine would need per run per core if nothing else ran), and the time 1,000 runs would
take at that rate. The machine's load average is printed too: other work on the same cores slows
everything down.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time

from legkit.sweeps import SweepSpec, run_batch, run_sweep


def cpu_seconds() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def spec_for(runs: int, duration: float, batch_size: int) -> SweepSpec:
    trees = -(-runs // 3)
    return SweepSpec(trees=trees, modules=20, branches=4, duration=duration, batch_size=batch_size)


def line(label: str, runs: int, wall: float, cpu: float) -> str:
    rate = 60.0 * runs / wall
    return f"{label:<40} {runs:>5} runs {wall:>8.1f} s {rate:>8.1f} runs/min {cpu / runs:>7.2f} CPU s/run   1,000 runs: {1000 / rate:>6.1f} min"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=96, help="runs of part 2 (default 96)")
    parser.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run (default 2)")
    parser.add_argument("--batch-sizes", type=int, nargs="*", default=[12, 24, 48], help="part 1's batch sizes (default 12 24 48; none to skip part 1)")
    parser.add_argument("--sweep-batch", type=int, default=48, help="batch size of part 2 (default 48)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="part 2's worker counts (default 1 2)")
    args = parser.parse_args()
    print(f"{os.cpu_count()} cores; load average before: {os.getloadavg()[0]:.2f}")
    print("part 1: one batch in this process")
    for size in args.batch_sizes:
        spec = spec_for(size, args.duration, size)
        runs = spec.runs()[:size]
        cpu, start = cpu_seconds(), time.perf_counter()
        run_batch(spec.to_dict(), runs)
        print(line(f"batch of {size}", size, time.perf_counter() - start, cpu_seconds() - cpu), flush=True)
    print(f"part 2: run_sweep, batches of {args.sweep_batch}")
    rates = {}
    configurations = [(w, None) for w in args.workers]
    if 1 in args.workers:
        configurations.insert(1, (1, 1))  # one worker process on one core: the unit the scaling is counted in
    for workers, threads in configurations:
        spec = spec_for(args.runs, args.duration, args.sweep_batch)
        with tempfile.TemporaryDirectory() as out:
            cpu, start = cpu_seconds(), time.perf_counter()
            table = run_sweep(spec, out, workers=workers, threads=threads, progress=False, figures=False)
            wall = time.perf_counter() - start
        rates[(workers, threads)] = 60.0 * table.num_rows / wall
        label = f"{workers} worker(s), " + ("physics on all cores" if workers == 1 and threads is None else f"{threads or (os.cpu_count() or 1) // workers} thread(s) each")
        print(line(label, table.num_rows, wall, cpu_seconds() - cpu), flush=True)
    if (1, None) in rates and (2, None) in rates:
        print(f"speed-up 1 -> 2 workers: {rates[(2, None)] / rates[(1, None)]:.2f}x (1 worker with the physics on all cores), "
              f"{rates[(2, None)] / rates[(1, 1)]:.2f}x (1 worker on one core)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
