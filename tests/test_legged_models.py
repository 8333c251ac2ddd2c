"""The quadruped and biped models: sizes, URDF round trip, leg inverse kinematics, and the gait experiment."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import legkit as lk
import legkit.stability as ls
from conftest import examples
from legkit.experiments import gait
from legkit.gaits import periodic_lip, quadruped_amble
from legkit.robots.biped import BipedParameters, build_biped
from legkit.robots.legs import model_to_urdf
from legkit.robots.quadruped import LEGS, QuadrupedParameters, build_quadruped

BUILDERS = {"quadruped": build_quadruped, "biped": build_biped}


def _actuated(model: lk.Model) -> int:
    return sum(model.joint_type(i) in ("revolute", "prismatic") for i in range(model.nbodies))


def test_sizes_match_the_paper():
    quadruped, biped = build_quadruped().model, build_biped().model
    assert (quadruped.nq, quadruped.nv, _actuated(quadruped)) == (19, 18, 12)
    assert (biped.nq, biped.nv, _actuated(biped)) == (23, 22, 16)


def test_mass_follows_overridden_parameters():
    heavy = QuadrupedParameters(head_mass=0.5)
    assert build_quadruped(heavy).model.total_mass == pytest.approx(heavy.total_mass, rel=1e-12)
    assert build_quadruped(heavy).model.total_mass == pytest.approx(build_quadruped().model.total_mass + 0.2, rel=1e-12)
    legs = BipedParameters(thigh_mass=6.0)
    assert build_biped(legs).model.total_mass == pytest.approx(legs.total_mass, rel=1e-12)
    with pytest.raises(ValueError, match="thigh_mass"):
        QuadrupedParameters(thigh_mass=-1.0)
    with pytest.raises(ValueError, match="arm_length"):
        BipedParameters(arm_length=0.0)


def _permutation(built: lk.Model, loaded: lk.Model) -> tuple[np.ndarray, np.ndarray]:
    """(perm_q, perm_v) with loaded_q = built_q[perm_q], matched through body names (orders differ)."""
    perm_v = np.arange(built.nv)
    for i, name in enumerate(loaded.names):
        if loaded.joint_type(i) in ("revolute", "prismatic"):
            perm_v[loaded.idx_v[i]] = built.idx_v[built.names.index(name)]
    return np.concatenate([np.arange(7), perm_v[6:] + 1]), perm_v


@examples(10)
@given(st.sampled_from(sorted(BUILDERS)), st.integers(0, 2**32 - 1))
def test_urdf_round_trip_gives_the_same_dynamics(kind, seed):
    robot = BUILDERS[kind]()
    built = robot.model
    loaded = lk.Model.from_urdf(robot.to_urdf(), floating_base=True)
    assert sorted(loaded.names) == sorted(built.names)
    perm_q, perm_v = _permutation(built, loaded)
    rng = np.random.default_rng(seed)
    q = built.neutral()
    quaternion = rng.normal(size=4)
    q[:3], q[3:7], q[7:] = rng.normal(size=3), quaternion / np.linalg.norm(quaternion), rng.uniform(-2, 2, built.nv - 6)
    v, a = rng.normal(size=built.nv), rng.normal(size=built.nv)
    np.testing.assert_allclose(lk.crba(loaded, q[perm_q]), lk.crba(built, q)[np.ix_(perm_v, perm_v)], atol=1e-12)
    np.testing.assert_allclose(lk.rnea(loaded, q[perm_q], v[perm_v], a[perm_v]), lk.rnea(built, q, v, a)[perm_v], rtol=1e-12, atol=1e-10)


def _foot_world(model: lk.Model, q: np.ndarray, body: str, point: np.ndarray) -> np.ndarray:
    pose = lk.forward_kinematics(model, q)[..., model.names.index(body), :, :]
    return np.einsum("...ij,j->...i", pose[..., :3, :3], point) + pose[..., :3, 3]


def test_urdf_export_refuses_a_joint_urdf_cannot_describe():
    model = lk.Model()
    model.add_revolute(0, [0, 1, 0], None, lk.MassProperties.solid_box(1.0, [0.1, 0.1, 0.3]), "arm")
    model.add_helical("arm", [0, 0, 1], 0.01, None, lk.MassProperties.solid_box(0.2, [0.05, 0.05, 0.05]), "screw")
    with pytest.raises(ValueError, match="helical joint \\(body 'screw'\\)"):
        model_to_urdf(model, "screw_arm")


@examples(30)
@given(st.sampled_from(LEGS), st.floats(-0.07, 0.07), st.floats(-0.03, 0.03), st.floats(0.06, 0.12))
def test_quadruped_leg_ik_reaches_the_target(leg, dx, dy, depth):
    robot = build_quadruped()
    hip = robot.parameters.hip_position(leg)
    target = hip + np.array([dx, dy, -depth])
    q = robot.model.neutral()
    cols = robot.joint_slice(leg)
    q[cols.start + 1 : cols.stop + 1] = robot.leg_angles(leg, target)
    body, point = robot.feet[leg]
    np.testing.assert_allclose(_foot_world(robot.model, q, body, point), target, atol=1e-12)


@examples(30)
@given(st.sampled_from(["l", "r"]), st.floats(-0.3, 0.3), st.floats(-0.1, 0.1), st.floats(0.6, 0.8))
def test_biped_leg_ik_reaches_the_target_with_a_flat_foot(side, dx, dy, depth):
    robot = build_biped()
    target = np.array([dx, (robot.parameters.hip_y if side == "l" else -robot.parameters.hip_y) + dy, -depth])
    assume(np.linalg.norm([dx, dy, depth]) < 0.999 * (robot.parameters.thigh_length + robot.parameters.shank_length))
    q = robot.model.neutral()
    cols = robot.joint_slice(side)
    q[cols.start + 1 : cols.stop + 1] = robot.leg_angles(side, target)
    pose = lk.forward_kinematics(robot.model, q)[robot.model.names.index(f"{side}_foot")]
    np.testing.assert_allclose(pose[:3, 3], target, atol=1e-12)
    np.testing.assert_allclose(pose[:3, :3], np.eye(3), atol=1e-12)
    corners = np.array([_foot_world(robot.model, q, b, p) for b, p in robot.feet[side]])
    np.testing.assert_allclose(corners[:, 2], target[2] - robot.parameters.ankle_height, atol=1e-12)


def test_unreachable_foot_raises():
    robot = build_quadruped()
    with pytest.raises(ValueError, match="out of reach"):
        robot.leg_angles("lf", robot.parameters.hip_position("lf") + [0.0, 0.0, -0.3])


def test_periodic_lip_satisfies_the_pendulum_equation():
    n, period, height = 256, 0.8, 0.9
    t = np.arange(n) * period / n
    zmp = np.column_stack([0.05 * np.sin(2 * np.pi * t / period), 0.02 * np.cos(4 * np.pi * t / period)])
    com = periodic_lip(zmp, period, height)
    # Exact for these two harmonics: amplitude divided by 1 + (h/g) w^2.
    for column, harmonic, amplitude, wave in ((0, 1, 0.05, np.sin), (1, 2, 0.02, np.cos)):
        w = 2 * np.pi * harmonic / period
        np.testing.assert_allclose(com[:, column], amplitude * wave(w * t) / (1 + height / lk.STANDARD_GRAVITY * w * w), atol=1e-14)


@pytest.mark.slow
def test_gait_experiment_writes_results_and_its_biped_zmp_equals_the_cop(tmp_path, capsys):
    assert gait.main(["--out", str(tmp_path), "--samples", "96"]) == 0
    table = capsys.readouterr().out
    assert "S_H min" in table and "J_e2 (eq. 13)" in table
    for robot in ("quadruped", "biped"):
        assert (tmp_path / f"gait_{robot}.png").stat().st_size > 0
        with (tmp_path / f"gait_{robot}.csv").open() as handle:
            rows = list(csv.DictReader(handle))
        assert len(rows) == 96
        assert {"t", "S_H", "S_H_energy", "static_margin", "zmp_x", "zmp_margin", "joule_power", "support"} <= set(rows[0])
    # Biped: the least-squares contact forces realise the motion exactly, so their CoP is the ZMP.
    with (tmp_path / "gait_biped.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    zmp = np.array([[float(r["zmp_x"]), float(r["zmp_y"])] for r in rows])
    cop = np.array([[float(r["cop_x"]), float(r["cop_y"])] for r in rows])
    np.testing.assert_allclose(zmp, cop, atol=1e-8)


def test_quadruped_amble_support_alternates_diagonal_and_lateral_pairs():
    robot = build_quadruped()
    ref = quadruped_amble(robot, 0.67, 0.4, 80, 1, 0.03, 0.09)
    assert np.all(ref.active.sum(axis=1) == 2)
    phases = [ref.support_label[i] for i in (0, 20, 40, 60)]
    # File 003, Sect. 4.2: LF-LB, LF-RR (printed "LR-RR"), RF-RR, RF-LR from the start of the cycle.
    assert phases == ["LF+LH", "LF+RH", "RF+RH", "RF+LH"]
    # The stance feet do not slide: their world positions are constant while in contact.
    points = np.stack([_foot_world(robot.model, ref.q, robot.model.names[b], p) for b, p in ref.contacts], axis=1)
    for n in range(4):
        on = ref.active[:, n]
        first = np.argmax(on)
        run = on[first : first + 40]
        np.testing.assert_allclose(points[first : first + 40][run, n], points[first, n][None, :].repeat(run.sum(), 0), atol=1e-12)
    # Its ZMP stays on the support line to the planned accuracy.
    assert ref.zmp_tracking_error < 5e-3
    assert np.all(np.abs(ls.static_stability_margin(ls.zmp(robot.model, ref.q, ref.v, ref.a), points, ref.active)) < 5e-3)


def test_gait_cli_rejects_bad_arguments():
    with pytest.raises(SystemExit):
        gait.main(["--robot", "hexapod"])
    with pytest.raises(SystemExit):
        gait.main(["--mu", "-1"])
    with pytest.raises(SystemExit):
        gait.main(["--min-normal-force", "-1"])
    for margin in ("-0.1", "1"):
        with pytest.raises(SystemExit):
            gait.main(["--torque-margin", margin])
    with pytest.raises(SystemExit):
        gait.main(["--replay-controller", "lqr"])
    for coarse in (["--coarse-intervals", "-1"], ["--coarse-intervals", "16"], ["--coarse-intervals", "8", "--intervals", "8"]):
        with pytest.raises(SystemExit):
            gait.main(coarse)  # negative, or not fewer than --intervals (default 16); 0 solves on --intervals directly


def test_gait_defaults_are_the_published_amble(tmp_path):
    # File 003, Fig. 3: 0.67 m/s, period 1.25 s, duty factor 0.5, v_tip_max 2 m/s, support order LF+LH first.
    assert gait.main(["--robot", "quadruped", "--out", str(tmp_path), "--samples", "80"]) == 0
    with (tmp_path / "gait_quadruped.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    t = np.array([float(r["t"]) for r in rows])
    assert t[1] == pytest.approx(1.25 / 80, rel=1e-12) and len(t) == 80
    assert [rows[i]["support"] for i in (0, 20, 40, 60)] == ["LF+LH", "LF+RH", "RF+RH", "RF+LH"]
    assert all(np.isfinite(float(r["S_H"])) for r in rows)


@pytest.mark.parametrize(("call", "argument"), [
    (lambda: periodic_lip(np.full((8, 2), np.nan), 1.0, 1.0), "zmp_offset"),
    (lambda: periodic_lip(np.zeros(8), 1.0, 1.0), "zmp_offset"),
    (lambda: periodic_lip(np.zeros((0, 2)), 1.0, 1.0), "zmp_offset"),
    (lambda: periodic_lip(np.zeros((8, 2)), 0.0, 1.0), "period"),
    (lambda: periodic_lip(np.zeros((8, 2)), 1.0, -1.0), "height"),
    (lambda: quadruped_amble(build_quadruped(), 0.5, 1.0, 0, 1, 0.05, 0.3), "samples"),
    (lambda: quadruped_amble(build_quadruped(), 0.5, -1.0, 40, 1, 0.05, 0.3), "period"),
    (lambda: quadruped_amble(build_quadruped(), 0.5, 1.0, 40, 0, 0.05, 0.3), "cycles"),
    (lambda: quadruped_amble(build_quadruped(), np.nan, 1.0, 40, 1, 0.05, 0.3), "speed"),
])
def test_reference_gaits_refuse_bad_arguments_by_name(call, argument):
    with pytest.raises(ValueError, match=argument):
        call()
