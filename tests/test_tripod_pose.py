"""Tripod body pose (eq. 2-5), hip transforms, coplanarity measures and stance intervals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import examples
from legkit.robots.rhex import HIP_POSITIONS, LEG_LENGTH, TRIPODS
from legkit.strain.pose import coplanarity, euler_zyx, hip_to_body, plane_residual, stance_intervals, toe_in_body, toe_in_leg, tripod_pose

SETTINGS = examples(100)


def elementary(axis: int, angle: float) -> np.ndarray:
    """Rotation about a coordinate axis, written out by hand."""
    c, s = np.cos(angle), np.sin(angle)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def spread_triangle(rng: np.random.Generator) -> np.ndarray:
    """Three planar points (3, 2) around a circle, at least 60 degrees apart, radii 0.1-0.5 m."""
    angles = rng.uniform(0, 2 * np.pi) + np.arange(3) * 2 * np.pi / 3 + rng.uniform(-0.5, 0.5, 3)
    radii = rng.uniform(0.1, 0.5, 3)
    return np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])


def world_support_frame(world_toes: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Support axes in world coordinates, built independently: x toward toe 1, z the given plane normal."""
    x = world_toes[1] - world_toes[0]
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(up, x), up])


# --------------------------------------------------------------------------------------------------
# tripod_pose
# --------------------------------------------------------------------------------------------------


def test_known_pose_on_flat_ground_recovered_to_1e12() -> None:
    roll, pitch, yaw, height = 0.05, -0.08, 0.3, 0.15
    rotation = elementary(2, yaw) @ elementary(1, pitch) @ elementary(0, roll)
    position = np.array([0.4, -0.2, height])
    # Toes on z = 0 with toe 0 -> toe 1 along world +x, so the support frame is the world frame shifted to toe 0.
    world_toes = np.array([[0.1, 0.0, 0.0], [0.6, 0.0, 0.0], [0.35, -0.45, 0.0]])
    body_toes = (world_toes - position) @ rotation  # R^T (w - p), row-wise
    pose = tripod_pose(body_toes, orientation="body_side")  # these toes run clockwise (eq. 2's q_3 points down)
    assert abs(pose.height - height) < 1e-12
    assert abs(pose.roll - roll) < 1e-12 and abs(pose.pitch - pitch) < 1e-12 and abs(pose.yaw - yaw) < 1e-12
    np.testing.assert_allclose(pose.position, position - world_toes[0], atol=1e-12)
    np.testing.assert_allclose(pose.rotation, rotation, atol=1e-12)


@SETTINGS
@given(
    seed=st.integers(0, 2**32 - 1),
    tilt=st.floats(0.0, 1.2),
    height=st.floats(0.02, 2.0),
)
def test_random_pose_and_plane_round_trip(seed: int, tilt: float, height: float) -> None:
    rng = np.random.default_rng(seed)
    # A random ground plane through a random point, tilted by up to ~70 degrees.
    heading = rng.uniform(0, 2 * np.pi)
    up = np.array([np.sin(tilt) * np.cos(heading), np.sin(tilt) * np.sin(heading), np.cos(tilt)])
    in_plane = np.linalg.svd(up[None, :])[2][1:]  # two orthonormal vectors spanning the plane
    anchor = rng.uniform(-1, 1, 3)
    # Well-separated toes: angles around a circle at least 60 degrees apart.
    planar = spread_triangle(rng)
    world_toes = anchor + planar[:, :1] * in_plane[0] + planar[:, 1:] * in_plane[1]
    rotation = random_rotation(rng)
    position = anchor + rng.uniform(-0.3, 0.3, 2) @ in_plane + height * up
    body_toes = (world_toes - position) @ rotation

    pose = tripod_pose(body_toes, orientation="body_side")
    frame = world_support_frame(world_toes, up)
    np.testing.assert_allclose(pose.rotation, frame.T @ rotation, atol=1e-9)
    np.testing.assert_allclose(pose.position, frame.T @ (position - world_toes[0]), atol=1e-9)
    assert abs(pose.height - height) < 1e-9
    # Every toe lies in the support plane z = 0; the first toe is the origin, the second on +x.
    support_toes = body_toes @ pose.rotation.T + pose.position
    np.testing.assert_allclose(support_toes[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(support_toes[0], 0.0, atol=1e-9)
    assert support_toes[1, 0] > 0 and abs(support_toes[1, 1]) < 1e-9
    np.testing.assert_allclose(pose.rotation @ pose.rotation.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(pose.rotation) - 1.0) < 1e-12
    np.testing.assert_allclose(euler_zyx(pose.roll, pose.pitch, pose.yaw), pose.rotation, atol=1e-12)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), permutation=st.permutations([0, 1, 2]))
