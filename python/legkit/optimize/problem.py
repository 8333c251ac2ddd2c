"""Multiphase direct collocation of a legged robot's motion with a fixed contact sequence.

The transcription of [Hardt 2002, Sect. 2.3 and 4.1], on legkit's kernels:

* phases with fixed contact sets (the discrete state d(t) of Sect. 4.1), each with its duration as a variable;
* per phase a grid of `intervals` Hermite–Simpson intervals (eq. 14: cubic states, linear controls); at every
  knot and midpoint the variables z = [q, v, u, lambda, slack]: configuration, velocity, actuated torques,
  the world-frame contact forces of the phase's feet and the stance feet's slack (below);
* dynamics (eq. 1) in inverse-dynamics form: the accelerations a are variables too (z = [q, v, u, lambda, a,
  slack]), the state rate is [dq/dt(q, v), a], and at every point the RNEA residual rnea(q, v, a, J_c^T lambda)
  - B u = 0 (legkit's batched RNEA with the forces as external wrenches) closes the dynamics (Ferrolho et al.,
  ICRA 2021, found this form converging in fewer iterations than collocating the forward dynamics; its
  Jacobian is also sparser: a joint's torque depends on its own leg and the base only). The stance feet are
  held in DIRCON's form (Posa, Kuindersma & Tedrake 2016): at every knot on the ground, at rest and not
  accelerating (`stance_blocks`), the midpoints freed from the contact manifold by a slack in the
  configuration rate (`rate`). Held at position level at every point instead, the forces were free to
  alternate between knots and midpoints (`stance_accelerations`);
* swing-tip height >= 0 (eq. 4) at the points and at fractions of every interval between them
  (`swing_clearance_blocks`), friction cone mu^2 F_z^2 - F_x^2 - F_y^2 >= 0 with F_z >= 0 (eq. 5, squared
  to stay smooth), for flat feet (`FlatFoot`) a contact torque T about the sole's centre within the foot-torque
  limits of eq. 6 and the whole sole held flat on the ground, the inelastic impact map at each touchdown (eq. 7, `lk.impact` with the new
  phase's feet),
  state/control bounds and the motor torque-speed line |u| <= (w_max - |w|) k (Sect. 2.3, split into its four
  linear faces); optionally each motor's input power within a limit (`InputPower`, Sect. 6);
* periodicity (Sect. 2.3: q(t_f) = q(0) up to the travelled distance, velocity after the wrap-around impact),
  or mirror periodicity over half a cycle for symmetric gaits (`mirror`: the phases are the first half, and
  the second half, the first's mirror image, begins where it ends: q(t_f) = mirror(q(0)) up to the travelled
  distance; `full_cycle` unrolls a solution), or fixed initial/final states.

The constraint Jacobian is exact, from the core's analytic derivatives (`lk.rnea_derivatives`, `lk.crba`, frame
Jacobians and their velocity and acceleration derivatives) in the variables' raw coordinates (`kinematics`);
its pattern, from the model's tree, is fixed before solving. Objectives: `objectives.py`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, cast

import numpy as np

import legkit as lk
from legkit._validation import float_array, instance
from legkit.optimize import kinematics as kin
from legkit.optimize.blocks import Block, Linear, Point, equal, group_hessian, group_pattern, weighted
from legkit.optimize.collocation import hermite_basis, hermite_simpson_defects
from legkit.optimize.mirror import Mirror
from legkit.optimize.objectives import MinMaxStability, build_objective, published_stability
from legkit.optimize.solver import NLP, SolveResult, solve

#: `MultiphaseProblem.nlp`'s second derivatives: IPOPT's L-BFGS approximation, or the Hessian of the Lagrangian from
#: legkit's kernels (`MultiphaseProblem.hessian`); the Jacobian is exact in both.
DERIVATIVES = ("legkit", "exact")


#: IPOPT's initial barrier parameter for `MultiphaseProblem.solve(polish=True)`. From the amble's point after
#: 600 L-BFGS J_s2 iterations the exact Hessian converged in 56 iterations with it; from the constraint
#: stage's point, in 326.
POLISH_MU_INIT = 1e-6


#: `MultiphaseProblem.solve(polish=True)` ends the L-BFGS run on the objective once its best point has improved
#: by less than this (second) over this many (first) iterations, and polishes from there: L-BFGS on the amble's
#: J_s2 either climbs quickly and then slowly, or crawls (p1 +1.5e-7 per iteration).
POLISH_SWITCH = (20, 5e-3)

#: `MultiphaseProblem.refine` holds J_s2's p1 at this fraction of the coarse optimum's. The 0.67 m/s amble (3 N
#: floor, mu 0.6) from 4 onto 16 intervals per phase: 0.1, 0.2, 0.3 converged in 55, 40, 54 iterations (S_H min
#: 0.042, 0.044, 0.063); 0.5 and 0.8 did not in 300.
REFINE_STABILITY = 0.2
#: The most intervals one phase takes: a 16-interval phase already costs IPOPT minutes (docs/optimize.md), and the
#: transcription's arrays grow with the points, so a larger count is a mistake, not a request.
MAX_INTERVALS = 1000
#: The largest stance force floor, in the robot's weights: feet in stance carry the weight on average over a cycle, a
#: few times it in a run's short stance; beyond this the floor is a typing error (and large enough ones overflow).
MAX_FORCE_FLOOR = 100.0


@dataclass(frozen=True)
class Phase:
    """One contact phase: the feet on the ground, the grid's interval count, and bounds on its duration [s]."""

    contacts: tuple[str, ...] = ()
    intervals: int = 6
    duration: tuple[float, float] = (0.05, 1.0)


@dataclass(frozen=True)
class FlatFoot:
    """A flat sole lying on the ground in stance ([Hardt 2002, Sect. 2.3, eq. 6]). The foot's contact point (the
    `feet` entry) is the centre of its sole, the sole's axes are the foot body's x (length l_x) and y (width l_y),
    and besides the force F the ground puts a torque T (foot-body frame, about that point) on it, limited by

        |T_x| <= 0.5 F_z l_y,   |T_y| <= 0.5 F_z l_x,   |T_z| <= mu_d F_z          (eq. 6, as published)

    (the first two: the centre of pressure stays on the sole). mu_d multiplies a force to bound a torque, so
    it is a length [m] although the paper calls it a friction coefficient. In stance the sole is held flat and
    still (six rows: the centre's position, the heights of a toe and a side point, the toe's y), at a
    touchdown the whole foot stops (eq. 7 with six impulse rows), and in swing those sole points stay above
    the ground (eq. 4).

    support (0, 1]: the fraction of each of eq. 6's three bounds the plan may use (1: eq. 6 as published). Below 1 it
    keeps the planned centre of pressure and torsion off the sole's edges, a margin a tracking controller needs: a
    plan pressing a sole's edge leaves it no torque to correct with, and the sole tips about that edge."""

    length: float  # l_x [m]
    width: float  # l_y [m]
    torsion: float  # mu_d [m]
    support: float = 1.0

    def __post_init__(self) -> None:
        for name in ("length", "width"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"FlatFoot.{name} must be > 0, got {getattr(self, name)}")
        if not self.torsion >= 0.0:
            raise ValueError(f"FlatFoot.torsion must be >= 0, got {self.torsion}")
        if not 0.0 < self.support <= 1.0:
            raise ValueError(f"FlatFoot.support must be in (0, 1], got {self.support}")


@dataclass(frozen=True)
class TorqueSpeedLine:
    """|u_i| <= (max_speed_i - |w_i|) gain_i per actuated joint ([Hardt 2002] Sect. 2.3: gain = G^2 eta / m)."""

    max_speed: np.ndarray | float  # [rad/s]
    gain: np.ndarray | float  # [N m s / rad]


@dataclass(frozen=True)
class InputPower:
    """Each actuated joint's motor draws at most ``limit_i`` [W] ([Hardt 2002] Sect. 6: the humanoid's "maximum input
    power constraints"). Its input power is U I = R I^2 + u w with the motor current I = u / (G K) of eq. 12: the
    Joule loss plus the mechanical power, R_i (u_i / (G_i K_i))^2 + u_i w_i <= limit_i at every collocation point.
    A braking joint (u w < 0) may feed power back; the bound is on what the motor draws."""

    limit: np.ndarray | float  # [W]
    resistance: np.ndarray | float  # [ohm]
    gear_ratio: np.ndarray | float
    torque_constant: np.ndarray | float  # [N m / A]


@dataclass
class Trajectory:
    """The variables of a transcription, per phase: times t (P,), q (P, nq), v (P, nv), u (P, nu), forces
    (P, c, 3) on the phase's feet (world frame), the phase durations, the accelerations a (P, nv) (None: `pack`
    takes them from the forward dynamics of q, v, u, forces), and
    the torques (P, c_flat, 3) on the phase's flat feet (`FlatFoot`, foot frame; None: zero), and the slack (P, r) of
    the phase's `contact_rows` (`MultiphaseProblem.rate`; None: zero)."""

    t: list[np.ndarray]
    q: list[np.ndarray]
    v: list[np.ndarray]
    u: list[np.ndarray]
    forces: list[np.ndarray]
    durations: np.ndarray
    stability_bound: float = 0.0  # p1 of the min-max objective J_s2 (0 when unused)
    a: list[np.ndarray] | None = None
    torques: list[np.ndarray] | None = None
    slack: list[np.ndarray] | None = None

    def stacked(self) -> dict[str, np.ndarray]:
        """Every point of every phase in time order (the shared phase-boundary instants appear twice)."""
        return {"t": np.concatenate(self.t), "q": np.concatenate(self.q), "v": np.concatenate(self.v),
                "u": np.concatenate(self.u), "phase": np.concatenate([np.full(len(t), k) for k, t in enumerate(self.t)])}


