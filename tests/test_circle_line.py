"""Tests of lk.circle_line and lk.rotation_toward_line.

References: reference.circle_line / reference.rotation_toward_line (dense angle sampling of the circle,
4096 samples, every sampled local minimum refined by golden-section search to 1e-14 rad), plus closed-form
answers for the special families (derived in comments), never values from the code under test.

Scenes are built in a local frame (circle at the origin, normal +z, in-plane axes x, y) and then placed by a
random rotation Q and translation T, with normal and line direction passed as random non-unit multiples.

Tolerances (reference.circle_line_tolerance): tol = 1e-12 * scale + 8 eps * coordinate magnitude, with
scale = radius + distance(centre, line). Any sound float64 algorithm is within a few hundred eps * scale
(1e-12 leaves >1e3 margin, still far tighter than float32 or any formula error); the 8 eps |X| term is the
irreducible uncertainty of inputs with coordinates of size |X| (it matters only for far-away scenes).
Closest-point *locations* of smooth minima are determined only to ~sqrt(eps * scale / curvature) by
distance values, so locations are compared to 1e-6 * scale (a wrong minimiser is O(scale) away).
"""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))

import legkit as lk  # noqa: E402
import reference as ref  # noqa: E402
from conftest import directions, examples, reals, rotations, vectors  # noqa: E402

EPS = ref.EPS
NAN = float("nan")
INF = float("inf")
LOCATION_REL = 1e-6


# --------------------------------------------------------------------------------------------------
# scene construction
# --------------------------------------------------------------------------------------------------


@dataclass
class Scene:
    """A circle-line query built in the local frame and placed by (Q, T)."""

    Q: np.ndarray
    T: np.ndarray
    radius: float
    normal_scale: float
    direction_scale: float
    line_point_local: np.ndarray
    line_direction_local: np.ndarray
    # closed-form expectations (None = not asserted)
    distance: float | None = None
    count: int | None = None
    equidistant: bool | None = None
    circle_points_local: np.ndarray | None = None
    line_points_local: np.ndarray | None = None
    location_rel: float = LOCATION_REL
    name: str = ""

    @property
    def center(self):
        return self.T.copy()

    @property
    def normal(self):
        return self.Q[:, 2] * self.normal_scale

    @property
    def line_point(self):
        return self.T + self.Q @ self.line_point_local

    @property
    def line_direction(self):
        return (self.Q @ self.line_direction_local) * self.direction_scale

    def args(self, offset=None):
        c, lp = self.center, self.line_point
        if offset is not None:
            c, lp = c + offset, lp + offset
        return c, self.normal, self.radius, lp, self.line_direction

    def to_global(self, local_points, offset=None):
        p = self.T + np.asarray(local_points) @ self.Q.T
        return p if offset is None else p + offset


def signed_scales():
    return st.tuples(st.sampled_from([1.0, -1.0]), reals(np.log(1e-2), np.log(1e2))).map(
        lambda t: t[0] * float(np.exp(t[1]))
    )


@st.composite
def placements(draw, radius_range=(0.1, 10.0)):
    return dict(
        Q=draw(rotations()),
        T=draw(vectors()),
        radius=draw(reals(*radius_range)),
        normal_scale=draw(signed_scales()),
        direction_scale=draw(signed_scales()),
    )


def in_plane(phi):
    e = np.array([np.cos(phi), np.sin(phi), 0.0])
    f = np.array([-np.sin(phi), np.cos(phi), 0.0])
    return e, f


Z = np.array([0.0, 0.0, 1.0])


@st.composite
def family_scene(draw, family):
    """Scenes whose answer is known in closed form (local frame: circle at 0, normal z, radius r)."""
    p = draw(placements())
    r = p["radius"]
    s = draw(reals(-10.0, 10.0))  # where along the line the given line point sits
    phi = draw(reals(-np.pi, np.pi))
    e, f = in_plane(phi)
    if family == "axis":
        # every circle point is at distance r from its own axis
        return Scene(**p, line_point_local=s * Z, line_direction_local=Z, distance=r, equidistant=True, count=1,
                     name=family)
    if family == "parallel_axis":
        # line {h e + t z}: distance from r(cos t', sin t') to it is |h e - r w|, minimal (|h - r|) at w = e
        h = draw(reals(0.05, 5.0)) * r
        return Scene(**p, line_point_local=h * e + s * Z, line_direction_local=Z, distance=abs(h - r), count=1,
                     equidistant=False, circle_points_local=np.array([r * e]), line_points_local=np.array([h * e]),
                     name=family)
    if family == "parallel_axis_close":
        # as parallel_axis, but the line hugs the axis (h = 1e-9 .. 1e-2 r) and its given point is far along
        # it: the offset h must not be computed by cancellation (sqrt(|w|^2 - (w.n)^2) has error eps s^2 / h).
        # Flags are asserted only where the distances over the circle vary by >= 2e-6 r (h >= 1e-6 r).
        h = float(np.exp(draw(reals(np.log(1e-9), np.log(1e-2))))) * r
        s = draw(reals(-100.0, 100.0))
        flags = dict(count=1, equidistant=False) if h >= 1e-6 * r else {}
        return Scene(**p, line_point_local=h * e + s * Z, line_direction_local=Z, distance=abs(h - r),
                     circle_points_local=np.array([r * e]) if flags else None,
                     line_points_local=np.array([h * e]) if flags else None, name=family, **flags)
    if family == "through_centre":
        # line through the centre with direction d = cos(a) e + sin(a) z; for X = r w (w in-plane unit),
        # dist = r sqrt(1 - (w.d)^2) = r sqrt(1 - cos^2(a) (w.e)^2): minimal r |sin a| at w = +-e (two points);
        # the feet are +-r cos(a) d.
        alpha = draw(reals(-1.2, 1.2))
        d = np.cos(alpha) * e + np.sin(alpha) * Z
        return Scene(**p, line_point_local=s * d, line_direction_local=d, distance=r * abs(np.sin(alpha)), count=2,
                     equidistant=False, circle_points_local=np.array([r * e, -r * e]),
                     line_points_local=np.array([r * np.cos(alpha) * d, -r * np.cos(alpha) * d]), name=family)
    if family == "in_plane_crossing":
        # line {o f + t e} in the plane, |o| < r: it crosses the circle at o f +- sqrt(r^2 - o^2) e
        o = draw(reals(-0.9, 0.9)) * r
        x = np.sqrt(r * r - o * o)
        pts = np.array([o * f + x * e, o * f - x * e])
        return Scene(**p, line_point_local=o * f + s * e, line_direction_local=e, distance=0.0, count=2,
                     equidistant=False, circle_points_local=pts, line_points_local=pts, name=family)
    if family == "in_plane_outside":
        # |o| > r: nearest circle point r sign(o) f, at distance |o| - r from the line point o f
        o = draw(reals(1.1, 5.0)) * r * draw(st.sampled_from([1.0, -1.0]))
        return Scene(**p, line_point_local=o * f + s * e, line_direction_local=e, distance=abs(o) - r, count=1,
                     equidistant=False, circle_points_local=np.array([np.sign(o) * r * f]),
                     line_points_local=np.array([o * f]), name=family)
    if family == "tangent":
        # |o| = r: touches at r sign(o) f. Rounding of the placed scene makes it cross or miss by ~eps*scale,
        # so the touching points are only determined to ~sqrt(eps * scale) (see check_scene) and the count
        # (1 touching or 2 nearby crossing points) is not asserted.
        o = r * draw(st.sampled_from([1.0, -1.0]))
        return Scene(**p, line_point_local=o * f + s * e, line_direction_local=e, distance=0.0,
                     equidistant=False, circle_points_local=np.array([np.sign(o) * r * f]),
                     line_points_local=np.array([o * f]), name=family)
    if family == "parallel_plane_crossing":
        # line {o f + h z + t e}: dist^2 = h^2 + (in-plane distance)^2; the projection crosses the circle when
        # |o| < r, so the minimum |h| is attained at the two crossing points.
        h = draw(reals(0.05, 5.0)) * r * draw(st.sampled_from([1.0, -1.0]))
        o = draw(reals(-0.9, 0.9)) * r
        x = np.sqrt(r * r - o * o)
        pts = np.array([o * f + x * e, o * f - x * e])
        return Scene(**p, line_point_local=o * f + h * Z + s * e, line_direction_local=e, distance=abs(h), count=2,
                     equidistant=False, circle_points_local=pts, line_points_local=pts + h * Z, name=family)
    if family == "parallel_plane_outside":
        h = draw(reals(0.05, 5.0)) * r * draw(st.sampled_from([1.0, -1.0]))
        o = draw(reals(1.1, 5.0)) * r * draw(st.sampled_from([1.0, -1.0]))
        return Scene(**p, line_point_local=o * f + h * Z + s * e, line_direction_local=e,
                     distance=float(np.hypot(h, abs(o) - r)), count=1, equidistant=False,
                     circle_points_local=np.array([np.sign(o) * r * f]),
                     line_points_local=np.array([o * f + h * Z]), name=family)
    raise AssertionError(family)


