"""Independent brute-force references for the legkit tests (plain numpy, never imports legkit).

Everything here is deliberately naive: point-mass sums written straight from the definitions, a
fine-grid discretisation of a solid box, and circle/line distances found by dense angle sampling
(4096 samples, then a 2048-sample zoom around each candidate) followed by golden-section refinement. None of it
shares code or formulas with the implementation under test beyond the mathematical definitions themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EPS = float(np.finfo(np.float64).eps)
INV_PHI = (np.sqrt(5.0) - 1.0) / 2.0  # 1/golden ratio, the golden-section shrink factor


# --------------------------------------------------------------------------------------------------
# Small linear-algebra helpers
# --------------------------------------------------------------------------------------------------


def norm(v, axis=-1) -> np.ndarray:
    """Euclidean norm that neither underflows nor overflows (scaled by the largest component)."""
    v = np.asarray(v, dtype=np.float64)
    m = np.max(np.abs(v), axis=axis, keepdims=True)
    safe = np.where(m > 0, m, 1.0)
    return np.squeeze(m, axis=axis) * np.sqrt(np.sum((v / safe) ** 2, axis=axis))


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / norm(v)


def quaternion_to_rotation(q) -> np.ndarray:
    """Proper rotation matrix of the (not necessarily unit) quaternion q = (w, x, y, z)."""
    w, x, y, z = unit(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def skew(a) -> np.ndarray:
    ax, ay, az = a
    return np.array([[0.0, -az, ay], [az, 0.0, -ax], [-ay, ax, 0.0]])


def rodrigues(axis, theta: float) -> np.ndarray:
    """Rotation by `theta` (right-hand rule) about the direction `axis`."""
    k = skew(unit(axis))
    return np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)


def homogeneous(rotation, translation) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rotation
    t[:3, 3] = translation
    return t


def perpendicular_basis(normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, n) orthonormal and right-handed, with n = normal / |normal|."""
    n = unit(normal)
    a = np.zeros(3)
    a[np.argmin(np.abs(n))] = 1.0
    u = unit(a - np.dot(a, n) * n)
    v = np.cross(n, u)
    return u, v, n


def angle_difference(a: float, b: float) -> float:
    """|a - b| modulo 2*pi, in [0, pi]."""
    d = np.remainder(a - b, 2.0 * np.pi)
    return float(min(d, 2.0 * np.pi - d))


# --------------------------------------------------------------------------------------------------
# Mass properties of point clouds, straight from the definitions
# --------------------------------------------------------------------------------------------------


def inertia_of_points_about(masses, positions, point) -> np.ndarray:
    """sum_i m_i (|r_i - p|^2 E - (r_i - p)(r_i - p)^T): the inertia tensor of point masses about p."""
    m = np.asarray(masses, dtype=np.float64).reshape(-1)
    d = np.asarray(positions, dtype=np.float64).reshape(-1, 3) - np.asarray(point, dtype=np.float64)
    inertia = np.zeros((3, 3))
    for mi, di in zip(m, d):
        inertia += mi * (np.dot(di, di) * np.eye(3) - np.outer(di, di))
    return inertia


def inertia_of_points_about_vectorised(masses, positions, point) -> np.ndarray:
    """Same as inertia_of_points_about, vectorised for large clouds (the box grid)."""
    m = np.asarray(masses, dtype=np.float64).reshape(-1)
    d = np.asarray(positions, dtype=np.float64).reshape(-1, 3) - np.asarray(point, dtype=np.float64)
    second = (m[:, None] * d).T @ d  # sum m d d^T (BLAS: blocked accumulation, small rounding for big n)
    return np.trace(second) * np.eye(3) - second


def point_cloud_mass_properties(masses, positions, vectorised: bool = False):
    """(total mass, centre of mass, inertia about the centre of mass) of a set of point masses."""
    m = np.asarray(masses, dtype=np.float64).reshape(-1)
    r = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    total = float(np.sum(m))
    com = (m @ r) / total
    about = inertia_of_points_about_vectorised if vectorised else inertia_of_points_about
    return total, com, about(m, r, com)


