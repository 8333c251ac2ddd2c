"""Summary figures of a sweep: per-scheme distributions and c0–c1 heat maps."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from legkit.control.gains import SCHEMES

if TYPE_CHECKING:
    import pyarrow as pa

#: Metrics drawn in ``distributions.png``: column, axis label.
DISTRIBUTIONS = (("final", "final distance (module widths)"), ("t10", "t10% (s; runs that reach it)"), ("energy", "energy (J)"))


def _columns(table: pa.Table) -> dict[str, np.ndarray]:
    return {name: np.asarray(table.column(name).to_pylist()) for name in table.column_names}


def summary_figures(table: pa.Table, out: str | Path) -> list[Path]:
    """``distributions.png``: per scheme, box plots of the final distance, t10% and energy, one box per
    value of each swept fault/terrain/noise axis that varies (else one box per scheme); ``heatmap.png`` (only
    when c0 or c1 takes several values): per scheme, the median final distance over the c0–c1 grid.
    Returns the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    c = _columns(table)
    schemes = [s for s in SCHEMES if s in set(c["scheme"])]
    varying = [a for a in ("loss", "delay", "terrain", "noise", "friction") if len(set(c[a])) > 1]
    groups = sorted(set(zip(*(c[a] for a in varying)))) if varying else [()]
    written = []

    figure, axes = plt.subplots(1, len(DISTRIBUTIONS), figsize=(4.2 * len(DISTRIBUTIONS), 3.6), squeeze=False)
    for axis, (metric, label) in zip(axes[0], DISTRIBUTIONS):
        data, labels, positions = [], [], []
        for k, scheme in enumerate(schemes):
            for g, group in enumerate(groups):
                mask = c["scheme"] == scheme
                for name, value in zip(varying, group):
                    mask &= c[name] == value
                values = c[metric][mask].astype(float)
                values = values[np.isfinite(values)]
                data.append(values if values.size else np.array([np.nan]))
                positions.append(k * (len(groups) + 1) + g)
                labels.append(scheme if not varying else f"{scheme}\n" + ",".join(f"{n}={v:g}" for n, v in zip(varying, group)))
        axis.boxplot(data, positions=positions, widths=0.7)
        axis.set_xticks(positions, labels, rotation=90 if varying else 0, fontsize=7 if varying else 9)
        axis.set_ylabel(label)
        axis.grid(True, axis="y", alpha=0.3)
    figure.suptitle(f"{len(c['run_id'])} balance runs: distribution per scheme")
    figure.tight_layout()
    path = out / "distributions.png"
    figure.savefig(path, dpi=110)
    plt.close(figure)
    written.append(path)

    gridded = [s for s in schemes if len(set(c["c0"][c["scheme"] == s])) * len(set(c["c1"][c["scheme"] == s])) > 1]
    if gridded:
        figure, axes = plt.subplots(1, len(gridded), figsize=(4.4 * len(gridded), 3.8), squeeze=False)
        for axis, scheme in zip(axes[0], gridded):
            mine = c["scheme"] == scheme
            c0s, c1s = sorted(set(c["c0"][mine])), sorted(set(c["c1"][mine]))
            grid = np.full((len(c1s), len(c0s)), np.nan)
            for i, c1 in enumerate(c1s):
                for j, c0 in enumerate(c0s):
                    values = c["final"][mine & (c["c0"] == c0) & (c["c1"] == c1)]
                    if values.size:
                        grid[i, j] = np.median(values)
            image = axis.imshow(grid, origin="lower", aspect="auto", cmap="viridis")
            axis.set_xticks(range(len(c0s)), [f"{v:g}" for v in c0s], rotation=90)
            axis.set_yticks(range(len(c1s)), [f"{v:g}" for v in c1s])
            axis.set_xlabel("c0")
            axis.set_ylabel("c1")
            axis.set_title(f"{scheme}: median final distance")
            figure.colorbar(image, ax=axis, label="module widths")
        figure.tight_layout()
        path = out / "heatmap.png"
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)
    return written
