"""``legkit tune``: search the gain constants of each scheme on training trees, validate on held-out trees.

The paper (Moll et al., IROS 2006, Sect. V) chose its gains by hand: K_P0 = 10, K_I0 = 0.1, K_D0 = 1e-4;
c0, c1 = (1, 0) constant, (0, 0.1) distance, (0, 1) momentum. Here Optuna's TPE sampler (seeded) searches,
per scheme, c0 and c1 (the constant scheme has no c1) and the base gains K_P0, K_I0, K_D0
(``--paper-base-gains`` keeps the paper's), minimising over the training trees the mean of
``final + t10_weight * t10`` (final distance in module widths; t10 in s, a run that never gets within 10 %
counting twice the duration; ``T10_WEIGHT`` = 2 widths per second by default). The paper's constants are
the first trial of every scheme. Locally, Optuna evaluates trials in rounds: each round asks every scheme
for ``per_round`` trials and runs all their training runs together, in batches (many runs per
``run_balance`` call) on the local workers. With ``--ray`` (or Ray already initialised) each scheme is a
Ray Tune experiment searched by the same sampler through ``ray.tune.search.optuna.OptunaSearch``, up to
``per_round`` trials at once, each trial a task of one CPU running its training trees in batches; within
TPE's random start-up (its first 10 trials) it proposes the same constants as the local search, later ones
differ as trials finish in another order. Then the paper's and
the tuned constants run on held-out trees (other seeds) and both are reported: median final distance and
median t10% with their interquartile ranges (lower medians and quartiles: values of actual runs, so
"never" stays a value), and the change of the medians.

The defaults fit a few minutes on two cores (4 training trees, 6 held-out, 32 trials per scheme, 1 s
runs). The full-size study (docs/sweeps.md):

    legkit tune --train 32 --test 64 --trials 120 --per-round 8 --duration 2 --ray auto
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import math
import shutil
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from legkit._extras import require
from legkit._help import HelpFormatter
from legkit._validation import bounded_int, positive_scalar
from legkit.control.gains import SCHEMES, GainSchedule
from legkit.sweeps.cli import median_quartiles
from legkit.sweeps.execute import LocalExecutor, RayExecutor, executor, run_batch
from legkit.sweeps.spec import RunParams

if TYPE_CHECKING:
    import optuna

#: Per scheme: (tuned point, the paper's training score, the tuned training score).
_Found = dict[str, tuple[dict[str, Any], float, float]]


class _Trial(Protocol):
    """What the search space needs of a trial: Optuna's, or Ray Tune's wrapper of it."""

    def suggest_float(self, name: str, low: float, high: float, *, log: bool = False) -> float: ...

#: Search ranges: (low, high, log scale).
COEFFICIENT_RANGES = {
    "constant": {"c0": (0.1, 10.0, True)},
    "distance": {"c0": (0.0, 3.0, False), "c1": (0.0, 3.0, False)},
    "momentum": {"c0": (0.0, 3.0, False), "c1": (0.0, 30.0, False)},
}
BASE_GAIN_RANGES = {"kp0": (1.0, 100.0, True), "ki0": (1e-3, 10.0, True), "kd0": (1e-5, 1e-1, True)}
T10_WEIGHT = 2.0  # module widths per second of t10: 0.05 s of t10 weighs as much as 0.1 widths of final distance
TRAIN_SEED0 = 1000
TEST_SEED0 = 2000


@dataclass
class SchemeResult:
    """One scheme's tuning: the paper's and the tuned constants, and the held-out runs of both (final
    distance in module widths, t10 in s with never as inf)."""

    scheme: str
    paper: dict[str, float]
    tuned: dict[str, float]
    train_score_paper: float
    train_score_tuned: float
    t10_weight: float
    test_final: dict[str, np.ndarray] = field(default_factory=dict)  # "paper" / "tuned" -> (n_test,)
    test_t10: dict[str, np.ndarray] = field(default_factory=dict)

    def median(self, metric: str, which: str) -> float:
        values = (self.test_final if metric == "final" else self.test_t10)[which]
        return float(np.percentile(values, 50, method="lower"))

    def improved(self) -> bool:
        """The tuned constants beat the paper's on the held-out trees on both medians (t10 at least as good)."""
        return self.median("final", "tuned") < self.median("final", "paper") and self.median("t10", "tuned") <= self.median("t10", "paper")


