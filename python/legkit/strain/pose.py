"""Body pose from three stance toes (Lin, Komsuoglu, Koditschek, ICRA 2003, eq. 2-5), and stance detection.

Frames. The body frame B is RHex's (``legkit.robots.rhex``): x forward, y left, z up. Leg i has a leg frame
at its hip, rotated by the hip angle theta_i about +y; in that frame the leg hangs along -z, and a leg of
length l deflected by d (a further rotation about +y, same sign as theta) has its toe at
(-l sin d, 0, -l cos d). ``hip_to_body`` is the paper's h_i^theta: the 4x4 transform leg frame -> body.

Tripod pose [Lin 2003, Sect. 5.1, eq. 2-5]. Given the three stance toes s_0, s_1, s_2 in the body frame:
  * support frame Q (eq. 2): origin s_0; e_1, e_2 the unit vectors from s_0 to s_1 and s_2; q_1 = e_1,
    q_2 = e_2 minus its q_1 component, normalised, q_3 = q_1 x q_2. Q = [q_1 q_2 q_3] (columns are the support
    axes in body coordinates). q_3 follows the toe order: it points up, away from the ground toward the body,
    when the toes run counter-clockwise seen from above, and into the ground otherwise (RHex's tripod A in
    ``walking.TRIPOD_LEGS`` order, left rear - left front - right middle, runs clockwise).
    ``orientation="body_side"`` (legkit's variant) turns Q half a turn about q_1 when q_3 points away from
    the body origin, so that q_3 is always the ground normal toward the body and u_z is the body height;
    with counter-clockwise toes the two are the same;
  * A = Q^T maps body to support coordinates, r(b) = A b - A s_0 (eq. 3);
  * u = -A s_0 (eq. 4): the body frame's origin in the support frame (the paper calls it the position of
    the COM: the two coincide when the body frame sits at the COM);
  * the paper's angles (eq. 5), from b_1 = A [1 0 0]^T and b_2 = A [0 1 0]^T (the body x and y axes in
    support coordinates) and pi_i the i-th entry:
        alpha = atan(pi_3 b_1 / sqrt(pi_1 b_1^2 + pi_2 b_1^2))     "pitch"
        gamma = atan(pi_3 b_2 / sqrt(pi_1 b_2^2 + pi_2 b_2^2))     "roll"
        beta  = atan(pi_1 b_1 / sqrt(pi_2 b_1^2 + pi_3 b_1^2))     "yaw"
    In legkit's body frame (x forward, y left, z up) alpha is the elevation of the forward axis above the
    support plane (nose up positive, exactly minus the Z-Y-X pitch below), gamma the elevation of the left
    axis (left side up positive; sin gamma = cos(pitch) sin(roll)), and beta = asin(pi_1 b_1) the complement
    of the angle between the forward axis and q_1: pi/2 when the body faces along the line from toe 0 to
    toe 1, smaller for any yaw either way, so it does not tell left from right. The paper calls b_1 the
    body's *lateral* axis; in such a frame alpha would be the elevation of the lateral axis, a roll, although
    the paper names it pitch. legkit applies eq. 5 literally to its own body axes, where the names fit;
  * legkit's Z-Y-X angles of A = Rz(yaw) Ry(pitch) Rx(roll), kept beside the paper's (they tell the sign of
    the yaw and compose back into A with ``euler_zyx``):
        roll = atan2(a_32, a_33),  pitch = atan2(-a_31, sqrt(a_32^2 + a_33^2)),  yaw = atan2(a_21, a_11).
    On flat ground with ``orientation="body_side"`` the support frame differs from the world frame by a yaw
    and a translation only, so roll, pitch and height equal their world values; yaw is relative to q_1.

Coplanarity. ``coplanarity(toes)`` is the paper's measure (Sect. 5.2) rho = sum_i s_i^T s_i - s_bar^T s_bar,
s_bar the mean toe, as printed (m^2). As printed it is not a coplanarity measure: it is not zero for coplanar
toes and depends on where the body frame's origin is (a translation of all toes by t changes it by
(k - 1)(2 s_bar . t + |t|^2); the centred scatter sum_i |s_i - s_bar|^2 = sum_i s_i^T s_i - k s_bar^T s_bar
would not). ``coplanarity(toes, definition="determinant")`` is legkit's algebraic measure: the largest
|det[s_b - s_a, s_c - s_a, s_e - s_a]| over four-toe subsets (six times a tetrahedron's volume, m^3), zero iff
every four toes are coplanar. ``plane_residual`` is the geometric one legkit recommends: the sum of squared
distances of the toes to their least-squares plane (m^2), zero iff they are coplanar, invariant to rigid
motions. ``legkit strain`` compares the three as stance detectors (docs/strain.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Literal

import numpy as np
import numpy.typing as npt

from legkit._validation import float_array, is_integer
from legkit.robots.rhex import HIP_POSITIONS

# Relative size below which three toes are treated as collinear: |cross| <= tol * (longest edge)^2.
COLLINEAR_TOLERANCE = 1e-9


def _leg_indices(leg_index: npt.ArrayLike) -> np.ndarray:
    try:
        index = np.asarray(leg_index)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"leg_index must be an integer array: {exc}") from exc
    if not np.issubdtype(index.dtype, np.integer):
        raise TypeError(f"leg_index must be integers, got dtype {index.dtype}")
    if np.any((index < 0) | (index > 5)):
        raise ValueError("leg_index must be between 0 and 5 (RHex has six legs)")
    return index


def rotation_y(angle: np.ndarray) -> np.ndarray:
    """Rotation matrices about +y: (..., 3, 3) for angle (...,) in radians."""
    c, s = np.cos(angle), np.sin(angle)
    zero, one = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, zero, s], -1), np.stack([zero, one, zero], -1), np.stack([-s, zero, c], -1)], -2)


def hip_to_body(theta: npt.ArrayLike, leg_index: npt.ArrayLike) -> np.ndarray:
    """The paper's h_i^theta: 4x4 transforms from leg i's frame to the body frame, x_body = R x_leg + t.

    Args:
        theta: hip angles (...,) in radians, rotation about +y from straight down (positive swings the toe back).
        leg_index: leg numbers 0..5 (``legkit.robots.rhex.LEG_NAMES`` order), broadcast against theta.

    Returns:
        (..., 4, 4) with R = Ry(theta) and t the hip position.
    """
    angle = float_array(theta, "theta")
    index = _leg_indices(leg_index)
    angle, index = np.broadcast_arrays(angle, index)
    transform = np.zeros(angle.shape + (4, 4))
    transform[..., :3, :3] = rotation_y(angle)
    transform[..., :3, 3] = HIP_POSITIONS[index]
    transform[..., 3, 3] = 1.0
    return transform


def toe_in_leg(length: npt.ArrayLike, deflection: npt.ArrayLike) -> np.ndarray:
    """Toe position (..., 3) in the leg frame for leg length (m) and deflection (rad): (-l sin d, 0, -l cos d)."""
    ell = float_array(length, "length")
    d = float_array(deflection, "deflection")
    ell, d = np.broadcast_arrays(ell, d)
    return np.stack([-ell * np.sin(d), np.zeros_like(ell), -ell * np.cos(d)], -1)


def toe_in_body(theta: npt.ArrayLike, length: npt.ArrayLike, deflection: npt.ArrayLike, leg_index: npt.ArrayLike) -> np.ndarray:
    """Toe position (..., 3) in the body frame: h_i^theta applied to ``toe_in_leg(length, deflection)``.

    Equivalent to hip_i + Ry(theta + d) (0, 0, -l); all arguments broadcast together.
    """
    angle = float_array(theta, "theta")
    d = float_array(deflection, "deflection")
    ell = float_array(length, "length")
    index = _leg_indices(leg_index)
    total = angle + d
    hip = HIP_POSITIONS[index]
    x = hip[..., 0] - ell * np.sin(total)
    z = hip[..., 2] - ell * np.cos(total)
    x, y, z = np.broadcast_arrays(x, hip[..., 1], z)
    return np.stack([x, y, z], -1)


@dataclass(frozen=True)
class TripodPose:
    """Body pose in the support frame of a tripod (all arrays carry the batch shape of the toes).

    Attributes:
        position: u = -A s_0 (eq. 4), (..., 3) metres; position[..., 2] is the body height above the toe
            plane when q_3 points toward the body.
        rotation: A (eq. 3), (..., 3, 3), body -> support coordinates.
        roll, pitch, yaw: (...,) radians, Z-Y-X angles of A (legkit's; module docstring).
        support_frame: Q = A^T (eq. 2), (..., 3, 3), columns are the support axes in body coordinates.
        origin: s_0, (..., 3), the support frame origin in body coordinates.
        alpha, gamma, beta: (...,) radians, the paper's eq. 5 (its "pitch", "roll", "yaw"): the elevations
            of the body's forward and left axes above the support plane, and the complement of the angle
            between the forward axis and q_1 (module docstring).
    """

    position: np.ndarray
    rotation: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    support_frame: np.ndarray
    origin: np.ndarray
    alpha: np.ndarray
    gamma: np.ndarray
    beta: np.ndarray

    @property
    def height(self) -> np.ndarray:
        """Body height above the toe plane, (...,) metres."""
        return self.position[..., 2]


def _check_toes(toes: npt.ArrayLike, minimum: int, exact: bool = False) -> np.ndarray:
    points = float_array(toes, "toes")
    count_ok = points.ndim >= 2 and (points.shape[-2] == minimum if exact else points.shape[-2] >= minimum)
    if not count_ok or points.shape[-1] != 3:
        wanted = f"{minimum}" if exact else f"at least {minimum}"
        raise ValueError(f"toes must have shape (..., {wanted}, 3), got {points.shape}")
    return points


def tripod_pose(toes: npt.ArrayLike, orientation: Literal["paper", "body_side"] = "paper") -> TripodPose:
    """Body pose from three stance toes [Lin 2003, eq. 2-5], vectorised over any batch shape.

    Args:
        toes: (..., 3, 3) toe positions in the body frame (metres), one row per toe, s_0 first; the order of
            s_0 and s_1 fixes the support x axis, the order of all three the side q_3 points to.
        orientation: "paper" (default): q_3 = q_1 x q_2 as eq. 2 builds it; "body_side": Q turned half a
            turn about q_1 where that q_3 points away from the body origin (module docstring).

    Raises:
        ValueError: wrong shape, NaN/inf, an unknown orientation, or a tripod whose toes are coincident or
            collinear (names the first offending batch index).
    """
    if orientation not in ("paper", "body_side"):
        raise ValueError(f"orientation must be 'paper' or 'body_side', got {orientation!r}")
    points = _check_toes(toes, 3, exact=True)
    # Component arithmetic on (...,) arrays: about three times faster than np.cross/einsum on big batches.
    x0, y0, z0 = points[..., 0, 0], points[..., 0, 1], points[..., 0, 2]
    ax, ay, az = points[..., 1, 0] - x0, points[..., 1, 1] - y0, points[..., 1, 2] - z0
    bx, by, bz = points[..., 2, 0] - x0, points[..., 2, 1] - y0, points[..., 2, 2] - z0
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    normal_norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    a_squared = ax * ax + ay * ay + az * az
    b_squared = bx * bx + by * by + bz * bz
    c_squared = (bx - ax) ** 2 + (by - ay) ** 2 + (bz - az) ** 2
    longest_squared = np.maximum(np.maximum(a_squared, b_squared), c_squared)
    degenerate = normal_norm <= COLLINEAR_TOLERANCE * longest_squared
    if np.any(degenerate):
        where = np.argwhere(np.atleast_1d(degenerate))[0]
        label = f" at batch index {tuple(int(i) for i in where)}" if points.ndim > 2 else ""
        raise ValueError(f"toes{label} are coincident or collinear: three stance toes must span a plane")
    # q_3 = q_1 x q_2 is the unit normal e_1 x e_2 (eq. 2); "body_side" flips it toward the body origin
    # (-s0 . n > 0), and q_2 = q_3 x q_1 flips with it.
    flip = (nx * x0 + ny * y0 + nz * z0 > 0.0) & (orientation == "body_side")
    scale = np.where(flip, -1.0, 1.0) / normal_norm
    zx, zy, zz = nx * scale, ny * scale, nz * scale
    inverse_a = 1.0 / np.sqrt(a_squared)
    xx, xy, xz = ax * inverse_a, ay * inverse_a, az * inverse_a
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    rotation = np.stack([xx, xy, xz, yx, yy, yz, zx, zy, zz], -1).reshape(points.shape[:-2] + (3, 3))
    position = -np.stack(
        [xx * x0 + xy * y0 + xz * z0, yx * x0 + yy * y0 + yz * z0, zx * x0 + zy * y0 + zz * z0], -1
    )
    # Rows of A are the support axes (A = Q^T), so a_3j = q_z[j], a_21 = q_y[0], a_11 = q_x[0].
    roll = np.arctan2(zy, zz)
    pitch = np.arctan2(-zx, np.hypot(zy, zz))
    yaw = np.arctan2(yx, xx)
    # Eq. 5 on b_1 = A e_x = (xx, yx, zx) and b_2 = A e_y = (xy, yy, zy); arctan2 with its non-negative
    # square root second is the paper's arctan of the ratio, defined also where the root is zero.
    alpha = np.arctan2(zx, np.hypot(xx, yx))
    gamma = np.arctan2(zy, np.hypot(xy, yy))
    beta = np.arctan2(xx, np.hypot(yx, zx))
    s0 = points[..., 0, :]
    return TripodPose(position, rotation, roll, pitch, yaw, np.swapaxes(rotation, -1, -2), s0, alpha, gamma, beta)


def euler_zyx(roll: npt.ArrayLike, pitch: npt.ArrayLike, yaw: npt.ArrayLike) -> np.ndarray:
    """Rotation Rz(yaw) Ry(pitch) Rx(roll), (..., 3, 3), the convention of ``tripod_pose``'s angles."""
    r, p, y = (float_array(v, name) for name, v in (("roll", roll), ("pitch", pitch), ("yaw", yaw)))
    r, p, y = np.broadcast_arrays(r, p, y)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1),
        ],
        -2,
    )


