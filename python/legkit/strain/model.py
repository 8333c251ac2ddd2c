"""The polynomial leg model of Lin, Komsuoglu and Koditschek (ICRA 2003, eq. 1), its fit and validation.

One strain reading sigma per leg is mapped to the leg configuration (length l, deflection d):

    m(sigma) = ( sum_j n1_j sigma^j ,  sum_j n2_j sigma^j ),   j = 0 .. N

fitted by ordinary least squares. Units are whatever the data carry; in legkit the strain is in
microstrain, the length in metres and the deflection in radians. Coefficient arrays are ordered lowest
power first: ``n1[j]`` multiplies ``sigma**j``.

The error measure is the paper's percent normalised RMS error

    p(d, d_hat) = sqrt( ||d - d_hat||^2 / (M d_max^2) ) * 100,    d_max = max_k |d_k|,

over M samples.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from legkit._validation import float_array, integer, real_numbers

MAX_ORDER = 8


def _as_samples(name: str, values: object) -> np.ndarray:
    """A finite 1-D float64 array, or a ValueError/TypeError naming the argument."""
    array = real_numbers(values, name)
    if array.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {array.shape}")
    if array.size == 0:
        raise ValueError(f"{name} is empty")
    if not np.all(np.isfinite(array)):
        bad = int(np.flatnonzero(~np.isfinite(array))[0])
        raise ValueError(f"{name} contains a non-finite value (NaN or inf) at index {bad}")
    return array


def _check_order(order: object) -> int:
    number = integer(order, "order")
    if not 0 <= number <= MAX_ORDER:
        raise ValueError(f"order must be between 0 and {MAX_ORDER}, got {order}")
    return number


def _check_training_data(
    strain: object, length: object, deflection: object, order: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    sigma = _as_samples("strain", strain)
    ell = _as_samples("length", length)
    delta = _as_samples("deflection", deflection)
    if not sigma.size == ell.size == delta.size:
        raise ValueError(
            f"strain, length and deflection must have the same length, got {sigma.size}, {ell.size}, {delta.size}"
        )
    if order >= 1 and np.ptp(sigma) == 0.0:
        raise ValueError("strain is constant: the polynomial map cannot be identified")
    distinct = np.unique(sigma).size
    if distinct < order + 1:
        raise ValueError(
            f"too few samples for order {order}: a polynomial of order {order} needs at least {order + 1} "
            f"distinct strain values, got {distinct}"
        )
    return sigma, ell, delta


@dataclass(frozen=True)
class LegModel:
    """Polynomial strain-to-configuration map m(sigma) = (length(sigma), deflection(sigma)).

    Attributes:
        length_coefficients: n1, shape (order + 1,), lowest power first (metres per strain unit^j).
        deflection_coefficients: n2, shape (order + 1,), lowest power first (radians per strain unit^j).
        length_standard_errors, deflection_standard_errors: OLS standard errors of the coefficients
            (residual variance times the diagonal of (V^T V)^-1); None when the model was not fitted or
            the fit had no residual degrees of freedom.
    """

    length_coefficients: np.ndarray
    deflection_coefficients: np.ndarray
    length_standard_errors: np.ndarray | None = None
    deflection_standard_errors: np.ndarray | None = None

    def __post_init__(self) -> None:
        n1 = _as_samples("length_coefficients", self.length_coefficients)
        n2 = _as_samples("deflection_coefficients", self.deflection_coefficients)
        if n1.size != n2.size:
            raise ValueError(
                f"length_coefficients and deflection_coefficients must have the same size, got {n1.size} and {n2.size}"
            )
        _check_order(n1.size - 1)
        object.__setattr__(self, "length_coefficients", n1)
        object.__setattr__(self, "deflection_coefficients", n2)
        for name in ("length_standard_errors", "deflection_standard_errors"):
            value = getattr(self, name)
            if value is not None:
                errors = _as_samples(name, value)
                if errors.size != n1.size:
                    raise ValueError(f"{name} must have {n1.size} entries, got {errors.size}")
                object.__setattr__(self, name, errors)

    @property
    def order(self) -> int:
        """Polynomial order N (the highest power of strain)."""
        return self.length_coefficients.size - 1

    @classmethod
    def fit(cls, strain: object, length: object, deflection: object, order: int = 1) -> LegModel:
        """Ordinary least squares fit of eq. 1 to M samples.

        Args:
            strain: (M,) strain readings.
            length: (M,) measured leg lengths.
            deflection: (M,) measured leg deflections.
            order: polynomial order N >= 0; needs at least N + 1 distinct strain values.

        The Vandermonde matrix is built on strain scaled to [-1, 1] for conditioning and the coefficients
        are mapped back to raw strain powers exactly (n_j = c_j / scale^j).

        Raises:
            ValueError: mismatched lengths, NaN/inf, constant strain (order >= 1), too few samples for the order.
            TypeError: non-numeric input or a non-integer order.
        """
        order = _check_order(order)
        sigma, ell, delta = _check_training_data(strain, length, deflection, order)
        scale = float(np.max(np.abs(sigma))) or 1.0
        vandermonde = np.vander(sigma / scale, order + 1, increasing=True)
        targets = np.column_stack([ell, delta])
        scaled, _, rank, _ = np.linalg.lstsq(vandermonde, targets, rcond=None)
        if rank < order + 1:
            raise ValueError(f"too few samples for order {order}: the design matrix has rank {rank} < {order + 1}")
        powers = scale ** np.arange(order + 1)
        coefficients = scaled / powers[:, None]
        dof = sigma.size - (order + 1)
        length_se = deflection_se = None
        if dof > 0:
            residual = targets - vandermonde @ scaled
            variance = np.sum(residual**2, axis=0) / dof
            gram_inverse_diagonal = np.diag(np.linalg.inv(vandermonde.T @ vandermonde)) / powers**2
            length_se = np.sqrt(variance[0] * gram_inverse_diagonal)
            deflection_se = np.sqrt(variance[1] * gram_inverse_diagonal)
        return cls(coefficients[:, 0], coefficients[:, 1], length_se, deflection_se)

    def predict(self, strain: object) -> tuple[np.ndarray, np.ndarray]:
        """(length, deflection) for strain of any shape; outputs have the strain's shape.

        Raises ValueError on NaN/inf strain (a prediction from a missing reading would be silent garbage).
        """
        sigma = float_array(strain, "strain")
        # Horner's rule, highest power first.
        length = np.full(sigma.shape, self.length_coefficients[-1])
        deflection = np.full(sigma.shape, self.deflection_coefficients[-1])
        for n1, n2 in zip(self.length_coefficients[-2::-1], self.deflection_coefficients[-2::-1]):
            length = length * sigma + n1
            deflection = deflection * sigma + n2
        return length, deflection

    def to_json(self) -> str:
        """The model as a JSON document (coefficients lowest power first; standard errors or null)."""

        def listed(values: np.ndarray | None) -> list[float] | None:
            return None if values is None else [float(v) for v in values]

        return json.dumps(
            {
                "kind": "legkit.strain.LegModel",
                "order": self.order,
                "length_coefficients": listed(self.length_coefficients),
                "deflection_coefficients": listed(self.deflection_coefficients),
                "length_standard_errors": listed(self.length_standard_errors),
                "deflection_standard_errors": listed(self.deflection_standard_errors),
            },
            indent=2,
        )

    @classmethod
    def from_json(cls, text: str) -> LegModel:
        """Inverse of ``to_json``; ValueError if the document is not a LegModel."""
        try:
            document = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"text is not valid JSON: {exc}") from exc
        if not isinstance(document, dict) or document.get("kind") != "legkit.strain.LegModel":
            raise ValueError("text is not a legkit.strain.LegModel document")
        model = cls(
            np.asarray(document["length_coefficients"], dtype=np.float64),
            np.asarray(document["deflection_coefficients"], dtype=np.float64),
            document.get("length_standard_errors"),
            document.get("deflection_standard_errors"),
        )
        if model.order != document["order"]:
            raise ValueError(f"document order {document['order']} does not match its {model.order + 1} coefficients")
        return model

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write ``to_json()`` to path."""
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(self.to_json())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LegModel:
        """Read a model written by ``save``."""
        with open(path, encoding="utf-8") as handle:
            return cls.from_json(handle.read())


