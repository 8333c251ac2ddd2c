"""The gaits of [Hardt 2002, Sect. 4.2 and 6] as `MultiphaseProblem`s, started from the hand-built references of
`legkit.gaits.references`.

The amble: duty factor 0.5, support order LF+LH, LF+RH, RF+RH, RF+LH (Sect. 4.2, read as in
`legkit.gaits.references.quadruped_amble`), a touchdown and a liftoff at every boundary, so every phase has
two feet down and S_H (eq. 10) is defined throughout; the full cycle is transcribed, or with `mirror=True` its
first half, the second being its mirror image (`legkit.optimize.mirror`).

The biped walk (Sect. 6: walking at up to 1.8 km/h, minimising J_e1 under the motors' torque-speed lines): the
flat-footed walk of `legkit.gaits.references.biped_walk`, double support, left stance, double support, right
stance from the left touchdown at t = 0, each sole a `FlatFoot` (eq. 6); the full cycle is transcribed, or with
`mirror=True` its first half (double support, left stance), the second being its mirror image.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

import legkit as lk
from legkit.gaits.analysis import contact_inverse_dynamics
from legkit.gaits.references import AMBLE_HIP_HEIGHT, GaitReference, biped_walk, quadruped_amble
from legkit.optimize.definition import FlatFoot, InputPower, Phase, TorqueSpeedLine
from legkit.optimize.layout import Trajectory
from legkit.optimize.mirror import side_mirror
from legkit.optimize.objectives import MinMaxStability, joule_loss
from legkit.optimize.problem import MultiphaseProblem
from legkit.optimize.solver import Progress, SolveResult, solve
from legkit.robots.biped import SIDES, Biped
from legkit.robots.motors import QUADRUPED_MOTOR, MotorParameters
from legkit.robots.quadruped import DIAGONAL_PAIRS, LEGS, Quadruped

#: IPOPT options for the amble: the monotone barrier update (the adaptive one drove mu to 1e-11 within a few
#: iterations of the J_s2 stage and then crawled along the constraints), and the constraint block of the KKT system
#: always regularised (`perturb_always_cd`): the touchdown rows M(q) (v+ - v-) - J^T Lambda scale with the legs' small
#: inertias, so the constraint Jacobian is nearly rank-deficient (singular values 3e-5 of the largest 93 on the
#: 2-interval amble), which IPOPT otherwise answers with Hessian perturbations of 1e-3 to 1e-1 at every iteration. On
#: the 16-interval mirrored amble from the reference, J_s2 with the exact Hessian then crept to p1 0.014 in 300
#: iterations; with it, it converged in 17 + 169 (p1 0.158). And MUMPS with the AMD ordering and without its scaling
#: (rather than `solve`'s METIS): from the reference at 0.67 and 0.60 m/s, 18 + 93 and 19 + 100 iterations against
#: 17 + 169 and 19 + 188, to optima within 0.3 % of METIS's (p1 0.1577 and 0.1640 against 0.1579 and 0.1644).
AMBLE_IPOPT = {"mu_strategy": "monotone", "perturb_always_cd": "yes", "mumps_pivot_order": 0, "mumps_scaling": 0}

#: `AMBLE_IPOPT` for a warm start from a neighbour's optimum (`MultiphaseProblem.continued`): without its barrier
#: update, so that `legkit.optimize.solver.WARM_START`'s adaptive one applies. The plan at 0.60 to 0.75 m/s, each from
#: the last, from 0.55 m/s (`benches/gait_optimisation.py --sequence`): 53, 45, 91, 49 iterations against 92, 44, 71,
#: 102 with the monotone update.
AMBLE_WARM_IPOPT = {key: value for key, value in AMBLE_IPOPT.items() if key != "mu_strategy"}

#: The amble's KKT systems are factorised first with the last iteration's regularisation
#: (`legkit.optimize.solver.solve(regularised_first=True)`): unregularised, every one of them had the wrong inertia.
#: `legkit gait --optimize`'s 16-interval amble at 0.67 m/s: 113 iterations and 36.6 s of CPU against 117 and 54.8 s
#: (KKT 18.8 against 31.7 s), to the same S_H min 0.1577. The walk, for contrast, took 127 iterations against 107 with it
#: (to J_e1 7.012 against 7.081 J/m) and keeps IPOPT's default.
AMBLE_REGULARISED_FIRST = True

#: Derivatives of the amble's J_s2 run: the exact Hessian of the Lagrangian (with `AMBLE_IPOPT`'s regularisation it
#: converges where L-BFGS stalls and has to be polished: on the 16-interval mirrored amble, L-BFGS then the polish took
#: 412 iterations to p1 0.158, the exact Hessian 186). "legkit": IPOPT's L-BFGS on the exact Jacobian.
AMBLE_DERIVATIVES = "exact"

#: The amble's execution bounds (`amble_problem`), on by default: the torso's yaw within 10 deg (J_s2 alone yawed it by
#: +-56 deg), no foot's load changing by more than 10 % of the body weight per millisecond (J_s2 alone moved 43-68 %
#: of it between feet at a switch instantaneously), and each torque rising from zero to stall in no less than 20 ms.
AMBLE_MAX_YAW = np.radians(10.0)
AMBLE_MAX_LOAD_RATE = 100.0  # [body weights / s]
AMBLE_TORQUE_RISE = 0.02  # [s]

#: The amble is transcribed as a mirrored half cycle by default: with the polish's durations held first it
#: converges 2-6x faster than its whole cycle, to the same worst-case S_H.
AMBLE_MIRROR = True

#: The amble's support pairs in time order from t = 0 ([Hardt 2002, Sect. 4.2]).
AMBLE_SUPPORT = (("lf", "lh"), ("lf", "rh"), ("rf", "rh"), ("rf", "lh"))


def torque_speed_line(motor: MotorParameters) -> TorqueSpeedLine:
    """The motor-gear characteristic line of Sect. 2.3: |u| <= (w_max - |w|) G^2 eta / m."""
    if not isinstance(motor, MotorParameters):
        raise TypeError(f"motor must be a legkit.robots.MotorParameters, got {type(motor).__name__}")
    return TorqueSpeedLine(motor.joint_max_speed, motor.gear_ratio**2 * motor.efficiency / motor.slope)


def stall_torque_bounds(motor: MotorParameters, nu: int, fraction: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper), each (nu,): fraction of the joint torque at stall, the characteristic line at zero speed."""
    line = torque_speed_line(motor)
    stall = fraction * line.max_speed * line.gain
    return np.full(nu, -stall), np.full(nu, stall)


