"""Side-by-side timing of legkit and Pinocchio dynamics, called from Python, on identical models.

For each model of `models.MODELS` (a 63-DoF SuperBot-like tree, revolute chains of 6 to 1024 links, a
floating-base quadruped) the script first checks that both libraries agree (ABA, RNEA, CRBA, M^-1 at one
random state, to 1e-8 relative; it aborts otherwise), then times one call of each algorithm from Python,
same state, same process, interleaved:

    legkit:    lk.aba(model, q, v, tau), lk.rnea(model, q, v, a), lk.crba(model, q), lk.minv(model, q),
               lk.point_accelerations(model, q, v, a, [(last body, point)])
    pinocchio: pin.aba(model, data, q, v, tau), pin.rnea(...), pin.crba(model, data, q),
               pin.computeMinverse(model, data, q)            (one preallocated pin.Data per model),
               pin.forwardKinematics(model, data, q, v, a) then pin.getFrameClassicalAcceleration(model, data,
               frame, LOCAL_WORLD_ALIGNED), the frame at the same point (PointAcc: two Python calls for
               Pinocchio, as its users make them)

Each figure is the median over `timeit` repeats (7, or 3 with --quick) of the mean per-call time of a repeat,
the number of calls per repeat chosen so that a repeat lasts ~0.15 s; legkit's and Pinocchio's repeats are
interleaved. A row is flagged "noisy" when its repeats spread by more than 25% of the median.

Targets: legkit / pin <= 0.8 per row; ABA linearity time(chain1024) / time(chain64) <= 18; one batched lk.aba over 10,000 states of the 63-DoF
tree >= 1.7x faster than a Python loop of 10,000 single calls. The targets are printed, never asserted.

Pinocchio 4.1's `Data` grows as the cube of the number of joints (~4 GB and ~15 s to allocate for 512
joints, ~35 GB estimated for 1024), so Pinocchio is not run on models with more than `PIN_MAX_JOINTS`
joints: chain1024 is timed for legkit alone, and Pinocchio's linearity ratio uses chain512.

The batch section also prints how many cores each contender actually got (process CPU time / wall time):
the batched call's per-state CPU cost is about a single call's, so its speedup is its parallelism, which a
busy shared machine takes away.

Run from the repository root (or anywhere):  python benches/dynamics_vs_pinocchio.py [--quick] [--models ...]
"""

from __future__ import annotations

import argparse
import fnmatch
import os
import platform
import resource
import sys
import time
import timeit
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

import legkit as lk

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import MODELS, random_state, superbot_tree  # noqa: E402

ALGORITHMS = ("ABA", "RNEA", "CRBA", "Minv", "PointAcc")
#: The point (last body's frame) whose classical acceleration PointAcc times.
POINT = np.array([0.05, 0.02, -0.1])
RTOL = 1e-8
TARGET_RATIO = 0.8
TARGET_LINEARITY = 18.0
TARGET_BATCH_SPEEDUP = 1.7
BATCH = 10_000
PIN_MAX_JOINTS = 600  # see the module docstring: pin.Data is O(njoints^3) in memory
LINEARITY_CHAINS = ("chain64", "chain512", "chain1024")


# --------------------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------------------


@dataclass
class Timing:
    median_us: float  # per call
    spread: float  # (max - min) / median over the repeats
    number: int  # calls per repeat


@dataclass
class Settings:
    repeat: int = 7
    seconds_per_repeat: float = 0.15


def _timer(f: Callable, args: tuple) -> timeit.Timer:
    """A timer of f(*args) with the callable and its arguments bound to locals of timeit's inner function,
    so a call costs the same interpreter overhead for both libraries (one CALL with positional arguments)."""
    names = [f"x{i}" for i in range(len(args))]
    namespace = {"_f": f, **{f"_{n}": a for n, a in zip(names, args)}}
    setup = "; ".join(["f = _f"] + [f"{n} = _{n}" for n in names])
    return timeit.Timer(f"f({', '.join(names)})", setup=setup, globals=namespace)


def _calibrate(timer: timeit.Timer, settings: Settings) -> int:
    """Calls per repeat for a repeat of ~seconds_per_repeat: grow the count until a run lasts >= 20 ms."""
    number = 1
    while True:
        elapsed = timer.timeit(number)
        if elapsed >= 0.02 or number >= 1 << 24:
            break
        number *= 10 if elapsed < 0.002 else 2
    return max(1, round(number * settings.seconds_per_repeat / max(elapsed, 1e-9)))