def test_height_roll_pitch_do_not_depend_on_toe_order(seed: int, permutation: list[int]) -> None:
    # Reordering the toes yaws the support frame only, which leaves Z-Y-X roll and pitch unchanged.
    rng = np.random.default_rng(seed)
    roll, pitch, yaw = rng.uniform(-0.6, 0.6, 3)
    rotation = euler_zyx(roll, pitch, yaw)
    world_toes = np.column_stack([spread_triangle(rng), np.zeros(3)])
    position = np.array([0.0, 0.0, rng.uniform(0.05, 0.3)])
    body_toes = (world_toes - position) @ rotation
    pose = tripod_pose(body_toes[list(permutation)], orientation="body_side")
    assert abs(pose.height - position[2]) < 1e-10
    assert abs(pose.roll - roll) < 1e-10 and abs(pose.pitch - pitch) < 1e-10


def test_batched_matches_single() -> None:
    rng = np.random.default_rng(3)
    toes = rng.normal(size=(4, 5, 3, 3))
    batch = tripod_pose(toes)
    for index in np.ndindex(4, 5):
        single = tripod_pose(toes[index])
        for field in ("rotation", "position", "support_frame", "origin"):
            np.testing.assert_array_equal(getattr(batch, field)[index], getattr(single, field), err_msg=field)
        for field in ("roll", "pitch", "yaw", "height", "alpha", "gamma", "beta"):
            assert getattr(batch, field)[index] == getattr(single, field), field
    assert batch.rotation.shape == (4, 5, 3, 3) and batch.height.shape == (4, 5)


def test_rhex_standing_pose() -> None:
    # All legs straight down at the unloaded length: the body is level at height L0.
    toes = HIP_POSITIONS + np.array([0.0, 0.0, -LEG_LENGTH])
    pose = tripod_pose(toes[list(TRIPODS[0])], orientation="body_side")
    assert abs(pose.height - LEG_LENGTH) < 1e-15
    assert abs(pose.roll) < 1e-15 and abs(pose.pitch) < 1e-15 and abs(pose.yaw) < 1e-15


@pytest.mark.parametrize(
    "toes",
    [
        [[0, 0, -1], [0, 0, -1], [1, 0, -1]],  # two coincident
        [[0, 0, -1], [0, 0, -1], [0, 0, -1]],  # all coincident
        [[0, 0, -1], [1, 0, -1], [2, 0, -1]],  # collinear
        [[0, 0, -1], [1, 1, -1], [2, 2, -1 + 1e-13]],  # collinear to rounding
    ],
)
def test_degenerate_tripods_raise(toes: list[list[float]]) -> None:
    with pytest.raises(ValueError, match="toes.*(coincident|collinear)"):
        tripod_pose(toes)


def test_degenerate_tripod_in_batch_is_located() -> None:
    toes = np.tile(np.array([[0.0, 0, -1], [1, 0, -1], [0, 1, -1]]), (3, 1, 1))
    toes[2, 2] = [2.0, 0.0, -1.0]
    with pytest.raises(ValueError, match=r"batch index \(2,\)"):
        tripod_pose(toes)


@pytest.mark.parametrize("toes", [np.zeros((3, 2)), np.zeros((4, 3)), np.zeros(3)])
def test_wrong_shape_raises(toes: np.ndarray) -> None:
    with pytest.raises(ValueError, match="toes must have shape"):
        tripod_pose(toes)


def test_nan_and_type_errors() -> None:
    toes = np.array([[0.0, 0, -1], [1, 0, -1], [0, np.nan, -1]])
    with pytest.raises(ValueError, match="toes contains a non-finite"):
        tripod_pose(toes)
    with pytest.raises(TypeError, match="toes"):
        tripod_pose([["a", "b", "c"]] * 3)


# --------------------------------------------------------------------------------------------------
# Hip transforms
# --------------------------------------------------------------------------------------------------


def test_hip_to_body_hand_cases() -> None:
    straight_down = hip_to_body(0.0, 0) @ np.append(toe_in_leg(LEG_LENGTH, 0.0), 1.0)
    np.testing.assert_allclose(straight_down[:3], HIP_POSITIONS[0] + [0, 0, -LEG_LENGTH], atol=1e-15)
    # A quarter turn about +y swings a hanging leg backwards to -x.
    quarter = hip_to_body(np.pi / 2, 5) @ np.array([0.0, 0.0, -1.0, 1.0])
    np.testing.assert_allclose(quarter[:3], HIP_POSITIONS[5] + [-1.0, 0.0, 0.0], atol=1e-15)


