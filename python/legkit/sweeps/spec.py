"""The declarative sweep: ``SweepSpec`` (the grid), its runs (``RunParams``, with deterministic ids) and batches.

A spec is the Cartesian product of its axes: tree seeds x schemes x c0 x c1 x K_P0 x K_I0 x K_D0 x bus loss
x bus delay x terrain roughness x friction x sensor noise x replicate seeds. Every run is one closed-loop
balance run (``legkit.control.run_balance``) of ``duration`` s.

* ``c0`` / ``c1`` None take the paper's value of each scheme (``GainSchedule.paper``); a sequence applies to
  every scheme; a mapping ``{scheme: sequence}`` gives each scheme its own values (schemes left out take
  the paper's). The constant scheme ignores c1 (its gain factor is c0), so it runs once per c0, recorded
  with c1 = 0.
* ``loss`` > 0 or ``delay`` > 1 put the agents on the asynchronous bus (that loss probability, delays of
  1..delay ticks, acknowledgements and retransmission).
* ``terrain`` is a roughness depth (m): 0 is the plane; d > 0 a heightfield of cells one module wide, each
  vertex dipped by a uniform random depth in [0, d] (its own per tree and replicate), so no module starts
  inside it.
* ``seeds`` are replicates: replicate 0 starts every tree from the same angles as ``legkit balance`` (start
  seed = tree seed); others from start angles, sensor noise and terrain of their own.

Runs that share a bus configuration are cut, in grid order, into batches of ``batch_size`` runs; a batch is
the unit of storage (one Parquet part). Workers run tasks of a few runs of a batch, each one ``run_balance``
call (its agents vectorised together, its plants stepped together), sized to the workers
(``legkit.sweeps.execute.task_size``). A run's id is a hash of its parameters (and the spec's duration, dt and tree
size): the same run has the same id in every sweep. A run's result does not depend on its batch: its start
angles, terrain, sensor noise and, on a lossy or delayed bus, its message losses, duplicates and delays come
from generators of its own (``derived_seed``).
"""

from __future__ import annotations

import hashlib
import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from legkit._validation import integer, is_integer, is_real
from legkit.control.gains import KD0, KI0, KP0, SCHEMES, GainSchedule
from legkit.robots.superbot import MAX_RANDOM_MODULES

#: Bounds checked before anything is spelled out or run: the runs of a grid (a million runs of the default 2 s take
#: about a core-year), a bus delay (ticks) and the steps of a run (duration / dt); a tree's modules are
#: `random_tree`'s bound, MAX_RANDOM_MODULES.
MAX_RUNS = 10**6
MAX_DELAY = 10**6
MAX_STEPS = 10**8

#: The axes of the grid, in the order they vary (the last fastest).
AXES = ("trees", "schemes", "c0", "c1", "kp0", "ki0", "kd0", "loss", "delay", "terrain", "friction", "noise", "seeds")


@dataclass(frozen=True)
class RunParams:
    """One run of a sweep: its tree (seed of ``random_tree(modules, branches, tree_seed)``), gain schedule,
    bus faults, terrain, friction, sensor noise and replicate seed."""

    tree_seed: int
    scheme: str
    c0: float
    c1: float
    kp0: float
    ki0: float
    kd0: float
    loss: float
    delay: int
    terrain: float
    friction: float
    noise: float
    seed: int

    @property
    def schedule(self) -> GainSchedule:
        return GainSchedule(self.scheme, self.c0, self.c1, self.kp0, self.ki0, self.kd0)

    @property
    def bus_key(self) -> tuple[float, int]:
        """Runs sharing this key can share one agent network (one bus)."""
        return (self.loss, self.delay)

    def derived_seed(self, stream: int) -> int:
        """A seed of this run's own, for ``stream`` (1 start angles, 2 sensor noise, 3 terrain, 4 bus)."""
        return int(np.random.SeedSequence([self.tree_seed, self.seed, stream]).generate_state(1)[0])

    @property
    def start_seed(self) -> int:
        """Seed of the start angles: the tree seed for replicate 0 (as ``legkit balance``), else its own."""
        return self.tree_seed if self.seed == 0 else self.derived_seed(1)


