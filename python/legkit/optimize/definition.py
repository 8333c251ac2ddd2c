"""What a multiphase transcription is given: its contact phases, flat soles and motor limits (`Phase`,
`FlatFoot`, `TorqueSpeedLine`, `InputPower`), and `ProblemDefinition`, the fields of a `MultiphaseProblem`,
checked when it is made. The bottom of the optimiser's house: it imports no other module of it but `mirror`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np

import legkit as lk
from legkit.optimize.mirror import Mirror

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
class ProblemDefinition:
    """The fields of a `MultiphaseProblem` (whose docstring documents them), validated on construction: the layers
    above (`legkit.optimize.layout`, `contact`, the constraint families, `assembly`) read them."""

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
    max_yaw: float = np.inf  # [rad] a free-flyer's yaw at every point (`constraints.limits.yaw_blocks`)
    max_force_rate: float = np.inf  # [N/s] on every component of every stance foot's force (`constraints.rates.load_rate_blocks`)
    max_torque_rate: float = np.inf  # [N m/s] on every actuated torque (`constraints.rates.load_rate_blocks`)

    def __post_init__(self) -> None:
        self._validate()

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
            lo, hi = period_bounds(self.period)
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



def period_bounds(period: float | tuple[float, float]) -> tuple[float, float]:
    """(lower, upper) of a period given as a value or as bounds."""
    # np.isscalar does not narrow the union for mypy; the cast states what it guarantees.
    return (cast(float, period), cast(float, period)) if np.isscalar(period) else cast(tuple[float, float], period)
