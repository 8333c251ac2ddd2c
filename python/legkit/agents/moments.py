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

    Written out component by component over contiguous (batch,) vectors: for the small 3x3 blocks this is
    several times faster than stacked matrix products. The second moment is assumed symmetric (it always
    is here) and the result is exactly symmetric."""
    shape = np.broadcast_shapes(moments.shape[:-1], rotation.shape[:-2], translation.shape[:-1])
    r = np.broadcast_to(rotation, shape + (3, 3)).reshape(-1, 9).T
    t = np.broadcast_to(translation, shape + (3,)).reshape(-1, 3).T
    x = np.broadcast_to(moments, shape + (WIDTH,)).reshape(-1, WIDTH).T
    mass, h = x[0], x[1:4]
    R = [[r[3 * i + j] for j in range(3)] for i in range(3)]
    P = [[x[4 + 3 * i + j] for j in range(3)] for i in range(3)]
    g = [R[i][0] * h[0] + R[i][1] * h[1] + R[i][2] * h[2] for i in range(3)]
    RP = [[R[i][0] * P[0][k] + R[i][1] * P[1][k] + R[i][2] * P[2][k] for k in range(3)] for i in range(3)]
    mt = [mass * t[i] for i in range(3)]
    out = np.empty((WIDTH, x.shape[1]))
    out[0] = mass
    for i in range(3):
        out[1 + i] = g[i] + mt[i]
        for j in range(i, 3):
            value = RP[i][0] * R[j][0] + RP[i][1] * R[j][1] + RP[i][2] * R[j][2] + g[i] * t[j] + t[i] * g[j] + mt[i] * t[j]
            out[4 + 3 * i + j] = value
            out[4 + 3 * j + i] = value
    return out.T.reshape(shape + (WIDTH,))


def inverse_pose(rotation: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse rigid transform (R^T, -R^T t) of (rotation (..., 3, 3), translation (..., 3))."""
    rotation_t = np.swapaxes(rotation, -1, -2)
    return rotation_t, -np.einsum("...ij,...j->...i", rotation_t, translation)