def _check_tilt(max_tilt: float) -> None:
    """max_tilt bounds roll and pitch through sin(max_tilt / 2), which is monotonic up to pi."""
    if not 0.0 < max_tilt <= np.pi:
        raise ValueError(f"max_tilt must be in (0, pi] rad, got {max_tilt}")


def amble_problem(robot: Quadruped, objectives: Sequence, speed: float, period: float, intervals: int,
                  motor: MotorParameters, friction: float = 0.8, duration_range: tuple[float, float] = (0.5, 1.5),
                  max_tilt: float = np.radians(15.0), joint_range: tuple[float, float, float] = (0.35, 1.8, 2.6),
                  max_swing_height: float = 0.06, max_impulse: float = np.inf, mirror: bool = False,
                  min_normal_force: float = 0.0, torque_margin: float = 0.0, max_yaw: float = AMBLE_MAX_YAW,
                  max_load_rate: float = AMBLE_MAX_LOAD_RATE, torque_rise: float = AMBLE_TORQUE_RISE,
                  dense_rates: bool = True) -> MultiphaseProblem:
    """The amble at `speed` [m/s] over a fixed `period` [s]; each phase lasts between duration_range x period / 4.
    The state bounds of Sect. 2.3 keep the torso above the ground and its roll and pitch within about
    max_tilt [rad] (|q_x|, |q_y| <= sin(max_tilt / 2)): unbounded, J_s2 pitches the torso by ~50 deg; and the
    joints within joint_range [rad] = (|hip roll|, |hip pitch|, knee bent its own way by at most this):
    unbounded, J_s2 swung the legs over the torso (swing feet 0.6 m up) and straightened the knees; and the swing
    tips below max_swing_height [m] (with the joint bounds alone they still rose 0.4 m, swinging the legs for
    angular momentum, which no replay could track). mirror: transcribe half the cycle (module docstring).
    min_normal_force [N]: the stance force floor (`MultiphaseProblem`; `legkit.optimize.tracking` needs one).
    torque_margin in [0, 1): the fraction of the motors' torque (bounds and characteristic line) the plan leaves to
    feedback: headroom for `legkit.optimize.tracking`'s corrections where a plan rides the stall torque (the MPC held
    some plans only with one and others only without).
    For a plan a robot can execute (`legkit.optimize.checks`): the torso's yaw within max_yaw [rad]
    (`MultiphaseProblem.max_yaw`); every foot's load changing by at most max_load_rate body weights per second, support
    switches included (`max_force_rate`); each torque by at most its stall torque per torque_rise [s]
    (`max_torque_rate`; 0 for none); the joint rates within the motors' no-load speed between the points too
    (`dense_rates`: at the points alone, the 4-interval amble's rates reached 1.14 x that speed between them). np.inf
    switches a bound off, dense_rates=False the rates between points."""
    if not 0.0 <= torque_margin < 1.0:
        raise ValueError(f"torque_margin must be in [0, 1), got {torque_margin}")
    if not 0.0 < period < np.inf:
        raise ValueError(f"period must be finite and > 0, got {period}")
    if not 0.0 < duration_range[0] <= duration_range[1] < np.inf:
        raise ValueError(f"duration_range must satisfy 0 < lower <= upper (finite), got {duration_range}")
    _check_tilt(max_tilt)
    if len(joint_range) != 3 or not all(0.0 <= bound < np.inf for bound in joint_range):
        raise ValueError(f"joint_range must be three finite bounds >= 0 (hip roll, hip pitch, knee), got {joint_range}")
    quarter = period / 4.0
    support = AMBLE_SUPPORT[:2] if mirror else AMBLE_SUPPORT
    phases = [Phase(pair, intervals, (duration_range[0] * quarter, duration_range[1] * quarter)) for pair in support]
    full = torque_speed_line(motor)
    line = TorqueSpeedLine(full.max_speed, full.gain * (1.0 - torque_margin))
    nu = robot.model.nv - 6
    upper = np.full(robot.model.nq, np.inf)
    upper[3:5] = np.sin(0.5 * max_tilt)
    lower = -upper
    lower[2] = 0.02
    roll, pitch, knee = joint_range
    for leg_index, leg in enumerate(LEGS):  # joints ordered leg by leg: hip roll, hip pitch, knee
        joints = 7 + 3 * leg_index
        bend = robot.parameters.knee_direction[leg]
        lower[joints : joints + 3] = [-roll, -pitch, min(0.0, bend * knee)]
        upper[joints : joints + 3] = [roll, pitch, max(0.0, bend * knee)]
    if not (max_yaw > 0.0 and max_load_rate > 0.0 and torque_rise >= 0.0):
        raise ValueError(f"max_yaw and max_load_rate must be > 0 and torque_rise >= 0, got {max_yaw}, {max_load_rate}, {torque_rise}")
    bounds = stall_torque_bounds(motor, nu, 1.0 - torque_margin)
    weight = robot.model.total_mass * float(np.linalg.norm(robot.model.gravity))
    return MultiphaseProblem(robot.model, phases, {leg: robot.feet[leg] for leg in LEGS}, objectives, speed=speed, period=period,
                             friction=friction, u_bounds=bounds, torque_speed=line,
                             q_bounds=(lower, upper), max_swing_height=max_swing_height, max_impulse=max_impulse,
                             min_normal_force=min_normal_force, max_force_rate=max_load_rate * weight, max_yaw=max_yaw,
                             dense_rates=dense_rates,
                             max_torque_rate=float(bounds[1][0]) / torque_rise if torque_rise > 0.0 else np.inf,
                             mirror=side_mirror(robot.model, {"lf": "rf", "lh": "rh"}) if mirror else None)