def time_calls(calls: list[tuple[Callable, tuple]], settings: Settings) -> list[Timing]:
    """Median per-call time of each f(*args) over `settings.repeat` repeats of ~seconds_per_repeat.

    The repeats of the different calls are interleaved (A B A B ...), so that a slow spell of the shared
    machine hits every contender alike rather than whichever happened to be running.
    """
    timers = [_timer(f, args) for f, args in calls]
    numbers = [_calibrate(t, settings) for t in timers]
    runs = [[] for _ in timers]
    for _ in range(settings.repeat):
        for timer, number, out in zip(timers, numbers, runs):
            out.append(timer.timeit(number) / number)
    timings = []
    for out, number in zip(runs, numbers):
        per_call = np.array(out)
        median = float(np.median(per_call))
        timings.append(Timing(median * 1e6, float((per_call.max() - per_call.min()) / median), number))
    return timings


def time_call(f: Callable, args: tuple, settings: Settings) -> Timing:
    return time_calls([(f, args)], settings)[0]


# --------------------------------------------------------------------------------------------------
# Equivalence
# --------------------------------------------------------------------------------------------------


def symmetrised_upper(M: np.ndarray) -> np.ndarray:
    """Pinocchio fills only the upper triangle of M and M^-1."""
    U = np.triu(M)
    return U + np.triu(U, 1).T


def relative_error(x: np.ndarray, reference: np.ndarray) -> float:
    return float(np.max(np.abs(x - reference)) / max(float(np.max(np.abs(reference))), 1e-300))


