"""Argument checks shared by the Python packages: every error names the offending argument."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def float_array(value: npt.ArrayLike, name: str, *, last: int | None = None, min_ndim: int = 0) -> np.ndarray:
    """`value` as a finite float64 array: TypeError if it is not numeric, ValueError on a wrong shape
    (fewer than `min_ndim` dimensions, or a last dimension other than `last`) or on NaN/inf."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise TypeError(f"{name} must be an array of real numbers, got {type(value).__name__}") from error
    if array.ndim < min_ndim:
        raise ValueError(f"{name} must have at least {min_ndim} dimensions, got shape {array.shape}")
    if last is not None and (array.ndim == 0 or array.shape[-1] != last):
        raise ValueError(f"{name} must have a last dimension of size {last}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains a non-finite value (NaN or inf)")
    return array