#: The plan's friction coefficient: the tracking MPC's friction pyramid (`legkit.optimize.tracking`), within which it
#: holds the plan.
AMBLE_PLAN_FRICTION = 0.6


@dataclass(frozen=True)
class AmbleOptions:
    """The options of the amble's plan (`amble_plan_problem`), as `legkit gait --optimize` takes them: swing tips up to
    tip_speed [m/s] (J_s2's `MinMaxStability`), mu = friction, every touchdown impulse component within max_impulse
    [N s] (0: soft touchdowns), a stance-force floor of min_normal_force [N], the fraction torque_margin of the motors'
    torque left to feedback, and a mirrored half cycle (mirror, `AMBLE_MIRROR`) or the whole."""

    tip_speed: float = 2.0
    friction: float = AMBLE_PLAN_FRICTION
    max_impulse: float = 0.0
    mirror: bool = AMBLE_MIRROR
    min_normal_force: float = 3.0
    torque_margin: float = 0.0


def amble_plan_problem(robot: Quadruped, intervals: int = 16, speed: float = 0.67, period: float = 1.25,
                       options: AmbleOptions = AmbleOptions(), **execution: Any) -> MultiphaseProblem:
    """The problem `plan_amble` solves on `intervals` per phase: `amble_problem` maximising the worst-case S_H (J_s2, eq. 11)
    with `QUADRUPED_MOTOR` and the defaults a tracking controller needs (`AmbleOptions`: soft touchdowns, a stance-force
    floor, mu 0.6), and the execution bounds (`execution`: `amble_problem`'s max_yaw, max_load_rate, torque_rise and
    dense_rates, to change one; each costs some S_H, docs/optimize.md)."""
    return amble_problem(robot, [MinMaxStability(options.tip_speed, DIAGONAL_PAIRS)], speed, period, intervals, QUADRUPED_MOTOR,
                         options.friction, max_impulse=options.max_impulse, mirror=options.mirror,
                         min_normal_force=options.min_normal_force, torque_margin=options.torque_margin, **execution)