def nrmse(d: object, d_hat: object) -> float:
    """The paper's percent error p(d, d_hat) = sqrt(||d - d_hat||^2 / (M d_max^2)) * 100, d_max = max |d|.

    Args:
        d: (M,) ground truth.
        d_hat: (M,) estimate.

    Raises:
        ValueError: mismatched lengths, NaN/inf, or d identically zero (d_max = 0 leaves p undefined).
    """
    truth = _as_samples("d", d)
    estimate = _as_samples("d_hat", d_hat)
    if truth.size != estimate.size:
        raise ValueError(f"d and d_hat must have the same length, got {truth.size} and {estimate.size}")
    d_max = float(np.max(np.abs(truth)))
    if d_max == 0.0:
        raise ValueError("d is identically zero: the normalisation d_max is zero")
    return float(np.sqrt(np.sum((truth - estimate) ** 2) / (truth.size * d_max**2)) * 100.0)


def kfold_indices(n_samples: int, folds: int, seed: int) -> list[np.ndarray]:
    """k disjoint index sets covering range(n_samples): a seeded permutation cut into near-equal parts.

    Raises ValueError unless 2 <= folds <= n_samples.
    """
    if not 2 <= integer(folds, "folds") <= n_samples:
        raise ValueError(f"folds must be between 2 and the number of samples ({n_samples}), got {folds}")
    permutation = np.random.default_rng(seed).permutation(n_samples)
    return [np.sort(part) for part in np.array_split(permutation, folds)]


