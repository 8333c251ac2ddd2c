"""Argument checks shared by the stability indices: every error names the offending argument."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from legkit._validation import float_array

UNIT_TOLERANCE = 1e-6


def bool_mask(value: npt.ArrayLike | None, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """A boolean mask broadcast to `shape` (all True when `value` is None)."""
    if value is None:
        return np.ones(shape, dtype=bool)
    mask = np.asarray(value)
    if mask.dtype != bool:
        raise TypeError(f"{name} must be a boolean array, got dtype {mask.dtype}")
    try:
        return np.broadcast_to(mask, shape)
    except ValueError as error:
        raise ValueError(f"{name} has shape {mask.shape}, which does not broadcast to {shape}") from error


def positive_scalar(value: object, name: str, *, allow_zero: bool = False) -> float:
    """A finite real scalar > 0 (or >= 0 with allow_zero)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    number = float(value)
    if not np.isfinite(number) or number < 0.0 or (number == 0.0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be finite and {bound}, got {value}")
    return number


def friction_coefficient(mu: npt.ArrayLike, name: str = "mu") -> np.ndarray:
    """Friction coefficient(s): finite and >= 0."""
    array = float_array(mu, name)
    if np.any(array < 0.0):
        raise ValueError(f"{name} must be >= 0, got {array.min()}")
    return array


def unit_vectors(value: npt.ArrayLike, name: str) -> np.ndarray:
    """(..., 3) vectors that must already be unit length (to 1e-6): a non-unit normal is a caller bug."""
    array = float_array(value, name, last=3)
    norms = np.linalg.norm(array, axis=-1)
    if np.any(np.abs(norms - 1.0) > UNIT_TOLERANCE):
        worst = norms.flat[np.argmax(np.abs(norms - 1.0))]
        raise ValueError(f"{name} must be unit vectors (|n| = 1 within {UNIT_TOLERANCE}), found |n| = {worst:.9g}")
    return array


def time_grid(t: npt.ArrayLike, samples: int, name: str = "t") -> np.ndarray:
    """Strictly increasing sample times matching `samples` values along the first axis."""
    times = float_array(t, name)
    if times.ndim != 1 or times.shape[0] != samples:
        raise ValueError(f"{name} must be 1-D with {samples} samples, got shape {times.shape}")
    if samples < 2:
        raise ValueError(f"{name} needs at least two samples to integrate over, got {samples}")
    if np.any(np.diff(times) <= 0.0):
        raise ValueError(f"{name} must be strictly increasing")
    return times
