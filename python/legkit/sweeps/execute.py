"""Running a sweep: tasks on a local process pool or on Ray, results streamed into verified Parquet parts, resumable.

Output folder layout (``out``):

* ``spec.json``: the spec (``SweepSpec.to_dict``), its id and the provenance of the build that started it
  (``provenance()``). A folder belongs to one spec: running another spec into it raises ValueError; resuming
  it with another build raises ValueError unless ``allow_mixed``.
* ``parts/batch-NNNNN.parquet``: one file per finished batch, its provenance and the checksum of its values
  (``checksum``) in the file's metadata, written to a temporary name, flushed to disk and renamed, so a part
  is either whole or absent. A part is kept on resume only if its rows are exactly its batch's run ids, once
  each, with the sweep's columns and types (``SCHEMA``), its provenance's build and values that match their
  checksum (``verify_part``): Parquet reads a flipped bit in a stored value without a word. Any other part is
  run again, with a line saying why (with ``strict``, ValueError naming the file). Files that are no batch of
  the spec are left out, with a line (``strict``: refused).
* ``results.parquet``: every run, in grid order (written the same way when all batches are done), its
  metadata the provenance of the build that wrote it with the spec id and the builds of its rows, and its
  checksum; ``read_results`` checks it, and reads the verified parts of an unfinished sweep too.

Work: a batch (``SweepSpec.batch_size`` runs) is the unit of storage; the unit of scheduling is a task of a
few runs (one ``run_balance`` call), sized to the executor's parallelism (``task_size``): small enough that
every worker has work until the tail, no smaller than ``TASK_FLOOR`` runs, below which the batched engine's
fixed cost per control step is paid by too few runs. A run's result does not depend on its task, so the
table is the same for any split (checked by tests).

Interruption: local workers die with the driver (``PR_SET_PDEATHSIG`` on Linux and a watchdog on the parent
id); Ctrl-C in ``run_sweep`` stops the workers, keeps the written parts and raises ``SweepInterrupted``.

One row per run: ``run_id``, ``index`` (grid order), ``batch``, the parameters (``RunParams``' fields, the
spec's ``duration``, ``dt``, ``modules``, ``branches``), the metrics: ``initial``, ``final`` and
``settled`` (mean over the last fifth of the run) distances in module widths, ``t10`` (s, NaN if never
within 10 % of the initial distance), ``overshoot`` (fraction of the initial distance), ``messages`` (data
messages per module per second) and ``energy`` (J, the integral of sum_j |tau_j v_j|), and ``build``, the
legkit build that computed the run.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import json
import math
import os
import platform
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict
from multiprocessing import get_context
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from legkit._extras import load, require
from legkit.sweeps.spec import RunParams, SweepSpec

if TYPE_CHECKING:
    import pyarrow as pa

    import legkit as lk
    from legkit.robots.superbot import ModuleTree

METRICS = ("initial", "final", "settled", "t10", "overshoot", "messages", "energy")
#: The fewest runs per task: throughput per core grows with the runs of a ``run_balance`` call up to about
#: four and is flat beyond (benches/balance_sweep.py --batch-sizes 1 2 4 8 16; docs/sweeps.md, Throughput).
TASK_FLOOR = 4
#: Tasks per unit of parallelism aimed at, so that the tail (the last tasks, run while other workers idle)
#: is a small share of the sweep.
TASKS_PER_WORKER = 16
#: What the balance plant runs on (``run_balance``'s defaults, used by ``run_batch``): part of a part's provenance.
ENGINE: dict[str, Any] = {"plant": "tree", "sample_every": 10, "rounds_per_step": 1}
PROVENANCE_KEY = b"legkit.provenance"
CHECKSUM_KEY = b"legkit.sha256"
_PART = re.compile(r"batch-(\d{5})\.parquet")


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped ``run_sweep``: the finished parts are kept (``done`` of ``total`` runs); running the
    same spec into ``out`` again resumes."""

    def __init__(self, out: Path, done: int, total: int):
        super().__init__(f"interrupted; {done} of {total} runs are kept in {out}: run the same command again to resume")
        self.out, self.done, self.total = out, done, total


