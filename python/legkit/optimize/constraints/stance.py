"""The stance feet of a multiphase transcription: on the ground and at their footholds (`Feet`, with the swing tips'
eq. 4 at the points), at rest at velocity and acceleration level at the knots (`stance_blocks`), their forces in the
friction cone (`friction_cone_blocks`, eq. 5) and a flat foot's torques within eq. 6 (`foot_torque_blocks`)."""

from __future__ import annotations

import numpy as np

import legkit as lk
from legkit.optimize import kinematics as kin
from legkit.optimize.blocks import Block, Linear, Point, group_pattern
from legkit.optimize.contact import ContactModel


def friction_cone_blocks(problem: ContactModel, k: int) -> list[Block]:
    """Eq. 5 at every point of phase k, squared to stay smooth: mu^2 F_z^2 - F_x^2 - F_y^2 >= 0 per stance foot."""
    phase, index = problem.phases[k], problem.point_index[k]
    if not (phase.contacts and problem.force_dims == 3):
        return []
    mu2 = problem.friction**2
    feet = len(phase.contacts)
    slope = np.tile([-2.0, -2.0, 2.0 * mu2], feet)
    owner = np.repeat(np.eye(feet), 3, axis=1)  # each foot's row sees its own force

    def cone(f: np.ndarray) -> np.ndarray:
        return mu2 * f.reshape(len(f), -1, 3)[..., 2] ** 2 - np.sum(f.reshape(len(f), -1, 3)[..., :2] ** 2, axis=-1)

    def cone_slopes(f: np.ndarray, slope: np.ndarray = slope, owner: np.ndarray = owner) -> np.ndarray:
        return owner * (slope * f)[:, None, :]

    return [Point(index[:, problem.force_columns[k]], cone, feet, 0.0, np.inf, derivative=cone_slopes)]


