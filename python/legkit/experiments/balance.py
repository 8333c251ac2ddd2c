"""The seed experiment (Moll et al., IROS 2006, Fig. 4): random SuperBot trees balance their centre of mass.

``legkit balance`` runs ``--trees`` random trees (``random_tree(--modules, --branches, seed)``: a vertical root
fixed to the ground plus modules in branches) once per gain schedule (constant, distance-based,
momentum-based) in the closed loop of ``legkit.control.run_balance``, and writes what it recorded. The default
trees are ``random_tree(20, 4, seed)``: a root plus 20 modules in 4 branches of 5, 63 joints. The paper [Moll
2006, Sect. V] says "20 modules divided into 4 branches of 5 modules" and "60 degrees of freedom", which
cannot both hold with a root; legkit reads the branches literally and adds the root.

``--plant tree`` (default) is ``lk.Simulation`` (legkit's tree engine) on a ground plane, ``--plant rapier``
the same on Rapier's multibody (the reference backend), ``--plant free`` the same fixed-base model and servos
without contacts (the seed's root is fixed, and nothing else is meant to touch the ground).

Reported per run (trees numbered from 1 in the table, ``balance.csv`` and the figure): the final distance of
the COM from the support line in module widths, the time to reach 10 % of the initial distance, the overshoot
(how far, as a fraction of the initial distance, the COM went past the line along the initial offset
direction), and the data messages per module per second. ``balance.html`` (meshcat) animates every run side
by side; with ``--gif`` also ``balance.gif``, which takes about 1.2 s to render.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

import legkit as lk
from legkit._extras import require
from legkit._help import HelpFormatter
from legkit._validation import add_output_folder, bounded_int
from legkit.control.closed_loop import DEFAULT_FRICTION, PLANTS, RunResult, run_balance
from legkit.robots.superbot import MAX_RANDOM_MODULES, ModuleTree, random_tree

if TYPE_CHECKING:
    from legkit.viewer import Scene


def write_csv(results: Sequence[RunResult], path: Path) -> None:
    """Long format: tree (numbered from 1, as in the table and the figure), scheme, time_s, distance_widths."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["tree", "scheme", "time_s", "distance_widths"])
        for r in results:
            writer.writerows((r.tree + 1, r.scheme, f"{t:.4f}", f"{d:.6f}") for t, d in zip(r.times, r.distance))


def plot(results: Sequence[RunResult], path: Path) -> None:
    """One panel per tree (a row, like the paper's Fig. 4), one curve per scheme."""
    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_trees = max(r.tree for r in results) + 1
    figure, axes = plt.subplots(1, n_trees, figsize=(3.6 * n_trees, 3.2), sharey=True, squeeze=False)
    for r in results:
        axis = axes[0, r.tree]
        axis.plot(r.times, r.distance, label=r.scheme)
        axis.set_title(f"tree {r.tree + 1}")
        axis.set_xlabel("time (s)")
        axis.grid(True, alpha=0.3)
    axes[0, 0].set_ylabel("COM to support line (module widths)")
    axes[0, 0].legend()
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def animation_scene(trees: Sequence[ModuleTree], results: Sequence[RunResult]) -> Scene:
    """A ``legkit.viewer.Scene`` of every run side by side: one row per tree (tree 1 at the back), one column
    per gain schedule, coloured as in ``balance.png``; each run with its support line (red, the vertical
    through the root) and its COM (a dark ball, with a disc where it projects on the ground)."""
    from legkit.viewer import Scene, Shape

    angles: list[np.ndarray] = []
    for r in results:
        if r.q is None:
            raise ValueError("results: need the recorded joint angles (RunResult.q)")
        angles.append(r.q)
    models = [tree.to_model()[0] for tree in trees]
    width = trees[0].parameters.width
    poses = {i: lk.forward_kinematics(models[r.tree], angles[i])[..., :3, 3].reshape(-1, 3) for i, r in enumerate(results)}
    reach = max(float(np.max(np.linalg.norm(p[:, :2], axis=1))) for p in poses.values()) + width
    height = max(float(np.max(p[:, 2])) for p in poses.values()) + width
    spacing = 2.2 * reach
    schemes = list(dict.fromkeys(r.scheme for r in results))
    scene = Scene(
        view=(0.0, 45.0), title="legkit balance: COM to the support line",
        caption="rows: trees 1 (back) to {} (front); columns: {}".format(len(trees), ", ".join(schemes)),
    )
    colors = {"constant": (0.122, 0.467, 0.706), "distance": (1.0, 0.498, 0.055), "momentum": (0.173, 0.627, 0.173)}
    lift = np.eye(4)
    lift[2, 3] = height / 2
    support = [Shape(0, "cylinder", (height / 2, width / 20), lift)]
    for r, q in zip(results, angles):
        offset = np.array([(r.tree - (len(trees) - 1) / 2) * spacing, (schemes.index(r.scheme) - (len(schemes) - 1) / 2) * spacing, 0.0])
        name = f"tree{r.tree + 1}_{r.scheme}"
        model = models[r.tree]
        scene.add_robot(model, q, r.times, name=name, offset=offset, color=colors.get(r.scheme))
        if r.tree == len(trees) - 1:
            scene.add_label(r.scheme, offset - [0.5 * spacing, 0.0, 0.0])
        if r.scheme == schemes[0]:
            scene.add_label(f"tree {r.tree + 1}", offset - [0.0, 0.5 * spacing, 0.0])
        com = lk.center_of_mass(model, q) + offset  # (samples, 3), one batched call
        at_com = np.tile(np.eye(4), (len(r.times), 1, 1))
        at_com[:, :3, 3] = com
        on_ground = at_com.copy()
        on_ground[:, 2, 3] = 0.0
        scene.add_rigid([Shape(0, "sphere", (0.25 * width,))], at_com, r.times, name=f"{name}_com", color=(0.15, 0.15, 0.15))
        scene.add_rigid([Shape(0, "cylinder", (0.002, 0.25 * width))], on_ground, r.times, name=f"{name}_com_ground", color=(0.15, 0.15, 0.15))
        at_root = np.eye(4)
        at_root[:3, 3] = offset
        scene.add_rigid(support, at_root, name=f"{name}_support", color=(0.85, 0.1, 0.1))
    return scene