@dataclass(frozen=True)
class CrossValidation:
    """k-fold cross-validation of one order: held-out percent NRMSE per fold and their means."""

    order: int
    length_errors: np.ndarray  # (folds,) percent
    deflection_errors: np.ndarray  # (folds,) percent

    @property
    def length_error(self) -> float:
        """Mean held-out length NRMSE over the folds (percent)."""
        return float(np.mean(self.length_errors))

    @property
    def deflection_error(self) -> float:
        """Mean held-out deflection NRMSE over the folds (percent)."""
        return float(np.mean(self.deflection_errors))


def cross_validate(
    strain: object, length: object, deflection: object, order: int = 1, folds: int = 5, seed: int = 0
) -> CrossValidation:
    """k-fold cross-validation: fit on k - 1 folds, score the held-out fold with ``nrmse``.

    Raises ValueError (as ``LegModel.fit``) if any training split has too few distinct strain values.
    """
    order = _check_order(order)
    sigma, ell, delta = _check_training_data(strain, length, deflection, order)
    parts = kfold_indices(sigma.size, folds, seed)
    length_errors, deflection_errors = [], []
    for k, held_out in enumerate(parts):
        train = np.ones(sigma.size, dtype=bool)
        train[held_out] = False
        try:
            model = LegModel.fit(sigma[train], ell[train], delta[train], order)
        except ValueError as exc:
            raise ValueError(f"fold {k}: {exc}") from exc
        length_hat, deflection_hat = model.predict(sigma[held_out])
        length_errors.append(nrmse(ell[held_out], length_hat))
        deflection_errors.append(nrmse(delta[held_out], deflection_hat))
    return CrossValidation(order, np.array(length_errors), np.array(deflection_errors))


@dataclass(frozen=True)
class OrderSelectionRow:
    """One row of the Table-1 analogue: fit (training) and cross-validation percent NRMSE of one order."""

    order: int
    fit_length: float
    fit_deflection: float
    cv_length: float
    cv_deflection: float


def order_selection_table(
    strain: object,
    length: object,
    deflection: object,
    orders: tuple[int, ...] = (1, 2, 3, 4),
    folds: int = 5,
    seed: int = 0,
) -> list[OrderSelectionRow]:
    """Fit and k-fold CV errors for each polynomial order (the paper's Table 1)."""
    rows = []
    for order in orders:
        model = LegModel.fit(strain, length, deflection, order)
        length_hat, deflection_hat = model.predict(strain)
        cv = cross_validate(strain, length, deflection, order, folds, seed)
        rows.append(
            OrderSelectionRow(
                order,
                nrmse(length, length_hat),
                nrmse(deflection, deflection_hat),
                cv.length_error,
                cv.deflection_error,
            )
        )
    return rows


def text_table(header: str, rows: Iterable[str]) -> str:
    """A plain-text table: the header, a rule under it ('+' below each '|', '-' elsewhere), then one line per row."""
    rule = "".join("+" if char == "|" else "-" for char in header)
    return "\n".join([header, rule, *rows])


def column_table(columns: Sequence[tuple[str, str]], rows: Iterable[Sequence[object]]) -> str:
    """A `text_table` of `columns` (title, format spec) joined by ' | ': each value formatted as wide as its column's
    title (pad a title to widen its column)."""
    header = " | ".join(title for title, _ in columns)
    return text_table(header, (" | ".join(format(value, f"{len(title)}{spec}") for (title, spec), value in zip(columns, row)) for row in rows))


ORDER_COLUMNS = (("order", "d"), ("fit length %", ".3f"), ("fit deflection %", ".3f"), ("CV length %", ".3f"), ("CV deflection %", ".3f"))


def format_order_table(rows: list[OrderSelectionRow]) -> str:
    """Plain-text rendering of ``order_selection_table`` (percent NRMSE)."""
    return column_table(ORDER_COLUMNS, [(row.order, row.fit_length, row.fit_deflection, row.cv_length, row.cv_deflection) for row in rows])
