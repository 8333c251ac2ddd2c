"""Tests of lk.MassProperties: construction and validation, composition (+, -), change of frame,
point clouds, boxes, inertia about a point and comparison.

Expected values come from hand calculations (in comments) or from the brute-force point-mass
references in reference.py, never from the code under test.

Tolerances. Every comparison is absolute, relative to the natural scale of the quantities involved:
  mass    : REL * (total mass M involved),
  com     : REL * L (L = largest coordinate magnitude involved, incl. translations),
  inertia : REL * M * L^2 (the size of the parallel-axis terms that any composition adds/subtracts),
with extra condition factors where an operation is ill-conditioned (noted at the test). A correct
float64 implementation does a few dozen flops on quantities bounded by these scales, so its error is
~1e-14 of them; REL = 1e-10 leaves four orders of magnitude of margin while a wrong formula (missing
parallel-axis term, R^T instead of R, mass-weighted averaging, float32 arithmetic) is off by >= 1e-7.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))

import legkit as lk  # noqa: E402
import reference as ref  # noqa: E402
from conftest import bodies, examples, point_clouds, reals, rotations, vectors  # noqa: E402

MP = lk.MassProperties
REL = 1e-10
NAN = float("nan")
INF = float("inf")


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------


def make(body) -> MP:
    return MP(*body.args)


def cloud_scale(*position_sets, extra: float = 0.0) -> float:
    """Largest coordinate magnitude among point sets (plus `extra`, e.g. |t|), floored at 1e-3."""
    return max([np.max(np.linalg.norm(p, axis=-1)) for p in position_sets] + [1e-3]) + extra


def gyration_radius(body) -> float:
    """sqrt(|I| / m): the body's own size, a positive length floor for com scales."""
    return float(np.sqrt(np.max(np.abs(body.inertia)) / body.mass))


def assert_mp(got, mass, com, inertia, *, mass_scale, com_scale, inertia_scale, rel=REL, context=""):
    """Assert got == (mass, com, inertia) to rel times the given absolute scales."""
    assert isinstance(got, MP), f"expected a MassProperties, got {type(got).__name__}"
    errors = {
        "mass": abs(float(got.mass) - mass) / mass_scale,
        "com": float(np.max(np.abs(np.asarray(got.com) - com))) / com_scale,
        "inertia": float(np.max(np.abs(np.asarray(got.inertia) - inertia))) / inertia_scale,
    }
    bad = {k: v for k, v in errors.items() if not v <= rel}
    assert not bad, (
        f"{context}: relative-to-scale errors {bad} exceed {rel:g}\n"
        f"  got      mass={got.mass!r}\n  com={np.asarray(got.com)!r}\n  inertia=\n{np.asarray(got.inertia)!r}\n"
        f"  expected mass={mass!r}\n  com={np.asarray(com)!r}\n  inertia=\n{np.asarray(inertia)!r}"
    )


def assert_mp_pair(got, expected, **scales):
    assert_mp(got, float(expected.mass), np.asarray(expected.com), np.asarray(expected.inertia), **scales)


def arg_error(exc_type, name):
    """pytest.raises for exc_type whose message names the argument `name` (case-insensitive word)."""
    return pytest.raises(exc_type, match=re.compile(rf"\b{re.escape(name)}\b", re.IGNORECASE))


# --------------------------------------------------------------------------------------------------
# construction and accessors
# --------------------------------------------------------------------------------------------------


@given(bodies())
def test_constructor_round_trips_values(body):
    a = make(body)
    assert isinstance(a.mass, float)
    assert a.mass == body.mass
    com = a.com
    inertia = a.inertia
    assert isinstance(com, np.ndarray) and com.shape == (3,) and com.dtype == np.float64
    assert isinstance(inertia, np.ndarray) and inertia.shape == (3, 3) and inertia.dtype == np.float64
    np.testing.assert_array_equal(com, body.com)
    # the input is exactly symmetric, so even a symmetrising implementation must return it unchanged
    # up to one rounding of each element
    np.testing.assert_allclose(inertia, body.inertia, rtol=0, atol=4 * ref.EPS * np.max(np.abs(body.inertia)))


