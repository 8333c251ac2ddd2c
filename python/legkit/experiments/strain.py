"""``legkit strain``: the leg-sensing experiment of Lin, Komsuoglu and Koditschek (ICRA 2003) end to end.

1. Calibrate: synthetic benchtop data from the compliant four-bar leg, averaged per held load, filtered to
   physically relevant loads, averaged evenly over configuration space; the Table-1 analogue (fit and
   cross-validation percent NRMSE for orders 1-4) and the order-1 model.
2. Walk: five runs at each of 0.2 and 0.45 m/s from a walking source (by default the kinematic,
   quasi-static generator ``legkit.strain.walking.kinematic_walk``; pass another ``WalkingSource`` to
   ``run`` to use the contact simulation); the Table-2 analogue (percent NRMSE of length and deflection
   over stance samples, model vs ground truth) and the body-pose errors with the model in the loop.
3. Plot the estimated height, roll and pitch against ground truth over one stride (Fig. 7 analogue).
4. Stance detection (Sect. 5.2): how well the paper's coplanarity rho, legkit's determinant measure and the
   plane residual of the six estimated toes (leg model in the loop, body frame) tell tripod support (exactly
   three toes down; the paper: "large values point out tripod support") from samples with more toes down.
   The kinematic generator never has more than three toes down, so this step walks RHex in the contact
   simulation (one run per speed, ``simulated_walk``). Printed per speed and measure: the AUC (the chance
   that a tripod sample scores above a more-toes sample; 1 separates perfectly, 0.5 is chance), the best
   balanced accuracy over thresholds and its threshold rho_hat, and the medians of both classes; rho is
   also shown with the body frame's origin moved 0.1 m forward, which the printed rho depends on.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from legkit._extras import progress, progress_bar, require
from legkit._help import HelpFormatter
from legkit._validation import add_output_folder, bounded_int, integer, positive_scalar
from legkit.strain.benchtop import (
    BenchtopData,
    CompliantFourBarLeg,
    average_by_group,
    grid_average,
    physically_relevant,
    synthetic_benchtop,
)
from legkit.strain.model import LegModel, column_table, format_order_table, nrmse, order_selection_table, text_table
from legkit.strain.pose import coplanarity, plane_residual
from legkit.strain.simulated import simulated_walk
from legkit.strain.walking import PoseEstimate, WalkingSource, WalkingStream, estimate_body_pose, kinematic_walk

SPEEDS = (0.2, 0.45)
#: Walking sources of ``legkit strain --source``: name -> (source, description).
SOURCES: dict[str, tuple[WalkingSource, str]] = {
    "kinematic": (kinematic_walk, "kinematic, quasi-static alternating-tripod generator (legkit.strain.walking.kinematic_walk)"),
    "simulated": (simulated_walk, "RHex in the contact simulation (legkit.strain.simulated.simulated_walk)"),
}


def calibration_set(data: BenchtopData, mu: float = 0.5, bins: tuple[int, int] = (25, 25)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(strain, length, deflection) for fitting: per-load means, physically relevant loads, grid-averaged."""
    _, (strain, length, deflection, normal, tangential) = average_by_group(
        data.configuration, data.strain, data.length, data.deflection, data.normal_force, data.tangential_force
    )
    keep = physically_relevant(normal, tangential, mu)
    cell_length, cell_deflection, (cell_strain,) = grid_average(length[keep], deflection[keep], strain[keep], bins=bins)
    return cell_strain, cell_length, cell_deflection


@dataclass(frozen=True)
class RunResult:
    """Errors of one walking run: percent NRMSE over stance samples, and pose errors over the whole run."""

    speed: float
    seed: int
    length_nrmse: float
    deflection_nrmse: float
    height_error: float  # max |error| (m)
    roll_error: float  # max |error| (rad)
    pitch_error: float  # max |error| (rad)