@dataclass
class AmblePlan:
    """`plan_amble`'s outcome: the problem on the fine mesh (a mirrored half cycle unless mirror=False:
    `problem.full_cycle()` and `problem.unroll` give the whole cycle), its solve (covering the coarse one), and the start:
    the hand-built reference on the problem's mesh."""

    problem: MultiphaseProblem
    result: SolveResult
    reference: Trajectory


def plan_amble(robot: Quadruped, speed: float = 0.67, period: float = 1.25, intervals: int = 16, coarse_intervals: int = 0, *,
               derivatives: str = AMBLE_DERIVATIVES, polish: bool = True, polish_max_iter: int = 1000, tol: float = 1e-6,
               max_iter: int = 300, progress: Progress | None = None, options: AmbleOptions = AmbleOptions(),
               problem: MultiphaseProblem | None = None) -> AmblePlan:
    """The amble a tracking controller holds, as `legkit gait --optimize` plans it: `amble_plan_problem` with `options`
    (problem: that problem when the caller has built it already) solved from the hand-built reference, feasibility
    first, then J_s2 with `derivatives` (default: the exact Hessian, `AMBLE_DERIVATIVES`; "legkit": L-BFGS, then with
    polish the exact-Hessian polish within polish_max_iter iterations). By default on `intervals` per phase directly;
    with coarse_intervals (fewer than intervals) on that mesh first, the optimum then refined onto `intervals`
    (`MultiphaseProblem.refine`: its worst-case S_H held at a fraction of the coarse optimum's, which is faster than J_s2
    on the fine mesh but does not reach its optimum). tol and max_iter (per stage) go to every IPOPT run,
    progress(iteration, objective, violation) is called at every iteration of every run."""
    if coarse_intervals and coarse_intervals >= intervals:
        raise ValueError(f"coarse_intervals must be 0 or fewer than intervals ({intervals}), got {coarse_intervals}")
    if problem is None:
        problem = amble_plan_problem(robot, intervals, speed, period, options)
    reference = guess_from_reference(problem, amble_reference(robot, speed, period, intervals))
    run_options: dict[str, Any] = {"tol": tol, "max_iter": max_iter, "progress": progress, "options": AMBLE_IPOPT,
                                   "regularised_first": AMBLE_REGULARISED_FIRST}
    solve_options = {"derivatives": derivatives, "feasibility_first": True, "polish": polish and derivatives == "legkit",
                     "polish_max_iter": polish_max_iter, **run_options}
    if not coarse_intervals:
        _, result = problem.solve(reference, **solve_options)
        return AmblePlan(problem, result, reference)
    coarse = amble_plan_problem(robot, coarse_intervals, speed, period, options)
    _, result = coarse.solve(guess_from_reference(coarse, amble_reference(robot, speed, period, coarse_intervals)), **solve_options)
    _, result = problem.refine(coarse, result, **run_options)
    return AmblePlan(problem, result, reference)


