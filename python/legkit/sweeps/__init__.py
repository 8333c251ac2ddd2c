"""Sweeps of the modular-robot balance experiment (Moll et al., IROS 2006) and gain tuning.

``SweepSpec`` declares a grid (trees x schemes x gains x bus faults x terrain x sensor noise x seeds);
``run_sweep`` runs it in batches (many runs per ``run_balance`` call, the unit of work of a worker) on a local
process pool or on Ray, streaming each finished batch into Parquet, resumable; ``summary_figures`` draws
it; ``tune`` searches the gain constants per scheme. ``legkit sweep`` and ``legkit tune`` are the commands.
See docs/sweeps.md.
"""

from legkit.sweeps.execute import METRICS, LocalExecutor, RayExecutor, ResultStore, executor, read_results, run_batch, run_sweep, terrain_ground
from legkit.sweeps.figures import summary_figures
from legkit.sweeps.spec import AXES, RunParams, SweepSpec

__all__ = [
    "AXES", "METRICS", "LocalExecutor", "RayExecutor", "ResultStore", "RunParams", "SweepSpec", "executor", "read_results",
    "run_batch", "run_sweep", "summary_figures", "terrain_ground",
]
