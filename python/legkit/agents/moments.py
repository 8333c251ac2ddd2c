"""Batched mass-property algebra on packed moments.

An agent's estimates are stored as *moments about the agent's frame origin*, packed into 13 floats:
``[m, h (3), P (9)]`` with ``h = sum m_i r_i = m c`` and ``P = sum m_i r_i r_i^T`` (row-major). In this form
composition is plain addition (exact and associative up to rounding, no division), an empty estimate is all
zeros, and a rigid transform x' = R x + t is linear:

    h' = R h + m t,     P' = R P R^T + (R h) t^T + t (R h)^T + m t t^T.

This is the parallel-axis theorem in disguise: the inertia about the COM is ``I = tr(P_c) E - P_c`` with
``P_c = P - h h^T / m``. (The seed paper's shorthand ``(m1 I1 + m2 I2) / (m1 + m2)`` for combined inertia is
not physically correct; the moment form composes inertia exactly.) Every function takes leading batch
dimensions; the ``*_components`` variants take component-major arrays (components first, batch last), the
layout the agents keep their state in.
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

    The second moment is assumed symmetric (it always is here); the result is exactly symmetric. See
    ``transform_components`` for the arithmetic."""
    r = np.moveaxis(np.asarray(rotation, dtype=float), (-2, -1), (0, 1))
    t = np.moveaxis(np.asarray(translation, dtype=float), -1, 0)
    x = np.moveaxis(np.asarray(moments, dtype=float), -1, 0)
    return np.moveaxis(transform_components(r, t, x), 0, -1)


def transform_components(rotation: np.ndarray, translation: np.ndarray, moments: np.ndarray) -> np.ndarray:
    """``transform`` on component-major arrays: rotation (3, 3, ...), translation (3, ...), moments (13, ...) ->
    (13, ...), the trailing (batch) dimensions broadcast. Long batch rows make this much faster than the
    same arithmetic on many small matrices.

    The sums are evaluated left to right: ``h'_i = ((R_i0 h_0 + R_i1 h_1) + R_i2 h_2) + m t_i`` and
    ``P'_ij = (((((RP)_i0 R_j0 + (RP)_i1 R_j1) + (RP)_i2 R_j2) + g_i t_j) + t_i g_j) + m t_i t_j`` (g = R h);
    the lower triangle of P' copies the upper one."""
    batch = rotation.shape[2:]
    if translation.shape[1:] == batch and moments.shape[1:] == batch:
        r, t, x = rotation, translation, moments
    else:
        batch = np.broadcast_shapes(batch, translation.shape[1:], moments.shape[1:])
        r, t, x = _align(rotation, 2, len(batch)), _align(translation, 1, len(batch)), _align(moments, 1, len(batch))
    # R [P | h] in one go: y[l] = (P_l0, P_l1, P_l2, h_l), so rp_g[i] = ((RP)_i0, (RP)_i1, (RP)_i2, g_i).
    y = x[_RP_G_INDEX]
    rp_g = r[:, 0, None] * y[0]
    rp_g += r[:, 1, None] * y[1]
    rp_g += r[:, 2, None] * y[2]
    rp, g = rp_g[:, :3], rp_g[:, 3]
    mass = x[0]
    mt = mass * t
    out = np.empty((WIDTH,) + batch)
    out[0] = mass
    np.add(g, mt, out=out[1:4])
    second = out[4:].reshape((3, 3) + batch)
    np.multiply(rp[:, None, 0], r[None, :, 0], out=second)
    second += rp[:, None, 1] * r[None, :, 1]
    second += rp[:, None, 2] * r[None, :, 2]
    second += g[:, None] * t[None]
    second += t[:, None] * g[None]
    second += mt[:, None] * t[None]
    out[_LOWER] = out[_UPPER]
    return out


def _align(array: np.ndarray, components: int, batch_ndim: int) -> np.ndarray:
    """A component-major array (``components`` leading axes, then batch axes) with singleton batch axes
    inserted after the component axes, so that its batch axes line up with ``batch_ndim`` others'."""
    missing = batch_ndim - (array.ndim - components)
    return array.reshape(array.shape[:components] + (1,) * missing + array.shape[components:]) if missing else array


# The packed moments' second-moment rows and first moment as columns: [l, c] = P_l0, P_l1, P_l2, h_l.
_RP_G_INDEX = np.array([[4, 5, 6, 1], [7, 8, 9, 2], [10, 11, 12, 3]])
# Flat indices (into the 13 packed floats) of the second moment's upper triangle (0,1), (0,2), (1,2) and of
# their mirror images (1,0), (2,0), (2,1).
_UPPER = np.array([5, 6, 9])
_LOWER = np.array([7, 10, 11])


def inverse_pose(rotation: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse rigid transform (R^T, -R^T t) of (rotation (..., 3, 3), translation (..., 3))."""
    r = np.moveaxis(rotation, (-2, -1), (0, 1))
    return np.swapaxes(rotation, -1, -2), np.moveaxis(inverse_translation_components(r, np.moveaxis(translation, -1, 0)), 0, -1)


def inverse_translation_components(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """-R^T t on component-major arrays: rotation (3, 3, ...), translation (3, ...) -> (3, ...).

    Summed from +0 as ``(R_0i t_0 + R_1i t_1) + R_2i t_2`` (as numpy's einsum did for it), so that results
    are bit for bit those of the einsum-based code this replaced."""
    r, t = _align_pair(rotation, translation)
    product = r[0] * t[0] + r[1] * t[1] + r[2] * t[2]
    product += 0.0
    return -product


def rotate_components(rotation: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """``rotation`` (3, 3, ...) times ``vector`` (3, ...) on component-major arrays -> (3, ...), the trailing
    (batch) dimensions broadcast.

    Summed from +0 as ``(R_i0 v_0 + R_i2 v_2) + R_i1 v_1``, the order numpy's einsum uses for contiguous
    operands, so that results are bit for bit those of the einsum-based code this replaced."""
    r, v = _align_pair(rotation, vector)
    product = r[:, 0] * v[0] + r[:, 2] * v[2] + r[:, 1] * v[1]
    product += 0.0
    return product


def _align_pair(rotation: np.ndarray, vector: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``rotation`` (3, 3, ...) and ``vector`` (3, ...) with their batch axes lined up (see ``_align``)."""
    if rotation.ndim - 2 == vector.ndim - 1:
        return rotation, vector
    batch_ndim = max(rotation.ndim - 2, vector.ndim - 1)
    return _align(rotation, 2, batch_ndim), _align(vector, 1, batch_ndim)
