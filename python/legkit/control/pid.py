"""A bank of independent PID controllers (one per joint), vectorised with numpy."""

from __future__ import annotations

import numpy as np

from legkit._validation import float_array, is_integer, positive_scalar, zeros


class PID:
    """PID controllers for ``shape`` joints: ``u = K_P e + K_I sum(e dt) + K_D de/dt`` with e = target - angle
    (rad), u in N m. The gains are passed on every call (so a schedule may change them); the integral and
    the previous error are the state. The derivative is a backward difference of the error, zero on the
    first call."""

    def __init__(self, shape: tuple[int, ...]):
        if not isinstance(shape, (tuple, list)):
            raise TypeError(f"shape: must be a tuple of integers, got {type(shape).__name__}")
        if not all(is_integer(n) and n >= 0 for n in shape):
            raise ValueError(f"shape: must be non-negative integers, got {shape}")
        self.shape = tuple(int(n) for n in shape)
        self.integral = zeros(self.shape, "shape")
        self.previous_error: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the integral and the previous error."""
        self.integral = np.zeros_like(self.integral)
        self.previous_error = None

    def __call__(self, error: np.ndarray, dt: float, kp: np.ndarray, ki: np.ndarray, kd: np.ndarray) -> np.ndarray:
        """Control effort for ``error`` (rad, of ``shape``) after a step of ``dt`` s; gains broadcast to ``shape``."""
        error = float_array(error, "error", shape=self.shape)
        positive_scalar(dt, "dt")
        for gain, name in ((kp, "kp"), (ki, "ki"), (kd, "kd")):
            gain = float_array(gain, name)
            try:
                np.broadcast_to(gain, self.shape)
            except ValueError:
                raise ValueError(f"{name} must broadcast to {self.shape}, got shape {gain.shape}") from None
        self.integral = self.integral + error * dt
        derivative = np.zeros(self.shape) if self.previous_error is None else (error - self.previous_error) / dt
        self.previous_error = error.copy()
        return kp * error + ki * self.integral + kd * derivative