FAMILIES = [
    "axis",
    "parallel_axis",
    "parallel_axis_close",
    "through_centre",
    "in_plane_crossing",
    "in_plane_outside",
    "tangent",
    "parallel_plane_crossing",
    "parallel_plane_outside",
]


@st.composite
def general_scene(draw):
    """A random circle and line, no structure."""
    p = draw(placements(radius_range=(0.01, 10.0)))
    return Scene(**p, line_point_local=draw(vectors()), line_direction_local=ref.unit(draw(directions())),
                 name="general")


# --------------------------------------------------------------------------------------------------
# checks
# --------------------------------------------------------------------------------------------------


def tolerance(center, radius, line_point, line_direction):
    return ref.circle_line_tolerance(center, radius, line_point, line_direction)


def check_single_result_geometry(res, center, normal, radius, line_point, line_direction, tol):
    """Invariants of any single-query answer: shapes/types, circle points on the circle, line points on the
    line, and each pair exactly `distance` apart."""
    assert isinstance(res.distance, float), type(res.distance)
    assert isinstance(res.count, int) and res.count in (1, 2), res.count
    assert isinstance(res.equidistant, bool), type(res.equidistant)
    cp, lp = np.asarray(res.circle_points), np.asarray(res.line_points)
    assert cp.shape == (res.count, 3) and lp.shape == (res.count, 3), (cp.shape, lp.shape, res.count)
    assert res.distance >= 0.0
    n = ref.unit(normal)
    d = ref.unit(line_direction)
    query = "query: " + ", ".join(
        f"{k}={np.asarray(v).tolist()!r}"
        for k, v in zip(CL_ORDER, (center, normal, radius, line_point, line_direction))
    )
    for x, y in zip(cp, lp):
        err = abs(ref.norm(x - center) - radius)
        assert err <= tol, f"circle point {x!r} off the circle by {err:.3e} (tol {tol:.3e}); {query}"
        err = abs(np.dot(x - center, n))
        assert err <= tol, f"circle point {x!r} off the circle's plane by {err:.3e} (tol {tol:.3e}); {query}"
        off_line = ref.norm(np.cross(y - line_point, d))
        assert off_line <= tol + 8 * EPS * ref.norm(y - line_point), (
            f"line point {y!r} off the line by {off_line:.3e} (tol {tol:.3e}); {query}"
        )
        assert abs(ref.norm(x - y) - res.distance) <= tol, (
            f"|circle point - line point| = {ref.norm(x - y)!r} but distance = {res.distance!r}; {query}"
        )


def assert_point_sets_match(got, expected, atol, what, all_expected=True):
    """Every returned point is one of the expected ones and (if all_expected) every expected one is returned."""
    got = np.asarray(got)
    expected = np.asarray(expected)
    for e in expected if all_expected else []:
        dmin = np.min(np.linalg.norm(got - e, axis=1))
        assert dmin <= atol, f"{what}: expected point {e!r} not returned (closest off by {dmin:.3e} > {atol:.3e}); got {got!r}"
    for g in got:
        dmin = np.min(np.linalg.norm(expected - g, axis=1))
        assert dmin <= atol, f"{what}: returned point {g!r} is not an expected one (off by {dmin:.3e}); expected {expected!r}"


def check_against_reference(res, args, tol, context=""):
    r_ref = ref.circle_line(*args)
    assert abs(res.distance - r_ref.distance) <= tol, (
        f"{context}: distance {res.distance!r} but brute force gives {r_ref.distance!r} "
        f"(diff {res.distance - r_ref.distance:.3e}, tol {tol:.3e}); query={[np.asarray(a).tolist() for a in args]}"
    )
    return r_ref


def check_scene(scene: Scene, offset=None):
    args = scene.args(offset)
    center, normal, radius, line_point, line_direction = args
    res = lk.circle_line(*args)
    tol = tolerance(center, radius, line_point, line_direction)
    check_single_result_geometry(res, *args, tol)
    # reference computed on the untranslated scene: translation must not change the answer
    r_ref = ref.circle_line(*scene.args())
    if scene.distance is not None:
        assert abs(r_ref.distance - scene.distance) <= tol, "reference self-check against the closed form"
        assert abs(res.distance - scene.distance) <= tol, (
            f"{scene.name}: distance {res.distance!r}, closed form {scene.distance!r} "
            f"(diff {res.distance - scene.distance:.3e}, tol {tol:.3e}); query={[np.asarray(a).tolist() for a in args]}"
        )
    assert abs(res.distance - r_ref.distance) <= tol, (
        f"{scene.name}: distance {res.distance!r}, brute force {r_ref.distance!r} "
        f"(diff {res.distance - r_ref.distance:.3e}, tol {tol:.3e}); query={[np.asarray(a).tolist() for a in args]}"
    )
    # Far from the origin the inputs' own rounding (~eps |offset|) breaks exact symmetries by more than the
    # scene's relative precision, so there a tie may legitimately be resolved to one point and an axis line may
    # be judged slightly off-axis: count and equidistant are not asserted, and the returned points need only be
    # among the expected ones.
    exact_count = offset is None
    if scene.count is not None and exact_count:
        assert res.count == scene.count, (
            f"{scene.name}: count {res.count}, expected {scene.count}; points {res.circle_points!r}; "
            f"query={[np.asarray(a).tolist() for a in args]}"
        )
    if scene.equidistant is not None and exact_count:
        assert res.equidistant is scene.equidistant, f"{scene.name}: equidistant {res.equidistant}"
    if res.equidistant:
        assert res.count == 1, "an equidistant answer gives one representative point"
    scale = ref.circle_line_scale(center, radius, line_point, line_direction)
    # Locations: ~sqrt(eps) conditioning of smooth minima (LOCATION_REL, module docstring), plus the effect of
    # perturbing the geometry by tol (inputs' rounding): near tangency a shift delta of the line moves or splits
    # the touching points by up to sqrt(2 scale delta).
    loc = scene.location_rel * scale + 2.0 * np.sqrt(2.0 * scale * tol) + tol
    if scene.circle_points_local is not None:
        assert_point_sets_match(res.circle_points, scene.to_global(scene.circle_points_local, offset), loc,
                                f"{scene.name} circle points", all_expected=exact_count)
    if scene.line_points_local is not None:
        assert_point_sets_match(res.line_points, scene.to_global(scene.line_points_local, offset), loc,
                                f"{scene.name} line points", all_expected=exact_count)
    return res, r_ref