def stance_blocks(problem: ContactModel, k: int) -> list[Block]:
    """The stance feet of phase k held at velocity and acceleration level at the knots (their positions:
    `Feet`): J_c v = 0 and J_c a + dJ_c/dt v = 0 (`lk.point_accelerations`) for each foot's `contact_rows`,
    one block each per foot over its leg's and the base's columns. With the midpoints freed by the slack
    (`rate`), this is DIRCON's form of the contact constraint (Posa, Kuindersma & Tedrake 2016). Held at
    position level at every point instead, the forces were free to alternate between knots and midpoints.
    A knot's velocity is stated once: not at a phase's first knot (the impact map or the
    previous phase's last knot states it), nor at its last for a foot that stays down through a soft
    touchdown (max_impulse 0: v is continuous there, and the impact map states it), nor where
    `initial`/`final` fix the state."""
    nq, nv, nx = problem.nq, problem.nv, problem.nx
    index = problem.point_index[k]
    knots = np.arange(0, len(index), 2)
    count = len(problem.phases)
    linked = problem.periodic and count > 1
    ancestors, q_body, v_body = problem.tree()
    width = index.shape[1]

    def full(g: np.ndarray, columns: np.ndarray) -> np.ndarray:  # the point variables, zero outside columns
        z = np.zeros((len(g), width))
        z[:, columns] = g
        return z

    blocks: list[Block] = []
    for name in problem.phases[k].contacts:
        rows = problem.contact_rows([name])
        points = [(body, point) for body, point, _ in rows]
        axes = np.concatenate([3 * i + np.asarray(a) for i, (_, _, a) in enumerate(rows)])
        reach = list(ancestors[problem.foot_body[name]])
        q_columns = problem.q_without_translation[np.isin(q_body[problem.q_without_translation], reach)]
        v_columns = np.flatnonzero(np.isin(v_body, reach))
        velocity_columns = np.concatenate([q_columns, nq + v_columns])
        # a foot's acceleration depends on its leg and the base only
        acceleration_columns = np.concatenate([velocity_columns, problem.a_columns[k].start + v_columns])

        def velocities(g: np.ndarray, columns: np.ndarray = velocity_columns, name: str = name) -> np.ndarray:
            z = full(g, columns)
            return np.einsum("bri,bi->br", problem.contact_jacobian(z[:, :nq], [name]), z[:, nq:nx])

        def accelerations(g: np.ndarray, columns: np.ndarray = acceleration_columns, points: list = points,
                          axes: np.ndarray = axes) -> np.ndarray:
            z = full(g, columns)
            a = problem.accelerations(z, k)
            values = np.asarray(lk.point_accelerations(problem.model, problem.configuration(z[:, :nq]), z[:, nq:nx], a, points))
            return values.reshape(len(g), -1)[:, axes]

        def velocity_slopes(g: np.ndarray, columns: np.ndarray = velocity_columns, rows: list = rows) -> np.ndarray:
            z = full(g, columns)
            q, v = z[:, :nq], z[:, nq:nx]
            unit = problem.configuration(q)
            slopes = np.zeros((len(g), 0, nx))
            for body, point, row_axes in rows:
                by_q, by_v = kin.point_velocity_derivatives(problem.model, unit, v, body, point)
                slopes = np.concatenate([slopes, np.concatenate([kin.raw(problem.model, q, by_q), by_v], axis=2)[:, row_axes]], axis=1)
            return slopes[:, :, columns]

        def velocity_curvature(g: np.ndarray, weights: np.ndarray, columns: np.ndarray = velocity_columns, rows: list = rows,
                               name: str = name) -> np.ndarray:
            """(B, k, k): the Hessian of weights . J_c(q) v: in q from `lk.point_velocity_hessian`, with v the rows'
            loads F = weights (`row_forces`) along `lk.kinematic_hessian`; linear in v."""
            z = full(g, columns)
            q, v = z[:, :nq], z[:, nq:nx]
            unit = problem.configuration(q)
            loads = problem.row_forces(weights, [name])
            curvature, gradient, turning = np.zeros((len(g), nv, nv)), np.zeros((len(g), nv)), np.zeros((len(g), nv, nv))
            for c, (body, point, _) in enumerate(rows):
                power_qq, power_q = lk.point_velocity_hessian(problem.model, unit, v, body, point, loads[:, c])
                curvature, gradient = curvature + np.asarray(power_qq), gradient + np.asarray(power_q)
                turning += np.einsum("br,brad->bad", loads[:, c], np.asarray(lk.kinematic_hessian(problem.model, unit, body, point))[:, :3])
            out = np.zeros((len(g), nx, nx))
            out[:, :nq, :nq] = kin.raw_hessian(problem.model, q, curvature, gradient)
            out[:, nq:nx, :nq] = turning @ kin.tangent_map(problem.model, q)  # d(J^T F)/dq: [v_a, q_c]
            out[:, :nq, nq:nx] = np.swapaxes(out[:, nq:nx, :nq], 1, 2)
            return out[:, columns][:, :, columns]

        def acceleration_slopes(g: np.ndarray, columns: np.ndarray = acceleration_columns, points: list = points,
                                axes: np.ndarray = axes) -> np.ndarray:
            z = full(g, columns)
            q, v, a = z[:, :nq], z[:, nq:nx], problem.accelerations(z, k)
            unit = problem.configuration(q)
            slopes = np.zeros((len(g), 3 * len(points), width))
            for i, (body, point) in enumerate(points):
                by_q, by_v, by_a = kin.point_acceleration_derivatives(problem.model, unit, v, a, body, point)
                slopes[:, 3 * i : 3 * i + 3, :nq] = kin.raw(problem.model, q, by_q)
                slopes[:, 3 * i : 3 * i + 3, nq:nx] = by_v
                slopes[:, 3 * i : 3 * i + 3, problem.a_columns[k]] = by_a
            return slopes[:, axes][:, :, columns]

        def acceleration_curvature(g: np.ndarray, weights: np.ndarray, columns: np.ndarray = acceleration_columns, rows: list = rows,
                                   name: str = name) -> np.ndarray:
            """(B, k, k): the Hessian of weights . the rows' accelerations, from `lk.point_acceleration_hessian` with the
            rows' loads F = weights (`row_forces`): qq (its q-gradient for the quaternion's chart), qv, vv and qa (a
            enters linearly)."""
            z = full(g, columns)
            q, v, a = z[:, :nq], z[:, nq:nx], problem.accelerations(z, k)
            unit = problem.configuration(q)
            loads = problem.row_forces(weights, [name])
            parts = [np.zeros((len(g), nv, nv)) for _ in range(4)] + [np.zeros((len(g), nv))]
            for c, (body, point, _) in enumerate(rows):  # a foot's few points; each call batched over all knots
                for total, part in zip(parts, lk.point_acceleration_hessian(problem.model, unit, v, a, body, point, loads[:, c])):
                    total += part
            qq, qv, vv, qa, gradient = parts
            out = np.zeros((len(g), width, width))
            turn = np.swapaxes(kin.tangent_map(problem.model, q), 1, 2)  # [q_raw, dq]
            accelerations = problem.a_columns[k]
            out[:, :nq, :nq] = kin.raw_hessian(problem.model, q, qq, gradient)
            out[:, :nq, nq:nx] = turn @ qv
            out[:, :nq, accelerations] = turn @ qa
            out[:, nq:nx, nq:nx] = vv
            out[:, nq:nx, :nq] = np.swapaxes(out[:, :nq, nq:nx], 1, 2)
            out[:, accelerations, :nq] = np.swapaxes(out[:, :nq, accelerations], 1, 2)
            return out[:, columns][:, :, columns]

        held = knots
        if k > 0 or linked or problem.initial is not None:
            held = held[held > 0]
        last = len(index) - 1
        soft_touchdown = (k < count - 1 or linked) and k in problem.impulse_index and problem.max_impulse == 0.0
        if (soft_touchdown and name in problem.contacts_after(k)) or (k == count - 1 and problem.final is not None):
            held = held[held < last]
        if len(held):
            blocks.append(Point(index[np.ix_(held, velocity_columns)], velocities, len(axes), derivative=velocity_slopes,
                                nonlinear=np.arange(len(q_columns)), curvature=velocity_curvature))
        blocks.append(Point(index[np.ix_(knots, acceleration_columns)], accelerations, len(axes), derivative=acceleration_slopes,
                            nonlinear=np.arange(len(velocity_columns)), curvature=acceleration_curvature))
    return blocks


