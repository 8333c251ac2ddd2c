"""A quadruped like the Sony four-legged robot of Hardt & von Stryk (RoboCup 2002), and URDF export.

Torso frame: origin at the torso's geometric centre, x forward, y left, z up. The heavy head is fixed to the
front of the torso. Each leg (lf, rf, lh, rh: left/right, fore/hind) hangs from a hip point on the torso
underside through a 2-DoF universal hip, roll about x first (abduction, body `<leg>_hip`, massless) then
pitch about y (`<leg>_thigh`), and a 1-DoF knee about y (`<leg>_shank`). At zero angles every leg points
straight down; the foot is the point at the end of the shank. Positive pitch swings the foot backwards
(toward -x), as a right-handed rotation about +y does to a point below the axis.

Free-flyer base: nq = 7 + 12 = 19, nv = 6 + 12 = 18, 12 actuated joints ordered leg by leg
(lf, rf, lh, rh), each (hip roll, hip pitch, knee).

The default numbers are an AIBO-ERS-210-sized robot (about 1.6 kg, 0.15 m legs); the paper's own
parameter table was not at hand, so every value is a documented, overridable field of
`QuadrupedParameters`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import choice, float_array, instance, parameter_fields
from legkit.robots.legs import FreeFlyerUrdf, box_trunk, limb_segment, roll_pitch_knee_ik

LEGS = ("lf", "rf", "lh", "rh")
#: Diagonal leg pairs and lateral leg pairs (support lines of a two-legged stance).
DIAGONAL_PAIRS = (("lf", "rh"), ("rf", "lh"))
LATERAL_PAIRS = (("lf", "lh"), ("rf", "rh"))


@dataclass(frozen=True)
class QuadrupedParameters:
    """Geometry [m] and masses [kg] of the quadruped; override any field: QuadrupedParameters(head_mass=0.4)."""

    torso_mass: float = 0.80
    torso_size: tuple[float, float, float] = (0.18, 0.10, 0.08)  # x, y, z edge lengths of the torso box
    head_mass: float = 0.30
    head_size: tuple[float, float, float] = (0.07, 0.07, 0.07)
    head_position: tuple[float, float, float] = (0.12, 0.0, 0.05)  # head box centre in the torso frame
    hip_x: float = 0.065  # fore hips at +hip_x, hind hips at -hip_x
    hip_y: float = 0.055  # left hips at +hip_y, right hips at -hip_y
    hip_z: float = -0.03  # hip height in the torso frame
    thigh_length: float = 0.070
    thigh_mass: float = 0.08
    shank_length: float = 0.075
    shank_mass: float = 0.04
    link_width: float = 0.02  # square cross-section of thigh and shank boxes
    knee_direction: dict[str, float] = field(
        default_factory=lambda: {"lf": -1.0, "rf": -1.0, "lh": 1.0, "rh": 1.0}
    )  # sign of the knee angle in the inverse kinematics: fore knees bend backwards (elbow), hind forwards

    def __post_init__(self) -> None:
        parameter_fields(
            self, positive=("torso_mass", "torso_size", "head_mass", "head_size", "thigh_mass", "shank_mass", "thigh_length",
                            "shank_length", "link_width"),
            real=("head_position", "hip_x", "hip_y", "hip_z"),
        )
        if not isinstance(self.knee_direction, dict):
            raise TypeError(f"knee_direction must be a dict, got {type(self.knee_direction).__name__}")
        if set(self.knee_direction) != set(LEGS) or any(abs(s) != 1.0 for s in self.knee_direction.values()):
            raise ValueError(f"knee_direction must map each of {LEGS} to +1 or -1, got {self.knee_direction}")

    def hip_position(self, leg: str) -> np.ndarray:
        """Hip point of `leg` in the torso frame [m]."""
        fore = 1.0 if leg[1] == "f" else -1.0
        left = 1.0 if leg[0] == "l" else -1.0
        return np.array([fore * self.hip_x, left * self.hip_y, self.hip_z])

    @property
    def total_mass(self) -> float:
        return self.torso_mass + self.head_mass + 4.0 * (self.thigh_mass + self.shank_mass)


@dataclass
class Quadruped(FreeFlyerUrdf):
    """The built quadruped: its legkit model, parameters and foot contact points."""

    model: lk.Model
    parameters: QuadrupedParameters
    urdf_name: ClassVar[str] = "quadruped"

    @property
    def feet(self) -> dict[str, tuple[str, np.ndarray]]:
        """Contact point of each leg: (body name, point in that body's frame [m])."""
        tip = np.array([0.0, 0.0, -self.parameters.shank_length])
        return {leg: (f"{leg}_shank", tip.copy()) for leg in LEGS}

    def contacts(self, legs: tuple[str, ...] = LEGS) -> list[tuple[int, np.ndarray]]:
        """Contact list for `lk.contact_dynamics` / `lk.jacobian`: (body index, point) of each leg in `legs`."""
        if isinstance(legs, str):
            raise TypeError(f"legs must be a tuple of leg names, got the string {legs!r}")
        for leg in legs:
            choice(leg, LEGS, "legs")
        return [(self.model.names.index(self.feet[leg][0]), self.feet[leg][1]) for leg in legs]

    def joint_slice(self, leg: str) -> slice:
        """Indices of `leg`'s three joints (roll, pitch, knee) in v (q is the same plus one)."""
        choice(leg, LEGS, "leg")
        first = self.model.idx_v[self.model.names.index(f"{leg}_hip")]
        return slice(first, first + 3)

    def leg_angles(self, leg: str, foot_in_torso: npt.ArrayLike) -> np.ndarray:
        """(..., 3) joint angles (hip roll, hip pitch, knee) [rad] that put the foot of `leg` at
        foot_in_torso (..., 3) [m, torso frame]. Raises ValueError when out of reach."""
        choice(leg, LEGS, "leg")
        p = self.parameters
        relative = float_array(foot_in_torso, "foot_in_torso", last=3) - p.hip_position(leg)
        return roll_pitch_knee_ik(relative, p.thigh_length, p.shank_length, p.knee_direction[leg])


def build_quadruped(parameters: QuadrupedParameters | None = None) -> Quadruped:
    """The quadruped of the module docstring as an `lk.Model` with a free-flyer torso."""
    p = QuadrupedParameters() if parameters is None else parameters
    instance(p, QuadrupedParameters, "parameters")
    model = box_trunk("torso", p.torso_mass, p.torso_size, "head", p.head_mass, p.head_size, p.head_position)
    knee = (np.eye(3), [0.0, 0.0, -p.thigh_length])
    for leg in LEGS:
        hip = model.add_revolute("torso", [1.0, 0.0, 0.0], (np.eye(3), p.hip_position(leg)), None, f"{leg}_hip")
        thigh = model.add_revolute(hip, [0.0, 1.0, 0.0], None, limb_segment(p.thigh_mass, p.thigh_length, p.link_width), f"{leg}_thigh")
        model.add_revolute(thigh, [0.0, 1.0, 0.0], knee, limb_segment(p.shank_mass, p.shank_length, p.link_width), f"{leg}_shank")
    return Quadruped(model, p)