# --------------------------------------------------------------------------------------------------
# hand-computed examples
# --------------------------------------------------------------------------------------------------


def test_hand_example_line_outside_in_plane():
    # unit circle in z = 0; line x = 2 along y: nearest circle point (1, 0, 0), foot (2, 0, 0), distance 1
    r = lk.circle_line([0, 0, 0], [0, 0, 1], 1.0, [2, 5, 0], [0, 1, 0])
    assert r.distance == pytest.approx(1.0, abs=1e-15)
    assert r.count == 1 and r.equidistant is False
    # a smooth minimum: its location is only defined to ~sqrt(eps) by distance values (module docstring)
    np.testing.assert_allclose(r.circle_points, [[1.0, 0.0, 0.0]], atol=LOCATION_REL * 2)
    np.testing.assert_allclose(r.line_points, [[2.0, 0.0, 0.0]], atol=LOCATION_REL * 2)


def test_hand_example_line_is_the_axis():
    r = lk.circle_line([0, 0, 0], [0, 0, 2], 1.5, [0, 0, 5], [0, 0, -3])
    assert r.distance == pytest.approx(1.5, abs=1e-15)
    assert r.equidistant is True and r.count == 1
    np.testing.assert_allclose(np.linalg.norm(r.circle_points[0]), 1.5, atol=1e-15)
    np.testing.assert_allclose(r.circle_points[0][2], 0.0, atol=1e-15)
    np.testing.assert_allclose(r.line_points, [[0.0, 0.0, 0.0]], atol=1e-15)


def test_hand_example_radius_zero():
    # the circle is the point (1, 1, 1); line = x axis: foot (1, 0, 0), distance sqrt(2)
    r = lk.circle_line([1, 1, 1], [0, 1, 0], 0.0, [0, 0, 0], [1, 0, 0])
    assert r.distance == pytest.approx(np.sqrt(2.0), abs=1e-15)
    assert r.count == 1 and r.equidistant is True
    np.testing.assert_allclose(r.circle_points, [[1.0, 1.0, 1.0]], atol=1e-15)
    np.testing.assert_allclose(r.line_points, [[1.0, 0.0, 0.0]], atol=1e-15)


def test_hand_example_line_through_centre_in_plane():
    r = lk.circle_line([0, 0, 0], [0, 0, 1], 2.0, [-3, 0, 0], [1, 0, 0])
    assert r.distance == pytest.approx(0.0, abs=1e-15)
    assert r.count == 2 and r.equidistant is False
    # crossing points (distance 0, V-shaped minima) are well conditioned
    assert_point_sets_match(r.circle_points, [[2, 0, 0], [-2, 0, 0]], 1e-12, "circle points")
    assert_point_sets_match(r.line_points, [[2, 0, 0], [-2, 0, 0]], 1e-12, "line points")


def test_hand_example_line_parallel_to_plane():
    # line z = 3, y = 0.6 along x over the unit circle: crosses above (+-0.8, 0.6, 0), distance 3
    r = lk.circle_line([0, 0, 0], [0, 0, 1], 1.0, [0, 0.6, 3], [1, 0, 0])
    assert r.distance == pytest.approx(3.0, abs=1e-15)
    assert r.count == 2
    # distance sqrt(9 + (in-plane distance)^2) is smooth at its minima: location to ~sqrt(eps) (docstring)
    assert_point_sets_match(r.circle_points, [[0.8, 0.6, 0], [-0.8, 0.6, 0]], LOCATION_REL * 4, "circle points")
    assert_point_sets_match(r.line_points, [[0.8, 0.6, 3], [-0.8, 0.6, 3]], LOCATION_REL * 4, "line points")


# Cases found by the property tests below, kept as fixed regressions: (query, expected flags or None).
# Checked with the same invariants and brute force as the property tests.
REGRESSIONS = {
    # parallel_axis family, distance 0: a line parallel to a nearly y-aligned normal through a circle point
    "parallel-axis-nearly-aligned-normal": (
        (
            [0.0, 0.0, 0.0],
            [1.465934043551448e-05, 0.9999999998925518, 1.0744816147933989e-10],
            1.0,
            [-0.9999999997851037, 1.465934043551448e-05, -1.465934043551448e-05],
            [2.915357960347044e-05, 1.9887374693686057, 2.136861847716919e-10],
        ),
        dict(count=1, equidistant=False),
    ),
    # radius 0, line parallel to the normal (directions equal up to an ulp, tiny x components) passing
    # 4.1e-5 from the centre: the distance must be the point-line distance 4.118319643915983e-05
    "radius-zero-line-parallel-to-normal": (
        (
            [0.0, 0.0, 0.0],
            [8.540973236015979e-39, 1.9561755098827145e-05, 0.9258185579077083],
            0.0,
            [0.0, 0.0, 1.94911792695584],
            [6.1841935151886e-39, 1.416392203616174e-05, 0.6703499664313196],
        ),
        dict(count=1, equidistant=True),
    ),
    # the same kind of set-up found through rotation_toward_line (point on the axis): distance 6.2165e-8
    "radius-zero-line-parallel-to-normal-2": (
        (
            [0.0, 0.0, 0.0],
            [1.3750669035920504e-69, 6.216527089015008e-08, 0.9999999999999981],
            0.0,
            [0.0, 0.0, 1.0],
            [1.463751099515076e-69, 6.617458639969246e-08, 1.0644944589178573],
        ),
        dict(count=1, equidistant=True),
    ),
    # nearly tangent line tilted 1e-6 out of the plane: the distance has two wells 1.4e-3 rad apart
    "tangent-tilted-double-well": (
        (
            [0.0, 0.0, 0.0],
            [0.0, -0.0, -0.9999999999999998],
            3.0,
            [-1.7999999999999998, -2.5999999999999996, 0.0],
            [0.5999994343142752, -0.8000004242636686, -7.071067811864296e-07],
        ),
        None,
    ),
    # the line IS the axis (normal and line direction parallel to 1e-51, line point on the axis to 1e-51;
    # the brute-force spread of distances over the circle is 3e-16, i.e. rounding)
    "axis-line-nearly-z-normal": (
        (
            [0.0, 0.0, 0.0],
            [0.00012600806401593902, 4.173049432566246e-32, -0.9999999920609839],
            1.0,
            [0.00012600806401593902, 4.173049432566246e-32, -0.9999999920609839],
            [0.0019254373294128571, 6.376532500278581e-31, -15.280270585565274],
        ),
        dict(count=1, equidistant=True),
    ),
    # the line is the axis (line direction = 2 x normal, normal scaled by 1e-3, both ~1e-7 off -z): the
    # representative circle point came back 8.4e-10 off the circle's plane (radius 1)
    "axis-line-normal-1e-7-off-z": (
        (
            [0.0, 0.0, 0.0],
            [7.775179140127354e-11, 1.117682001393307e-10, -0.0009999999999999907],
            1.0,
            [0.0, 0.0, 0.0],
            [1.5550358280254707e-07, 2.235364002786614e-07, -1.9999999999999813],
        ),
        dict(count=1, equidistant=True),
    ),
    # the line is the axis through the centre; normal nearly -z with 1e-4 x/y components
    "axis-line-tilted-normal": (
        (
            [0.0, 0.0, 0.0],
            [5.135579277246771e-05, 9.950184849665618e-05, -0.9999999937309825],
            1.0,
            [0.0, 0.0, 0.0],
            [0.0007847304159295114, 0.0015204151808634282, -15.280270611083305],
        ),
        dict(count=1, equidistant=True),
    ),
}


