"""What links the phases of a multiphase transcription across its boundaries (`boundary_blocks`: q continuous, or
periodic up to the travelled distance and, with a mirror, mirrored; v across the impact map; optionally u), the cycle
time (`period_blocks`) and a free-flyer's quaternion scale (`quaternion_gauge_blocks`)."""

from __future__ import annotations

import numpy as np

from legkit.optimize.blocks import Block, Linear, Point, equal
from legkit.optimize.constraints.impact import velocity_transition
from legkit.optimize.contact import ContactModel
from legkit.optimize.definition import period_bounds


def boundary_blocks(problem: ContactModel) -> list[Block]:
    """Per phase boundary (the wrap-around too when periodic): the start's q equal to the end's (periodic: up to the
    travel, the base quaternion by direction), v after the boundary (`impact.velocity_transition`), and with
    continuous_controls u equal."""
    blocks: list[Block] = []
    nq, nx, nu = problem.nq, problem.nx, problem.nu
    count = len(problem.phases)
    for k in range(count if problem.periodic else count - 1):
        end, start = problem.point_index[k][-1], problem.start_seen_from(k)
        if problem.periodic and (k + 1) % count == 0 and problem.travel_index is not None:
            # q_start = q_end - speed * sum(T) on the travel coordinate, equal elsewhere. The base quaternion's
            # norm already follows from the first point's |q| = 1 through the defects, so only its direction
            # wraps around (3 rows: equal 4 components would be a nearly redundant row, ill-conditioning
            # the KKT system).
            quaternion = [3, 4, 5, 6] if problem.model.floating_base else []
            keep = [i for i in range(nq) if i != problem.travel_index and i not in quaternion]
            blocks.append(equal(len(keep), start.q[keep], end[keep], start.q_sign[keep]))
            if quaternion:
                blocks.append(same_rotation_block(np.concatenate([start.q[3:7], end[3:7]]), np.r_[start.q_sign[3:7], np.ones(4)]))
            blocks.append(Linear(1, np.zeros(count + 2, dtype=np.int64),
                                 np.r_[start.q[problem.travel_index], end[problem.travel_index], problem.duration_index],
                                 np.r_[1.0, -1.0, np.full(count, problem.speed)]))
        else:
            blocks.append(equal(nq, start.q, end[:nq], start.q_sign))
        blocks.append(velocity_transition(problem, k, start))
        if problem.continuous_controls and nu:
            blocks.append(equal(nu, start.u, end[nx : nx + nu], start.u_sign))
    return blocks


def period_blocks(problem: ContactModel) -> list[Block]:
    """The cycle time within `period` (with a mirror the phases are half of it)."""
    if problem.period is None:
        return []
    count = len(problem.phases)
    lo, hi = period_bounds(problem.period)
    halves = 1.0 if problem.mirror is None else 2.0  # the phases are half the cycle
    return [Linear(1, np.zeros(count, dtype=np.int64), problem.duration_index, np.full(count, halves), lower=lo, upper=hi)]


def quaternion_gauge_blocks(problem: ContactModel) -> list[Block]:
    """|quaternion|^2 = 1 at the first point of a free-flyer: fixes the scale gauge of the quaternion (kernels normalise it)."""
    if not problem.model.floating_base:
        return []
    first = problem.point_index[0][0]
    return [Point(first[None, 3:7], lambda quat: np.sum(quat * quat, axis=1, keepdims=True) - 1.0, 1,
                  derivative=lambda quat: 2.0 * quat[:, None, :])]


def same_rotation(pair: np.ndarray) -> np.ndarray:
    """(B, 3): vector parts of two [x, y, z, w] quaternions (B, 8), each normalised, subtracted."""
    first, second = pair[:, :4], pair[:, 4:]
    return first[:, :3] / np.linalg.norm(first, axis=1, keepdims=True) - second[:, :3] / np.linalg.norm(second, axis=1, keepdims=True)


def same_rotation_block(index: np.ndarray, signs: np.ndarray) -> Point:
    """`same_rotation` of the quaternion pair x[index] (8,), each component times its sign first."""
    def slopes(pair: np.ndarray) -> np.ndarray:  # d(vector / |q|) / dq = [I 0] / |q| - vector q^T / |q|^3, per quaternion
        out = np.empty((len(pair), 3, 8))
        for half, sign in ((slice(0, 4), 1.0), (slice(4, 8), -1.0)):
            quaternion = signs[half] * pair[:, half]
            norm = np.linalg.norm(quaternion, axis=1)[:, None, None]
            part = -quaternion[:, :3, None] * quaternion[:, None, :] / norm**3
            part[:, :, :3] += np.eye(3) / norm
            out[:, :, half] = sign * part * signs[half]
        return out

    return Point(index[None], lambda pair: same_rotation(signs * pair), 3, derivative=slopes)