@SETTINGS
@given(
    theta=st.floats(-np.pi, np.pi),
    length=st.floats(0.05, 0.2),
    deflection=st.floats(-0.5, 0.5),
    leg=st.integers(0, 5),
)
def test_toe_in_body_is_hip_transform_of_leg_toe(theta: float, length: float, deflection: float, leg: int) -> None:
    transform = hip_to_body(theta, leg)
    expected = transform[:3, :3] @ toe_in_leg(length, deflection) + transform[:3, 3]
    np.testing.assert_allclose(toe_in_body(theta, length, deflection, leg), expected, atol=1e-15)
    np.testing.assert_allclose(transform[:3, :3], elementary(1, theta), atol=1e-15)
    # Deflection adds to the hip angle: the toe is at distance `length` from the hip.
    assert abs(np.linalg.norm(toe_in_body(theta, length, deflection, leg) - HIP_POSITIONS[leg]) - length) < 1e-15


def test_hip_to_body_rejects_bad_leg_index() -> None:
    with pytest.raises(ValueError, match="leg_index"):
        hip_to_body(0.0, 6)
    with pytest.raises(TypeError, match="leg_index"):
        hip_to_body(0.0, 1.5)


# --------------------------------------------------------------------------------------------------
# Coplanarity and stance intervals
# --------------------------------------------------------------------------------------------------


def test_coplanarity_hand_cases() -> None:
    tetrahedron = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    assert coplanarity(tetrahedron, "determinant") == pytest.approx(1.0, abs=1e-15)  # 6 x volume 1/6
    square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    assert coplanarity(square, "determinant") == 0.0
    # Five points: only subsets containing the raised point are non-coplanar; the largest is |det| = 2.
    five = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 2.0]])
    assert coplanarity(five, "determinant") == pytest.approx(2.0, abs=1e-14)


def test_plane_residual_hand_case() -> None:
    # Four points alternately 0.1 above and below z = 0: the best plane is z = 0, residual 4 x 0.01.
    points = np.array([[0.0, 0, 0.1], [1, 0, -0.1], [1, 1, 0.1], [0, 1, -0.1]])
    assert plane_residual(points) == pytest.approx(0.04, abs=1e-15)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(4, 7), lift=st.floats(0.0, 0.2))
def test_coplanarity_measures_on_planes_and_off_them(seed: int, count: int, lift: float) -> None:
    rng = np.random.default_rng(seed)
    rotation = random_rotation(rng)
    flat = np.column_stack([rng.uniform(-0.3, 0.3, (count, 2)), np.zeros(count)])
    flat[-1, 2] = lift
    points = flat @ rotation.T + rng.uniform(-1, 1, 3)
    # Geometric measure: smallest squared singular value of the centred points (an independent SVD route).
    centred = points - points.mean(axis=0)
    reference = np.linalg.svd(centred, compute_uv=False)[-1] ** 2
    assert plane_residual(points) == pytest.approx(reference, abs=1e-12)
    if lift == 0.0:
        assert coplanarity(points, "determinant") < 1e-12 and plane_residual(points) < 1e-12
    # Both measures are invariant under a rigid motion.
    moved = points @ random_rotation(rng).T + rng.uniform(-1, 1, 3)
    assert coplanarity(moved, "determinant") == pytest.approx(coplanarity(points, "determinant"), abs=1e-12)
    assert plane_residual(moved) == pytest.approx(plane_residual(points), abs=1e-12)


def test_coplanarity_rejects_too_few_toes() -> None:
    with pytest.raises(ValueError, match="toes must have shape"):
        coplanarity(np.zeros((3, 3)), "determinant")
    with pytest.raises(ValueError, match="toes must have shape"):
        coplanarity(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="definition"):
        coplanarity(np.zeros((6, 3)), "volume")
    with pytest.raises(ValueError, match="toes must have shape"):
        plane_residual(np.zeros((2, 3)))


def test_stance_intervals_hand_case() -> None:
    rho = np.array([5, 0, 0, 5, 0, 5, 5, 0, 0, 0])
    np.testing.assert_array_equal(stance_intervals(rho, 1.0), [[1, 3], [4, 5], [7, 10]])
    np.testing.assert_array_equal(stance_intervals(rho, 1.0, min_length=2), [[1, 3], [7, 10]])
    assert stance_intervals(rho, -1.0).shape == (0, 2)