@pytest.mark.parametrize("case", REGRESSIONS.values(), ids=REGRESSIONS.keys())
def test_regression_queries(case):
    query, flags = case
    args = tuple(np.asarray(a, dtype=np.float64) for a in query)
    res = lk.circle_line(*args)
    tol = tolerance(args[0], args[2], args[3], args[4])
    check_single_result_geometry(res, *args, tol)
    check_against_reference(res, args, tol)
    if flags is not None:
        assert (res.count, res.equidistant) == (flags["count"], flags["equidistant"]), res


# --------------------------------------------------------------------------------------------------
# random scenes
# --------------------------------------------------------------------------------------------------


@pytest.mark.slow
@examples(200)
@given(general_scene())
def test_general_scene_matches_brute_force(scene):
    res, r_ref = check_scene(scene)
    center, normal, radius, line_point, line_direction = scene.args()
    scale = ref.circle_line_scale(center, radius, line_point, line_direction)
    if r_ref.sample_spread > 1e-6 * scale:
        assert res.equidistant is False


@given(general_scene(), st.sampled_from([2.0, -1.0, 0.5, 1e-3, 1e3]), st.sampled_from([2.0, -1.0, 0.25, 1e3]))
def test_direction_lengths_and_signs_do_not_matter(scene, normal_factor, direction_factor):
    c, n, r, lp, ld = scene.args()
    base = lk.circle_line(c, n, r, lp, ld)
    scaled = lk.circle_line(c, n * normal_factor, r, lp, ld * direction_factor)
    tol = tolerance(c, r, lp, ld)
    assert abs(base.distance - scaled.distance) <= tol
    check_single_result_geometry(scaled, c, n, r, lp, ld, tol)


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
@examples(100)
@given(data=st.data())
def test_special_family(family, data):
    check_scene(data.draw(family_scene(family), label=family))


@examples(100)
@given(vectors(), directions(), vectors(), directions())
def test_radius_zero(center, normal, line_point, line_direction):
    res = lk.circle_line(center, normal, 0.0, line_point, line_direction)
    tol = tolerance(center, 0.0, line_point, line_direction)
    check_single_result_geometry(res, center, normal, 0.0, line_point, line_direction, tol)
    expected = float(ref.point_line_distance(center, line_point, line_direction))
    assert abs(res.distance - expected) <= tol
    assert res.count == 1 and res.equidistant is True
    np.testing.assert_allclose(res.circle_points[0], center, rtol=0, atol=tol)
    np.testing.assert_allclose(res.line_points[0], ref.foot_on_line(center, line_point, line_direction), rtol=0,
                               atol=tol + 8 * EPS * np.linalg.norm(line_point))


@pytest.mark.slow
@examples(150)
@given(vectors(), directions(), directions(), directions(), reals(np.log(1e-12), np.log(1e-2)), reals(-100.0, 100.0),
       st.sampled_from([None, 1.0, -2.5]))
def test_radius_zero_line_passing_close_to_the_centre(center, normal, line_direction, side, log_gap, s, along_axis):
    """A radius-0 circle (a point) and a line passing at a small gap from it, with the given line point far
    along the line: the distance is the gap. The line direction is random or parallel to the normal (the
    line parallel to the circle's axis). Point-line distance computed as sqrt(|w|^2 - (w.d)^2) loses half
    the digits here (error ~ eps |w|^2 / gap); computed from the perpendicular component it does not."""
    if along_axis is not None:
        line_direction = along_axis * normal
    d = ref.unit(line_direction)
    p = np.cross(d, ref.unit(side))
    assume(np.linalg.norm(p) > 0.1)
    gap = float(np.exp(log_gap)) * (1.0 + abs(s))
    line_point = center + gap * ref.unit(p) + s * d
    expected = float(ref.point_line_distance(center, line_point, line_direction))  # == gap up to rounding
    res = lk.circle_line(center, normal, 0.0, line_point, line_direction)
    tol = tolerance(center, 0.0, line_point, line_direction)
    check_single_result_geometry(res, center, normal, 0.0, line_point, line_direction, tol)
    assert abs(res.distance - expected) <= tol, (
        f"distance {res.distance!r}, expected {expected!r} (diff {res.distance - expected:.3e}, tol {tol:.3e}); "
        f"query={[np.asarray(a).tolist() for a in (center, normal, 0.0, line_point, line_direction)]}"
    )


TILTS = [1e-6, 1e-8, 1e-10]


@pytest.mark.slow
@examples(200)
@given(st.sampled_from(FAMILIES), st.sampled_from(TILTS), st.data())
def test_nearly_degenerate_family(family, tilt, data):
    """Each special family with the line direction tilted by 1e-6, 1e-8 or 1e-10 rad about a random axis
    perpendicular to it: only the brute-force reference and the invariants are asserted."""
    scene = data.draw(family_scene(family), label="scene")
    d = scene.line_direction_local
    w = np.cross(d, ref.unit(data.draw(directions(), label="tilt axis")))
    assume(np.linalg.norm(w) > 0.1)
    w = ref.unit(w)
    scene.line_direction_local = np.cos(tilt) * d + np.sin(tilt) * w
    scene.distance = scene.count = scene.equidistant = None
    scene.circle_points_local = scene.line_points_local = None
    scene.name = f"{family} tilted {tilt:g}"
    check_scene(scene)