def foot_torque_blocks(problem: ContactModel, k: int) -> list[Block]:
    """Eq. 6 at every point of phase k, for each flat foot on the ground: c_i F_z - s T_i >= 0 for i = x, y, z
    and s = +-1, with c = support x (0.5 l_y, 0.5 l_x, mu_d) (`FlatFoot.support`); linear in the force and torque variables."""
    contacts = list(problem.phases[k].contacts)
    if not problem.flat_contacts(contacts):
        return []
    index = problem.point_index[k]
    forces = index[:, problem.force_columns[k]].reshape(len(index), -1, 3)
    torques = index[:, problem.torque_columns[k]].reshape(len(index), -1, 3)
    blocks: list[Block] = []
    for c, name in enumerate(problem.flat_contacts(contacts)):
        sole = problem.flat_feet[name]
        limit = sole.support * np.array([0.5 * sole.width, 0.5 * sole.length, sole.torsion])
        normal = forces[:, contacts.index(name), 2]
        for sign in (1.0, -1.0):
            rows = np.arange(3 * len(index))
            blocks.append(Linear(len(rows), np.r_[rows, rows], np.r_[np.repeat(normal, 3), torques[:, c].ravel()],
                                 np.r_[np.tile(limit, len(index)), np.full(len(rows), -sign)], lower=0.0, upper=np.inf))
    return blocks