def _pyarrow() -> ModuleType:
    require("pyarrow")
    import pyarrow
    import pyarrow.parquet

    return pyarrow


@functools.lru_cache(maxsize=1)
def provenance() -> dict[str, Any]:
    """What produced a result: legkit's version, its ``build`` (a hash of the compiled extension and of every
    Python file of the package: either changes results), the extension's own hash, the git commit of the
    checkout if the package runs from one, the engine and its settings, Python and the platform."""
    import legkit

    package = Path(legkit.__file__).parent
    extension = hashlib.sha256()
    for path in sorted(package.glob("_core*.so")) + sorted(package.glob("_core*.pyd")):
        extension.update(path.read_bytes())
    build = hashlib.sha256(extension.digest())
    for path in sorted(package.rglob("*.py")):
        build.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes())
    try:
        from importlib.metadata import version

        legkit_version = version("legkit")
    except Exception:  # noqa: BLE001 - not installed (a source checkout on the path)
        legkit_version = "unknown"
    try:
        commit = subprocess.run(
            ["git", "-C", str(package), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        commit = None
    from legkit.robots.superbot import ModuleParameters

    servo = ModuleParameters()
    return {
        "legkit": legkit_version, "build": build.hexdigest()[:16], "extension": extension.hexdigest()[:16], "commit": commit,
        "engine": {**ENGINE, "servo_armature": servo.servo_armature, "servo_damping": servo.servo_damping,
                   "servo_torque_limit": servo.servo_torque_limit},
        "python": platform.python_version(), "platform": platform.platform(),
    }


def _describe(p: dict[str, Any] | None) -> str:
    if p is None:
        return "an unrecorded build"
    commit = f", commit {p['commit'][:10]}" if p.get("commit") else ""
    return f"legkit {p.get('legkit')} build {p.get('build')}{commit}"


def run_batch(spec_values: dict[str, Any], runs: Sequence[RunParams], threads: int | None = None) -> list[dict[str, Any]]:
    """Run some runs of a sweep (one ``run_balance`` call) and return their rows (parameters, metrics and
    the build of this process, without ids).

    ``threads`` caps the physics threads of this process (RAYON_NUM_THREADS; it takes effect if the process
    has not stepped a batch yet): a pool of w workers on c cores gives each c // w."""
    if threads is not None:
        os.environ["RAYON_NUM_THREADS"] = str(threads)
    from legkit.agents import BusConfig
    from legkit.control import RunSpec, run_balance
    from legkit.robots.superbot import random_tree

    modules, branches = spec_values["modules"], spec_values["branches"]
    tree_seeds = sorted({r.tree_seed for r in runs})
    trees = [random_tree(modules, branches, s) for s in tree_seeds]
    specs = []
    for r in runs:
        tree = tree_seeds.index(r.tree_seed)
        specs.append(RunSpec(
            tree, r.schedule, start_seed=r.start_seed, ground=terrain_ground(r, trees[tree]), noise=r.noise, noise_seed=r.derived_seed(2),
            bus_seed=r.derived_seed(4),
        ))
    loss, delay = runs[0].bus_key
    if any(r.bus_key != (loss, delay) for r in runs):
        raise ValueError("runs: a batch must share its bus configuration (loss, delay)")
    # Every batch's bus has the same seed: each run draws from its own streams (RunSpec.bus_seed).
    bus = BusConfig(mode="async", loss=loss, delay_max=delay) if loss > 0 or delay > 1 else None
    results = run_balance(
        trees, spec_values["duration"], dt=spec_values["dt"], runs=specs, bus=bus, progress=False, plant=ENGINE["plant"],
        sample_every=ENGINE["sample_every"], rounds_per_step=ENGINE["rounds_per_step"],
    )
    build = provenance()["build"]
    rows = []
    for r, result in zip(runs, results):
        tail = result.distance[result.times >= 0.8 * result.times[-1]]
        rows.append({
            **asdict(r), "duration": spec_values["duration"], "dt": spec_values["dt"], "modules": modules, "branches": branches,
            "initial": result.initial, "final": result.final, "settled": float(tail.mean()), "t10": result.time_to_10_percent,
            "overshoot": result.overshoot, "messages": result.messages_per_module_second, "energy": result.energy, "build": build,
        })
    return rows


def terrain_ground(run: RunParams, tree: ModuleTree) -> lk.Ground:
    """The run's ground: a plane of its friction, or for ``terrain`` d > 0 a heightfield of module-wide cells
    reaching three module widths past the tree's blocks at zero angles, every vertex dipped by a uniform depth
    in [0, d] drawn from the run's own generator (its tree seed and replicate)."""
    import legkit as lk

    if run.terrain == 0:
        return lk.Ground.plane(run.friction)
    reach = float(np.max(np.abs(tree.lattice_cells()[..., :2]))) + 3.0  # module widths
    cells = 2 * math.ceil(reach) + 1
    heights = -run.terrain * np.random.default_rng(run.derived_seed(3)).random((cells, cells))
    return lk.Ground.heightfield(heights, tree.parameters.width, run.friction)


def schema() -> pa.Schema:
    """The columns of a sweep's table and their types (every part and ``results.parquet``)."""
    pa = _pyarrow()
    integers = {"tree_seed", "delay", "seed", "modules", "branches", "index", "batch"}
    strings = {"scheme", "run_id", "build"}
    names = [*RunParams.__dataclass_fields__, "duration", "dt", "modules", "branches", *METRICS, "build", "run_id", "index", "batch"]
    return pa.schema([(n, pa.int64() if n in integers else pa.string() if n in strings else pa.float64()) for n in names])


def checksum(table: pa.Table) -> str:
    """The sha256 of ``table``'s values, column by column in order (its name, then its values in row order: the
    bytes of a numeric column, the repr of a text column's list): the same however Parquet stores them."""
    pa = _pyarrow()
    digest = hashlib.sha256()
    for name, column in zip(table.column_names, table.columns):
        digest.update(name.encode() + b"\0")
        if pa.types.is_integer(column.type) or pa.types.is_floating(column.type):
            digest.update(np.ascontiguousarray(column.to_numpy()).tobytes())
        else:
            digest.update(repr(column.to_pylist()).encode())
    return digest.hexdigest()


def _recorded(table: pa.Table, record: dict[str, Any]) -> pa.Table:
    """``table`` with ``record`` (its provenance) and its checksum as its metadata."""
    return table.replace_schema_metadata({PROVENANCE_KEY: json.dumps(record).encode(), CHECKSUM_KEY: checksum(table).encode()})


def _checksum_mismatch(table: pa.Table) -> str | None:
    """Why ``table``'s values are not the ones written (None: they are), from the checksum in its metadata."""
    recorded = (table.schema.metadata or {}).get(CHECKSUM_KEY)
    if recorded is None:
        return "records no checksum of its values"
    actual = checksum(table)
    if actual != recorded.decode(errors="replace"):
        return f"holds values other than those written (sha256 {actual[:16]}, recorded {recorded.decode(errors='replace')[:16]})"
    return None


def _durable_write(path: Path, write: Callable[[Path], object]) -> None:
    """``write`` to a temporary name beside ``path``, flushed to disk, then renamed onto ``path`` (and the
    rename flushed): after a crash the file is whole or absent."""
    temporary = path.with_name(path.name + ".tmp")
    write(temporary)
    with open(temporary, "rb") as handle:
        os.fsync(handle.fileno())
    os.replace(temporary, path)
    try:
        directory = os.open(path.parent, os.O_RDONLY)
    except OSError:  # pragma: no cover - a platform without directory handles
        return
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


class ResultStore:
    """The output folder of one sweep (see the module docstring). Opening it only reads: ``create`` makes the
    folder and its ``spec.json``. ``log`` receives the one-line reasons for parts run again (None: silent)."""

    def __init__(
        self, out: str | os.PathLike, spec: SweepSpec, allow_mixed: bool = False, strict: bool = False,
        log: Callable[[str], None] | None = None,
    ):
        self.out = Path(out)
        self.spec = spec
        self.parts = self.out / "parts"
        if log is not None and not callable(log):
            raise TypeError(f"log: must be a callable taking a line, or None, got {type(log).__name__}")
        self.allow_mixed, self.strict, self.log = allow_mixed, strict, log
        self.provenance = provenance()
        self.batches = spec.batches()
        self.stored: dict[str, Any] | None = None
        if self.out.exists() and not self.out.is_dir():
            raise ValueError(f"out: {self.out} is a file, not a folder")
        spec_file = self.out / "spec.json"
        if spec_file.exists():
            try:
                self.stored = json.loads(spec_file.read_text())
                if not isinstance(self.stored, dict):
                    raise ValueError("not a JSON object")
            except (ValueError, OSError) as error:
                raise ValueError(f"out: {spec_file} is not a sweep's spec.json ({error})") from None
            if self.stored.get("spec_id") != spec.spec_id:
                raise ValueError(
                    f"out: {self.out} holds another sweep (spec id {self.stored.get('spec_id')}, this one {spec.spec_id}); "
                    "resume with the same spec or choose another folder"
                )
            stored_build = (self.stored.get("provenance") or {}).get("build")
            if stored_build != self.provenance["build"] and not allow_mixed:
                raise ValueError(
                    f"out: {self.out} was started by {_describe(self.stored.get('provenance'))}, this is "
                    f"{_describe(self.provenance)}: resuming would mix two engines' results; choose another folder, "
                    "or allow it with --allow-mixed (allow_mixed=True)"
                )

    def create(self) -> None:
        """Make the folder and write ``spec.json`` (with this build's provenance; a resume with another build
        under ``allow_mixed`` is added to its ``resumed_by``)."""
        try:
            self.parts.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise ValueError(f"out: cannot create {self.parts}: {error.strerror}") from None
        if self.stored is None:
            record: dict[str, Any] = {"spec_id": self.spec.spec_id, "spec": self.spec.to_dict(), "provenance": self.provenance}
        elif (self.stored.get("provenance") or {}).get("build") != self.provenance["build"]:
            record = {**self.stored, "resumed_by": [*self.stored.get("resumed_by", []), self.provenance]}
        else:
            return
        _durable_write(self.out / "spec.json", lambda path: path.write_bytes(json.dumps(record, indent=1).encode()))
        self.stored = record

    def part(self, batch: int) -> Path:
        return self.parts / f"batch-{batch:05d}.parquet"

    def verify_part(self, batch: int) -> str | None:
        """Why the part of ``batch`` cannot be kept (None: it can): unreadable, other columns or types, no
        rows, run ids other than its batch's or repeated, another build (unless ``allow_mixed``), or values
        that do not match their checksum."""
        pa = _pyarrow()
        path = self.part(batch)
        try:
            table = pa.parquet.read_table(path)
        except Exception as error:  # noqa: BLE001 - pyarrow raises several kinds for a damaged file
            return f"cannot be read ({str(error).splitlines()[0] if str(error) else type(error).__name__})"
        expected = schema()
        if table.schema.remove_metadata() != expected:
            got = {f.name: f.type for f in table.schema}
            missing = [n for n in expected.names if n not in got]
            extra = [n for n in got if n not in expected.names]
            retyped = [f"{f.name} ({got[f.name]}, not {f.type})" for f in expected if f.name in got and got[f.name] != f.type]
            details = [f"{label} {', '.join(names)}" for label, names in (("missing", missing), ("unexpected", extra), ("retyped", retyped)) if names]
            return "has other columns than the sweep's: " + ("; ".join(details) or "another order")
        if table.num_rows == 0:
            return "has no rows"
        ids = table.column("run_id").to_pylist()
        wanted = [self.spec.run_id(r) for r in self.batches[batch]]
        if len(set(ids)) != len(ids):
            return f"repeats run ids ({len(ids) - len(set(ids))} duplicate rows)"
        if set(ids) != set(wanted):
            return f"holds {len(set(ids) - set(wanted))} runs of no run of its batch and misses {len(set(wanted) - set(ids))} of its {len(wanted)}"
        if set(table.column("batch").to_pylist()) != {batch}:
            return "its rows name another batch"
        metadata = table.schema.metadata or {}
        try:
            recorded = json.loads(metadata[PROVENANCE_KEY])
        except (KeyError, ValueError):
            return "records no provenance"
        builds = set(table.column("build").to_pylist())
        if builds != {recorded.get("build")}:
            return f"its rows' builds {sorted(builds)} are not its recorded build {recorded.get('build')}"
        if recorded.get("build") != self.provenance["build"] and not self.allow_mixed:
            return f"was written by {_describe(recorded)}, this is {_describe(self.provenance)}"
        return _checksum_mismatch(table)

    def stray_files(self) -> list[Path]:
        """Files in ``parts`` that are no batch's part of this spec (temporary files of a killed write aside)."""
        if not self.parts.is_dir():
            return []
        stray = []
        for path in sorted(self.parts.iterdir()):
            match = _PART.fullmatch(path.name)
            if path.name.endswith(".tmp") or (match and int(match.group(1)) < len(self.batches)):
                continue
            stray.append(path)
        return stray

    def finished(self) -> list[int]:
        """The batches whose parts are kept (verified); every other part's reason goes to ``log``, or with
        ``strict`` raises ValueError naming the file."""
        for path in self.stray_files():
            self._reject(path, "is no batch of this sweep; left out")
        kept = []
        for b in range(len(self.batches)):
            if not self.part(b).exists():
                continue
            reason = self.verify_part(b)
            if reason is None:
                kept.append(b)
            else:
                self._reject(self.part(b), f"{reason}; running its batch again")
        return kept

    def _reject(self, path: Path, reason: str) -> None:
        if self.strict:
            raise ValueError(f"strict: {path} {reason.split(';')[0]}")
        if self.log is not None:
            self.log(f"{path}: {reason}")

    def write(self, batch: int, rows: list[dict[str, Any]]) -> None:
        """Write the part of ``batch``, recording this build's provenance (or, when every row comes from one
        other build, under ``allow_mixed``, that build's id in it)."""
        pa = _pyarrow()
        builds = {row["build"] for row in rows}
        recorded = {**self.provenance, "build": builds.pop()} if len(builds) == 1 else self.provenance
        table = _recorded(pa.Table.from_pylist(rows, schema=schema()), recorded)
        _durable_write(self.part(batch), lambda path: pa.parquet.write_table(table, path))

    def table(self, batches: Sequence[int] | None = None) -> pa.Table | None:
        """The runs of ``batches`` (default: the verified ones), in grid order (a pyarrow Table)."""
        pa = _pyarrow()
        batches = self.finished() if batches is None else batches
        if not batches:
            return None
        table = pa.concat_tables([pa.parquet.read_table(self.part(b)).replace_schema_metadata(None) for b in batches])
        return table.sort_by("index")

    def write_results(self, table: pa.Table) -> None:
        """Write ``results.parquet``: ``table`` with this build's provenance, the spec id and the builds of its
        rows, and its checksum, in its metadata."""
        pa = _pyarrow()
        record = {**self.provenance, "spec_id": self.spec.spec_id, "builds": sorted(set(table.column("build").to_pylist()))}
        table = _recorded(table, record)
        _durable_write(self.out / "results.parquet", lambda path: pa.parquet.write_table(table, path))


def read_results(out: str | os.PathLike) -> pa.Table:
    """The runs of the sweep in ``out`` (finished or not: its verified parts), in grid order, as a pyarrow Table;
    ``results.parquet`` whose values do not match their checksum raises ValueError naming it."""
    pa = _pyarrow()
    out = Path(out)
    if (out / "results.parquet").exists():
        table = pa.parquet.read_table(out / "results.parquet")
        mismatch = _checksum_mismatch(table)
        if mismatch is not None:
            raise ValueError(f"out: {out / 'results.parquet'} {mismatch}; run the sweep again to rebuild it from its parts")
        return table
    spec_file = out / "spec.json"
    if not spec_file.exists():
        raise ValueError(f"out: {out} holds no sweep (no spec.json)")
    try:
        spec = SweepSpec.from_dict(json.loads(spec_file.read_text())["spec"])
    except (ValueError, KeyError, TypeError) as error:
        raise ValueError(f"out: {spec_file} is not a sweep's spec.json ({error})") from None
    table = ResultStore(out, spec, allow_mixed=True).table()
    if table is None:
        raise ValueError(f"out: {out} holds no finished run yet")
    return table


def task_size(runs: int, parallelism: int, batch_size: int) -> int:
    """Runs per task for ``runs`` runs on ``parallelism`` workers: about ``TASKS_PER_WORKER`` tasks each,
    at least ``TASK_FLOOR`` runs (at most a batch)."""
    return max(1, min(batch_size, max(TASK_FLOOR, math.ceil(runs / (parallelism * TASKS_PER_WORKER)))))


def split(runs: Sequence[RunParams], size: int) -> list[list[RunParams]]:
    """``runs`` cut into ceil(len / size) consecutive pieces of nearly equal length."""
    pieces = max(1, math.ceil(len(runs) / size))
    bounds = np.linspace(0, len(runs), pieces + 1).round().astype(int)
    return [list(runs[a:b]) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def _worker_start(parent: int) -> None:
    """A local worker's initializer: it dies with its driver. On Linux the kernel kills it when the driver
    exits (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); everywhere a watchdog thread exits once the parent id
    changes (the driver gone, the worker adopted). Ctrl-C is the driver's to handle: the worker ignores it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # tqdm's default lock (made with a worker's first bar, should a run show one) is a named semaphore that a
    # killed worker would leave to the resource tracker, which then warns as the driver exits.
    load("tqdm", "sweep").tqdm.set_lock(threading.RLock())
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # 1: PR_SET_PDEATHSIG
        except (OSError, AttributeError):  # pragma: no cover - a libc without prctl
            pass
    if os.getppid() != parent:  # the driver died before the signal was armed
        os._exit(1)
    threading.Thread(target=_watchdog, args=(parent,), daemon=True, name="legkit-watchdog").start()


def _watchdog(parent: int) -> None:
    while True:
        time.sleep(0.5)
        if os.getppid() != parent:
            os._exit(1)


def _task(arguments: tuple[Any, dict[str, Any], list[RunParams], int | None]) -> tuple[Any, list[dict[str, Any]]]:
    key, spec_values, runs, threads = arguments
    return key, run_batch(spec_values, runs, threads)


#: The most local worker processes, and physics threads per worker, a sweep starts (each is an OS process or thread).
MAX_WORKERS = 1024


class LocalExecutor:
    """Runs tasks on ``workers`` local processes (spawned once, kept until ``close``; they die with this
    process), each stepping its plants on ``threads`` threads (default: cores // workers); one worker
    without ``threads`` runs them in this process, with the physics on every core. ``map`` yields
    (key, rows) as tasks finish; ``abort`` stops every worker at once."""

    def __init__(self, workers: int, threads: int | None = None):
        for name, value in (("workers", workers), ("threads", 1 if threads is None else threads)):
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_WORKERS:
                raise ValueError(f"{name}: must be an int in 1..{MAX_WORKERS}, got {value!r}")
        self.workers = workers
        self.parallelism = workers  # tasks that run at once
        self.threads = max(1, (os.cpu_count() or 1) // workers) if threads is None else threads
        in_process = workers == 1 and threads is None
        self._pool = None if in_process else get_context("spawn").Pool(workers, initializer=_worker_start, initargs=(os.getpid(),))

    def map(self, spec_values: dict[str, Any], tasks: Sequence[tuple[Any, list[RunParams]]]) -> Iterator[tuple[Any, list[dict]]]:
        if self._pool is None:
            for key, runs in tasks:
                yield key, run_batch(spec_values, runs)
            return
        yield from self._pool.imap_unordered(_task, [(key, spec_values, runs, self.threads) for key, runs in tasks])

    def abort(self) -> None:
        """Stop the running tasks now (Ctrl-C): the workers are killed, nothing more is returned."""
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
            self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool.join()
            self._pool = None

    def __enter__(self) -> LocalExecutor:
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: Any) -> None:
        if kind is None:
            self.close()
        else:
            self.abort()


class RayExecutor(LocalExecutor):
    """Runs tasks as Ray tasks (one CPU and one physics thread each) on the cluster at ``address``: "auto"
    or "ray://host:10001" (an existing cluster: ValueError saying how to start one if there is none),
    "local" or None (a new instance started here, even when RAY_ADDRESS names a cluster), unless Ray is
    already initialised in this process, which is then used. ``parallelism`` is the cluster's CPUs."""

    def __init__(self, address: str | None = None):
        if address is not None and not isinstance(address, str):
            raise TypeError(f"ray: must be an address (a str) or None, got {type(address).__name__}")
        require("ray")
        import ray

        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            local = address in (None, "local")
            try:
                # address="local" starts a new instance whatever RAY_ADDRESS says (ray.init's documented meaning).
                ray.init(address="local" if local else address, log_to_driver=False, include_dashboard=False if local else None)
            except ValueError as error:  # an address Ray cannot use (a client address without ray[client])
                raise ValueError(f"ray: {error}") from None
            except ConnectionError:
                raise ValueError(
                    f"ray: no Ray cluster found at {address!r}; start one with `ray start --head` (docs/sweeps.md, On a cluster), "
                    "or start one for this run with --ray local (ray='local')"
                ) from None
            self._started = True
        self._remote = ray.remote(num_cpus=1)(run_batch)
        self._pool = None
        self.parallelism = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._pending: dict[Any, Any] = {}

    def map(self, spec_values: dict[str, Any], tasks: Sequence[tuple[Any, list[RunParams]]]) -> Iterator[tuple[Any, list[dict]]]:
        ray = self._ray
        values = ray.put(spec_values)
        self._pending = {self._remote.remote(values, runs, 1): key for key, runs in tasks}
        while self._pending:
            finished, _ = ray.wait(list(self._pending), num_returns=1)
            for ref in finished:
                yield self._pending.pop(ref), ray.get(ref)

    def abort(self) -> None:
        for ref in self._pending:
            self._ray.cancel(ref, force=True)
        self._pending = {}
        self.close()

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()
            self._started = False


def executor(workers: int | None = None, ray: str | None = None, threads: int | None = None) -> LocalExecutor:
    """A ``RayExecutor`` when ``ray`` is given or Ray is already initialised, else a ``LocalExecutor`` of
    ``workers`` processes (default: one per core) with ``threads`` physics threads each."""
    if ray is not None or _ray_initialized():
        return RayExecutor(ray)
    return LocalExecutor((os.cpu_count() or 1) if workers is None else workers, threads)


def run_sweep(
    spec: SweepSpec, out: str | os.PathLike, workers: int | None = None, ray: str | None = None, progress: bool = True,
    figures: bool = True, max_batches: int | None = None, threads: int | None = None, strict: bool = False,
    allow_mixed: bool = False, log: Callable[[str], None] | None = None,
) -> pa.Table:
    """Run every batch of ``spec`` not yet in ``out`` and return the table of all runs (pyarrow, grid order).

    Locally on ``workers`` processes (default: one per core; 1 runs in this process with the physics on
    every core; ``threads`` sets the physics threads of each worker, default cores // workers), or on Ray when
    ``ray`` is given: an address (``"auto"``, ``"ray://host:10001"``, or ``"local"`` to start one here), or when
    Ray is already initialised. Batches are cut into tasks sized to the parallelism (``task_size``); a batch is
    written as its part when its last task arrives. ``results.parquet`` and, with ``figures``, the summary
    figures once all are done. ``max_batches`` stops after that many new batches (a partial sweep; the rest on
    the next call). Parts already in ``out`` are verified (``ResultStore.verify_part``): a damaged one is run
    again, with a line to ``log`` (default: stderr), or with ``strict`` refused (ValueError naming the file);
    ``allow_mixed`` keeps parts of another build. Everything is checked before ``out`` is created. Ctrl-C
    stops the workers and raises ``SweepInterrupted`` (a KeyboardInterrupt) with the finished parts kept."""
    if not isinstance(spec, SweepSpec):
        raise TypeError(f"spec: must be a SweepSpec, got {type(spec).__name__}")
    if max_batches is not None and (isinstance(max_batches, bool) or not isinstance(max_batches, int) or max_batches < 1):
        raise ValueError(f"max_batches: must be an int >= 1, got {max_batches!r}")
    require("pyarrow", *(["ray"] if ray is not None else []))
    if log is None:
        log = _stderr
    store = ResultStore(out, spec, allow_mixed=allow_mixed, strict=strict, log=log)
    batches = store.batches
    order = {r: i for i, r in enumerate(spec.runs())}
    kept = store.finished()
    todo = [b for b in range(len(batches)) if b not in kept]
    total = sum(len(runs) for runs in batches)
    if max_batches is not None:
        todo = todo[:max_batches]
    pool = executor(workers, ray, threads)  # may fail (no cluster): before anything is created
    try:
        store.create()
        size = task_size(sum(len(batches[b]) for b in todo), pool.parallelism, spec.batch_size)
        tasks = [((b, k), piece) for b in todo for k, piece in enumerate(split(batches[b], size))]
        pieces = {b: 0 for b in todo}
        for (b, _), _ in tasks:
            pieces[b] += 1
        arrived: dict[int, dict[int, list[dict]]] = {b: {} for b in todo}
        done = sum(len(batches[b]) for b in kept)
        tqdm = load("tqdm", "sweep").tqdm
        tqdm.set_lock(threading.RLock())  # as in the workers (_worker_start): the bar is written from this thread only
        with tqdm(
            total=total, initial=done, desc="sweep", unit="run", disable=not progress, smoothing=0.1, file=sys.stderr, dynamic_ncols=True,
        ) as bar:
            for (b, k), rows in pool.map(spec.to_dict(), tasks):
                foreign = {row["build"] for row in rows} - {store.provenance["build"]}
                if foreign and not allow_mixed:  # a cluster node with another legkit installed
                    raise ValueError(
                        f"ray: a worker ran legkit build {sorted(foreign)[0]}, this driver is build {store.provenance['build']}; "
                        "install the same legkit on every node, or allow it with --allow-mixed (allow_mixed=True)"
                    )
                arrived[b][k] = rows
                bar.update(len(rows))
                if len(arrived[b]) == pieces[b]:
                    done_pieces = arrived.pop(b)
                    rows = [row for k in range(pieces[b]) for row in done_pieces[k]]
                    for run, row in zip(batches[b], rows):
                        row.update(run_id=spec.run_id(run), index=order[run], batch=b)
                    store.write(b, rows)
                    kept.append(b)
        pool.close()
    except KeyboardInterrupt:
        pool.abort()
        # A part renamed into place is whole (the interrupt may fall between its rename and the bookkeeping).
        written = set(kept) | {b for b in todo if store.part(b).exists()}
        raise SweepInterrupted(store.out, sum(len(batches[b]) for b in written), total) from None
    except BaseException:
        pool.abort()
        raise
    table = store.table(sorted(kept))
    assert table is not None  # a spec has at least one batch, and one is written by now
    if len(kept) == len(batches):
        store.write_results(table)
        if figures:
            from legkit.sweeps.figures import summary_figures

            summary_figures(table, store.out)
    return table


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _ray_initialized() -> bool:
    try:
        import ray
    except ImportError:
        return False
    return ray.is_initialized()
