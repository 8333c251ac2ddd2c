"""Running a sweep: batches on a local process pool or on Ray, results streamed into Parquet, resumable.

Output folder layout (``out``):

* ``spec.json``: the spec (``SweepSpec.to_dict``) and its id. A folder belongs to one spec: running another
  spec into it raises ValueError.
* ``parts/batch-NNNNN.parquet``: one file per finished batch, written to a temporary name and renamed, so a
  part is either whole or absent. An interrupted sweep (killed, Ctrl-C, a lost node) leaves the finished
  batches; running the same spec into the same folder runs only the missing ones.
* ``results.parquet``: every run, in grid order (written when all batches are done); ``read_results`` reads
  the parts of an unfinished sweep too.

One row per run: ``run_id``, ``index`` (grid order), ``batch``, the parameters (``RunParams``' fields, the
spec's ``duration``, ``dt``, ``modules``, ``branches``) and the metrics: ``initial``, ``final`` and
``settled`` (mean over the last fifth of the run) distances in module widths, ``t10`` (s, NaN if never
within 10 % of the initial distance), ``overshoot`` (fraction of the initial distance), ``messages`` (data
messages per module per second) and ``energy`` (J, the integral of sum_j |tau_j v_j|).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict
from multiprocessing import get_context
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from legkit.sweeps.spec import RunParams, SweepSpec

if TYPE_CHECKING:
    import pyarrow as pa

    import legkit as lk
    from legkit.robots.superbot import ModuleTree

METRICS = ("initial", "final", "settled", "t10", "overshoot", "messages", "energy")


def _pyarrow() -> ModuleType:
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError as error:  # pragma: no cover - depends on the installation
        raise ImportError("legkit.sweeps writes Parquet with pyarrow: pip install 'legkit[sweep]'") from error
    return pyarrow


def run_batch(spec_values: dict[str, Any], runs: Sequence[RunParams], threads: int | None = None) -> list[dict[str, Any]]:
    """Run one batch (one ``run_balance`` call) and return its rows (parameters and metrics, without ids).

    ``threads`` caps the physics threads of this process (RAYON_NUM_THREADS; it takes effect if the process
    has not stepped a batch yet): a pool of w workers on c cores gives each c // w."""
    if threads is not None:
        os.environ["RAYON_NUM_THREADS"] = str(threads)
    from legkit.agents import BusConfig
    from legkit.experiments.balance import RunSpec, run_balance
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
    results = run_balance(trees, spec_values["duration"], dt=spec_values["dt"], runs=specs, bus=bus, progress=False)
    rows = []
    for r, result in zip(runs, results):
        tail = result.distance[result.times >= 0.8 * result.times[-1]]
        rows.append({
            **asdict(r), "duration": spec_values["duration"], "dt": spec_values["dt"], "modules": modules, "branches": branches,
            "initial": result.initial, "final": result.final, "settled": float(tail.mean()), "t10": result.time_to_10_percent,
            "overshoot": result.overshoot, "messages": result.messages_per_module_second, "energy": result.energy,
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


class ResultStore:
    """The output folder of one sweep (see the module docstring)."""

    def __init__(self, out: str | os.PathLike, spec: SweepSpec):
        self.out = Path(out)
        self.spec = spec
        self.parts = self.out / "parts"
        spec_file = self.out / "spec.json"
        if spec_file.exists():
            stored = json.loads(spec_file.read_text())
            if stored.get("spec_id") != spec.spec_id:
                raise ValueError(
                    f"out: {self.out} holds another sweep (spec id {stored.get('spec_id')}, this one {spec.spec_id}); "
                    "resume with the same spec or choose another folder"
                )
        else:
            self.parts.mkdir(parents=True, exist_ok=True)
            _atomic_write(spec_file, json.dumps({"spec_id": spec.spec_id, "spec": spec.to_dict()}, indent=1).encode())
        self.parts.mkdir(parents=True, exist_ok=True)

    def part(self, batch: int) -> Path:
        return self.parts / f"batch-{batch:05d}.parquet"

    def done(self, batch: int) -> bool:
        return self.part(batch).exists()

    def write(self, batch: int, rows: list[dict[str, Any]]) -> None:
        pa = _pyarrow()
        table = pa.Table.from_pylist(rows)
        temporary = self.part(batch).with_suffix(".tmp")
        pa.parquet.write_table(table, temporary)
        os.replace(temporary, self.part(batch))

    def table(self) -> pa.Table | None:
        """Every finished run, in grid order (a pyarrow Table)."""
        pa = _pyarrow()
        files = sorted(self.parts.glob("batch-*.parquet"))
        if not files:
            return None
        table = pa.concat_tables([pa.parquet.read_table(f) for f in files])
        return table.sort_by("index")


def _atomic_write(path: Path, data: bytes) -> None:
    temporary = path.with_suffix(path.suffix + ".tmp")
    temporary.write_bytes(data)
    os.replace(temporary, path)


def read_results(out: str | os.PathLike) -> pa.Table:
    """The runs of the sweep in ``out`` (finished or not), in grid order, as a pyarrow Table."""
    pa = _pyarrow()
    out = Path(out)
    if (out / "results.parquet").exists():
        return pa.parquet.read_table(out / "results.parquet")
    spec_file = out / "spec.json"
    if not spec_file.exists():
        raise ValueError(f"out: {out} holds no sweep (no spec.json)")
    spec = SweepSpec.from_dict(json.loads(spec_file.read_text())["spec"])
    table = ResultStore(out, spec).table()
    if table is None:
        raise ValueError(f"out: {out} holds no finished run yet")
    return table


class LocalExecutor:
    """Runs batches on ``workers`` local processes (spawned once, kept until ``close``), each stepping its
    plants on ``threads`` threads (default: cores // workers); one worker without ``threads`` runs them in
    this process, with the physics on every core. ``map`` yields (key, rows) as batches finish."""

    def __init__(self, workers: int, threads: int | None = None):
        for name, value in (("workers", workers), ("threads", 1 if threads is None else threads)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name}: must be an int >= 1, got {value!r}")
        self.workers = workers
        self.parallelism = workers  # batches that run at once
        self.threads = max(1, (os.cpu_count() or 1) // workers) if threads is None else threads
        in_process = workers == 1 and threads is None
        self._pool = None if in_process else ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"))

    def map(self, spec_values: dict[str, Any], batches: Sequence[tuple[Any, list[RunParams]]]) -> Iterator[tuple[Any, list[dict]]]:
        if self._pool is None:
            for key, runs in batches:
                yield key, run_batch(spec_values, runs)
            return
        pending = {self._pool.submit(run_batch, spec_values, runs, self.threads): key for key, runs in batches}
        try:
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    yield pending.pop(future), future.result()
        finally:
            for future in pending:
                future.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)

    def __enter__(self) -> LocalExecutor:
        return self

    def __exit__(self, *_: Any) -> None:
        self.close()


class RayExecutor(LocalExecutor):
    """Runs batches as Ray tasks (one CPU and one physics thread each) on the cluster at ``address``
    (None or "local": an instance started here, unless Ray is already initialised)."""

    def __init__(self, address: str | None = None):
        try:
            import ray
        except ImportError as error:  # pragma: no cover - depends on the installation
            raise ImportError("ray: running on Ray needs the cluster extra: pip install 'legkit[cluster]'") from error
        self._ray = ray
        if not ray.is_initialized():
            ray.init(address=None if address in (None, "local") else address, log_to_driver=False)
        self._remote = ray.remote(num_cpus=1)(run_batch)
        self._pool = None
        self.parallelism = max(1, int(ray.cluster_resources().get("CPU", 1)))

    def map(self, spec_values: dict[str, Any], batches: Sequence[tuple[Any, list[RunParams]]]) -> Iterator[tuple[Any, list[dict]]]:
        ray = self._ray
        pending = {self._remote.remote(spec_values, runs, 1): key for key, runs in batches}
        try:
            while pending:
                finished, _ = ray.wait(list(pending), num_returns=1)
                for ref in finished:
                    yield pending.pop(ref), ray.get(ref)
        finally:
            for ref in pending:
                ray.cancel(ref)

    def close(self) -> None:
        pass


def executor(workers: int | None = None, ray: str | None = None, threads: int | None = None) -> LocalExecutor:
    """A ``RayExecutor`` when ``ray`` is given or Ray is already initialised, else a ``LocalExecutor`` of
    ``workers`` processes (default: one per core) with ``threads`` physics threads each."""
    if ray is not None or _ray_initialized():
        return RayExecutor(ray)
    return LocalExecutor((os.cpu_count() or 1) if workers is None else workers, threads)


def run_sweep(
    spec: SweepSpec, out: str | os.PathLike, workers: int | None = None, ray: str | None = None, progress: bool = True,
    figures: bool = True, max_batches: int | None = None, threads: int | None = None,
) -> pa.Table:
    """Run every batch of ``spec`` not yet in ``out`` and return the table of all runs (pyarrow, grid order).

    Locally on ``workers`` processes (default: one per core; 1 runs in this process with the physics on
    every core; ``threads`` sets the physics threads of each worker, default cores // workers), or on Ray when
    ``ray`` is given: an address (``"auto"``, ``"ray://host:10001"``, or ``"local"`` to start one here), or when
    Ray is already initialised. Finished batches are written as they arrive (in any order); ``results.parquet``
    and, with ``figures``, the summary figures once all are done. ``max_batches`` stops after that many new
    batches (a partial sweep; the rest on the next call)."""
    if not isinstance(spec, SweepSpec):
        raise TypeError(f"spec: must be a SweepSpec, got {type(spec).__name__}")
    if max_batches is not None and (isinstance(max_batches, bool) or not isinstance(max_batches, int) or max_batches < 1):
        raise ValueError(f"max_batches: must be an int >= 1, got {max_batches!r}")
    store = ResultStore(out, spec)
    batches = spec.batches()
    order = {r: i for i, r in enumerate(spec.runs())}
    todo = [(b, runs) for b, runs in enumerate(batches) if not store.done(b)]
    total = sum(len(runs) for runs in batches)
    done = total - sum(len(runs) for _, runs in todo)
    if max_batches is not None:
        todo = todo[:max_batches]
    with (
        executor(workers, ray, threads) as pool,
        tqdm(total=total, initial=done, desc="sweep", unit="run", disable=not progress, smoothing=0.0) as bar,
    ):
        for b, rows in pool.map(spec.to_dict(), todo):
            for run, row in zip(batches[b], rows):
                row.update(run_id=spec.run_id(run), index=order[run], batch=b)
            store.write(b, rows)
            bar.update(len(rows))
    table = store.table()
    assert table is not None  # a spec has at least one batch, and one is written by now
    if all(store.done(b) for b in range(len(batches))):
        pa = _pyarrow()
        pa.parquet.write_table(table, store.out / "results.parquet")
        if figures:
            from legkit.sweeps.figures import summary_figures

            summary_figures(table, store.out)
    return table


def _ray_initialized() -> bool:
    try:
        import ray
    except ImportError:
        return False
    return ray.is_initialized()
