"""The DC motors and gears that drive legkit's example robots' joints, and their torque-speed characteristic.

[Hardt 2002, Sect. 2.3] bounds each joint torque by the motor-gear characteristic line
|u| <= (w_max - |w|) G^2 eta / m; `MotorParameters` holds what that line and the Joule loss (eq. 12) need.
The paper gives no motor constants for its robots; the two below are legkit's assumptions, documented where they
are used (`legkit.optimize.gaits.walk_problem`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from legkit._validation import parameter_fields


@dataclass(frozen=True)
class MotorParameters:
    """DC motor and gear of every actuated joint (same for all joints of a robot)."""

    resistance: float  # ohm
    torque_constant: float  # N m / A
    gear_ratio: float  # motor turns per joint turn
    efficiency: float  # gear efficiency in (0, 1]
    no_load_speed: float  # motor no-load speed [rad/s]
    stall_torque: float  # motor stall torque [N m]

    def __post_init__(self) -> None:
        parameter_fields(self, positive=[f.name for f in fields(self)])
        if self.efficiency > 1.0:
            raise ValueError(f"efficiency must be in (0, 1], got {self.efficiency}")

    @property
    def joint_max_speed(self) -> float:
        return self.no_load_speed / self.gear_ratio

    @property
    def slope(self) -> float:
        """Motor speed-torque gradient m [rad/s per N m]."""
        return self.no_load_speed / self.stall_torque




#: The quadruped's joints: a small DC motor with a 60:1 gear (joint no-load speed 21 rad/s, stall 1.26 N m after the gear).
QUADRUPED_MOTOR = MotorParameters(resistance=5.0, torque_constant=0.012, gear_ratio=60.0, efficiency=0.7, no_load_speed=1257.0, stall_torque=0.03)
#: The biped's joints: a larger motor with a 160:1 gear (joint no-load speed 5.2 rad/s).
BIPED_MOTOR = MotorParameters(resistance=0.5, torque_constant=0.05, gear_ratio=160.0, efficiency=0.8, no_load_speed=838.0, stall_torque=1.2)