def box_grid(mass: float, size, center, rotation, n: int):
    """A solid box discretised as n^3 equal point masses at the midpoints of an n x n x n grid of cells."""
    size = np.asarray(size, dtype=np.float64)
    axes = [((np.arange(n) + 0.5) / n - 0.5) * s for s in size]
    x, y, z = np.meshgrid(*axes, indexing="ij")
    local = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    positions = local @ np.asarray(rotation, dtype=np.float64).T + np.asarray(center, dtype=np.float64)
    masses = np.full(n**3, mass / n**3)
    return masses, positions


def box_grid_bias(mass: float, size, n: int) -> np.ndarray:
    """Exact (solid box inertia) - (midpoint-grid inertia), in the box frame.

    Along one axis the n midpoints x_k = h (k + 1/2 - n/2), h = s/n, have
    mean(x_k^2) = h^2 (n^2 - 1) / 12 = s^2/12 - h^2/12, whereas the continuum has s^2/12.
    So the grid under-estimates each second moment by m h^2 / 12 exactly, and
    I_xx = m (<y^2> + <z^2>) is low by m (h_y^2 + h_z^2) / 12 (similarly for yy, zz); products of
    inertia vanish for both by symmetry. The midpoint rule is therefore O(h^2) with a known constant.
    """
    h2 = (np.asarray(size, dtype=np.float64) / n) ** 2
    return mass / 12.0 * np.diag([h2[1] + h2[2], h2[0] + h2[2], h2[0] + h2[1]])


# --------------------------------------------------------------------------------------------------
# 1-D periodic minimisation: dense sampling + golden-section refinement
# --------------------------------------------------------------------------------------------------


def _golden_section(f, lo: np.ndarray, hi: np.ndarray, tol: float):
    """Vectorised golden-section search of f on the brackets [lo_i, hi_i]; returns (x_i, f(x_i))."""
    a = lo.astype(np.float64).copy()
    b = hi.astype(np.float64).copy()
    c = b - INV_PHI * (b - a)
    d = a + INV_PHI * (b - a)
    fc = f(c)
    fd = f(d)
    width = float(np.max(b - a))
    iterations = int(np.ceil(np.log(tol / width) / np.log(INV_PHI))) + 2 if width > tol else 0
    for _ in range(iterations):
        left = fc <= fd  # the minimum is in [a, d]
        a, b = np.where(left, a, c), np.where(left, d, b)
        new_c = b - INV_PHI * (b - a)
        new_d = a + INV_PHI * (b - a)
        x_new = np.where(left, new_c, new_d)
        f_new = f(x_new)
        c, d = np.where(left, new_c, d), np.where(left, c, new_d)
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
    x = np.where(fc <= fd, c, d)
    return x, np.minimum(fc, fd)


@dataclass
class PeriodicMinimum:
    value: float  # global minimum of f
    angles: np.ndarray  # refined local minimisers, best first, mutually separated by > 1e-6 rad
    values: np.ndarray  # f at those minimisers
    sample_spread: float  # max - min of f over the dense samples


def _sampled_local_minima(values: np.ndarray, cyclic: bool) -> np.ndarray:
    """Boolean mask of samples that are <= both neighbours (end samples compare with their one neighbour
    when not cyclic)."""
    if cyclic:
        return (values <= np.roll(values, 1, axis=-1)) & (values <= np.roll(values, -1, axis=-1))
    left = np.concatenate([np.full(values.shape[:-1] + (1,), np.inf), values[..., :-1]], axis=-1)
    right = np.concatenate([values[..., 1:], np.full(values.shape[:-1] + (1,), np.inf)], axis=-1)
    return (values <= left) & (values <= right)


