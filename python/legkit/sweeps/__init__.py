"""Sweeps of the modular-robot balance experiment (Moll et al., IROS 2006) and gain tuning.

``SweepSpec`` declares a grid (trees x schemes x gains x bus faults x terrain x sensor noise x seeds);
``run_sweep`` runs it in tasks (a few runs per ``run_balance`` call, sized to the workers) on a local
process pool or on Ray, streaming each finished batch into a verified Parquet part with its provenance, resumable; ``summary_figures`` draws
it; ``tune`` searches the gain constants per scheme. ``legkit sweep`` and ``legkit tune`` are the commands.
See docs/sweeps.md.
"""

from legkit.sweeps.execute import (
    METRICS,
    LocalExecutor,
    RayExecutor,
    ResultStore,
    SweepInterrupted,
    executor,
    provenance,
    read_results,
    run_batch,
    run_sweep,
    schema,
    task_size,
    terrain_ground,
)
from legkit.sweeps.figures import summary_figures
from legkit.sweeps.spec import AXES, RunParams, SweepSpec

__all__ = [
    "AXES", "METRICS", "LocalExecutor", "RayExecutor", "ResultStore", "RunParams", "SweepInterrupted", "SweepSpec", "executor",
    "provenance", "read_results", "run_batch", "run_sweep", "schema", "summary_figures", "task_size", "terrain_ground",
]