def evaluate_run(stream: WalkingStream, model: LegModel, seed: int) -> tuple[RunResult, PoseEstimate]:
    """Score the leg model and the pose estimator on one stream."""
    estimate = estimate_body_pose(stream.hip_angle, stream.strain, model, stream.stance_centre, stream.toe_radius)
    stance = stream.stance
    result = RunResult(
        speed=stream.speed,
        seed=seed,
        length_nrmse=nrmse(stream.length[stance], estimate.length[stance]),
        deflection_nrmse=nrmse(stream.deflection[stance], estimate.deflection[stance]),
        height_error=float(np.max(np.abs(estimate.pose.height - stream.height))),
        roll_error=float(np.max(np.abs(estimate.pose.roll - stream.roll))),
        pitch_error=float(np.max(np.abs(estimate.pose.pitch - stream.pitch))),
    )
    return result, estimate


def format_walking_table(results: list[RunResult]) -> str:
    """Table-2 analogue: mean +- std over runs of the NRMSEs, and the worst pose errors, per speed."""
    header = (
        "speed m/s | runs | length NRMSE %  | deflection NRMSE % | max height err mm | max roll err deg "
        "| max pitch err deg"
    )
    lines = []
    for speed in sorted({r.speed for r in results}):
        rows = [r for r in results if r.speed == speed]
        length = np.array([r.length_nrmse for r in rows])
        deflection = np.array([r.deflection_nrmse for r in rows])
        lines.append(
            f"{speed:9.2f} | {len(rows):4d} | {length.mean():6.3f} +- {length.std():5.3f} | "
            f"{deflection.mean():8.3f} +- {deflection.std():6.3f} | "
            f"{1e3 * max(r.height_error for r in rows):17.2f} | "
            f"{np.degrees(max(r.roll_error for r in rows)):16.3f} | "
            f"{np.degrees(max(r.pitch_error for r in rows)):17.3f}"
        )
    return text_table(header, lines)


def plot_stride(stream: WalkingStream, estimate: PoseEstimate, path: Path, source_label: str = "kinematic walking generator") -> None:
    """Fig. 7 analogue: estimated vs true height, roll and pitch over the first full stride."""
    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stride = stream.time < stream.time[0] + stream.period
    t = stream.time[stride] - stream.time[0]
    series = [
        ("height (mm)", 1e3 * stream.height, 1e3 * estimate.pose.height),
        ("roll (deg)", np.degrees(stream.roll), np.degrees(estimate.pose.roll)),
        ("pitch (deg)", np.degrees(stream.pitch), np.degrees(estimate.pose.pitch)),
    ]
    figure, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for axis, (label, truth, estimated) in zip(axes, series):
        axis.plot(t, truth[stride], "k-", label="ground truth")
        axis.plot(t, estimated[stride], "r--", label="leg model + tripod pose")
        axis.set_ylabel(label)
        axis.grid(True, alpha=0.3)
    axes[0].legend(loc="best")
    axes[0].set_title(f"Body pose over one stride at {stream.speed:.2f} m/s ({source_label})")
    axes[-1].set_xlabel("time (s)")
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


#: Contact measures of the six toes (T, 6, 3) compared as stance detectors; large means tripod support.
DETECTION_MEASURES = {
    "rho (paper, Sect. 5.2)": coplanarity,
    "rho, body origin +0.1 m x": lambda toes: coplanarity(toes + np.array([0.1, 0.0, 0.0])),
    "determinant": lambda toes: coplanarity(toes, "determinant"),
    "plane residual": plane_residual,
}


@dataclass(frozen=True)
class StanceDetection:
    """How one measure separates tripod support from more toes down over one walking run."""

    speed: float
    measure: str
    auc: float
    balanced_accuracy: float
    threshold: float  # rho_hat: tripod support when the measure exceeds it
    tripod_median: float
    more_toes_median: float