def pin_point_acceleration(pin_model, pin_data, frame: int, q, v, acc) -> np.ndarray:
    pin.forwardKinematics(pin_model, pin_data, q, v, acc)
    return pin.getFrameClassicalAcceleration(pin_model, pin_data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear


def check_equivalence(name: str, lk_model, pin_model, pin_data, frame: int, state) -> dict[str, float]:
    q, v, tau, acc = state
    pairs = {
        "ABA": (lk.aba(lk_model, q, v, tau), pin.aba(pin_model, pin_data, q, v, tau).copy()),
        "RNEA": (lk.rnea(lk_model, q, v, acc), pin.rnea(pin_model, pin_data, q, v, acc).copy()),
        "CRBA": (lk.crba(lk_model, q), symmetrised_upper(pin.crba(pin_model, pin_data, q).copy())),
        "Minv": (lk.minv(lk_model, q), symmetrised_upper(pin.computeMinverse(pin_model, pin_data, q).copy())),
        "PointAcc": (lk.point_accelerations(lk_model, q, v, acc, [(lk_model.nbodies - 1, POINT)])[0],
                     pin_point_acceleration(pin_model, pin_data, frame, q, v, acc).copy()),
    }
    errors = {}
    for algorithm, (ours, theirs) in pairs.items():
        if ours.shape != theirs.shape:
            sys.exit(f"ABORT: {name} {algorithm}: legkit shape {ours.shape} != pinocchio shape {theirs.shape}")
        errors[algorithm] = relative_error(ours, theirs)
        if not errors[algorithm] <= RTOL:
            sys.exit(
                f"ABORT: {name}: legkit and Pinocchio disagree on {algorithm}: max |difference| / max |pin| = "
                f"{errors[algorithm]:.3e} > {RTOL:g}. The models are not identical (or one library is wrong); "
                "timings would be meaningless."
            )
    return errors


# --------------------------------------------------------------------------------------------------
# The table
# --------------------------------------------------------------------------------------------------


@dataclass
class ModelResult:
    name: str
    nv: int
    lk: dict[str, Timing] = field(default_factory=dict)
    pin: dict[str, Timing | None] = field(default_factory=dict)
    max_error: float | None = None
    # The ABA calls (legkit, pinocchio or None) of the chains used again by the linearity section.
    aba_calls: tuple[tuple, tuple | None] | None = None


def calls(lk_model, pin_model, pin_data, frame: int, state) -> dict[str, tuple[tuple, tuple | None]]:
    q, v, tau, acc = state
    lk_calls = {
        "ABA": (lk.aba, (lk_model, q, v, tau)),
        "RNEA": (lk.rnea, (lk_model, q, v, acc)),
        "CRBA": (lk.crba, (lk_model, q)),
        "Minv": (lk.minv, (lk_model, q)),
        "PointAcc": (lk.point_accelerations, (lk_model, q, v, acc, [(lk_model.nbodies - 1, POINT)])),
    }
    pin_calls = {
        "ABA": (pin.aba, (pin_model, pin_data, q, v, tau)),
        "RNEA": (pin.rnea, (pin_model, pin_data, q, v, acc)),
        "CRBA": (pin.crba, (pin_model, pin_data, q)),
        "Minv": (pin.computeMinverse, (pin_model, pin_data, q)),
        "PointAcc": (pin_point_acceleration, (pin_model, pin_data, frame, q, v, acc)),
    }
    return {a: (lk_calls[a], pin_calls[a] if pin_data is not None else None) for a in ALGORITHMS}


HEADER = f"{'model':<10} {'nv':>5} {'algorithm':<9} {'legkit µs':>11} {'pin µs':>11} {'lk/pin':>7}  {'':<6}"


def format_row(model: str, nv: int, algorithm: str, ours: Timing, theirs: Timing | None) -> str:
    row = f"{model:<10} {nv:>5} {algorithm:<9} {ours.median_us:>11.3f} "
    spread = max(ours.spread, theirs.spread if theirs is not None else 0.0)
    noisy = f"  (noisy: spread {spread:.0%})" if spread > 0.25 else ""
    if theirs is None:
        return row + f"{'n/a':>11} {'n/a':>7}  {'':<6}{noisy}"
    ratio = ours.median_us / theirs.median_us
    verdict = "ok" if ratio <= TARGET_RATIO else "MISS"
    return row + f"{theirs.median_us:>11.3f} {ratio:>7.2f}  {verdict:<6}{noisy}"


def run_model(name: str, settings: Settings, rng: np.random.Generator) -> ModelResult:
    lk_model, pin_model = MODELS[name]()
    result = ModelResult(name, lk_model.nv)
    q, v, tau = random_state(lk_model, rng)
    acc = rng.normal(size=lk_model.nv)
    state = (q, v, tau, acc)
    # legkit's last body is Pinocchio's last joint (`models.build`: joint frames are body frames).
    frame = pin_model.addFrame(pin.Frame("point", pin_model.njoints - 1, pin.SE3(np.eye(3), POINT), pin.FrameType.OP_FRAME))
    pin_data = pin_model.createData() if pin_model.njoints <= PIN_MAX_JOINTS else None
    if pin_data is not None:
        result.max_error = max(check_equivalence(name, lk_model, pin_model, pin_data, frame, state).values())
    for algorithm, ((lk_f, lk_args), pin_call) in calls(lk_model, pin_model, pin_data, frame, state).items():
        if pin_call is None:
            result.lk[algorithm], result.pin[algorithm] = time_call(lk_f, lk_args, settings), None
        else:
            result.lk[algorithm], result.pin[algorithm] = time_calls([(lk_f, lk_args), pin_call], settings)
        print(format_row(name, result.nv, algorithm, result.lk[algorithm], result.pin[algorithm]), flush=True)
        if algorithm == "ABA" and name in LINEARITY_CHAINS:
            result.aba_calls = ((lk_f, lk_args), pin_call)  # keeps pin_data (and its memory) alive
    return result


# --------------------------------------------------------------------------------------------------
# ABA linearity and batch
# --------------------------------------------------------------------------------------------------


def linearity(results: dict[str, ModelResult], settings: Settings, rng) -> None:
    """ABA on chain64, chain512 and chain1024 timed again, interleaved, so that each ratio compares
    times taken under the same load (the table's rows were timed up to a minute apart). legkit's chain1024,
    left out of the table by --quick, is built here (ABA alone is cheap); nothing else is."""
    print("\nABA linearity: time per call on a long chain / on chain64 (O(n) scaling would give n / 64),"
          " re-timed interleaved")
    entries: dict[tuple[str, str], tuple | str] = {}
    for name in LINEARITY_CHAINS:
        if name in results and results[name].aba_calls is not None:
            lk_call, pin_call = results[name].aba_calls
        elif name == "chain1024":
            lk_model, _ = MODELS[name]()
            q, v, tau = random_state(lk_model, rng)
            lk_call, pin_call = (lk.aba, (lk_model, q, v, tau)), None
        else:
            entries[("legkit", name)] = entries[("pinocchio", name)] = f"{name} not selected"
            continue
        n = int(name.removeprefix("chain"))
        entries[("legkit", name)] = lk_call
        entries[("pinocchio", name)] = pin_call if pin_call is not None else (
            f"not run: pin.Data for {n + 1} joints would need ~{4.2 * (n / 512) ** 3:.0f} GB"
        )
    runnable = [key for key, call in entries.items() if not isinstance(call, str)]
    times = dict(zip(runnable, (t.median_us for t in time_calls([entries[k] for k in runnable], settings))))
    for lib in ("legkit", "pinocchio"):
        for long in LINEARITY_CHAINS[1:]:
            n = int(long.removeprefix("chain"))
            t, base = times.get((lib, long)), times.get((lib, "chain64"))
            if t is None or base is None:
                why = entries[(lib, long)] if t is None else entries[(lib, "chain64")]
                print(f"  {lib:<9} {long:>9} / chain64: {why}")
                continue
            ratio = t / base
            target = ""
            if n == 1024:
                target = f"  target <= {TARGET_LINEARITY:g}: {'ok' if ratio <= TARGET_LINEARITY else 'MISS'}"
            print(f"  {lib:<9} {long:>9} / chain64: {t:9.2f} µs / {base:6.2f} µs = {ratio:6.2f}"
                  f"  (linear: {n / 64:g}){target}")


def cores_used(f: Callable, calls: int = 5) -> float:
    """Process CPU time / wall time over `calls` calls of f: how many cores f actually got."""
    def cpu() -> float:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return usage.ru_utime + usage.ru_stime

    c0, w0 = cpu(), time.perf_counter()
    for _ in range(calls):
        f()
    return (cpu() - c0) / (time.perf_counter() - w0)


def batch(settings: Settings, rng) -> None:
    lk_model, _ = superbot_tree()
    Q, V, T = random_state(lk_model, rng, (BATCH,))
    rows = list(zip(Q, V, T))  # row views, made once: the loop below times the calls only
    aba = lk.aba

    def loop():
        for q, v, tau in rows:
            aba(lk_model, q, v, tau)

    batched = aba(lk_model, Q, V, T)
    single = np.stack([aba(lk_model, q, v, tau) for q, v, tau in rows])
    err = relative_error(batched, single)
    if not err <= RTOL:
        sys.exit(f"ABORT: batched lk.aba differs from single calls: relative error {err:.3e}")
    one, many = time_calls([(aba, (lk_model, Q, V, T)), (loop, ())], settings)
    used = {"batch": cores_used(lambda: aba(lk_model, Q, V, T)), "loop": cores_used(loop, 2)}
    speedup = many.median_us / one.median_us
    print(f"\nBatch: lk.aba on {BATCH:,} random states of the 63-DoF tree (identical results: rel. error {err:.1e})")
    print(f"  one batched call : {one.median_us / 1e3:9.3f} ms  ({one.median_us / BATCH * 1e3:7.1f} ns/state)"
          f"  cores used (CPU time / wall time): {used['batch']:.2f}")
    print(f"  Python loop      : {many.median_us / 1e3:9.3f} ms  ({many.median_us / BATCH * 1e3:7.1f} ns/state)"
          f"  cores used: {used['loop']:.2f}")
    verdict = "ok" if speedup >= TARGET_BATCH_SPEEDUP else "MISS"
    print(f"  speedup          : {speedup:9.2f}x  (target >= {TARGET_BATCH_SPEEDUP:g}x: {verdict})")


# --------------------------------------------------------------------------------------------------


def load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "n/a"


def select(patterns: list[str] | None, quick: bool) -> list[str]:
    names = list(MODELS)
    if patterns:
        unknown = [p for p in patterns if not any(fnmatch.fnmatchcase(n, p) for n in names)]
        if unknown:
            sys.exit(f"--models: {unknown} match none of {names}")
        names = [n for n in names if any(fnmatch.fnmatchcase(n, p) for p in patterns)]
    if quick:
        names = [n for n in names if n != "chain1024"]
    return names


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 repeats of ~0.05 s, no chain1024 in the table")
    parser.add_argument(
        "--models", nargs="+", metavar="PATTERN", help=f"model names or shell patterns, from: {' '.join(MODELS)}"
    )
    args = parser.parse_args()
    settings = Settings(repeat=3, seconds_per_repeat=0.05) if args.quick else Settings()
    names = select(args.models, args.quick)

    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    print(f"cores: os.cpu_count() = {os.cpu_count()}, usable (affinity) = {affinity}"
          f", RAYON_NUM_THREADS = {os.environ.get('RAYON_NUM_THREADS', 'unset')}")
    print(f"pinocchio {pin.__version__}, numpy {np.__version__}, python {platform.python_version()}, "
          f"legkit from {Path(lk.__file__).parent}")
    print(f"load average at start: {load()}  (a busy machine inflates times and hides the batch's parallelism)")
    print(f"timing: median of {settings.repeat} repeats of ~{settings.seconds_per_repeat:g} s each; "
          f"equivalence checked to {RTOL:g} relative; target legkit/pin <= {TARGET_RATIO:g}\n")

    rng = np.random.default_rng(20240601)
    start = time.perf_counter()
    print(HEADER)
    print("-" * len(HEADER))
    results: dict[str, ModelResult] = {}
    for name in names:
        results[name] = run_model(name, settings, rng)
    checked = [r.max_error for r in results.values() if r.max_error is not None]
    if checked:
        print(f"(equivalence: worst relative difference over all checked models and algorithms {max(checked):.1e})")
    missed = [
        f"{r.name}/{a}" for r in results.values() for a in ALGORITHMS
        if r.pin.get(a) is not None and r.lk[a].median_us / r.pin[a].median_us > TARGET_RATIO
    ]
    print(f"rows missing the {TARGET_RATIO:g} target: {', '.join(missed) if missed else 'none'}")

    linearity(results, settings, rng)
    batch(settings, rng)
    print(f"\ntotal {time.perf_counter() - start:.0f} s; load average at end: {load()}")


if __name__ == "__main__":
    main()
