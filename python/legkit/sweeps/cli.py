"""``legkit sweep``: a grid of balance runs, locally or on Ray, into a resumable Parquet folder with figures.

Every axis takes one or more values; ``a:b:n`` stands for n values evenly from a to b. ``--c0``/``--c1``
values apply to every scheme, or to one with ``scheme=values`` (``--c1 distance=0:1:6 momentum=0:5:6``).
Examples:

    legkit sweep --trees 8                                       # 8 trees x 3 schemes, the paper's gains, into legkit-out/sweep
    legkit sweep --trees 16 --schemes distance momentum --c0 0:1:5 --c1 0:2:5 --out grid
    legkit sweep --trees 32 --loss 0 0.1 0.3 --terrain 0 0.01 --noise 0 0.02 --seeds 2 --ray auto --out faults

Running the same command again with the same --out resumes: finished batches whose parts check out are kept,
the rest run (--strict refuses a damaged part instead; --allow-mixed resumes a folder written by another
legkit build). Ctrl-C stops at once, keeps the finished batches and exits with status 130.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from legkit._help import HelpFormatter
from legkit._validation import add_output_folder, bounded_int
from legkit.control.gains import SCHEMES
from legkit.sweeps.spec import SweepSpec

if TYPE_CHECKING:
    import pyarrow as pa


def parse_values(name: str, tokens: list[str], kind: type = float) -> list[Any]:
    """Numbers from ``tokens``, each a value or ``a:b:n`` (n values evenly from a to b); ValueError naming ``name``."""
    values: list[Any] = []
    for token in tokens:
        for part in token.split(","):
            if not part:
                continue
            try:
                if ":" in part:
                    low, high, count = part.split(":")
                    values += [kind(v) for v in np.linspace(float(low), float(high), int(count))]
                else:
                    values.append(kind(part))
            except ValueError:
                raise ValueError(f"--{name}: expected numbers or a:b:n ranges, got {part!r}") from None
    return values


def parse_coefficients(name: str, tokens: list[str] | None) -> Any:
    """``--c0``/``--c1``: None (the paper's), values for every scheme, or ``scheme=values`` tokens (a mapping)."""
    if tokens is None:
        return None
    if not any("=" in t for t in tokens):
        return parse_values(name, tokens)
    mapping = {}
    for token in tokens:
        scheme, _, values = token.partition("=")
        if scheme not in SCHEMES or not values:
            raise ValueError(f"--{name}: expected scheme=values with a scheme of {SCHEMES}, got {token!r}")
        mapping[scheme] = parse_values(name, [values])
    return mapping


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="legkit sweep", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter,
        epilog=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument("--spec", type=Path, help="a JSON file of SweepSpec arguments (the axis options below are then ignored)")
    parser.add_argument("--trees", nargs="+", default=["4"], help="number of random trees (seeds 0..n-1), or --tree-seeds")
    parser.add_argument("--tree-seeds", nargs="+", help="explicit tree seeds (values or a:b:n)")
    parser.add_argument("--modules", type=bounded_int(1, 10_000), default=20, help="modules per tree besides the root (default 20)")
    parser.add_argument("--branches", type=bounded_int(1, 10_000), default=4, help="branches off the root (default 4)")
    parser.add_argument("--schemes", nargs="+", default=list(SCHEMES), help=f"gain schedules (default all: {' '.join(SCHEMES)})")
    parser.add_argument("--c0", nargs="+", help="c0 values (default: the paper's per scheme)")
    parser.add_argument("--c1", nargs="+", help="c1 values (default: the paper's per scheme)")
    for name, default in (("kp0", "10"), ("ki0", "0.1"), ("kd0", "1e-4")):
        parser.add_argument(f"--{name}", nargs="+", default=[default], help=f"base gain values (default {default})")
    parser.add_argument("--loss", nargs="+", default=["0"], help="bus loss probabilities (default 0)")
    parser.add_argument("--delay", nargs="+", default=["1"], help="largest bus delays in ticks (default 1)")
    parser.add_argument("--terrain", nargs="+", default=["0"], help="terrain roughness depths in m (default 0: plane)")
    parser.add_argument("--friction", nargs="+", default=["0.8"], help="ground friction coefficients (default 0.8)")
    parser.add_argument("--noise", nargs="+", default=["0"], help="sensor noise std on the joint angles, rad (default 0)")
    parser.add_argument("--seeds", type=bounded_int(1, 10_000), default=1, help="replicates per configuration (default 1)")
    parser.add_argument("--duration", type=float, default=2.0, help="simulated seconds per run (default 2)")
    parser.add_argument("--batch-size", type=bounded_int(1, 10_000), default=48,
                        help="runs per batch, one Parquet part (default 48; runs per task adapt to the workers)")
    parser.add_argument("--workers", type=bounded_int(1, 1024), help="local worker processes (default: one per core)")
    parser.add_argument("--ray", metavar="ADDRESS",
                        help="run on Ray: 'auto' or 'ray://host:10001' (a running cluster), or 'local' (start one here, even if RAY_ADDRESS is set)")
    parser.add_argument("--strict", action="store_true", help="refuse a damaged or foreign part in --out (naming it) rather than run its batch again")
    parser.add_argument("--allow-mixed", action="store_true", help="resume a folder started by another legkit build (each row records its build)")
    add_output_folder(parser, "sweep", "results.parquet and its figures (checked when the sweep starts)", checked=False)
    parser.add_argument("--no-figures", action="store_true", help="do not draw the summary figures")
    parser.add_argument("--dry-run", action="store_true", help="print the number of runs and batches, run nothing")
    return parser


def spec_from_args(args: argparse.Namespace) -> SweepSpec:
    if args.spec is not None:
        try:
            text = args.spec.read_text()
        except OSError as error:
            raise ValueError(f"--spec: cannot read {str(args.spec)!r}: {error.strerror or error}") from None
        try:
            values = json.loads(text)
        except ValueError as error:
            raise ValueError(f"--spec: {str(args.spec)!r} is not JSON ({error})") from None
        if not isinstance(values, dict):
            raise ValueError(f"--spec: {str(args.spec)!r} must hold a JSON object of SweepSpec arguments")
        return SweepSpec.from_dict(values)
    trees: Any = parse_values("tree-seeds", args.tree_seeds, int) if args.tree_seeds else None
    if trees is None:
        counts = parse_values("trees", args.trees, int)
        if len(counts) != 1:
            raise ValueError("--trees: one count; list seeds with --tree-seeds")
        trees = counts[0]
    return SweepSpec(
        trees=trees, modules=args.modules, branches=args.branches, schemes=args.schemes,
        c0=parse_coefficients("c0", args.c0), c1=parse_coefficients("c1", args.c1),
        kp0=parse_values("kp0", args.kp0), ki0=parse_values("ki0", args.ki0), kd0=parse_values("kd0", args.kd0),
        loss=parse_values("loss", args.loss), delay=parse_values("delay", args.delay, int), terrain=parse_values("terrain", args.terrain),
        friction=parse_values("friction", args.friction), noise=parse_values("noise", args.noise), seeds=args.seeds,
        duration=args.duration, batch_size=args.batch_size,
    )


def summary(table: pa.Table) -> str:
    """Per scheme: runs, median final distance and t10% with their interquartile ranges."""
    columns = table.to_pydict()
    scheme = np.array(columns["scheme"])
    lines = [f"{'scheme':>9} {'runs':>5} {'final median [IQR] (widths)':>30} {'t10% median [IQR] (s)':>28} {'reached':>8}"]
    for s in SCHEMES:
        mask = scheme == s
        if not mask.any():
            continue
        final = np.array(columns["final"])[mask]
        t10 = np.array(columns["t10"], dtype=float)[mask]
        t10 = np.where(np.isnan(t10), np.inf, t10)
        lines.append(f"{s:>9} {mask.sum():>5} {median_quartiles(final):>30} {median_quartiles(t10):>28} {np.isfinite(t10).mean():>7.0%}")
    return "\n".join(lines)


def median_quartiles(values: np.ndarray) -> str:
    """"median [first quartile, third quartile]", lower ones (values of actual runs: inf, a run that never got there, prints "never")."""
    q1, median, q3 = np.percentile(values, [25, 50, 75], method="lower")
    text = lambda v: "never" if not np.isfinite(v) else f"{v:.3f}"  # noqa: E731
    return f"{text(median)} [{text(q1)}, {text(q3)}]"


def check_out(path: Path) -> None:
    """ValueError naming --out unless ``path`` is a folder, or can become one, that this process can write
    (checked without creating anything)."""
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing == path and not path.is_dir():
        raise ValueError(f"--out: {str(path)!r} is a file, not a folder")
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"--out: cannot write to {str(existing)!r}")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from legkit._extras import require
    from legkit.sweeps.execute import run_sweep

    try:
        spec = spec_from_args(args)
        if args.dry_run:
            print(f"{len(spec.runs())} runs in {len(spec.batches())} batches (spec id {spec.spec_id})")
            return 0
        require("pyarrow", *(["ray"] if args.ray else []))
        check_out(args.out)
        table = run_sweep(
            spec, args.out, workers=args.workers, ray=args.ray, figures=not args.no_figures, strict=args.strict, allow_mixed=args.allow_mixed,
        )
    except (ValueError, TypeError, ImportError) as error:
        print(f"legkit sweep: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:  # SweepInterrupted says what is kept and how to resume
        text = str(interrupt) or f"interrupted; the finished batches are kept in {args.out}: run the same command again to resume"
        print(f"legkit sweep: {text}", file=sys.stderr)
        return 130
    print(summary(table))
    print(f"wrote {args.out}/results.parquet ({table.num_rows} runs)" + ("" if args.no_figures else " and its figures"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
