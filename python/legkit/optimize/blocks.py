"""Constraint blocks of a transcribed NLP: each knows its rows, bounds, the fixed sparsity patterns of its
Jacobian and of its part of the Hessian of the Lagrangian, and their values.

Two kinds cover most rows: linear rows (constant Jacobian, no curvature) and point rows, a function applied
independently to many small groups of variables (a knot's state, a touchdown's pre-impact state) with its exact
Jacobian (closed-form algebra without one is differenced by `point_jacobian`). A block's curvature
sum_rows mu_row d2(row)/dx2 is exact where the block gives it (`Point.curvature`, from the core's second-order
kernels), else `group_hessian`: forward differences of the exact Jacobian, all groups at once.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from legkit.optimize.collocation import FD_STEP, point_jacobian


class Block(Protocol):
    """rows: local row of each Jacobian entry; cols: its variable; values(x), jacobian(x) in that order.
    hessian_rows, hessian_cols: the variables of each entry of hessian(x, multipliers (size,)), the block's
    sum_rows multiplier d2(row)/dx2 (either triangle; entries at one place are summed)."""

    size: int
    lower: np.ndarray
    upper: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    hessian_rows: np.ndarray
    hessian_cols: np.ndarray

    def values(self, x: np.ndarray) -> np.ndarray: ...

    def jacobian(self, x: np.ndarray) -> np.ndarray: ...

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray: ...


#: Relative step of `group_hessian`'s forward differences of an exact gradient: about the square root of the machine
#: epsilon, which balances their truncation and rounding errors.
HESSIAN_STEP = 1e-8


def group_hessian(gradient: Callable[[np.ndarray, np.ndarray], np.ndarray], z: np.ndarray, weights: np.ndarray,
                  columns: np.ndarray, exact: bool = True) -> np.ndarray:
    """(P, k, k): the Hessians of weights[p] . f(z_p) at P groups z (P, k), by differences of the weighted gradient
    gradient(z (B, k), weights (B, r)) -> (B, k) (the vector-Jacobian product weights . df/dz) along `columns` (the
    inputs f depends on nonlinearly; the curvature between two other inputs is zero), all groups and columns in one
    call. exact (the gradient is exact to rounding): forward differences, 1 + len(columns) gradients per group,
    ~1e-7 relative; else (a gradient itself differenced, ~1e-10) central differences of step `FD_STEP`, twice as
    many gradients, ~1e-5. Symmetrised."""
    points, k = z.shape
    c = len(columns)
    step = HESSIAN_STEP if exact else FD_STEP
    delta = step * np.maximum(1.0, np.abs(z[:, columns]))  # (P, c)
    # Copy j of the forward (central) batch moves input columns[j] forward (and copy c + j backward); the forward
    # batch's last copy is z itself.
    moved = np.repeat(z[:, None, :], c + 1 if exact else 2 * c, axis=1)
    moved[:, np.arange(c), columns] += delta
    if not exact:
        moved[:, c + np.arange(c), columns] -= delta
    slopes = np.asarray(gradient(moved.reshape(-1, k), np.repeat(weights, moved.shape[1], axis=0))).reshape(points, -1, k)
    ahead, behind = slopes[:, :c], slopes[:, c:]  # behind: z's gradient (1 copy) or the backward copies
    rows = (ahead - behind) / ((1.0 if exact else 2.0) * delta[:, :, None])  # (P, c, k): d gradient / d z_columns
    out = np.zeros((points, k, k))
    out[:, columns] = rows
    out += np.swapaxes(out, 1, 2)
    out[:, columns[:, None], columns] *= 0.5  # set from both sides
    return out


def weighted(derivative: Callable[[np.ndarray], np.ndarray]) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The weighted gradient (z, weights) -> weights . derivative(z) of a Jacobian (B, k) -> (B, r, k)."""
    return lambda z, weights: np.einsum("brk,br->bk", np.asarray(derivative(z)), weights)


