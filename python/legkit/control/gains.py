"""Gain schedules of the seed paper (Moll et al., IROS 2006, §V): every PID gain is the base gain times a
factor that each joint computes from its own agent's estimates.

* constant:  K = K0
* distance:  K = (c0 + c1 d) K0, d the distance from the estimated COM to the support line, in module widths
* momentum:  K = (c0 + c1 |m2 u x (p2 - q)|) K0, m2 (kg) and p2 (m) the mass and COM of the part the joint
  moves, u the unit joint axis and q a point on it (kg m): the mass moment the joint has to swing.

Base gains K_P0 = 10, K_I0 = 0.1, K_D0 = 1e-4; distance c0 = 0, c1 = 0.1; momentum c0 = 0, c1 = 1.
The paper does not state the unit of d; it is taken here in module widths, the unit its figures use for the
distance, which puts the distance-based gains in the same range as the constant ones for the seed's trees.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KP0 = 10.0
KI0 = 0.1
KD0 = 1e-4
SCHEMES = ("constant", "distance", "momentum")


@dataclass(frozen=True)
class GainSchedule:
    """``scheme`` in SCHEMES, coefficients ``c0``, ``c1`` and base gains ``kp0``, ``ki0``, ``kd0``."""

    scheme: str = "constant"
    c0: float = 1.0
    c1: float = 0.0
    kp0: float = KP0
    ki0: float = KI0
    kd0: float = KD0

    def __post_init__(self) -> None:
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme: must be one of {SCHEMES}, got {self.scheme!r}")
        for name in ("c0", "c1", "kp0", "ki0", "kd0"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
                raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")

    @staticmethod
    def paper(scheme: str) -> GainSchedule:
        """The seed paper's values for ``scheme``."""
        coefficients = {"constant": (1.0, 0.0), "distance": (0.0, 0.1), "momentum": (0.0, 1.0)}
        if scheme not in coefficients:
            raise ValueError(f"scheme: must be one of {SCHEMES}, got {scheme!r}")
        return GainSchedule(scheme, *coefficients[scheme])

    def factor(self, distance_widths: np.ndarray, mass_moment: np.ndarray) -> np.ndarray:
        """The gain factor per joint from the support distance (module widths) and the mass moment (kg m)."""
        if self.scheme == "constant":
            return np.full(np.shape(mass_moment), self.c0)
        if self.scheme == "distance":
            return self.c0 + self.c1 * np.asarray(distance_widths, dtype=float)
        return self.c0 + self.c1 * np.asarray(mass_moment, dtype=float)

    def gains(self, distance_widths: np.ndarray, mass_moment: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K_P, K_I, K_D) per joint."""
        factor = self.factor(distance_widths, mass_moment)
        return factor * self.kp0, factor * self.ki0, factor * self.kd0
