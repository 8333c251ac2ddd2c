"""Energy indices of a gait and the actuator torque-speed limit [Hardt 2002, Sect. 2.3 and 3.2].

Joint i is driven by a DC motor through a gear of ratio G_i (motor turns per joint turn) and efficiency
eta_i; K_i is the motor torque constant [N m/A], R_i the winding resistance [ohm]. A joint torque u_i needs
the motor current u_i / (G_i K_i), whose Joule loss is R_i (u_i / (G_i K_i))^2 [W].

Arrays of torques and joint velocities are (T, n): T time samples, n actuated joints; the motor parameters
are scalars or (n,) and broadcast.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array, positive_scalar, time_grid


def _per_joint(value: npt.ArrayLike, name: str, joints: int, *, allow_zero: bool = False) -> np.ndarray:
    array = float_array(value, name)
    if array.ndim > 1 or (array.ndim == 1 and array.shape[0] != joints):
        raise ValueError(f"{name} must be a scalar or have {joints} entries (one per joint), got shape {array.shape}")
    if np.any(array < 0.0) or (not allow_zero and np.any(array == 0.0)):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}, got {array}")
    return array


def _torques(torques: npt.ArrayLike) -> np.ndarray:
    u = float_array(torques, "torques", min_ndim=2)
    if u.ndim != 2:
        raise ValueError(f"torques must be (T, n), got shape {u.shape}")
    return u


def joule_loss_power(
    torques: npt.ArrayLike, resistance: npt.ArrayLike, gear_ratio: npt.ArrayLike, torque_constant: npt.ArrayLike
) -> np.ndarray:
    """Instantaneous Joule loss (T,) [W] = sum_i R_i (u_i / (G_i K_i))^2 of torques (T, n) [N m]."""
    u = _torques(torques)
    n = u.shape[1]
    r = _per_joint(resistance, "resistance", n, allow_zero=True)
    gk = _per_joint(gear_ratio, "gear_ratio", n) * _per_joint(torque_constant, "torque_constant", n)
    return np.sum(r * (u / gk) ** 2, axis=-1)


def joule_loss_index(
    torques: npt.ArrayLike,
    t: npt.ArrayLike,
    distance: float,
    resistance: npt.ArrayLike,
    gear_ratio: npt.ArrayLike,
    torque_constant: npt.ArrayLike,
) -> float:
    """Energy Performance 1, J_e1 [Hardt 2002, eq. 12], in J/m: the Joule loss integrated over t (trapezoidal
    rule) per distance d_S travelled.

    torques: (T, n) [N m]; t: (T,) [s]; distance > 0 [m] travelled over t; motor parameters as the module
    docstring. Lower is better (an energy cost, not a margin).
    """
    power = joule_loss_power(torques, resistance, gear_ratio, torque_constant)
    times = time_grid(t, power.shape[0])
    return float(np.trapezoid(power, times)) / positive_scalar(distance, "distance")


def specific_resistance(
    torques: npt.ArrayLike,
    joint_velocities: npt.ArrayLike,
    t: npt.ArrayLike,
    forward_velocity: npt.ArrayLike,
    mass: float,
    gravity: float = lk.STANDARD_GRAVITY,
    *,
    definition: Literal["paper", "mean"] = "paper",
) -> float:
    """Energy Performance 2, J_e2 [Hardt 2002, eq. 13], from the specific resistance of Gregorio et al.

    definition="paper" (default): J_e2 = integral over t of sum_i |u_i theta_dot_i| / (m g v) dt [s], as
    published: the integral of the dimensionless specific resistance, so it has units of seconds and grows
    with the duration of t (the text calls the index dimensionless; the equation is not).
    definition="mean": that integrand's time mean, J_e2 / (t_end - t_0) (dimensionless): the specific
    resistance itself, which at constant v is the work sum_i |u_i theta_dot_i| spent per m g and metre.

    torques, joint_velocities: (T, n) [N m], [rad/s]; t: (T,) [s]; forward_velocity v: scalar or (T,) forward
    speed [m/s], > 0 (the integrand divides by it); mass > 0 [kg]; gravity > 0 [m/s^2] (for a model, the
    magnitude of ``model.gravity``). Trapezoidal rule. Negative joint work is
    counted as spent (|.|): motors do not recover it.
    """
    if definition not in ("paper", "mean"):
        raise ValueError(f"definition must be 'paper' or 'mean', got {definition!r}")
    u = _torques(torques)
    w = float_array(joint_velocities, "joint_velocities")
    if w.shape != u.shape:
        raise ValueError(f"joint_velocities must have the shape of torques {u.shape}, got {w.shape}")
    times = time_grid(t, u.shape[0])
    speed = float_array(forward_velocity, "forward_velocity")
    if speed.ndim > 1 or (speed.ndim == 1 and speed.shape[0] != u.shape[0]):
        raise ValueError(f"forward_velocity must be a scalar or have {u.shape[0]} samples, got shape {speed.shape}")
    if np.any(speed <= 0.0):
        raise ValueError(f"forward_velocity must be > 0 (J_e2 divides by it), got minimum {speed.min()}")
    weight = positive_scalar(mass, "mass") * positive_scalar(gravity, "gravity")
    integral = float(np.trapezoid(np.sum(np.abs(u * w), axis=-1) / (weight * speed), times))
    return integral if definition == "paper" else integral / float(times[-1] - times[0])


def torque_speed_margin(
    torques: npt.ArrayLike,
    joint_velocities: npt.ArrayLike,
    max_speed: npt.ArrayLike,
    gear_ratio: npt.ArrayLike,
    efficiency: npt.ArrayLike,
    slope: npt.ArrayLike,
) -> np.ndarray:
    """Margin (T, n) [N m] to the actuator torque-speed line of [Hardt 2002, Sect. 2.3] (interior constraint 3):
    |u_i| <= (theta_dot_max,i - |theta_dot_i|) G_i^2 eta_i / m_i.

    max_speed: the joint's no-load speed theta_dot_max (motor no-load speed / G) [rad/s]; slope m_i: the
    motor's speed-torque gradient [rad/s per N m]; efficiency eta_i in (0, 1]. A motor delivers torque
    (omega_0 - omega_motor) / m_i, which through the gear becomes the line above at the joint.
    Positive means the torque is feasible at that speed; negative by how much it is exceeded.
    """
    u = _torques(torques)
    w = float_array(joint_velocities, "joint_velocities")
    if w.shape != u.shape:
        raise ValueError(f"joint_velocities must have the shape of torques {u.shape}, got {w.shape}")
    n = u.shape[1]
    eta = _per_joint(efficiency, "efficiency", n)
    if np.any(eta > 1.0):
        raise ValueError(f"efficiency must be in (0, 1], got {eta}")
    gear = _per_joint(gear_ratio, "gear_ratio", n)
    limit = (_per_joint(max_speed, "max_speed", n) - np.abs(w)) * gear**2 * eta / _per_joint(slope, "slope", n)
    return limit - np.abs(u)
