"""A biped as in Hardt & von Stryk (RoboCup 2002): hip 3, knee 1, foot 2 DoF per leg, 2 DoF per shoulder.

Pelvis frame (the free-flyer base): origin at the hip-joint midpoint, x forward, y left, z up. A torso box
is fixed on top of the pelvis. Each leg (l, r) hangs from a hip point through hip yaw (z, body
`<s>_hip_yaw`), hip roll (x, `<s>_hip_roll`), hip pitch (y, `<s>_thigh`), knee (y, `<s>_shank`), ankle
pitch (y, `<s>_ankle`) and ankle roll (x, `<s>_foot`); the yaw/roll/ankle bodies are massless joint
frames. Each arm hangs from a shoulder point through shoulder pitch (y, `<s>_shoulder`, massless) and
shoulder roll (x, `<s>_arm`). At zero angles legs and arms point straight down and the soles are flat.
The foot frame sits at the ankle; its sole is the rectangle x in [-heel, toe], y in [-half_width,
half_width] at z = -ankle_height, whose four corners are the foot's contact points.

Free-flyer base: nq = 7 + 16 = 23, nv = 6 + 16 = 22, 16 actuated joints: left leg (6), right leg (6),
left arm (2), right arm (2). Defaults are an adult-sized walking machine (about 42 kg, 0.84 m legs) that
walks at the paper's 1.8 km/h; every value is an overridable field of `BipedParameters`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import choice, float_array, instance, parameter_fields
from legkit.robots.legs import FreeFlyerUrdf, box_trunk, limb_segment, roll_pitch_knee_ik

SIDES = ("l", "r")
LEG_JOINTS = ("hip_yaw", "hip_roll", "thigh", "shank", "ankle", "foot")  # body names after the side prefix
#: The joint each body's revolute joint is, by body name after the side prefix (legs, then arms).
JOINT_LABELS = {"hip_yaw": "hip yaw", "hip_roll": "hip roll", "thigh": "hip pitch", "shank": "knee", "ankle": "ankle pitch",
                "foot": "ankle roll", "shoulder": "shoulder pitch", "arm": "shoulder roll"}


@dataclass(frozen=True)
class BipedParameters:
    """Geometry [m] and masses [kg] of the biped; override any field: BipedParameters(thigh_mass=6.0)."""

    pelvis_mass: float = 8.0
    pelvis_size: tuple[float, float, float] = (0.20, 0.30, 0.12)
    torso_mass: float = 12.0
    torso_size: tuple[float, float, float] = (0.20, 0.34, 0.45)
    torso_position: tuple[float, float, float] = (0.0, 0.0, 0.30)  # torso box centre in the pelvis frame
    hip_y: float = 0.10  # left hip at +hip_y, right at -hip_y, at the pelvis origin height
    thigh_length: float = 0.42
    thigh_mass: float = 5.0
    shank_length: float = 0.42
    shank_mass: float = 3.0
    link_width: float = 0.08
    ankle_height: float = 0.06  # sole below the ankle axis
    foot_mass: float = 1.0
    foot_toe: float = 0.16  # sole extends from -foot_heel to +foot_toe along x
    foot_heel: float = 0.06
    foot_half_width: float = 0.05
    shoulder_y: float = 0.21
    shoulder_z: float = 0.50  # shoulder height in the pelvis frame
    arm_length: float = 0.60
    arm_mass: float = 2.0

    def __post_init__(self) -> None:
        parameter_fields(self, positive=[f.name for f in fields(self) if f.name != "torso_position"], real=("torso_position",))

    @property
    def total_mass(self) -> float:
        legs = self.thigh_mass + self.shank_mass + self.foot_mass
        return self.pelvis_mass + self.torso_mass + 2.0 * (legs + self.arm_mass)

    @property
    def sole(self) -> tuple[float, float, float, float]:
        """(x_back, x_front, y_right, y_left) of the sole in the foot frame, for `foot_torque_margin`."""
        return (-self.foot_heel, self.foot_toe, -self.foot_half_width, self.foot_half_width)


@dataclass
class Biped(FreeFlyerUrdf):
    """The built biped: its legkit model, parameters and sole contact points."""

    model: lk.Model
    parameters: BipedParameters
    urdf_name: ClassVar[str] = "biped"

    @property
    def feet(self) -> dict[str, list[tuple[str, np.ndarray]]]:
        """Sole corners of each foot (heel-right, heel-left, toe-left, toe-right): (body name, point in the
        foot frame [m])."""
        p = self.parameters
        z = -p.ankle_height
        corners = [
            (-p.foot_heel, -p.foot_half_width), (-p.foot_heel, p.foot_half_width), (p.foot_toe, p.foot_half_width), (p.foot_toe, -p.foot_half_width)
        ]
        return {side: [(f"{side}_foot", np.array([x, y, z])) for x, y in corners] for side in SIDES}

    def contacts(self, sides: tuple[str, ...] = SIDES) -> list[tuple[int, np.ndarray]]:
        """Contact list for `lk.contact_dynamics` / `lk.jacobian`: the four sole corners of each foot in `sides`."""
        if isinstance(sides, str):
            raise TypeError(f"sides must be a tuple of side names, got the string {sides!r}")
        for side in sides:
            choice(side, SIDES, "sides")
        return [(self.model.names.index(body), point) for side in sides for body, point in self.feet[side]]

    def joint_slice(self, side: str, limb: str = "leg") -> slice:
        """Indices in v of the six joints of a leg or the two of an arm (q index = v index + 1)."""
        choice(side, SIDES, "side")
        choice(limb, ("leg", "arm"), "limb")
        first_body = f"{side}_hip_yaw" if limb == "leg" else f"{side}_shoulder"
        first = self.model.idx_v[self.model.names.index(first_body)]
        return slice(first, first + (6 if limb == "leg" else 2))

    def leg_angles(self, side: str, ankle_in_pelvis: npt.ArrayLike) -> np.ndarray:
        """(..., 6) leg angles [rad] (hip yaw, roll, pitch, knee, ankle pitch, ankle roll) that put the ankle of
        `side` at ankle_in_pelvis (..., 3) [m, pelvis frame] with zero yaw and the sole parallel to the pelvis
        xy plane. ValueError when out of reach."""
        choice(side, SIDES, "side")
        p = self.parameters
        hip = np.array([0.0, p.hip_y if side == "l" else -p.hip_y, 0.0])
        rpk = roll_pitch_knee_ik(float_array(ankle_in_pelvis, "ankle_in_pelvis", last=3) - hip, p.thigh_length, p.shank_length, 1.0)
        roll, pitch, knee = rpk[..., 0], rpk[..., 1], rpk[..., 2]
        # R_x(roll) R_y(pitch + knee) R_y(ankle_pitch) R_x(ankle_roll) = I.
        return np.stack([np.zeros_like(roll), roll, pitch, knee, -(pitch + knee), -roll], axis=-1)


def build_biped(parameters: BipedParameters | None = None) -> Biped:
    """The biped of the module docstring as an `lk.Model` with a free-flyer pelvis."""
    p = BipedParameters() if parameters is None else parameters
    instance(p, BipedParameters, "parameters")
    model = box_trunk("pelvis", p.pelvis_mass, p.pelvis_size, "torso", p.torso_mass, p.torso_size, p.torso_position)
    foot_length = p.foot_toe + p.foot_heel
    foot_body = lk.MassProperties.solid_box(
        p.foot_mass, [foot_length, 2.0 * p.foot_half_width, p.ankle_height],
        center=[0.5 * (p.foot_toe - p.foot_heel), 0.0, -0.5 * p.ankle_height],
    )
    x, y, z = np.eye(3)
    for side in SIDES:
        sign = 1.0 if side == "l" else -1.0
        yaw = model.add_revolute("pelvis", z, (np.eye(3), [0.0, sign * p.hip_y, 0.0]), None, f"{side}_hip_yaw")
        roll = model.add_revolute(yaw, x, None, None, f"{side}_hip_roll")
        thigh = model.add_revolute(roll, y, None, limb_segment(p.thigh_mass, p.thigh_length, p.link_width), f"{side}_thigh")
        shank_body = limb_segment(p.shank_mass, p.shank_length, p.link_width)
        shank = model.add_revolute(thigh, y, (np.eye(3), [0.0, 0.0, -p.thigh_length]), shank_body, f"{side}_shank")
        ankle = model.add_revolute(shank, y, (np.eye(3), [0.0, 0.0, -p.shank_length]), None, f"{side}_ankle")
        model.add_revolute(ankle, x, None, foot_body, f"{side}_foot")
    for side in SIDES:
        sign = 1.0 if side == "l" else -1.0
        shoulder = model.add_revolute("pelvis", y, (np.eye(3), [0.0, sign * p.shoulder_y, p.shoulder_z]), None, f"{side}_shoulder")
        model.add_revolute(shoulder, x, None, limb_segment(p.arm_mass, p.arm_length, p.link_width), f"{side}_arm")
    return Biped(model, p)