@pytest.mark.slow
@examples(100)
@given(general_scene(), st.sampled_from([1e-6, 1e-8, 1e-10, 1e-13]))
def test_nearly_zero_radius(scene, relative_radius):
    scene.radius = relative_radius * max(scene.radius, 1.0)
    scene.name = f"radius {scene.radius:g}"
    check_scene(scene)


@pytest.mark.slow
@examples(150)
@given(st.sampled_from(["general"] + FAMILIES), st.sampled_from([1e6, 1e9]), directions(), st.data())
def test_large_coordinates(family, magnitude, offset_direction, data):
    """The whole scene translated by |offset| = 1e6 or 1e9 must give the untranslated answer within
    1e-12 scale + 8 eps |coordinates| (the inputs themselves are only known to eps/2 |coordinate|)."""
    scene = data.draw(general_scene() if family == "general" else family_scene(family), label="scene")
    offset = ref.unit(offset_direction) * magnitude
    if family == "parallel_axis_close":
        # the side on which the line hugs the axis (h >= 1e-9 r) is below the inputs' rounding at this
        # offset, so the closest circle point is not determined: check distances only
        scene.circle_points_local = scene.line_points_local = None
    res, _ = check_scene(scene, offset=offset)
    near = lk.circle_line(*scene.args())
    tol = tolerance(*[scene.args(offset)[i] for i in (0, 2, 3, 4)])
    assert abs(res.distance - near.distance) <= tol


# --------------------------------------------------------------------------------------------------
# rotation_toward_line
# --------------------------------------------------------------------------------------------------


def rotation_tolerance(axis_point, axis_direction, point, line_point, line_direction):
    a = ref.unit(axis_direction)
    v = np.asarray(point) - np.asarray(axis_point)
    centre = np.asarray(axis_point) + np.dot(v, a) * a
    radius = float(ref.norm(v - np.dot(v, a) * a))
    scale = ref.circle_line_scale(centre, radius, line_point, line_direction)
    magnitude = max(ref.norm(axis_point), ref.norm(point), ref.norm(line_point)) + radius
    return 1e-12 * scale + 8 * EPS * magnitude, scale, centre, radius


def distance_after_rotation(theta, axis_point, axis_direction, point, line_point, line_direction):
    moved = ref.rotate_about_axis(point, axis_point, axis_direction, theta)
    return float(ref.point_line_distance(moved, line_point, line_direction))


@pytest.mark.slow
@examples(200)
@given(vectors(), directions(), vectors(), vectors(), directions())
def test_rotation_toward_line_matches_brute_force(axis_point, axis_direction, point, line_point, line_direction):
    args = (axis_point, axis_direction, point, line_point, line_direction)
    theta, dist = lk.rotation_toward_line(*args)
    assert isinstance(theta, float) and isinstance(dist, float)
    assert -np.pi < theta <= np.pi, theta
    tol, scale, centre, radius = rotation_tolerance(*args)
    r_ref = ref.rotation_toward_line(*args)
    assert abs(dist - r_ref.distance) <= tol, (
        f"dist {dist!r}, brute force {r_ref.distance!r} (diff {dist - r_ref.distance:.3e}, tol {tol:.3e}); args={[a.tolist() for a in args]}"
    )
    # rotating the point by the returned angle (independent Rodrigues) must achieve the returned distance
    achieved = distance_after_rotation(theta, *args)
    assert abs(achieved - dist) <= tol, f"rotation by theta={theta!r} gives distance {achieved!r}, returned {dist!r}"
    # the same question asked as a circle-line query
    cl = lk.circle_line(centre, axis_direction, radius, line_point, line_direction)
    assert abs(cl.distance - dist) <= tol
    # where the minimiser is unique, well separated and not too flat (and the circle not vanishingly small),
    # the angle itself must match: any angle whose distance is within tol of the minimum lies within
    # sqrt(tol / k) of it, k the (conservatively estimated) curvature.
    if radius > 1e-3 * scale:
        best = r_ref.angles[0]
        second = r_ref.values[1] if len(r_ref.values) > 1 else np.inf
        h = 1e-2
        rise = min(distance_after_rotation(best + s, *args) for s in (-h, h)) - r_ref.distance
        k = rise / h**2
        if second - r_ref.distance > 1e-6 * scale and k > 1e-2 * scale:
            dtheta = ref.angle_difference(theta, best)
            allowed = 2 * np.sqrt(tol / k) + 1e-12
            assert dtheta <= allowed, (
                f"theta {theta!r} vs brute-force minimiser {best!r} (|diff| {dtheta:.3e} > {allowed:.3e})"
            )


@examples(150)
@given(vectors(), directions(), vectors(), st.one_of(reals(-np.pi, np.pi), st.sampled_from([1e-8, -6e-8, 1e-5, 3.0])),
       st.one_of(directions(), st.just(None)), reals(-10.0, 10.0))
def test_rotation_onto_a_line_that_crosses_the_circle(axis_point, axis_direction, point, theta0, line_direction, s):
    """The line passes through the point rotated by theta0 (so the minimum distance is 0), with its given
    point s along it; line direction random or parallel to the axis. The returned angle must actually bring
    the point onto the line (checked by an independent Rodrigues rotation) and the distance must be ~0."""
    target = ref.rotate_about_axis(point, axis_point, axis_direction, theta0)
    if line_direction is None:
        line_direction = 2.0 * axis_direction
    line_point = target + s * ref.unit(line_direction)
    args = (axis_point, axis_direction, point, line_point, line_direction)
    tol, scale, _, radius = rotation_tolerance(*args)
    assume(radius >= 1e-3 * (1 + np.linalg.norm(point - axis_point)))
    theta, dist = lk.rotation_toward_line(*args)
    achieved = distance_after_rotation(theta, *args)
    assert abs(dist) <= tol, f"distance {dist!r} should be ~0 (tol {tol:.3e}); args={[np.asarray(a).tolist() for a in args]}"
    assert achieved <= tol, (
        f"rotating by the returned theta={theta!r} leaves the point {achieved!r} from the line (tol {tol:.3e}); "
        f"a crossing angle is theta0={theta0!r}; args={[np.asarray(a).tolist() for a in args]}"
    )


