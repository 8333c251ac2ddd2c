"""Gain schedules of [Moll 2006] (Sect. IV for the heuristics, Sect. V for the constants): every PID gain
is the base gain times a factor that each joint
computes from its own agent's estimates.

* constant:  K = K0                         (the paper's default: identical gains on every module)
* distance:  K = (c0 + c1 d) K0             (§IV, K_P = (c_0 + c_1 d_support) K_P0), d the distance from the
  estimated COM to the support line, in module widths
* momentum:  K = (c0 + c1 |m2 u x (p2 - q)|) K0   (§IV, K_P = (c_0 + c_1 ||v||) K_P0, v = m2 u x (p2 - q)),
  m2 (kg) and p2 (m) the mass and COM of the part the joint moves, u the unit joint axis and q a point on
  it (kg m): the mass moment the joint has to swing.

"The integral and derivative gain are adjusted analogously" (§IV): K_I and K_D take the same factor.
Base gains K_P0 = 10, K_I0 = 0.1, K_D0 = 1e-4; distance c0 = 0, c1 = 0.1; momentum c0 = 0, c1 = 1 (§V).
The paper does not state the unit of d; it is taken here in module widths, the unit its figures use for the
distance, which puts the distance-based gains in the same range as the constant ones for the seed's trees.

`gain_factor` and `scaled_gains` are the one implementation of the schedule: a `GainSchedule` evaluates it
for itself, and the balance controller (``legkit.control.balance``) for every module's schedule at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from legkit._validation import float_array, positive_scalar

KP0 = 10.0
KI0 = 0.1
KD0 = 1e-4
SCHEMES = ("constant", "distance", "momentum")
CONSTANT, DISTANCE, MOMENTUM = range(len(SCHEMES))  # the schemes as indices into SCHEMES
_PAPER_COEFFICIENTS = {"constant": (1.0, 0.0), "distance": (0.0, 0.1), "momentum": (0.0, 1.0)}  # (c0, c1), §V


def gain_factor(
    scheme: int | np.ndarray, c0: float | np.ndarray, c1: float | np.ndarray, distance_widths: npt.ArrayLike, mass_moment: npt.ArrayLike
) -> np.ndarray:
    """The factor K / K0 = c0 + c1 x of the schedule (module docstring): x the support distance
    ``distance_widths`` (module widths) under DISTANCE, the mass moment ``mass_moment`` (kg m) under MOMENTUM,
    0 under CONSTANT. ``scheme`` holds indices into SCHEMES; all arguments broadcast together (the balance
    controller passes one (N, 1) row per module against (N, 3) joints)."""
    variable = np.where(scheme == DISTANCE, distance_widths, np.where(scheme == MOMENTUM, mass_moment, 0.0))
    return c0 + c1 * variable


def scaled_gains(
    factor: np.ndarray, kp0: float | np.ndarray, ki0: float | np.ndarray, kd0: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_P, K_I, K_D) = factor (K_P0, K_I0, K_D0): all three gains take the same factor (§IV)."""
    return factor * kp0, factor * ki0, factor * kd0


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
            positive_scalar(getattr(self, name), name, allow_zero=True)

    @staticmethod
    def paper(scheme: str) -> GainSchedule:
        """The seed paper's values for ``scheme``."""
        if scheme not in _PAPER_COEFFICIENTS:
            raise ValueError(f"scheme: must be one of {SCHEMES}, got {scheme!r}")
        return GainSchedule(scheme, *_PAPER_COEFFICIENTS[scheme])

    @property
    def scheme_index(self) -> int:
        """The scheme as its index into SCHEMES (CONSTANT, DISTANCE or MOMENTUM)."""
        return SCHEMES.index(self.scheme)

    def factor(self, distance_widths: npt.ArrayLike, mass_moment: npt.ArrayLike) -> np.ndarray:
        """The gain factor per joint from the support distance (module widths) and the mass moment (kg m)."""
        distance, moment = float_array(distance_widths, "distance_widths"), float_array(mass_moment, "mass_moment")
        return gain_factor(self.scheme_index, self.c0, self.c1, distance, moment)

    def gains(self, distance_widths: npt.ArrayLike, mass_moment: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K_P, K_I, K_D) per joint."""
        return scaled_gains(self.factor(distance_widths, mass_moment), self.kp0, self.ki0, self.kd0)
