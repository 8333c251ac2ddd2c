"""Eq. 1 of [Hardt 2002] in a multiphase transcription: the Hermite–Simpson defects of every phase (`Defects`), its
controls linear on each interval (`control_blocks`), and the inverse dynamics at every point (`InverseDynamics`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import legkit as lk
from legkit.optimize import kinematics as kin
from legkit.optimize.blocks import Block, Linear, group_hessian, group_pattern
from legkit.optimize.collocation import hermite_simpson_defects
from legkit.optimize.contact import ContactModel


def control_blocks(problem: ContactModel, k: int) -> list[Block]:
    """Linear controls on each interval of phase k (eq. 14): u_m = (u_k + u_k+1) / 2."""
    nx, nu, phase, index = problem.nx, problem.nu, problem.phases[k], problem.point_index[k]
    if not nu:
        return []
    u = slice(nx, nx + nu)
    rows = np.arange(phase.intervals * nu)
    return [Linear(len(rows), np.tile(rows, 3),
                   np.concatenate([index[1::2, u].ravel(), index[0:-1:2, u].ravel(), index[2::2, u].ravel()]),
                   np.r_[np.ones(len(rows)), -0.5 * np.ones(2 * len(rows))])]


def inverse_dynamics_blocks(problem: ContactModel) -> list[Block]:
    """`InverseDynamics` over every phase: one block, one RNEA call, per layout of the point variables."""
    layouts: dict[tuple[int, int], list[int]] = {}  # one block, one RNEA call, per layout of the point variables
    for k, phase in enumerate(problem.phases):
        layouts.setdefault((len(phase.contacts), len(problem.flat_contacts(phase.contacts))), []).append(k)
    return [InverseDynamics(problem, ks) for ks in layouts.values()]


class Defects:
    """The Hermite–Simpson defects of one phase (`collocation` docstring); h = T / intervals, T a variable."""

    def __init__(self, problem: ContactModel, k: int) -> None:
        self.problem, self.k = problem, k
        index = problem.point_index[k]
        self.index, self.duration, self.intervals = index, problem.duration_index[k], problem.phases[k].intervals
        nx, nz = problem.nx, index.shape[1]
        self.size = 2 * nx * self.intervals
        self.lower = self.upper = np.zeros(self.size)
        # Structural pattern of one interval: rows [interpolation; Simpson] x cols [z_a, z_m, z_b, T].
        dependence, _ = problem.rate_dependence(k)
        select = np.zeros((nx, nz), dtype=bool)
        select[:, :nx] = np.eye(nx, dtype=bool)
        column = np.ones((nx, 1), dtype=bool)
        self.mask = np.block([[select | dependence, select, select | dependence, column],
                              [select | dependence, dependence, select | dependence, column]])
        interval = np.arange(self.intervals)
        cols = np.concatenate([index[2 * interval], index[2 * interval + 1], index[2 * interval + 2],
                               np.full((self.intervals, 1), self.duration)], axis=1)  # (N, 3 nz + 1)
        r, c = np.nonzero(self.mask)
        self.rows = (interval[:, None] * 2 * nx + r[None]).ravel()
        self.cols = cols[:, c].ravel()
        self._r, self._c = r, c
        # Curvature: each point's weighted rate (`ContactModel.rate_curvature`), linear in v, a and the slack for a given q
        # (v + J_c(q)^T slack enters R(q) v_lin, q (x) w and the joint rates linearly), so every entry pairs with q; and T
        # with every variable the rate depends on (the defects hold h f = T f / N).
        self._nonlinear = problem.q_without_translation
        self._seen = np.flatnonzero(dependence.any(axis=0))
        rows_h, cols_h, self._local = group_pattern(index, self._nonlinear)
        self.hessian_rows = np.concatenate([rows_h, np.full(index[:, self._seen].size, self.duration)])
        self.hessian_cols = np.concatenate([cols_h, index[:, self._seen].ravel()])

    def values(self, x: np.ndarray) -> np.ndarray:
        z = x[self.index]
        rates, states = self.problem.rate(z, self.k), z[:, : self.problem.nx]
        interpolation, simpson = hermite_simpson_defects(states[0::2], states[1::2], rates[0::2], rates[1::2],
                                                         x[self.duration] / self.intervals)
        return np.concatenate([interpolation, simpson], axis=1).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        nx, n_int = self.problem.nx, self.intervals
        z = x[self.index]
        rates, jac = self.problem.rate(z, self.k), self.problem.rate_jacobian(z, self.k)
        nz = z.shape[1]
        h = x[self.duration] / n_int
        eye = np.zeros((nx, nz))
        eye[:, :nx] = np.eye(nx)
        ja, jm, jb = jac[0:-1:2], jac[1::2], jac[2::2]
        fa, fm, fb = rates[0:-1:2], rates[1::2], rates[2::2]
        block = np.zeros((n_int, 2 * nx, 3 * nz + 1))
        block[:, :nx, :nz] = -0.5 * eye - h / 8.0 * ja
        block[:, :nx, nz : 2 * nz] = eye
        block[:, :nx, 2 * nz : 3 * nz] = -0.5 * eye + h / 8.0 * jb
        block[:, :nx, -1] = -(fa - fb) / (8.0 * n_int)
        block[:, nx:, :nz] = -eye - h / 6.0 * ja
        block[:, nx:, nz : 2 * nz] = -4.0 * h / 6.0 * jm
        block[:, nx:, 2 * nz : 3 * nz] = eye - h / 6.0 * jb
        block[:, nx:, -1] = -(fa + 4.0 * fm + fb) / (6.0 * n_int)
        return block[:, self._r, self._c].ravel()

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        problem, k = self.problem, self.k
        z, duration = x[self.index], x[self.duration]
        h = duration / self.intervals
        interpolation, simpson = np.moveaxis(multipliers.reshape(self.intervals, 2, problem.nx), 1, 0)
        weights = np.zeros((len(z), problem.nx))  # of each point's rate in sum mu . defects (knots in two intervals)
        weights[0:-1:2] -= h * (interpolation / 8.0 + simpson / 6.0)
        weights[1::2] -= h * 4.0 * simpson / 6.0
        weights[2::2] += h * (interpolation / 8.0 - simpson / 6.0)
        curvature = problem.rate_curvature(z, weights, k)
        by_duration = problem.rate_gradient(z, weights, k) / duration
        return np.concatenate([curvature.ravel()[self._local], by_duration[:, self._seen].ravel()])


class InverseDynamics:
    """Eq. 1 in inverse-dynamics form at every point of the phases ks (phases with one layout of the point
    variables: as many feet, and flat feet, on the ground): rnea(q, v, a, J_c^T lambda) - B u = 0 (nv rows per
    point). d/d(q, v) by `lk.rnea_derivatives` in one batched call for all of them, with the world-fixed foot
    forces' turning term (`kinematics.force_slope`); the rows are affine in a, u and the foot loads: d/da = M(q)
    (`crba`), d/du = -B, d/dlambda = -J^T (each foot point's world-aligned linear Jacobian) and, for a flat foot's
    torques, -J_w^T (its body's angular Jacobian in the body frame). No row depends on a free-flyer's position.
    The pattern follows the tree (`Layout.tree_dependence`)."""

    def __init__(self, problem: ContactModel, ks: Sequence[int]) -> None:
        self.problem, self.ks = problem, list(ks)
        nq, nv, nx, nu = problem.nq, problem.nv, problem.nx, problem.nu
        self.index = np.concatenate([problem.point_index[k] for k in self.ks])
        points, nz = self.index.shape
        self.size = points * nv
        self.lower = self.upper = np.zeros(self.size)
        first = self.ks[0]  # the layout is the same in every phase of the block
        self.force_columns, self.torque_columns = problem.force_columns[first], problem.torque_columns[first]
        self.a_columns = problem.a_columns[first]
        vv, vq, reach = problem.tree_dependence()
        forces = np.arange(nz)[self.force_columns].reshape(-1, problem.force_dims)
        torques = np.arange(nz)[self.torque_columns].reshape(-1, 3)
        self.forces, self.torques = forces, torques
        # Per phase: its points in the block, its contacts and the nonzeros (r, c) of one point's rows.
        self._parts: list[tuple[slice, tuple[str, ...], np.ndarray, np.ndarray]] = []
        rows, cols, contacts = [], [], []
        start = 0
        for k in self.ks:
            phase_contacts = problem.phases[k].contacts
            mask = np.zeros((nv, nz), dtype=bool)
            mask[:, :nq], mask[:, nq:nx], mask[:, self.a_columns] = vq, vv, vv
            mask[problem.actuated, nx + np.arange(nu)] = True
            for c, name in enumerate(phase_contacts):
                mask[np.ix_(reach[name], forces[c])] = True
            for c, name in enumerate(problem.flat_contacts(phase_contacts)):
                mask[np.ix_(reach[name], torques[c])] = True
            r, nonzero_cols = np.nonzero(mask)
            count = len(problem.point_index[k])
            rows.append(((start + np.arange(count))[:, None] * nv + r[None]).ravel())
            cols.append(problem.point_index[k][:, nonzero_cols].ravel())
            self._parts.append((slice(start, start + count), phase_contacts, r, nonzero_cols))
            contacts += [phase_contacts] * count
            start += count
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)
        self.feet = problem.contact_points(contacts)
        # Curvature (`curvature`): the rows are nonlinear in q (not a free-flyer's position) and v only.
        self._nonlinear = problem.q_without_translation
        patterns = [group_pattern(self.index[points], np.r_[self._nonlinear, nq:nx]) for points, *_ in self._parts]
        self.hessian_rows = np.concatenate([rows for rows, _, _ in patterns])
        self.hessian_cols = np.concatenate([cols for _, cols, _ in patterns])
        self._local = [local for _, _, local in patterns]

    def residual(self, z: np.ndarray, feet: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
        """The rows at the block's point variables z (B, nz), row b with the feet of row b of `feet`
        (`ContactModel.contact_points`) down."""
        problem = self.problem
        q = problem.configuration(z[:, : problem.nq])
        f_ext = problem.point_wrenches(q, z[:, self.force_columns], *feet, z[:, self.torque_columns])
        generalized = np.asarray(lk.rnea(problem.model, q, z[:, problem.nq : problem.nx], z[:, self.a_columns], f_ext))
        return generalized - problem.tau(z[:, problem.nx : problem.nx + problem.nu])

    def values(self, x: np.ndarray) -> np.ndarray:
        return self.residual(x[self.index], self.feet).ravel()

    def dense(self, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """(B, nv, nz): the rows' Jacobian at point variables z (B, nz) with `contacts` down."""
        problem, model = self.problem, self.problem.model
        nq, nx = problem.nq, problem.nx
        q = problem.configuration(z[:, :nq])
        f_ext = problem.point_wrenches(q, z[:, self.force_columns], *problem.contact_points([contacts]), z[:, self.torque_columns])
        by_q, by_v = (np.asarray(d) for d in lk.rnea_derivatives(model, q, z[:, nq:nx], z[:, self.a_columns], f_ext))
        jac = np.zeros((len(z), problem.nv, z.shape[1]))
        jac[:, :, nq:nx] = by_v
        jac[:, :, self.a_columns] = np.asarray(lk.crba(model, q))
        jac[:, problem.actuated, nx + np.arange(problem.nu)] = -1.0
        forces = problem.world_forces(z[:, self.force_columns], len(contacts))
        axes = slice(3 - problem.force_dims, 3)  # the world axes the force variables hold
        full = kin.point_jacobians(model, q, [(problem.foot_body[name], problem.foot_point[name]) for name in contacts])
        for foot in range(len(contacts)):
            jac[:, :, self.forces[foot]] = -np.swapaxes(full[:, foot, axes], 1, 2)
        # rnea_derivatives holds the loads in their bodies' frames; the forces are world-fixed (`force_slope`).
        by_q -= np.einsum("bcki,bckl,bclj->bij", full[:, :, :3], kin.skew(forces), full[:, :, 3:])
        for foot, name in enumerate(problem.flat_contacts(contacts)):
            angular = np.asarray(lk.jacobian(model, q, problem.foot_body[name], None, "local"))
            jac[:, :, self.torques[foot]] = -angular[:, 3:].transpose(0, 2, 1)
        jac[:, :, :nq] = kin.raw(model, z[:, :nq], by_q)
        return jac

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        z = x[self.index]
        return np.concatenate([self.dense(z[points], contacts)[:, r, c].ravel() for points, contacts, r, c in self._parts])

    def hessian(self, x: np.ndarray, multipliers: np.ndarray) -> np.ndarray:
        z, weights = x[self.index], multipliers.reshape(len(self.index), self.problem.nv)
        return np.concatenate([self.curvature(z[points], weights[points], contacts).ravel()[local]
                               for (points, contacts, _, _), local in zip(self._parts, self._local)])

    def curvature(self, z: np.ndarray, weights: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """(B, nz, nz): the Hessian of weights . rows at point variables z with `contacts` down. The RNEA's share from
        `lk.rnea_second_order_derivatives` and the foot forces' -F . J(q) w from `lk.point_velocity_hessian` (mapped to
        raw q: `kinematics.raw_hessian`); the loads cross with q by the feet's velocity derivatives at w; a flat foot's
        -T . J_w(q) w curves in q by differences of its exact slope (`group_hessian`)."""
        problem, model = self.problem, self.problem.model
        nq, nx = problem.nq, problem.nx
        q_raw, v, a = z[:, :nq], z[:, nq:nx], z[:, self.a_columns]
        q = problem.configuration(q_raw)
        by_qq, by_vv, by_qv, by_aq = (np.einsum("bi,bijk->bjk", weights, np.asarray(t)) for t in lk.rnea_second_order_derivatives(model, q, v, a))
        tangent = kin.tangent_map(model, q_raw)
        out = np.zeros((len(z), z.shape[1], z.shape[1]))
        if problem.flat_contacts(contacts):
            out += group_hessian(lambda zz, ww: self._torque_slope(zz, ww, contacts), z, weights, self._nonlinear)
        by_q = kin.vecmat(weights, np.asarray(lk.rnea_derivatives(model, q, v, a)[0]))
        forces = problem.world_forces(z[:, self.force_columns], len(contacts))
        for foot, name in enumerate(contacts):  # the forces' virtual power -F . J(q) w
            power_qq, power_q = lk.point_velocity_hessian(model, q, weights, problem.foot_body[name], problem.foot_point[name], forces[:, foot])
            by_qq, by_q = by_qq - np.asarray(power_qq), by_q - np.asarray(power_q)
        out[:, :nq, :nq] += kin.raw_hessian(model, q_raw, by_qq, by_q)
        out[:, nq:nx, nq:nx] += by_vv
        cross: list[tuple[slice | np.ndarray, np.ndarray]] = [(slice(nq, nx), np.swapaxes(tangent, 1, 2) @ by_qv),
                                                              (self.a_columns, np.swapaxes(by_aq @ tangent, 1, 2))]
        for loads, slope in zip(self._load_columns(contacts), self._load_velocity_slopes(q, weights, contacts)):
            cross.append((loads, -np.swapaxes(kin.raw(model, q_raw, slope), 1, 2)))
        for columns, block in cross:  # (B, nq, len(columns)): with q
            out[:, :nq, columns] += block
            out[:, columns, :nq] += np.swapaxes(block, 1, 2)
        return out

    def _load_columns(self, contacts: Sequence[str]) -> list[np.ndarray]:
        """The point variables of each foot's force, then of each flat foot's torques (`_load_velocity_slopes`' order)."""
        flat = self.problem.flat_contacts(contacts)
        return [self.forces[foot] for foot in range(len(contacts))] + [self.torques[foot] for foot in range(len(flat))]

    def _load_velocity_slopes(self, q: np.ndarray, weights: np.ndarray, contacts: Sequence[str]) -> list[np.ndarray]:
        """At unit q, d/dq (tangent) of each foot point's world velocity J w along the force variables' axes
        (B, force_dims, nv), then of each flat foot's body-frame angular velocity (`_torque_velocity_slopes`)."""
        problem = self.problem
        axes = slice(3 - problem.force_dims, 3)
        slopes = [kin.point_velocity_derivatives(problem.model, q, weights, problem.foot_body[name], problem.foot_point[name])[0][:, axes]
                  for name in contacts]
        return slopes + self._torque_velocity_slopes(q, weights, contacts)

    def _torque_velocity_slopes(self, q: np.ndarray, weights: np.ndarray, contacts: Sequence[str]) -> list[np.ndarray]:
        """At unit q, d/dq (tangent) of each flat foot's body-frame angular velocity J_w w (B, 3, nv)."""
        problem = self.problem
        return [np.asarray(lk.frame_velocity_derivatives(problem.model, q, weights, problem.foot_body[name], None, "local")[0])[:, 3:]
                for name in problem.flat_contacts(contacts)]

    def _torque_slope(self, z: np.ndarray, weights: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """(B, nz): d/dq_raw of the flat feet's -T . J_w(q) w at point variables z (zero elsewhere)."""
        problem = self.problem
        q = problem.configuration(z[:, : problem.nq])
        columns, slopes = self._load_columns(contacts)[len(contacts) :], self._torque_velocity_slopes(q, weights, contacts)
        tangent = -sum(np.einsum("br,bra->ba", z[:, c], slope) for c, slope in zip(columns, slopes))
        out = np.zeros_like(z)
        out[:, : problem.nq] = kin.raw(problem.model, z[:, : problem.nq], tangent[:, None])[:, 0]
        return out