def amble_reference(robot: Quadruped, speed: float, period: float, intervals: int) -> GaitReference:
    """`quadruped_amble` sampled on the collocation points of equal phases (two cycles, so the last point of
    the cycle continues the travel coordinate)."""
    return quadruped_amble(robot, speed, period, 8 * intervals, 2, 0.03, AMBLE_HIP_HEIGHT)


#: The biped walk's supports in time order from the left touchdown at t = 0 (`biped_walk`'s contact sequence).
WALK_SUPPORT = (("l", "r"), ("l",), ("l", "r"), ("r",))

#: mu_d of eq. 6 [m] for the biped's soles; the paper gives no value (`walk_problem`).
SOLE_TORSION = 0.04

#: IPOPT options for the walk: the monotone barrier update (exact Hessian, from the same feasible point: adaptive
#: reached J_e1 13.6 J/m in 300 iterations, monotone 8.7 J/m in 190) and, as for the amble (`AMBLE_IPOPT`), the KKT
#: system's constraint block always regularised.
WALK_IPOPT = {"mu_strategy": "monotone", "perturb_always_cd": "yes"}

#: Derivatives for the walk's J_e1 stage: the exact Hessian (with `WALK_IPOPT`, the walk on (2, 8)
#: intervals, converged to 7.01 J/m in 17 + 94 iterations; L-BFGS on the exact Jacobian took 700 to 7.11 J/m).
WALK_DERIVATIVES = "exact"

#: The walk is transcribed over its whole cycle by default: its mirrored half (28 s instead of 40 s) holds the
#: torso's roll at its bound on the quaternion's x, and the mirror image, scaled to the quaternion norm the
#: collocation drifted to over the half (1.0017), exceeds that bound by 1.5e-4 in the whole cycle.
WALK_MIRROR = False

#: The walk's pelvis heading within 10 deg (J_e1 alone turned it by 85 deg: the robot walked sideways).
WALK_MAX_YAW = np.radians(10.0)


#: The walk's plan uses friction up to 0.6 and 0.8 of eq. 6's sole bounds (`FlatFoot.support`), below the 0.8 of the
#: ground it is replayed on and the whole sole: margins the tracking MPC corrects with. Planned with friction 0.8 and
#: the whole sole, the trailing foot's centre of pressure sat on its toe edge at 0.8 friction in every double support,
#: and the MPC (holding every sole flat) fell within 5 cycles.
WALK_PLAN_FRICTION = 0.6
WALK_SOLE_SUPPORT = 0.8


