"""Kinematic walking generator: physical consistency of its ground truth, the pose targets, the experiment."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import examples
from legkit import STANDARD_GRAVITY
from legkit.experiments.strain import calibration_set, main
from legkit.robots.rhex import LEG_LENGTH, TOTAL_MASS, TRIPODS, rhex_model
from legkit.strain.benchtop import CompliantFourBarLeg, StrainSensor, leg_frame_loads, synthetic_benchtop
from legkit.strain.model import LegModel, nrmse
from legkit.strain.pose import stance_intervals, tripod_pose
from legkit.strain.walking import ClockGait, estimate_body_pose, kinematic_walk, tripod_clock_signal

LEG = CompliantFourBarLeg()


@pytest.fixture(scope="module")
def calibrated() -> LegModel:
    strain, length, deflection = calibration_set(synthetic_benchtop(LEG, seed=0))
    return LegModel.fit(strain, length, deflection, order=1)


@examples(15)
@given(
    speed=st.floats(0.1, 0.6),
    seed=st.integers(0, 2**32 - 1),
    com=st.tuples(st.floats(-0.01, 0.01), st.floats(-0.01, 0.01)),
)
def test_ground_truth_is_physically_consistent(speed: float, seed: int, com: tuple[float, float]) -> None:
    stream = kinematic_walk(speed, 1.5, seed, com_offset=com)
    rows = np.arange(stream.time.size)
    # Exactly one tripod in stance at every sample (duty factor 1/2).
    tripods = np.array(TRIPODS)
    in_stance = stream.stance[:, tripods].all(axis=2)
    assert np.all(in_stance.sum(axis=1) == 1) and stream.stance.sum(axis=1).max() == 3
    support = tripods[np.argmax(in_stance, axis=1)]
    # Stance toes are on the ground z = 0 in the world; swing toes are not below it by more than compression.
    world_toes = np.einsum("tij,tkj->tki", stream.body_rotation, stream.toes) + stream.body_position[:, None, :]
    np.testing.assert_allclose(world_toes[rows[:, None], support, 2], 0.0, atol=1e-12)
    # Quasi-static equilibrium: the vertical stance forces carry the weight and their centre of pressure is
    # the centre of mass (body-frame offset (c_x, c_y, 0)) projected on the ground.
    forces = stream.normal_force[rows[:, None], support]
    np.testing.assert_allclose(forces.sum(axis=1), TOTAL_MASS * STANDARD_GRAVITY, rtol=1e-12)
    stance_xy = world_toes[rows[:, None], support, :2]
    centre_of_pressure = np.einsum("tk,tki->ti", forces, stance_xy) / forces.sum(axis=1)[:, None]
    centre_of_mass = stream.body_position + stream.body_rotation @ np.array([com[0], com[1], 0.0])
    np.testing.assert_allclose(centre_of_pressure, centre_of_mass[:, :2], atol=1e-12)
    assert np.all(stream.normal_force[~stream.stance] == 0.0)
    # Swing legs are unloaded; the generator's pose matches tripod_pose on the true stance toes.
    assert np.all(stream.length[~stream.stance] == LEG_LENGTH) and np.all(stream.deflection[~stream.stance] == 0.0)
    pose = tripod_pose(stream.toes[rows[:, None], support], orientation="body_side")
    np.testing.assert_allclose(pose.height, stream.height, atol=1e-12)
    np.testing.assert_allclose(pose.roll, stream.roll, atol=1e-12)
    np.testing.assert_allclose(pose.pitch, stream.pitch, atol=1e-12)


def test_stance_leg_configuration_follows_the_leg_model() -> None:
    stream = kinematic_walk(0.3, 1.0, 4)
    leg_angle = stream.hip_angle + stream.deflection
    # The vertical ground force resolved along the deflected leg (in the tilted body frame).
    vertical = stream.body_rotation[:, 2, :]
    radial = stream.normal_force * (vertical[:, None, 0] * np.sin(leg_angle) + vertical[:, None, 2] * np.cos(leg_angle))
    torque = stream.normal_force * (vertical[:, None, 2] * np.sin(leg_angle) - vertical[:, None, 0] * np.cos(leg_angle))
    length, deflection, _ = LEG.deform(radial, torque * LEG.nominal_length)
    # Fixed point of the load / deformation coupling reached to well below sensor resolution.
    np.testing.assert_allclose(stream.length, length, atol=1e-9)
    np.testing.assert_allclose(stream.deflection, deflection, atol=1e-9)
    # On a level body the helper for benchtop loads gives the same resolution.
    level_radial, _ = leg_frame_loads(stream.normal_force, 0.0, leg_angle)
    assert np.max(np.abs(level_radial - radial)) < 0.02 * np.max(stream.normal_force)


def test_clock_gait_timing() -> None:
    gait = ClockGait(stance_sweep=0.6, stance_centre=-0.1)
    period = gait.period(0.2)
    assert period == pytest.approx(4 * LEG_LENGTH * np.sin(0.3) / 0.2)
    phase = np.linspace(0, 1, 601)[:-1]
    theta, stance = gait.hip_angles(phase)
    assert np.all(stance.mean(axis=0) == 0.5)
    assert np.all(np.abs(theta[stance] + 0.1) <= 0.3 + 1e-12)
    assert theta[stance].min() == pytest.approx(-0.4) and theta[stance].max() == pytest.approx(0.2, abs=2e-3)
    # Legs only ever turn forward (+theta): unwrapped angles increase monotonically.
    assert np.all(np.diff(np.unwrap(theta, axis=0), axis=0) > 0)
    with pytest.raises(ValueError, match="speed"):
        gait.period(0.0)
    with pytest.raises(ValueError, match="stance_sweep"):
        ClockGait(stance_sweep=4.0)


def test_stance_intervals_of_the_clock_signal_are_half_periods() -> None:
    stream = kinematic_walk(0.2, 3.0, 1, sensor=StrainSensor(rate=300.0))
    signal = tripod_clock_signal(stream.hip_angle, stream.stance_centre)
    samples_per_half_period = stream.period / 2 * 300
    for tripod, legs in enumerate(TRIPODS):
        intervals = stance_intervals(signal[:, tripod], stream.stance_sweep / 2 + 1e-9)
        inner = intervals[(intervals[:, 0] > 0) & (intervals[:, 1] < stream.time.size)]
        assert inner.size > 0
        assert np.all(np.abs(np.diff(inner, axis=1) - samples_per_half_period) <= 1.0)
        mask = np.zeros(stream.time.size, dtype=bool)
        for start, stop in intervals:
            mask[start:stop] = True
        np.testing.assert_array_equal(mask, stream.stance[:, legs[0]])


@pytest.mark.parametrize("speed", [0.2, 0.45])
def test_pose_targets_with_the_leg_model_in_the_loop(calibrated: LegModel, speed: float) -> None:
    stream = kinematic_walk(speed, 2.5, 7)  # more than two strides
    estimate = estimate_body_pose(stream.hip_angle, stream.strain, calibrated, stream.stance_centre)
    assert np.max(np.abs(estimate.pose.height - stream.height)) <= 0.005
    assert np.max(np.abs(estimate.pose.roll - stream.roll)) <= np.radians(2.0)
    assert np.max(np.abs(estimate.pose.pitch - stream.pitch)) <= np.radians(2.0)
    stance = stream.stance
    assert nrmse(stream.length[stance], estimate.length[stance]) <= 2.0
    assert nrmse(stream.deflection[stance], estimate.deflection[stance]) <= 10.0
    # The body really moves: the errors are small against the motion they track.
    assert np.ptp(stream.height) > 0.005 and np.ptp(stream.roll) > np.radians(2.0)


@examples(60)
@given(
    theta=st.floats(-0.6, 0.6),
    length=st.floats(0.12, 0.2),
    radius=st.floats(0.0, 0.03),
    samples=st.integers(1, 4),
)
def test_toe_radius_puts_the_ground_below_the_toe_centres(theta, length, radius, samples) -> None:
    # Every leg at the same angle and a leg model predicting (length, 0) for any strain: the toe centres lie
    # at z = -length cos(theta) in the body frame, a level plane, so by hand the body stands
    # length cos(theta) + radius above the ground, level, with the support origin radius below s_0.
    hips = np.full((samples, 6), theta)
    model = LegModel([length, 0.0], [0.0, 0.0])
    strain = np.zeros((samples, 6))
    estimate = estimate_body_pose(hips, strain, model, toe_radius=radius)
    centres = estimate_body_pose(hips, strain, model)
    np.testing.assert_allclose(estimate.pose.height, length * np.cos(theta) + radius, atol=1e-12)
    np.testing.assert_allclose(np.stack([estimate.pose.roll, estimate.pose.pitch]), 0.0, atol=1e-12)
    np.testing.assert_allclose(estimate.pose.origin[:, 2], -length * np.cos(theta) - radius, atol=1e-12)
    np.testing.assert_array_equal(estimate.pose.rotation, centres.pose.rotation)
    np.testing.assert_array_equal(estimate.toes, centres.toes)


def test_walk_is_deterministic_and_validates_input() -> None:
    a, b = kinematic_walk(0.3, 0.5, 2), kinematic_walk(0.3, 0.5, 2)
    np.testing.assert_array_equal(a.strain, b.strain)
    np.testing.assert_array_equal(a.height, b.height)
    with pytest.raises(ValueError, match="duration"):
        kinematic_walk(0.3, -1.0)
    with pytest.raises(ValueError, match="shorter than one sample"):
        kinematic_walk(0.3, 1e-4)
    with pytest.raises(ValueError, match="com_offset"):
        kinematic_walk(0.3, 0.5, com_offset=(0.3, 0.0))
    with pytest.raises(ValueError, match="hip_angle and strain"):
        estimate_body_pose(a.hip_angle, a.strain[:, :3], LegModel([0.17, 0.0], [0.0, 0.0]))
    for bad in (-0.001, np.nan, np.inf):
        with pytest.raises(ValueError, match="toe_radius"):
            estimate_body_pose(a.hip_angle, a.strain, LegModel([0.17, 0.0], [0.0, 0.0]), toe_radius=bad)
    assert a.toe_radius == 0.0  # point toes


def test_rhex_model_structure() -> None:
    model = rhex_model()
    assert model.nq == 13 and model.nv == 12 and model.nbodies == 7
    assert model.total_mass == pytest.approx(TOTAL_MASS)
    assert all(model.joint_type(i) == "revolute" for i in range(1, 7))


@pytest.mark.slow
def test_experiment_main_writes_figure_and_tables(tmp_path, capsys) -> None:
    assert main(["--out", str(tmp_path), "--runs", "1", "--duration", "1.5"]) == 0
    printed = capsys.readouterr().out
    assert "Table 1 analogue" in printed and "Table 2 analogue" in printed
    assert "kinematic" in printed
    figure = tmp_path / "strain_pose_stride.png"
    assert figure.exists() and figure.stat().st_size > 10_000