def coplanarity(toes: npt.ArrayLike, definition: Literal["paper", "determinant"] = "paper") -> np.ndarray:
    """A coplanarity measure rho of k toes (...,) (module docstring; small when the toes share a plane).

    definition="paper" (default): rho = sum_i s_i^T s_i - s_bar^T s_bar, s_bar = (1/k) sum_i s_i, as printed in
    [Lin 2003, Sect. 5.2] (k = 6 there; any k >= 3 here), m^2.
    definition="determinant": max over four-toe subsets {a, b, c, e} of |det[s_b - s_a, s_c - s_a,
    s_e - s_a]| (k >= 4), m^3; zero iff every four toes are coplanar.
    """
    if definition not in ("paper", "determinant"):
        raise ValueError(f"definition must be 'paper' or 'determinant', got {definition!r}")
    if definition == "paper":
        points = _check_toes(toes, 3)
        mean = points.mean(axis=-2)
        return np.sum(points * points, axis=(-2, -1)) - np.sum(mean * mean, axis=-1)
    points = _check_toes(toes, 4)
    best = np.zeros(points.shape[:-2])
    for a, b, c, e in combinations(range(points.shape[-2]), 4):
        base = points[..., a, :]
        volume = np.abs(
            np.linalg.det(np.stack([points[..., b, :] - base, points[..., c, :] - base, points[..., e, :] - base], -2))
        )
        best = np.maximum(best, volume)
    return best


