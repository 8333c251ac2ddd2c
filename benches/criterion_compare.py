"""The criterion benchmarks of `legkit-dynamics` on this tree against a saved baseline, one ratio per benchmark.

By default the baseline is the code of `main`: the script checks it out in a temporary git worktree (removed
afterwards), runs `cargo bench -p legkit-dynamics --bench "*" -- --save-baseline base` there with this
tree's target directory (so the dependencies are built once), then `cargo bench ... -- --baseline-lenient base` here, and
prints each benchmark's median time under both and their ratio (this tree / baseline), flagging the ratios beyond
the threshold. It is a benchmark, never a test: run it before landing a change to the core, on a machine as quiet
as you can find, and rerun a flagged row alone (a filter after `--`) before believing it.

    python benches/criterion_compare.py                          # main against this tree, every benchmark
    python benches/criterion_compare.py --base HEAD~3 -- chain64  # another baseline; criterion's filter
    python benches/criterion_compare.py --saved                  # against the baseline saved by the last run
    python benches/criterion_compare.py -- --warm-up-time 1 --measurement-time 3   # shorter runs, noisier

The exit status is 1 when a ratio is beyond the threshold, so that a script can stop on it.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")).resolve()
CRITERION = TARGET / "criterion"
BASELINE = "base"


def cargo_bench(cwd: Path, criterion_args: list[str]) -> None:
    env = {**os.environ, "CARGO_TARGET_DIR": str(TARGET), "CRITERION_HOME": str(CRITERION)}
    env.setdefault("CARGO_BUILD_JOBS", "1")
    command = ["cargo", "bench", "-p", "legkit-dynamics", "--bench", "*", "--", *criterion_args]
    print(f"$ (cd {cwd} && {shlex.join(command)})", flush=True)
    subprocess.run(command, cwd=cwd, env=env, check=True, stdout=subprocess.DEVNULL)


def save_baseline(ref: str, criterion_args: list[str]) -> None:
    """Runs the benchmarks of `ref`'s code in a temporary worktree and saves them as the baseline."""
    # Outside this tree: cargo would merge this tree's .cargo/config.toml with the worktree's, doubling the rustflags,
    # and so rebuild every dependency.
    tree = Path(tempfile.mkdtemp(prefix="legkit-bench-base-")) / "tree"
    subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(tree), ref], cwd=ROOT, check=True)
    try:
        cargo_bench(tree, ["--save-baseline", BASELINE, *criterion_args])
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, check=False)
        shutil.rmtree(tree.parent, ignore_errors=True)


def median_ns(estimates: Path) -> float:
    return float(json.loads(estimates.read_text())["median"]["point_estimate"])


def results(since: float) -> list[tuple[str, float | None, float]]:
    """(benchmark, baseline median or None, this run's median) in ns, for the benchmarks this run measured."""
    rows = []
    for new in sorted(CRITERION.glob("**/new/estimates.json")):
        if new.stat().st_mtime < since:
            continue
        bench = new.parent.parent
        base = bench / BASELINE / "estimates.json"
        name = json.loads((new.parent / "benchmark.json").read_text())["full_id"]
        rows.append((name, median_ns(base) if base.exists() else None, median_ns(new)))
    return rows


def report(rows: list[tuple[str, float | None, float]], threshold: float) -> int:
    """Prints the table; returns how many ratios are beyond 1 + threshold."""
    width = max([len(name) for name, _, _ in rows] + [9])
    print(f"\n{'benchmark':<{width}}  {'baseline':>12}  {'this tree':>12}  {'ratio':>6}")
    regressions = 0
    for name, base, new in rows:
        if base is None:
            print(f"{name:<{width}}  {'(none)':>12}  {format_time(new):>12}  {'new':>6}")
            continue
        ratio = new / base
        flag = ""
        if ratio > 1 + threshold:
            flag, regressions = "  SLOWER", regressions + 1
        elif ratio < 1 - threshold:
            flag = "  faster"
        print(f"{name:<{width}}  {format_time(base):>12}  {format_time(new):>12}  {ratio:6.3f}{flag}")
    print(f"\n{regressions} of {sum(b is not None for _, b, _ in rows)} benchmarks more than {threshold:.0%} slower "
          "(medians; rerun a flagged one alone before believing it)")
    return regressions


def format_time(ns: float) -> str:
    for unit, scale in (("s", 1e9), ("ms", 1e6), ("µs", 1e3)):
        if ns >= scale:
            return f"{ns / scale:.3f} {unit}"
    return f"{ns:.1f} ns"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--base", default="main", help="git revision whose code is the baseline (default: main)")
    which.add_argument("--saved", action="store_true", help="compare with the baseline the last run saved")
    parser.add_argument("--threshold", type=float, default=10.0, help="percent slower that flags a row (default 10)")
    parser.add_argument("criterion", nargs="*", help="after --: criterion's arguments (a filter, --measurement-time)")
    args = parser.parse_args()
    if args.threshold < 0:
        parser.error(f"--threshold must be >= 0, got {args.threshold}")
    if not args.saved:
        save_baseline(args.base, args.criterion)
    elif not any(CRITERION.glob(f"**/{BASELINE}/estimates.json")):
        sys.exit(f"--saved: no baseline '{BASELINE}' under {CRITERION}; run once without --saved")
    # The baseline's build wrote the same artefacts as this tree's (cargo names them relative to the workspace root),
    # from files newer than this tree's: touching the crate's root makes cargo rebuild it from this tree's sources.
    (ROOT / "crates" / "dynamics" / "src" / "lib.rs").touch()
    start = time.time()
    cargo_bench(ROOT, ["--baseline-lenient", BASELINE, *args.criterion])
    rows = results(start)
    if not rows:
        sys.exit("no benchmark ran (does the filter match any?)")
    sys.exit(1 if report(rows, args.threshold / 100) else 0)


if __name__ == "__main__":
    main()