def constants(schedule: GainSchedule) -> dict[str, float]:
    return {"c0": schedule.c0, "c1": schedule.c1, "kp0": schedule.kp0, "ki0": schedule.ki0, "kd0": schedule.kd0}


def score(rows: Sequence[dict[str, Any]], duration: float, t10_weight: float = T10_WEIGHT) -> float:
    """The training objective: mean of final + t10_weight * t10 (never: twice the duration)."""
    final = np.array([r["final"] for r in rows])
    t10 = np.array([r["t10"] for r in rows], dtype=float)
    return float(np.mean(final + t10_weight * np.where(np.isnan(t10), 2 * duration, t10)))


def tune(
    schemes: Sequence[str] = SCHEMES, train: int = 4, test: int = 6, trials: int = 32, per_round: int = 4,
    duration: float = 1.0, modules: int = 20, branches: int = 4, base_gains: bool = True, seed: int = 0,
    workers: int | None = 1, ray: str | None = None, batch_size: int = 48, progress: bool = True, t10_weight: float = T10_WEIGHT,
) -> list[SchemeResult]:
    """Tune every scheme of ``schemes`` (see the module docstring); returns one ``SchemeResult`` per scheme."""
    require("optuna", *(["ray"] if ray is not None else []))
    schemes = list(schemes)
    for s in schemes:
        if s not in SCHEMES:
            raise ValueError(f"schemes: each must be one of {SCHEMES}, got {s!r}")
    counts = (("train", train), ("test", test), ("trials", trials), ("per_round", per_round), ("batch_size", batch_size), ("modules", modules))
    for name, value in counts:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name}: must be an int >= 1, got {value!r}")
    positive_scalar(duration, "duration")
    positive_scalar(t10_weight, "t10_weight", allow_zero=True)
    problem = _Problem(
        {"modules": modules, "branches": branches, "duration": float(duration), "dt": 1e-3}, [TRAIN_SEED0 + i for i in range(train)],
        base_gains, t10_weight, batch_size,
    )
    test_seeds = [TEST_SEED0 + i for i in range(test)]
    with executor(workers, ray) as pool:
        search = _search_with_ray_tune if isinstance(pool, RayExecutor) else _search_with_optuna
        found = search(pool, problem, schemes, trials, per_round, seed, progress)
        results, jobs = [], []
        for s in schemes:
            tuned_point, paper_score, tuned_score = found[s]
            tuned, paper = _schedule_of(s, tuned_point), GainSchedule.paper(s)
            jobs += [((s, "paper"), paper, test_seeds), ((s, "tuned"), tuned, test_seeds)]
            results.append(SchemeResult(s, constants(paper), constants(tuned), paper_score, tuned_score, t10_weight))
        rows = _evaluate(pool, problem, jobs)
    for result in results:
        for which in ("paper", "tuned"):
            got = rows[(result.scheme, which)]
            result.test_final[which] = np.array([r["final"] for r in got])
            t10 = np.array([r["t10"] for r in got], dtype=float)
            result.test_t10[which] = np.where(np.isnan(t10), np.inf, t10)
    return results