def plane_residual(toes: npt.ArrayLike) -> np.ndarray:
    """Sum of squared distances (m^2) of k >= 3 toes to their least-squares plane, (...,).

    The smallest eigenvalue of the scatter matrix of the centred toes; zero iff the toes are coplanar.
    """
    points = _check_toes(toes, 3)
    centred = points - points.mean(axis=-2, keepdims=True)
    scatter = np.einsum("...ki,...kj->...ij", centred, centred)
    return np.maximum(np.linalg.eigvalsh(scatter)[..., 0], 0.0)


def stance_intervals(rho: npt.ArrayLike, threshold: float, min_length: int = 1) -> np.ndarray:
    """Maximal runs of samples with rho <= threshold, as an (n, 2) int array of [start, stop) indices.

    Args:
        rho: (T,) a contact signal that is small during support (coplanarity, plane residual, or any other).
        threshold: samples with rho <= threshold count as support.
        min_length: runs shorter than this many samples are dropped (debouncing).
    """
    signal = float_array(rho, "rho")
    if signal.ndim != 1:
        raise ValueError(f"rho must be one-dimensional, got shape {signal.shape}")
    if not np.isfinite(threshold):
        raise ValueError(f"threshold must be finite, got {threshold}")
    if not is_integer(min_length) or min_length < 1:
        raise ValueError(f"min_length must be a positive integer, got {min_length!r}")
    inside = np.concatenate([[False], signal <= threshold, [False]]).astype(np.int8)
    change = np.diff(inside)
    starts = np.flatnonzero(change == 1)
    stops = np.flatnonzero(change == -1)
    keep = stops - starts >= min_length
    return np.column_stack([starts[keep], stops[keep]]).astype(np.int64).reshape(-1, 2)
