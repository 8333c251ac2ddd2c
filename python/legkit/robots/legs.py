"""Pieces shared by the legged-robot models: limb segments, two-link leg inverse kinematics, URDF export."""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar
from xml.sax.saxutils import quoteattr

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array, instance, positive_scalar


def limb_segment(mass: float, length: float, width: float) -> lk.MassProperties:
    """A uniform box limb of `length` hanging from its joint along -z."""
    return lk.MassProperties.solid_box(mass, [width, width, length], center=[0.0, 0.0, -length / 2.0])


def roll_pitch_knee_ik(foot: npt.ArrayLike, upper: float, lower: float, knee_direction: float) -> np.ndarray:
    """Closed-form inverse kinematics of a roll(x)-pitch(y)-knee(y) leg; foot (..., 3) relative to the hip.

    Forward map: foot = R_x(roll) R_y(pitch) [(0, 0, -upper) + R_y(knee) (0, 0, -lower)]. knee_direction
    (+1/-1) picks the sign of the knee angle. Returns (..., 3) [roll, pitch, knee] [rad]; ValueError when the
    foot is farther than upper + lower or closer than |upper - lower| (with 1e-12 slack), or the arguments are not
    finite (NaN would come back as angles).
    """
    f = float_array(foot, "foot", last=3)
    upper, lower = positive_scalar(upper, "upper"), positive_scalar(lower, "lower")
    if knee_direction not in (1, -1):
        raise ValueError(f"knee_direction: must be +1 or -1, got {knee_direction!r}")
    roll = np.arctan2(f[..., 1], -f[..., 2])
    wx, wz = f[..., 0], -np.hypot(f[..., 1], f[..., 2])
    reach_sq = wx * wx + wz * wz
    cos_knee = (reach_sq - upper * upper - lower * lower) / (2.0 * upper * lower)
    if np.any(np.abs(cos_knee) > 1.0 + 1e-12):
        raise ValueError(
            f"foot target out of reach: hip-to-foot distance {np.sqrt(reach_sq.max()):.4f} m outside "
            f"[{abs(upper - lower):.4f}, {upper + lower:.4f}] m"
        )
    knee = knee_direction * np.arccos(np.clip(cos_knee, -1.0, 1.0))
    pitch = np.arctan2(-wx, -wz) - np.arctan2(lower * np.sin(knee), upper + lower * np.cos(knee))
    return np.stack([roll, pitch, knee], axis=-1)


def _rpy(rotation: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    pitch = float(np.arcsin(np.clip(-rotation[2, 0], -1.0, 1.0)))
    if abs(rotation[2, 0]) < 1.0 - 1e-12:
        return float(np.arctan2(rotation[2, 1], rotation[2, 2])), pitch, float(np.arctan2(rotation[1, 0], rotation[0, 0]))
    return 0.0, pitch, float(np.arctan2(-rotation[0, 1], rotation[1, 1]))  # gimbal lock: fold roll into yaw


def _numbers(values: npt.ArrayLike) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(values))


def _inertial(body: lk.MassProperties) -> str:
    if body.mass <= 0.0:
        return ""
    i = [repr(float(x)) for x in np.ravel(body.inertia)]
    return (
        f'<inertial><origin xyz="{_numbers(body.com)}" rpy="0 0 0"/><mass value="{float(body.mass)!r}"/>'
        f'<inertia ixx="{i[0]}" ixy="{i[1]}" ixz="{i[2]}" iyy="{i[4]}" iyz="{i[5]}" izz="{i[8]}"/>'
        "</inertial>"
    )


def box_trunk(base_name: str, base_mass: float, base_size: Sequence[float], part_name: str, part_mass: float,
              part_size: Sequence[float], part_position: Sequence[float]) -> lk.Model:
    """A free-flyer model whose base is a solid box with a second box fixed to it at part_position [m] in the base's
    frame: the trunk the legged robots' limbs are added to (the biped's torso on its pelvis, the quadruped's head on
    its torso)."""
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(base_mass, list(base_size)), base_name=base_name)
    model.add_fixed(base_name, (np.eye(3), list(part_position)), lk.MassProperties.solid_box(part_mass, list(part_size)), part_name)
    return model


class FreeFlyerUrdf:
    """`to_urdf` for a built free-flyer robot (its `model`, named `urdf_name` in the URDF)."""

    model: lk.Model
    urdf_name: ClassVar[str]

    def to_urdf(self) -> str:
        """URDF text of the model (the free-flyer base as the root link); load with Model.from_urdf(xml, floating_base=True)."""
        return model_to_urdf(self.model, self.urdf_name)


def model_to_urdf(model: lk.Model, robot_name: str) -> str:
    """URDF text of any legkit model: one link per body (named as the body, with its inertia), one joint
    `<body>_joint` per non-base body (revolute with +-pi limits, prismatic with +-1 m, or fixed). A floating
    base is not written as a joint (URDF has none): load with Model.from_urdf(xml, floating_base=True). A joint
    URDF has no type for (helical) is a ValueError naming its body."""
    instance(model, lk.Model, "model")
    instance(robot_name, str, "robot_name")
    for i in range(1, model.nbodies):
        if model.joint_type(i) not in ("revolute", "prismatic", "fixed"):
            raise ValueError(f"model: URDF has no {model.joint_type(i)} joint (body {model.names[i]!r})")
    lines = ['<?xml version="1.0"?>', f"<robot name={quoteattr(robot_name)}>"]
    for i, name in enumerate(model.names):
        lines.append(f"  <link name={quoteattr(name)}>{_inertial(model.body(i))}</link>")
    for i in range(1, model.nbodies):
        placement = model.placement(i)
        roll, pitch, yaw = _rpy(placement[:3, :3])
        kind = model.joint_type(i)
        parts = [
            f"  <joint name={quoteattr(model.names[i] + '_joint')} type={quoteattr(kind)}>",
            f"<parent link={quoteattr(model.names[model.parents[i]])}/><child link={quoteattr(model.names[i])}/>",
            f'<origin xyz="{_numbers(placement[:3, 3])}" rpy="{_numbers([roll, pitch, yaw])}"/>',
        ]
        if kind in ("revolute", "prismatic"):
            limit = np.pi if kind == "revolute" else 1.0
            axis = model.joint_axis(i)
            assert axis is not None  # revolute and prismatic joints have one
            parts.append(f'<axis xyz="{_numbers(axis)}"/>')
            parts.append(f'<limit lower="{-float(limit)!r}" upper="{float(limit)!r}" effort="1000" velocity="100"/>')
        parts.append("</joint>")
        lines.append("".join(parts))
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