def separation(scores: np.ndarray, tripod: np.ndarray) -> tuple[float, float, float]:
    """(AUC, best balanced accuracy, its threshold) of `scores` (n,) for the classes `tripod` (n,) bool,
    classifying score > threshold as tripod."""
    positive, negative = np.sort(scores[tripod]), np.sort(scores[~tripod])
    if positive.size == 0 or negative.size == 0:
        raise ValueError("tripod must hold samples of both classes")
    # Mann-Whitney: count the (tripod, other) pairs ordered correctly, ties as half.
    below = np.searchsorted(negative, positive, side="left")
    ties = np.searchsorted(negative, positive, side="right") - below
    auc = float(np.sum(below + 0.5 * ties)) / (positive.size * negative.size)
    thresholds = np.unique(scores)
    sensitivity = 1.0 - np.searchsorted(positive, thresholds, side="right") / positive.size
    specificity = np.searchsorted(negative, thresholds, side="right") / negative.size
    balanced = 0.5 * (sensitivity + specificity)
    best = int(np.argmax(balanced))
    return auc, float(balanced[best]), float(thresholds[best])


def stance_detection(stream: WalkingStream, estimate: PoseEstimate) -> list[StanceDetection]:
    """Every ``DETECTION_MEASURES`` entry on the estimated toes of one run; samples with fewer than three
    toes down (the body carried by two legs or tipping) belong to neither class and are left out."""
    down = stream.stance.sum(axis=1)
    keep = down >= 3
    tripod = down[keep] == 3
    rows = []
    for name, measure in DETECTION_MEASURES.items():
        scores = measure(estimate.toes[keep])
        auc, accuracy, threshold = separation(scores, tripod)
        median_tripod, median_other = float(np.median(scores[tripod])), float(np.median(scores[~tripod]))
        rows.append(StanceDetection(stream.speed, name, auc, accuracy, threshold, median_tripod, median_other))
    return rows


DETECTION_COLUMNS = (
    ("speed m/s", ".2f"),
    ("measure                   ", "s"),
    ("  AUC", ".3f"),
    ("balanced acc.", ".3f"),
    ("threshold ", ".3g"),
    ("median tripod", ".3g"),
    ("median >3 toes", ".3g"),
)


def format_detection_table(rows: list[StanceDetection]) -> str:
    return column_table(
        DETECTION_COLUMNS,
        [(r.speed, r.measure, r.auc, r.balanced_accuracy, r.threshold, r.tripod_median, r.more_toes_median) for r in rows],
    )


@dataclass(frozen=True)
class ExperimentResult:
    """Everything the experiment prints: the calibrated model, Table 1 and Table 2, and the figure path."""

    model: LegModel
    order_table: str
    walking_table: str
    runs: list[RunResult]
    figure: Path
    detection_table: str
    detection: list[StanceDetection]


def run(
    out: Path,
    source: WalkingSource = kinematic_walk,
    runs: int = 5,
    duration: float = 4.0,
    seed: int = 0,
    leg: CompliantFourBarLeg | None = None,
    source_label: str = "kinematic walking generator",
) -> ExperimentResult:
    """Calibrate on synthetic benchtop data, walk at ``SPEEDS`` with ``source``, write the figure to out."""
    if not callable(source):
        raise TypeError(f"source: must be a WalkingSource (a callable), got {type(source).__name__}")
    if not 1 <= integer(runs, "runs") <= 1000:
        raise ValueError(f"runs must be in 1..1000, got {runs}")
    positive_scalar(duration, "duration")
    leg = leg or CompliantFourBarLeg()
    strain, length, deflection = calibration_set(synthetic_benchtop(leg, seed=seed))
    order_table = format_order_table(order_selection_table(strain, length, deflection, seed=seed))
    model = LegModel.fit(strain, length, deflection, order=1)

    results: list[RunResult] = []
    first: tuple[WalkingStream, PoseEstimate] | None = None
    jobs = [(speed, seed * 1000 + k) for speed in SPEEDS for k in range(runs)]
    for speed, run_seed in progress(jobs, desc="walking runs", leave=False):
        stream = source(speed, duration, run_seed)
        if not isinstance(stream, WalkingStream):
            raise TypeError(f"source: returned {type(stream).__name__}, not a WalkingStream")
        result, estimate = evaluate_run(stream, model, run_seed)
        results.append(result)
        if first is None:
            first = (stream, estimate)
    out.mkdir(parents=True, exist_ok=True)
    figure = out / "strain_pose_stride.png"
    assert first is not None  # runs >= 1
    plot_stride(*first, figure, source_label)
    detection: list[StanceDetection] = []
    # Each simulated walk takes seconds (the contact simulation's steps): the bar ticks per strain sample.
    with progress_bar(desc="stance detection (simulated walks)", total=len(SPEEDS), unit="walk", leave=False,
                  bar_format="{l_bar}{bar}| {n:.2f}/{total} walks [{elapsed}<{remaining}]") as bar:
        for done, speed in enumerate(SPEEDS):

            def tick(fraction: float, done: int = done) -> None:
                bar.update(done + fraction - bar.n)

            stream = simulated_walk(speed, duration, seed, ticks=tick)
            detection += stance_detection(stream, evaluate_run(stream, model, seed)[1])
    return ExperimentResult(
        model, order_table, format_walking_table(results), results, figure, format_detection_table(detection), detection
    )