@dataclass(frozen=True)
class _Problem:
    """What every trial shares: the runs' settings (``run_batch``'s spec values), the training trees, the
    search space's extent, the objective's t10 weight and the runs per batch."""

    spec_values: dict[str, Any]
    train_seeds: list[int]
    base_gains: bool
    t10_weight: float
    batch_size: int

    def space(self, scheme: str) -> dict[str, tuple[float, float, bool]]:
        return {**COEFFICIENT_RANGES[scheme], **(BASE_GAIN_RANGES if self.base_gains else {})}

    def paper_point(self, scheme: str) -> dict[str, float]:
        """The paper's constants as a point of the search space: every study's first trial."""
        return {name: constants(GainSchedule.paper(scheme))[name] for name in self.space(scheme)}

    def score(self, rows: Sequence[dict[str, Any]]) -> float:
        return score(rows, self.spec_values["duration"], self.t10_weight)


def _schedule_of(scheme: str, params: dict[str, float]) -> GainSchedule:
    """The paper's schedule of ``scheme`` with ``params`` (a point of the search space) in place."""
    values = {**constants(GainSchedule.paper(scheme)), **params}
    if scheme == "constant":
        values["c1"] = 0.0
    return GainSchedule(scheme, **values)


def _runs(schedule: GainSchedule, tree_seeds: Sequence[int]) -> list[RunParams]:
    """``schedule`` on each tree, replicate 0, on the plane, reliable bus, no noise."""
    s = schedule
    return [RunParams(tree, s.scheme, s.c0, s.c1, s.kp0, s.ki0, s.kd0, 0.0, 1, 0.0, 0.8, 0.0, 0) for tree in tree_seeds]


def _evaluate(pool: LocalExecutor, problem: _Problem, jobs: list[tuple[Any, GainSchedule, list[int]]]) -> dict[Any, list[dict]]:
    """Run every (key, schedule, tree seeds) job on ``pool``, all in batches; rows per key."""
    runs, keys = [], []
    for key, schedule, seeds in jobs:
        runs += _runs(schedule, seeds)
        keys += [key] * len(seeds)
    parts = max(pool.parallelism, math.ceil(len(runs) / problem.batch_size))
    chunks = [list(c) for c in np.array_split(np.arange(len(runs)), parts) if len(c)]
    rows_by_index: dict[int, dict] = {}
    for chunk_index, rows in pool.map(problem.spec_values, [(k, [runs[i] for i in chunk]) for k, chunk in enumerate(chunks)]):
        rows_by_index.update(zip(chunks[chunk_index], rows))
    out: dict[Any, list[dict]] = {}
    for i in range(len(runs)):
        out.setdefault(keys[i], []).append(rows_by_index[i])
    return out