@dataclass(frozen=True, eq=False)
class SweepSpec:
    """A grid of balance runs; see the module docstring. Sequences are the values of each axis; ``trees``
    an int n means tree seeds 0..n-1, ``seeds`` an int n replicates 0..n-1. Two specs are equal when they
    spell out the same grid (``to_dict``)."""

    trees: int | Sequence[int] = 4
    modules: int = 20
    branches: int = 4
    schemes: Sequence[str] = SCHEMES
    c0: Sequence[float] | Mapping[str, Sequence[float]] | None = None
    c1: Sequence[float] | Mapping[str, Sequence[float]] | None = None
    kp0: Sequence[float] = (KP0,)
    ki0: Sequence[float] = (KI0,)
    kd0: Sequence[float] = (KD0,)
    loss: Sequence[float] = (0.0,)
    delay: Sequence[int] = (1,)
    terrain: Sequence[float] = (0.0,)
    friction: Sequence[float] = (0.8,)
    noise: Sequence[float] = (0.0,)
    seeds: int | Sequence[int] = 1
    duration: float = 2.0
    dt: float = 1e-3
    batch_size: int = 48
    _normal: dict[str, Any] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_normal", _normalise(self))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SweepSpec) and self._normal == other._normal

    def __hash__(self) -> int:
        return hash(self.spec_id)

    def to_dict(self) -> dict[str, Any]:
        """The spec in plain JSON types, every axis spelled out (``SweepSpec.from_dict`` reads it back)."""
        return dict(self._normal)

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> SweepSpec:
        names = {f.name for f in fields(SweepSpec) if f.init}
        unknown = sorted(set(values) - names)
        if unknown:
            raise ValueError(f"spec: unknown argument(s) {unknown}; known: {sorted(names)}")
        return SweepSpec(**values)

    @property
    def spec_id(self) -> str:
        """A hash of the whole spec (batch size included): a sweep's output folder belongs to one spec."""
        return _digest(self._normal)

    def runs(self) -> list[RunParams]:
        """Every run of the grid, in grid order (duplicates of the constant scheme over c1 removed)."""
        n = self._normal
        runs, seen = [], set()
        for tree, scheme in itertools.product(n["trees"], n["schemes"]):
            for c0, c1, kp0, ki0, kd0, loss, delay, terrain, friction, noise, seed in itertools.product(
                n["c0"][scheme], n["c1"][scheme], n["kp0"], n["ki0"], n["kd0"], n["loss"], n["delay"], n["terrain"],
                n["friction"], n["noise"], n["seeds"],
            ):
                run = RunParams(tree, scheme, c0, 0.0 if scheme == "constant" else c1, kp0, ki0, kd0, loss, delay, terrain, friction, noise, seed)
                if run not in seen:
                    seen.add(run)
                    runs.append(run)
        return runs

    def run_id(self, run: RunParams) -> str:
        """The run's id: a hash of its parameters and of what the spec adds to them (duration, dt, tree size)."""
        n = self._normal
        return _digest({**asdict(run), "duration": n["duration"], "dt": n["dt"], "modules": n["modules"], "branches": n["branches"]})

    def batches(self) -> list[list[RunParams]]:
        """The runs cut into batches: runs sharing a bus configuration, in grid order, ``batch_size`` at a time."""
        groups: dict[tuple[float, int], list[RunParams]] = {}
        for run in self.runs():
            groups.setdefault(run.bus_key, []).append(run)
        size = self._normal["batch_size"]
        return [group[i:i + size] for group in groups.values() for i in range(0, len(group), size)]


def _digest(values: Mapping[str, Any]) -> str:
    return hashlib.sha256(json.dumps(values, sort_keys=True).encode()).hexdigest()[:16]