# Exactly representable symmetric set-ups in which two rotations tie; the lower-z one must be returned.
TIE_CASES = [
    # axis x through 0; P = (0, 1, 0) sweeps (0, cos t, sin t); the line through 0 along (0.8, 0, 0.6) is
    # nearest at (0, 0, +-1) (distance sqrt(1 - 0.6^2) = 0.8); lower z = (0, 0, -1) <=> theta = -pi/2
    ("x-axis", [0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 0], [0.8, 0, 0.6], -np.pi / 2, 0.8),
    # axis y through (1, 2, 3); P = (3, 2, 3): v = (2, 0, 0) sweeps (2 cos t, 0, -2 sin t); the line through the
    # centre along (1, 0, 1) crosses the circle at centre +- sqrt(2) (1, 0, 1); lower one: cos t = sin t... with
    # 2 cos t = -sqrt 2 and -2 sin t = -sqrt 2  <=> theta = 3 pi / 4, distance 0
    ("y-axis", [1, 2, 3], [0, 1, 0], [3, 2, 3], [1, 2, 3], [1, 0, 1], 3 * np.pi / 4, 0.0),
    # the same with the axis direction reversed: the right-hand angle changes sign
    ("minus-y-axis", [1, 2, 3], [0, -1, 0], [3, 2, 3], [1, 2, 3], [1, 0, 1], -3 * np.pi / 4, 0.0),
    # axis x through 0, P = (0, 0, 2) sweeps (0, -2 sin t, 2 cos t); line at x = 1.5 along (0, 1, 1) (parallel to
    # the circle's plane, height 1.5): its projection crosses the circle at +-(0, sqrt2, sqrt2); lower z is
    # (0, -sqrt2, -sqrt2) <=> sin t = sqrt2/2, cos t = -sqrt2/2 <=> theta = 3 pi / 4, distance 1.5
    ("plane-parallel", [0, 0, 0], [1, 0, 0], [0, 0, 2], [1.5, 0, 0], [0, 1, 1], 3 * np.pi / 4, 1.5),
    # the same scene scaled by 4 (axis direction non-unit)
    ("plane-parallel-scaled", [0, 0, 0], [4, 0, 0], [0, 0, 8], [6, 0, 0], [0, 3, 3], 3 * np.pi / 4, 6.0),
]


@pytest.mark.parametrize("case", TIE_CASES, ids=[c[0] for c in TIE_CASES])
def test_rotation_tie_returns_lowest_rotated_point(case):
    _, axis_point, axis_direction, point, line_point, line_direction, expected_theta, expected_dist = case
    args = [np.array(a, dtype=np.float64) for a in (axis_point, axis_direction, point, line_point, line_direction)]
    theta, dist = lk.rotation_toward_line(*args)
    # the brute force agrees that there are two minimisers with equal distance
    r_ref = ref.rotation_toward_line(*args)
    assert len(r_ref.values) >= 2 and abs(r_ref.values[1] - r_ref.values[0]) <= 1e-12
    assert abs(r_ref.distance - expected_dist) <= 1e-12
    assert dist == pytest.approx(expected_dist, abs=1e-12)
    assert ref.angle_difference(theta, expected_theta) <= 1e-6, (
        f"theta {theta!r}, expected {expected_theta!r} (the tie partner with lower z)"
    )


@examples(100)
@given(st.sampled_from(["through_centre", "in_plane_crossing", "parallel_plane_crossing"]), st.data())
def test_rotation_tie_rule_in_random_placements(family, data):
    """Symmetric scenes (two circle points tie exactly) in random placements: the returned angle rotates the
    point to the tie partner with the lower z, provided the two z differ clearly."""
    scene = data.draw(family_scene(family), label="scene")
    phi0 = data.draw(reals(-np.pi, np.pi), label="start angle")
    along = data.draw(reals(-5.0, 5.0), label="axis point offset")
    c, n, r, lp, ld = scene.args()
    axis_point = c + along * ref.unit(n)
    point = scene.to_global(r * np.array([np.cos(phi0), np.sin(phi0), 0.0]))
    ties = scene.to_global(scene.circle_points_local)
    assume(abs(ties[0][2] - ties[1][2]) > 0.1 * r)
    target = ties[np.argmin(ties[:, 2])]
    nu = ref.unit(n)
    u, w = point - c, target - c
    expected = float(np.arctan2(np.dot(np.cross(u, w), nu), np.dot(u, w)))
    theta, dist = lk.rotation_toward_line(axis_point, n, point, lp, ld)
    tol, _, _, _ = rotation_tolerance(axis_point, n, point, lp, ld)
    assert abs(dist - scene.distance) <= tol
    assert ref.angle_difference(theta, expected) <= 1e-5, (
        f"theta {theta!r}, expected {expected!r} (lower-z tie partner {target!r}, other {ties[np.argmax(ties[:, 2])]!r})"
    )


@examples(100)
@given(vectors(), directions(), vectors(), directions())
def test_rotation_point_on_axis_gives_zero(axis_point, axis_direction, line_point, line_direction):
    theta, dist = lk.rotation_toward_line(axis_point, axis_direction, axis_point.copy(), line_point, line_direction)
    assert theta == 0.0
    expected = float(ref.point_line_distance(axis_point, line_point, line_direction))
    tol, _, _, _ = rotation_tolerance(axis_point, axis_direction, axis_point, line_point, line_direction)
    assert abs(dist - expected) <= tol


ROTATION_REGRESSIONS = {
    # the point is ON the axis (point == axis_point): theta must be 0 and the distance is the point-line
    # distance 6.216527089015006e-08 (the line is parallel to the axis up to rounding)
    "point-on-axis-line-parallel-to-axis": (
        ([0.0, 0.0, 0.0], [1.3750669035920504e-69, 6.216527089015008e-08, 0.9999999999999981], [0.0, 0.0, 0.0],
         [0.0, 0.0, 1.0], [1.463751099515076e-69, 6.617458639969246e-08, 1.0644944589178573]),
        0.0,
    ),
    # axis through (1, 0, 0) parallel to the line; the point's circle crosses the line: a rotation of about
    # 6.2165e-8 rad brings the point onto the line (distance ~0)
    "circle-crossing-line-parallel-to-axis": (
        ([1.0, 0.0, 0.0], [1.3750669035920504e-69, 6.216527089015008e-08, 0.9999999999999981], [0.0, 0.0, 0.0],
         [0.0, 0.0, 1.0], [1.463751099515076e-69, 6.617458639969246e-08, 1.0644944589178573]),
        None,
    ),
}


@pytest.mark.parametrize("case", ROTATION_REGRESSIONS.values(), ids=ROTATION_REGRESSIONS.keys())
def test_rotation_regression_queries(case):
    query, expected_theta = case
    args = tuple(np.asarray(a, dtype=np.float64) for a in query)
    theta, dist = lk.rotation_toward_line(*args)
    tol, _, _, _ = rotation_tolerance(*args)
    r_ref = ref.rotation_toward_line(*args)
    if expected_theta is not None:
        assert theta == expected_theta
    assert abs(dist - r_ref.distance) <= tol, f"dist {dist!r}, brute force {r_ref.distance!r} (tol {tol:.3e})"
    achieved = distance_after_rotation(theta, *args)
    assert abs(achieved - dist) <= tol, f"rotation by theta={theta!r} gives distance {achieved!r}, returned {dist!r}"


def test_rotation_point_on_axis_exact_examples():
    theta, dist = lk.rotation_toward_line([1, 2, 3], [0, 0, 1], [1, 2, 7], [0, 0, 0], [1, 0, 0])
    assert theta == 0.0
    assert dist == pytest.approx(np.hypot(2.0, 7.0), abs=1e-14)


@examples(100)
@given(vectors(), directions(), vectors(), st.sampled_from([1.0, 2.0, -1.0, -0.5]))
def test_rotation_axis_equal_to_line_gives_zero(axis_point, axis_direction, point, factor):
    theta, dist = lk.rotation_toward_line(axis_point, axis_direction, point, axis_point.copy(), axis_direction * factor)
    assert theta == 0.0
    expected = float(ref.point_line_distance(point, axis_point, axis_direction))
    tol, _, _, _ = rotation_tolerance(axis_point, axis_direction, point, axis_point, axis_direction)
    assert abs(dist - expected) <= tol