def walk_problem(robot: Biped, speed: float, motor: MotorParameters, intervals: tuple[int, int] = (2, 8),
                 friction: float = WALK_PLAN_FRICTION, sole_support: float = WALK_SOLE_SUPPORT, max_tilt: float = np.radians(10.0),
                 max_swing_height: float = 0.15,
                 double_support: tuple[float, float] = (0.04, 0.4), single_support: tuple[float, float] = (0.3, 1.0),
                 period: float | tuple[float, float] | None = 1.6, objectives: Sequence | None = None,
                 max_input_power: float | None = None, mirror: bool = False,
                 dense_rates: bool = True, max_yaw: float = WALK_MAX_YAW) -> MultiphaseProblem:
    """The biped walk at `speed` [m/s] minimising J_e1 (eq. 12) with `motor`'s resistance, gear and torque
    constant at every joint (or the given `objectives`), under its torque-speed line (Sect. 2.3) and stall torque; the soles flat on the
    ground in stance with eq. 6's torque limits. intervals: (per double-support phase, per single-support
    phase); the phase durations [s] lie in double_support and single_support and sum to `period` [s] (fixed,
    bounds, or None: free; the default is the reference's, a 0.4 m step). max_input_power [W]: each motor's input
    power bound (`InputPower`, Sect. 6's "maximum input power constraints"; None: unbounded). sole_support: the
    fraction of eq. 6's bounds the plan uses (`FlatFoot.support`). mirror: transcribe
    half the cycle (module docstring). dense_rates: the joint rates within the motors' no-load speed between the
    points too (`MultiphaseProblem.dense_rates`; at the points alone they reached 38-48 rad/s between them, against the
    5.2 rad/s the motors can turn). max_yaw [rad]: the pelvis' heading (`MultiphaseProblem.max_yaw`; np.inf for none).

    Parameters the paper does not give, assumed here: the motor (legkit's `BIPED_MOTOR`: Fig. 6 names 42 V
    motors with 66:1 gears for an 18 kg biped but no motor constants, and legkit's biped weighs 42 kg); mu_d =
    `SOLE_TORSION` = 0.04 m (about mu times the sole's mean distance from its centre); the pelvis' roll and
    pitch within max_tilt, joint ranges of a human-like leg (hip yaw +-0.3, hip roll +-0.4, hip pitch
    [-1.2, 1.0], knee [0, 2.2], ankle pitch +-1.0, ankle roll +-0.4, shoulder pitch +-1.0, shoulder roll
    [-0.5, 0.5] rad) and swing soles below max_swing_height [m]."""
    _check_tilt(max_tilt)
    p = robot.parameters
    centre = np.array([0.5 * (p.foot_toe - p.foot_heel), 0.0, -p.ankle_height])
    feet = {side: (f"{side}_foot", centre) for side in SIDES}
    sole = FlatFoot(p.foot_toe + p.foot_heel, 2.0 * p.foot_half_width, SOLE_TORSION, sole_support)
    phases = [Phase(support, intervals[0] if len(support) == 2 else intervals[1], double_support if len(support) == 2 else single_support)
              for support in (WALK_SUPPORT[:2] if mirror else WALK_SUPPORT)]
    line = torque_speed_line(motor)
    model = robot.model
    nu = model.nv - 6
    upper = np.full(model.nq, np.inf)
    upper[3:5] = np.sin(0.5 * max_tilt)
    lower = -upper
    lower[2] = 0.3
    leg = ([-0.3, -0.4, -1.2, 0.0, -1.0, -0.4], [0.3, 0.4, 1.0, 2.2, 1.0, 0.4])
    for side in SIDES:
        joints = robot.joint_slice(side)
        lower[joints.start + 1 : joints.stop + 1], upper[joints.start + 1 : joints.stop + 1] = leg
        arm = robot.joint_slice(side, "arm")
        lower[arm.start + 1 : arm.stop + 1], upper[arm.start + 1 : arm.stop + 1] = [-1.0, -0.5], [1.0, 0.5]
    if objectives is None:
        objectives = [joule_loss(motor.resistance, motor.gear_ratio, motor.torque_constant)]
    return MultiphaseProblem(model, phases, feet, objectives, speed=speed, period=period, friction=friction,
                             u_bounds=stall_torque_bounds(motor, nu), torque_speed=line, q_bounds=(lower, upper),
                             max_swing_height=max_swing_height, flat_feet={side: sole for side in SIDES},
                             input_power=None if max_input_power is None else
                             InputPower(max_input_power, motor.resistance, motor.gear_ratio, motor.torque_constant),
                             mirror=side_mirror(model, {"l": "r"}) if mirror else None, dense_rates=dense_rates, max_yaw=max_yaw)


