"""Batched mass-property algebra on packed moments.

An agent's estimates are stored as *moments about the agent's frame origin*, packed into 13 floats:
``[m, h (3), P (9)]`` with ``h = sum m_i r_i = m c`` and ``P = sum m_i r_i r_i^T`` (row-major). In this form
composition is plain addition (exact and associative up to rounding, no division), an empty estimate is all
zeros, and a rigid transform x' = R x + t is linear:

    h' = R h + m t,     P' = R P R^T + (R h) t^T + t (R h)^T + m t t^T.

This is the parallel-axis theorem in disguise: the inertia about the COM is ``I = tr(P_c) E - P_c`` with
``P_c = P - h h^T / m``. (The seed paper's shorthand ``(m1 I1 + m2 I2) / (m1 + m2)`` for combined inertia is
not physically correct; the moment form composes inertia exactly.) Every function takes leading batch
dimensions.
"""

from __future__ import annotations

import math

import numpy as np

WIDTH = 13


def pack(mass: np.ndarray, com: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """Packed moments (..., 13) from mass (...,) kg, COM (..., 3) m and inertia about the COM (..., 3, 3) kg m^2."""
    mass = np.asarray(mass, dtype=float)
    com = np.asarray(com, dtype=float)
    inertia = np.asarray(inertia, dtype=float)
    trace = np.trace(inertia, axis1=-2, axis2=-1)
    second_about_com = 0.5 * trace[..., None, None] * np.eye(3) - inertia
    second = second_about_com + mass[..., None, None] * com[..., :, None] * com[..., None, :]
    shape = np.broadcast_shapes(mass.shape, com.shape[:-1], inertia.shape[:-2])
    packed = np.empty(shape + (WIDTH,))
    packed[..., 0] = mass
    packed[..., 1:4] = mass[..., None] * com
    packed[..., 4:] = second.reshape(shape + (9,))
    return packed


def unpack(moments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mass (...,), COM (..., 3), inertia about the COM (..., 3, 3)) from packed moments.

    Where the mass is zero (an empty estimate) the COM and inertia are returned as zeros."""
    moments = np.asarray(moments, dtype=float)
    mass = moments[..., 0]
    first = moments[..., 1:4]
    second = moments[..., 4:].reshape(moments.shape[:-1] + (3, 3))
    nonzero = mass > 0
    safe = np.where(nonzero, mass, 1.0)
    com = np.where(nonzero[..., None], first / safe[..., None], 0.0)
    second_about_com = second - mass[..., None, None] * com[..., :, None] * com[..., None, :]
    trace = np.trace(second_about_com, axis1=-2, axis2=-1)
    inertia = trace[..., None, None] * np.eye(3) - second_about_com
    inertia = 0.5 * (inertia + np.swapaxes(inertia, -1, -2))
    return mass, com, np.where(nonzero[..., None, None], inertia, 0.0)


def transform(rotation: np.ndarray, translation: np.ndarray, moments: np.ndarray) -> np.ndarray:
    """Moments expressed in the frame where the moments' frame has pose (rotation (..., 3, 3), translation (..., 3)).

    Computed on component-major copies, one array operation per term for all components at once, in the
    order ``h' = (R_i0 h_0 + R_i1 h_1) + R_i2 h_2 + m t_i`` and ``P'_ij = ((RP)_i0 R_j0 + (RP)_i1 R_j1 +
    (RP)_i2 R_j2) + g_i t_j + t_i g_j + m t_i t_j`` (g = R h), left to right. The second moment is assumed
    symmetric (it always is here); the result is exactly symmetric (the lower triangle copies the upper)."""
    shape = np.broadcast_shapes(moments.shape[:-1], rotation.shape[:-2], translation.shape[:-1])
    count = math.prod(shape)
    r = _component_major(rotation, shape, (3, 3)).reshape(3, 3, count)
    t = _component_major(translation, shape, (3,))
    x = _component_major(moments, shape, (WIDTH,))
    mass, h, second = x[0], x[1:4], x[4:].reshape(3, 3, count)
    g = r[:, 0] * h[0] + r[:, 1] * h[1] + r[:, 2] * h[2]
    rp = r[:, 0, None] * second[0] + r[:, 1, None] * second[1] + r[:, 2, None] * second[2]
    mt = mass * t
    out = np.empty((WIDTH, count))
    out[0] = mass
    np.add(g, mt, out=out[1:4])
    full = out[4:].reshape(3, 3, count)
    np.multiply(rp[:, None, 0], r[None, :, 0], out=full)
    full += rp[:, None, 1] * r[None, :, 1]
    full += rp[:, None, 2] * r[None, :, 2]
    full += g[:, None] * t[None]
    full += t[:, None] * g[None]
    full += mt[:, None] * t[None]
    out[_LOWER] = out[_UPPER]
    return out.T.reshape(shape + (WIDTH,))


def _component_major(array: np.ndarray, shape: tuple[int, ...], item: tuple[int, ...]) -> np.ndarray:
    """``array`` (batch dims + ``item``) broadcast to ``shape`` + ``item``, as a C-contiguous (item size, count)
    copy: each component one contiguous row, so the arithmetic runs over long contiguous vectors."""
    if array.shape != shape + item:
        array = np.broadcast_to(array, shape + item)
    return array.reshape(-1, math.prod(item)).T.copy()


# Flat indices (into the 13 packed floats) of the second moment's upper triangle (0,1), (0,2), (1,2) and of
# their mirror images (1,0), (2,0), (2,1).
_UPPER = np.array([5, 6, 9])
_LOWER = np.array([7, 10, 11])


def inverse_pose(rotation: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse rigid transform (R^T, -R^T t) of (rotation (..., 3, 3), translation (..., 3))."""
    rotation_t = np.swapaxes(rotation, -1, -2)
    t = translation[..., None, :]
    # Summed from +0 in this order (as numpy's einsum did for it): results stay bit for bit the same.
    product = rotation_t[..., 0] * t[..., 0] + rotation_t[..., 1] * t[..., 1] + rotation_t[..., 2] * t[..., 2]
    product += 0.0
    return rotation_t, -product


def rotate(rotation: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``rotation`` (..., 3, 3) times ``vector`` (..., 3), batch dimensions broadcast.

    Summed from +0 as ``(R_i0 v_0 + R_i2 v_2) + R_i1 v_1``, the order numpy's einsum uses for contiguous
    operands, so that results are bit for bit those of the einsum-based code this replaced."""
    v = vector[..., None, :]
    product = rotation[..., 0] * v[..., 0] + rotation[..., 2] * v[..., 2] + rotation[..., 1] * v[..., 1]
    product += 0.0
    return product