def test_rotation_hand_example():
    # z axis through 0, point (1, 0, 0); line x = 0, y = 2 along z... i.e. through (0, 2, 0) along z:
    # the point must swing to (0, 1, 0): theta = +pi/2 (right-hand about +z), distance 1
    # dist(t) = sqrt(5 - 4 sin t) ~ 1 + (t - pi/2)^2: a smooth minimum, so theta is only determined to
    # 2 sqrt(tol / k) = 2e-6 by distance values (see test_rotation_toward_line_matches_brute_force)
    theta, dist = lk.rotation_toward_line([0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 2, 0], [0, 0, 1])
    assert theta == pytest.approx(np.pi / 2, abs=2e-6)
    assert dist == pytest.approx(1.0, abs=1e-14)
    theta, dist = lk.rotation_toward_line([0, 0, 0], [0, 0, -1], [1, 0, 0], [0, 2, 0], [0, 0, 1])
    assert theta == pytest.approx(-np.pi / 2, abs=2e-6)
    # opposite side: line through (-2, 0, 0): half a turn, theta = +pi (interval is (-pi, pi])
    theta, dist = lk.rotation_toward_line([0, 0, 0], [0, 0, 1], [1, 0, 0], [-2, 0, 0], [0, 0, 1])
    assert -np.pi < theta <= np.pi, theta
    assert ref.angle_difference(theta, np.pi) <= 2e-6, theta
    assert dist == pytest.approx(1.0, abs=1e-14)


# --------------------------------------------------------------------------------------------------
# batches
# --------------------------------------------------------------------------------------------------


def random_queries(n, seed):
    """n circle-line queries: mostly random, with every 10th row one of the degenerate kinds."""
    rng = np.random.default_rng(seed)
    center = rng.uniform(-10, 10, (n, 3))
    normal = rng.normal(size=(n, 3)) * rng.uniform(0.1, 10, (n, 1))
    radius = rng.uniform(0, 5, n)
    line_point = rng.uniform(-10, 10, (n, 3))
    line_direction = rng.normal(size=(n, 3))
    kind = np.arange(n) % 10
    radius[kind == 1] = 0.0
    axis = kind == 2  # line = axis
    line_point[axis] = center[axis] + 3.0 * normal[axis]
    line_direction[axis] = -normal[axis]
    through = kind == 3  # line through the centre
    line_point[through] = center[through]
    return center, normal, radius, line_point, line_direction


def test_batch_equals_single_queries_bitwise():
    center, normal, radius, line_point, line_direction = random_queries(1000, seed=1)
    b = lk.circle_line(center, normal, radius, line_point, line_direction)
    n = len(radius)
    assert np.asarray(b.distance).shape == (n,) and np.asarray(b.distance).dtype == np.float64
    assert b.circle_points.shape == (n, 2, 3) and b.line_points.shape == (n, 2, 3)
    assert np.asarray(b.count).shape == (n,) and np.asarray(b.count).dtype.kind in "iu"
    assert np.asarray(b.equidistant).shape == (n,) and np.asarray(b.equidistant).dtype == np.bool_
    for i in range(n):
        s = lk.circle_line(center[i], normal[i], radius[i], line_point[i], line_direction[i])
        k = s.count
        assert b.distance[i] == s.distance or (np.isnan(b.distance[i]) and np.isnan(s.distance)), i
        assert b.count[i] == k and bool(b.equidistant[i]) == s.equidistant, i
        np.testing.assert_array_equal(b.circle_points[i, :k], s.circle_points, err_msg=f"row {i}")
        np.testing.assert_array_equal(b.line_points[i, :k], s.line_points, err_msg=f"row {i}")
        if k == 1:
            np.testing.assert_array_equal(b.circle_points[i, 1], b.circle_points[i, 0], err_msg=f"row {i}")
            np.testing.assert_array_equal(b.line_points[i, 1], b.line_points[i, 0], err_msg=f"row {i}")


def test_batch_broadcasts_single_arguments():
    center, normal, radius, line_point, line_direction = random_queries(50, seed=2)
    n0, ld0, lp0 = normal[0], line_direction[0], line_point[0]
    b = lk.circle_line(center, n0, 1.5, lp0, ld0)
    assert np.asarray(b.distance).shape == (50,) and b.circle_points.shape == (50, 2, 3)
    for i in range(50):
        s = lk.circle_line(center[i], n0, 1.5, lp0, ld0)
        assert b.distance[i] == s.distance and b.count[i] == s.count
        np.testing.assert_array_equal(b.circle_points[i, : s.count], s.circle_points)
    # radius (N,) against a single centre
    b = lk.circle_line(center[0], n0, radius, lp0, ld0)
    assert np.asarray(b.distance).shape == (50,)
    for i in range(50):
        assert b.distance[i] == lk.circle_line(center[0], n0, radius[i], lp0, ld0).distance
    # lists are accepted in a batch too
    b = lk.circle_line(center[:3].tolist(), n0.tolist(), radius[:3].tolist(), lp0.tolist(), ld0.tolist())
    assert np.asarray(b.distance).shape == (3,)


def test_batch_two_leading_dimensions():
    center, normal, radius, line_point, line_direction = random_queries(20, seed=3)
    b = lk.circle_line(center.reshape(4, 5, 3), normal[0], radius.reshape(4, 5), line_point[0], line_direction[0])
    assert np.asarray(b.distance).shape == (4, 5)
    assert b.circle_points.shape == (4, 5, 2, 3) and b.line_points.shape == (4, 5, 2, 3)
    assert np.asarray(b.count).shape == (4, 5) and np.asarray(b.equidistant).shape == (4, 5)
    flat = lk.circle_line(center, normal[0], radius, line_point[0], line_direction[0])
    np.testing.assert_array_equal(np.asarray(b.distance).reshape(20), flat.distance)
    np.testing.assert_array_equal(b.circle_points.reshape(20, 2, 3), flat.circle_points)


def test_batch_incompatible_shapes_raise():
    with pytest.raises(ValueError):
        lk.circle_line(np.zeros((4, 3)), [0, 0, 1], np.ones(5), [1, 0, 0], [0, 1, 0])


def test_rotation_batch_equals_single_queries_bitwise():
    rng = np.random.default_rng(4)
    n = 1000
    axis_point = rng.uniform(-10, 10, (n, 3))
    axis_direction = rng.normal(size=(n, 3))
    point = rng.uniform(-10, 10, (n, 3))
    line_point = rng.uniform(-10, 10, (n, 3))
    line_direction = rng.normal(size=(n, 3))
    point[::10] = axis_point[::10]  # on the axis
    line_point[5::10] = axis_point[5::10]
    line_direction[5::10] = 2.0 * axis_direction[5::10]  # axis == line
    theta, dist = lk.rotation_toward_line(axis_point, axis_direction, point, line_point, line_direction)
    assert np.asarray(theta).shape == (n,) and np.asarray(dist).shape == (n,)
    for i in range(n):
        t, d = lk.rotation_toward_line(axis_point[i], axis_direction[i], point[i], line_point[i], line_direction[i])
        assert theta[i] == t and dist[i] == d, (i, theta[i], t, dist[i], d)
    # broadcasting: one axis and line, many points
    theta, dist = lk.rotation_toward_line(axis_point[0], axis_direction[0], point[:7], line_point[0], line_direction[0])
    assert np.asarray(theta).shape == (7,)
    for i in range(7):
        t, d = lk.rotation_toward_line(axis_point[0], axis_direction[0], point[i], line_point[0], line_direction[0])
        assert theta[i] == t and dist[i] == d


