"""Constraint blocks of a transcribed NLP: each knows its rows, bounds, fixed sparsity pattern and values.

Two kinds cover everything but the collocation defects: linear rows (constant Jacobian) and point rows, a
function applied independently to many small groups of variables (a knot's state, a touchdown's pre-impact
state), differentiated by `point_jacobian`'s coloured central differences.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from legkit.optimize.collocation import point_jacobian


class Block(Protocol):
    """rows: local row of each Jacobian entry; cols: its variable; values(x), jacobian(x) in that order."""

    size: int
    lower: np.ndarray
    upper: np.ndarray
    rows: np.ndarray
    cols: np.ndarray

    def values(self, x: np.ndarray) -> np.ndarray: ...

    def jacobian(self, x: np.ndarray) -> np.ndarray: ...


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
    symbolic: Callable | None = None  # (SymbolicModel, z casadi (k,)) -> (outputs,): the same function for casadi
    #: (P, k) -> (P, outputs, k): the function's Jacobian where it has a cheaper form; else `point_jacobian`'s.
    derivative: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        points, k = self.index.shape
        self.size = points * self.outputs
        self.lower = np.resize(np.asarray(self.lower_bound, dtype=np.float64), self.size)
        self.upper = np.resize(np.asarray(self.upper_bound, dtype=np.float64), self.size)
        self.rows = np.repeat(np.arange(self.size), k)
        self.cols = np.repeat(self.index, self.outputs, axis=0).ravel()

    def values(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(self.function(x[self.index])).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        if self.derivative is not None:
            return np.asarray(self.derivative(x[self.index])).ravel()
        return point_jacobian(self.function, x[self.index])[1].ravel()