@SETTINGS
@given(values=st.lists(st.floats(0, 1), min_size=1, max_size=200), threshold=st.floats(0, 1))
def test_stance_intervals_reconstruct_the_mask(values: list[float], threshold: float) -> None:
    rho = np.array(values)
    intervals = stance_intervals(rho, threshold)
    mask = np.zeros(rho.size, dtype=bool)
    for start, stop in intervals:
        assert stop > start and not mask[start:stop].any()
        mask[start:stop] = True
    np.testing.assert_array_equal(mask, rho <= threshold)
    # Maximal runs: consecutive intervals are separated by at least one sample.
    assert np.all(intervals[1:, 0] > intervals[:-1, 1])


def test_stance_intervals_bad_input() -> None:
    with pytest.raises(ValueError, match="rho must be one-dimensional"):
        stance_intervals(np.zeros((2, 2)), 0.1)
    with pytest.raises(ValueError, match="rho contains a non-finite"):
        stance_intervals([0.0, np.nan], 0.1)
    with pytest.raises(ValueError, match="min_length"):
        stance_intervals([0.0], 0.1, min_length=0)


# --------------------------------------------------------------------------------------------------
# The published eq. 2 frame, eq. 5 angles and Sect. 5.2 coplanarity, by hand from [Lin 2003]
# --------------------------------------------------------------------------------------------------


def paper_frame(toes: np.ndarray) -> np.ndarray:
    """A = [q1 q2 q3]^T of eq. 2, written out: Gram-Schmidt of the two edge directions, q3 = q1 x q2."""
    e1 = (toes[1] - toes[0]) / np.linalg.norm(toes[1] - toes[0])
    e2 = (toes[2] - toes[0]) / np.linalg.norm(toes[2] - toes[0])
    q2 = e2 - (e1 @ e2) * e1
    q2 /= np.linalg.norm(q2)
    return np.array([e1, q2, np.cross(e1, q2)])


def test_paper_frame_follows_the_toe_order_and_body_side_turns_it_up() -> None:
    rng = np.random.default_rng(11)
    for _ in range(20):
        body_toes = rng.uniform(-0.3, 0.3, (3, 3)) + [0.0, 0.0, -0.2]
        a = paper_frame(body_toes)
        pose = tripod_pose(body_toes)
        np.testing.assert_allclose(pose.rotation, a, atol=1e-12)
        np.testing.assert_allclose(pose.position, -a @ body_toes[0], atol=1e-12)  # eq. 4
        toward_body = a[2] @ (-body_toes[0]) > 0.0
        side = tripod_pose(body_toes, orientation="body_side")
        if toward_body:
            np.testing.assert_allclose(side.rotation, a, atol=1e-12)
        else:  # half a turn about q1: q2 and q3 change sign, and the height becomes positive
            np.testing.assert_allclose(side.rotation, a * [[1.0], [-1.0], [-1.0]], atol=1e-12)
            assert pose.height < 0.0 < side.height
    with pytest.raises(ValueError, match="orientation"):
        tripod_pose(np.eye(3), orientation="up")