def _search_with_optuna(
    pool: LocalExecutor, problem: _Problem, schemes: Sequence[str], trials: int, per_round: int, seed: int, progress: bool
) -> _Found:
    """Optuna in this process, trials evaluated in rounds on ``pool``: {scheme: (tuned point, paper's score, tuned score)}."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    studies = {s: optuna.create_study(sampler=_sampler(seed + k)) for k, s in enumerate(schemes)}
    for s, study in studies.items():
        study.enqueue_trial(problem.paper_point(s))
    rounds = math.ceil(trials / per_round)
    for round_index in range(rounds):
        asked = {s: [studies[s].ask() for _ in range(min(per_round, trials - round_index * per_round))] for s in schemes}
        jobs = [
            ((s, trial.number), _schedule_of(s, _suggest_all(trial, problem.space(s))), problem.train_seeds)
            for s, trial_list in asked.items()
            for trial in trial_list
        ]
        rows = _evaluate(pool, problem, jobs)
        for s, trial_list in asked.items():
            for trial in trial_list:
                studies[s].tell(trial, problem.score(rows[(s, trial.number)]))
        if progress:
            best = ", ".join(f"{s} {studies[s].best_value:.3f}" for s in schemes)
            print(f"round {round_index + 1}/{rounds}: best training score {best}", file=sys.stderr, flush=True)
    found: _Found = {}
    for s in schemes:
        paper_score = studies[s].trials[0].value  # the enqueued paper point, told its score in the first round
        assert paper_score is not None
        found[s] = (studies[s].best_params, paper_score, studies[s].best_value)
    return found


def _search_with_ray_tune(
    pool: LocalExecutor, problem: _Problem, schemes: Sequence[str], trials: int, per_round: int, seed: int, progress: bool
) -> _Found:
    """Ray Tune on the Ray instance of ``pool``, one experiment per scheme, searched by Optuna's sampler through
    ``OptunaSearch`` (the same space, sampler and first trial as ``_search_with_optuna``), ``per_round``
    trials at a time, each trial a task of one CPU: {scheme: (tuned point, paper's score, tuned score)}."""
    import optuna
    from ray import tune as ray_tune
    from ray.tune.search.optuna import OptunaSearch

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    found: _Found = {}
    storage = tempfile.mkdtemp(prefix="legkit-tune-")  # Tune's experiment records; nothing in them is kept
    try:
        for k, s in enumerate(schemes):
            space, paper = problem.space(s), problem.paper_point(s)
            searcher = OptunaSearch(
                space=functools.partial(_suggest_all, space=space), metric="score", mode="min", points_to_evaluate=[paper],
                sampler=_sampler(seed + k),
            )
            tuner = ray_tune.Tuner(
                ray_tune.with_parameters(_ray_tune_trial, scheme=s, problem=problem),
                tune_config=ray_tune.TuneConfig(search_alg=searcher, num_samples=trials, max_concurrent_trials=per_round),
                run_config=ray_tune.RunConfig(name=f"legkit-tune-{s}", storage_path=storage, verbose=0),
            )
            with contextlib.redirect_stdout(sys.stderr):  # Tune's banners; stdout is the report's
                grid = tuner.fit()
            if grid.errors:
                raise RuntimeError(f"legkit tune: {len(grid.errors)} Ray Tune trial(s) of {s} failed: {grid.errors[0]}")
            # In trial order: the first of equal scores wins, as in Optuna's best trial.
            scored = []
            for i in range(len(grid)):  # ResultGrid is indexed (no __iter__: type checkers do not take it as iterable)
                result = grid[i]
                assert result.config is not None and result.metrics is not None  # set for every finished trial
                scored.append(({name: result.config[name] for name in space}, result.metrics["score"]))
            tuned, tuned_score = min(scored, key=lambda point_score: point_score[1])
            (paper_score,) = [value for point, value in scored if point == paper]
            found[s] = (tuned, paper_score, tuned_score)
            if progress:
                print(f"{s}: {len(scored)} trials on Ray Tune, best training score {tuned_score:.3f}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(storage, ignore_errors=True)
    return found


def _ray_tune_trial(config: dict[str, float], scheme: str, problem: _Problem) -> None:
    """One Ray Tune trial: the constants ``config`` on every training tree, in batches, on one physics thread."""
    from ray import tune as ray_tune

    runs = _runs(_schedule_of(scheme, config), problem.train_seeds)
    rows = [row for i in range(0, len(runs), problem.batch_size) for row in run_batch(problem.spec_values, runs[i:i + problem.batch_size], threads=1)]
    ray_tune.report({"score": problem.score(rows)})


def _sampler(seed: int) -> optuna.samplers.TPESampler:
    import optuna

    return optuna.samplers.TPESampler(seed=seed, multivariate=True)


def _suggest_all(trial: _Trial, space: dict[str, tuple[float, float, bool]]) -> dict[str, float]:
    """A point of ``space`` from ``trial`` (Optuna's, or Ray Tune's wrapper of it), its parameters in order."""
    return {name: _suggest(trial, name, bounds) for name, bounds in space.items()}


def _suggest(trial: _Trial, name: str, bounds: tuple[float, float, bool]) -> float:
    low, high, log = bounds
    return float(trial.suggest_float(name, low, high, log=log))


def _change(paper: float, tuned: float) -> str:
    if not np.isfinite(paper):
        return "from never" if np.isfinite(tuned) else "never both"
    return f"{100 * (tuned - paper) / paper:+.0f}%" if paper > 0 else "n/a"


def report(results: Sequence[SchemeResult]) -> str:
    """The tuned constants beside the paper's, and the held-out medians [quartiles] of both."""
    lines = []
    for r in results:
        names = [n for n in ("c0", "c1", "kp0", "ki0", "kd0") if not (r.scheme == "constant" and n == "c1")]
        lines.append(f"{r.scheme}:")
        lines.append("  " + " ".join(f"{n:>10}" for n in ["", *names]))
        for which, values in (("paper", r.paper), ("tuned", r.tuned)):
            lines.append("  " + f"{which:>10}" + " ".join(f"{values[n]:>10.4g}" for n in names))
        lines.append(f"  training score (mean final + {r.t10_weight:g} t10): paper {r.train_score_paper:.3f}, tuned {r.train_score_tuned:.3f}")
        n = len(r.test_final["paper"])
        lines.append(f"  held-out trees ({n}): median [quartiles]")
        lines.append(f"    final distance (widths)  paper {median_quartiles(r.test_final['paper'])}  "
                     f"tuned {median_quartiles(r.test_final['tuned'])}  "
                     f"change {_change(r.median('final', 'paper'), r.median('final', 'tuned'))}")
        lines.append(f"    t10% (s)                 paper {median_quartiles(r.test_t10['paper'])}  tuned {median_quartiles(r.test_t10['tuned'])}  "
                     f"change {_change(r.median('t10', 'paper'), r.median('t10', 'tuned'))}")
        lines.append(f"    tuned beats the paper on both medians: {'yes' if r.improved() else 'no'}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="legkit tune", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter,
        epilog=__doc__.split("\n\n", 1)[1],
    )
    parser.add_argument("--schemes", nargs="+", default=list(SCHEMES), help=f"schemes to tune (default all: {' '.join(SCHEMES)})")
    parser.add_argument("--train", type=bounded_int(1, 1000), default=4, help=f"training trees, seeds {TRAIN_SEED0}.. (default 4)")
    parser.add_argument("--test", type=bounded_int(1, 1000), default=6, help=f"held-out trees, seeds {TEST_SEED0}.. (default 6)")
    parser.add_argument("--trials", type=bounded_int(1, 100_000), default=32, help="trials per scheme, the paper's first (default 32)")
    parser.add_argument("--per-round", type=bounded_int(1, 1000), default=4,
                        help="trials per scheme evaluated together (on Ray Tune: at once) (default 4)")
    parser.add_argument("--duration", type=float, default=1.0, help="simulated seconds per run (default 1)")
    parser.add_argument("--modules", type=bounded_int(1, 10_000), default=20, help="modules per tree besides the root (default 20)")
    parser.add_argument("--branches", type=bounded_int(1, 10_000), default=4, help="branches off the root (default 4)")
    parser.add_argument("--paper-base-gains", action="store_true", help="keep the paper's K_P0, K_I0, K_D0 (search c0, c1 only)")
    parser.add_argument("--seed", type=bounded_int(0, 2**31 - 1), default=0, help="sampler seed (default 0)")
    parser.add_argument("--t10-weight", type=float, default=T10_WEIGHT,
                        help=f"module widths per second of t10 in the objective (default {T10_WEIGHT})")
    parser.add_argument("--workers", type=bounded_int(1, 1024), default=1,
                        help="local worker processes (default 1: this process, physics on every core)")
    parser.add_argument("--ray", metavar="ADDRESS", help="tune with Ray Tune on Ray at ADDRESS ('auto', 'ray://host:10001', or 'local')")
    args = parser.parse_args(argv)
    try:
        results = tune(
            args.schemes, args.train, args.test, args.trials, args.per_round, args.duration, args.modules, args.branches,
            not args.paper_base_gains, args.seed, args.workers, args.ray, t10_weight=args.t10_weight,
        )
    except (ValueError, TypeError, ImportError) as error:
        print(f"legkit tune: {error}", file=sys.stderr)
        return 2
    print(report(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