def group_pattern(index: np.ndarray, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, local) of the Hessian entries `group_hessian` can make nonzero in groups of variables index
    (P, k): the pairs with at least one input in columns, lower triangle within a group; local indexes the
    flattened (P, k, k) result."""
    points, k = index.shape
    mask = np.zeros((k, k), dtype=bool)
    mask[columns] = True
    mask |= mask.T
    i, j = np.nonzero(np.tril(mask))
    local = (np.arange(points)[:, None] * k * k + i * k + j).ravel()
    return index[:, i].ravel(), index[:, j].ravel(), local


class Linear:
    """g = A x + offset with A given as triplets (duplicates summed)."""

    def __init__(self, size: int, rows: ArrayLike, cols: ArrayLike, coefficients: ArrayLike, offset: ArrayLike = 0.0,
                 lower: ArrayLike = 0.0, upper: ArrayLike = 0.0) -> None:
        self.size = size
        self.rows = np.asarray(rows, dtype=np.int64)
        self.cols = np.asarray(cols, dtype=np.int64)
        self.coefficients = np.asarray(coefficients, dtype=np.float64)
        self.offset = np.broadcast_to(np.asarray(offset, dtype=np.float64), (size,))
        self.lower = np.broadcast_to(np.asarray(lower, dtype=np.float64), (size,)).copy()
        self.upper = np.broadcast_to(np.asarray(upper, dtype=np.float64), (size,)).copy()

    def values(self, x: np.ndarray) -> np.ndarray:
        return np.bincount(self.rows, weights=self.coefficients * x[self.cols], minlength=self.size) + self.offset

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.coefficients

    hessian_rows = hessian_cols = np.zeros(0, dtype=np.int64)

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        return np.zeros(0)


def equal(size: int, left: np.ndarray, right: np.ndarray, signs: ArrayLike = 1.0) -> Linear:
    """signs * x[left] - x[right] = 0 elementwise (continuity, periodicity, mirror periodicity)."""
    left, right = np.ravel(left), np.ravel(right)
    rows = np.arange(size)
    return Linear(size, np.concatenate([rows, rows]), np.concatenate([left, right]),
                  np.r_[np.broadcast_to(np.asarray(signs, dtype=np.float64), (size,)), -np.ones(size)])


@dataclass
class Point:
    """g[p] = function(x[index[p]]) for P groups index (P, k); function maps (B, k) -> (B, r); rows point-major."""

    index: np.ndarray
    function: Callable[[np.ndarray], np.ndarray]
    outputs: int
    lower_bound: float | np.ndarray = 0.0
    upper_bound: float | np.ndarray = 0.0
    #: (P, k) -> (P, outputs, k): the function's exact Jacobian; None: `point_jacobian`'s differences (algebra only).
    derivative: Callable[[np.ndarray], np.ndarray] | None = None
    #: ((P, k), weights (P, outputs)) -> (P, k): weights . the exact Jacobian, for a function whose vector product is
    #: cheaper than its Jacobian (the Jacobian is then assembled from it, one output at a time).
    gradient: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    #: The inputs the function depends on nonlinearly (default: all), where `group_hessian` differences.
    nonlinear: np.ndarray | None = None
    #: derivative or gradient is exact to rounding (not itself differenced): `group_hessian`'s forward differences.
    exact: bool = True
    #: ((P, k), weights (P, outputs)) -> (P, k, k): the exact curvature sum_r weights_r d2f_r/dz2, in place of
    #: `group_hessian`'s differences.
    curvature: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    #: (outputs, k) bool: the inputs each output depends on (default: all), the Jacobian's pattern per group.
    mask: np.ndarray | None = None

    def __post_init__(self) -> None:
        points, k = self.index.shape
        self.size = points * self.outputs
        self.lower = np.resize(np.asarray(self.lower_bound, dtype=np.float64), self.size)
        self.upper = np.resize(np.asarray(self.upper_bound, dtype=np.float64), self.size)
        mask = np.ones((self.outputs, k), dtype=bool) if self.mask is None else np.asarray(self.mask, dtype=bool)
        self._rows, self._cols = np.nonzero(mask)
        self.rows = (np.arange(points)[:, None] * self.outputs + self._rows[None]).ravel()
        self.cols = self.index[:, self._cols].ravel()
        self._nonlinear = np.arange(k) if self.nonlinear is None else np.asarray(self.nonlinear, dtype=np.int64)
        self.hessian_rows, self.hessian_cols, self._local = group_pattern(self.index, self._nonlinear)

    def values(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.function(x[self.index])).ravel()

    def slopes(self, z: np.ndarray) -> np.ndarray:
        """(P, outputs, k): the function's Jacobian at groups z (P, k)."""
        if self.derivative is not None:
            return np.asarray(self.derivative(z))
        if self.gradient is not None:  # one output at a time, all in one call
            unit = np.tile(np.eye(self.outputs), (len(z), 1))
            return np.asarray(self.gradient(np.repeat(z, self.outputs, axis=0), unit)).reshape(len(z), self.outputs, -1)
        return point_jacobian(self.function, z)[1]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self.slopes(x[self.index])[:, self._rows, self._cols].ravel()

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        z = x[self.index]
        weights = multipliers.reshape(len(z), self.outputs)
        if self.curvature is not None:
            return np.asarray(self.curvature(z, weights)).ravel()[self._local]
        gradient = weighted(self.slopes) if self.gradient is None else self.gradient
        exact = self.exact and (self.derivative is not None or self.gradient is not None)
        return group_hessian(gradient, z, weights, self._nonlinear, exact).ravel()[self._local]
