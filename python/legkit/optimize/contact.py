"""Contact kinematics at the point variables of a `Layout` (`ContactModel`): the configuration map, the collocated
state rate and its derivatives, the feet's positions, wrenches, Jacobians and accelerations, the forward dynamics of a
guess (`pack`), from legkit's batched kernels (`legkit.optimize.kinematics`); and a mirrored half cycle unrolled onto
its whole cycle (`full_cycle`, `unroll`, `whole_cycle`), which replays and tracking start from."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TypeVar

import numpy as np

import legkit as lk
from legkit.optimize import kinematics as kin
from legkit.optimize.layout import Layout, Trajectory
from legkit.optimize.mirror import Mirror

#: A `ContactModel` of any class: the whole cycle of a problem is a problem of its class.
SelfModel = TypeVar("SelfModel", bound="ContactModel")


class ContactModel(Layout):
    """A `Layout` with the kernels its constraint families, objectives, replays and tracking evaluate: point variables
    to configurations, rates, foot positions, wrenches and contact Jacobians; the whole cycle of a mirrored half."""

    # ------------------------------------------------------------------ kernels
    def configuration(self, q: np.ndarray) -> np.ndarray:
        """q (B, nq) with a unit base quaternion: the kernels see a valid configuration whatever the iterate's norm."""
        return kin.unit(self.model, q)

    def q_rate(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """dq/dt (B, nq): base position rate R v_lin, quaternion rate, joint rates (`kinematics.q_rate`)."""
        return kin.q_rate(self.model, q, v)

    def foot_positions(self, q: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """World positions (..., len(names), 3) of the named feet."""
        poses = np.asarray(lk.forward_kinematics(self.model, self.configuration(q)))
        return np.stack([np.einsum("...ij,j->...i", poses[..., self.foot_body[n], :3, :3], self.foot_point[n])
                         + poses[..., self.foot_body[n], :3, 3] for n in names], axis=-2)

    def external_wrenches(self, q: np.ndarray, forces: np.ndarray, contacts: Sequence[str],
                          torques: np.ndarray | None = None) -> np.ndarray | None:
        """Body-frame wrenches (B, nbodies, 6) of the world-frame foot forces (B, len(contacts) * force_dims) and
        the flat feet's foot-frame torques (B, 3 x their count) at configurations q (B, nq, unit quaternion), as
        legkit's rnea/aba take them (None without contacts)."""
        # One row of feet, broadcast over the batch.
        return self.point_wrenches(q, forces, *self.contact_points([contacts]), torques)

    def contact_points(self, contacts: Sequence[Sequence[str]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per row of a batch, its feet on the ground (`contacts`, one sequence per row, all of one length and
        with as many flat feet): their bodies (B, count), points (B, count, 3) and the flat feet's bodies
        (B, flat count), as `point_wrenches` takes them."""
        rows = len(contacts)
        bodies = np.array([[self.foot_body[name] for name in row] for row in contacts], dtype=np.int64).reshape(rows, -1)
        points = np.array([[self.foot_point[name] for name in row] for row in contacts]).reshape(rows, -1, 3)
        flat = np.array([[self.foot_body[name] for name in self.flat_contacts(row)] for row in contacts], dtype=np.int64)
        return bodies, points, flat.reshape(rows, -1)

    def point_wrenches(self, q: np.ndarray, forces: np.ndarray, bodies: np.ndarray, points: np.ndarray, flat: np.ndarray,
                       torques: np.ndarray | None = None) -> np.ndarray | None:
        """`external_wrenches` with each row's feet as `contact_points` gives them (rows may differ in which
        feet are down; one row of feet broadcasts over q's)."""
        count = bodies.shape[1]
        if count == 0:
            return None
        poses = np.asarray(lk.forward_kinematics(self.model, q))
        world = self.world_forces(forces, count)
        f_ext = np.zeros((len(q), self.model.nbodies, 6))
        rows = np.arange(len(q))
        for c in range(count):  # a few feet; each line is batched over all points
            body = bodies[:, c]
            local = np.einsum("bji,bj->bi", poses[rows, body, :3, :3], world[:, c])
            f_ext[rows, body, :3] += local
            f_ext[rows, body, 3:] += np.cross(points[:, c], local)
        for c in range(flat.shape[1]):
            assert torques is not None, "flat feet on the ground need their torques"
            f_ext[rows, flat[:, c], 3:] += torques[:, 3 * c : 3 * c + 3]
        return f_ext

    def tau(self, u: np.ndarray) -> np.ndarray:
        """Generalised forces B u (B, nv) of the actuated torques u (B, nu)."""
        tau = np.zeros((len(u), self.nv))
        tau[:, self.actuated] = u
        return tau

    def forward_accelerations(self, z: np.ndarray, k: int) -> np.ndarray:
        """a = aba(q, v, B u, J_c^T lambda) (B, nv) at phase k's point variables z (B, nz, a and slack unused): eq. 1
        forward, for a guess that has no accelerations (`pack`)."""
        q, v = self.configuration(z[:, : self.nq]), z[:, self.nq : self.nx]
        contacts = self.phases[k].contacts
        f_ext = self.external_wrenches(q, z[:, self.force_columns[k]], contacts, z[:, self.torque_columns[k]])
        return np.asarray(lk.aba(self.model, q, v, self.tau(z[:, self.nx : self.nx + self.nu]), f_ext))

    def rate(self, z: np.ndarray, k: int) -> np.ndarray:
        """The collocated state rate (B, nx) at phase k's point variables: [dq/dt, a], a the accelerations (variables,
        whose dynamics are the RNEA residual rows). dq/dt is that of v + J_c^T slack, J_c the phase's `contact_rows`:
        the slack (zero at the knots, free at the midpoints) lets the stance feet be held at position, velocity and
        acceleration level at every knot without over-determining the collocation (Posa, Kuindersma & Tedrake 2016,
        DIRCON)."""
        q, v = z[:, : self.nq], z[:, self.nq : self.nx]
        slack = z[:, self.slack_columns[k]]
        if slack.shape[1]:
            v = v + np.einsum("bri,br->bi", self.contact_jacobian(q, self.phases[k].contacts), slack)
        return np.concatenate([self.q_rate(q, v), z[:, self.a_columns[k]]], axis=1)

    def rate_jacobian(self, z: np.ndarray, k: int) -> np.ndarray:
        """d `rate` / dz (B, nx, nz): the q rate's slopes in closed form (`kinematics.q_rate_derivatives`), the
        slack's J_c(q)^T slack by `kinematics.force_slope` (the slack acts like a force at the contact points)."""
        nq, nx, model = self.nq, self.nx, self.model
        q, v, slack = z[:, :nq], z[:, nq:nx], z[:, self.slack_columns[k]]
        jac = np.zeros((len(z), nx, z.shape[1]))
        jac[:, nq:, self.a_columns[k]] = np.eye(self.nv)
        if not slack.shape[1]:
            by_q, jac[:, :nq, nq:nx] = kin.q_rate_derivatives(model, q, v)
            jac[:, :nq, :nq] = by_q
            return jac
        contacts, unit = self.phases[k].contacts, self.configuration(q)
        points, full, contact = self.contact_frames(unit, contacts)
        forces = self.row_forces(slack, contacts)
        by_q, by_w = kin.q_rate_derivatives(model, q, v + np.einsum("bri,br->bi", contact, slack))
        jac[:, :nq, :nq] = by_q + by_w @ kin.raw(model, q, kin.force_slope(model, unit, points, forces, full))
        jac[:, :nq, nq:nx] = by_w
        jac[:, :nq, self.slack_columns[k]] = by_w @ np.swapaxes(contact, 1, 2)
        return jac

    def rate_gradient(self, z: np.ndarray, weights: np.ndarray, k: int) -> np.ndarray:
        """weights . d `rate` / dz (B, nz) for weights (B, nx): `rate_jacobian`'s vector product, without forming it
        (d(slack . J_c(q) u) / dq by the contact points' velocity derivatives at u)."""
        nq, nx, model = self.nq, self.nx, self.model
        q, v, slack = z[:, :nq], z[:, nq:nx], z[:, self.slack_columns[k]]
        out = np.zeros_like(z)
        out[:, self.a_columns[k]] = weights[:, nq:]
        on_q = weights[:, :nq]
        if not slack.shape[1]:
            by_q, by_w = kin.q_rate_derivatives(model, q, v)
            out[:, :nq] = kin.vecmat(on_q, by_q)
            out[:, nq:nx] = kin.vecmat(on_q, by_w)
            return out
        contacts, unit = self.phases[k].contacts, self.configuration(q)
        points, _, contact = self.contact_frames(unit, contacts)
        by_q, by_w = kin.q_rate_derivatives(model, q, v + np.einsum("bri,br->bi", contact, slack))
        u = kin.vecmat(on_q, by_w)
        forces = self.row_forces(slack, contacts)
        turning = sum(np.einsum("bk,bkj->bj", forces[:, c], kin.point_velocity_derivatives(model, unit, u, body, point)[0])
                      for c, (body, point) in enumerate(points))
        out[:, :nq] = kin.vecmat(on_q, by_q) + kin.raw(model, q, np.asarray(turning)[:, None, :])[:, 0]
        out[:, nq:nx] = u
        out[:, self.slack_columns[k]] = np.einsum("bri,bi->br", contact, u)
        return out

    def rate_curvature(self, z: np.ndarray, weights: np.ndarray, k: int) -> np.ndarray:
        """(B, nz, nz): the Hessian of weights (B, nx) . `rate` at phase k's point variables z. With R(q, w) the
        weighted q rate (`kinematics.q_rate_hessian`) at w = v + J_c(q)^T slack, u = dR/dw and W = dw/dq
        (`kinematics.force_slope`): d2/dq2 = R_qq + R_qw W + W^T R_wq + d2(slack . J_c(q) u)/dq2
        (`lk.point_velocity_hessian`), d2/dq dv = R_qw and d2/dq dslack = R_qw J_c^T + d(J_c u)/dq^T; R is linear in w."""
        nq, nx, model = self.nq, self.nx, self.model
        q, v, slack = z[:, :nq], z[:, nq:nx], z[:, self.slack_columns[k]]
        out = np.zeros((len(z), z.shape[1], z.shape[1]))
        on_q = weights[:, :nq]
        if not slack.shape[1]:
            out[:, :nx, :nx] = kin.q_rate_hessian(model, q, v, on_q)
            return out
        contacts, unit = self.phases[k].contacts, self.configuration(q)
        rows = self.contact_rows(contacts)
        points, full, contact = self.contact_frames(unit, contacts)
        w = v + np.einsum("bri,br->bi", contact, slack)
        rate = kin.q_rate_hessian(model, q, w, on_q)
        by_qw = rate[:, :nq, nq:]
        u = kin.vecmat(on_q, kin.q_rate_derivatives(model, q, w)[1])
        forces = self.row_forces(slack, contacts)
        turning = kin.raw(model, q, kin.force_slope(model, unit, points, forces, full))  # W (B, nv, nq)
        curvature, gradient = np.zeros((len(z), self.nv, self.nv)), np.zeros((len(z), self.nv))
        velocity_slopes = []
        for c, (body, point, axes) in enumerate(rows):
            power_qq, power_q = lk.point_velocity_hessian(model, unit, u, body, point, forces[:, c])
            curvature, gradient = curvature + np.asarray(power_qq), gradient + np.asarray(power_q)
            velocity_slopes.append(kin.point_velocity_derivatives(model, unit, u, body, point)[0][:, axes])
        cross = by_qw @ turning
        out[:, :nq, :nq] = rate[:, :nq, :nq] + cross + np.swapaxes(cross, 1, 2) + kin.raw_hessian(model, q, curvature, gradient)
        out[:, :nq, nq:nx] = by_qw
        with_slack = by_qw @ np.swapaxes(contact, 1, 2) + np.swapaxes(kin.raw(model, q, np.concatenate(velocity_slopes, axis=1)), 1, 2)
        out[:, :nq, self.slack_columns[k]] = with_slack
        out[:, nq:nx, :nq] = np.swapaxes(by_qw, 1, 2)
        out[:, self.slack_columns[k], :nq] = np.swapaxes(with_slack, 1, 2)
        return out

    def rate_dependence(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(nx, nz) bool twice: which point variables each component of `rate` depends on (structurally), and
        which of those it equals (a joint's q rate its v, the v rate its a)."""
        nq, nx = self.nq, self.nx
        nz = self.point_index[k].shape[1]
        dependence = np.zeros((nx, nz), dtype=bool)
        identity = np.zeros((nx, nz), dtype=bool)
        if self.model.floating_base:
            dependence[0:3, 3:7] = dependence[0:3, nq : nq + 3] = True  # R(quaternion) v_lin
            dependence[3:7, 3:7] = dependence[3:7, nq + 3 : nq + 6] = True  # quaternion (x) omega / 2
            identity[7:nq, nq + 6 : nx] = np.eye(nq - 7, dtype=bool)
        else:
            identity[:nq, nq:nx] = np.eye(nq, dtype=bool)
        identity[nq:, self.a_columns[k]] = np.eye(self.nv, dtype=bool)
        # The slack's J_c^T slack moves the q rates of each held point's chain, through its q (not a free-flyer's position).
        ancestors, q_body, _ = self.tree()
        column = self.slack_columns[k].start
        for body, _, axes in self.contact_rows(self.phases[k].contacts):
            chain = list(ancestors[body])
            q_columns = self.q_without_translation[np.isin(q_body[self.q_without_translation], chain)]
            dependence[np.ix_(np.flatnonzero(np.isin(q_body, chain)), np.r_[q_columns, column + np.arange(len(axes))])] = True
            column += len(axes)
        return dependence | identity, identity

    def contact_frames(self, q: np.ndarray, contacts: Sequence[str]) -> tuple[list[kin.ContactPoint], np.ndarray, np.ndarray]:
        """The named feet's `contact_rows` at unit q (B, nq): their points, the points' world-aligned Jacobians
        (B, points, 6, nv) and the rows' linear Jacobian (B, r, nv) (`contact_jacobian`)."""
        rows = self.contact_rows(contacts)
        points = [(body, point) for body, point, _ in rows]
        full = kin.point_jacobians(self.model, q, points)
        return points, full, np.concatenate([full[:, i, axes] for i, (_, _, axes) in enumerate(rows)], axis=1)

    def contact_jacobian(self, q: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """(B, r, nv): the world-aligned linear Jacobians of the `contact_rows` of the named feet at q (B, nq)."""
        q = self.configuration(q)
        return np.concatenate([np.asarray(lk.jacobian(self.model, q, body, point, "local_world_aligned"))[:, axes]
                               for body, point, axes in self.contact_rows(contacts)], axis=1)

    def pack(self, trajectory: Trajectory) -> np.ndarray:
        """The variable vector of a trajectory (an initial guess or a neighbouring problem's solution)."""
        x = np.zeros(self.n)
        for k, index in enumerate(self.point_index):
            parts = [trajectory.q[k], trajectory.v[k], trajectory.u[k]]
            count = len(self.phases[k].contacts)
            forces = np.asarray(trajectory.forces[k], dtype=np.float64).reshape(len(index), count, 3)
            parts.append((forces if self.force_dims == 3 else forces[..., 2:]).reshape(len(index), -1))
            flat = len(self.flat_contacts(self.phases[k].contacts))
            parts.append(np.zeros((len(index), 3 * flat)) if trajectory.torques is None else trajectory.torques[k])
            z = np.concatenate([np.asarray(p, dtype=np.float64).reshape(len(index), -1) for p in parts], axis=1)
            a = trajectory.a[k] if trajectory.a is not None else self.forward_accelerations(z, k)
            z = np.concatenate([z, np.asarray(a, dtype=np.float64).reshape(len(index), -1)], axis=1)
            slack = np.zeros((len(index), index.shape[1] - z.shape[1])) if trajectory.slack is None else trajectory.slack[k]
            z = np.concatenate([z, np.asarray(slack, dtype=np.float64).reshape(len(index), -1)], axis=1)
            if z.shape != index.shape:
                raise ValueError(f"trajectory phase {k} has {z.shape} point values, the problem needs {index.shape}")
            x[index] = z
        x[self.duration_index] = trajectory.durations
        x[self.p1_index] = trajectory.stability_bound
        for k, index in self.impulse_index.items():  # least-squares impulses of the trajectory's own velocity jump
            end, start = self.point_index[k][-1], self.start_seen_from(k)
            q = x[end[: self.nq]][None]
            jump = np.asarray(lk.crba(self.model, self.configuration(q)))[0] @ (start.v_sign * x[start.v] - x[end[self.nq : self.nx]])
            x[index] = np.linalg.lstsq(self.contact_jacobian(q, self.contacts_after(k))[0].T, jump, rcond=None)[0]
        return x

    def stance_accelerations(self, x: np.ndarray) -> list[np.ndarray]:
        """Per phase (points, stance feet, 3): the world acceleration J a + dJ/dt v (`lk.point_accelerations`) of
        each stance foot's point at the point's state and accelerations a (`accelerations`). A motion holds its stance
        feet at rest, so these are zero on it."""
        out = []
        for k, phase in enumerate(self.phases):
            z = x[self.point_index[k]]
            held = [(self.foot_body[name], self.foot_point[name]) for name in phase.contacts]
            if not held:
                out.append(np.zeros((len(z), 0, 3)))
                continue
            q, v = self.configuration(z[:, : self.nq]), z[:, self.nq : self.nx]
            out.append(np.asarray(lk.point_accelerations(self.model, q, v, self.accelerations(z, k), held)))
        return out

    def full_cycle(self: SelfModel) -> SelfModel:
        """The same gait over its whole cycle without a mirror (self when there is none): what `unroll`'s
        trajectories are solutions of."""
        if self.mirror is None:
            return self
        return replace(self, phases=self.cycle_phases(), mirror=None)

    def unroll(self, trajectory: Trajectory) -> Trajectory:
        """A mirrored half cycle followed by its mirror image, moved on by the half cycle's time and travel: the
        whole cycle, as `full_cycle()` transcribes it (the trajectory itself when there is no mirror)."""
        mirror = self.mirror
        if mirror is None:
            return trajectory
        half = float(np.sum(trajectory.durations))
        shift, scale = np.zeros(self.nq), np.ones(self.nq)
        if self.travel_index is not None:
            shift[self.travel_index] = self.speed * half
        if self.model.floating_base:
            # The half cycle's wrap-around states the quaternion by direction (its norm drifts within the defects'
            # error), the whole cycle's middle boundary all four components: the mirror image takes the end's norm.
            scale[3:7] = np.linalg.norm(trajectory.q[-1][-1, 3:7]) / np.linalg.norm(trajectory.q[0][0, 3:7])
        u_order, u_sign = mirror.control_order(np.asarray(self.actuated, dtype=np.int64))

        def twice(parts: list[np.ndarray], mirrored: Callable[[np.ndarray], np.ndarray]) -> list[np.ndarray]:
            return list(parts) + [mirrored(np.asarray(p)) for p in parts]

        def controls(u: np.ndarray) -> np.ndarray:
            return u_sign * u[..., u_order]

        a, torques, slack = trajectory.a, trajectory.torques, trajectory.slack
        q = twice(trajectory.q, lambda q: scale * mirror.q(q) + shift)
        if slack is not None:  # the mirror image of the correction J_c^T slack, in the mirrored feet's rows
            slack = list(slack)
            for k, phase in enumerate(self.phases):
                mirrored = mirror.contacts(phase.contacts)
                correction = mirror.v(np.einsum("bri,br->bi", self.contact_jacobian(trajectory.q[k], phase.contacts), slack[k]))
                rows = self.contact_jacobian(q[len(self.phases) + k], mirrored)
                slack.append(np.einsum("bri,bi->br", np.linalg.pinv(np.swapaxes(rows, 1, 2)), correction))
        return Trajectory(
            twice(trajectory.t, lambda t: t + half), q,
            twice(trajectory.v, mirror.v), twice(trajectory.u, controls), twice(trajectory.forces, Mirror.vectors),
            np.concatenate([trajectory.durations, trajectory.durations]), trajectory.stability_bound,
            None if a is None else twice(a, mirror.v), None if torques is None else twice(torques, Mirror.axial), slack,
        )

    def whole_trajectory(self: SelfModel, trajectory: Trajectory) -> tuple[SelfModel, Trajectory]:
        """`whole_cycle` for a trajectory: the whole cycle's problem and the trajectory unrolled over it (both as given
        without a mirror). Whatever samples or replays a gait periodically starts here, so a half cycle is never
        repeated as if it were the whole."""
        return self.full_cycle(), self.unroll(trajectory)

    def whole_cycle(self: SelfModel, x: np.ndarray) -> tuple[SelfModel, np.ndarray]:
        """A point x of this problem as the whole cycle's problem (`full_cycle`) and its point: unrolled if this is a
        mirrored half cycle (`unroll`), so that what follows (outputs, the violation re-evaluated, a replay) sees the
        whole gait."""
        if self.mirror is None:
            return self, x
        whole = self.full_cycle()
        return whole, whole.pack(self.unroll(self.unpack(x)))

