"""Summary figures of a sweep: per-scheme distributions and c0–c1 heat maps."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from legkit._extras import require
from legkit.control.gains import SCHEMES

if TYPE_CHECKING:
    import pyarrow as pa
    from matplotlib.figure import Figure

#: Metrics drawn in ``distributions.png``: column, axis label.
DISTRIBUTIONS = (("final", "final distance (module widths)"), ("t10", "t10% (s; runs that reach it)"), ("energy", "energy (J)"))


def _columns(table: pa.Table) -> dict[str, np.ndarray]:
    return {name: np.asarray(table.column(name).to_pylist()) for name in table.column_names}


#: Quantiles that bound a heat map's colour scale: one outlying cell cannot flatten every other.
COLOUR_QUANTILES = (0.05, 0.95)


def summary_figures(table: pa.Table, out: str | Path) -> list[Path]:
    """``distributions.png`` (``distributions_figure``) and, only when c0 or c1 takes several values,
    ``heatmap.png`` (``heatmap_figure``). Returns the files written."""
    require("matplotlib", extra="sweep")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    c = _columns(table)
    written = []
    for name, figure in (("distributions.png", distributions_figure(c)), ("heatmap.png", heatmap_figure(c))):
        if figure is None:
            continue
        path = out / name
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)
    return written


def distributions_figure(c: dict[str, np.ndarray]) -> Figure:
    """Per metric (one row each: final distance, t10%, energy), box plots per scheme, one box per value
    (combination) of the fault/terrain/noise axes that vary. Each box's label is one line (scheme and the
    varied axes' values), upright when axes vary; the figure grows with the number of boxes and the labels'
    length, so labels never overlap or leave the figure."""
    require("matplotlib", extra="sweep")
    import matplotlib.pyplot as plt

    schemes = [s for s in SCHEMES if s in set(c["scheme"])]
    varying = [a for a in ("loss", "delay", "terrain", "noise", "friction") if len(set(c[a])) > 1]
    groups = sorted(set(zip(*(c[a] for a in varying)))) if varying else [()]
    # One line per box, upright: a box needs one line's height of width (7 pt), its label's length of height.
    labels = [" ".join([scheme, *(f"{n}={v:g}" for n, v in zip(varying, group))]) for scheme in schemes for group in groups]
    boxes = len(schemes) * (len(groups) + 1)
    width = max(6.0, 0.2 * boxes + 1.5)
    height = len(DISTRIBUTIONS) * 2.2 + (0.0 if not varying else 0.075 * max(map(len, labels)) + 0.4)
    figure, axes = plt.subplots(len(DISTRIBUTIONS), 1, figsize=(width, height), squeeze=False, sharex=True)
    positions = [k * (len(groups) + 1) + g for k in range(len(schemes)) for g in range(len(groups))]
    for axis, (metric, label) in zip(axes[:, 0], DISTRIBUTIONS):
        data = []
        for scheme in schemes:
            for group in groups:
                mask = c["scheme"] == scheme
                for name, value in zip(varying, group):
                    mask &= c[name] == value
                values = c[metric][mask].astype(float)
                values = values[np.isfinite(values)]
                data.append(values if values.size else np.array([np.nan]))
        axis.boxplot(data, positions=positions, widths=0.7)
        axis.set_ylabel(label, fontsize=8)
        axis.grid(True, axis="y", alpha=0.3)
        finite = np.concatenate(data)
        finite = finite[np.isfinite(finite)]
        if metric == "energy" and finite.size and finite.min() > 0 and finite.max() > 50 * finite.min():  # spans decades
            axis.set_yscale("log")
            axis.set_ylabel(label + ", log scale", fontsize=8)
    axes[-1, 0].set_xticks(positions, labels, rotation=90 if varying else 0, fontsize=7)
    figure.suptitle(f"{len(c['run_id'])} balance runs: distribution per scheme" + (f" and {', '.join(varying)}" if varying else ""))
    figure.tight_layout()
    return figure


def heatmap_figure(c: dict[str, np.ndarray]) -> Figure | None:
    """Per scheme with several c0 or c1 values, the median final distance over the c0–c1 grid (None if no
    scheme has); the colour scale spans the ``COLOUR_QUANTILES`` of the cells (every panel its own), values
    beyond drawn in the end colours, as the colour bar's label says."""
    require("matplotlib", extra="sweep")
    import matplotlib.pyplot as plt

    schemes = [s for s in SCHEMES if s in set(c["scheme"])]
    gridded = [s for s in schemes if len(set(c["c0"][c["scheme"] == s])) * len(set(c["c1"][c["scheme"] == s])) > 1]
    if not gridded:
        return None
    figure, axes = plt.subplots(1, len(gridded), figsize=(4.6 * len(gridded), 4.0), squeeze=False)
    low_q, high_q = COLOUR_QUANTILES
    for axis, scheme in zip(axes[0], gridded):
        mine = c["scheme"] == scheme
        c0s, c1s = sorted(set(c["c0"][mine])), sorted(set(c["c1"][mine]))
        grid = np.full((len(c1s), len(c0s)), np.nan)
        for i, c1 in enumerate(c1s):
            for j, c0 in enumerate(c0s):
                values = c["final"][mine & (c["c0"] == c0) & (c["c1"] == c1)]
                if values.size:
                    grid[i, j] = np.median(values)
        cells = grid[np.isfinite(grid)]
        # Cells' own values, rounded inward: one outlier among a few cells cannot stretch the scale.
        low, high = (np.quantile(cells, low_q, method="higher"), np.quantile(cells, high_q, method="lower")) if cells.size else (0.0, 1.0)
        if high <= low:
            high = low + 1e-12
        image = axis.imshow(grid, origin="lower", aspect="auto", cmap="viridis", vmin=low, vmax=high)
        axis.set_xticks(range(len(c0s)), [f"{v:g}" for v in c0s], rotation=90, fontsize=7)
        axis.set_yticks(range(len(c1s)), [f"{v:g}" for v in c1s], fontsize=7)
        axis.set_xlabel("c0")
        axis.set_ylabel("c1")
        axis.set_title(f"{scheme}: median final distance", fontsize=9)
        figure.colorbar(
            image, ax=axis, extend="both",
            label=f"module widths (scale: {100 * low_q:g}–{100 * high_q:g} % quantiles)",
        )
    figure.tight_layout()
    return figure
