"""Hermite–Simpson collocation and coloured finite-difference Jacobians of batched point functions.

[Hardt 2002, Sect. 4.1, eq. 14]: DIRCOL approximates the states by
cubic Hermite polynomials and the controls linearly on each grid interval [t_k, t_k+1]. With f the state
derivative, the cubic through (x_k, f_k) and (x_k+1, f_k+1) is collocated at the midpoint m, which gives the
two (separated) Hermite–Simpson defects per interval of length h:

    interpolation  x_m - (x_k + x_k+1) / 2 - h (f_k - f_k+1) / 8 = 0    (the cubic's value at the midpoint)
    Simpson        x_k+1 - x_k - h (f_k + 4 f_m + f_k+1) / 6 = 0        (its slope there equals f_m)

For an exact trajectory the first is O(h^4) (Hermite interpolation error), the second O(h^5) (Simpson's rule).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

#: Relative central-difference step: the cube root of the float64 epsilon balances truncation and rounding.
FD_STEP = 6e-6


def hermite_basis(s: Any) -> tuple[Any, Any, Any, Any]:
    """Weights of (x_k, h f_k, x_k+1, h f_k+1) in the interval's cubic at s in [0, 1] (eq. 14's states): numbers,
    arrays or casadi expressions."""
    return 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2


def hermite_simpson_defects(
    x_knots: np.ndarray, x_mid: np.ndarray, f_knots: np.ndarray, f_mid: np.ndarray, h: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(interpolation (N, n), Simpson (N, n)) defects of N intervals (module docstring): x_knots, f_knots
    (N + 1, n), x_mid, f_mid (N, n), h scalar or (N,)."""
    h = np.reshape(np.asarray(h, dtype=np.float64), (-1, 1))
    x0, x1, f0, f1 = x_knots[:-1], x_knots[1:], f_knots[:-1], f_knots[1:]
    interpolation = x_mid - 0.5 * (x0 + x1) - h * (f0 - f1) / 8.0
    simpson = x1 - x0 - h * (f0 + 4.0 * f_mid + f1) / 6.0
    return interpolation, simpson


def point_jacobian(
    function: Callable[[np.ndarray], np.ndarray], z: np.ndarray, step: float = FD_STEP, columns: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Values (P, m) and Jacobians (P, m, c) of a function applied independently to each of P points z (P, n),
    differentiated with respect to the inputs `columns` (c of them; default all n, in order).

    Every point's outputs depend on that point's inputs only, so perturbing input j of all points at once
    is a valid colouring: the 2 c central differences of all P points are one batched call of (2 c + 1) P rows.
    """
    points, n = z.shape
    columns = np.arange(n) if columns is None else np.asarray(columns, dtype=np.int64)
    c = len(columns)
    delta = step * np.maximum(1.0, np.abs(z[:, columns]))  # (P, c)
    plus = np.repeat(z[:, None, :], c, axis=1)  # (P, c, n): row j perturbs input columns[j]
    minus = plus.copy()
    rows = np.arange(c)
    plus[:, rows, columns] += delta
    minus[:, rows, columns] -= delta
    batch = np.concatenate([z[:, None, :], plus, minus], axis=1).reshape(points * (2 * c + 1), n)
    out = np.asarray(function(batch)).reshape(points, 2 * c + 1, -1)
    value = out[:, 0]
    jac = (out[:, 1 : c + 1] - out[:, c + 1 :]) / (2.0 * delta[:, :, None])  # (P, c, m)
    return value, np.transpose(jac, (0, 2, 1))


def complex_step_jacobian(function: Callable[[np.ndarray], np.ndarray], z: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Jacobians (P, m, c) of closed-form algebra applied independently to each of P points z (P, n) with respect to the
    inputs `columns`, by complex steps: d f / d z_j = Im f(z + i s e_j) / s, exact to rounding (no difference is
    taken). function must accept complex arrays (arithmetic and np.sqrt on the principal branch)."""
    points, n = z.shape
    c = len(columns)
    batch = np.repeat(z[:, None, :].astype(np.complex128), c, axis=1)  # (P, c, n): row j steps input columns[j]
    batch[:, np.arange(c), columns] += 1j * COMPLEX_STEP
    out = np.asarray(function(batch.reshape(points * c, n))).reshape(points, c, -1)
    return np.transpose(out.imag / COMPLEX_STEP, (0, 2, 1))


#: The imaginary step of `complex_step_jacobian`: any tiny value works, since no difference of values is taken.
COMPLEX_STEP = 1e-30