@SETTINGS
@given(roll=st.floats(-0.7, 0.7), pitch=st.floats(-0.7, 0.7), yaw=st.floats(-1.2, 1.2), height=st.floats(0.05, 0.4))
def test_paper_angles_alpha_gamma_beta_by_hand(roll: float, pitch: float, yaw: float, height: float) -> None:
    # Toes on flat ground z = 0, counter-clockwise, toe 0 -> toe 1 along world +x: the support frame is the world
    # frame at toe 0, so A is the body's rotation R and b1, b2 its first two columns.
    rotation = elementary(2, yaw) @ elementary(1, pitch) @ elementary(0, roll)
    world_toes = np.array([[0.1, 0.0, 0.0], [0.6, 0.0, 0.0], [0.35, 0.45, 0.0]])
    body_toes = (world_toes - [0.3, 0.1, height]) @ rotation
    pose = tripod_pose(body_toes)
    b1, b2 = rotation[:, 0], rotation[:, 1]
    assert pose.alpha == pytest.approx(np.arctan(b1[2] / np.sqrt(b1[0] ** 2 + b1[1] ** 2)), abs=1e-12)
    assert pose.gamma == pytest.approx(np.arctan(b2[2] / np.sqrt(b2[0] ** 2 + b2[1] ** 2)), abs=1e-12)
    with np.errstate(divide="ignore"):  # at zero yaw and pitch the root is 0 and arctan(inf) = pi/2, as written
        assert pose.beta == pytest.approx(np.arctan(b1[0] / np.sqrt(b1[1] ** 2 + b1[2] ** 2)), abs=1e-12)
    # What they mean: alpha = -pitch (nose up), sin gamma = cos(pitch) sin(roll), sin beta = cos(yaw) cos(pitch).
    assert pose.alpha == pytest.approx(-pitch, abs=1e-12)
    assert np.sin(pose.gamma) == pytest.approx(np.cos(pitch) * np.sin(roll), abs=1e-12)
    assert np.sin(pose.beta) == pytest.approx(np.cos(yaw) * np.cos(pitch), abs=1e-12)
    # beta does not tell a yaw to the left from one to the right; legkit's Z-Y-X yaw does.
    mirrored = tripod_pose((world_toes - [0.3, 0.1, height]) @ (elementary(2, -yaw) @ elementary(1, pitch) @ elementary(0, roll)))
    assert mirrored.beta == pytest.approx(pose.beta, abs=1e-12)
    assert mirrored.yaw == pytest.approx(-pose.yaw, abs=1e-12)


def test_paper_angles_at_rest_and_their_dependence_on_toe_order() -> None:
    toes = HIP_POSITIONS + np.array([0.0, 0.0, -LEG_LENGTH])
    # RHex standing level, tripod B (right rear, right front, left middle: counter-clockwise): alpha = gamma = 0,
    # and the body faces along toe 0 -> toe 1, so beta = pi/2.
    level = tripod_pose(toes[list(TRIPODS[1])])
    assert abs(level.alpha) < 1e-15 and abs(level.gamma) < 1e-15 and level.beta == pytest.approx(np.pi / 2, abs=1e-15)
    # The angles are invariant to moving the body frame's origin (all toes shifted), not to the toe order: a
    # clockwise order turns eq. 2's q3 into the ground, which flips the sign of gamma on a tilted body.
    tilted = toes @ elementary(0, 0.2).T
    ccw, cw = tripod_pose(tilted[list(TRIPODS[1])]), tripod_pose(tilted[list(TRIPODS[0])])
    shifted = tripod_pose(tilted[list(TRIPODS[1])] + [0.05, -0.02, 0.1])
    assert shifted.gamma == pytest.approx(ccw.gamma, abs=1e-14) and shifted.alpha == pytest.approx(ccw.alpha, abs=1e-14)
    assert cw.gamma == pytest.approx(-ccw.gamma, abs=1e-14) and abs(ccw.gamma) > 0.1
    assert tripod_pose(tilted[list(TRIPODS[0])], orientation="body_side").gamma == pytest.approx(ccw.gamma, abs=1e-14)


def test_paper_coplanarity_by_hand_and_where_it_is_not_a_coplanarity() -> None:
    # Six toes on the plane z = -0.15 (coplanar): rho = sum |s_i|^2 - |s_bar|^2, s_bar = (1/6) sum s_i.
    toes = HIP_POSITIONS + np.array([0.0, 0.0, -0.15])
    squares = sum(float(x * x + y * y + z * z) for x, y, z in toes)
    mean = toes.sum(axis=0) / 6.0
    expected = squares - float(mean @ mean)
    assert coplanarity(toes) == pytest.approx(expected, rel=1e-14)
    assert coplanarity(toes) > 0.1 and plane_residual(toes) < 1e-15  # coplanar, yet far from zero
    # Moving the body frame's origin by t adds (k - 1)(2 s_bar . t + |t|^2): the measure depends on the origin.
    t = np.array([0.02, -0.01, 0.05])
    assert coplanarity(toes + t) == pytest.approx(expected + 5.0 * (2.0 * mean @ t + t @ t), rel=1e-13)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_paper_coplanarity_is_invariant_to_rotations_about_the_body_origin(seed: int) -> None:
    rng = np.random.default_rng(seed)
    toes = rng.uniform(-0.3, 0.3, (6, 3))
    assert coplanarity(toes @ random_rotation(rng).T) == pytest.approx(coplanarity(toes), abs=1e-13)
    batch = np.stack([toes, toes + 0.1])
    np.testing.assert_allclose(coplanarity(batch), [coplanarity(toes), coplanarity(toes + 0.1)], atol=1e-15)