def write_animation(trees: Sequence[ModuleTree], results: Sequence[RunResult], html_path: Path, gif_path: Path | None) -> None:
    """``balance.html`` (meshcat, self-contained) of ``animation_scene``, and ``gif_path`` (a GIF) unless None."""
    scene = animation_scene(trees, results)
    scene.write_html(html_path, max_fps=ANIMATION_FPS)
    if gif_path is not None:
        scene.write_gif(gif_path, fps=GIF_FPS, size=GIF_SIZE)


def table(results: Sequence[RunResult]) -> str:
    """The summary table as text."""
    lines = [
        "distances in module widths; t10%: first time within 10 % of the initial distance",
        f"{'tree':>4} {'scheme':>9} {'initial':>8} {'final':>8} {'t10% (s)':>9} {'overshoot':>9} {'msg/mod/s':>10}",
    ]
    for r in results:
        reached = "never" if np.isnan(r.time_to_10_percent) else f"{r.time_to_10_percent:.3f}"
        lines.append(
            f"{r.tree + 1:>4} {r.scheme:>9} {r.initial:>8.3f} {r.final:>8.3f} {reached:>9} "
            f"{100 * r.overshoot:>8.1f}% {r.messages_per_module_second:>10.1f}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``legkit balance``: run the experiment, write ``balance.csv``, ``balance.png``, ``balance.html`` (unless
    ``--no-animation``) and ``balance.gif`` (with ``--gif``) to ``--out``, print the table."""
    parser = argparse.ArgumentParser(prog="legkit balance", formatter_class=HelpFormatter, description=__doc__.split("\n\n")[0])
    parser.add_argument("--trees", type=bounded_int(1, 1000), default=4, help="number of random trees (default 4)")
    parser.add_argument("--modules", type=bounded_int(1, MAX_RANDOM_MODULES), default=20, help="modules per tree besides the root (default 20)")
    parser.add_argument("--branches", type=bounded_int(1, 10_000), default=4, help="branches off the root (default 4)")
    parser.add_argument("--seed", type=bounded_int(0, 2**31 - 1), default=0, help="seed of the trees and of the bus (default 0)")
    parser.add_argument("--duration", type=float, default=DEFAULT_DURATION, help=f"simulated seconds (default {DEFAULT_DURATION})")
    parser.add_argument("--loss", type=float, default=0.0, help="message loss probability (default 0: synchronous bus)")
    parser.add_argument("--friction", type=float, default=DEFAULT_FRICTION, help=f"ground friction coefficient (default {DEFAULT_FRICTION})")
    add_output_folder(parser, "balance", "balance.csv, balance.png and the animation")
    parser.add_argument("--plant", choices=PLANTS, default="tree", help="simulator: legkit's tree engine (default), Rapier, or free (no contacts)")
    parser.add_argument("--no-animation", action="store_true", help="do not write balance.html (or balance.gif)")
    parser.add_argument("--gif", action="store_true", help="also write balance.gif, the animation as a picture (about 1.2 s to render)")
    args = parser.parse_args(argv)
    if not 0 < args.duration <= MAX_DURATION:
        parser.error(f"--duration: must be in (0, {MAX_DURATION:g}] s")
    if not 0 <= args.loss < 1:
        parser.error("--loss: must be in [0, 1)")
    try:
        trees = [random_tree(args.modules, args.branches, args.seed + i) for i in range(args.trees)]
        results = run_balance(
            trees, args.duration, loss=args.loss, plant=args.plant, seed=args.seed, friction=args.friction, progress=True,
        )
    except (ValueError, RuntimeError) as error:
        print(f"legkit balance: {error}", file=sys.stderr)
        return 2
    write_csv(results, args.out / "balance.csv")
    plot(results, args.out / "balance.png")
    written = [args.out / "balance.csv", args.out / "balance.png"]
    if not args.no_animation:
        gif = args.out / "balance.gif" if args.gif else None
        write_animation(trees, results, args.out / "balance.html", gif)
        written += [args.out / "balance.html"] + ([gif] if gif else [])
    print(table(results))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


DEFAULT_DURATION = 3.0
#: The longest run the command takes (s of simulated time): its records grow with the duration.
MAX_DURATION = 3600.0
ANIMATION_FPS = 20.0  # keyframes per second of motion in balance.html
GIF_FPS = 10.0
GIF_SIZE = (960, 540)

if __name__ == "__main__":
    sys.exit(main())
