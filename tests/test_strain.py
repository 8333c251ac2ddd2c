"""Leg strain model (eq. 1): fitting, prediction, NRMSE, cross-validation, JSON, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import examples
from legkit.strain.model import (
    LegModel,
    cross_validate,
    format_order_table,
    kfold_indices,
    nrmse,
    order_selection_table,
)

SETTINGS = examples(100)


def spread_strain(rng: np.random.Generator, count: int, scale: float) -> np.ndarray:
    """Distinct, well-spread strain values in [-scale, 3 scale] (jittered grid, shuffled)."""
    grid = np.linspace(-scale, 3 * scale, count) + rng.uniform(-0.2, 0.2, count) * 4 * scale / count
    return rng.permutation(grid)


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    order=st.integers(0, 4),
    extra=st.integers(0, 40),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
)
def test_exact_polynomial_data_recovers_the_coefficients(seed: int, order: int, extra: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    sigma = spread_strain(rng, order + 1 + extra, scale)
    # Coefficients of comparable effect over the strain range: n_j = c_j / scale^j.
    n1 = rng.uniform(-1, 1, order + 1) / scale ** np.arange(order + 1)
    n2 = rng.uniform(-1, 1, order + 1) / scale ** np.arange(order + 1)
    length = sum(n1[j] * sigma**j for j in range(order + 1))
    deflection = sum(n2[j] * sigma**j for j in range(order + 1))
    model = LegModel.fit(sigma, length, deflection, order=order)
    weights = scale ** np.arange(order + 1)
    np.testing.assert_allclose(model.length_coefficients * weights, n1 * weights, atol=1e-8)
    np.testing.assert_allclose(model.deflection_coefficients * weights, n2 * weights, atol=1e-8)
    assert model.order == order
    predicted_length, predicted_deflection = model.predict(sigma)
    np.testing.assert_allclose(predicted_length, length, atol=1e-8)
    np.testing.assert_allclose(predicted_deflection, deflection, atol=1e-8)


def test_linear_fit_matches_closed_form_and_standard_errors() -> None:
    # Simple regression by the textbook formulas, independent of the Vandermonde least squares.
    rng = np.random.default_rng(7)
    x = rng.uniform(0, 1000, 200)
    y = 0.17 - 2e-5 * x + rng.normal(0, 1e-3, 200)
    model = LegModel.fit(x, y, 3 * y, order=1)
    sxx = np.sum((x - x.mean()) ** 2)
    slope = np.sum((x - x.mean()) * (y - y.mean())) / sxx
    intercept = y.mean() - slope * x.mean()
    residual_variance = np.sum((y - intercept - slope * x) ** 2) / (x.size - 2)
    np.testing.assert_allclose(model.length_coefficients, [intercept, slope], rtol=1e-10)
    np.testing.assert_allclose(model.deflection_coefficients, [3 * intercept, 3 * slope], rtol=1e-10)
    assert model.length_standard_errors[1] == pytest.approx(math.sqrt(residual_variance / sxx), rel=1e-8)
    assert model.length_standard_errors[0] == pytest.approx(
        math.sqrt(residual_variance * (1 / x.size + x.mean() ** 2 / sxx)), rel=1e-8
    )


def test_exactly_determined_fit_has_no_standard_errors() -> None:
    model = LegModel.fit([0.0, 1.0], [1.0, 3.0], [0.0, -1.0], order=1)
    np.testing.assert_allclose(model.length_coefficients, [1.0, 2.0])
    assert model.length_standard_errors is None and model.deflection_standard_errors is None


def test_nrmse_hand_computation() -> None:
    # Errors 0.5, 0, 1, 0.5 -> sum of squares 1.5; M = 4; d_max = 3: sqrt(1.5 / 36) * 100.
    assert nrmse([1.0, -2.0, 3.0, 0.0], [1.5, -2.0, 2.0, 0.5]) == pytest.approx(20.412414523193153, rel=1e-14)
    # d_max is the largest magnitude, here from a negative sample: sqrt(1 / (2 * 16)) * 100.
    assert nrmse([-4.0, 1.0], [-4.0, 2.0]) == pytest.approx(100 / math.sqrt(32), rel=1e-14)


@SETTINGS
@given(
    pairs=st.lists(
        st.tuples(st.floats(-1e3, 1e3, allow_subnormal=False), st.floats(-1e3, 1e3, allow_subnormal=False)),
        min_size=1,
        max_size=50,
    ).filter(lambda pairs: max(abs(d) for d, _ in pairs) > 1e-3)
)
def test_nrmse_matches_a_plain_loop(pairs: list[tuple[float, float]]) -> None:
    squared = 0.0
    for d, d_hat in pairs:
        squared += (d - d_hat) ** 2
    d_max = max(abs(d) for d, _ in pairs)
    expected = math.sqrt(squared / (len(pairs) * d_max**2)) * 100
    truth, estimate = zip(*pairs)
    assert nrmse(truth, estimate) == pytest.approx(expected, rel=1e-12, abs=1e-12)


@SETTINGS
@given(n=st.integers(2, 300), folds=st.integers(2, 20), seed=st.integers(0, 2**32 - 1))
def test_folds_are_disjoint_and_cover_the_data(n: int, folds: int, seed: int) -> None:
    folds = min(folds, n)
    parts = kfold_indices(n, folds, seed)
    assert len(parts) == folds
    joined = np.concatenate(parts)
    assert joined.size == n and np.array_equal(np.sort(joined), np.arange(n))  # disjoint and covering
    sizes = [part.size for part in parts]
    assert max(sizes) - min(sizes) <= 1 and min(sizes) >= 1
    assert all(np.array_equal(a, b) for a, b in zip(parts, kfold_indices(n, folds, seed)))  # deterministic


def test_leave_one_out_matches_the_hat_matrix_shortcut() -> None:
    # For OLS the leave-one-out residual is e_i / (1 - h_ii); with single-sample folds the paper's NRMSE of a
    # fold is |e_i / (1 - h_ii)| / |d_i| * 100, so the CV mean has a closed form.
    rng = np.random.default_rng(11)
    sigma = rng.uniform(0, 1000, 40)
    length = 0.17 - 2e-5 * sigma + rng.normal(0, 5e-4, 40)
    deflection = 1e-4 * sigma + rng.normal(0, 5e-3, 40)
    cv = cross_validate(sigma, length, deflection, order=2, folds=40, seed=0)
    design = np.vander(sigma, 3, increasing=True)
    hat = design @ np.linalg.solve(design.T @ design, design.T)
    leverage = np.diag(hat)
    for values, errors in ((length, cv.length_errors), (deflection, cv.deflection_errors)):
        loo = (values - hat @ values) / (1 - leverage)
        expected = np.abs(loo) / np.abs(values) * 100
        order = kfold_indices(40, 40, 0)
        np.testing.assert_allclose(errors, expected[np.concatenate(order)], rtol=1e-7)
        assert np.mean(errors) == pytest.approx(np.mean(expected), rel=1e-7)


def test_order_selection_table_on_quadratic_data() -> None:
    rng = np.random.default_rng(5)
    sigma = rng.uniform(-500, 2500, 300)
    length = 0.17 - 2e-5 * sigma + 3e-9 * sigma**2 + rng.normal(0, 1e-5, 300)
    deflection = 1e-4 * sigma - 2e-8 * sigma**2 + rng.normal(0, 1e-4, 300)
    rows = order_selection_table(sigma, length, deflection, orders=(1, 2, 3, 4), folds=5, seed=1)
    assert [row.order for row in rows] == [1, 2, 3, 4]
    # The quadratic term is far above the noise: order 1 is visibly worse; orders >= 2 reach the noise floor.
    assert rows[0].cv_length > 3 * rows[1].cv_length and rows[0].cv_deflection > 3 * rows[1].cv_deflection
    for row in rows[1:]:
        assert row.fit_length == pytest.approx(rows[1].fit_length, rel=0.05)
    # Training error never increases with order (nested models).
    fits = [row.fit_length for row in rows]
    assert all(b <= a + 1e-15 for a, b in zip(fits, fits[1:]))
    text = format_order_table(rows)
    assert text.count("\n") == 5 and "CV deflection" in text


def test_json_round_trip(tmp_path) -> None:
    rng = np.random.default_rng(2)
    sigma = rng.uniform(0, 1000, 50)
    model = LegModel.fit(sigma, 0.17 - 2e-5 * sigma + rng.normal(0, 1e-4, 50), 1e-4 * sigma, order=3)
    path = tmp_path / "leg.json"
    model.save(path)
    loaded = LegModel.load(path)
    assert np.array_equal(loaded.length_coefficients, model.length_coefficients)
    assert np.array_equal(loaded.deflection_coefficients, model.deflection_coefficients)
    assert np.array_equal(loaded.length_standard_errors, model.length_standard_errors)
    np.testing.assert_array_equal(loaded.predict(sigma)[0], model.predict(sigma)[0])
    unfitted = LegModel([0.17, -2e-5], [0.0, 1e-4])
    assert LegModel.from_json(unfitted.to_json()).length_standard_errors is None


def test_predict_keeps_shape_and_uses_horner_correctly() -> None:
    model = LegModel([1.0, 2.0, 3.0], [0.0, 0.0, 1.0])
    length, deflection = model.predict(np.array([[0.0, 1.0], [2.0, -1.0]]))
    np.testing.assert_array_equal(length, [[1.0, 6.0], [17.0, 2.0]])
    np.testing.assert_array_equal(deflection, [[0.0, 1.0], [4.0, 1.0]])


# --------------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("strain", "length", "deflection", "order", "error", "match"),
    [
        ([0.0, 1.0, 2.0], [1.0, 2.0], [1.0, 2.0, 3.0], 1, ValueError, "same length"),
        ([0.0, np.nan, 2.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 1, ValueError, "strain contains a non-finite"),
        ([0.0, 1.0, 2.0], [1.0, np.inf, 3.0], [1.0, 2.0, 3.0], 1, ValueError, "length contains a non-finite"),
        ([0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [np.nan, 2.0, 3.0], 1, ValueError, "deflection contains"),
        ([5.0, 5.0, 5.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 1, ValueError, "strain is constant"),
        ([0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 3, ValueError, "too few samples for order 3"),
        ([0.0, 1.0, 1.0, 0.0], [1.0, 2.0, 3.0, 4.0], [1.0, 2.0, 3.0, 4.0], 2, ValueError, "too few samples"),
        ([0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 1.0, TypeError, "order must be an integer"),
        ([0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], -1, ValueError, "order must be between"),
        ([[0.0, 1.0]], [1.0, 2.0], [1.0, 2.0], 1, ValueError, "strain must be one-dimensional"),
        ([], [], [], 1, ValueError, "strain is empty"),
        (["a", "b"], [1.0, 2.0], [1.0, 2.0], 1, TypeError, "strain must be an array of numbers"),
    ],
)
def test_fit_rejects_bad_input(strain, length, deflection, order, error, match) -> None:
    with pytest.raises(error, match=match):
        LegModel.fit(strain, length, deflection, order=order)


def test_other_bad_inputs() -> None:
    model = LegModel([0.17, -2e-5], [0.0, 1e-4])
    with pytest.raises(ValueError, match="strain contains a non-finite"):
        model.predict([1.0, np.nan])
    with pytest.raises(ValueError, match="d is identically zero"):
        nrmse([0.0, 0.0], [1.0, 0.0])
    with pytest.raises(ValueError, match="d and d_hat must have the same length"):
        nrmse([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="folds must be between"):
        kfold_indices(5, 6, 0)
    with pytest.raises(ValueError, match="folds must be between"):
        cross_validate([0.0, 1.0, 2.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0], order=1, folds=1)
    with pytest.raises(ValueError, match=r"fold \d+: too few samples for order 2"):
        # Three distinct strains suffice for order 2 overall, but every 2-fold training split has at most two.
        cross_validate([0.0, 1.0, 2.0, 2.0], [1.0, 2.0, 3.0, 3.0], [0.0, 1.0, 2.0, 2.0], order=2, folds=2, seed=3)
    with pytest.raises(ValueError, match="same size"):
        LegModel([0.17, 1.0], [0.0])
    with pytest.raises(ValueError, match="not a legkit.strain.LegModel"):
        LegModel.from_json('{"kind": "something else"}')
    with pytest.raises(ValueError, match="not valid JSON"):
        LegModel.from_json("{")