def minimise_periodic(
    f,
    start: float = 0.0,
    samples: int = 4096,
    candidates: int = 16,
    zoom_samples: int = 2048,
    zoom_candidates: int = 32,
    tol: float = 1e-14,
):
    """Global minimum of a 2*pi-periodic f (vectorised over angles of any shape) by brute force.

    1. f is evaluated on `samples` equally spaced angles (step h) starting at `start`;
    2. around each of the `candidates` lowest sampled local minima, f is sampled again on
       [theta_i - 2h, theta_i + 2h] with `zoom_samples` points (step ~2e-6 rad), which separates two
       minima closer together than h (this happens for nearly tangent lines, whose distance function has
       two wells ~sqrt(gap) apart);
    3. each of the `zoom_candidates` lowest zoomed local minima is refined by golden-section search on
       [theta_j - s, theta_j + s] (s the zoomed step) down to a bracket of `tol` rad.
    Sampled values are kept as candidates, so the result is never worse than the dense sampling.
    """
    step = 2.0 * np.pi / samples
    theta = start + step * np.arange(samples)
    values = f(theta)
    idx = np.nonzero(_sampled_local_minima(values, cyclic=True))[0]
    idx = idx[np.argsort(values[idx], kind="stable")][:candidates]
    if int(np.argmin(values)) not in idx:
        idx = np.append(idx, int(np.argmin(values)))
    offsets = np.linspace(-2.0 * step, 2.0 * step, zoom_samples)
    sub_step = offsets[1] - offsets[0]
    sub_theta = theta[idx][:, None] + offsets[None, :]
    sub_values = f(sub_theta)
    mask = _sampled_local_minima(sub_values, cyclic=False)
    cand_theta, cand_values = sub_theta[mask], sub_values[mask]
    order = np.argsort(cand_values, kind="stable")[:zoom_candidates]
    cand_theta, cand_values = cand_theta[order], cand_values[order]
    x, fx = _golden_section(f, cand_theta - sub_step, cand_theta + sub_step, tol)
    better = fx <= cand_values
    x = np.where(better, x, cand_theta)
    fx = np.where(better, fx, cand_values)
    order = np.argsort(fx, kind="stable")
    kept_x, kept_f = [], []
    for i in order:
        if all(angle_difference(x[i], y) > 1e-6 for y in kept_x):
            kept_x.append(float(x[i]))
            kept_f.append(float(fx[i]))
    return PeriodicMinimum(
        value=kept_f[0],
        angles=np.array(kept_x),
        values=np.array(kept_f),
        sample_spread=float(np.max(values) - np.min(values)),
    )


# --------------------------------------------------------------------------------------------------
# Circle-line distance and rotation toward a line
# --------------------------------------------------------------------------------------------------


def point_line_distance(points, line_point, line_direction) -> np.ndarray:
    """Distance of each point (..., 3) to the infinite line through line_point along line_direction."""
    d = unit(line_direction)
    w = np.asarray(points, dtype=np.float64) - np.asarray(line_point, dtype=np.float64)
    return norm(np.cross(w, d), axis=-1)


def foot_on_line(point, line_point, line_direction) -> np.ndarray:
    d = unit(line_direction)
    p = np.asarray(point, dtype=np.float64)
    lp = np.asarray(line_point, dtype=np.float64)
    return lp + np.dot(p - lp, d) * d


@dataclass
class CircleLineReference:
    distance: float
    angles: np.ndarray  # local minimisers in the circle's (u, v) parametrisation, best first
    values: np.ndarray
    circle_points: np.ndarray  # (k, 3) at those angles
    sample_spread: float
    basis: tuple


def circle_line(center, normal, radius, line_point, line_direction, samples: int = 4096) -> CircleLineReference:
    """Brute-force minimum distance between a circle and an infinite line.

    The circle is X(t) = C + r (cos t u + sin t v). To keep rounding small, the line is re-anchored at
    the foot of the perpendicular from C and everything is expressed relative to C, so every evaluated
    quantity has magnitude <= radius + dist(C, line) and the distance is accurate to a few eps of that.
    """
    c = np.asarray(center, dtype=np.float64)
    r = float(radius)
    u, v, n = perpendicular_basis(normal)
    d = unit(line_direction)
    q = foot_on_line(c, line_point, d) - c  # line point relative to C, perpendicular to d

    def f(t):
        t = np.asarray(t, dtype=np.float64)
        x = r * (np.cos(t)[..., None] * u + np.sin(t)[..., None] * v)
        return norm(np.cross(x - q, d), axis=-1)

    m = minimise_periodic(f, samples=samples)
    points = c + r * (np.cos(m.angles)[:, None] * u + np.sin(m.angles)[:, None] * v)
    return CircleLineReference(m.value, m.angles, m.values, points, m.sample_spread, (u, v, n))


