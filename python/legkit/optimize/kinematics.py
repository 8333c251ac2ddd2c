"""Contact kinematics of a transcription's variables, with their derivatives from legkit's core.

The NLP's configuration variables are raw: a free-flyer's [position (world), quaternion [x, y, z, w] of any
norm, joint angles]. The kernels see the quaternion normalised (`unit`), and their derivatives are taken on q's
tangent space (q (+) dq with dq = [dv_lin, dw] in the base frame, as `lk.integrate`). `tangent_map` is d(dq) /
d(q_raw), so a kernel's derivative times it (`raw`) is the derivative with respect to the variables. Every
function here is batched over its leading axis (B points of a transcription) and calls each kernel once.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final, Literal

import numpy as np

import legkit as lk

#: A contact point: (body index, point in the body's frame).
ContactPoint = tuple[int, np.ndarray]

_WORLD: Final[Literal["local_world_aligned"]] = "local_world_aligned"


def skew(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices [w]x of (..., 3) vectors."""
    out = np.zeros(w.shape + (3,))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    return out


def vecmat(w: np.ndarray, m: np.ndarray) -> np.ndarray:
    """(B, j): each row's w (B, i) times its matrix m (B, i, j)."""
    return (w[:, None, :] @ m)[:, 0]


def matvec(m: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(B, i): each row's matrix m (B, i, j) times its w (B, j)."""
    return (m @ w[:, :, None])[:, :, 0]


def unit(model: lk.Model, q: np.ndarray) -> np.ndarray:
    """q (..., nq) with a unit base quaternion: a configuration the kernels take, whatever the iterate's norm."""
    if not model.floating_base:
        return q
    q = q.copy()
    q[..., 3:7] /= np.linalg.norm(q[..., 3:7], axis=-1, keepdims=True)
    return q


def rotation(quaternion: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation of a (not necessarily unit) [x, y, z, w] quaternion."""
    x, y, z, w = np.moveaxis(quaternion / np.linalg.norm(quaternion, axis=-1, keepdims=True), -1, 0)
    out = np.empty(quaternion.shape[:-1] + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    return out


def attitude_map(quaternion: np.ndarray) -> np.ndarray:
    """(B, 3, 4): d(dw) / d(quaternion) for R = R(quaternion / |quaternion|), R' = R exp([dw]x): dw = 2 vec(u* (x) du)
    / |quaternion| with u the unit quaternion; its radial part maps to zero (the norm is not seen)."""
    norm = np.linalg.norm(quaternion, axis=1)
    u = quaternion / norm[:, None]
    out = np.empty((len(u), 3, 4))
    out[:, :, :3] = -skew(u[:, :3])
    out[:, [0, 1, 2], [0, 1, 2]] += u[:, 3, None]
    out[:, :, 3] = -u[:, :3]
    return 2.0 * out / norm[:, None, None]


def _attitude_rows(u: np.ndarray) -> np.ndarray:
    """(B, 3, 4): [u_w I - [u_v]x, -u_v] of (B, 4) quaternions u, linear in u (`attitude_map` is 2 / |q| of it at u = q / |q|)."""
    out = np.empty((len(u), 3, 4))
    out[:, :, :3] = -skew(u[:, :3])
    out[:, [0, 1, 2], [0, 1, 2]] += u[:, 3, None]
    out[:, :, 3] = -u[:, :3]
    return out


def attitude_map_slopes(quaternion: np.ndarray) -> np.ndarray:
    """(B, 3, 4, 4): entry [i, c, b] is d `attitude_map`[i, c] / d quaternion_b: with n = |q|, u = q / n and
    du/dq = (I - u u^T) / n, d(2 A(u) / n) = -2 u_b A(u) / n^2 + 2 A(du/dq_b) / n (`_attitude_rows` A is linear)."""
    norm = np.linalg.norm(quaternion, axis=1)
    u = quaternion / norm[:, None]
    projector = (np.eye(4) - u[:, :, None] * u[:, None, :]) / norm[:, None, None]  # (B, 4, b): du / dq_b
    along = _attitude_rows(np.moveaxis(projector, 2, 1).reshape(-1, 4)).reshape(len(u), 4, 3, 4)  # [B, b, i, c]
    out = 2.0 * np.moveaxis(along, 1, 3) / norm[:, None, None, None]
    return out - 2.0 * _attitude_rows(u)[:, :, :, None] * u[:, None, None, :] / norm[:, None, None, None] ** 2


def raw_hessian(model: lk.Model, q: np.ndarray, curvature: np.ndarray, gradient: np.ndarray) -> np.ndarray:
    """(B, nq, nq): the Hessian with respect to raw q (B, nq) of a function f(unit q) whose tangent-space gradient is
    `gradient` (B, nv) and whose `curvature` (B, nv, nv) [a, d] is that gradient's slope along dq_d (as
    `lk.kinematic_hessian`): T^T K T plus the gradient's share of the slopes of T = `tangent_map` (R^T's along the
    quaternion: -[t_b]x R^T, t_b = attitude_map[:, b]; `attitude_map_slopes`)."""
    tangent = tangent_map(model, q)
    out = np.swapaxes(tangent, 1, 2) @ curvature @ tangent  # [c, b]
    if model.floating_base:
        quaternion = q[:, 3:7]
        moved = np.cross(np.swapaxes(attitude_map(quaternion), 1, 2), gradient[:, None, :3])  # (B, 4, 3): t_b x g_lin
        out[:, :3, 3:7] += np.einsum("bij,bkj->bik", rotation(quaternion), moved)  # g^T d(R^T)/dq_b = R (t_b x g)
        out[:, 3:7, 3:7] += np.einsum("bi,bicd->bcd", gradient[:, 3:6], attitude_map_slopes(quaternion))
    return out


def tangent_map(model: lk.Model, q: np.ndarray) -> np.ndarray:
    """(B, nv, nq): d(dq) / d(q_raw) (module docstring). A free-flyer's block is [R^T, 0; 0, `attitude_map`], the
    joints' the identity."""
    nq, nv = model.nq, model.nv
    out = np.zeros((len(q), nv, nq))
    if model.floating_base:
        out[:, :3, :3] = np.swapaxes(rotation(q[:, 3:7]), 1, 2)
        out[:, 3:6, 3:7] = attitude_map(q[:, 3:7])
        out[:, 6:, 7:] = np.eye(nv - 6)
    else:
        out[:] = np.eye(nv)
    return out