def _normalise(spec: SweepSpec) -> dict[str, Any]:
    """The spec's values checked and spelled out in JSON types; ValueError/TypeError naming the argument."""
    out: dict[str, Any] = {}
    out["trees"] = _ints("trees", spec.trees, count_ok=True, low=0)
    out["modules"] = _int("modules", spec.modules, low=1, high=MAX_RANDOM_MODULES)
    out["branches"] = _int("branches", spec.branches, low=1, high=5)
    if out["branches"] > out["modules"]:
        raise ValueError(f"branches: must be <= modules ({out['modules']}), got {out['branches']}")
    schemes = [spec.schemes] if isinstance(spec.schemes, str) else list(_sequence("schemes", spec.schemes))
    for s in schemes:
        if s not in SCHEMES:
            raise ValueError(f"schemes: each must be one of {SCHEMES}, got {s!r}")
    out["schemes"] = _unique("schemes", schemes)
    for name in ("c0", "c1"):
        out[name] = _per_scheme(name, getattr(spec, name), out["schemes"])
    for name in ("kp0", "ki0", "kd0"):
        out[name] = _floats(name, getattr(spec, name), low=0.0)
    out["loss"] = _floats("loss", spec.loss, low=0.0, below=1.0)
    out["delay"] = _ints("delay", spec.delay, low=1, high=MAX_DELAY)
    out["terrain"] = _floats("terrain", spec.terrain, low=0.0)
    out["friction"] = _floats("friction", spec.friction, low=0.0)
    out["noise"] = _floats("noise", spec.noise, low=0.0)
    out["seeds"] = _ints("seeds", spec.seeds, count_ok=True, low=0)
    out["duration"] = _float("duration", spec.duration, positive=True)
    out["dt"] = _float("dt", spec.dt, positive=True)
    if out["dt"] > out["duration"]:
        raise ValueError(f"dt: must be <= duration ({out['duration']}), got {out['dt']}")
    if out["duration"] / out["dt"] > MAX_STEPS:
        raise ValueError(f"duration: at most {MAX_STEPS:.0e} steps of dt per run, got {out['duration']} / {out['dt']}")
    out["batch_size"] = _int("batch_size", spec.batch_size, low=1)
    runs = len(out["trees"]) * sum(len(out["c0"][s]) * len(out["c1"][s]) for s in out["schemes"]) * len(out["seeds"])
    runs *= np.prod([len(out[axis]) for axis in ("kp0", "ki0", "kd0", "loss", "delay", "terrain", "friction", "noise")], dtype=object)
    if runs > MAX_RUNS:
        raise ValueError(f"spec: the grid has {runs} runs, more than {MAX_RUNS}; sweep fewer values")
    return out


def _sequence(name: str, value: Any) -> Sequence[Any] | np.ndarray:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (Sequence, np.ndarray)):
        raise TypeError(f"{name}: must be a sequence of values, got {type(value).__name__}")
    if len(value) == 0:
        raise ValueError(f"{name}: needs at least one value")
    if len(value) > MAX_RUNS:
        raise ValueError(f"{name}: at most {MAX_RUNS} values, got {len(value)}")
    return value


def _unique(name: str, values: list[Any]) -> list[Any]:
    if len(set(values)) != len(values):
        raise ValueError(f"{name}: values repeat: {values}")
    return values


def _int(name: str, value: Any, low: int | None = None, high: int | None = None) -> int:
    number = integer(value, name)
    if (low is not None and number < low) or (high is not None and number > high):
        bounds = f">= {low}" if high is None else f"in {low}..{high}"
        raise ValueError(f"{name}: must be {bounds}, got {value}")
    return number


def _ints(name: str, value: Any, low: int, count_ok: bool = False, high: int | None = None) -> list[int]:
    if count_ok and is_integer(value):
        return list(range(_int(name, value, low=1, high=MAX_RUNS)))
    return _unique(name, [_int(name, v, low=low, high=high) for v in _sequence(name, value)])


def _float(name: str, value: Any, positive: bool = False, low: float | None = None, below: float | None = None) -> float:
    if not is_real(value):
        raise TypeError(f"{name}: must be a number, got {type(value).__name__}")
    value = float(value)
    if not np.isfinite(value) or (positive and value <= 0) or (low is not None and value < low) or (below is not None and value >= below):
        bounds = "> 0" if positive else f"in [{low}, {below})" if below is not None else f">= {low}"
        raise ValueError(f"{name}: must be a finite number {bounds}, got {value!r}")
    return value


def _floats(name: str, value: Any, low: float, below: float | None = None) -> list[float]:
    return _unique(name, [_float(name, v, low=low, below=below) for v in _sequence(name, value)])


def _per_scheme(name: str, value: Any, schemes: list[str]) -> dict[str, list[float]]:
    index = ("c0", "c1").index(name)
    paper = {s: [[GainSchedule.paper(s).c0, GainSchedule.paper(s).c1][index]] for s in schemes}
    if value is None:
        return paper
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - set(SCHEMES))
        if unknown:
            raise ValueError(f"{name}: keys must be schemes {SCHEMES}, got {unknown}")
        unswept = sorted(set(value) - set(schemes))
        if unswept:
            raise ValueError(f"{name}: values given for {unswept}, which the sweep does not run (schemes {schemes})")
        return {s: _floats(f"{name}[{s!r}]", value[s], low=0.0) if s in value else paper[s] for s in schemes}
    values = _floats(name, value, low=0.0)
    return {s: list(values) for s in schemes}