# --------------------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------------------

GOOD = dict(center=[0.0, 0.0, 0.0], normal=[0.0, 0.0, 1.0], radius=1.0, line_point=[2.0, 0.0, 0.0],
            line_direction=[0.0, 1.0, 0.0])
CL_ORDER = ["center", "normal", "radius", "line_point", "line_direction"]

VECTOR_BAD = {
    "nan": [0.0, NAN, 0.0],
    "inf": [INF, 0.0, 1.0],
    "-inf": [0.0, 1.0, -INF],
    "len2": [1.0, 0.0],
    "len4": [1.0, 0.0, 0.0, 0.0],
    "3x4": np.ones((3, 4)),
}
CL_BAD = (
    [(arg, kind, v) for arg in ("center", "line_point", "normal", "line_direction") for kind, v in VECTOR_BAD.items()]
    + [(arg, "zero", [0.0, 0.0, 0.0]) for arg in ("normal", "line_direction")]
    + [("radius", kind, v) for kind, v in {"negative": -1.0, "nan": NAN, "inf": INF, "-inf": -INF,
                                            "tiny-negative": -1e-300}.items()]
)


def arg_error(name):
    return pytest.raises(ValueError, match=re.compile(rf"\b{re.escape(name)}\b"))


def call_circle_line(**overrides):
    kw = {**GOOD, **overrides}
    return lk.circle_line(*[kw[k] for k in CL_ORDER])


@pytest.mark.parametrize("arg,kind,value", CL_BAD, ids=[f"{a}-{k}" for a, k, _ in CL_BAD])
def test_circle_line_bad_argument_names_it(arg, kind, value):
    with arg_error(arg):
        call_circle_line(**{arg: value})


@pytest.mark.parametrize(
    "arg,bad_row",
    [("center", [NAN, 0, 0]), ("normal", [0, 0, 0]), ("line_point", [0, INF, 0]), ("line_direction", [0, 0, 0])],
)
def test_circle_line_batch_with_one_bad_row_names_the_argument(arg, bad_row):
    batch = np.tile(np.asarray(GOOD[arg], dtype=float), (6, 1))
    batch[3] = bad_row
    with arg_error(arg):
        call_circle_line(**{arg: batch})
    radii = np.ones(6)
    radii[4] = -0.5
    with arg_error("radius"):
        call_circle_line(radius=radii)


def test_circle_line_non_numeric_arguments():
    for arg in CL_ORDER:
        with pytest.raises((TypeError, ValueError)):
            call_circle_line(**{arg: "abc"})
    with pytest.raises((TypeError, ValueError)):
        call_circle_line(radius=None)


RT_GOOD = dict(axis_point=[0.0, 0.0, 0.0], axis_direction=[0.0, 0.0, 1.0], point=[1.0, 0.0, 0.0],
               line_point=[0.0, 2.0, 0.0], line_direction=[0.0, 0.0, 1.0])
RT_ORDER = ["axis_point", "axis_direction", "point", "line_point", "line_direction"]
RT_BAD = (
    [(arg, kind, v) for arg in RT_ORDER for kind, v in VECTOR_BAD.items()]
    + [(arg, "zero", [0.0, 0.0, 0.0]) for arg in ("axis_direction", "line_direction")]
)


@pytest.mark.parametrize("arg,kind,value", RT_BAD, ids=[f"{a}-{k}" for a, k, _ in RT_BAD])
def test_rotation_toward_line_bad_argument_names_it(arg, kind, value):
    kw = {**RT_GOOD, arg: value}
    with arg_error(arg):
        lk.rotation_toward_line(*[kw[k] for k in RT_ORDER])


def test_rotation_toward_line_batch_with_one_bad_row_names_the_argument():
    for arg, bad_row in [("axis_direction", [0, 0, 0]), ("point", [NAN, 0, 0]), ("line_direction", [0, 0, 0])]:
        batch = np.tile(np.asarray(RT_GOOD[arg], dtype=float), (5, 1))
        batch[2] = bad_row
        kw = {**RT_GOOD, arg: batch}
        with arg_error(arg):
            lk.rotation_toward_line(*[kw[k] for k in RT_ORDER])


def test_interpreter_survives_bad_input_in_a_fresh_process():
    """Run a battery of bad calls in a child interpreter: each must raise ValueError/TypeError and the
    process must exit normally (no abort, segfault or Rust panic escaping as a non-Exception)."""
    script = textwrap.dedent(
        """
        import numpy as np
        import legkit as lk
        nan, inf = float("nan"), float("inf")
        good = [[0, 0, 0], [0, 0, 1], 1.0, [2, 0, 0], [0, 1, 0]]
        bad = [
            lambda: lk.circle_line([nan, 0, 0], *good[1:]),
            lambda: lk.circle_line(good[0], [0, 0, 0], *good[2:]),
            lambda: lk.circle_line(*good[:2], -1.0, *good[3:]),
            lambda: lk.circle_line(*good[:4], [0, 0, 0]),
            lambda: lk.circle_line([0, 0], *good[1:]),
            lambda: lk.circle_line(np.full((100, 3), nan), *good[1:]),
            lambda: lk.rotation_toward_line([0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 1]),
            lambda: lk.rotation_toward_line([0, 0, 0], [0, 0, 1], [inf, 0, 0], [0, 2, 0], [0, 0, 1]),
            lambda: lk.MassProperties(nan, [0, 0, 0], np.eye(3)),
            lambda: lk.MassProperties(1.0, [0, 0, 0], np.diag([1.0, 1.0, 3.0])),
            lambda: lk.MassProperties(1.0, [0, 0], np.eye(3)),
            lambda: lk.MassProperties.solid_box(1.0, [1, 1, 1]) - lk.MassProperties.point(2.0, [0, 0, 0]),
            lambda: lk.MassProperties.solid_box(1.0, [1, 1, 1]).transformed(np.diag([1.0, 1.0, -1.0]), [0, 0, 0]),
            lambda: lk.MassProperties.from_points([1.0, 2.0], np.zeros((3, 3))),
            lambda: lk.MassProperties("x", [0, 0, 0], np.eye(3)),
        ]
        raised = 0
        for i, call in enumerate(bad):
            try:
                call()
            except (ValueError, TypeError):
                raised += 1
        print("survived", raised)
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, f"child interpreter died (rc {done.returncode}):\n{done.stderr[-2000:]}"
    assert "survived" in done.stdout
    raised = int(done.stdout.split("survived")[1].split()[0])
    assert raised == 15, done.stdout
