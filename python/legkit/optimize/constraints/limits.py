"""Limits at every collocation point: the motor torque-speed line (`torque_speed_blocks`, [Hardt 2002, Sect. 2.3]),
each motor's input power (`input_power_blocks`, Sect. 6) and a free-flyer's yaw (`yaw_blocks`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from legkit.optimize.blocks import Block, Linear, Point
from legkit.optimize.contact import ContactModel


def yaw_blocks(problem: ContactModel) -> list[Block]:
    """-max_yaw <= yaw <= max_yaw at every point: yaw = atan2(2 (w z + x y), w^2 + x^2 - y^2 - z^2) of the base
    quaternion [x, y, z, w] (both arguments homogeneous of degree 2: the quaternion's norm drops out)."""
    if not np.isfinite(problem.max_yaw):
        return []

    def yaw(quaternion: np.ndarray) -> np.ndarray:
        x, y, z, w = quaternion.T
        return np.arctan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)[:, None]

    def slopes(quaternion: np.ndarray) -> np.ndarray:
        x, y, z, w = quaternion.T
        sine, cosine = 2.0 * (w * z + x * y), w * w + x * x - y * y - z * z
        by_sine, by_cosine = 2.0 * np.stack([y, x, w, z], axis=1), 2.0 * np.stack([x, -y, -z, w], axis=1)
        return ((cosine[:, None] * by_sine - sine[:, None] * by_cosine) / (sine * sine + cosine * cosine)[:, None])[:, None, :]

    index = np.concatenate([index[:, 3:7] for index in problem.point_index])
    return [Point(index, yaw, 1, -problem.max_yaw, problem.max_yaw, derivative=slopes)]


def torque_speed_blocks(problem: ContactModel) -> list[Block]:
    """(w_max - |w|) k - |u| >= 0 as four linear faces per actuated joint and point."""
    line = problem.torque_speed
    assert line is not None  # built only with a torque-speed line
    w_max = np.broadcast_to(np.asarray(line.max_speed, dtype=np.float64), (problem.nu,))
    gain = np.broadcast_to(np.asarray(line.gain, dtype=np.float64), (problem.nu,))
    index = np.concatenate(problem.point_index_u_w(), axis=0)  # (P, nu, 2): (u, w) columns
    points = len(index)
    blocks: list[Block] = []
    for su in (1.0, -1.0):
        for sw in (1.0, -1.0):
            rows = np.arange(points * problem.nu)
            coeff_u = np.full(points * problem.nu, -su)
            coeff_w = np.tile(-sw * gain, points)
            blocks.append(Linear(len(rows), np.r_[rows, rows], np.r_[index[..., 0].ravel(), index[..., 1].ravel()],
                                 np.r_[coeff_u, coeff_w], offset=np.tile(w_max * gain, points), lower=0.0, upper=np.inf))
    return blocks


def input_power_blocks(problem: ContactModel) -> list[Block]:
    """R (u / (G K))^2 + u w <= limit per actuated joint and point: one block per joint, whose coefficients
    are its own (a point block's function is applied to batches of points of one kind)."""
    power = problem.input_power
    assert power is not None  # built only with an input-power limit

    def per_joint(value: np.ndarray | float) -> np.ndarray:
        return np.broadcast_to(np.asarray(value, dtype=np.float64), (problem.nu,))

    limit = per_joint(power.limit)
    loss = per_joint(power.resistance) / (per_joint(power.gear_ratio) * per_joint(power.torque_constant)) ** 2
    index = np.concatenate(problem.point_index_u_w(), axis=0)  # (P, nu, 2): (u, w) columns
    blocks: list[Block] = []
    for i in range(problem.nu):
        drawn, slopes = input_power(float(loss[i]))
        blocks.append(Point(index[:, i], drawn, 1, lower_bound=-np.inf, upper_bound=float(limit[i]), derivative=slopes))
    return blocks


def input_power(loss: float) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray]]:
    """(B, 2) points (u, w) -> (B, 1) input powers loss u^2 + u w [W], and its slopes (B, 1, 2)."""
    def power(z: np.ndarray) -> np.ndarray:
        return (loss * z[:, 0] ** 2 + z[:, 0] * z[:, 1])[:, None]

    def slopes(z: np.ndarray) -> np.ndarray:
        return np.stack([2.0 * loss * z[:, 0] + z[:, 1], z[:, 0]], axis=1)[:, None, :]

    return power, slopes