def raw(model: lk.Model, q: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """A derivative (B, ..., nv) on q's tangent space at raw q (B, nq), as one with respect to q_raw (B, ..., nq):
    times `tangent_map`, block by block."""
    if not model.floating_base:
        return tangent
    rows = tangent.reshape(len(q), -1, model.nv)
    out = np.empty(rows.shape[:2] + (model.nq,))
    out[:, :, :3] = rows[:, :, :3] @ np.swapaxes(rotation(q[:, 3:7]), 1, 2)
    out[:, :, 3:7] = rows[:, :, 3:6] @ attitude_map(q[:, 3:7])
    out[:, :, 7:] = rows[:, :, 6:]
    return out.reshape(tangent.shape[:-1] + (model.nq,))


def q_rate(model: lk.Model, q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """dq/dt (B, nq) of raw q at velocity v: a free-flyer's position rate R v_lin, its quaternion's q (x) [w, 0] / 2
    (tangent to |q| = const, so a collocated quaternion keeps its norm up to the defects' error), joint rates."""
    if not model.floating_base:
        return v
    quaternion, omega = q[:, 3:7], v[:, 3:6]
    vector, w = quaternion[:, :3], quaternion[:, 3:]
    position = matvec(rotation(quaternion), v[:, :3])
    spin = 0.5 * np.concatenate([w * omega + np.cross(vector, omega), -np.sum(vector * omega, axis=1, keepdims=True)], axis=1)
    return np.concatenate([position, spin, v[:, 6:]], axis=1)


def q_rate_derivatives(model: lk.Model, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(d q_rate / d q_raw (B, nq, nq), d q_rate / dv (B, nq, nv)) of `q_rate`."""
    count, nq, nv = len(q), model.nq, model.nv
    if not model.floating_base:
        return np.zeros((count, nq, nq)), np.broadcast_to(np.eye(nv), (count, nv, nv)).copy()
    quaternion, omega = q[:, 3:7], v[:, 3:6]
    by_q, by_v = np.zeros((count, nq, nq)), np.zeros((count, nq, nv))
    r = rotation(quaternion)
    by_q[:, :3, 3:7] = -r @ skew(v[:, :3]) @ attitude_map(quaternion)  # R' w = R w - R [w]x dw
    by_q[:, 3:6, 3:6] = -0.5 * skew(omega)  # q (x) [w, 0] / 2 is linear in q
    by_q[:, 3:6, 6] = 0.5 * omega
    by_q[:, 6, 3:6] = -0.5 * omega
    by_v[:, :3, :3] = r
    by_v[:, 3:6, 3:6] = 0.5 * (quaternion[:, 3, None, None] * np.eye(3) + skew(quaternion[:, :3]))
    by_v[:, 6, 3:6] = -0.5 * quaternion[:, :3]
    by_v[:, 7:, 6:] = np.eye(nv - 6)
    return by_q, by_v


def q_rate_hessian(model: lk.Model, q: np.ndarray, v: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(B, nq + nv, nq + nv): the Hessian of weights (B, nq) . `q_rate`(q, v) with respect to (raw q, v). The position
    rate's weight is mu . v_lin with mu = R^T weights_position, and dmu/dq_c = -t_c x mu (t_b = attitude_map[:, b]), so
    d/dq_b = mu . (t_b x v), d2/dq_b dq_c = (mu x t_c) . (t_b x v) + mu . (dt_b/dq_c x v) and d2/dq_b dv_lin = mu x t_b.
    The quaternion's rate q (x) [w, 0] / 2 is bilinear in (q, w); the joints' rates are linear."""
    count, nq, nv = len(q), model.nq, model.nv
    out = np.zeros((count, nq + nv, nq + nv))
    if not model.floating_base:
        return out
    quaternion, velocity = q[:, 3:7], v[:, :3]
    turns = np.swapaxes(attitude_map(quaternion), 1, 2)  # (B, 4, 3): t_b
    mu = np.einsum("bji,bj->bi", rotation(quaternion), weights[:, :3])
    turned = np.cross(mu[:, None, :], turns)  # mu x t_b
    moved = np.cross(np.moveaxis(attitude_map_slopes(quaternion), 1, 3), velocity[:, None, None, :])  # dt_b/dq_c x v
    block = np.einsum("bxi,byi->bxy", np.cross(turns, velocity[:, None, :]), turned) + np.einsum("bxyi,bi->bxy", moved, mu)
    out[:, 3:7, 3:7] = block
    out[:, 3:7, nq : nq + 3] = turned
    spin = weights[:, 3:7]  # d/dw of its weight is (q_w spin_v + spin_v x q_v - spin_w q_v) / 2, linear in q
    out[:, 3:6, nq + 3 : nq + 6] = 0.5 * (np.swapaxes(skew(spin[:, :3]), 1, 2) - spin[:, 3, None, None] * np.eye(3))
    out[:, 6, nq + 3 : nq + 6] = 0.5 * spin[:, :3]
    out[:, nq:, :nq] = np.swapaxes(out[:, :nq, nq:], 1, 2)
    return out


def point_jacobians(model: lk.Model, q: np.ndarray, points: Sequence[ContactPoint]) -> np.ndarray:
    """(B, len(points), 6, nv): each point's world-aligned Jacobian [linear; angular] at unit q."""
    out = np.empty((len(q), len(points), 6, model.nv))
    for c, (body, point) in enumerate(points):
        out[:, c] = lk.jacobian(model, q, body, point, _WORLD)
    return out


def tangent_position_curvature(model: lk.Model, unit_q: np.ndarray, points: Sequence[ContactPoint], weights: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """(curvature (B, nv, nv), gradient (B, nv)) on the tangent space at unit q (B, nq) of sum_c weights[:, c] . the
    world position of point c, weights (B, len(points), 3): `lk.kinematic_hessian`'s and `lk.jacobian`'s linear rows."""
    curvature, gradient = np.zeros((len(unit_q), model.nv, model.nv)), np.zeros((len(unit_q), model.nv))
    for c, (body, point) in enumerate(points):  # a few feet; each line is batched over all rows
        curvature += np.einsum("br,brad->bad", weights[:, c], np.asarray(lk.kinematic_hessian(model, unit_q, body, point, _WORLD))[:, :3])
        gradient += np.einsum("br,bra->ba", weights[:, c], np.asarray(lk.jacobian(model, unit_q, body, point, _WORLD))[:, :3])
    return curvature, gradient


def position_curvature(model: lk.Model, q: np.ndarray, points: Sequence[ContactPoint], weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Hessian (B, nq, nq), gradient (B, nq)) with respect to raw q (B, nq) of sum_c weights[:, c] . the world
    position of point c, weights (B, len(points), 3): `raw_hessian` of `tangent_position_curvature`."""
    curvature, gradient = tangent_position_curvature(model, unit(model, q), points, weights)
    return raw_hessian(model, q, curvature, gradient), raw(model, q, gradient[:, None])[:, 0]


def point_wrenches(model: lk.Model, q: np.ndarray, points: Sequence[ContactPoint], forces: np.ndarray) -> np.ndarray:
    """Body-frame wrenches (B, nbodies, 6) as `lk.rnea` takes them of world forces (B, len(points), 3) at the points."""
    poses = np.asarray(lk.forward_kinematics(model, q))
    out = np.zeros((len(q), model.nbodies, 6))
    for c, (body, point) in enumerate(points):  # a few feet; each line is batched over all rows
        local = np.einsum("bji,bj->bi", poses[:, body, :3, :3], forces[:, c])
        out[:, body, :3] += local
        out[:, body, 3:] += np.cross(point, local)
    return out


def force_slope(model: lk.Model, q: np.ndarray, points: Sequence[ContactPoint], forces: np.ndarray,
                jacobians: np.ndarray | None = None) -> np.ndarray:
    """d(sum_c J_c(q)^T F_c) / dq (B, nv, nv) on the tangent space at unit q, for world forces F (B, c, 3) held in
    world axes at the points; J_c the points' world-aligned linear Jacobians (`point_jacobians`, computed if None).
    `lk.rnea_derivatives` holds an external force in its body's frame; turning with the body, a world force's body
    components change by [f]x J_w dq, which adds J_lin^T [F]x J_ang (world axes) per point."""
    if jacobians is None:
        jacobians = point_jacobians(model, q, points)
    zero = np.zeros((len(q), model.nv))
    held = np.asarray(lk.rnea_derivatives(model, q, zero, zero, point_wrenches(model, q, points, forces))[0])
    gravity = np.asarray(lk.rnea_derivatives(model, q, zero, zero)[0])
    turning = np.einsum("bcki,bckl,bclj->bij", jacobians[:, :, :3], skew(forces), jacobians[:, :, 3:])
    return gravity - held + turning


def mass_slope(model: lk.Model, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """d(M(q) w) / dq (B, nv, nv) on the tangent space at unit q: the RNEA's slope at v = 0, a = w, less gravity's."""
    zero = np.zeros_like(w)
    return np.asarray(lk.rnea_derivatives(model, q, zero, w)[0]) - np.asarray(lk.rnea_derivatives(model, q, zero, zero)[0])


def point_velocity_derivatives(model: lk.Model, q: np.ndarray, v: np.ndarray, body: int, point: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray]:
    """(d/dq on the tangent space, d/dv), each (B, 3, nv), of the point's world velocity J_lin(q) v at unit q."""
    by_q, by_v = lk.frame_velocity_derivatives(model, q, v, body, point, _WORLD)
    return np.asarray(by_q)[:, :3], np.asarray(by_v)[:, :3]


def point_acceleration_derivatives(model: lk.Model, q: np.ndarray, v: np.ndarray, a: np.ndarray, body: int,
                                   point: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d/dq on the tangent space, d/dv, d/da), each (B, 3, nv), of the point's classical world acceleration
    J a + dJ/dt v + w x v_point (`lk.point_accelerations`) at unit q: the spatial acceleration's slopes
    (`lk.frame_acceleration_derivatives`) plus those of w x v_point = -[v_point]x w + [w]x v_point."""
    dv_dq, da_dq, da_dv, da_da = (np.asarray(d) for d in lk.frame_acceleration_derivatives(model, q, v, a, body, point, _WORLD))
    velocity = np.asarray(lk.frame_velocity(model, q, v, body, point, _WORLD))
    linear, angular = skew(velocity[:, :3]), skew(velocity[:, 3:])
    jac = np.asarray(lk.jacobian(model, q, body, point, _WORLD))
    by_q = da_dq[:, :3] - linear @ dv_dq[:, 3:] + angular @ dv_dq[:, :3]
    by_v = da_dv[:, :3] - linear @ jac[:, 3:] + angular @ jac[:, :3]
    return by_q, by_v, da_da[:, :3]