@dataclass
class MultiphaseProblem:
    """Multiphase Hermite–Simpson transcription of a legged robot's motion (module docstring).

    feet: contact points by name, (body, point in body frame). actuated: v indices driven by u (default: every
    joint, i.e. v[6:] for a free-flyer, all of v otherwise). periodic: q, v wrap around (the travel coordinate
    q[travel_index] advancing by speed x cycle time); otherwise initial/final (q, v) fix the ends (NaN: free).
    mirror (periodic problems; `legkit.optimize.mirror`): the phases are half a cycle, the other half their
    mirror image. period: the cycle time (the whole cycle's, with a mirror), fixed (float) or bounded (lo, hi).
    force_dims: 3 (friction cone) or 1 (normal force only, for models that cannot push sideways). flat_feet:
    `FlatFoot` soles by foot name (eq. 6; needs force_dims 3). q/v/u_bounds: (lower, upper) arrays.
    max_impulse: a bound [N s] on every component of every touchdown impulse (eq. 7, the impulse variables); 0
    makes every touchdown soft, the landing feet arriving at rest and v continuous (a gait whose impacts carry
    the robot's momentum cannot be replayed by joint tracking). min_normal_force [N]: a floor
    on every stance foot's normal force at every point (eq. 5 with a margin: the min-max S_H optimum otherwise
    balances on one foot of two, leaving a tracking controller nothing to push with on the other).
    objectives: terms from `legkit.optimize.objectives`, summed. dense_rates (with a torque_speed line): each actuated
    joint's rate within the line's no-load speed over every interval, on the velocity's Hermite cubic, not only at
    the points (`dense_rate_blocks`: its Bernstein control points bounded). max_yaw [rad]: a free-flyer's yaw (its
    heading about the world's z) within +-max_yaw at every point. max_force_rate [N/s], max_torque_rate [N m/s]:
    bounds on how fast the foot forces and the torques change, across phase boundaries too (a lifting foot unloads,
    a landing foot loads, within the half interval beside the switch): `load_rate_blocks`.
    """

    model: lk.Model
    phases: Sequence[Phase]
    feet: Mapping[str, tuple[int | str, Sequence[float] | np.ndarray]] = field(default_factory=dict)
    objectives: Sequence = ()
    actuated: Sequence[int] | None = None
    periodic: bool = True
    speed: float = 0.0
    travel_index: int | None = None
    period: float | tuple[float, float] | None = None
    initial: tuple[np.ndarray, np.ndarray] | None = None
    final: tuple[np.ndarray, np.ndarray] | None = None
    friction: float = 0.8
    force_dims: int = 3
    q_bounds: tuple[np.ndarray, np.ndarray] | None = None
    v_bounds: tuple[np.ndarray, np.ndarray] | None = None
    u_bounds: tuple[np.ndarray, np.ndarray] | None = None
    torque_speed: TorqueSpeedLine | None = None
    input_power: InputPower | None = None
    continuous_controls: bool = False
    max_swing_height: float = np.inf  # [m] swing tips stay between the ground (eq. 4) and this height
    max_impulse: float = np.inf  # [N s] bound on every component of every touchdown impulse (0: feet land at rest)
    min_normal_force: float = 0.0  # [N] floor on every stance normal force
    flat_feet: Mapping[str, FlatFoot] = field(default_factory=dict)
    mirror: Mirror | None = None
    dense_rates: bool = False  # the joint rates within the torque-speed line's no-load speed between the points too
    max_yaw: float = np.inf  # [rad] a free-flyer's yaw at every point (`yaw_blocks`)
    max_force_rate: float = np.inf  # [N/s] on every component of every stance foot's force (`load_rate_blocks`)
    max_torque_rate: float = np.inf  # [N m/s] on every actuated torque (`load_rate_blocks`)

    def __post_init__(self) -> None:
        self._validate()
        model = self.model
        self.nq, self.nv = model.nq, model.nv
        self.nx = self.nq + self.nv
        # The q a point's dynamics, momentum and impact depend on: all but a free-flyer's position, as they
        # (and the feet's positions relative to each other and to the COM) are the same wherever the robot is.
        self.q_without_translation = np.arange(3 if model.floating_base else 0, self.nq)
        assert self.actuated is not None  # _validate makes it a list
        self.nu = len(self.actuated)
        self.foot_names = list(self.feet)
        self.foot_body = {name: (model.names.index(b) if isinstance(b, str) else int(b)) for name, (b, _) in self.feet.items()}
        self.foot_point = {name: np.asarray(p, dtype=np.float64) for name, (_, p) in self.feet.items()}
        # A flat sole's toe and side points (FlatFoot): with the centre they fix the sole's pose in stance.
        self.sole_points: dict[str, str] = {}
        for name, sole in self.flat_feet.items():
            for label, shift in (("toe", [0.5 * sole.length, 0.0, 0.0]), ("side", [0.0, 0.5 * sole.width, 0.0])):
                self.foot_body[f"{name}/{label}"] = self.foot_body[name]
                self.foot_point[f"{name}/{label}"] = self.foot_point[name] + shift
                self.sole_points[f"{name}/{label}"] = name
        # Variable layout: per phase a (P, nz) block of point variables z = [q, v, u, forces, torques, a, slack]
        # (torques on flat feet only, slack: one per `contact_rows` row,
        # used at the midpoints only: `rate`), then the durations, then p1.
        self.point_index: list[np.ndarray] = []
        self.force_columns: list[slice] = []
        self.torque_columns: list[slice] = []
        self.a_columns: list[slice] = []
        self.slack_columns: list[slice] = []
        offset = 0
        for phase in self.phases:
            forces = self.nx + self.nu + self.force_dims * len(phase.contacts)
            torques = forces + 3 * len(self.flat_contacts(phase.contacts))
            accelerations = torques + self.nv
            nz = accelerations + sum(len(axes) for _, _, axes in self.contact_rows(phase.contacts))
            self.force_columns.append(slice(self.nx + self.nu, forces))
            self.torque_columns.append(slice(forces, torques))
            self.a_columns.append(slice(torques, accelerations))
            self.slack_columns.append(slice(accelerations, nz))
            points = 2 * phase.intervals + 1
            self.point_index.append(offset + np.arange(points * nz).reshape(points, nz))
            offset += points * nz
        self.duration_index = offset + np.arange(len(self.phases))
        self.p1_index = offset + len(self.phases)
        # Then the impulses (world frame, force_dims per foot of the new phase, like the forces) of every
        # touchdown (eq. 7), by boundary.
        offset = self.p1_index + 1
        self.impulse_index: dict[int, np.ndarray] = {}
        count = len(self.phases)
        for k in range(count if self.periodic else count - 1):
            after = self.contacts_after(k)
            if set(after) - set(self.phases[k].contacts):
                size = self.force_dims * len(after) + 3 * len(self.flat_contacts(after))  # `contact_rows`
                self.impulse_index[k] = offset + np.arange(size)
                offset += size
        self.n = offset
        self._build()

    # ------------------------------------------------------------------ validation
    def _validate(self) -> None:
        model = self.model
        if not isinstance(model, lk.Model):
            raise TypeError(f"model must be a legkit.Model, got {type(model).__name__}")
        # `kinematics` maps a free-flyer's quaternion to its tangent space and takes every other joint's q rate as its v.
        spherical = [model.names[i] for i in range(1, model.nbodies) if model.joint_type(i) == "spherical"]
        if spherical:
            raise ValueError(f"model: spherical joints cannot be transcribed (their quaternions have no configuration map "
                             f"here), got {spherical}; model them as three revolute joints")
        if len(self.phases) == 0:
            raise ValueError("phases must hold at least one Phase")
        if self.force_dims not in (1, 3):
            raise ValueError(f"force_dims must be 1 or 3, got {self.force_dims}")
        if not self.max_swing_height > 0.0:
            raise ValueError(f"max_swing_height must be > 0, got {self.max_swing_height}")
        if not self.max_impulse >= 0.0:
            raise ValueError(f"max_impulse must be >= 0, got {self.max_impulse}")
        weight = model.total_mass * float(np.linalg.norm(model.gravity))
        if not 0.0 <= self.min_normal_force <= MAX_FORCE_FLOOR * weight:
            raise ValueError(
                f"min_normal_force must be in [0, {MAX_FORCE_FLOOR:g} x the robot's weight ({weight:.4g} N)], got {self.min_normal_force}"
            )
        for name in ("max_force_rate", "max_torque_rate"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0 (inf: unbounded), got {getattr(self, name)}")
        if not self.max_yaw > 0.0 or (np.isfinite(self.max_yaw) and not self.model.floating_base):
            raise ValueError(f"max_yaw must be > 0 and needs a free-flyer base, got {self.max_yaw}")
        if self.dense_rates and self.torque_speed is None:
            raise ValueError("dense_rates needs a torque_speed line (its no-load speed bounds the rates)")
        if not 0.0 < self.friction < np.inf:
            raise ValueError(f"friction must be finite and > 0, got {self.friction}")
        if not np.isfinite(self.speed):
            raise ValueError(f"speed must be finite, got {self.speed}")
        if self.input_power is not None:
            power = self.input_power
            for name in ("limit", "resistance", "gear_ratio", "torque_constant"):
                values = np.asarray(getattr(power, name), dtype=np.float64)
                if not (np.all(np.isfinite(values)) and np.all(values >= 0.0 if name == "resistance" else values > 0.0)):
                    bound = ">= 0" if name == "resistance" else "> 0"
                    raise ValueError(f"input_power.{name} must be finite and {bound}, got {getattr(power, name)!r}")
        for i, phase in enumerate(self.phases):
            if isinstance(phase.intervals, bool) or not isinstance(phase.intervals, int | np.integer):
                raise TypeError(f"phases[{i}].intervals must be an integer, got {type(phase.intervals).__name__}")
            if not 1 <= phase.intervals <= MAX_INTERVALS:
                raise ValueError(f"phases[{i}].intervals must be in [1, {MAX_INTERVALS}], got {phase.intervals}")
            lo, hi = phase.duration
            if not 0.0 < lo <= hi:
                raise ValueError(f"phases[{i}].duration must satisfy 0 < lower <= upper, got {phase.duration}")
            unknown = [c for c in phase.contacts if c not in self.feet]
            if unknown:
                raise ValueError(f"phases[{i}].contacts names unknown feet {unknown}; feet are {list(self.feet)}")
            if len(set(phase.contacts)) != len(phase.contacts):
                raise ValueError(f"phases[{i}].contacts repeats a foot: {phase.contacts}")
        for name, (body, _) in self.feet.items():
            if isinstance(body, str) and body not in model.names:
                raise ValueError(f"feet[{name!r}] names body {body!r}, which the model does not have")
        unknown = [name for name in self.flat_feet if name not in self.feet]
        if unknown:
            raise ValueError(f"flat_feet names unknown feet {unknown}; feet are {list(self.feet)}")
        if self.flat_feet and self.force_dims != 3:
            raise ValueError(f"flat_feet need force_dims 3 (eq. 6 bounds a torque by the friction of F), got {self.force_dims}")
        if any(not isinstance(sole, FlatFoot) for sole in self.flat_feet.values()):
            raise TypeError("flat_feet must map foot names to FlatFoot")
        self.actuated = list(range(6 if model.floating_base else 0, model.nv)) if self.actuated is None else [int(i) for i in self.actuated]
        if any(not 0 <= i < model.nv for i in self.actuated) or len(set(self.actuated)) != len(self.actuated):
            raise ValueError(f"actuated must list distinct v indices in [0, {model.nv}), got {self.actuated}")
        for name, size in (("q_bounds", model.nq), ("v_bounds", model.nv), ("u_bounds", len(self.actuated))):
            self._validate_bounds(name, size)
        if self.travel_index is None and model.floating_base:
            self.travel_index = 0
        if self.mirror is not None:
            self._validate_mirror()
        sequence = [frozenset(p.contacts) for p in self.cycle_phases()]
        pairs = [(i, i - 1) for i in range(1, len(sequence))]
        if self.periodic and len(sequence) > 1:
            pairs.append((0, len(sequence) - 1))  # the cycle wraps around
        for i, j in pairs:
            if sequence[i] == sequence[j]:
                raise ValueError(f"phases[{i}] has the same contacts as phases[{j}]: an inconsistent contact sequence "
                                 "(a phase boundary must change the contacts; merge the two phases)")
        if self.speed != 0.0:
            if not self.periodic or self.travel_index is None:
                raise ValueError("speed needs a periodic problem with a travel_index (a free-flyer's x by default)")
            self._check_reach()
        if self.period is not None:
            lo, hi = _period_bounds(self.period)
            if not 0.0 < lo <= hi:
                raise ValueError(f"period must be > 0 (or bounds 0 < lower <= upper), got {self.period}")
            cycle = self.cycle_phases()
            if sum(p.duration[1] for p in cycle) < lo or sum(p.duration[0] for p in cycle) > hi:
                raise ValueError(f"period {self.period} cannot be met by the phases' duration bounds "
                                 f"(their sums over the cycle lie in [{sum(p.duration[0] for p in cycle)}, {sum(p.duration[1] for p in cycle)}])")
        if not self.periodic and (self.initial is None and self.final is None):
            raise ValueError("a non-periodic problem needs initial and/or final states")

    def _validate_bounds(self, name: str, size: int) -> None:
        """(lower, upper) of `size` values each, lower <= upper, none NaN."""
        bounds = getattr(self, name)
        if bounds is None:
            return
        try:
            lower, upper = (np.asarray(side, dtype=np.float64) for side in bounds)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{name} must be (lower, upper) arrays of {size} numbers: {error}") from None
        if lower.shape != (size,) or upper.shape != (size,):
            raise ValueError(f"{name} must be (lower, upper) arrays of shape ({size},), got {lower.shape} and {upper.shape}")
        if not np.all(lower <= upper):  # False on NaN too
            bad = int(np.flatnonzero(~(lower <= upper))[0])
            raise ValueError(f"{name}: lower[{bad}] = {lower[bad]} must be <= upper[{bad}] = {upper[bad]} (and not NaN)")

    def _validate_mirror(self) -> None:
        mirror = self.mirror
        if not isinstance(mirror, Mirror):
            raise TypeError(f"mirror must be a legkit.optimize.mirror.Mirror, got {type(mirror).__name__}")
        if not self.periodic:
            raise ValueError("mirror needs a periodic problem (it links the half cycle's end to its mirrored start)")
        if mirror.q_order.shape != (self.model.nq,) or mirror.v_order.shape != (self.model.nv,):
            raise ValueError(f"mirror is for a model with nq = {len(mirror.q_order)}, nv = {len(mirror.v_order)}; "
                             f"this one has {self.model.nq}, {self.model.nv}")
        unpaired = [name for name in self.feet if mirror.feet.get(name) not in self.feet]
        if unpaired:
            raise ValueError(f"mirror.feet must pair every foot with a foot; {unpaired} are not")
        assert self.actuated is not None  # _validate made it a list
        if {int(mirror.v_order[i]) for i in self.actuated} != set(self.actuated):
            raise ValueError("actuated: the mirror of an actuated joint must be actuated")
        travel = self.travel_index
        if travel is not None and (mirror.q_order[travel] != travel or mirror.q_sign[travel] != 1.0):
            raise ValueError(f"mirror must keep the travel coordinate q[{travel}] (a sagittal mirror keeps x)")

    def cycle_phases(self) -> list[Phase]:
        """The phases of a whole cycle: the problem's, then with a mirror their mirror images."""
        if self.mirror is None:
            return list(self.phases)
        return list(self.phases) + [Phase(self.mirror.contacts(p.contacts), p.intervals, p.duration) for p in self.phases]

    def contacts_after(self, k: int) -> tuple[str, ...]:
        """The feet down after the boundary that ends phase k, named as phase k sees them: at the wrap-around
        of a mirrored half cycle, the mirror of the first phase's."""
        after = (k + 1) % len(self.phases)
        if after == 0 and self.mirror is not None:
            return self.mirror.contacts(self.phases[0].contacts)
        return tuple(self.phases[after].contacts)

    def contacts_before(self, k: int) -> tuple[str, ...]:
        """The feet down before the boundary that starts phase k, named as phase k sees them."""
        if k == 0 and self.mirror is not None:
            return self.mirror.contacts(self.phases[-1].contacts)
        return tuple(self.phases[k - 1].contacts)

    def _check_reach(self) -> None:
        """A foot on the ground for a time T lets its hip travel speed x T under it; more than the leg's
        diameter of reach (twice the length of the chain from the base to the foot) is unreachable."""
        model = self.model
        for name, (body, point) in self.feet.items():
            cycle = self.cycle_phases()
            down = [name in p.contacts for p in cycle]
            if all(down):
                raise ValueError(f"speed {self.speed} m/s is unreachable: foot {name!r} never leaves the ground in phases, "
                                 "so it cannot move with the body (an inconsistent contact sequence for a moving gait)")
            index = model.names.index(body) if isinstance(body, str) else int(body)
            reach = float(np.linalg.norm(point))
            while index > 0:
                reach += float(np.linalg.norm(np.asarray(model.placement(index))[:3, 3]))
                index = model.parents[index]
            # The shortest contiguous stance of this foot, the phase list read cyclically from a swing phase.
            first_swing = down.index(False)
            runs: list[float] = []
            run = 0.0
            for k in range(first_swing, first_swing + len(down) + 1):
                phase = cycle[k % len(down)]
                if name in phase.contacts:
                    run += phase.duration[0]
                elif run > 0.0:
                    runs, run = runs + [run], 0.0
            if runs and abs(self.speed) * min(runs) > 2.0 * reach:
                raise ValueError(f"speed {self.speed} m/s is unreachable: foot {name!r} stays down at least {min(runs):.3g} s, "
                                 f"while its hip moves {abs(self.speed) * min(runs):.3g} m, beyond the leg's reach of 2 x {reach:.3g} m")

    # ------------------------------------------------------------------ kernels
    def configuration(self, q: np.ndarray) -> np.ndarray:
        """q (B, nq) with a unit base quaternion: the kernels see a valid configuration whatever the iterate's norm."""
        return kin.unit(self.model, q)

    def q_rate(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """dq/dt (B, nq): base position rate R v_lin, quaternion rate, joint rates (`kinematics.q_rate`)."""
        return kin.q_rate(self.model, q, v)

    def foot_positions(self, q: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """World positions (..., len(names), 3) of the named feet."""
        poses = np.asarray(lk.forward_kinematics(self.model, self.configuration(q)))
        return np.stack([np.einsum("...ij,j->...i", poses[..., self.foot_body[n], :3, :3], self.foot_point[n])
                         + poses[..., self.foot_body[n], :3, 3] for n in names], axis=-2)

    def world_forces(self, forces: np.ndarray, count: int) -> np.ndarray:
        """(B, count, 3) world forces from the (B, count * force_dims) force variables."""
        forces = forces.reshape(forces.shape[0], count, self.force_dims)
        if self.force_dims == 3:
            return forces
        return np.concatenate([np.zeros(forces.shape[:-1] + (2,)), forces], axis=-1)

    def flat_contacts(self, contacts: Sequence[str]) -> list[str]:
        """The flat feet (`FlatFoot`) among contacts, in their order: the owners of the torque variables."""
        return [name for name in contacts if name in self.flat_feet]

    def external_wrenches(self, q: np.ndarray, forces: np.ndarray, contacts: Sequence[str],
                          torques: np.ndarray | None = None) -> np.ndarray | None:
        """Body-frame wrenches (B, nbodies, 6) of the world-frame foot forces (B, len(contacts) * force_dims) and
        the flat feet's foot-frame torques (B, 3 x their count) at configurations q (B, nq, unit quaternion), as
        legkit's rnea/aba take them (None without contacts)."""
        # One row of feet, broadcast over the batch.
        return self.point_wrenches(q, forces, *self.contact_points([contacts]), torques)

    def contact_points(self, contacts: Sequence[Sequence[str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per row of a batch, its feet on the ground (`contacts`, one sequence per row, all of one length and
        with as many flat feet): their bodies (B, count), points (B, count, 3) and the flat feet's bodies
        (B, flat count), as `point_wrenches` takes them."""
        rows = len(contacts)
        bodies = np.array([[self.foot_body[name] for name in row] for row in contacts], dtype=np.int64).reshape(rows, -1)
        points = np.array([[self.foot_point[name] for name in row] for row in contacts]).reshape(rows, -1, 3)
        flat = np.array([[self.foot_body[name] for name in self.flat_contacts(row)] for row in contacts], dtype=np.int64)
        return bodies, points, flat.reshape(rows, -1)

    def point_wrenches(self, q: np.ndarray, forces: np.ndarray, bodies: np.ndarray, points: np.ndarray, flat: np.ndarray,
                       torques: np.ndarray | None = None) -> np.ndarray | None:
        """`external_wrenches` with each row's feet as `contact_points` gives them (rows may differ in which
        feet are down; one row of feet broadcasts over q's)."""
        count = bodies.shape[1]
        if count == 0:
            return None
        poses = np.asarray(lk.forward_kinematics(self.model, q))
        world = self.world_forces(forces, count)
        f_ext = np.zeros((len(q), self.model.nbodies, 6))
        rows = np.arange(len(q))
        for c in range(count):  # a few feet; each line is batched over all points
            body = bodies[:, c]
            local = np.einsum("bji,bj->bi", poses[rows, body, :3, :3], world[:, c])
            f_ext[rows, body, :3] += local
            f_ext[rows, body, 3:] += np.cross(points[:, c], local)
        for c in range(flat.shape[1]):
            assert torques is not None, "flat feet on the ground need their torques"
            f_ext[rows, flat[:, c], 3:] += torques[:, 3 * c : 3 * c + 3]
        return f_ext

    def tau(self, u: np.ndarray) -> np.ndarray:
        """Generalised forces B u (B, nv) of the actuated torques u (B, nu)."""
        tau = np.zeros((len(u), self.nv))
        tau[:, self.actuated] = u
        return tau

    def forward_accelerations(self, z: np.ndarray, k: int) -> np.ndarray:
        """a = aba(q, v, B u, J_c^T lambda) (B, nv) at phase k's point variables z (B, nz, a and slack unused): eq. 1
        forward, for a guess that has no accelerations (`pack`)."""
        q, v = self.configuration(z[:, : self.nq]), z[:, self.nq : self.nx]
        contacts = self.phases[k].contacts
        f_ext = self.external_wrenches(q, z[:, self.force_columns[k]], contacts, z[:, self.torque_columns[k]])
        return np.asarray(lk.aba(self.model, q, v, self.tau(z[:, self.nx : self.nx + self.nu]), f_ext))

    def rate(self, z: np.ndarray, k: int) -> np.ndarray:
        """The collocated state rate (B, nx) at phase k's point variables: [dq/dt, a], a the accelerations (variables,
        whose dynamics are the RNEA residual rows). dq/dt is that of v + J_c^T slack, J_c the phase's `contact_rows`:
        the slack (zero at the knots, free at the midpoints) lets the stance feet be held at position, velocity and
        acceleration level at every knot without over-determining the collocation (Posa, Kuindersma & Tedrake 2016,
        DIRCON)."""
        q, v = z[:, : self.nq], z[:, self.nq : self.nx]
        slack = z[:, self.slack_columns[k]]
        if slack.shape[1]:
            v = v + np.einsum("bri,br->bi", self.contact_jacobian(q, self.phases[k].contacts), slack)
        return np.concatenate([self.q_rate(q, v), z[:, self.a_columns[k]]], axis=1)

    def rate_jacobian(self, z: np.ndarray, k: int) -> np.ndarray:
        """d `rate` / dz (B, nx, nz): the q rate's slopes in closed form (`kinematics.q_rate_derivatives`), the
        slack's J_c(q)^T slack by `kinematics.force_slope` (the slack acts like a force at the contact points)."""
        nq, nx, model = self.nq, self.nx, self.model
        q, v, slack = z[:, :nq], z[:, nq:nx], z[:, self.slack_columns[k]]
        jac = np.zeros((len(z), nx, z.shape[1]))
        jac[:, nq:, self.a_columns[k]] = np.eye(self.nv)
        if not slack.shape[1]:
            by_q, jac[:, :nq, nq:nx] = kin.q_rate_derivatives(model, q, v)
            jac[:, :nq, :nq] = by_q
            return jac
        contacts, unit = self.phases[k].contacts, self.configuration(q)
        points, full, contact = self.contact_frames(unit, contacts)
        forces = self.row_forces(slack, contacts)
        by_q, by_w = kin.q_rate_derivatives(model, q, v + np.einsum("bri,br->bi", contact, slack))
        jac[:, :nq, :nq] = by_q + by_w @ kin.raw(model, q, kin.force_slope(model, unit, points, forces, full))
        jac[:, :nq, nq:nx] = by_w
        jac[:, :nq, self.slack_columns[k]] = by_w @ np.swapaxes(contact, 1, 2)
        return jac

    def rate_gradient(self, z: np.ndarray, weights: np.ndarray, k: int) -> np.ndarray:
        """weights . d `rate` / dz (B, nz) for weights (B, nx): `rate_jacobian`'s vector product, without forming it
        (d(slack . J_c(q) u) / dq by the contact points' velocity derivatives at u)."""
        nq, nx, model = self.nq, self.nx, self.model
        q, v, slack = z[:, :nq], z[:, nq:nx], z[:, self.slack_columns[k]]
        out = np.zeros_like(z)
        out[:, self.a_columns[k]] = weights[:, nq:]
        on_q = weights[:, :nq]
        if not slack.shape[1]:
            by_q, by_w = kin.q_rate_derivatives(model, q, v)
            out[:, :nq] = kin.vecmat(on_q, by_q)
            out[:, nq:nx] = kin.vecmat(on_q, by_w)
            return out
        contacts, unit = self.phases[k].contacts, self.configuration(q)
        points, _, contact = self.contact_frames(unit, contacts)
        by_q, by_w = kin.q_rate_derivatives(model, q, v + np.einsum("bri,br->bi", contact, slack))
        u = kin.vecmat(on_q, by_w)
        forces = self.row_forces(slack, contacts)
        turning = sum(np.einsum("bk,bkj->bj", forces[:, c], kin.point_velocity_derivatives(model, unit, u, body, point)[0])
                      for c, (body, point) in enumerate(points))
        out[:, :nq] = kin.vecmat(on_q, by_q) + kin.raw(model, q, np.asarray(turning)[:, None, :])[:, 0]
        out[:, nq:nx] = u
        out[:, self.slack_columns[k]] = np.einsum("bri,bi->br", contact, u)
        return out

    def accelerations(self, z: np.ndarray, k: int) -> np.ndarray:
        """a (B, nv) at phase k's point variables."""
        return z[:, self.a_columns[k]]

    def rate_dependence(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(nx, nz) bool twice: which point variables each component of `rate` depends on (structurally), and
        which of those it equals (a joint's q rate its v, the v rate its a)."""
        nq, nx = self.nq, self.nx
        nz = self.point_index[k].shape[1]
        dependence = np.zeros((nx, nz), dtype=bool)
        identity = np.zeros((nx, nz), dtype=bool)
        if self.model.floating_base:
            dependence[0:3, 3:7] = dependence[0:3, nq : nq + 3] = True  # R(quaternion) v_lin
            dependence[3:7, 3:7] = dependence[3:7, nq + 3 : nq + 6] = True  # quaternion (x) omega / 2
            identity[7:nq, nq + 6 : nx] = np.eye(nq - 7, dtype=bool)
        else:
            identity[:nq, nq:nx] = np.eye(nq, dtype=bool)
        identity[nq:, self.a_columns[k]] = np.eye(self.nv, dtype=bool)
        # The slack's J_c^T slack moves the q rates of each held point's chain, through its q (not a free-flyer's position).
        ancestors, q_body, _ = self.tree()
        column = self.slack_columns[k].start
        for body, _, axes in self.contact_rows(self.phases[k].contacts):
            chain = list(ancestors[body])
            q_columns = self.q_without_translation[np.isin(q_body[self.q_without_translation], chain)]
            dependence[np.ix_(np.flatnonzero(np.isin(q_body, chain)), np.r_[q_columns, column + np.arange(len(axes))])] = True
            column += len(axes)
        return dependence | identity, identity

    def tree(self) -> tuple[list[set[int]], np.ndarray, np.ndarray]:
        """(each body's ancestors including itself, the body of each q index, the body of each v index)."""
        model = self.model
        ancestors = []
        for i in range(model.nbodies):
            chain, j = {i}, i
            while j > 0:
                j = model.parents[j]
                chain.add(j)
            ancestors.append(chain)
        bodies = np.arange(model.nbodies)
        return (ancestors, np.repeat(bodies, np.diff(list(model.idx_q) + [model.nq])),
                np.repeat(bodies, np.diff(list(model.idx_v) + [model.nv])))

    def tree_dependence(self) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Structural dependence of the joint-space dynamics on the model's tree: (nv, nv) bool between v
        indices whose bodies lie on one branch (one is an ancestor of the other), (nv, nq) the same for q
        (a free-flyer's position excluded: uniform gravity), and per foot the (nv,) rows its force reaches
        (the foot body's ancestors). A leg's joint torques never see another leg's joints or feet."""
        model = self.model
        bodies = model.nbodies
        ancestors, q_body, v_body = self.tree()
        related = np.array([[i in ancestors[j] or j in ancestors[i] for j in range(bodies)] for i in range(bodies)])
        vv, vq = related[np.ix_(v_body, v_body)], related[np.ix_(v_body, q_body)]
        if model.floating_base:
            vq[:, :3] = False
        reach = {name: np.isin(v_body, list(ancestors[body])) for name, body in self.foot_body.items()}
        return vv, vq, reach

    # ------------------------------------------------------------------ NLP assembly
    def _build(self) -> None:
        blocks: list[Block] = []
        nq, nx, nu = self.nq, self.nx, self.nu
        count = len(self.phases)
        for k, phase in enumerate(self.phases):
            index = self.point_index[k]
            blocks.append(_Defects(self, k))
            u = slice(nx, nx + nu)
            if nu:  # linear controls on each interval (eq. 14): u_m = (u_k + u_k+1) / 2
                rows = np.arange(phase.intervals * nu)
                blocks.append(Linear(len(rows), np.tile(rows, 3),
                                     np.concatenate([index[1::2, u].ravel(), index[0:-1:2, u].ravel(), index[2::2, u].ravel()]),
                                     np.r_[np.ones(len(rows)), -0.5 * np.ones(2 * len(rows))]))
            blocks.extend(self._contact_blocks(k))
        layouts: dict[tuple[int, int], list[int]] = {}  # one block, one RNEA call, per layout of the point variables
        for k, phase in enumerate(self.phases):
            layouts.setdefault((len(phase.contacts), len(self.flat_contacts(phase.contacts))), []).append(k)
        blocks.extend(_InverseDynamics(self, ks) for ks in layouts.values())
        for k in range(count if self.periodic else count - 1):
            end, start = self.point_index[k][-1], self._start_seen_from(k)
            if self.periodic and (k + 1) % count == 0 and self.travel_index is not None:
                # q_start = q_end - speed * sum(T) on the travel coordinate, equal elsewhere. The base quaternion's
                # norm already follows from the first point's |q| = 1 through the defects, so only its direction
                # wraps around (3 rows: equal 4 components would be a nearly redundant row, ill-conditioning
                # the KKT system).
                quaternion = [3, 4, 5, 6] if self.model.floating_base else []
                keep = [i for i in range(nq) if i != self.travel_index and i not in quaternion]
                blocks.append(equal(len(keep), start.q[keep], end[keep], start.q_sign[keep]))
                if quaternion:
                    blocks.append(_same_rotation_block(np.concatenate([start.q[3:7], end[3:7]]), np.r_[start.q_sign[3:7], np.ones(4)]))
                blocks.append(Linear(1, np.zeros(count + 2, dtype=np.int64),
                                     np.r_[start.q[self.travel_index], end[self.travel_index], self.duration_index],
                                     np.r_[1.0, -1.0, np.full(count, self.speed)]))
            else:
                blocks.append(equal(nq, start.q, end[:nq], start.q_sign))
            blocks.append(self._velocity_transition(k, start))
            if self.continuous_controls and nu:
                blocks.append(equal(nu, start.u, end[nx : nx + nu], start.u_sign))
        if self.period is not None:
            lo, hi = _period_bounds(self.period)
            halves = 1.0 if self.mirror is None else 2.0  # the phases are half the cycle
            blocks.append(Linear(1, np.zeros(count, dtype=np.int64), self.duration_index, np.full(count, halves), lower=lo, upper=hi))
        if self.model.floating_base:  # fixes the scale gauge of the quaternion (kernels normalise it)
            first = self.point_index[0][0]
            blocks.append(Point(first[None, 3:7], lambda quat: np.sum(quat * quat, axis=1, keepdims=True) - 1.0, 1,
                                derivative=lambda quat: 2.0 * quat[:, None, :]))
        blocks.extend(self.load_rate_blocks())
        blocks.extend(self.dense_rate_blocks())
        blocks.extend(self.yaw_blocks())
        if self.torque_speed is not None and nu:
            blocks.extend(self._torque_speed_blocks())
        if self.input_power is not None and nu:
            blocks.extend(self._input_power_blocks())
        objective, gradient, self.curvatures, extra = build_objective(self, self.objectives)
        self.uses_p1 = bool(extra)
        self.stability_blocks = extra
        blocks.extend(extra)
        self.blocks = blocks
        self.objective, self.gradient = objective, gradient
        self._offsets = np.cumsum([0] + [b.size for b in blocks])
        rows = np.concatenate([b.rows + o for b, o in zip(blocks, self._offsets)])
        cols = np.concatenate([b.cols for b in blocks])
        # Entries sharing (row, col) are summed into one nonzero of the fixed pattern.
        key, self._entry = np.unique(rows * self.n + cols, return_inverse=True)
        self.jac_rows, self.jac_cols = key // self.n, key % self.n
        self.m = int(self._offsets[-1])
        # The Hessian of the Lagrangian's lower triangle, likewise: each entry folded below the diagonal.
        rows = np.concatenate([b.hessian_rows for b in blocks] + [c.rows for c in self.curvatures])
        cols = np.concatenate([b.hessian_cols for b in blocks] + [c.cols for c in self.curvatures])
        key, self._hessian_entry = np.unique(np.maximum(rows, cols) * self.n + np.minimum(rows, cols), return_inverse=True)
        self.hess_rows, self.hess_cols = key // self.n, key % self.n

    def _contact_blocks(self, k: int) -> list[Block]:
        phase, index = self.phases[k], self.point_index[k]
        blocks: list[Block] = [_Feet(self, k)] if self.foot_names else []
        blocks.extend(self.stance_blocks(k))
        blocks.extend(self.swing_clearance_blocks(k))
        if phase.contacts and self.force_dims == 3:  # friction cone (eq. 5), squared to stay smooth
            mu2 = self.friction**2
            feet = len(phase.contacts)
            slope = np.tile([-2.0, -2.0, 2.0 * mu2], feet)
            owner = np.repeat(np.eye(feet), 3, axis=1)  # each foot's row sees its own force

            def cone(f: np.ndarray) -> np.ndarray:
                return mu2 * f.reshape(len(f), -1, 3)[..., 2] ** 2 - np.sum(f.reshape(len(f), -1, 3)[..., :2] ** 2, axis=-1)

            def cone_slopes(f: np.ndarray, slope: np.ndarray = slope, owner: np.ndarray = owner) -> np.ndarray:
                return owner * (slope * f)[:, None, :]

            blocks.append(Point(index[:, self.force_columns[k]], cone, feet, 0.0, np.inf,
                                derivative=cone_slopes))
        blocks.extend(self.foot_torque_blocks(k))
        return blocks

    def stance_blocks(self, k: int) -> list[Block]:
        """The stance feet of phase k held at velocity and acceleration level at the knots (their positions:
        `_Feet`): J_c v = 0 and J_c a + dJ_c/dt v = 0 (`lk.point_accelerations`) for each foot's `contact_rows`,
        one block each per foot over its leg's and the base's columns. With the midpoints freed by the slack
        (`rate`), this is DIRCON's form of the contact constraint (Posa, Kuindersma & Tedrake 2016). Held at
        position level at every point instead, the forces were free to alternate between knots and midpoints.
        A knot's velocity is stated once: not at a phase's first knot (the impact map or the
        previous phase's last knot states it), nor at its last for a foot that stays down through a soft
        touchdown (max_impulse 0: v is continuous there, and the impact map states it), nor where
        `initial`/`final` fix the state."""
        nq, nx = self.nq, self.nx
        index = self.point_index[k]
        knots = np.arange(0, len(index), 2)
        count = len(self.phases)
        linked = self.periodic and count > 1
        ancestors, q_body, v_body = self.tree()
        width = index.shape[1]

        def full(g: np.ndarray, columns: np.ndarray) -> np.ndarray:  # the point variables, zero outside columns
            z = np.zeros((len(g), width))
            z[:, columns] = g
            return z

        blocks: list[Block] = []
        for name in self.phases[k].contacts:
            rows = self.contact_rows([name])
            points = [(body, point) for body, point, _ in rows]
            axes = np.concatenate([3 * i + np.asarray(a) for i, (_, _, a) in enumerate(rows)])
            reach = list(ancestors[self.foot_body[name]])
            q_columns = self.q_without_translation[np.isin(q_body[self.q_without_translation], reach)]
            v_columns = np.flatnonzero(np.isin(v_body, reach))
            velocity_columns = np.concatenate([q_columns, nq + v_columns])
            # a foot's acceleration depends on its leg and the base only
            acceleration_columns = np.concatenate([velocity_columns, self.a_columns[k].start + v_columns])

            def velocities(g: np.ndarray, columns: np.ndarray = velocity_columns, name: str = name) -> np.ndarray:
                z = full(g, columns)
                return np.einsum("bri,bi->br", self.contact_jacobian(z[:, :nq], [name]), z[:, nq:nx])

            def accelerations(g: np.ndarray, columns: np.ndarray = acceleration_columns, points: list = points,
                              axes: np.ndarray = axes) -> np.ndarray:
                z = full(g, columns)
                a = self.accelerations(z, k)
                values = np.asarray(lk.point_accelerations(self.model, self.configuration(z[:, :nq]), z[:, nq:nx], a, points))
                return values.reshape(len(g), -1)[:, axes]

            def velocity_slopes(g: np.ndarray, columns: np.ndarray = velocity_columns, rows: list = rows) -> np.ndarray:
                z = full(g, columns)
                q, v = z[:, :nq], z[:, nq:nx]
                unit = self.configuration(q)
                slopes = np.zeros((len(g), 0, nx))
                for body, point, row_axes in rows:
                    by_q, by_v = kin.point_velocity_derivatives(self.model, unit, v, body, point)
                    slopes = np.concatenate([slopes, np.concatenate([kin.raw(self.model, q, by_q), by_v], axis=2)[:, row_axes]], axis=1)
                return slopes[:, :, columns]

            def acceleration_slopes(g: np.ndarray, columns: np.ndarray = acceleration_columns, points: list = points,
                                    axes: np.ndarray = axes) -> np.ndarray:
                z = full(g, columns)
                q, v, a = z[:, :nq], z[:, nq:nx], self.accelerations(z, k)
                unit = self.configuration(q)
                slopes = np.zeros((len(g), 3 * len(points), width))
                for i, (body, point) in enumerate(points):
                    by_q, by_v, by_a = kin.point_acceleration_derivatives(self.model, unit, v, a, body, point)
                    slopes[:, 3 * i : 3 * i + 3, :nq] = kin.raw(self.model, q, by_q)
                    slopes[:, 3 * i : 3 * i + 3, nq:nx] = by_v
                    slopes[:, 3 * i : 3 * i + 3, self.a_columns[k]] = by_a
                return slopes[:, axes][:, :, columns]

            held = knots
            if k > 0 or linked or self.initial is not None:
                held = held[held > 0]
            last = len(index) - 1
            soft_touchdown = (k < count - 1 or linked) and k in self.impulse_index and self.max_impulse == 0.0
            if (soft_touchdown and name in self.contacts_after(k)) or (k == count - 1 and self.final is not None):
                held = held[held < last]
            if len(held):
                blocks.append(Point(index[np.ix_(held, velocity_columns)], velocities, len(axes), derivative=velocity_slopes,
                                    nonlinear=np.arange(len(q_columns))))
            blocks.append(Point(index[np.ix_(knots, acceleration_columns)], accelerations, len(axes), derivative=acceleration_slopes,
                                nonlinear=np.arange(len(velocity_columns))))
        return blocks

    #: Where on each interval (fractions of it) `swing_clearance_blocks` holds the swing tips above the ground.
    CLEARANCE_FRACTIONS = (0.25, 0.75)

    def swing_clearance_blocks(self, k: int) -> list[Block]:
        """Eq. 4 between the collocation points of phase k: each swing tip (and sole point) at or above the ground
        at `CLEARANCE_FRACTIONS` of every interval, on the state's Hermite cubic through the interval's knots
        with their rates [dq/dt] scaled by the interval's length (the curve `legkit.optimize.replay` samples).
        At the points alone, the converged amble's swing feet dipped up to 11 mm below the ground between them,
        and a replay stumbled on them."""
        contacts = self.phases[k].contacts
        swing = [n for n in self.foot_names + list(self.sole_points) if self.sole_points.get(n, n) not in contacts]
        if not swing:
            return []
        nq, nv, intervals = self.nq, self.nv, self.phases[k].intervals
        # The swing feet's chains: a height is the same wherever in x, y and whatever the other legs do.
        ancestors, q_body, v_body = self.tree()
        chain = list(set().union(*(ancestors[self.foot_body[n]] for n in swing)))
        q_columns = np.flatnonzero(np.isin(q_body, chain))
        q_columns = q_columns[q_columns >= (2 if self.model.floating_base else 0)]
        v_columns = np.flatnonzero(np.isin(v_body, chain))
        index = self.point_index[k]
        groups = np.concatenate([index[0:-1:2][:, q_columns], index[0:-1:2][:, nq + v_columns], index[2::2][:, q_columns],
                                 index[2::2][:, nq + v_columns], np.full((intervals, 1), self.duration_index[k])], axis=1)
        c, cv = len(q_columns), len(v_columns)
        spans = ((0, c), (c, c + cv), (c + cv, 2 * c + cv), (2 * c + cv, 2 * (c + cv)))  # q0, v0, q1, v1; then the duration
        basis = [hermite_basis(s) for s in self.CLEARANCE_FRACTIONS]

        def full(part: np.ndarray, columns: np.ndarray = q_columns, size: int = nq) -> np.ndarray:  # zero elsewhere
            out = np.zeros((len(part), size))
            out[:, columns] = part
            return out

        def states(g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            q0, v0, q1, v1 = (g[:, a:b] for a, b in spans)
            return full(q0), full(v0, v_columns, nv), full(q1), full(v1, v_columns, nv), g[:, -1:] / intervals

        def heights(g: np.ndarray) -> np.ndarray:
            q0, v0, q1, v1, h = states(g)
            r0, r1 = h * self.q_rate(q0, v0), h * self.q_rate(q1, v1)
            q = np.stack([b[0] * q0 + b[1] * r0 + b[2] * q1 + b[3] * r1 for b in basis], axis=1)  # (B, fractions, nq)
            return self.foot_positions(q, swing)[..., 2].reshape(len(g), -1)

        swing_points = [(self.foot_body[n], self.foot_point[n]) for n in swing]

        def height_gradient(g: np.ndarray, weights: np.ndarray) -> np.ndarray:
            """weights (B, fractions x swing) . d heights / dg (B, columns), through q_s = b0 q0 + b1 h rate0 + b2 q1
            + b3 h rate1 at each fraction."""
            q0, v0, q1, v1, h = states(g)
            (dq0, dv0), (dq1, dv1) = kin.q_rate_derivatives(self.model, q0, v0), kin.q_rate_derivatives(self.model, q1, v1)
            dv0, dv1 = dv0[:, :, v_columns], dv1[:, :, v_columns]
            rate0, rate1 = self.q_rate(q0, v0), self.q_rate(q1, v1)
            out = np.zeros_like(g)
            for f, b in enumerate(basis):
                q = b[0] * q0 + b[1] * h * rate0 + b[2] * q1 + b[3] * h * rate1
                height = kin.point_jacobians(self.model, self.configuration(q), swing_points)[:, :, 2]  # (B, swing, nv)
                on_q = kin.raw(self.model, q, np.einsum("bs,bsj->bj", weights[:, f * len(swing) : (f + 1) * len(swing)], height)[:, None])[:, 0]
                out[:, spans[0][0] : spans[0][1]] += (b[0] * on_q + b[1] * h * kin.vecmat(on_q, dq0))[:, q_columns]
                out[:, spans[1][0] : spans[1][1]] += b[1] * h * kin.vecmat(on_q, dv0)
                out[:, spans[2][0] : spans[2][1]] += (b[2] * on_q + b[3] * h * kin.vecmat(on_q, dq1))[:, q_columns]
                out[:, spans[3][0] : spans[3][1]] += b[3] * h * kin.vecmat(on_q, dv1)
                out[:, -1] += np.sum(on_q * (b[1] * rate0 + b[3] * rate1), axis=1) / intervals
            return out

        return [Point(groups, heights, len(basis) * len(swing), 0.0, np.inf, gradient=height_gradient)]

    def foot_torque_blocks(self, k: int) -> list[Block]:
        """Eq. 6 at every point of phase k, for each flat foot on the ground: c_i F_z - s T_i >= 0 for i = x, y, z
        and s = +-1, with c = support x (0.5 l_y, 0.5 l_x, mu_d) (`FlatFoot.support`); linear in the force and torque variables."""
        contacts = list(self.phases[k].contacts)
        if not self.flat_contacts(contacts):
            return []
        index = self.point_index[k]
        forces = index[:, self.force_columns[k]].reshape(len(index), -1, 3)
        torques = index[:, self.torque_columns[k]].reshape(len(index), -1, 3)
        blocks: list[Block] = []
        for c, name in enumerate(self.flat_contacts(contacts)):
            sole = self.flat_feet[name]
            limit = sole.support * np.array([0.5 * sole.width, 0.5 * sole.length, sole.torsion])
            normal = forces[:, contacts.index(name), 2]
            for sign in (1.0, -1.0):
                rows = np.arange(3 * len(index))
                blocks.append(Linear(len(rows), np.r_[rows, rows], np.r_[np.repeat(normal, 3), torques[:, c].ravel()],
                                     np.r_[np.tile(limit, len(index)), np.full(len(rows), -sign)], lower=0.0, upper=np.inf))
        return blocks

    def contact_rows(self, contacts: Sequence[str]) -> list[tuple[int, np.ndarray, list[int]]]:
        """(body, point, world axes) whose velocities a touchdown of `contacts` stops (eq. 7): each foot's point
        (its vertical axis only when force_dims is 1), and for a flat foot its toe (y, z) and side (z) points,
        which with the centre stop the whole sole (six independent rows)."""
        rows = []
        for name in contacts:
            rows.append((self.foot_body[name], self.foot_point[name], [0, 1, 2] if self.force_dims == 3 else [2]))
            if name in self.flat_feet:
                rows.append((self.foot_body[name], self.foot_point[f"{name}/toe"], [1, 2]))
                rows.append((self.foot_body[name], self.foot_point[f"{name}/side"], [2]))
        return rows

    def contact_frames(self, q: np.ndarray, contacts: Sequence[str]) -> tuple[list[kin.ContactPoint], np.ndarray, np.ndarray]:
        """The named feet's `contact_rows` at unit q (B, nq): their points, the points' world-aligned Jacobians
        (B, points, 6, nv) and the rows' linear Jacobian (B, r, nv) (`contact_jacobian`)."""
        rows = self.contact_rows(contacts)
        points = [(body, point) for body, point, _ in rows]
        full = kin.point_jacobians(self.model, q, points)
        return points, full, np.concatenate([full[:, i, axes] for i, (_, _, axes) in enumerate(rows)], axis=1)

    def row_forces(self, values: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """World forces (B, points, 3) at the `contact_rows` points of the named feet from per-row values (B, r)
        (impulses, slack), zero on the axes a row does not hold."""
        rows = self.contact_rows(contacts)
        out = np.zeros((len(values), len(rows), 3))
        column = 0
        for i, (_, _, axes) in enumerate(rows):
            out[:, i, axes] = values[:, column : column + len(axes)]
            column += len(axes)
        return out

    def contact_jacobian(self, q: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """(B, r, nv): the world-aligned linear Jacobians of the `contact_rows` of the named feet at q (B, nq)."""
        q = self.configuration(q)
        return np.concatenate([np.asarray(lk.jacobian(self.model, q, body, point, "local_world_aligned"))[:, axes]
                               for body, point, axes in self.contact_rows(contacts)], axis=1)

    def impact_rows(self, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """The inelastic impact (eq. 7, as `lk.impact`) in implicit form at z = [q-, v-, v+, Lambda] (B, .):
        M(q) (v+ - v-) - J^T Lambda (nv rows) and J v+ (force_dims k rows), J = `contact_jacobian`."""
        nq, nv = self.nq, self.nv
        q, v_minus, v_plus, impulses = z[:, :nq], z[:, nq : nq + nv], z[:, nq + nv : nq + 2 * nv], z[:, nq + 2 * nv :]
        mass = np.asarray(lk.crba(self.model, self.configuration(q)))
        jac = self.contact_jacobian(q, contacts)
        return np.concatenate([np.einsum("bij,bj->bi", mass, v_plus - v_minus) - np.einsum("bji,bj->bi", jac, impulses),
                               np.einsum("bij,bj->bi", jac, v_plus)], axis=1)

    def impact_derivative(self, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """The Jacobian (B, rows, columns of z) of `impact_rows`: affine in v-, v+ and Lambda (-M, [M; J] and -J^T);
        d/dq of M(q) w by `kinematics.mass_slope`, of J^T Lambda by `kinematics.force_slope`, of J v+ by the
        points' velocity derivatives."""
        nq, nv, model = self.nq, self.nv, self.model
        q = self.configuration(z[:, :nq])
        v_minus, v_plus, impulses = z[:, nq : nq + nv], z[:, nq + nv : nq + 2 * nv], z[:, nq + 2 * nv :]
        points, full, contact = self.contact_frames(q, contacts)
        mass = np.asarray(lk.crba(model, q))
        jac = np.zeros((len(z), nv + impulses.shape[1], z.shape[1]))
        top = kin.mass_slope(model, q, v_plus - v_minus) - kin.force_slope(model, q, points, self.row_forces(impulses, contacts), full)
        bottom = np.concatenate([kin.point_velocity_derivatives(model, q, v_plus, body, point)[0][:, axes]
                                 for body, point, axes in self.contact_rows(contacts)], axis=1)
        jac[:, :, :nq] = kin.raw(model, z[:, :nq], np.concatenate([top, bottom], axis=1))
        jac[:, :nv, nq : nq + nv] = -mass
        jac[:, :nv, nq + nv : nq + 2 * nv] = mass
        jac[:, nv:, nq + nv : nq + 2 * nv] = contact
        jac[:, :nv, nq + 2 * nv :] = -contact.transpose(0, 2, 1)
        return jac

    def _start_seen_from(self, k: int) -> _Start:
        """The variables of the point after the boundary that ends phase k, as phase k's end sees them (`_Start`)."""
        start = self.point_index[(k + 1) % len(self.phases)][0]
        nq, nx = self.nq, self.nx
        if (k + 1) % len(self.phases) or self.mirror is None:
            return _Start(start[:nq], np.ones(nq), start[nq:nx], np.ones(self.nv), start[nx : nx + self.nu], np.ones(self.nu))
        mirror = self.mirror
        u_order, u_sign = mirror.control_order(np.asarray(self.actuated, dtype=np.int64))
        return _Start(start[mirror.q_order], mirror.q_sign, start[nq + mirror.v_order], mirror.v_sign, start[nx + u_order], u_sign)

    def _velocity_transition(self, k: int, start: _Start) -> Block:
        """v after the boundary: the impact map (eq. 7) when feet touch down, else continuity. The impact is
        stated implicitly with the impulses as variables (`impact_rows`, bilinear in q and v+, v-, Lambda): the
        explicit map v+ = impact(q, v-) solves a KKT system whose second derivatives are far larger."""
        end = self.point_index[k][-1]
        nq, nx, nv = self.nq, self.nx, self.nv
        if k not in self.impulse_index:
            return equal(nv, start.v, end[nq:nx], start.v_sign)
        contacts = self.contacts_after(k)
        signs = np.r_[np.ones(nx), start.v_sign, np.ones(len(self.impulse_index[k]))]
        index = np.concatenate([end[:nx], start.v, self.impulse_index[k]])[None]
        return Point(index, lambda z: self.impact_rows(signs * z, contacts), nv + len(self.impulse_index[k]),
                     derivative=lambda z: self.impact_derivative(signs * z, contacts) * signs, nonlinear=self.q_without_translation)

    def yaw_blocks(self) -> list[Block]:
        """-max_yaw <= yaw <= max_yaw at every point: yaw = atan2(2 (w z + x y), w^2 + x^2 - y^2 - z^2) of the base
        quaternion [x, y, z, w] (both arguments homogeneous of degree 2: the quaternion's norm drops out)."""
        if not np.isfinite(self.max_yaw):
            return []

        def yaw(quaternion: np.ndarray) -> np.ndarray:
            x, y, z, w = quaternion.T
            return np.arctan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)[:, None]

        def slopes(quaternion: np.ndarray) -> np.ndarray:
            x, y, z, w = quaternion.T
            sine, cosine = 2.0 * (w * z + x * y), w * w + x * x - y * y - z * z
            by_sine, by_cosine = 2.0 * np.stack([y, x, w, z], axis=1), 2.0 * np.stack([x, -y, -z, w], axis=1)
            return ((cosine[:, None] * by_sine - sine[:, None] * by_cosine) / (sine * sine + cosine * cosine)[:, None])[:, None, :]

        index = np.concatenate([index[:, 3:7] for index in self.point_index])
        return [Point(index, yaw, 1, -self.max_yaw, self.max_yaw, derivative=slopes)]

    def dense_rate_blocks(self) -> list[Block]:
        """|w_i(s)| <= no-load speed of each actuated joint i over every interval (dense_rates): w(s) is the velocity's
        Hermite cubic [Hardt 2002, eq. 14] through (v_k, h a_k) and (v_k+1, h a_k+1), h = T / N; in Bernstein form its
        control points are v_k, v_k + h a_k / 3, v_k+1 - h a_k+1 / 3, v_k+1, and the cubic lies in their convex hull, so
        bounding the two inner ones (bilinear in the duration and the accelerations) bounds it everywhere; the ends are
        points, held by the torque-speed line."""
        if not self.dense_rates or self.torque_speed is None or not self.nu:
            return []
        actuated, nu = np.asarray(self.actuated), self.nu
        limit = np.tile(np.broadcast_to(np.asarray(self.torque_speed.max_speed, dtype=np.float64), (nu,)), 2)
        blocks: list[Block] = []
        for k, index in enumerate(self.point_index):
            a = index[:, self.a_columns[k]][:, actuated]
            v = index[:, self.nq + actuated]
            groups = np.concatenate([v[0:-1:2], a[0:-1:2], v[2::2], a[2::2], np.full((len(v) // 2, 1), self.duration_index[k])], axis=1)
            third = 1.0 / (3.0 * self.phases[k].intervals)  # h / 3 per unit duration

            def rates(g: np.ndarray, third: float = third) -> np.ndarray:
                v0, a0, v1, a1 = (g[:, i * nu : (i + 1) * nu] for i in range(4))
                step = third * g[:, -1:]
                return np.concatenate([v0 + step * a0, v1 - step * a1], axis=1)

            def slopes(g: np.ndarray, third: float = third) -> np.ndarray:
                out = np.zeros((len(g), 2 * nu, 4 * nu + 1))
                eye = np.eye(nu)
                step = third * g[:, -1, None, None]
                out[:, :nu, :nu], out[:, nu:, 2 * nu : 3 * nu] = eye, eye
                out[:, :nu, nu : 2 * nu], out[:, nu:, 3 * nu : 4 * nu] = step * eye, -step * eye
                out[:, :nu, -1], out[:, nu:, -1] = third * g[:, nu : 2 * nu], -third * g[:, 3 * nu : 4 * nu]
                return out

            blocks.append(Point(groups, rates, 2 * nu, -limit, limit, derivative=slopes, nonlinear=np.array([4 * nu])))
        return blocks

    def load_rate_blocks(self) -> list[Block]:
        """|x(t_p+1) - x(t_p)| <= rate (t_p+1 - t_p) between neighbouring points for every component x of every
        stance foot's force (max_force_rate) and every actuated torque (max_torque_rate): linear rows in x and the
        phase's duration (t_p+1 - t_p = T / (2 N)). At a phase boundary, where two points share one instant, a foot
        down on both sides keeps its force within one half interval's change, a lifting foot's force at its last
        point and a landing foot's at its first are within one half interval's change of zero (the load moves
        between feet over the half intervals beside the switch, not at once), and the torques likewise."""
        terms: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []  # a, its sign, b, phase, c

        def add(a: np.ndarray, b: np.ndarray | None, k: int, rate: float, a_sign: np.ndarray | float = 1.0) -> None:
            """Rows |a_sign x[a] - x[b]| <= rate T_k / (2 N_k) (b None: |a_sign x[a]|), elementwise over a."""
            a = np.ravel(a)
            b_index = np.full(len(a), -1) if b is None else np.ravel(b)
            terms.append((a, np.broadcast_to(np.asarray(a_sign, dtype=np.float64), a.shape).ravel(), b_index,
                          np.full(len(a), k), np.full(len(a), rate / (2.0 * self.phases[k].intervals))))

        count = len(self.phases)
        nx, nu = self.nx, self.nu

        def forces(k: int, point: int, name: str) -> np.ndarray:
            contacts = list(self.phases[k].contacts)
            own = self.point_index[k][point, self.force_columns[k]].reshape(len(contacts), self.force_dims)
            return own[contacts.index(name)]

        for k in range(count):
            index = self.point_index[k]
            if np.isfinite(self.max_torque_rate) and nu:
                add(index[1:, nx : nx + nu], index[:-1, nx : nx + nu], k, self.max_torque_rate)
            if np.isfinite(self.max_force_rate):
                for name in self.phases[k].contacts:
                    add(np.stack([forces(k, p, name) for p in range(1, len(index))]),
                        np.stack([forces(k, p, name) for p in range(len(index) - 1)]), k, self.max_force_rate)
            if k == count - 1 and not self.periodic:
                continue
            after = (k + 1) % count
            wrapped = after == 0 and self.mirror is not None
            start = self._start_seen_from(k)
            if np.isfinite(self.max_torque_rate) and nu:
                add(start.u, self.point_index[k][-1, nx : nx + nu], k, self.max_torque_rate, start.u_sign)
            if not np.isfinite(self.max_force_rate):
                continue
            sign = np.array([1.0, -1.0, 1.0])[3 - self.force_dims :] if wrapped else 1.0  # a mirrored force's y flips
            before, later = self.phases[k].contacts, self.contacts_after(k)
            for name in dict.fromkeys((*before, *later)):  # ordered: a set's order follows the hash seed
                own = self.mirror.feet[name] if wrapped and self.mirror is not None else name  # its name in phase `after`
                if name in before and name in later:
                    add(forces(after, 0, own), forces(k, len(self.point_index[k]) - 1, name), k, self.max_force_rate, sign)
                elif name in before:
                    add(forces(k, len(self.point_index[k]) - 1, name), None, k, self.max_force_rate)
                else:
                    add(forces(after, 0, own), None, after, self.max_force_rate)
        if not terms:
            return []
        a, a_sign, b, phase, c = (np.concatenate(part) for part in zip(*terms))
        size, paired = len(a), np.flatnonzero(b >= 0)
        rows = np.concatenate([np.arange(size), paired, np.arange(size)])
        cols = np.concatenate([a, b[paired], self.duration_index[phase]])
        coefficients = np.concatenate([a_sign, -np.ones(len(paired)), -c])
        flip = np.r_[-np.ones(len(cols) - size), np.ones(size)]  # difference - c T <= 0, then -difference - c T <= 0
        return [Linear(size, rows, cols, coefficients, lower=-np.inf, upper=0.0),
                Linear(size, rows, cols, coefficients * flip, lower=-np.inf, upper=0.0)]

    def _torque_speed_blocks(self) -> list[Block]:
        """(w_max - |w|) k - |u| >= 0 as four linear faces per actuated joint and point."""
        line = self.torque_speed
        assert line is not None  # built only with a torque-speed line
        w_max = np.broadcast_to(np.asarray(line.max_speed, dtype=np.float64), (self.nu,))
        gain = np.broadcast_to(np.asarray(line.gain, dtype=np.float64), (self.nu,))
        index = np.concatenate(self.point_index_u_w(), axis=0)  # (P, nu, 2): (u, w) columns
        points = len(index)
        blocks: list[Block] = []
        for su in (1.0, -1.0):
            for sw in (1.0, -1.0):
                rows = np.arange(points * self.nu)
                coeff_u = np.full(points * self.nu, -su)
                coeff_w = np.tile(-sw * gain, points)
                blocks.append(Linear(len(rows), np.r_[rows, rows], np.r_[index[..., 0].ravel(), index[..., 1].ravel()],
                                     np.r_[coeff_u, coeff_w], offset=np.tile(w_max * gain, points), lower=0.0, upper=np.inf))
        return blocks

    def _input_power_blocks(self) -> list[Block]:
        """R (u / (G K))^2 + u w <= limit per actuated joint and point: one block per joint, whose coefficients
        are its own (a point block's function is applied to batches of points of one kind)."""
        power = self.input_power
        assert power is not None  # built only with an input-power limit

        def per_joint(value: np.ndarray | float) -> np.ndarray:
            return np.broadcast_to(np.asarray(value, dtype=np.float64), (self.nu,))

        limit = per_joint(power.limit)
        loss = per_joint(power.resistance) / (per_joint(power.gear_ratio) * per_joint(power.torque_constant)) ** 2
        index = np.concatenate(self.point_index_u_w(), axis=0)  # (P, nu, 2): (u, w) columns
        blocks: list[Block] = []
        for i in range(self.nu):
            drawn, slopes = _input_power(float(loss[i]))
            blocks.append(Point(index[:, i], drawn, 1, lower_bound=-np.inf, upper_bound=float(limit[i]), derivative=slopes))
        return blocks

    def point_index_u_w(self) -> list[np.ndarray]:
        """Per phase (P, nu, 2): the variable of each actuated torque and of its joint's velocity."""
        return [np.stack([index[:, self.nx : self.nx + self.nu], index[:, self.nq + np.asarray(self.actuated)]], axis=-1)
                for index in self.point_index]

    # ------------------------------------------------------------------ NLP interface
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lower, upper = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        for k, phase in enumerate(self.phases):
            index = self.point_index[k]
            for part, bounds in ((slice(0, self.nq), self.q_bounds), (slice(self.nq, self.nx), self.v_bounds),
                                 (slice(self.nx, self.nx + self.nu), self.u_bounds)):
                if bounds is not None:
                    lower[index[:, part]] = np.asarray(bounds[0], dtype=np.float64)
                    upper[index[:, part]] = np.asarray(bounds[1], dtype=np.float64)
            normal = index[:, self.force_columns[k]][:, self.force_dims - 1 :: self.force_dims]
            lower[normal] = self.min_normal_force  # unilateral contact (eq. 5), with its margin
            lower[index[0::2, self.slack_columns[k]]] = upper[index[0::2, self.slack_columns[k]]] = 0.0  # the slack acts at the midpoints
            lower[self.duration_index[k]], upper[self.duration_index[k]] = phase.duration
        for state, point in ((self.initial, self.point_index[0][0]), (self.final, self.point_index[-1][-1])):
            if state is not None:
                values = np.concatenate([np.asarray(state[0], dtype=np.float64), np.asarray(state[1], dtype=np.float64)])
                if values.shape != (self.nx,):
                    raise ValueError(f"initial/final must be (q (nq,), v (nv,)), got {values.shape[0]} values for nq + nv = {self.nx}")
                fixed = ~np.isnan(values)
                lower[point[: self.nx][fixed]] = upper[point[: self.nx][fixed]] = values[fixed]
        for index in self.impulse_index.values():
            lower[index], upper[index] = -self.max_impulse, self.max_impulse
        if self.translation_gauge:
            lower[self.point_index[0][0, :2]] = upper[self.point_index[0][0, :2]] = 0.0
        if not self.uses_p1:
            lower[self.p1_index] = upper[self.p1_index] = 0.0
        return lower, upper

    @property
    def translation_gauge(self) -> bool:
        """A periodic free-flyer gait is invariant to horizontal translation (flat ground, feet free to land
        anywhere): the base starts at x = y = 0, which makes its optimum isolated (`solve` moves the guess)."""
        return self.periodic and self.model.floating_base and self.initial is None and self.final is None

    def gauged(self, x: np.ndarray) -> np.ndarray:
        """x translated horizontally so that the base starts at x = y = 0 (`translation_gauge`)."""
        x = np.array(x, dtype=np.float64)
        if self.translation_gauge:
            shift = x[self.point_index[0][0, :2]].copy()
            for index in self.point_index:
                x[index[:, :2]] -= shift
        return x

    def constraints(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([b.values(x) for b in self.blocks])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        values = np.concatenate([b.jacobian(x) for b in self.blocks])
        return np.bincount(self._entry, weights=values, minlength=len(self.jac_rows))

    def hessian(self, x: np.ndarray, objective_factor: float, multipliers: np.ndarray) -> np.ndarray:
        """The lower triangle of objective_factor d2f/dx2 + sum_i multipliers_i d2g_i/dx2 on (hess_rows, hess_cols):
        each block's curvature by central differences of its exact Jacobian (`blocks.group_hessian`)."""
        values = [b.hessian(x, multipliers[start:stop]) for b, start, stop in zip(self.blocks, self._offsets, self._offsets[1:])]
        if objective_factor != 0.0:
            values += [objective_factor * c.values(x) for c in self.curvatures]
        else:
            values += [np.zeros(len(c.rows)) for c in self.curvatures]
        return np.bincount(self._hessian_entry, weights=np.concatenate(values), minlength=len(self.hess_rows))

    def nlp(self, derivatives: str = "legkit", objective: bool = True) -> NLP:
        """The NLP: objective, constraints and their exact Jacobian from legkit's kernels. derivatives="legkit": IPOPT
        approximates the Hessian of the Lagrangian by L-BFGS; "exact": it is given `hessian`. objective=False: the
        constraints alone (objective 0)."""
        if derivatives not in DERIVATIVES:
            raise ValueError(f"derivatives must be one of {DERIVATIVES}, got {derivatives!r}")
        lower, upper = self.bounds()
        f, gradient = (self.objective, self.gradient) if objective else (lambda x: 0.0, lambda x: np.zeros(self.n))
        hessian = None
        if derivatives == "exact":
            hessian = self.hessian if objective else (lambda x, _, multipliers: self.hessian(x, 0.0, multipliers))
        return NLP(lower, upper, np.concatenate([b.lower for b in self.blocks]), np.concatenate([b.upper for b in self.blocks]),
                   f, gradient, self.constraints, self.jacobian, self.jac_rows, self.jac_cols, hessian, self.hess_rows, self.hess_cols)

    def solve(self, guess: Trajectory | np.ndarray | SolveResult, derivatives: str = "exact", feasibility_first: bool = False,
              polish: bool = False, polish_max_iter: int = 1000, **options: Any) -> tuple[Trajectory, SolveResult]:
        """Solve from a guess (a Trajectory, a variable vector, or the `SolveResult` of a problem with the same
        layout, e.g. the gait at a neighbouring speed: its point and multipliers, a primal-dual warm start
        (`legkit.optimize.solver.WARM_START`)), with the Hessian of the Lagrangian (derivatives="exact", default) or
        IPOPT's L-BFGS approximation of it ("legkit"; `nlp`); options go to `legkit.optimize.solver.solve`.

        feasibility_first (problems with a MinMaxStability term): continuation in two IPOPT runs, first the
        constraints alone with p1 held below every S_H row, then the objective from that feasible point with p1
        at its worst S_H row. polish (with derivatives "legkit"): the L-BFGS run on the objective ends once it
        stalls (`POLISH_SWITCH`; options' stall replaces it, and applies to the objective's run only), then IPOPT
        runs twice more from its best point (its last after a stall), with the exact Hessian and a small initial
        barrier parameter (`POLISH_MU_INIT`), each within polish_max_iter iterations (the L-BFGS runs take options'
        max_iter): first with the phase durations held at that point's, then with them free, from the held run's
        point and multipliers. The durations are the slow variables: released at once, they crept to their
        optimum over ~1000 iterations on the mirrored amble at 0.60 m/s; held first, 116 + 180.
        L-BFGS keeps climbing where the exact Hessian converges.
        The result's iterations, times and history cover every run."""
        if polish and derivatives == "exact":
            raise ValueError("polish follows an L-BFGS solve (derivatives 'legkit'), got derivatives='exact'")
        if isinstance(guess, SolveResult):
            if feasibility_first:
                raise ValueError("feasibility_first does not apply to a warm start from a SolveResult")
            multipliers = guess.multipliers
            guess = guess.x
        else:
            multipliers = None
        x0 = self.gauged(self.pack(guess) if isinstance(guess, Trajectory) else self.point(guess, "guess"))
        nlp = self.nlp(derivatives)
        stall = options.pop("stall", POLISH_SWITCH if polish else None)  # on the objective's run only
        if polish:
            exact = {**options, "max_iter": polish_max_iter, "options": {**(options.get("options") or {}), "mu_init": POLISH_MU_INIT}}
        if feasibility_first and self.uses_p1:
            x0 = x0.copy()
            x0[self.p1_index] = 0.0
            x0[self.p1_index] = min(b.values(x0).min() for b in self.stability_blocks) - 1.0
            first = solve(self._p1_held(derivatives, x0[self.p1_index]), x0, **options)
            x0 = first.x.copy()
            x0[self.p1_index] += min(b.values(x0).min() for b in self.stability_blocks)
            result = solve(nlp, x0, stall=stall, **options)
            result = result.after(first)
        else:
            result = solve(nlp, x0, multipliers=multipliers, stall=stall, **options)
        if polish:
            start = result.x if result.status == "User_Requested_Stop" else result.best()[0]
            held = self.nlp("exact")  # the phase durations held where L-BFGS left them
            held.x_lower[self.duration_index] = held.x_upper[self.duration_index] = start[self.duration_index]
            result = solve(held, start, **exact).after(result)
            result = solve(self.nlp("exact"), result.x, multipliers=result.multipliers, **exact).after(result)
        return self.unpack(result.best()[0]), result

    def _p1_held(self, derivatives: str, p1: float) -> NLP:
        """The NLP with p1 held at `p1`: the constraints, every S_H row at least p1 (J_s2 then constant)."""
        nlp = self.nlp(derivatives)
        nlp.x_lower[self.p1_index] = nlp.x_upper[self.p1_index] = p1
        return nlp

    def refined(self, coarse: MultiphaseProblem, x: np.ndarray) -> np.ndarray:
        """`x`, a point of `coarse` (the same problem on other intervals per phase), on this problem's mesh: each
        phase's point variables (knots and midpoints, evenly spaced in the phase's time) interpolated linearly, the
        durations, p1 and touchdown impulses copied, gauged (`gauged`)."""
        instance(coarse, MultiphaseProblem, "coarse")
        same = (len(coarse.phases) == len(self.phases) and coarse.n - coarse.p1_index == self.n - self.p1_index
                and all(a.contacts == b.contacts for a, b in zip(coarse.phases, self.phases))
                and all(a.shape[1] == b.shape[1] for a, b in zip(coarse.point_index, self.point_index)))
        if not same:
            raise ValueError("coarse must be this problem with other intervals per phase (the same phases, contacts and variables per point)")
        x = coarse.point(x)
        fine = np.empty(self.n)
        for index, coarse_index in zip(self.point_index, coarse.point_index):
            s, s_coarse = np.linspace(0.0, 1.0, len(index)), np.linspace(0.0, 1.0, len(coarse_index))
            values = x[coarse_index]
            fine[index] = np.stack([np.interp(s, s_coarse, column) for column in values.T], axis=1)
        fine[self.duration_index[0]:] = x[coarse.duration_index[0]:]  # durations, p1, impulses: the same layout
        return self.gauged(fine)

    def refine(self, coarse: MultiphaseProblem, result: SolveResult, stability_fraction: float = REFINE_STABILITY,
               derivatives: str = "exact", **options: Any) -> tuple[Trajectory, SolveResult]:
        """Mesh refinement: `result`, solved on `coarse` (this problem on fewer intervals per phase), made a
        solution of this problem from its interpolation (`refined`). With J_s2 (MinMaxStability) p1 is held at
        stability_fraction x the coarse optimum's, so the worst-case S_H stays at least that and the run is a
        feasibility problem; other objective terms are minimised. J_s2 itself on the fine mesh took as many
        iterations from the interpolation as from the reference (16 intervals per phase: 709 against 712, ~2 min;
        `REFINE_STABILITY`). Options go to `legkit.optimize.solver.solve`; the result covers
        both solves."""
        instance(coarse, MultiphaseProblem, "coarse")
        instance(result, SolveResult, "result")
        if not 0.0 <= stability_fraction <= 1.0:
            raise ValueError(f"stability_fraction must be in [0, 1], got {stability_fraction}")
        x0 = self.refined(coarse, result.best()[0])
        if self.uses_p1:
            x0[self.p1_index] *= stability_fraction
            nlp = self._p1_held(derivatives, x0[self.p1_index])
        else:
            nlp = self.nlp(derivatives)
        fine = solve(nlp, x0, **options).after(result)
        return self.unpack(fine.best()[0]), fine

    def continued(self, result: SolveResult, speed: float) -> SolveResult:
        """`result`, solved at `speed` [m/s], as a warm start at this problem's speed (`solve(problem.continued(
        result, speed))`): the travel coordinate and its rate stretched by self.speed / speed at every point, the
        multipliers kept (`legkit.optimize.solver.WARM_START`: the 16-interval amble from 0.67 to 0.70 m/s in 53
        iterations, against 111 cold)."""
        if self.travel_index is None or not self.speed > 0.0:
            raise ValueError("continued needs a problem with a travel coordinate and a positive speed")
        if not speed > 0.0:
            raise ValueError(f"speed must be > 0, got {speed}")
        if result.x.shape != (self.n,):
            raise ValueError(f"result.x must have shape ({self.n},), got {result.x.shape}")
        travel = self.travel_index
        rate = travel - 1 if self.model.floating_base and travel >= 7 else travel  # a free-flyer's x, y: its body-frame rate
        x = result.x.copy()
        for index in self.point_index:
            x[index[:, [travel, self.nq + rate]]] *= self.speed / speed
        return replace(result, x=x)

    def stance_accelerations(self, x: np.ndarray) -> list[np.ndarray]:
        """Per phase (points, stance feet, 3): the world acceleration J a + dJ/dt v (`lk.point_accelerations`) of
        each stance foot's point at the point's state and accelerations a (`accelerations`). A motion holds its stance
        feet at rest, so these are zero on it."""
        out = []
        for k, phase in enumerate(self.phases):
            z = x[self.point_index[k]]
            held = [(self.foot_body[name], self.foot_point[name]) for name in phase.contacts]
            if not held:
                out.append(np.zeros((len(z), 0, 3)))
                continue
            q, v = self.configuration(z[:, : self.nq]), z[:, self.nq : self.nx]
            out.append(np.asarray(lk.point_accelerations(self.model, q, v, self.accelerations(z, k), held)))
        return out

    def stability_index(self, x: np.ndarray) -> list[np.ndarray]:
        """S_H as published (eq. 10) at every point of every phase, for a problem with a MinMaxStability
        objective (whatever form its constraint takes)."""
        terms = [t for t in self.objectives if isinstance(t, MinMaxStability)]
        if not terms:
            raise ValueError("stability_index needs a problem whose objectives hold a MinMaxStability term")
        return [published_stability(self, k, terms[0], x[index]) for k, index in enumerate(self.point_index)]

    # ------------------------------------------------------------------ mirror periodicity
    def full_cycle(self) -> MultiphaseProblem:
        """The same gait over its whole cycle without a mirror (self when there is none): what `unroll`'s
        trajectories are solutions of."""
        if self.mirror is None:
            return self
        return replace(self, phases=self.cycle_phases(), mirror=None)

    def unroll(self, trajectory: Trajectory) -> Trajectory:
        """A mirrored half cycle followed by its mirror image, moved on by the half cycle's time and travel: the
        whole cycle, as `full_cycle()` transcribes it (the trajectory itself when there is no mirror)."""
        mirror = self.mirror
        if mirror is None:
            return trajectory
        half = float(np.sum(trajectory.durations))
        shift, scale = np.zeros(self.nq), np.ones(self.nq)
        if self.travel_index is not None:
            shift[self.travel_index] = self.speed * half
        if self.model.floating_base:
            # The half cycle's wrap-around states the quaternion by direction (its norm drifts within the defects'
            # error), the whole cycle's middle boundary all four components: the mirror image takes the end's norm.
            scale[3:7] = np.linalg.norm(trajectory.q[-1][-1, 3:7]) / np.linalg.norm(trajectory.q[0][0, 3:7])
        u_order, u_sign = mirror.control_order(np.asarray(self.actuated, dtype=np.int64))

        def twice(parts: list[np.ndarray], mirrored: Callable[[np.ndarray], np.ndarray]) -> list[np.ndarray]:
            return list(parts) + [mirrored(np.asarray(p)) for p in parts]

        def controls(u: np.ndarray) -> np.ndarray:
            return u_sign * u[..., u_order]

        a, torques, slack = trajectory.a, trajectory.torques, trajectory.slack
        q = twice(trajectory.q, lambda q: scale * mirror.q(q) + shift)
        if slack is not None:  # the mirror image of the correction J_c^T slack, in the mirrored feet's rows
            slack = list(slack)
            for k, phase in enumerate(self.phases):
                mirrored = mirror.contacts(phase.contacts)
                correction = mirror.v(np.einsum("bri,br->bi", self.contact_jacobian(trajectory.q[k], phase.contacts), slack[k]))
                rows = self.contact_jacobian(q[len(self.phases) + k], mirrored)
                slack.append(np.einsum("bri,bi->br", np.linalg.pinv(np.swapaxes(rows, 1, 2)), correction))
        return Trajectory(
            twice(trajectory.t, lambda t: t + half), q,
            twice(trajectory.v, mirror.v), twice(trajectory.u, controls), twice(trajectory.forces, Mirror.vectors),
            np.concatenate([trajectory.durations, trajectory.durations]), trajectory.stability_bound,
            None if a is None else twice(a, mirror.v), None if torques is None else twice(torques, Mirror.axial), slack,
        )

    def whole_trajectory(self, trajectory: Trajectory) -> tuple[MultiphaseProblem, Trajectory]:
        """`whole_cycle` for a trajectory: the whole cycle's problem and the trajectory unrolled over it (both as given
        without a mirror). Whatever samples or replays a gait periodically starts here, so a half cycle is never
        repeated as if it were the whole."""
        return self.full_cycle(), self.unroll(trajectory)

    def whole_cycle(self, x: np.ndarray) -> tuple[MultiphaseProblem, np.ndarray]:
        """A point x of this problem as the whole cycle's problem (`full_cycle`) and its point: unrolled if this is a
        mirrored half cycle (`unroll`), so that what follows (outputs, the violation re-evaluated, a replay) sees the
        whole gait."""
        if self.mirror is None:
            return self, x
        whole = self.full_cycle()
        return whole, whole.pack(self.unroll(self.unpack(x)))

    # ------------------------------------------------------------------ packing
    def pack(self, trajectory: Trajectory) -> np.ndarray:
        """The variable vector of a trajectory (an initial guess or a neighbouring problem's solution)."""
        x = np.zeros(self.n)
        for k, index in enumerate(self.point_index):
            parts = [trajectory.q[k], trajectory.v[k], trajectory.u[k]]
            count = len(self.phases[k].contacts)
            forces = np.asarray(trajectory.forces[k], dtype=np.float64).reshape(len(index), count, 3)
            parts.append((forces if self.force_dims == 3 else forces[..., 2:]).reshape(len(index), -1))
            flat = len(self.flat_contacts(self.phases[k].contacts))
            parts.append(np.zeros((len(index), 3 * flat)) if trajectory.torques is None else trajectory.torques[k])
            z = np.concatenate([np.asarray(p, dtype=np.float64).reshape(len(index), -1) for p in parts], axis=1)
            a = trajectory.a[k] if trajectory.a is not None else self.forward_accelerations(z, k)
            z = np.concatenate([z, np.asarray(a, dtype=np.float64).reshape(len(index), -1)], axis=1)
            slack = np.zeros((len(index), index.shape[1] - z.shape[1])) if trajectory.slack is None else trajectory.slack[k]
            z = np.concatenate([z, np.asarray(slack, dtype=np.float64).reshape(len(index), -1)], axis=1)
            if z.shape != index.shape:
                raise ValueError(f"trajectory phase {k} has {z.shape} point values, the problem needs {index.shape}")
            x[index] = z
        x[self.duration_index] = trajectory.durations
        x[self.p1_index] = trajectory.stability_bound
        for k, index in self.impulse_index.items():  # least-squares impulses of the trajectory's own velocity jump
            end, start = self.point_index[k][-1], self._start_seen_from(k)
            q = x[end[: self.nq]][None]
            jump = np.asarray(lk.crba(self.model, self.configuration(q)))[0] @ (start.v_sign * x[start.v] - x[end[self.nq : self.nx]])
            x[index] = np.linalg.lstsq(self.contact_jacobian(q, self.contacts_after(k))[0].T, jump, rcond=None)[0]
        return x

    def point(self, x: object, name: str = "x") -> np.ndarray:
        """x as a point of this problem: finite float64 of shape (n,) (TypeError or ValueError naming `name`)."""
        return float_array(x, name, shape=(self.n,))

    def unpack(self, x: np.ndarray) -> Trajectory:
        x = self.point(x)
        durations = x[self.duration_index].copy()
        starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        t, q, v, u, forces, a, torques, slack = [], [], [], [], [], [], [], []
        for k, index in enumerate(self.point_index):
            z = x[index]
            torques.append(z[:, self.torque_columns[k]].reshape(len(z), -1, 3))
            slack.append(z[:, self.slack_columns[k]])
            t.append(starts[k] + np.linspace(0.0, durations[k], len(index)))
            q.append(z[:, : self.nq])
            v.append(z[:, self.nq : self.nx])
            u.append(z[:, self.nx : self.nx + self.nu])
            forces.append(self.world_forces(z[:, self.force_columns[k]], len(self.phases[k].contacts)))
            a.append(self.accelerations(z, k))
        return Trajectory(t, q, v, u, forces, durations, float(x[self.p1_index]), a, torques, slack)


def _period_bounds(period: float | tuple[float, float]) -> tuple[float, float]:
    """(lower, upper) of a period given as a value or as bounds."""
    # np.isscalar does not narrow the union for mypy; the cast states what it guarantees.
    return (cast(float, period), cast(float, period)) if np.isscalar(period) else cast(tuple[float, float], period)


def _same_rotation(pair: np.ndarray) -> np.ndarray:
    """(B, 3): vector parts of two [x, y, z, w] quaternions (B, 8), each normalised, subtracted."""
    first, second = pair[:, :4], pair[:, 4:]
    return first[:, :3] / np.linalg.norm(first, axis=1, keepdims=True) - second[:, :3] / np.linalg.norm(second, axis=1, keepdims=True)


def _same_rotation_block(index: np.ndarray, signs: np.ndarray) -> Point:
    """`_same_rotation` of the quaternion pair x[index] (8,), each component times its sign first."""
    def slopes(pair: np.ndarray) -> np.ndarray:  # d(vector / |q|) / dq = [I 0] / |q| - vector q^T / |q|^3, per quaternion
        out = np.empty((len(pair), 3, 8))
        for half, sign in ((slice(0, 4), 1.0), (slice(4, 8), -1.0)):
            quaternion = signs[half] * pair[:, half]
            norm = np.linalg.norm(quaternion, axis=1)[:, None, None]
            part = -quaternion[:, :3, None] * quaternion[:, None, :] / norm**3
            part[:, :, :3] += np.eye(3) / norm
            out[:, :, half] = sign * part * signs[half]
        return out

    return Point(index[None], lambda pair: _same_rotation(signs * pair), 3, derivative=slopes)


@dataclass(frozen=True)
class _Start:
    """The point after a phase boundary, as the phase before sees it: the variables of its q, v and u and the
    signs that turn them into the earlier phase's frame (all 1, except across the wrap-around of a mirrored
    half cycle, where q_sign * x[q] is the mirror of the start's configuration, and so on)."""

    q: np.ndarray
    q_sign: np.ndarray
    v: np.ndarray
    v_sign: np.ndarray
    u: np.ndarray
    u_sign: np.ndarray


class _Defects:
    """The Hermite–Simpson defects of one phase (`collocation` docstring); h = T / intervals, T a variable."""

    def __init__(self, problem: MultiphaseProblem, k: int) -> None:
        self.problem, self.k = problem, k
        index = problem.point_index[k]
        self.index, self.duration, self.intervals = index, problem.duration_index[k], problem.phases[k].intervals
        nx, nz = problem.nx, index.shape[1]
        self.size = 2 * nx * self.intervals
        self.lower = self.upper = np.zeros(self.size)
        # Structural pattern of one interval: rows [interpolation; Simpson] x cols [z_a, z_m, z_b, T].
        dependence, _ = problem.rate_dependence(k)
        select = np.zeros((nx, nz), dtype=bool)
        select[:, :nx] = np.eye(nx, dtype=bool)
        column = np.ones((nx, 1), dtype=bool)
        self.mask = np.block([[select | dependence, select, select | dependence, column],
                              [select | dependence, dependence, select | dependence, column]])
        interval = np.arange(self.intervals)
        cols = np.concatenate([index[2 * interval], index[2 * interval + 1], index[2 * interval + 2],
                               np.full((self.intervals, 1), self.duration)], axis=1)  # (N, 3 nz + 1)
        r, c = np.nonzero(self.mask)
        self.rows = (interval[:, None] * 2 * nx + r[None]).ravel()
        self.cols = cols[:, c].ravel()
        self._r, self._c = r, c
        # Curvature: each point's weighted rate, linear in v, a and the slack for a given q (v + J_c(q)^T slack enters
        # R(q) v_lin, q (x) w and the joint rates linearly), so differenced along q alone; and T with every variable
        # the rate depends on (the defects hold h f = T f / N).
        self._nonlinear = problem.q_without_translation
        self._seen = np.flatnonzero(dependence.any(axis=0))
        rows_h, cols_h, self._local = group_pattern(index, self._nonlinear)
        self.hessian_rows = np.concatenate([rows_h, np.full(index[:, self._seen].size, self.duration)])
        self.hessian_cols = np.concatenate([cols_h, index[:, self._seen].ravel()])

    def values(self, x: np.ndarray) -> np.ndarray:
        z = x[self.index]
        rates, states = self.problem.rate(z, self.k), z[:, : self.problem.nx]
        interpolation, simpson = hermite_simpson_defects(states[0::2], states[1::2], rates[0::2], rates[1::2],
                                                         x[self.duration] / self.intervals)
        return np.concatenate([interpolation, simpson], axis=1).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        nx, n_int = self.problem.nx, self.intervals
        z = x[self.index]
        rates, jac = self.problem.rate(z, self.k), self.problem.rate_jacobian(z, self.k)
        nz = z.shape[1]
        h = x[self.duration] / n_int
        eye = np.zeros((nx, nz))
        eye[:, :nx] = np.eye(nx)
        ja, jm, jb = jac[0:-1:2], jac[1::2], jac[2::2]
        fa, fm, fb = rates[0:-1:2], rates[1::2], rates[2::2]
        block = np.zeros((n_int, 2 * nx, 3 * nz + 1))
        block[:, :nx, :nz] = -0.5 * eye - h / 8.0 * ja
        block[:, :nx, nz : 2 * nz] = eye
        block[:, :nx, 2 * nz : 3 * nz] = -0.5 * eye + h / 8.0 * jb
        block[:, :nx, -1] = -(fa - fb) / (8.0 * n_int)
        block[:, nx:, :nz] = -eye - h / 6.0 * ja
        block[:, nx:, nz : 2 * nz] = -4.0 * h / 6.0 * jm
        block[:, nx:, 2 * nz : 3 * nz] = eye - h / 6.0 * jb
        block[:, nx:, -1] = -(fa + 4.0 * fm + fb) / (6.0 * n_int)
        return block[:, self._r, self._c].ravel()

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        problem, k = self.problem, self.k
        z, duration = x[self.index], x[self.duration]
        h = duration / self.intervals
        interpolation, simpson = np.moveaxis(multipliers.reshape(self.intervals, 2, problem.nx), 1, 0)
        weights = np.zeros((len(z), problem.nx))  # of each point's rate in sum mu . defects (knots in two intervals)
        weights[0:-1:2] -= h * (interpolation / 8.0 + simpson / 6.0)
        weights[1::2] -= h * 4.0 * simpson / 6.0
        weights[2::2] += h * (interpolation / 8.0 - simpson / 6.0)
        curvature = group_hessian(lambda zz, ww: problem.rate_gradient(zz, ww, k), z, weights, self._nonlinear)
        by_duration = problem.rate_gradient(z, weights, k) / duration
        return np.concatenate([curvature.ravel()[self._local], by_duration[:, self._seen].ravel()])


class _InverseDynamics:
    """Eq. 1 in inverse-dynamics form at every point of the phases ks (phases with one layout of the point
    variables: as many feet, and flat feet, on the ground): rnea(q, v, a, J_c^T lambda) - B u = 0 (nv rows per
    point). d/d(q, v) by `lk.rnea_derivatives` in one batched call for all of them, with the world-fixed foot
    forces' turning term (`kinematics.force_slope`); the rows are affine in a, u and the foot loads: d/da = M(q)
    (`crba`), d/du = -B, d/dlambda = -J^T (each foot point's world-aligned linear Jacobian) and, for a flat foot's
    torques, -J_w^T (its body's angular Jacobian in the body frame). No row depends on a free-flyer's position.
    The pattern follows the tree (`MultiphaseProblem.tree_dependence`)."""

    def __init__(self, problem: MultiphaseProblem, ks: Sequence[int]) -> None:
        self.problem, self.ks = problem, list(ks)
        nq, nv, nx, nu = problem.nq, problem.nv, problem.nx, problem.nu
        self.index = np.concatenate([problem.point_index[k] for k in self.ks])
        points, nz = self.index.shape
        self.size = points * nv
        self.lower = self.upper = np.zeros(self.size)
        first = self.ks[0]  # the layout is the same in every phase of the block
        self.force_columns, self.torque_columns = problem.force_columns[first], problem.torque_columns[first]
        self.a_columns = problem.a_columns[first]
        vv, vq, reach = problem.tree_dependence()
        forces = np.arange(nz)[self.force_columns].reshape(-1, problem.force_dims)
        torques = np.arange(nz)[self.torque_columns].reshape(-1, 3)
        self.forces, self.torques = forces, torques
        # Per phase: its points in the block, its contacts and the nonzeros (r, c) of one point's rows.
        self._parts: list[tuple[slice, tuple[str, ...], np.ndarray, np.ndarray]] = []
        rows, cols, contacts = [], [], []
        start = 0
        for k in self.ks:
            phase_contacts = problem.phases[k].contacts
            mask = np.zeros((nv, nz), dtype=bool)
            mask[:, :nq], mask[:, nq:nx], mask[:, self.a_columns] = vq, vv, vv
            mask[problem.actuated, nx + np.arange(nu)] = True
            for c, name in enumerate(phase_contacts):
                mask[np.ix_(reach[name], forces[c])] = True
            for c, name in enumerate(problem.flat_contacts(phase_contacts)):
                mask[np.ix_(reach[name], torques[c])] = True
            r, nonzero_cols = np.nonzero(mask)
            count = len(problem.point_index[k])
            rows.append(((start + np.arange(count))[:, None] * nv + r[None]).ravel())
            cols.append(problem.point_index[k][:, nonzero_cols].ravel())
            self._parts.append((slice(start, start + count), phase_contacts, r, nonzero_cols))
            contacts += [phase_contacts] * count
            start += count
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)
        self.feet = problem.contact_points(contacts)
        # Curvature: the rows are nonlinear in q (not a free-flyer's position) and v only; differenced along q, and
        # d2/dv2 (C(q, v) v is quadratic in v) from `lk.rnea_second_order_derivatives`.
        self._nonlinear = problem.q_without_translation
        patterns = [group_pattern(self.index[points], np.r_[self._nonlinear, nq:nx]) for points, *_ in self._parts]
        self.hessian_rows = np.concatenate([rows for rows, _, _ in patterns])
        self.hessian_cols = np.concatenate([cols for _, cols, _ in patterns])
        self._local = [local for _, _, local in patterns]

    def residual(self, z: np.ndarray, feet: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        """The rows at the block's point variables z (B, nz), row b with the feet of row b of `feet`
        (`MultiphaseProblem.contact_points`) down."""
        problem = self.problem
        q = problem.configuration(z[:, : problem.nq])
        f_ext = problem.point_wrenches(q, z[:, self.force_columns], *feet, z[:, self.torque_columns])
        generalized = np.asarray(lk.rnea(problem.model, q, z[:, problem.nq : problem.nx], z[:, self.a_columns], f_ext))
        return generalized - problem.tau(z[:, problem.nx : problem.nx + problem.nu])

    def values(self, x: np.ndarray) -> np.ndarray:
        return self.residual(x[self.index], self.feet).ravel()

    def dense(self, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """(B, nv, nz): the rows' Jacobian at point variables z (B, nz) with `contacts` down."""
        problem, model = self.problem, self.problem.model
        nq, nx = problem.nq, problem.nx
        q = problem.configuration(z[:, :nq])
        f_ext = problem.point_wrenches(q, z[:, self.force_columns], *problem.contact_points([contacts]), z[:, self.torque_columns])
        by_q, by_v = (np.asarray(d) for d in lk.rnea_derivatives(model, q, z[:, nq:nx], z[:, self.a_columns], f_ext))
        jac = np.zeros((len(z), problem.nv, z.shape[1]))
        jac[:, :, nq:nx] = by_v
        jac[:, :, self.a_columns] = np.asarray(lk.crba(model, q))
        jac[:, problem.actuated, nx + np.arange(problem.nu)] = -1.0
        forces = problem.world_forces(z[:, self.force_columns], len(contacts))
        axes = slice(3 - problem.force_dims, 3)  # the world axes the force variables hold
        full = kin.point_jacobians(model, q, [(problem.foot_body[name], problem.foot_point[name]) for name in contacts])
        for foot in range(len(contacts)):
            jac[:, :, self.forces[foot]] = -np.swapaxes(full[:, foot, axes], 1, 2)
        # rnea_derivatives holds the loads in their bodies' frames; the forces are world-fixed (`force_slope`).
        by_q -= np.einsum("bcki,bckl,bclj->bij", full[:, :, :3], kin.skew(forces), full[:, :, 3:])
        for foot, name in enumerate(problem.flat_contacts(contacts)):
            angular = np.asarray(lk.jacobian(model, q, problem.foot_body[name], None, "local"))
            jac[:, :, self.torques[foot]] = -angular[:, 3:].transpose(0, 2, 1)
        jac[:, :, :nq] = kin.raw(model, z[:, :nq], by_q)
        return jac

    def gradient(self, z: np.ndarray, weights: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """weights . d rows / dz (B, nz) for weights (B, nv): `dense`'s vector product, without forming it."""
        problem, model = self.problem, self.problem.model
        nq, nx = problem.nq, problem.nx
        q = problem.configuration(z[:, :nq])
        f_ext = problem.point_wrenches(q, z[:, self.force_columns], *problem.contact_points([contacts]), z[:, self.torque_columns])
        by_q, by_v = (np.asarray(d) for d in lk.rnea_derivatives(model, q, z[:, nq:nx], z[:, self.a_columns], f_ext))
        out = np.zeros_like(z)
        on_q = kin.vecmat(weights, by_q)
        out[:, nq:nx] = kin.vecmat(weights, by_v)
        out[:, self.a_columns] = kin.matvec(np.asarray(lk.crba(model, q)), weights)
        out[:, nx + np.arange(problem.nu)] = -weights[:, problem.actuated]
        forces = problem.world_forces(z[:, self.force_columns], len(contacts))
        axes = slice(3 - problem.force_dims, 3)
        full = kin.point_jacobians(model, q, [(problem.foot_body[name], problem.foot_point[name]) for name in contacts])
        moved = np.einsum("bckj,bj->bck", full, weights)  # each foot frame's velocity under the weights
        for foot in range(len(contacts)):
            out[:, self.forces[foot]] = -moved[:, foot, axes]
        on_q -= np.einsum("bck,bckl,bclj->bj", moved[:, :, :3], kin.skew(forces), full[:, :, 3:])
        for foot, name in enumerate(problem.flat_contacts(contacts)):
            angular = np.asarray(lk.jacobian(model, q, problem.foot_body[name], None, "local"))
            out[:, self.torques[foot]] = -np.einsum("bkj,bj->bk", angular[:, 3:], weights)
        out[:, :nq] = kin.raw(model, z[:, :nq], on_q[:, None, :])[:, 0]
        return out

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        z = x[self.index]
        return np.concatenate([self.dense(z[points], contacts)[:, r, c].ravel() for points, contacts, r, c in self._parts])

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        z, weights = x[self.index], multipliers.reshape(len(self.index), self.problem.nv)
        out = []
        for (points, contacts, _, _), local in zip(self._parts, self._local):
            def gradient(zz: np.ndarray, ww: np.ndarray, contacts: Sequence[str] = contacts) -> np.ndarray:
                return self.gradient(zz, ww, contacts)

            curvature = group_hessian(gradient, z[points], weights[points], self._nonlinear)
            nq, nx = self.problem.nq, self.problem.nx
            part = z[points]
            by_vv = lk.rnea_second_order_derivatives(self.problem.model, self.problem.configuration(part[:, :nq]), part[:, nq:nx],
                                                     part[:, self.a_columns])[1]
            curvature[:, nq:nx, nq:nx] += np.einsum("bi,bijk->bjk", weights[points], np.asarray(by_vv))
            out.append(curvature.ravel()[local])
        return np.concatenate(out)


class _Feet:
    """The feet at the points of phase k, from one batched forward-kinematics difference over q: stance feet
    on the ground (height 0) and, with 3-D forces, at the foothold where the phase began (x, y) at every knot
    (with their velocities and accelerations: `stance_blocks`); swing tips at or above the ground (eq. 4) at
    every point. A flat foot's toe and side points (`FlatFoot`) are at height 0 in stance, the
    toe also at its first y (the sole flat and unturned), and at or above the ground in swing.

    A phase's first point is the previous phase's last (the same q, up to the periodic shift along the ground),
    so a foot's height there is stated once: a foot down on both sides of the boundary by the earlier phase,
    a lifting foot by the earlier phase's height = 0, a landing foot by the later phase's height = 0. Stating
    it twice would make the constraint Jacobian rank-deficient (LICQ fails; IPOPT's multipliers diverge)."""

    def __init__(self, problem: MultiphaseProblem, k: int) -> None:
        self.problem = problem
        index = problem.point_index[k]
        self.index = index[:, : problem.nq]
        names = problem.foot_names + list(problem.sole_points)
        owner = [problem.sole_points.get(name, name) for name in names]  # the foot a sole point belongs to
        self.names = names
        points, nq, count = len(index), problem.nq, len(names)
        tree, q_body, _ = problem.tree()
        ancestors = {name: tree[problem.foot_body[name]] for name in names}
        rows, cols, source, sign, unilateral, output, anchor_output = [], [], [], [], [], [], []
        row = 0

        def add(point: int, foot: int, axis: int, above: bool, anchor: bool) -> None:
            nonlocal row
            reach = np.flatnonzero(np.isin(q_body, list(ancestors[names[foot]])))
            flat = (point * count * 3 + foot * 3 + axis) * nq  # jac is (P, count * 3, nq)
            rows.append(np.full(len(reach), row))
            cols.append(index[point, reach])
            source.append(flat + reach)
            sign.append(np.ones(len(reach)))
            if anchor:  # minus the same coordinate at the phase's first point
                rows.append(np.full(len(reach), row))
                cols.append(index[0, reach])
                source.append((foot * 3 + axis) * nq + reach)
                sign.append(-np.ones(len(reach)))
            unilateral.append(above)
            output.append(point * count * 3 + foot * 3 + axis)
            anchor_output.append(foot * 3 + axis if anchor else -1)
            row += 1

        count_phases = len(problem.phases)
        linked = problem.periodic and count_phases > 1
        before = problem.contacts_before(k) if (k > 0 or linked) else None
        after = problem.contacts_after(k) if (k < count_phases - 1 or linked) else None
        for point in range(points):
            for foot, (name, foot_name) in enumerate(zip(names, owner)):
                if (point == 0 and before is not None and foot_name in before) or (
                        point == points - 1 and after is not None and foot_name in after and foot_name not in problem.phases[k].contacts):
                    continue  # the height at this shared point is stated by the neighbouring phase
                if foot_name in problem.phases[k].contacts:
                    if point % 2:  # a midpoint: the slack frees it (`MultiphaseProblem.rate`)
                        continue
                    add(point, foot, 2, False, False)
                    if name == foot_name and problem.force_dims == 3 and point > 0:
                        add(point, foot, 0, False, True)
                        add(point, foot, 1, False, True)
                    elif name.endswith("/toe") and point > 0:
                        add(point, foot, 1, False, True)
                else:
                    add(point, foot, 2, True, False)  # swing: height >= 0
        self.size = row
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)
        self._source, self._sign = np.concatenate(source), np.concatenate(sign)
        self.lower = np.zeros(row)
        self.upper = np.where(unilateral, problem.max_swing_height, 0.0)
        self._output, self._anchor = np.array(output), np.array(anchor_output)
        self.hessian_rows, self.hessian_cols, self._local = group_pattern(self.index, problem.q_without_translation)

    def _positions(self, q: np.ndarray) -> np.ndarray:
        return self.problem.foot_positions(q, self.names).reshape(len(q), -1)

    def values(self, x: np.ndarray) -> np.ndarray:
        positions = self._positions(x[self.index]).ravel()
        return positions[self._output] - np.where(self._anchor >= 0, positions[np.maximum(self._anchor, 0)], 0.0)

    def _slopes(self, q: np.ndarray) -> np.ndarray:
        """(B, feet x 3, nq): the positions' Jacobian at raw q (B, nq)."""
        problem = self.problem
        points = [(problem.foot_body[name], problem.foot_point[name]) for name in self.names]
        linear = kin.point_jacobians(problem.model, problem.configuration(q), points)[:, :, :3]  # (B, feet, 3, nv)
        return kin.raw(problem.model, q, linear.reshape(len(q), -1, problem.nv))

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self._sign * self._slopes(x[self.index]).ravel()[self._source]

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        q = x[self.index]
        # Each row's multiplier weighs its position and, for an anchored row, minus the first point's.
        anchored = self._anchor >= 0
        size = len(q) * 3 * len(self.names)
        weights = np.bincount(self._output, multipliers, minlength=size) - np.bincount(self._anchor[anchored], multipliers[anchored], minlength=size)
        curvature = group_hessian(weighted(self._slopes), q, weights.reshape(len(q), -1), self.problem.q_without_translation)
        return curvature.ravel()[self._local]


def _input_power(loss: float) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """(B, 2) points (u, w) -> (B, 1) input powers loss u^2 + u w [W], and its slopes (B, 1, 2)."""
    def power(z: np.ndarray) -> np.ndarray:
        return (loss * z[:, 0] ** 2 + z[:, 0] * z[:, 1])[:, None]

    def slopes(z: np.ndarray) -> np.ndarray:
        return np.stack([2.0 * loss * z[:, 0] + z[:, 1], z[:, 0]], axis=1)[:, None, :]

    return power, slopes
