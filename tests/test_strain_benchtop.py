"""Compliant four-bar leg model, synthetic benchtop data, averaging, resampling and the friction filter."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import examples
from legkit.strain import benchtop
from legkit.strain.model import LegModel, cross_validate, nrmse

SETTINGS = examples(60)
RIGID_SECONDARY = benchtop.CompliantFourBarLeg(axial_stiffness=np.inf, clamp_stiffness=np.inf)


def per_load_relevant(data, mu=0.5):
    """Per-load means of (strain, length, deflection) for the physically relevant loads."""
    _, (strain, length, deflection, normal, tangential) = benchtop.average_by_group(
        data.configuration, data.strain, data.length, data.deflection, data.normal_force, data.tangential_force
    )
    keep = benchtop.physically_relevant(normal, tangential, mu)
    return strain[keep], length[keep], deflection[keep]


# --------------------------------------------------------------------------------------------------
# The leg model
# --------------------------------------------------------------------------------------------------


def test_pure_radial_load_hand_computation() -> None:
    # Rigid secondary modes, radial load f: phi = a_r f / k, c = a_r phi, d = a_d phi, sigma = g phi.
    leg = benchtop.CompliantFourBarLeg(
        linkage_compression=0.05, linkage_deflection=0.3, linkage_stiffness=5.0,
        axial_stiffness=np.inf, clamp_stiffness=np.inf, gauge_gain=1000.0,
    )
    length, deflection, strain = leg.deform(20.0, 0.0)
    assert length == pytest.approx(leg.nominal_length - 0.05 * 0.2, abs=1e-15)
    assert deflection == pytest.approx(0.3 * 0.2, abs=1e-15)
    assert strain == pytest.approx(200.0, abs=1e-12)


def test_series_secondary_modes_hand_computation() -> None:
    # Pure hip torque tau: phi = a_d tau / k, c = a_r phi, d = a_d phi + tau / k_clamp; no axial load.
    leg = benchtop.CompliantFourBarLeg(linkage_compression=0.04, linkage_deflection=0.2, linkage_stiffness=4.0,
                                       axial_stiffness=1e4, clamp_stiffness=100.0)
    length, deflection, strain = leg.deform(0.0, 2.0)
    assert leg.nominal_length - length == pytest.approx(0.04 * 0.1, abs=1e-15)
    assert deflection == pytest.approx(0.2 * 0.1 + 0.02, abs=1e-15)
    assert strain == pytest.approx(leg.gauge_gain * 0.1, abs=1e-12)


@SETTINGS
@given(radial=st.floats(-50, 80), torque=st.floats(-5, 5))
def test_displacement_and_strain_consistent_with_compliance(radial: float, torque: float) -> None:
    leg = benchtop.CompliantFourBarLeg()
    length, deflection, strain = leg.deform(radial, torque)
    compliance = leg.compliance()
    np.testing.assert_allclose([leg.nominal_length - length, deflection], compliance @ [radial, torque], atol=1e-14)
    assert leg.strain_from_displacement(length, deflection) == pytest.approx(strain, abs=1e-9)
    # Maxwell reciprocity and positive compliance (energy).
    assert compliance[0, 1] == compliance[1, 0] and np.all(np.linalg.eigvalsh(compliance) > 0)


def test_leg_parameter_validation() -> None:
    with pytest.raises(ValueError, match="linkage_stiffness"):
        benchtop.CompliantFourBarLeg(linkage_stiffness=0.0)
    with pytest.raises(ValueError, match="clamp_stiffness"):
        benchtop.CompliantFourBarLeg(clamp_stiffness=np.nan)
    with pytest.raises(ValueError, match="radial_force contains a non-finite"):
        benchtop.CompliantFourBarLeg().deform(np.nan, 0.0)


def test_leg_frame_loads_hand_cases() -> None:
    # Leg straight down: the normal force is purely radial; a forward tangential force pushes toward -d.
    radial, torque = benchtop.leg_frame_loads(10.0, 2.0, 0.0, nominal_length=0.2)
    assert radial == pytest.approx(10.0) and torque == pytest.approx(-0.4)
    # Leg swung back a quarter turn (horizontal, toe behind the hip): the normal force is tangential.
    radial, torque = benchtop.leg_frame_loads(10.0, 0.0, np.pi / 2, nominal_length=0.2)
    assert radial == pytest.approx(0.0, abs=1e-14) and torque == pytest.approx(2.0)


# --------------------------------------------------------------------------------------------------
# Sensor, filter, averaging, resampling
# --------------------------------------------------------------------------------------------------


@SETTINGS
@given(values=st.lists(st.floats(-2000, 4000), min_size=1, max_size=100), bits=st.integers(1, 12))
def test_quantize_levels_and_error(values: list[float], bits: int) -> None:
    low, high = -1000.0, 3000.0
    step = (high - low) / (2**bits - 1)
    signal = np.array(values)
    out = benchtop.quantize(signal, bits, (low, high))
    levels = (out - low) / step
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-9)
    assert np.all((out >= low - 1e-9) & (out <= high + 1e-9))
    inside = (signal >= low) & (signal <= high)
    assert np.all(np.abs(out - signal)[inside] <= step / 2 + 1e-9)
    assert np.all(out[signal > high] == pytest.approx(high)) and np.all(out[signal < low] == pytest.approx(low))


def test_six_bit_sensor_has_64_levels() -> None:
    sensor = benchtop.StrainSensor(noise_std=0.0, bits=6, full_scale=(0.0, 63.0))
    readings = sensor.measure(np.linspace(-5, 70, 10000), np.random.default_rng(0))
    np.testing.assert_array_equal(np.unique(readings), np.arange(64.0))


def test_physically_relevant_hand_cases() -> None:
    normal = np.array([10.0, 10.0, 10.0, 0.0, -5.0, 10.0])
    tangential = np.array([0.0, 4.9, -5.0, 0.0, 0.0, -4.9])
    np.testing.assert_array_equal(benchtop.physically_relevant(normal, tangential), [True, True, False, False, False, True])
    np.testing.assert_array_equal(benchtop.physically_relevant(normal, tangential, mu=0.6)[2], True)
    with pytest.raises(ValueError, match="mu"):
        benchtop.physically_relevant(normal, tangential, mu=-1.0)
    with pytest.raises(ValueError, match="same shape"):
        benchtop.physically_relevant(normal, tangential[:2])


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 200))
def test_average_by_group_matches_a_loop(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    groups = rng.integers(0, 10, n)
    values = rng.normal(size=n)
    ids, (means,) = benchtop.average_by_group(groups, values)
    for group, mean in zip(ids, means):
        assert mean == pytest.approx(np.mean([v for g, v in zip(groups, values) if g == group]), abs=1e-12)
    assert sorted(set(groups.tolist())) == ids.tolist()


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 400), per_cell=st.integers(1, 4))
def test_resample_evenly_takes_at_most_per_cell_from_every_occupied_cell(seed: int, n: int, per_cell: int) -> None:
    rng = np.random.default_rng(seed)
    # Deliberately uneven: most samples crowd one corner of the configuration space.
    length = np.concatenate([rng.uniform(0.16, 0.17, n), rng.uniform(0.13, 0.17, 5)])
    deflection = np.concatenate([rng.uniform(0.0, 0.02, n), rng.uniform(-0.2, 0.2, 5)])
    chosen = benchtop.resample_evenly(length, deflection, bins=(6, 6), per_cell=per_cell, seed=seed)
    cells = benchtop.configuration_cells(length, deflection, (6, 6))
    assert np.all(np.diff(chosen) > 0)
    counts = np.bincount(cells[chosen], minlength=36)
    available = np.bincount(cells, minlength=36)
    np.testing.assert_array_equal(counts, np.minimum(available, per_cell))
    np.testing.assert_array_equal(benchtop.resample_evenly(length, deflection, (6, 6), per_cell, seed), chosen)


def test_grid_average_one_point_per_occupied_cell() -> None:
    length = np.array([0.10, 0.101, 0.2, 0.199, 0.16])
    deflection = np.array([0.0, 0.001, 1.0, 0.999, 0.6])
    strain = np.array([1.0, 3.0, 10.0, 20.0, 7.0])
    cell_length, cell_deflection, (cell_strain,) = benchtop.grid_average(length, deflection, strain, bins=(2, 2))
    # Cells: (low, low) holds samples 0, 1; (high, high) holds 2, 3, 4 (0.16 and 0.6 are in the upper halves).
    np.testing.assert_allclose(cell_strain, [2.0, 37.0 / 3])
    np.testing.assert_allclose(cell_length, [0.1005, (0.2 + 0.199 + 0.16) / 3])
    np.testing.assert_allclose(cell_deflection, [0.0005, (1.0 + 0.999 + 0.6) / 3])


# --------------------------------------------------------------------------------------------------
# Calibration targets on the synthetic benchtop
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_linear_model_recovers_generating_coefficients(seed: int) -> None:
    # With rigid secondary modes the configuration is exactly linear in strain; the only error is the
    # sensor (noise, 6-bit quantisation). Recovery within 4 standard errors, and the fitted map within half
    # an ADC step (in configuration units) of the generating map over the calibrated range.
    sensor = benchtop.StrainSensor()
    strain, length, deflection = per_load_relevant(benchtop.synthetic_benchtop(RIGID_SECONDARY, sensor=sensor, seed=seed))
    model = LegModel.fit(strain, length, deflection, order=1)
    n1, n2 = RIGID_SECONDARY.generating_coefficients()
    assert np.all(np.abs(model.length_coefficients - n1) <= 4 * model.length_standard_errors)
    assert np.all(np.abs(model.deflection_coefficients - n2) <= 4 * model.deflection_standard_errors)
    half_step = (sensor.full_scale[1] - sensor.full_scale[0]) / (2**sensor.bits - 1) / 2
    sigma = np.linspace(strain.min(), strain.max(), 50)
    fitted_length, fitted_deflection = model.predict(sigma)
    assert np.max(np.abs(fitted_length - (n1[0] + n1[1] * sigma))) <= abs(n1[1]) * half_step
    assert np.max(np.abs(fitted_deflection - (n2[0] + n2[1] * sigma))) <= abs(n2[1]) * half_step


def test_default_leg_meets_paper_error_levels() -> None:
    strain, length, deflection = per_load_relevant(benchtop.synthetic_benchtop(benchtop.CompliantFourBarLeg(), seed=4))
    cv = cross_validate(strain, length, deflection, order=1, folds=5, seed=0)
    assert cv.length_error <= 2.0 and cv.deflection_error <= 10.0
    # The unmodelled secondary modes matter: deflection is clearly harder than length.
    assert cv.deflection_error > cv.length_error


def test_filter_removes_pulling_and_slipping_loads() -> None:
    data = benchtop.synthetic_benchtop(sweep=benchtop.BenchtopSweep(hold_samples=2), seed=0)
    keep = benchtop.physically_relevant(data.normal_force, data.tangential_force)
    assert 0 < keep.sum() < keep.size
    assert np.all(data.normal_force[keep] > 0)
    assert np.all(np.abs(data.tangential_force[keep]) < 0.5 * data.normal_force[keep])
    # 300 Hz sampling, load held for two samples each.
    np.testing.assert_allclose(np.diff(data.time), 1 / 300)
    assert np.all(np.bincount(data.configuration) == 2)


def test_benchtop_is_deterministic_per_seed() -> None:
    sweep = benchtop.BenchtopSweep(hold_samples=3)
    a, b = benchtop.synthetic_benchtop(sweep=sweep, seed=5), benchtop.synthetic_benchtop(sweep=sweep, seed=5)
    np.testing.assert_array_equal(a.strain, b.strain)
    assert not np.array_equal(a.strain, benchtop.synthetic_benchtop(sweep=sweep, seed=6).strain)
    assert nrmse(a.length, b.length) == 0.0
