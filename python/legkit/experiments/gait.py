"""`legkit gait`: stability and energy indices over one cycle of a quadruped amble and a biped walk.

Reproduces the gait analysis of [Hardt 2002]: the amble of its Fig. 3 (0.67 m/s, gait period 1.25 s, duty factor
0.5, v_tip_max = 2 m/s, support order LF+LH, LF+RH, RF+RH, RF+LH), and a biped walking at the 1.8 km/h (0.5 m/s) of
its Sect. 6. The references are `legkit.gaits.references`' (the amble on `AMBLE_QUADRUPED`, whose legs reach the
published stride), their analysis `legkit.gaits.analysis.analyse`; this module parses the arguments and writes the
outputs.

Outputs in --out: gait_<robot>.csv (one row per sample) and gait_<robot>.png (S_H over the cycle, like the paper's
Fig. 3: the published S_H, with the energy variant overlaid; the static and ZMP margins below). A short table is
printed. Nothing is random: the same arguments give the same files.

`--optimize` replaces the references by optimised gaits (`legkit.optimize.gaits`): the amble maximising the
worst-case S_H (J_s2) and the biped walk minimising the Joule loss (J_e1) with a Fig.-6 torque-speed plot
(`run_optimized_amble`, `run_optimized_walk`).
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import legkit.stability as st
from legkit._extras import load, require
from legkit._help import HelpFormatter
from legkit._validation import add_output_folder, bounded_float, bounded_int
from legkit.gaits.analysis import GaitAnalysis, analyse, biped_extras
from legkit.gaits.references import AMBLE_HIP_HEIGHT, AMBLE_QUADRUPED, MAX_SAMPLES, biped_walk, quadruped_amble
from legkit.robots.biped import JOINT_LABELS, SIDES, Biped, build_biped
from legkit.robots.motors import BIPED_MOTOR, QUADRUPED_MOTOR, MotorParameters
from legkit.robots.quadruped import DIAGONAL_PAIRS, LEGS, build_quadruped

if TYPE_CHECKING:
    from legkit.optimize.gaits import AmbleOptions
    from legkit.optimize.layout import Trajectory
    from legkit.optimize.problem import MultiphaseProblem
    from legkit.optimize.replay import Replay


@dataclass(frozen=True)
class GaitOptions:
    """The command's arguments, typed, as `main` builds them once from its parser (`from_arguments`) and hands them to
    the functions that run it (each option's meaning: `legkit gait --help`)."""

    robot: str
    out: Path
    cycles: int
    samples: int
    mu: float | None
    quadruped_speed: float
    quadruped_period: float
    quadruped_tip_speed: float
    biped_speed: float
    biped_step: float
    biped_tip_speed: float
    optimize: bool
    intervals: int
    coarse_intervals: int
    derivatives: str
    biped_intervals: int
    max_iter: int
    biped_max_iter: int
    tol: float
    biped_max_power: float | None
    replay_cycles: int
    replay_kp: float
    replay_kd: float
    replay_controller: str
    min_normal_force: float
    torque_margin: float
    max_impulse: float
    no_animation: bool
    mirror: bool | None
    polish: bool
    polish_max_iter: int

    @classmethod
    def from_arguments(cls, args: argparse.Namespace) -> GaitOptions:
        """The options of parsed arguments."""
        return cls(**{option.name: getattr(args, option.name) for option in fields(cls)})

    def amble(self) -> AmbleOptions:
        """The amble plan's problem options (`legkit.optimize.gaits.AmbleOptions`): the command's, its defaults otherwise."""
        from legkit.optimize.gaits import AMBLE_MIRROR, AMBLE_PLAN_FRICTION, AmbleOptions

        return AmbleOptions(self.quadruped_tip_speed, AMBLE_PLAN_FRICTION if self.mu is None else self.mu, self.max_impulse,
                            AMBLE_MIRROR if self.mirror is None else self.mirror, self.min_normal_force, self.torque_margin)


# --------------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------------


def write_csv(path: Path, analysis: GaitAnalysis) -> None:
    names = list(analysis.columns)
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(names + ["support"])
        rows = np.stack([analysis.columns[n] for n in names], axis=1)
        for row, label in zip(rows, analysis.ref.support_label):
            writer.writerow([f"{x:.9g}" for x in row] + [label])


def plot(path: Path, analysis: GaitAnalysis, title: str) -> None:
    """S_H over the cycle (paper Fig. 3) with the support phases shaded, and the static/ZMP margins below."""
    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, labels = analysis.ref.t, analysis.ref.support_label
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    starts = [0] + [i for i in range(1, len(labels)) if labels[i] != labels[i - 1]] + [len(labels)]
    shades: dict[str, str] = {}
    for a, b in zip(starts[:-1], starts[1:]):
        colour = shades.setdefault(labels[a], f"C{len(shades) + 2}")
        for axis in (top, bottom):
            axis.axvspan(t[a], t[b - 1], color=colour, alpha=0.12, lw=0)
        top.text(0.5 * (t[a] + t[b - 1]), 1.0, labels[a], transform=top.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
    top.plot(t, analysis.columns["S_H"], color="C0", label="S_H (paper, eq. 10)")
    top.plot(t, analysis.columns["S_H_energy"], color="C1", ls="--", lw=0.9, label="S_H (energy variant)")
    top.legend(loc="lower right", fontsize=8)
    top.axhline(0.0, color="k", lw=0.8)
    top.set_ylabel("S_H [N m s]")
    top.set_title(title, pad=14)
    bottom.plot(t, analysis.columns["static_margin"] * 1e3, color="C1", label="static margin")
    bottom.plot(t, analysis.columns["zmp_margin"] * 1e3, color="C0", ls="--", label="ZMP margin")
    bottom.axhline(0.0, color="k", lw=0.8)
    bottom.set_ylabel("margin [mm]")
    bottom.set_xlabel("t [s]")
    bottom.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


#: What the tables' signs mean, printed under them (units are in each row's brackets).
LEGEND = (
    "Signs: a margin is > 0 when its condition holds and < 0 by how much it fails: static and ZMP margins, the COM's\n"
    "ground projection and the ZMP inside the support polygon (on one or two feet there is no inside: never > 0);\n"
    "friction, inside the friction cone; torque-speed, within the motor's torque at that speed; foot-torque and FRI,\n"
    "the foot not tipping. S_H > 0 is stable [Hardt 2002, eq. 10]; '-': not defined for that robot."
)


def print_table(analyses: list[GaitAnalysis]) -> None:
    keys = list(dict.fromkeys(k for a in analyses for k in a.summary))
    width = max(len(k) for k in keys)
    print(f"{'':{width}}  " + "  ".join(f"{a.robot:>12}" for a in analyses))
    for key in keys:
        cells = [f"{a.summary[key]:12.5g}" if key in a.summary else f"{'-':>12}" for a in analyses]
        print(f"{key:{width}}  " + "  ".join(cells))
    print(LEGEND)


def reference(robot_name: str, options: GaitOptions) -> tuple[Any, Any]:
    """The robot and its hand-built reference gait at the command's speed, period and step. ValueError when a foot
    target is out of the legs' reach."""
    if robot_name == "quadruped":
        quadruped = build_quadruped(AMBLE_QUADRUPED)
        return quadruped, quadruped_amble(quadruped, options.quadruped_speed, options.quadruped_period, options.samples, options.cycles, 0.03,
                                          AMBLE_HIP_HEIGHT)
    biped = build_biped()
    return biped, biped_walk(biped, options.biped_speed / 3.6, options.biped_step, options.samples, options.cycles, 0.2, 0.05, 0.82, 0.3)


def run(robot_name: str, options: GaitOptions, progress: Any) -> GaitAnalysis:
    """Build the robot and its reference, analyse it, and write its CSV and figure."""
    robot, ref = reference(robot_name, options)
    if robot_name == "quadruped":
        model, motor, tip_speed = robot.model, QUADRUPED_MOTOR, options.quadruped_tip_speed
        diagonal = [(LEGS.index(a), LEGS.index(b)) for a, b in DIAGONAL_PAIRS]
        title = (f"Quadruped amble, duty 0.5, {options.quadruped_speed:g} m/s, period {options.quadruped_period:g} s: "
                 f"S_H over {options.cycles} cycle(s)")
    else:
        model, motor, tip_speed, diagonal = robot.model, BIPED_MOTOR, options.biped_tip_speed, None
        title = f"Biped walk, {options.biped_speed:g} km/h: S_H over {options.cycles} cycle(s)"
    progress.update()
    analysis = analyse(robot_name, model, ref, motor, tip_speed, FRICTION if options.mu is None else options.mu, diagonal, progress.update)
    if robot_name == "biped":
        biped_extras(robot, analysis)
    write_csv(options.out / f"gait_{robot_name}.csv", analysis)
    plot(options.out / f"gait_{robot_name}.png", analysis, title)
    progress.update()
    return analysis


def run_optimized_amble(options: GaitOptions) -> dict[str, float]:
    """`--optimize`: the Fig. 3 amble optimised by multiphase collocation on IPOPT (`legkit.optimize`), maximising
    the worst-case S_H (J_s2, eq. 11) from the hand-built reference, its touchdown impulses bounded by --max-impulse
    (default 0: the feet land at rest); one labelled progress line per IPOPT stage. With
    --coarse-intervals, J_s2 is solved on that mesh and the optimum refined onto --intervals (`MultiphaseProblem.refine`).
    Writes gait_quadruped_optimized.csv (every collocation point: t, phase, support, q, v, u, S_H) and .png
    (S_H over the period with its worst case marked, beside the reference's), then replays the gait in
    `lk.Simulation` over --replay-cycles cycles under the contact-constrained MPC of `legkit.optimize.tracking` (by
    default; --replay-controller pd: joint PD tracking with --replay-kp, --replay-kd + feed-forward torques), saying
    which, and, unless --no-animation, writes the replay beside the plan as .html (meshcat) and .gif, captioned with
    the controller."""
    from legkit.optimize.checks import midpoint_stance_acceleration
    from legkit.optimize.gaits import amble_plan_problem, amble_reference, guess_from_reference, plan_amble

    robot = build_quadruped(AMBLE_QUADRUPED)
    speed, period = options.quadruped_speed, options.quadruped_period
    problem = amble_plan_problem(robot, options.intervals, speed, period, options.amble())
    print(f"optimising the amble: {problem.n} variables, {problem.m} constraints, {len(problem.jac_rows)} Jacobian nonzeros"
          + (f", from {options.coarse_intervals} intervals per phase" if options.coarse_intervals else ""))
    if not options.coarse_intervals:
        _announce(problem, problem.gauged(problem.pack(guess_from_reference(problem, amble_reference(robot, speed, period, options.intervals)))),
                  "amble")
    coarse = f" on {options.coarse_intervals} interval{'s' if options.coarse_intervals > 1 else ''}" if options.coarse_intervals else ""
    polish = options.polish and options.derivatives == "legkit"
    hessian = "exact Hessian" if options.derivatives == "exact" else "L-BFGS"
    progress = _StageProgress([f"constraints{coarse} (p1 held below S_H)", f"J_s2{coarse} ({hessian})"]
                              + ([f"polish{coarse}: exact Hessian, durations held", f"polish{coarse}: exact Hessian"] if polish else [])
                              + ([f"refine onto {options.intervals} intervals"] if options.coarse_intervals else []))
    cpu = time.process_time()
    plan = plan_amble(robot, speed, period, options.intervals, options.coarse_intervals, derivatives=options.derivatives, polish=options.polish,
                      polish_max_iter=options.polish_max_iter, tol=options.tol, max_iter=options.max_iter, progress=progress,
                      options=options.amble(), problem=problem)
    cpu = time.process_time() - cpu
    progress.close()
    problem, result = plan.problem, plan.result
    reference_s_h = np.concatenate(problem.stability_index(problem.pack(plan.reference)))
    x, _ = result.best()
    if x is result.x:
        kept = result.history[-1][0]
    else:
        assert result.best_feasible is not None  # best() returns another point than IPOPT's only from best_feasible
        kept = result.best_feasible[0]
    problem, x = problem.whole_cycle(x)
    trajectory = problem.unpack(x)
    data = trajectory.stacked()
    labels = ["+".join(leg.upper() for leg in problem.phases[k].contacts) for k in data["phase"]]
    columns = _write_trajectory_csv(options.out / "gait_quadruped_optimized.csv", trajectory, labels,
                                    {"S_H": np.concatenate(problem.stability_index(x))})
    worst, worst_t = st.worst_case(columns["S_H"], data["t"])
    _plot_optimized(options.out / "gait_quadruped_optimized.png", data["t"], columns["S_H"], plan.reference.stacked()["t"], reference_s_h,
                    labels, worst, worst_t,
                    f"Optimised amble (J_s2), {speed:g} m/s, period {period:g} s: IPOPT {result.status}, iterate {kept} kept"
                    + (f", refined from {options.coarse_intervals} intervals" if options.coarse_intervals else ""))
    simulated = _replay(options, problem, trajectory, QUADRUPED_MOTOR, options.out / "gait_quadruped_optimized", "the amble")
    return {
        "IPOPT iterations": result.iterations, "solve wall time [s]": result.wall_time, "solve CPU time of this process [s]": cpu,
        "function + Jacobian share of the solve [%]": 100.0 * result.evaluation_time / result.wall_time,
        "kept iterate (IPOPT's last unless a better one within tol)": float(kept),
        "max constraint violation (legkit dynamics)": problem.nlp().violation(x),
        "largest stance-foot acceleration at the midpoints [m/s^2] (the knots hold 0)": midpoint_stance_acceleration(problem, x),
        **interval_drift_summary(problem, x),
        **execution_summary(problem, x),
        "S_H min, optimised [N m s]": worst, "S_H min at [s]": worst_t, "S_H min, reference [N m s]": float(reference_s_h.min()),
        **{f"phase {k} ({'+'.join(p.contacts).upper()}) duration [s]": float(d)
           for k, (p, d) in enumerate(zip(problem.phases, trajectory.durations))},
        **_replay_summary(options, simulated),
        "solver succeeded (1 = yes)": float(result.success),
    }


def run_optimized_walk(options: GaitOptions) -> dict[str, float]:
    """`--optimize`: the biped walk at --biped-speed minimising J_e1 (eq. 12) under the motors' torque-speed lines
    ([Hardt 2002, Sect. 2.3 and 6]; `legkit.optimize.gaits.walk_problem`), its soles flat with eq. 6's torque
    limits, from the hand-built reference (`biped_walk`); constraints first, then J_e1, one progress line per
    IPOPT iteration. Writes gait_biped_optimized.csv (every collocation point: t, phase, support, q, v, u, the
    feet's forces and torques) and gait_biped_torque_speed.png (Fig. 6: each joint's (speed, torque) points over
    the period against the motor's characteristic lines for several gear ratios), then replays the walk in
    `lk.Simulation` as the amble is replayed (--replay-controller; the MPC holds each stance sole as a frame, its
    wrench within eq. 6) and, unless --no-animation, writes gait_biped_optimized.html and .gif."""
    from legkit.optimize.checks import inverse_dynamics_residuals
    from legkit.optimize.gaits import WALK_MIRROR, WALK_PLAN_FRICTION, guess_from_reference, solve_walk, walk_problem, walk_reference

    robot = build_biped()
    speed = options.biped_speed / 3.6
    intervals = (max(1, options.biped_intervals // 4), options.biped_intervals)
    problem = walk_problem(robot, speed, BIPED_MOTOR, intervals, WALK_PLAN_FRICTION if options.mu is None else options.mu,
                           max_input_power=options.biped_max_power,
                           mirror=WALK_MIRROR if options.mirror is None else options.mirror)
    guess = guess_from_reference(problem, walk_reference(robot, speed, intervals))
    print(f"optimising the biped walk: {problem.n} variables, {problem.m} constraints, {len(problem.jac_rows)} Jacobian nonzeros")
    _announce(problem, problem.gauged(problem.pack(guess)), "walk")
    cpu = time.process_time()
    progress = _StageProgress(["constraints", "J_e1"])
    _, result = solve_walk(problem, guess, tol=options.tol, max_iter=options.biped_max_iter, progress=progress)
    progress.close()
    cpu = time.process_time() - cpu
    x, objective = result.best()
    problem, x = problem.whole_cycle(x)
    trajectory = problem.unpack(x)
    data = trajectory.stacked()
    labels = ["+".join(problem.phases[k].contacts).upper() for k in data["phase"]]
    wrenches = {}
    for side in SIDES:  # zero while the foot is in the air
        force, torque = np.zeros((len(data["t"]), 3)), np.zeros((len(data["t"]), 3))
        rows = np.cumsum([0] + [len(t) for t in trajectory.t])
        for k, phase in enumerate(problem.phases):
            if side in phase.contacts:
                force[rows[k] : rows[k + 1]] = trajectory.forces[k][:, phase.contacts.index(side)]
                assert trajectory.torques is not None  # the walk's feet are flat: unpack gives their torques
                torque[rows[k] : rows[k + 1]] = trajectory.torques[k][:, problem.flat_contacts(phase.contacts).index(side)]
        wrenches.update({f"{side}_F{axis}": force[:, i] for i, axis in enumerate("xyz")})
        wrenches.update({f"{side}_T{axis}": torque[:, i] for i, axis in enumerate("xyz")})
    _write_trajectory_csv(options.out / "gait_biped_optimized.csv", trajectory, labels, wrenches)
    joint_speed = data["v"][:, problem.actuated]
    plot_torque_speed(options.out / "gait_biped_torque_speed.png", robot, joint_speed, data["u"], BIPED_MOTOR,
                      f"Optimised biped walk (J_e1), {options.biped_speed:g} km/h: IPOPT {result.status}")
    simulated = _replay(options, problem, trajectory, BIPED_MOTOR, options.out / "gait_biped_optimized", "the walk")
    return {
        "IPOPT iterations (constraints, then J_e1)": result.iterations, "solve wall time [s]": result.wall_time,
        "solve CPU time of this process [s]": cpu, "J_e1 (eq. 12) [J/m]": objective,
        "max constraint violation (legkit dynamics)": problem.nlp().violation(x),
        "max |rnea - B u| (lk.rnea) [N m]": float(np.max(np.abs(np.concatenate(inverse_dynamics_residuals(problem, x))))),
        **interval_drift_summary(problem, x),
        **execution_summary(problem, x),
        "period [s]": float(np.sum(trajectory.durations)), "step length [m]": 0.5 * speed * float(np.sum(trajectory.durations)),
        **{f"phase {k} ({'+'.join(p.contacts).upper()}) duration [s]": float(d)
           for k, (p, d) in enumerate(zip(problem.phases, trajectory.durations))},
        "torque-speed margin min (Sect. 2.3) [N m]": float(np.min(st.torque_speed_margin(
            data["u"], joint_speed, BIPED_MOTOR.joint_max_speed, BIPED_MOTOR.gear_ratio, BIPED_MOTOR.efficiency, BIPED_MOTOR.slope))),
        **_replay_summary(options, simulated),
        "solver succeeded (1 = yes)": float(result.success),
    }


def _replay(options: GaitOptions, problem: MultiphaseProblem, trajectory: Trajectory, motor: MotorParameters, stem: Path,
            gait: str) -> Replay:
    """Replay a solved gait in `lk.Simulation` for --replay-cycles cycles under --replay-controller, saying which, and,
    unless --no-animation, write stem.html and stem.gif captioned with the controller."""
    from legkit.optimize.gaits import stall_torque_bounds
    from legkit.optimize.replay import replay
    from legkit.optimize.tracking import track

    if options.replay_controller == "mpc":
        controller = ("the contact-constrained MPC (legkit.optimize.tracking: 2 ms control period, 120 ms horizon, "
                      "stance forces >= 0.5 N in the friction pyramid (soles: eq. 6), swing feet above the ground, the motors' stall torques)")
        caption = "the contact-constrained MPC (2 ms, 120 ms horizon)"
        print(f"replaying {options.replay_cycles} cycles in lk.Simulation under {controller}")
        simulated = track(problem, trajectory, options.replay_cycles, torque_bounds=stall_torque_bounds(motor, problem.nu))
    else:
        controller = f"joint PD tracking (kp {options.replay_kp:g} N m/rad, kd {options.replay_kd:g} N m s/rad) + the planned torques as feed-forward"
        caption = f"joint PD (kp {options.replay_kp:g}, kd {options.replay_kd:g}) + feed-forward"
        print(f"replaying {options.replay_cycles} cycles in lk.Simulation under {controller}")
        simulated = replay(problem, trajectory, options.replay_cycles, kp=options.replay_kp, kd=options.replay_kd, control_every=1)
    if not options.no_animation:
        _animate_replay(stem, problem, simulated, caption, gait)
    return simulated


def _replay_summary(options: GaitOptions, simulated: Replay) -> dict[str, float]:
    return {f"replay ({options.replay_controller}): drift over {options.replay_cycles} cycles [% of distance]": 100.0 * simulated.drift_fraction,
            "replay: stayed upright (1 = yes)": float(simulated.upright),
            "replay: fell after [s] (inf: never)": simulated.fell_at}


#: The largest drift over one interval (`interval_drift_summary`) of a plan that is a motion of its model, 2 deg of attitude
#: and 0.1 rad at the joints: beyond it the mesh is too coarse for the dynamics between the points (more intervals). The
#: default amble on 16 intervals per phase drifts 0.22 deg and 0.020 rad, its optimum on 4 intervals 37 deg and 1.8 rad.
MOTION_DRIFT = {"largest drift over one interval, attitude [deg]": 2.0, "largest drift over one interval, joints": 0.1}


def verdict(summary: dict[str, float], cycles: int) -> list[str]:
    """The summary's outcome in words: whether IPOPT converged, whether the plan is a motion of the model (its interval
    drift within `MOTION_DRIFT`) and whether the replay stayed upright."""
    converged = summary["solver succeeded (1 = yes)"] == 1.0
    drift = {key: summary[key] for key in MOTION_DRIFT if key in summary}
    beyond = [f"{key.rpartition(', ')[2]} {value:.3g} > {MOTION_DRIFT[key]:g}" for key, value in drift.items() if not value <= MOTION_DRIFT[key]]
    fell, upright = summary["replay: fell after [s] (inf: never)"], summary["replay: stayed upright (1 = yes)"] == 1.0
    return [
        "verdict: " + ("IPOPT converged" if converged else "IPOPT did NOT converge: the plan is its best feasible iterate, not an optimum"),
        "verdict: " + (f"NOT a motion of the model (drift over one interval: {', '.join(beyond)}; use more intervals)" if beyond
                       else "a motion of the model (drift over one interval within 2 deg of attitude and 0.1 rad at the joints)"),
        "verdict: " + (f"the replay stayed upright over {cycles} cycle{'s' if cycles > 1 else ''}" if upright
                       else f"the replay FELL after {fell:.2f} s"),
    ]


def execution_summary(problem: MultiphaseProblem, x: np.ndarray) -> dict[str, float]:
    """`legkit.optimize.checks.execution_check` of a solution as summary rows."""
    from legkit.optimize.checks import execution_check


    check = execution_check(problem, x)
    return {"torso yaw max [deg]": check.yaw, "joint rate max between points / motors' no-load speed": check.joint_rate,
            "torque max / bound": check.torque, "torque rate max [bound per ms]": check.torque_rate,
            "foot load rate max [body weight per ms]": check.force_rate, "swing tip min between points [m]": check.swing_height}


def interval_drift_summary(problem: MultiphaseProblem, x: np.ndarray) -> dict[str, float]:
    """The largest drift of the model's own dynamics over one collocation interval (`legkit.optimize.shooting`):
    how far the mesh is from a motion. Large values (degrees of attitude, tenths of a radian) ask for more
    intervals (--intervals, --biped-intervals)."""
    from legkit.optimize import interval_drift


    worst = interval_drift(problem, x).worst(problem.model.floating_base)
    return {f"largest drift over one interval, {name}": value for name, value in worst.items()
            if name in ("attitude [deg]", "joints", "joint rates")}


#: Gear ratios drawn in the torque-speed figure: the paper's choice for its biped (Fig. 6, Sect. 6: 42 V motors with
#: 66:1 gears), one between, and BIPED_MOTOR's own (the constraint).
FIG6_GEAR_RATIOS = (66.0, 100.0, BIPED_MOTOR.gear_ratio)


def plot_torque_speed(path: Path, robot: Biped, joint_speed: np.ndarray, torque: np.ndarray, motor: MotorParameters, title: str) -> None:
    """Fig. 6 of [Hardt 2002]: per joint (left and right together), |torque| against |speed| [rpm] at every collocation
    point, with the characteristic line |u| = (w_max - |w|) G^2 eta / m (Sect. 2.3) of `motor` at each gear ratio
    in FIG6_GEAR_RATIOS (the motor's own ratio bounds the optimisation)."""
    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rpm = 60.0 / (2.0 * np.pi)
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(robot.model.names):
        if robot.model.idx_v[i] >= 6 and name[:2] in ("l_", "r_") and robot.model.joint_type(i) == "revolute":
            groups.setdefault(name[2:], []).append(robot.model.idx_v[i] - 6)
    fig, axes = plt.subplots(2, (len(groups) + 1) // 2, figsize=(13, 6), sharex=True)
    top = max(np.max(np.abs(torque)), 1e-9)
    for axis, (name, columns) in zip(axes.ravel(), groups.items()):
        for gear, style in zip(FIG6_GEAR_RATIOS, (":", "--", "-")):
            w_max = motor.no_load_speed / gear
            gain = gear**2 * motor.efficiency / motor.slope
            axis.plot([0.0, w_max * rpm], [w_max * gain, 0.0], color="k", ls=style, lw=0.8, label=f"{gear:g}:1")
        for column, side in zip(columns, ("left", "right")):
            axis.plot(np.abs(joint_speed[:, column]) * rpm, np.abs(torque[:, column]), ".", ms=4, label=side)
        axis.set_title(JOINT_LABELS[name], fontsize=9)
        axis.set_ylim(0.0, 1.3 * top)
        axis.set_xlim(0.0, 1.05 * motor.no_load_speed / min(FIG6_GEAR_RATIOS) * rpm)  # every line's no-load speed
    for axis in axes[-1]:
        axis.set_xlabel("|joint speed| [rpm]")
    for axis in axes[:, 0]:
        axis.set_ylabel("|joint torque| [N m]")
    axes.ravel()[0].legend(fontsize=7, title="motor line, gear", title_fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


#: IPOPT iterations of the gaits' cold solves with the default options, constraints and objective stages together
#: (docs/optimize.md, "Results"), and the CPU an iteration took in units of one evaluation of the NLP's functions
#: and derivatives (constraints, Jacobian, Hessian) timed before it: the KKT factorisations take the rest, more of it
#: on the amble's larger system (45.7 s over 117 iterations after a 0.08 s evaluation; the walk on 12 intervals 21.6 s
#: over 90 after 0.09 s). For the estimate printed before a solve.
EXPECTED_ITERATIONS = {"amble": 117, "walk": 90}
ITERATION_COST = {"amble": 4.9, "walk": 2.7}


def _announce(problem: MultiphaseProblem, x: np.ndarray, gait: str) -> None:
    """Print the estimated CPU time of a cold solve of `problem` (the `gait`'s) from x: `EXPECTED_ITERATIONS` iterations
    of `ITERATION_COST` evaluations each, one evaluation timed here."""
    iterations, cost = EXPECTED_ITERATIONS[gait], ITERATION_COST[gait]
    start = time.process_time()
    nlp = problem.nlp("exact")
    nlp.constraints(x), nlp.jacobian(x)
    assert nlp.hessian is not None  # derivatives="exact"
    nlp.hessian(x, 1.0, np.ones(problem.m))
    seconds = time.process_time() - start
    print(f"  estimate: about {iterations} IPOPT iterations of ~{cost * seconds:.2f} s of CPU each, "
          f"~{iterations * cost * seconds:.0f} s in all (one evaluation of the functions and derivatives took {seconds:.2f} s)",
          flush=True)


class _StageProgress:
    """progress(iteration, objective, violation) printing one labelled line per IPOPT run (a stage of the solve: its
    iterations, objective, largest violation and the CPU seconds since the solve began), updated in place on a terminal;
    written to a file or a pipe, also a flushed line every `BLOCK` iterations, so that a log shows a long stage
    moving. `close` ends the last stage's line."""

    #: Iterations between the lines a redirected log gets within a stage.
    BLOCK = 10

    def __init__(self, labels: Sequence[str]) -> None:
        self.labels, self.stage, self.running, self.last = list(labels), -1, False, (0, 0.0, 0.0)
        self.live = sys.stdout.isatty()
        self.start = time.process_time()

    def __call__(self, iteration: int, objective: float, violation: float) -> None:
        if iteration == 0:  # IPOPT's first iterate: a new run
            self.close()
            self.stage, self.running = self.stage + 1, True
        self.last = (iteration, objective, violation)
        if self.live:
            print("\r" + self.line(), end="", flush=True)
        elif iteration and iteration % self.BLOCK == 0:
            print(self.line(running=True), flush=True)

    def line(self, running: bool = False) -> str:
        label = self.labels[self.stage] if self.stage < len(self.labels) else f"run {self.stage + 1}"
        iteration, objective, violation = self.last
        count = f"at iteration {iteration}" if running else f"{iteration} iterations"
        return (f"  {label}: {count}, objective {objective: .6e}, max violation {violation:.2e}, "
                f"{time.process_time() - self.start:.1f} s of CPU")

    def close(self) -> None:
        if self.running:
            print(("\r" if self.live else "") + self.line(), flush=True)
            self.running = False


def _write_trajectory_csv(path: Path, trajectory: Trajectory, labels: list[str], extra: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every collocation point of an optimised trajectory: t, phase, the `extra` columns, q, v, u, and the
    support label; returns the numeric columns."""
    data = trajectory.stacked()
    columns = {"t": data["t"], "phase": data["phase"].astype(float), **extra}
    for name, values in (("q", data["q"]), ("v", data["v"]), ("u", data["u"])):
        columns.update({f"{name}{i}": values[:, i] for i in range(values.shape[1])})
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(list(columns) + ["support"])
        for row, label in zip(np.stack(list(columns.values()), axis=1), labels):
            writer.writerow([f"{x:.9g}" for x in row] + [label])
    return columns


def _animate_replay(stem: Path, problem: MultiphaseProblem, simulated: Replay, controller: str, gait: str) -> None:
    """stem.html (meshcat) and stem.gif: the replay in simulation (coloured) beside the optimised plan (grey,
    translucent in the HTML, REPLAY_AHEAD[gait] m ahead of it), both seen from the side in a frame that moves with the
    plan's travel (so that the robots stay large in the picture and apart), the controller named in the title."""
    from legkit import viewer

    moving = np.zeros(len(simulated.t))
    if problem.travel_index is not None:
        moving = simulated.planned_q[:, problem.travel_index] - simulated.planned_q[0, problem.travel_index]
    simulated_q, planned_q = simulated.q.copy(), simulated.planned_q.copy()
    simulated_q[:, 0] -= moving
    planned_q[:, 0] -= moving
    speed = moving[-1] / simulated.t[-1] if simulated.t[-1] > 0 else 0.0
    scene = viewer.Scene(view=(75.0, 15.0), title=f"{gait} replayed in simulation under {controller}",
                         caption=f"legkit gait --optimize. Coloured: simulated; grey: the optimised plan, {REPLAY_AHEAD[gait]:g} m ahead; "
                                 f"seen from a frame moving at the plan's {speed:.2f} m/s"
                                 + ("" if simulated.upright else f"; fell at {simulated.fell_at:.2f} s"))
    scene.add_robot(problem.model, planned_q, simulated.t, name="planned", color=(0.55, 0.55, 0.6, 0.35), label="planned",
                    offset=[REPLAY_AHEAD[gait], 0.0, 0.0])
    scene.add_robot(problem.model, simulated_q, simulated.t, name="simulated", label="simulated")
    scene.write_html(stem.with_suffix(".html"))
    scene.write_gif(stem.with_suffix(".gif"), size=(800, 450))


#: [m] how far ahead of the simulated robot the replay's animation shows the plan, by gait (a stride and more apart).
REPLAY_AHEAD = {"the amble": 0.45, "the walk": 0.9}


def _plot_optimized(path: Path, t: np.ndarray, s_h: np.ndarray, reference_t: np.ndarray, reference: np.ndarray, labels: list[str],
                    worst: float, worst_t: float, title: str) -> None:
    """Fig. 3 of [Hardt 2002] for the optimised gait: S_H over one period, the worst case marked."""
    require("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(8, 4))
    starts = [0] + [i for i in range(1, len(labels)) if labels[i] != labels[i - 1]] + [len(labels)]
    for n, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
        axis.axvspan(t[a], t[b - 1], color=f"C{n % 4 + 2}", alpha=0.12, lw=0)
        axis.text(0.5 * (t[a] + t[b - 1]), 1.0, labels[a], transform=axis.get_xaxis_transform(), ha="center", va="bottom", fontsize=7)
    axis.plot(reference_t, reference, color="C1", ls="--", lw=0.9, label="hand-built reference")
    axis.plot(t, s_h, color="C0", marker=".", label="optimised (J_s2)")
    axis.plot([worst_t], [worst], "rv", label=f"worst case {worst:.3g} N m s")
    axis.axhline(0.0, color="k", lw=0.8)
    axis.set_xlabel("t [s]")
    axis.set_ylabel("S_H (eq. 10) [N m s]")
    axis.set_title(title, pad=14, fontsize=9)
    axis.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """`legkit gait`: analyse the quadruped amble and/or the biped walk; writes CSVs and figures to --out."""
    parser = argparse.ArgumentParser(prog="legkit gait", formatter_class=HelpFormatter, description=__doc__.splitlines()[0])
    parser.add_argument("--robot", choices=["quadruped", "biped", "both"], default="both", help="robots to analyse")
    add_output_folder(parser, "gait", "the CSVs, figures and animation")
    parser.add_argument("--cycles", type=_positive_int, default=1, help="gait cycles to analyse")
    parser.add_argument("--samples", type=_positive_int, default=400, help="samples per cycle (>= 8)")
    parser.add_argument("--mu", type=float, default=None,
                        help="friction coefficient: of the friction-cone margin (default 0.8) and of the optimised amble's and walk's "
                             "plans (default 0.6, the tracking MPC's friction pyramid; the replay's ground has 0.8)")
    parser.add_argument("--quadruped-speed", type=float, default=0.67, help="amble speed [m/s] (Fig. 3: 0.67)")
    parser.add_argument("--quadruped-period", type=float, default=1.25, help="amble cycle time [s] (Fig. 3: 1.25)")
    parser.add_argument("--quadruped-tip-speed", type=float, default=2.0, help="swing-leg tip speed limit v_tip_max [m/s] (Fig. 3: 2)")
    parser.add_argument("--biped-speed", type=float, default=1.8, help="walking speed [km/h]")
    parser.add_argument("--biped-step", type=float, default=0.4, help="step length [m]")
    parser.add_argument("--biped-tip-speed", type=float, default=3.0, help="swing-foot speed limit v_tip_max [m/s]")
    parser.add_argument("--optimize", action="store_true", help="optimise the quadruped amble for the worst-case S_H "
                        "(J_s2) on IPOPT, write its CSV/figure and replay it in simulation, and the biped walk for the "
                        "Joule loss (J_e1), writing its CSV and torque-speed figure (--robot picks one or both)")
    parser.add_argument("--intervals", type=_positive_int, default=16,
                        help="--optimize: collocation intervals per amble phase (16: a plan that is a motion of the model)")
    parser.add_argument("--coarse-intervals", type=_non_negative_int, default=0,
                        help="--optimize: solve the amble on this many intervals per phase first, then refine it onto --intervals with its "
                             "worst-case S_H held at a fraction of the coarse optimum's (MultiphaseProblem.refine: faster, short of the "
                             "fine mesh's optimum; default 0: J_s2 solved on --intervals directly)")
    parser.add_argument("--derivatives", choices=("exact", "legkit"), default="exact",
                        help="--optimize: the amble's J_s2 run with the exact Hessian of the Lagrangian (exact) or IPOPT's L-BFGS "
                             "approximation of it (legkit, then the --polish stages); the Jacobian is exact in both")
    parser.add_argument("--biped-intervals", type=_positive_int, default=12,
                        help="--optimize: collocation intervals per biped single-support phase (a quarter, at least 1, per double "
                             "support; 12: a plan that is a motion of the model, 8 drifts 0.15 rad at the joints over an interval)")
    parser.add_argument("--max-iter", type=_positive_int, default=300,
                        help="--optimize: IPOPT iteration limit for the amble (per continuation stage)")
    parser.add_argument("--biped-max-iter", type=_positive_int, default=1000,
                        help="--optimize: IPOPT iteration limit for the biped walk (per stage; J_e1 still falls slowly after 1000)")
    parser.add_argument("--tol", type=bounded_float(0.0, 1.0, open_low=True), default=1e-6, help="--optimize: IPOPT tolerance")
    parser.add_argument("--biped-max-power", type=bounded_float(0.0, np.inf, open_low=True, open_high=True), default=None,
                        help="--optimize: each biped motor's input power limit [W] (Sect. 6; default: none)")
    parser.add_argument("--replay-cycles", type=_positive_int, default=5, help="--optimize: cycles replayed in simulation")
    parser.add_argument("--replay-kp", type=_gain, default=50.0, help="--optimize: joint PD stiffness of the replay [N m/rad]")
    parser.add_argument("--replay-kd", type=_gain, default=1.0, help="--optimize: joint PD damping of the replay [N m s/rad]")
    parser.add_argument("--replay-controller", choices=("mpc", "pd"), default="mpc",
                        help="--optimize: the amble's replay: the contact-constrained model-predictive tracking of legkit.optimize.tracking "
                             "(mpc, the default: faster than real time; it holds plans that are motions of their model with a force floor, "
                             "as the defaults make them), or joint PD + feed-forward (pd, which holds none of them)")
    parser.add_argument("--min-normal-force", type=_gain, default=3.0,
                        help="--optimize: floor on every stance normal force of the amble's plan [N] (0: eq. 5 as published; the tracking "
                             "MPC needs one)")
    parser.add_argument("--torque-margin", type=bounded_float(0.0, 1.0, open_high=True), default=0.0,
                        help="--optimize: fraction of the motors' torque the amble's plan leaves to feedback (0: the full line)")
    parser.add_argument("--max-impulse", type=bounded_float(0.0, np.inf), default=0.0,
                        help="--optimize: bound on the amble's touchdown impulses [N s] (0: feet land at rest; inf: eq. 7 unbounded)")
    parser.add_argument("--no-animation", action="store_true", help="--optimize: do not write the replay's .html and .gif")
    parser.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                        help="--optimize: transcribe half of each gait's cycle, the other half its mirror image (mirror periodicity), "
                             "or (--no-mirror) the whole cycle; default: the amble's half (AMBLE_MIRROR), the walk's whole cycle (WALK_MIRROR)")
    parser.add_argument("--polish", action=argparse.BooleanOptionalAction, default=True,
                        help="--optimize with --derivatives legkit: after the amble's L-BFGS runs (J_s2's ended once it stalls), IPOPT "
                             "with the exact Hessian from their best point, first with the phase durations held, then free")
    parser.add_argument("--polish-max-iter", type=_positive_int, default=1000, help="--optimize: IPOPT iteration limit of the amble's polish")
    args = parser.parse_args(argv)
    if args.samples < 8:
        parser.error("--samples must be at least 8")
    if args.mu is not None and not (np.isfinite(args.mu) and args.mu > 0.0):
        parser.error("--mu must be a positive number")
    for name in ("quadruped_speed", "quadruped_period", "quadruped_tip_speed", "biped_speed", "biped_step", "biped_tip_speed"):
        if not np.isfinite(getattr(args, name)) or getattr(args, name) <= 0.0:
            parser.error(f"--{name.replace('_', '-')} must be a positive number")
    if args.coarse_intervals and args.coarse_intervals >= args.intervals:
        parser.error(f"--coarse-intervals must be fewer than --intervals ({args.intervals})")
    if args.optimize:
        from legkit.optimize.definition import MAX_INTERVALS

        for option in ("intervals", "biped_intervals"):
            if getattr(args, option) > MAX_INTERVALS:
                parser.error(f"--{option.replace('_', '-')} must be at most {MAX_INTERVALS}, got {getattr(args, option)}")
    robots = ["quadruped", "biped"] if args.robot == "both" else [args.robot]
    if args.samples * args.cycles > MAX_SAMPLES:
        parser.error(f"--samples x --cycles must be <= {MAX_SAMPLES:,}, got {args.samples:,} x {args.cycles:,}")
    options = GaitOptions.from_arguments(args)
    for name in robots:
        try:
            reference(name, options)
        except ValueError as error:  # a speed, period or step the legs cannot reach
            given = "--quadruped-speed/--quadruped-period" if name == "quadruped" else "--biped-speed/--biped-step"
            parser.error(f"{given}: {error}")
    if options.optimize:
        for name in robots:
            summary = run_optimized_amble(options) if name == "quadruped" else run_optimized_walk(options)
            width = max(len(k) for k in summary)
            for key, value in summary.items():
                print(f"{key:{width}}  {value:12.5g}")
            print(LEGEND)
            for line in verdict(summary, options.replay_cycles):
                print(line)
            if name == "quadruped":
                print(f"wrote gait_quadruped_optimized.csv/.png{'' if options.no_animation else '/.html/.gif'} to {options.out}")
            else:
                print(f"wrote gait_biped_optimized.csv and gait_biped_torque_speed.png to {options.out}")
        return 0
    with load("tqdm").tqdm(total=5 * len(robots), desc="gait analysis", unit="stage") as progress:
        analyses = [run(name, options, progress) for name in robots]
    print_table(analyses)
    print(f"wrote {', '.join(f'gait_{n}.csv/.png' for n in robots)} to {options.out}")
    return 0


#: The friction coefficient of the analyses and of the walk's plan (the amble's plan: `AMBLE_PLAN_FRICTION`).
FRICTION = 0.8

#: Counts (cycles, samples, intervals, iterations) the command takes: far beyond what a run needs.
_positive_int = bounded_int(1, 1_000_000)
_non_negative_int = bounded_int(0, 1_000_000)
#: Gains and forces: finite and >= 0.
_gain = bounded_float(0.0, np.inf, open_high=True)