def main(argv: list[str] | None = None) -> int:
    """``legkit strain``: print Tables 1 and 2 analogues and write the Fig. 7 analogue to --out."""
    parser = argparse.ArgumentParser(prog="legkit strain", formatter_class=HelpFormatter, description=__doc__.splitlines()[0])
    add_output_folder(parser, "strain", "the figures")
    parser.add_argument("--runs", type=bounded_int(1, 1000), default=5, help="walking runs per speed")
    parser.add_argument("--duration", type=float, default=4.0, help="length of each walking run (s)")
    parser.add_argument("--seed", type=bounded_int(0, 2**31 - 1), default=0,
                        help="seed of the synthetic bench-top calibration and of the walking runs")
    parser.add_argument("--source", choices=sorted(SOURCES), default="kinematic", help="walking data source")
    args = parser.parse_args(argv)
    if not 0 < args.duration <= 3600:
        parser.error("--duration must be in (0, 3600] s")

    leg = CompliantFourBarLeg()
    source, description = SOURCES[args.source]
    result = run(
        args.out, source=source, runs=args.runs, duration=args.duration, seed=args.seed, leg=leg,
        source_label=f"{args.source} walking",
    )
    n1, n2 = leg.generating_coefficients()
    np.set_printoptions(precision=6)
    print("Leg model calibration (synthetic benchtop, compliant four-bar leg; strain in microstrain)")
    print("Table 1 analogue: percent NRMSE of the polynomial map, fit and 5-fold cross-validation\n")
    print(result.order_table)
    print("\nOrder-1 model: length = n1_0 + n1_1 sigma (m), deflection = n2_0 + n2_1 sigma (rad)")
    print(f"  fitted     n1 = {result.model.length_coefficients}   n2 = {result.model.deflection_coefficients}")
    print(f"  linkage    n1 = {n1}   n2 = {n2}   (exact map if the axial and clamp modes were rigid)")
    rigid = CompliantFourBarLeg(axial_stiffness=np.inf, clamp_stiffness=np.inf)
    check = LegModel.fit(*calibration_set(synthetic_benchtop(rigid, seed=args.seed)), order=1)
    n1_rigid, n2_rigid = rigid.generating_coefficients()
    length_z = np.abs(check.length_coefficients - n1_rigid) / check.length_standard_errors
    deflection_z = np.abs(check.deflection_coefficients - n2_rigid) / check.deflection_standard_errors
    print(
        "  recovery with rigid axial/clamp modes (sensor error only): |fitted - generating| / standard error = "
        f"{np.round(length_z, 2)} (length), {np.round(deflection_z, 2)} (deflection)"
    )
    print(f"\nWalking: {description}")
    print("Table 2 analogue: model vs ground truth over stance samples; pose errors with the model in the loop\n")
    print(result.walking_table)
    print(f"\nFig. 7 analogue written to {result.figure}")
    print("\nStance detection (Sect. 5.2) on the six estimated toes, simulated walking: tripod support vs more toes down\n")
    print(result.detection_table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
