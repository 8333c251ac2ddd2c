"""Rates between the collocation points: each actuated joint's rate within its motor's no-load speed over every
interval (`dense_rate_blocks`), and how fast the stance forces and the torques change (`load_rate_blocks`)."""

from __future__ import annotations

import numpy as np

from legkit.optimize.blocks import Block, Linear, Point
from legkit.optimize.contact import ContactModel


def dense_rate_blocks(problem: ContactModel) -> list[Block]:
    """|w_i(s)| <= no-load speed of each actuated joint i over every interval (dense_rates): w(s) is the velocity's
    Hermite cubic [Hardt 2002, eq. 14] through (v_k, h a_k) and (v_k+1, h a_k+1), h = T / N; in Bernstein form its
    control points are v_k, v_k + h a_k / 3, v_k+1 - h a_k+1 / 3, v_k+1, and the cubic lies in their convex hull, so
    bounding the two inner ones (bilinear in the duration and the accelerations) bounds it everywhere; the ends are
    points, held by the torque-speed line."""
    if not problem.dense_rates or problem.torque_speed is None or not problem.nu:
        return []
    actuated, nu = np.asarray(problem.actuated), problem.nu
    limit = np.tile(np.broadcast_to(np.asarray(problem.torque_speed.max_speed, dtype=np.float64), (nu,)), 2)
    blocks: list[Block] = []
    for k, index in enumerate(problem.point_index):
        a = index[:, problem.a_columns[k]][:, actuated]
        v = index[:, problem.nq + actuated]
        groups = np.concatenate([v[0:-1:2], a[0:-1:2], v[2::2], a[2::2], np.full((len(v) // 2, 1), problem.duration_index[k])], axis=1)
        third = 1.0 / (3.0 * problem.phases[k].intervals)  # h / 3 per unit duration

        def rates(g: np.ndarray, third: float = third) -> np.ndarray:
            v0, a0, v1, a1 = (g[:, i * nu : (i + 1) * nu] for i in range(4))
            step = third * g[:, -1:]
            return np.concatenate([v0 + step * a0, v1 - step * a1], axis=1)

        def slopes(g: np.ndarray, third: float = third) -> np.ndarray:
            out = np.zeros((len(g), 2 * nu, 4 * nu + 1))
            eye = np.eye(nu)
            step = third * g[:, -1, None, None]
            out[:, :nu, :nu], out[:, nu:, 2 * nu : 3 * nu] = eye, eye
            out[:, :nu, nu : 2 * nu], out[:, nu:, 3 * nu : 4 * nu] = step * eye, -step * eye
            out[:, :nu, -1], out[:, nu:, -1] = third * g[:, nu : 2 * nu], -third * g[:, 3 * nu : 4 * nu]
            return out

        # Rate i of the first inner control point depends on v0_i, a0_i and T; of the second on v1_i, a1_i and T.
        mask = np.zeros((2 * nu, 4 * nu + 1), dtype=bool)
        joints = np.arange(nu)
        mask[joints, joints] = mask[joints, nu + joints] = True
        mask[nu + joints, 2 * nu + joints] = mask[nu + joints, 3 * nu + joints] = True
        mask[:, -1] = True
        blocks.append(Point(groups, rates, 2 * nu, -limit, limit, derivative=slopes, nonlinear=np.array([4 * nu]), mask=mask))
    return blocks


def load_rate_blocks(problem: ContactModel) -> list[Block]:
    """|x(t_p+1) - x(t_p)| <= rate (t_p+1 - t_p) between neighbouring points for every component x of every
    stance foot's force (max_force_rate) and every actuated torque (max_torque_rate): linear rows in x and the
    phase's duration (t_p+1 - t_p = T / (2 N)). At a phase boundary, where two points share one instant, a foot
    down on both sides keeps its force within one half interval's change, a lifting foot's force at its last
    point and a landing foot's at its first are within one half interval's change of zero (the load moves
    between feet over the half intervals beside the switch, not at once), and the torques likewise."""
    terms: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []  # a, its sign, b, phase, c

    def add(a: np.ndarray, b: np.ndarray | None, k: int, rate: float, a_sign: np.ndarray | float = 1.0) -> None:
        """Rows |a_sign x[a] - x[b]| <= rate T_k / (2 N_k) (b None: |a_sign x[a]|), elementwise over a."""
        a = np.ravel(a)
        b_index = np.full(len(a), -1) if b is None else np.ravel(b)
        terms.append((a, np.broadcast_to(np.asarray(a_sign, dtype=np.float64), a.shape).ravel(), b_index,
                      np.full(len(a), k), np.full(len(a), rate / (2.0 * problem.phases[k].intervals))))

    count = len(problem.phases)
    nx, nu = problem.nx, problem.nu

    def forces(k: int, point: int, name: str) -> np.ndarray:
        contacts = list(problem.phases[k].contacts)
        own = problem.point_index[k][point, problem.force_columns[k]].reshape(len(contacts), problem.force_dims)
        return own[contacts.index(name)]

    for k in range(count):
        index = problem.point_index[k]
        if np.isfinite(problem.max_torque_rate) and nu:
            add(index[1:, nx : nx + nu], index[:-1, nx : nx + nu], k, problem.max_torque_rate)
        if np.isfinite(problem.max_force_rate):
            for name in problem.phases[k].contacts:
                add(np.stack([forces(k, p, name) for p in range(1, len(index))]),
                    np.stack([forces(k, p, name) for p in range(len(index) - 1)]), k, problem.max_force_rate)
        if k == count - 1 and not problem.periodic:
            continue
        after = (k + 1) % count
        wrapped = after == 0 and problem.mirror is not None
        start = problem.start_seen_from(k)
        if np.isfinite(problem.max_torque_rate) and nu:
            add(start.u, problem.point_index[k][-1, nx : nx + nu], k, problem.max_torque_rate, start.u_sign)
        if not np.isfinite(problem.max_force_rate):
            continue
        sign = np.array([1.0, -1.0, 1.0])[3 - problem.force_dims :] if wrapped else 1.0  # a mirrored force's y flips
        before, later = problem.phases[k].contacts, problem.contacts_after(k)
        for name in dict.fromkeys((*before, *later)):  # ordered: a set's order follows the hash seed
            own = problem.mirror.feet[name] if wrapped and problem.mirror is not None else name  # its name in phase `after`
            if name in before and name in later:
                add(forces(after, 0, own), forces(k, len(problem.point_index[k]) - 1, name), k, problem.max_force_rate, sign)
            elif name in before:
                add(forces(k, len(problem.point_index[k]) - 1, name), None, k, problem.max_force_rate)
            else:
                add(forces(after, 0, own), None, after, problem.max_force_rate)
    if not terms:
        return []
    a, a_sign, b, phase, c = (np.concatenate(part) for part in zip(*terms))
    size, paired = len(a), np.flatnonzero(b >= 0)
    rows = np.concatenate([np.arange(size), paired, np.arange(size)])
    cols = np.concatenate([a, b[paired], problem.duration_index[phase]])
    coefficients = np.concatenate([a_sign, -np.ones(len(paired)), -c])
    flip = np.r_[-np.ones(len(cols) - size), np.ones(size)]  # difference - c T <= 0, then -difference - c T <= 0
    return [Linear(size, rows, cols, coefficients, lower=-np.inf, upper=0.0),
            Linear(size, rows, cols, coefficients * flip, lower=-np.inf, upper=0.0)]