def test_constructor_accepts_lists_and_integers():
    a = MP(2, [1, 2, 3], [[1, 0, 0], [0, 2, 0], [0, 0, 2]])
    assert a.mass == 2.0
    np.testing.assert_array_equal(a.com, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(a.inertia, np.diag([1.0, 2.0, 2.0]))


@pytest.mark.parametrize(
    "inertia",
    [
        np.zeros((3, 3)),  # a point mass
        np.diag([0.0, 1.0, 1.0]),  # a thin rod along x: I_yy + I_xx = I_zz exactly (boundary)
        np.diag([1.0, 1.0, 2.0]),  # a flat plate in the xy plane: I_xx + I_yy = I_zz (boundary)
        np.diag([2.0, 3.0, 4.0]),
    ],
    ids=["point", "rod", "plate", "generic"],
)
def test_constructor_accepts_physical_boundary_inertias(inertia):
    a = MP(1.5, [0.0, 0.0, 0.0], inertia)
    np.testing.assert_array_equal(a.inertia, inertia)


def test_constructor_accepts_rotated_flat_plate():
    # A flat plate (principal moments 1, 1, 2: triangle inequality with equality) expressed in a rotated
    # frame is physical; rounding of R diag R^T must not make it rejected.
    r = ref.rodrigues([1.0, 2.0, 3.0], 0.7)
    inertia = r @ np.diag([1.0, 1.0, 2.0]) @ r.T
    inertia = 0.5 * (inertia + inertia.T)
    a = MP(1.0, [0.5, -0.5, 2.0], inertia)
    np.testing.assert_allclose(a.inertia, inertia, rtol=0, atol=1e-15)


@given(point_clouds(min_points=1, max_points=8), st.sampled_from(["general", "planar", "collinear"]), rotations(),
       vectors())
def test_constructor_accepts_the_inertia_of_any_point_cloud(cloud, shape, rotation, origin):
    """The brute-force inertia of real point masses is physical by construction, including the boundary
    cases of planar clouds (I_zz = I_xx + I_yy exactly: triangle equality) and collinear ones (a zero
    principal moment), placed in a random orientation (so only up to rounding). The constructor must accept
    them: its PSD / triangle checks need a tolerance of a few eps relative to the tensor's size."""
    masses, positions = cloud
    if shape == "planar":
        positions = positions * np.array([1.0, 1.0, 0.0])
    elif shape == "collinear":
        positions = positions * np.array([1.0, 0.0, 0.0])
    positions = positions @ rotation.T + origin
    m, com, inertia = ref.point_cloud_mass_properties(masses, positions)
    inertia = 0.5 * (inertia + inertia.T)
    a = MP(m, com, inertia)
    np.testing.assert_allclose(a.inertia, inertia, rtol=0, atol=4 * ref.EPS * np.max(np.abs(inertia)) + 1e-300)


def test_point_mass():
    p = MP.point(2.5, [1.0, -2.0, 3.0])
    assert p.mass == 2.5
    np.testing.assert_array_equal(p.com, [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(p.inertia, np.zeros((3, 3)))


def test_zero():
    z = MP.zero()
    assert z.mass == 0.0
    np.testing.assert_array_equal(z.inertia, np.zeros((3, 3)))


# --------------------------------------------------------------------------------------------------
# boxes
# --------------------------------------------------------------------------------------------------


def test_box_axis_aligned_hand_values():
    # m = 12, size (1, 2, 3): I_xx = 12 (4 + 9) / 12 = 13, I_yy = 12 (1 + 9) / 12 = 10, I_zz = 12 (1 + 4) / 12 = 5
    b = MP.solid_box(12.0, [1.0, 2.0, 3.0])
    assert b.mass == 12.0
    np.testing.assert_array_equal(b.com, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(b.inertia, np.diag([13.0, 10.0, 5.0]), rtol=0, atol=1e-14)


def test_box_with_center_and_rotation_hand_values():
    # Rotating the box frame by +90 deg about z maps box-x to parent-y: the long-in-x moment (13) now
    # belongs to the parent y axis: I = R diag(13, 10, 5) R^T = diag(10, 13, 5).
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    b = MP.solid_box(12.0, [1.0, 2.0, 3.0], center=[1.0, 2.0, 3.0], rotation=rz)
    np.testing.assert_array_equal(b.com, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(b.inertia, np.diag([10.0, 13.0, 5.0]), rtol=0, atol=1e-14)
    # a cube's inertia is isotropic: any rotation leaves it m s^2/6 E
    cube = MP.solid_box(6.0, [2.0, 2.0, 2.0], center=[0, 0, 0], rotation=ref.rodrigues([1, 1, 0], 0.3))
    np.testing.assert_allclose(cube.inertia, 4.0 * np.eye(3), rtol=0, atol=1e-14)


GRID_N = 40


@pytest.mark.slow
@examples(40)
@given(reals(0.01, 100.0), vectors(0.05, 5.0), vectors(), rotations())
def test_box_matches_fine_grid_of_point_masses(mass, size, center, rotation):
    """The box formula against a 40^3 midpoint-grid discretisation of the solid box.

    The grid's inertia is biased by exactly m (h_j^2 + h_k^2) / 12 per axis (h = size / 40; see
    reference.box_grid_bias), i.e. a relative O(h^2) = O(1/n^2) = 6e-4 error. We check both
    (a) the box is within that analytic bias of the grid (plus rounding), and
    (b) the box equals grid + analytic bias to REL of m |size|^2: a tight check of the formula.
    """
    b = MP.solid_box(mass, size, center=center, rotation=rotation)
    masses, positions = ref.box_grid(mass, size, center, rotation, GRID_N)
    m_ref, com_ref, inertia_grid = ref.point_cloud_mass_properties(masses, positions, vectorised=True)
    bias = rotation @ ref.box_grid_bias(mass, size, GRID_N) @ rotation.T
    inertia_scale = mass * float(np.dot(size, size))
    # The grid sums 64000 terms (pairwise summation, error ~ eps log2(n) each) and the centre is recovered
    # from coordinates of size |center|: com error <~ 1e-13 |center|, inertia error <~ 1e-12 m |size|^2.
    assert abs(b.mass - m_ref) <= REL * mass
    np.testing.assert_allclose(b.com, center, rtol=0, atol=REL * (np.linalg.norm(center) + 1))
    np.testing.assert_allclose(b.com, com_ref, rtol=0, atol=REL * (np.linalg.norm(center) + 1))
    err = np.max(np.abs(np.asarray(b.inertia) - inertia_grid))
    assert err <= np.max(np.abs(bias)) + REL * inertia_scale, (err, bias)
    err_corrected = np.max(np.abs(np.asarray(b.inertia) - (inertia_grid + bias)))
    assert err_corrected <= REL * inertia_scale, (
        f"box inertia differs from bias-corrected grid by {err_corrected:.3e} (scale {inertia_scale:.3e})\n"
        f"box=\n{np.asarray(b.inertia)!r}\ngrid+bias=\n{inertia_grid + bias!r}"
    )


@given(reals(0.01, 100.0), vectors(0.05, 5.0), vectors(), rotations())
def test_box_pose_equals_transformed_box(mass, size, center, rotation):
    posed = MP.solid_box(mass, size, center=center, rotation=rotation)
    moved = MP.solid_box(mass, size).transformed(rotation, center)
    L = np.linalg.norm(center) + np.linalg.norm(size)
    assert_mp_pair(posed, moved, mass_scale=mass, com_scale=L, inertia_scale=mass * L**2)


def test_box_default_center_and_rotation():
    assert MP.solid_box(3.0, [1.0, 2.0, 0.5]) == MP.solid_box(3.0, [1.0, 2.0, 0.5], center=[0, 0, 0], rotation=np.eye(3))


# --------------------------------------------------------------------------------------------------
# composition: +
# --------------------------------------------------------------------------------------------------


def test_addition_hand_example():
    # 1 kg at x = +1 and 3 kg at x = -1: M = 4, com x = (1 - 3)/4 = -0.5;
    # about the com: I_yy = I_zz = 1 (1.5)^2 + 3 (0.5)^2 = 3, I_xx = 0.
    s = MP.point(1.0, [1.0, 0.0, 0.0]) + MP.point(3.0, [-1.0, 0.0, 0.0])
    assert s.mass == 4.0
    np.testing.assert_allclose(s.com, [-0.5, 0.0, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.inertia, np.diag([0.0, 3.0, 3.0]), rtol=0, atol=1e-14)


def test_addition_is_not_the_mass_weighted_average_of_inertias():
    """The seed paper's shorthand I = (m1 I1 + m2 I2) / (m1 + m2) is NOT composition.

    Two 1 kg points at x = +-1: the shorthand gives 0 (both inertias are 0); the true inertia about the
    common com (the origin) is diag(0, 2, 2). Two identical co-located cubes: the shorthand gives I, the
    truth is 2 I (inertia is extensive, not an average)."""
    a, b = MP.point(1.0, [1.0, 0.0, 0.0]), MP.point(1.0, [-1.0, 0.0, 0.0])
    shorthand = (a.mass * a.inertia + b.mass * b.inertia) / (a.mass + b.mass)
    s = a + b
    np.testing.assert_allclose(s.inertia, np.diag([0.0, 2.0, 2.0]), rtol=0, atol=1e-14)
    assert np.max(np.abs(s.inertia - shorthand)) > 1.0

    cube = MP.solid_box(6.0, [1.0, 1.0, 1.0], center=[0.3, 0.2, 0.1])  # I = 6 * 2/12 E = E
    shorthand = (cube.mass * cube.inertia + cube.mass * cube.inertia) / (2 * cube.mass)
    s = cube + cube
    np.testing.assert_allclose(s.inertia, 2.0 * np.eye(3), rtol=0, atol=1e-14)
    np.testing.assert_allclose(shorthand, np.eye(3), rtol=0, atol=1e-14)
    assert np.max(np.abs(s.inertia - shorthand)) > 0.5


@pytest.mark.slow
@given(bodies(), bodies())
def test_addition_matches_union_of_point_clouds(a, b):
    """a + b is the body made of both: compare with the brute-force mass properties of the union of the
    two equivalent point clouds."""
    s = make(a) + make(b)
    masses = np.concatenate([a.cloud_masses, b.cloud_masses])
    positions = np.concatenate([a.cloud_positions, b.cloud_positions])
    m_ref, com_ref, inertia_ref = ref.point_cloud_mass_properties(masses, positions)
    L = cloud_scale(positions)
    assert_mp(s, m_ref, com_ref, inertia_ref, mass_scale=m_ref, com_scale=L, inertia_scale=m_ref * L**2)


@pytest.mark.slow
@given(bodies(), bodies())
def test_addition_commutes(a, b):
    ab, ba = make(a) + make(b), make(b) + make(a)
    M = a.mass + b.mass
    L = cloud_scale(a.cloud_positions, b.cloud_positions)
    assert_mp_pair(ab, ba, mass_scale=M, com_scale=L, inertia_scale=M * L**2)


@pytest.mark.slow
@given(bodies(), bodies(), bodies())
def test_addition_associates(a, b, c):
    left = (make(a) + make(b)) + make(c)
    right = make(a) + (make(b) + make(c))
    M = a.mass + b.mass + c.mass
    L = cloud_scale(a.cloud_positions, b.cloud_positions, c.cloud_positions)
    assert_mp_pair(left, right, mass_scale=M, com_scale=L, inertia_scale=M * L**2)


MODERATE = dict(mass_range=(0.5, 2.0), com_range=(-1.0, 1.0), length_range=(0.2, 1.0))


@pytest.mark.slow
@given(bodies(**MODERATE), bodies(**MODERATE), bodies(**MODERATE))
def test_eq_operator_on_algebraic_identities_of_moderate_bodies(a, b, c):
    """The same identities through the public == (isclose with rtol=1e-9, atol=1e-12). Bodies are kept
    of moderate, comparable size so rounding (~1e-15) is far below both tolerances whatever the exact
    per-element definition of isclose."""
    A, B, C = make(a), make(b), make(c)
    assert A + B == B + A
    assert (A + B) + C == A + (B + C)
    assert (A + B) - B == A
    assert A.isclose((A + B) - B)
    assert MP.zero() + A == A
    assert A + MP.zero() == A


# --------------------------------------------------------------------------------------------------
# zero()
# --------------------------------------------------------------------------------------------------


@given(bodies())
def test_zero_is_identity(body):
    a = make(body)
    L = cloud_scale(body.cloud_positions)
    scales = dict(mass_scale=body.mass, com_scale=L, inertia_scale=body.mass * L**2)
    # adding nothing must not move the com or change the inertia (ideally bit-for-bit; allow rounding)
    assert_mp(MP.zero() + a, *body.args, **scales, context="zero() + a")
    assert_mp(a + MP.zero(), *body.args, **scales, context="a + zero()")
    assert_mp(a - MP.zero(), *body.args, **scales, context="a - zero()")
    assert_mp(sum([a], MP.zero()), *body.args, **scales, context="sum([a], zero())")


@given(bodies())
def test_a_minus_a_is_zero(body):
    a = make(body)
    d = a - a
    assert d.mass == 0.0
    np.testing.assert_array_equal(d.inertia, np.zeros((3, 3)))
    assert d == MP.zero()


def test_zero_plus_zero_and_empty_sum():
    z = MP.zero() + MP.zero()
    assert z.mass == 0.0
    assert z == MP.zero()
    assert sum([], MP.zero()) == MP.zero()


# --------------------------------------------------------------------------------------------------
# subtraction
# --------------------------------------------------------------------------------------------------


@given(bodies(), bodies())
def test_subtraction_inverts_addition(a, b):
    """(a + b) - b == a. Recovering a's com divides by a's mass: com = ((M c_ab) - m_b c_b) / m_a, so the
    com error is amplified by M / m_a (condition number of the subtraction); the inertia error is bounded
    by the M L^2 parallel-axis terms that are added and removed."""
    A, B = make(a), make(b)
    back = (A + B) - B
    M = a.mass + b.mass
    L = cloud_scale(a.cloud_positions, b.cloud_positions)
    assert_mp(
        back, *a.args, mass_scale=M, com_scale=L * M / a.mass, inertia_scale=M * L**2, context="(a+b)-b"
    )


@pytest.mark.slow
@given(point_clouds(min_points=4, max_points=12), st.data())
def test_subtraction_removes_a_sub_cloud(cloud, data):
    """from_points(all) - from_points(part) == brute-force mass properties of the rest."""
    masses, positions = cloud
    n = len(masses)
    k = data.draw(st.integers(1, n - 3), label="points removed")
    m_rest, com_rest, inertia_rest = ref.point_cloud_mass_properties(masses[k:], positions[k:])
    # three or more generic points: the rest has a strictly physical inertia (skip near-collinear rests)
    eig = np.linalg.eigvalsh(inertia_rest)
    L = cloud_scale(positions)
    M = float(np.sum(masses))
    assume(np.min(eig) > 1e-6 * M * L**2)
    got = MP.from_points(masses, positions) - MP.from_points(masses[:k], positions[:k])
    assert_mp(
        got, m_rest, com_rest, inertia_rest,
        mass_scale=M, com_scale=L * M / m_rest, inertia_scale=M * L**2, context="all - part",
    )


def test_subtraction_leaving_a_point_mass():
    # (p1 + p2) - p2 must give back the point mass p1 (zero inertia) rather than reject the rounding-level
    # non-physical remainder: subtraction is the exact inverse of addition.
    p1 = MP.point(1.0, [1.0, 2.0, 3.0])
    p2 = MP.point(2.0, [-1.0, 0.5, 4.0])
    back = (p1 + p2) - p2
    assert back == p1
    assert abs(back.mass - 1.0) <= 1e-15
    np.testing.assert_allclose(back.com, [1.0, 2.0, 3.0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(back.inertia, np.zeros((3, 3)), rtol=0, atol=1e-12)


def test_subtraction_rejects_negative_or_zero_mass():
    big = MP.solid_box(1.0, [1.0, 1.0, 1.0])
    heavier = MP.point(2.0, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        big - heavier
    same_mass_other_body = MP.point(1.0, [0.5, 0.0, 0.0])
    with pytest.raises(ValueError):
        big - same_mass_other_body


def test_subtraction_rejects_non_physical_inertia():
    # Same centre; masses 2 - 1 = 1 > 0, but inertias 2 (1 + 1)/12 = 1/3 minus 1 (4 + 4)/12 = 2/3 < 0.
    a = MP.solid_box(2.0, [1.0, 1.0, 1.0])
    b = MP.solid_box(1.0, [2.0, 2.0, 2.0])
    with pytest.raises(ValueError):
        a - b
    # Triangle inequality violated but PSD: a flat plate (principal moments 1, 1, 2) minus a rod along z
    # with I_xx = I_yy = 0.5 leaves principal moments (0.5, 0.5, 2): 0.5 + 0.5 < 2.
    plate = MP(2.0, [0, 0, 0], np.diag([1.0, 1.0, 2.0]))
    rod = MP(1.0, [0, 0, 0], np.diag([0.5, 0.5, 0.0]))
    with pytest.raises(ValueError):
        plate - rod


# --------------------------------------------------------------------------------------------------
# change of frame
# --------------------------------------------------------------------------------------------------


def test_transformed_hand_example():
    # box diag(13, 10, 5) at the origin; rotate +90 deg about z and translate by (1, 2, 3)
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    b = MP.solid_box(12.0, [1.0, 2.0, 3.0]).transformed(rz, [1.0, 2.0, 3.0])
    assert b.mass == 12.0
    np.testing.assert_allclose(b.com, [1.0, 2.0, 3.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(b.inertia, np.diag([10.0, 13.0, 5.0]), rtol=0, atol=1e-14)
    # a com off the origin is rotated too: com' = R com + t
    p = MP.point(1.0, [1.0, 0.0, 0.0]).transformed(rz, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(p.com, [0.0, 1.0, 1.0], rtol=0, atol=1e-15)


@given(bodies(), rotations(), vectors())
def test_transformed_matches_transformed_point_cloud(body, rotation, translation):
    """Moving the body == moving every point of its equivalent cloud (x' = R x + t) and recomputing."""
    got = make(body).transformed(rotation, translation)
    moved = body.cloud_positions @ rotation.T + translation
    m_ref, com_ref, inertia_ref = ref.point_cloud_mass_properties(body.cloud_masses, moved)
    L = cloud_scale(body.cloud_positions, moved)
    assert_mp(got, m_ref, com_ref, inertia_ref, mass_scale=body.mass, com_scale=L, inertia_scale=body.mass * L**2)
    assert got.mass == body.mass


@given(bodies(), bodies(), rotations(), vectors())
def test_transformed_distributes_over_addition(a, b, rotation, translation):
    left = (make(a) + make(b)).transformed(rotation, translation)
    right = make(a).transformed(rotation, translation) + make(b).transformed(rotation, translation)
    M = a.mass + b.mass
    L = cloud_scale(a.cloud_positions, b.cloud_positions, extra=np.linalg.norm(translation))
    assert_mp_pair(left, right, mass_scale=M, com_scale=L, inertia_scale=M * L**2)


@given(bodies(), rotations(), vectors())
def test_transformed_then_inverse_is_identity(body, rotation, translation):
    a = make(body)
    back = a.transformed(rotation, translation).transformed(rotation.T, -rotation.T @ translation)
    L = np.linalg.norm(body.com) + np.linalg.norm(translation) + gyration_radius(body)
    # a pure change of frame does no parallel-axis arithmetic: inertia errors scale with |I| only
    assert_mp(
        back, *body.args, mass_scale=body.mass, com_scale=L, inertia_scale=np.max(np.abs(body.inertia)),
        context="transformed then inverse",
    )


@given(bodies(), rotations(), vectors())
def test_transformed_accepts_a_4x4_homogeneous_matrix(body, rotation, translation):
    a = make(body)
    by_pair = a.transformed(rotation, translation)
    by_matrix = a.transformed(ref.homogeneous(rotation, translation))
    L = np.linalg.norm(body.com) + np.linalg.norm(translation) + gyration_radius(body)
    assert_mp_pair(
        by_matrix, by_pair, mass_scale=body.mass, com_scale=L, inertia_scale=np.max(np.abs(body.inertia))
    )


def test_transformed_4x4_hand_example():
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    t = ref.homogeneous(rz, [1.0, 2.0, 3.0])
    b = MP.solid_box(12.0, [1.0, 2.0, 3.0], center=[1.0, 0.0, 0.0]).transformed(t)
    np.testing.assert_allclose(b.com, [1.0, 3.0, 3.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(b.inertia, np.diag([10.0, 13.0, 5.0]), rtol=0, atol=1e-14)


# --------------------------------------------------------------------------------------------------
# point clouds and inertia about a point
# --------------------------------------------------------------------------------------------------


@given(point_clouds())
def test_from_points_matches_brute_force(cloud):
    masses, positions = cloud
    got = MP.from_points(masses, positions)
    m_ref, com_ref, inertia_ref = ref.point_cloud_mass_properties(masses, positions)
    L = cloud_scale(positions)
    assert_mp(got, m_ref, com_ref, inertia_ref, mass_scale=m_ref, com_scale=L, inertia_scale=m_ref * L**2)


@pytest.mark.slow
@given(point_clouds())
def test_sum_of_points_equals_from_points(cloud):
    masses, positions = cloud
    total = sum((MP.point(m, p) for m, p in zip(masses, positions)), MP.zero())
    m_ref, com_ref, inertia_ref = ref.point_cloud_mass_properties(masses, positions)
    L = cloud_scale(positions)
    scales = dict(mass_scale=m_ref, com_scale=L, inertia_scale=m_ref * L**2)
    assert_mp(total, m_ref, com_ref, inertia_ref, **scales, context="sum of points")
    assert_mp_pair(total, MP.from_points(masses, positions), **scales)


def test_from_points_hand_example_and_lists():
    # unit masses at the 8 corners of the cube [-1, 1]^3: com 0, I = 8 (1 + 1) E = 16 E
    corners = [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    c = MP.from_points([1] * 8, corners)
    assert c.mass == 8.0
    np.testing.assert_allclose(c.com, np.zeros(3), rtol=0, atol=1e-15)
    np.testing.assert_allclose(c.inertia, 16.0 * np.eye(3), rtol=0, atol=1e-13)


@pytest.mark.slow
@given(point_clouds(), vectors(-20, 20))
def test_inertia_about_point_matches_brute_force(cloud, point):
    masses, positions = cloud
    got = MP.from_points(masses, positions).inertia_about(point)
    assert isinstance(got, np.ndarray) and got.shape == (3, 3)
    expected = ref.inertia_of_points_about(masses, positions, point)
    L = cloud_scale(positions, point[None, :])
    M = float(np.sum(masses))
    err = np.max(np.abs(got - expected))
    assert err <= REL * M * L**2, f"inertia_about({point!r}) off by {err:.3e}\ngot=\n{got!r}\nexpected=\n{expected!r}"


@given(bodies())
def test_inertia_about_com_is_inertia_and_about_far_point(body):
    a = make(body)
    np.testing.assert_allclose(
        a.inertia_about(body.com), a.inertia, rtol=0,
        atol=REL * (body.mass * np.dot(body.com, body.com) + np.max(np.abs(body.inertia))),
    )
    # about the origin, brute force on the equivalent cloud
    expected = ref.inertia_of_points_about(body.cloud_masses, body.cloud_positions, np.zeros(3))
    L = cloud_scale(body.cloud_positions)
    np.testing.assert_allclose(a.inertia_about([0.0, 0.0, 0.0]), expected, rtol=0, atol=REL * body.mass * L**2)


def test_inertia_about_hand_example():
    # 2 kg point at (1, 0, 0), about (0, 1, 0): d = (1, -1, 0), |d|^2 = 2
    # I = 2 (2 E - d d^T) = [[2, 2, 0], [2, 2, 0], [0, 0, 4]]
    got = MP.point(2.0, [1.0, 0.0, 0.0]).inertia_about([0.0, 1.0, 0.0])
    np.testing.assert_allclose(got, [[2.0, 2.0, 0.0], [2.0, 2.0, 0.0], [0.0, 0.0, 4.0]], rtol=0, atol=1e-15)


# --------------------------------------------------------------------------------------------------
# isclose / ==
# --------------------------------------------------------------------------------------------------


def test_isclose_and_eq_semantics():
    a = MP(2.0, [1.0, 2.0, 3.0], np.diag([1.0, 2.0, 2.5]))
    same = MP(2.0, [1.0, 2.0, 3.0], np.diag([1.0, 2.0, 2.5]))
    assert a == same and a.isclose(same) and not (a != same)
    # far below the default tolerances (rtol 1e-9): equal
    tiny = MP(2.0 * (1 + 1e-13), [1.0, 2.0, 3.0 * (1 + 1e-13)], np.diag([1.0, 2.0, 2.5]) * (1 + 1e-13))
    assert a == tiny
    # clearly different in each component: not equal
    assert a != MP(2.0 * (1 + 1e-6), [1.0, 2.0, 3.0], np.diag([1.0, 2.0, 2.5]))
    assert a != MP(2.0, [1.0, 2.0, 3.0 + 1e-6], np.diag([1.0, 2.0, 2.5]))
    assert a != MP(2.0, [1.0, 2.0, 3.0], np.diag([1.0, 2.0, 2.5 * (1 + 1e-6)]))
    assert not a.isclose(MP(2.0, [1.0, 2.0, 3.0 + 1e-6], np.diag([1.0, 2.0, 2.5])))
    # explicit tolerances are honoured
    assert a.isclose(MP(2.0, [1.0, 2.0, 3.0 + 1e-6], np.diag([1.0, 2.0, 2.5])), rtol=1e-3, atol=1e-3)
    assert not a.isclose(tiny, rtol=0.0, atol=0.0)
    # comparing with a non-MassProperties is simply unequal
    assert (a == "not a body") is False
    assert a != MP.zero()


# --------------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------------

GOOD_COM = [0.0, 0.0, 0.0]
GOOD_INERTIA = np.diag([1.0, 1.0, 1.0])


@pytest.mark.parametrize("mass", [NAN, INF, -INF, -1.0, 0.0, -0.0, -1e-300])
def test_bad_mass_raises_value_error_naming_mass(mass):
    with arg_error(ValueError, "mass"):
        MP(mass, GOOD_COM, GOOD_INERTIA)
    with arg_error(ValueError, "mass"):
        MP.point(mass, GOOD_COM)
    with arg_error(ValueError, "mass"):
        MP.solid_box(mass, [1.0, 1.0, 1.0])


@pytest.mark.parametrize(
    "com",
    [[NAN, 0.0, 0.0], [0.0, INF, 0.0], [0.0, 0.0, -INF], [0.0, 0.0], [0.0, 0.0, 0.0, 0.0], np.zeros((3, 3)), []],
    ids=["nan", "inf", "-inf", "len2", "len4", "3x3", "empty"],
)
def test_bad_com_raises_value_error_naming_com(com):
    with arg_error(ValueError, "com"):
        MP(1.0, com, GOOD_INERTIA)


@pytest.mark.parametrize(
    "inertia",
    [
        [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],  # not symmetric
        [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]],  # eigenvalues 3, -1, 1: not PSD
        np.diag([-1.0, 1.0, 1.0]),  # negative moment
        np.diag([1.0, 1.0, 3.0]),  # PSD but 1 + 1 < 3: triangle inequality violated
        np.diag([1.0, 1.0, 2.01]),  # violated by 0.5 %
        ref.rodrigues([1.0, -2.0, 0.5], 1.1) @ np.diag([1.0, 1.0, 2.1]) @ ref.rodrigues([1.0, -2.0, 0.5], 1.1).T,
        np.diag([NAN, 1.0, 1.0]),
        np.diag([INF, INF, INF]),
        [1.0, 1.0, 1.0],  # shape (3,)
        np.eye(2),
        np.eye(4),
        np.zeros((3, 4)),
    ],
    ids=["asym", "not-psd", "negative", "triangle", "triangle-0.5%", "triangle-rotated", "nan", "inf",
         "shape3", "2x2", "4x4", "3x4"],
)
def test_bad_inertia_raises_value_error_naming_inertia(inertia):
    with arg_error(ValueError, "inertia"):
        MP(1.0, GOOD_COM, inertia)


@pytest.mark.parametrize(
    "rotation",
    [
        2.0 * np.eye(3),
        np.diag([1.0, 1.0, -1.0]),  # orthonormal but a reflection (det -1)
        -np.eye(3),  # det -1
        ref.rodrigues([0, 0, 1], 0.4) + 1e-4,  # perturbed rotation
        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, NAN]]),
        np.zeros((3, 3)),
        np.eye(2),
    ],
    ids=["scaled", "reflection", "minus-identity", "perturbed", "nan", "zeros", "2x2"],
)
def test_bad_rotation_raises_value_error_naming_rotation(rotation):
    a = MP.solid_box(1.0, [1.0, 2.0, 3.0])
    with arg_error(ValueError, "rotation"):
        a.transformed(rotation, [0.0, 0.0, 0.0])
    with arg_error(ValueError, "rotation"):
        MP.solid_box(1.0, [1.0, 2.0, 3.0], rotation=rotation)


def test_bad_translation_and_homogeneous_matrix():
    a = MP.solid_box(1.0, [1.0, 2.0, 3.0])
    with arg_error(ValueError, "translation"):
        a.transformed(np.eye(3), [0.0, NAN, 0.0])
    with arg_error(ValueError, "translation"):
        a.transformed(np.eye(3), [0.0, 0.0])
    bad_bottom = np.eye(4)
    bad_bottom[3] = [0.0, 0.0, 0.0, 2.0]
    with pytest.raises(ValueError):
        a.transformed(bad_bottom)
    with pytest.raises(ValueError):
        a.transformed(ref.homogeneous(np.diag([1.0, -1.0, 1.0]), [0, 0, 0]))


def test_bad_from_points():
    with pytest.raises(ValueError):
        MP.from_points([1.0, 2.0, 3.0], np.zeros((2, 3)))  # lengths differ
    with pytest.raises(ValueError):
        MP.from_points([1.0, 2.0], np.zeros((2, 2)))  # positions not (n, 3)
    with pytest.raises(ValueError):
        MP.from_points([1.0, -2.0], np.zeros((2, 3)))  # negative mass
    with pytest.raises(ValueError):
        MP.from_points([1.0, NAN], np.zeros((2, 3)))
    with pytest.raises(ValueError):
        MP.from_points([1.0, 2.0], [[0.0, 0.0, 0.0], [0.0, INF, 0.0]])


BOX = MP.solid_box(1.0, [1.0, 1.0, 1.0])
OTHER_BAD_CALLS = {
    "box-negative-size": lambda: MP.solid_box(1.0, [1.0, -1.0, 1.0]),
    "box-size-shape": lambda: MP.solid_box(1.0, [1.0, 1.0]),
    "box-size-nan": lambda: MP.solid_box(1.0, [1.0, 1.0, NAN]),
    "box-center-nan": lambda: MP.solid_box(1.0, [1.0, 1.0, 1.0], center=[0.0, NAN, 0.0]),
    "box-center-shape": lambda: MP.solid_box(1.0, [1.0, 1.0, 1.0], center=[0.0, 0.0]),
    "inertia_about-nan": lambda: BOX.inertia_about([0.0, NAN, 0.0]),
    "inertia_about-inf": lambda: BOX.inertia_about([INF, 0.0, 0.0]),
    "inertia_about-shape": lambda: BOX.inertia_about([0.0, 0.0]),
    "point-position-nan": lambda: MP.point(1.0, [NAN, 0.0, 0.0]),
    "point-position-shape": lambda: MP.point(1.0, [0.0, 0.0]),
}


@pytest.mark.parametrize("call", OTHER_BAD_CALLS.values(), ids=OTHER_BAD_CALLS.keys())
def test_other_bad_arguments_raise_value_error(call):
    with pytest.raises(ValueError):
        call()


def test_non_numeric_arguments_raise_type_or_value_error():
    with pytest.raises((TypeError, ValueError)):
        MP("heavy", GOOD_COM, GOOD_INERTIA)
    with pytest.raises((TypeError, ValueError)):
        MP(1.0, "origin", GOOD_INERTIA)
    with pytest.raises((TypeError, ValueError)):
        MP(1.0, GOOD_COM, "identity")
    with pytest.raises((TypeError, ValueError)):
        MP(None, GOOD_COM, GOOD_INERTIA)
    a = MP.solid_box(1.0, [1.0, 1.0, 1.0])
    with pytest.raises(TypeError):
        a + "body"
    with pytest.raises(TypeError):
        a - None
    # the interpreter is still fine after all of the above
    assert (a + a).mass == 2.0
