"""RHex walking in the contact simulation (legkit.strain.simulated): leg springs, clock, gait, the strain models' accuracy targets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from legkit.experiments.strain import calibration_set, main
from legkit.robots.rhex import LEG_LENGTH, TOTAL_MASS, TRIPODS, rhex_compliant_model, rhex_model
from legkit.strain.benchtop import CompliantFourBarLeg, synthetic_benchtop
from legkit.strain.model import LegModel, nrmse
from legkit.strain.pose import toe_in_body
from legkit.strain.simulated import (
    TOE_BODIES,
    BuehlerClock,
    SimulationSettings,
    leg_polar,
    leg_springs,
    simulated_walk,
)
from legkit.strain.walking import ClockGait, estimate_body_pose

G = lk.STANDARD_GRAVITY
LEG = CompliantFourBarLeg()
TRIPOD_ARRAY = np.array(TRIPODS)


@pytest.fixture(scope="module")
def calibrated() -> LegModel:
    strain, length, deflection = calibration_set(synthetic_benchtop(LEG, seed=0))
    return LegModel.fit(strain, length, deflection, order=1)


# Two-second simulated walks: every test on them is slow.
@pytest.fixture(scope="module", params=[pytest.param(speed, marks=pytest.mark.slow) for speed in (0.2, 0.45)])
def walk(request):
    return simulated_walk(request.param, 2.0, seed=3)


def first_stride(stream):
    return stream.time < stream.time[0] + stream.period


def single_tripod_support(stream, support):
    """Samples where the given tripod (per sample) has all three toes down and the other tripod none."""
    rows = np.arange(stream.time.size)[:, None]
    own = stream.stance[rows, TRIPOD_ARRAY[support]].all(axis=1)
    other = stream.stance[rows, TRIPOD_ARRAY[1 - support]].any(axis=1)
    return own & ~other


# --- the leg springs reproduce the four-bar compliance --------------------------------------------------


@examples(60)
@given(
    a_r=st.floats(0.01, 0.08),
    a_d=st.floats(-0.4, 0.4),
    k_link=st.floats(1.0, 10.0),
    k_axial=st.floats(5e3, 1e5),
    k_clamp=st.floats(50.0, 1e3),
    f_r=st.floats(-1.0, 1.0),
    f_t=st.floats(-1.0, 1.0),
)
def test_springs_give_the_four_bar_compliance(a_r, a_d, k_link, k_axial, k_clamp, f_r, f_t):
    # Statics on the simulated leg, independently of the derivation: a toe force F maps to joint torques
    # J^T F (legkit's Jacobian of the toe on the compliant model), the springs give the joint deflections,
    # and leg_polar the (length, deflection). Small loads keep it linear.
    leg = CompliantFourBarLeg(
        linkage_compression=a_r, linkage_deflection=a_d, linkage_stiffness=k_link,
        axial_stiffness=k_axial, clamp_stiffness=k_clamp,
    )
    springs = leg_springs(leg)
    model = rhex_compliant_model(springs.axis)
    scale = 1e-3
    # Leg 0 hanging straight down: radial force f_r pushes the toe up (+z), f_t = -F_x (toward +d).
    force = scale * np.array([-f_t, 0.0, f_r])
    jacobian = lk.jacobian(model, model.neutral(), int(TOE_BODIES[0]), point=[0.0, 0.0, -LEG_LENGTH])[:3]
    torques = jacobian.T @ force
    flex = torques[7] / springs.flex_stiffness
    slide = torques[8] / springs.slide_stiffness
    length, deflection = leg_polar(flex, slide, springs.axis)
    expected = leg.compliance() @ (scale * np.array([f_r, f_t * LEG_LENGTH]))
    magnitude = np.abs(leg.compliance()).max() * scale
    np.testing.assert_allclose([LEG_LENGTH - length, deflection], expected, atol=1e-4 * magnitude)


def test_default_springs_match_the_documented_values():
    # By hand: C = a a^T / k_link + diag(1/k_axial, 1/k_clamp) = [[4.333e-4, 2e-3], [2e-3, 1.1e-2]];
    # u ~ (-0.17 * 2e-3 / 4.333e-4, 0, 1) = (-0.7846, 0, 1) -> (-0.617, 0, 0.787); k_slide = 0.787^2 / 4.333e-4
    # = 1.43e3 N/m; k_flex = 1 / (1.1e-2 - 4e-6 / 4.333e-4) = 565 N m/rad.
    springs = leg_springs(LEG)
    np.testing.assert_allclose(springs.axis, [-0.617, 0.0, 0.787], atol=1e-3)
    assert springs.slide_stiffness == pytest.approx(1.43e3, rel=2e-3)
    assert springs.flex_stiffness == pytest.approx(565.2, rel=2e-3)


@examples(60)
@given(
    hips=st.lists(st.floats(-4.0, 4.0), min_size=6, max_size=6),
    flex=st.lists(st.floats(-0.3, 0.3), min_size=6, max_size=6),
    slide=st.lists(st.floats(-0.03, 0.03), min_size=6, max_size=6),
)
def test_leg_polar_gives_the_forward_kinematics_toe(hips, flex, slide):
    springs = leg_springs(LEG)
    model = rhex_compliant_model(springs.axis)
    q = model.neutral()
    q[7::3], q[8::3], q[9::3] = hips, flex, slide
    poses = lk.forward_kinematics(model, q)
    toes_fk = np.array([poses[b][:3, :3] @ [0.0, 0.0, -LEG_LENGTH] + poses[b][:3, 3] for b in TOE_BODIES])
    length, deflection = leg_polar(np.array(flex), np.array(slide), springs.axis)
    np.testing.assert_allclose(toe_in_body(np.array(hips), length, deflection, np.arange(6)), toes_fk, atol=1e-12)


def test_compliant_model_keeps_the_rigid_model_mass_and_rejects_bad_axes():
    model = rhex_compliant_model(leg_springs(LEG).axis)
    assert model.nq == 7 + 18 and model.total_mass == pytest.approx(rhex_model().total_mass, rel=1e-12)
    for bad in ([0.0, 0.0, 2.0], [0.0, 1.0, 0.0], [np.nan, 0.0, 1.0], [1.0, 0.0]):
        with pytest.raises(ValueError, match="spring_axis"):
            rhex_compliant_model(bad)


# --- the clock -----------------------------------------------------------------------------------------


@examples(60)
@given(sweep=st.floats(0.2, 1.5), centre=st.floats(-0.5, 0.5), phase=st.floats(-3.0, 3.0))
def test_half_duty_clock_is_the_walking_clock(sweep, centre, phase):
    angle, _ = BuehlerClock(sweep, centre, 0.5).hip_targets(np.array([phase]), 1.0)
    expected, _ = ClockGait(sweep, centre).hip_angles(np.array([phase]))
    wrapped = np.mod(angle + np.pi, 2 * np.pi) - np.pi
    np.testing.assert_allclose(np.angle(np.exp(1j * (wrapped - expected))), 0.0, atol=1e-12)


@examples(40)
@given(duty=st.floats(0.5, 0.9), centre=st.floats(-0.4, 0.4), period=st.floats(0.2, 2.0))
def test_clock_is_continuous_and_its_rate_is_the_derivative(duty, centre, period):
    clock = BuehlerClock(0.6, centre, duty)
    phase = np.linspace(0.0, 2.0, 20001)
    angle, rate = clock.hip_targets(phase, period)
    step = np.diff(angle, axis=0)
    # Continuous and monotone: the largest per-sample step is the swing rate times the sample spacing.
    assert np.all(step > 0) and step.max() <= rate.max() * period * 1e-4 * (1 + 1e-9)
    np.testing.assert_allclose(angle[-1] - angle[0], 2 * 2 * np.pi, rtol=1e-12)
    # Each leg spends the duty factor in its slow stance sweep.
    slow = np.isclose(rate, 0.6 / (duty * period))
    np.testing.assert_allclose(slow[:-1].mean(axis=0), duty, atol=2e-3)


def test_bad_walk_arguments_raise():
    for kwargs, name in (
        ({"speed": 0.0, "duration": 1.0}, "speed"),
        ({"speed": 0.2, "duration": -1.0}, "duration"),
        ({"speed": 0.2, "duration": 1e-4}, "duration"),
    ):
        with pytest.raises(ValueError, match=name):
            simulated_walk(**kwargs)
    with pytest.raises(ValueError, match="duty_factor"):
        BuehlerClock(duty_factor=0.4)
    with pytest.raises(ValueError, match="stance_sweep"):
        BuehlerClock(stance_sweep=4.0)


# --- the simulated walk ----------------------------------------------------------------------------------


def test_walks_forward_at_roughly_the_commanded_speed(walk):
    elapsed = walk.time[-1] - walk.time[0]
    speed = (walk.body_position[-1, 0] - walk.body_position[0, 0]) / elapsed
    assert abs(speed - walk.speed) <= 0.3 * walk.speed


def test_tripods_alternate(walk):
    # The tripod carrying more of the ground force switches A, B, A, ... about twice per gait period.
    load = np.stack([walk.normal_force[:, TRIPOD_ARRAY[k]].sum(axis=1) for k in (0, 1)], axis=1)
    loaded = load.sum(axis=1) > 0
    dominant = np.argmax(load, axis=1)[loaded]
    # Load sharing flickers during double support: keep runs lasting at least a tenth of a period.
    starts = np.flatnonzero(np.diff(dominant, prepend=-1))
    lengths = np.diff(np.append(starts, dominant.size))
    held = dominant[starts][lengths >= 0.1 * walk.period / (walk.time[1] - walk.time[0])]
    switches = np.count_nonzero(np.diff(held))
    expected = 2 * (walk.time[-1] - walk.time[0]) / walk.period
    assert expected - 2 <= switches <= expected + 2
    # Averaged over the record, the dominant tripod carries most of the load.
    assert load[loaded].max(axis=1).sum() / load[loaded].sum() > 0.75


def test_stance_legs_carry_the_weight(walk):
    strides = int((walk.time[-1] - walk.time[0]) / walk.period)
    window = walk.time < walk.time[0] + strides * walk.period
    mean_force = walk.normal_force[window].sum(axis=1).mean()
    assert abs(mean_force - TOTAL_MASS * G) <= 0.1 * TOTAL_MASS * G
    assert np.all(walk.normal_force[~walk.stance] == 0.0)


def test_stream_is_self_consistent_and_deterministic(walk):
    # Strain is the four-bar gauge reading of the recorded leg state, within sensor noise and quantisation.
    true = LEG.strain_from_displacement(walk.length, walk.deflection)
    step = 4000.0 / 63
    assert np.abs(walk.strain - np.clip(true, -1000, 3000)).max() <= step / 2 + 6 * 20.0
    assert np.all(np.abs(walk.hip_angle) <= np.pi)
    np.testing.assert_allclose(walk.toes, toe_in_body(walk.hip_angle, walk.length, walk.deflection, np.arange(6)), atol=1e-15)
    short = SimulationSettings(warmup_periods=0.5, settle_time=0.05)
    ticks: list[float] = []
    a, b = simulated_walk(walk.speed, 0.2, seed=11, settings=short), simulated_walk(walk.speed, 0.2, seed=11, settings=short, ticks=ticks.append)
    assert np.array_equal(a.strain, b.strain) and np.array_equal(a.body_position, b.body_position)
    # One tick per strain sample, warm-up included, rising to the whole walk.
    assert len(ticks) > len(a.time) and np.all(np.diff(ticks) > 0) and ticks[0] > 0 and ticks[-1] == 1.0


# --- the accuracy targets on simulated data (benches/strain_simulated_targets.py prints them for seeds 3-5) -----


def test_accuracy_targets_on_the_simulated_walk(walk, calibrated):
    # NRMSE over all stance samples; pose errors over the first stride's single-tripod-support samples.
    estimate = estimate_body_pose(walk.hip_angle, walk.strain, calibrated, walk.stance_centre, walk.toe_radius)
    assert nrmse(walk.length[walk.stance], estimate.length[walk.stance]) <= 2.0
    assert nrmse(walk.deflection[walk.stance], estimate.deflection[walk.stance]) <= 10.0
    stride = first_stride(walk) & single_tripod_support(walk, estimate.support)
    # A stride at either speed holds dozens of single-support samples: the maxima below are not vacuous.
    assert np.count_nonzero(stride) >= 0.1 * walk.period * 300
    assert np.abs(estimate.pose.height - walk.height)[stride].max() <= 0.005
    assert np.abs(estimate.pose.roll - walk.roll)[stride].max() <= np.radians(2.0)
    assert np.abs(estimate.pose.pitch - walk.pitch)[stride].max() <= np.radians(2.0)


def test_stance_toes_barely_sink(walk):
    # The soft contact's penetration is what the toe-radius correction leaves in the height estimate:
    # stance toe centres (radius 6 mm) stay within a few millimetres above the ground and never below it.
    world_z = np.einsum("tij,tkj->tki", walk.body_rotation, walk.toes)[..., 2] + walk.body_position[:, None, 2]
    stance_z = world_z[walk.stance]
    assert stance_z.min() >= 0.0 and stance_z.max() <= walk.toe_radius + 1e-4


@pytest.mark.slow
def test_cli_simulated_source(tmp_path, capsys):
    assert main(["--source", "simulated", "--runs", "1", "--duration", "0.5", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "RHex in the contact simulation" in printed and (tmp_path / "strain_pose_stride.png").is_file()