class Feet:
    """The feet at the points of phase k, from one batched forward-kinematics difference over q: stance feet
    on the ground (height 0) and, with 3-D forces, at the foothold where the phase began (x, y) at every knot
    (with their velocities and accelerations: `stance_blocks`); swing tips at or above the ground (eq. 4) at
    every point. A flat foot's toe and side points (`FlatFoot`) are at height 0 in stance, the
    toe also at its first y (the sole flat and unturned), and at or above the ground in swing.

    A phase's first point is the previous phase's last (the same q, up to the periodic shift along the ground),
    so a foot's height there is stated once: a foot down on both sides of the boundary by the earlier phase,
    a lifting foot by the earlier phase's height = 0, a landing foot by the later phase's height = 0. Stating
    it twice would make the constraint Jacobian rank-deficient (LICQ fails; IPOPT's multipliers diverge)."""

    def __init__(self, problem: ContactModel, k: int) -> None:
        self.problem = problem
        index = problem.point_index[k]
        self.index = index[:, : problem.nq]
        names = problem.foot_names + list(problem.sole_points)
        owner = [problem.sole_points.get(name, name) for name in names]  # the foot a sole point belongs to
        self.names = names
        points, nq, count = len(index), problem.nq, len(names)
        tree, q_body, _ = problem.tree()
        ancestors = {name: tree[problem.foot_body[name]] for name in names}
        rows, cols, source, sign, unilateral, output, anchor_output = [], [], [], [], [], [], []
        row = 0

        def add(point: int, foot: int, axis: int, above: bool, anchor: bool) -> None:
            nonlocal row
            reach = np.flatnonzero(np.isin(q_body, list(ancestors[names[foot]])))
            flat = (point * count * 3 + foot * 3 + axis) * nq  # jac is (P, count * 3, nq)
            rows.append(np.full(len(reach), row))
            cols.append(index[point, reach])
            source.append(flat + reach)
            sign.append(np.ones(len(reach)))
            if anchor:  # minus the same coordinate at the phase's first point
                rows.append(np.full(len(reach), row))
                cols.append(index[0, reach])
                source.append((foot * 3 + axis) * nq + reach)
                sign.append(-np.ones(len(reach)))
            unilateral.append(above)
            output.append(point * count * 3 + foot * 3 + axis)
            anchor_output.append(foot * 3 + axis if anchor else -1)
            row += 1

        count_phases = len(problem.phases)
        linked = problem.periodic and count_phases > 1
        before = problem.contacts_before(k) if (k > 0 or linked) else None
        after = problem.contacts_after(k) if (k < count_phases - 1 or linked) else None
        for point in range(points):
            for foot, (name, foot_name) in enumerate(zip(names, owner)):
                if (point == 0 and before is not None and foot_name in before) or (
                        point == points - 1 and after is not None and foot_name in after and foot_name not in problem.phases[k].contacts):
                    continue  # the height at this shared point is stated by the neighbouring phase
                if foot_name in problem.phases[k].contacts:
                    if point % 2:  # a midpoint: the slack frees it (`ContactModel.rate`)
                        continue
                    add(point, foot, 2, False, False)
                    if name == foot_name and problem.force_dims == 3 and point > 0:
                        add(point, foot, 0, False, True)
                        add(point, foot, 1, False, True)
                    elif name.endswith("/toe") and point > 0:
                        add(point, foot, 1, False, True)
                else:
                    add(point, foot, 2, True, False)  # swing: height >= 0
        self.size = row
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)
        self._source, self._sign = np.concatenate(source), np.concatenate(sign)
        self.lower = np.zeros(row)
        self.upper = np.where(unilateral, problem.max_swing_height, 0.0)
        self._output, self._anchor = np.array(output), np.array(anchor_output)
        self._points = [(problem.foot_body[name], problem.foot_point[name]) for name in names]
        self.hessian_rows, self.hessian_cols, self._local = group_pattern(self.index, problem.q_without_translation)

    def _positions(self, q: np.ndarray) -> np.ndarray:
        return self.problem.foot_positions(q, self.names).reshape(len(q), -1)

    def values(self, x: np.ndarray) -> np.ndarray:
        positions = self._positions(x[self.index]).ravel()
        return positions[self._output] - np.where(self._anchor >= 0, positions[np.maximum(self._anchor, 0)], 0.0)

    def _slopes(self, q: np.ndarray) -> np.ndarray:
        """(B, feet x 3, nq): the positions' Jacobian at raw q (B, nq)."""
        problem = self.problem
        linear = kin.point_jacobians(problem.model, problem.configuration(q), self._points)[:, :, :3]  # (B, feet, 3, nv)
        return kin.raw(problem.model, q, linear.reshape(len(q), -1, problem.nv))

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        return self._sign * self._slopes(x[self.index]).ravel()[self._source]

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        q = x[self.index]
        # Each row's multiplier weighs its position and, for an anchored row, minus the first point's.
        anchored = self._anchor >= 0
        size = len(q) * 3 * len(self.names)
        weights = np.bincount(self._output, multipliers, minlength=size) - np.bincount(self._anchor[anchored], multipliers[anchored], minlength=size)
        return kin.position_curvature(self.problem.model, q, self._points, weights.reshape(len(q), -1, 3))[0].ravel()[self._local]