@dataclass
class RotationReference:
    distance: float
    angles: np.ndarray  # local minimisers in (-pi, pi], best first
    values: np.ndarray
    rotated_points: np.ndarray  # (k, 3)
    radius: float  # distance of the point from the axis
    sample_spread: float


def rotate_about_axis(point, axis_point, axis_direction, theta) -> np.ndarray:
    """The point rotated by theta (right-hand rule about axis_direction) about the axis line (Rodrigues)."""
    a = np.asarray(axis_point, dtype=np.float64)
    return a + rodrigues(axis_direction, theta) @ (np.asarray(point, dtype=np.float64) - a)


def wrap_angle(theta):
    """Map angles to (-pi, pi]."""
    t = np.remainder(np.asarray(theta, dtype=np.float64) + np.pi, 2.0 * np.pi) - np.pi
    return np.where(t <= -np.pi, t + 2.0 * np.pi, t)


def rotation_toward_line(axis_point, axis_direction, point, line_point, line_direction, samples: int = 4096):
    """Brute force: rotate `point` about the axis by densely sampled angles (Rodrigues' formula written out
    as p(t) = c + p_perp cos t + (a x p_perp) sin t), refine by golden section, and measure its distance
    to the line (re-anchored at the foot of the perpendicular from c, as in circle_line)."""
    a = unit(axis_direction)
    ap = np.asarray(axis_point, dtype=np.float64)
    p = np.asarray(point, dtype=np.float64) - ap
    along = np.dot(a, p)
    c = ap + along * a  # centre of the circle the point sweeps
    p_perp = p - along * a
    a_cross = np.cross(a, p_perp)
    d = unit(line_direction)
    q = foot_on_line(c, line_point, d) - c

    def f(t):
        t = np.asarray(t, dtype=np.float64)
        x = np.cos(t)[..., None] * p_perp + np.sin(t)[..., None] * a_cross
        return norm(np.cross(x - q, d), axis=-1)

    m = minimise_periodic(f, start=-np.pi, samples=samples)
    angles = wrap_angle(m.angles)
    rotated = c + np.cos(angles)[:, None] * p_perp + np.sin(angles)[:, None] * a_cross
    return RotationReference(m.value, angles, m.values, rotated, float(norm(p_perp)), m.sample_spread)


def circle_line_scale(center, radius, line_point, line_direction) -> float:
    """radius + distance from the centre to the line: the natural length scale of a circle-line query."""
    return float(radius) + float(point_line_distance(center, line_point, line_direction))


def circle_line_tolerance(center, radius, line_point, line_direction, factor: float = 1e-12) -> float:
    """Absolute tolerance for distances/points of a circle-line query.

    factor * scale covers the arithmetic of any sound algorithm (a few hundred eps would already do;
    1e-12 leaves margin for near-degenerate configurations and is still ~1e4 times tighter than a single
    float32 step or a wrong formula). 8 * eps * (coordinate magnitude) covers the inputs themselves: a
    coordinate of size X is only known to eps*X/2, so no algorithm can resolve the geometry better than
    that when the scene sits far from the origin.
    """
    scale = circle_line_scale(center, radius, line_point, line_direction)
    magnitude = max(norm(center), norm(line_point)) + float(radius)
    return factor * scale + 8.0 * EPS * magnitude


# --------------------------------------------------------------------------------------------------
# Derivatives of an NLP
# --------------------------------------------------------------------------------------------------


def central_jacobian(function, x, step: float = 1e-6) -> np.ndarray:
    """d function / dx by plain central differences, one column at a time, step relative to max(1, |x_j|)."""
    x = np.asarray(x, dtype=np.float64)
    columns = []
    for j in range(len(x)):
        h = step * max(1.0, abs(x[j]))
        plus, minus = x.copy(), x.copy()
        plus[j] += h
        minus[j] -= h
        columns.append((np.asarray(function(plus)) - np.asarray(function(minus))) / (2.0 * h))
    return np.stack(columns, axis=-1)