def solve_walk(problem: MultiphaseProblem, guess: Trajectory, derivatives: str = WALK_DERIVATIVES,
               **options: Any) -> tuple[Trajectory, SolveResult]:
    """The walk in two IPOPT runs: the constraints alone with the L-BFGS Hessian (on the coarse walk it met them
    in 9 iterations, against 97 with the exact Hessian), then the objective with `derivatives` from that feasible point,
    both with `WALK_IPOPT` (options' "options" override it). options go to `legkit.optimize.solver.solve` in both runs;
    the result covers both."""
    ipopt = {**WALK_IPOPT, **options.pop("options", {})}
    first = solve(problem.nlp("legkit", objective=False), problem.gauged(problem.pack(guess)), options=ipopt, **options)
    trajectory, result = problem.solve(first.x, derivatives=derivatives, options=ipopt, **options)
    return trajectory, result.after(first)


def walk_reference(robot: Biped, speed: float, intervals: tuple[int, int] = (2, 8), step_length: float = 0.4) -> GaitReference:
    """`biped_walk` (double support 20 % of the cycle, step_length [m]) on the collocation points of
    `walk_problem`'s phases at their reference durations (0.1 and 0.4 of the period), one cycle and the next
    cycle's first point. The walk is sampled finely (a common multiple of both phases' point spacings; its derivatives by periodic
    differences on that grid) and the collocation points picked from it."""
    double, single = intervals
    if double < 1 or single < 1:
        raise ValueError(f"intervals must be two positive counts, got {intervals}")
    samples = 20 * double * single  # per cycle: the double-support points every 2 single, the single every 8 double samples
    fine = biped_walk(robot, speed, step_length, samples, 2, 0.2, 0.05, 0.82, 0.3)
    steps = [samples // (20 * double) if len(support) == 2 else samples // (5 * single) for support in WALK_SUPPORT]
    rows = np.cumsum(np.concatenate([[0]] + [np.full(2 * (double if len(support) == 2 else single), step)
                                             for support, step in zip(WALK_SUPPORT, steps)]))  # one cycle and its end
    return GaitReference(fine.t[rows], fine.q[rows], fine.v[rows], fine.a[rows], fine.contacts, fine.active[rows],
                         [fine.support_label[i] for i in rows], fine.distance, fine.feet, fine.zmp_tracking_error)


def guess_from_reference(problem: MultiphaseProblem, ref: GaitReference) -> Trajectory:
    """An initial guess from a sampled reference whose samples fall on the collocation points: states and
    accelerations as sampled (kinematically consistent, so the defects start small), torques and contact
    forces by `contact_inverse_dynamics` (least squares: the inverse-dynamics residual starts as the
    reference's unbalanced base wrench). The problem's feet are the reference's feet (`ref.feet`) in order; a
    foot's force is the sum over its contact points, and a flat foot's torque their moment about its point."""
    dynamics = contact_inverse_dynamics(problem.model, ref)
    names = list(problem.feet)
    total = np.stack([dynamics.forces[:, group].sum(axis=1) for group in ref.feet], axis=1)  # (T, feet, 3)
    flat = [names.index(n) for n in problem.flat_feet]
    torque = np.zeros((len(ref.t), len(names), 3))
    if flat:
        poses = np.asarray(lk.forward_kinematics(problem.model, ref.q))
        centres = problem.foot_positions(ref.q, names)
        for j in flat:
            group = ref.feet[j]
            world = np.sum(np.cross(dynamics.points[:, group] - centres[:, j, None], dynamics.forces[:, group]), axis=1)
            torque[:, j] = np.einsum("tji,tj->ti", poses[:, problem.foot_body[names[j]], :3, :3], world)
    t, q, v, u, forces, a, torques = [], [], [], [], [], [], []
    start = 0
    for phase in problem.phases:
        rows = start + np.arange(2 * phase.intervals + 1)
        t.append(ref.t[rows])
        q.append(ref.q[rows])
        v.append(ref.v[rows])
        a.append(ref.a[rows])
        u.append(dynamics.torques[rows])
        forces.append(total[rows][:, [names.index(c) for c in phase.contacts]])
        torques.append(torque[rows][:, [names.index(c) for c in problem.flat_contacts(phase.contacts)]])
        start = rows[-1]
    durations = np.array([t_k[-1] - t_k[0] for t_k in t])
    return Trajectory(t, q, v, u, forces, durations, a=a, torques=torques)
