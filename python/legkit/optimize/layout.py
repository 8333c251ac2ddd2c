"""The variables of a multiphase transcription (`Layout`): per phase a grid of point variables z = [q, v, u, forces,
torques, a, slack] at the knots and midpoints, then the phase durations, p1 and the touchdown impulses; which columns
hold what, the feet's contact rows, the model's tree, and `Trajectory`, the variables unpacked."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from legkit._validation import float_array
from legkit.optimize.definition import ProblemDefinition


@dataclass
class Trajectory:
    """The variables of a transcription, per phase: times t (P,), q (P, nq), v (P, nv), u (P, nu), forces
    (P, c, 3) on the phase's feet (world frame), the phase durations, the accelerations a (P, nv) (None: `pack`
    takes them from the forward dynamics of q, v, u, forces), and
    the torques (P, c_flat, 3) on the phase's flat feet (`FlatFoot`, foot frame; None: zero), and the slack (P, r) of
    the phase's `contact_rows` (`ContactModel.rate`; None: zero)."""

    t: list[np.ndarray]
    q: list[np.ndarray]
    v: list[np.ndarray]
    u: list[np.ndarray]
    forces: list[np.ndarray]
    durations: np.ndarray
    stability_bound: float = 0.0  # p1 of the min-max objective J_s2 (0 when unused)
    a: list[np.ndarray] | None = None
    torques: list[np.ndarray] | None = None
    slack: list[np.ndarray] | None = None

    def stacked(self) -> dict[str, np.ndarray]:
        """Every point of every phase in time order (the shared phase-boundary instants appear twice)."""
        return {"t": np.concatenate(self.t), "q": np.concatenate(self.q), "v": np.concatenate(self.v),
                "u": np.concatenate(self.u), "phase": np.concatenate([np.full(len(t), k) for k, t in enumerate(self.t)])}



@dataclass(frozen=True)
class Start:
    """The point after a phase boundary, as the phase before sees it: the variables of its q, v and u and the
    signs that turn them into the earlier phase's frame (all 1, except across the wrap-around of a mirrored
    half cycle, where q_sign * x[q] is the mirror of the start's configuration, and so on)."""

    q: np.ndarray
    q_sign: np.ndarray
    v: np.ndarray
    v_sign: np.ndarray
    u: np.ndarray
    u_sign: np.ndarray


class Layout(ProblemDefinition):
    """A `ProblemDefinition`'s variables: their sizes (nq, nv, nx, nu, n), the index of every point's variables
    (`point_index`, per phase (points, nz)) and the columns of z that hold the forces, torques, accelerations and
    slack, the durations', p1's and the impulses' indices; the feet's bodies and points; `unpack`."""

    def __post_init__(self) -> None:
        super().__post_init__()
        model = self.model
        self.nq, self.nv = model.nq, model.nv
        self.nx = self.nq + self.nv
        # The q a point's dynamics, momentum and impact depend on: all but a free-flyer's position, as they
        # (and the feet's positions relative to each other and to the COM) are the same wherever the robot is.
        self.q_without_translation = np.arange(3 if model.floating_base else 0, self.nq)
        assert self.actuated is not None  # _validate makes it a list
        self.nu = len(self.actuated)
        self.foot_names = list(self.feet)
        self.foot_body = {name: (model.names.index(b) if isinstance(b, str) else int(b)) for name, (b, _) in self.feet.items()}
        self.foot_point = {name: np.asarray(p, dtype=np.float64) for name, (_, p) in self.feet.items()}
        # A flat sole's toe and side points (FlatFoot): with the centre they fix the sole's pose in stance.
        self.sole_points: dict[str, str] = {}
        for name, sole in self.flat_feet.items():
            for label, shift in (("toe", [0.5 * sole.length, 0.0, 0.0]), ("side", [0.0, 0.5 * sole.width, 0.0])):
                self.foot_body[f"{name}/{label}"] = self.foot_body[name]
                self.foot_point[f"{name}/{label}"] = self.foot_point[name] + shift
                self.sole_points[f"{name}/{label}"] = name
        # Variable layout: per phase a (P, nz) block of point variables z = [q, v, u, forces, torques, a, slack]
        # (torques on flat feet only, slack: one per `contact_rows` row,
        # used at the midpoints only: `rate`), then the durations, then p1.
        self.point_index: list[np.ndarray] = []
        self.force_columns: list[slice] = []
        self.torque_columns: list[slice] = []
        self.a_columns: list[slice] = []
        self.slack_columns: list[slice] = []
        offset = 0
        for phase in self.phases:
            forces = self.nx + self.nu + self.force_dims * len(phase.contacts)
            torques = forces + 3 * len(self.flat_contacts(phase.contacts))
            accelerations = torques + self.nv
            nz = accelerations + sum(len(axes) for _, _, axes in self.contact_rows(phase.contacts))
            self.force_columns.append(slice(self.nx + self.nu, forces))
            self.torque_columns.append(slice(forces, torques))
            self.a_columns.append(slice(torques, accelerations))
            self.slack_columns.append(slice(accelerations, nz))
            points = 2 * phase.intervals + 1
            self.point_index.append(offset + np.arange(points * nz).reshape(points, nz))
            offset += points * nz
        self.duration_index = offset + np.arange(len(self.phases))
        self.p1_index = offset + len(self.phases)
        # Then the impulses (world frame, force_dims per foot of the new phase, like the forces) of every
        # touchdown (eq. 7), by boundary.
        offset = self.p1_index + 1
        self.impulse_index: dict[int, np.ndarray] = {}
        count = len(self.phases)
        for k in range(count if self.periodic else count - 1):
            after = self.contacts_after(k)
            if set(after) - set(self.phases[k].contacts):
                size = self.force_dims * len(after) + 3 * len(self.flat_contacts(after))  # `contact_rows`
                self.impulse_index[k] = offset + np.arange(size)
                offset += size
        self.n = offset

    def contacts_after(self, k: int) -> tuple[str, ...]:
        """The feet down after the boundary that ends phase k, named as phase k sees them: at the wrap-around
        of a mirrored half cycle, the mirror of the first phase's."""
        after = (k + 1) % len(self.phases)
        if after == 0 and self.mirror is not None:
            return self.mirror.contacts(self.phases[0].contacts)
        return tuple(self.phases[after].contacts)

    def contacts_before(self, k: int) -> tuple[str, ...]:
        """The feet down before the boundary that starts phase k, named as phase k sees them."""
        if k == 0 and self.mirror is not None:
            return self.mirror.contacts(self.phases[-1].contacts)
        return tuple(self.phases[k - 1].contacts)

    def world_forces(self, forces: np.ndarray, count: int) -> np.ndarray:
        """(B, count, 3) world forces from the (B, count * force_dims) force variables."""
        forces = forces.reshape(forces.shape[0], count, self.force_dims)
        if self.force_dims == 3:
            return forces
        return np.concatenate([np.zeros(forces.shape[:-1] + (2,)), forces], axis=-1)

    def flat_contacts(self, contacts: Sequence[str]) -> list[str]:
        """The flat feet (`FlatFoot`) among contacts, in their order: the owners of the torque variables."""
        return [name for name in contacts if name in self.flat_feet]

    def accelerations(self, z: np.ndarray, k: int) -> np.ndarray:
        """a (B, nv) at phase k's point variables."""
        return z[:, self.a_columns[k]]

    def tree(self) -> tuple[list[set[int]], np.ndarray, np.ndarray]:
        """(each body's ancestors including itself, the body of each q index, the body of each v index)."""
        model = self.model
        ancestors = []
        for i in range(model.nbodies):
            chain, j = {i}, i
            while j > 0:
                j = model.parents[j]
                chain.add(j)
            ancestors.append(chain)
        bodies = np.arange(model.nbodies)
        return (ancestors, np.repeat(bodies, np.diff(list(model.idx_q) + [model.nq])),
                np.repeat(bodies, np.diff(list(model.idx_v) + [model.nv])))

    def tree_dependence(self) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Structural dependence of the joint-space dynamics on the model's tree: (nv, nv) bool between v
        indices whose bodies lie on one branch (one is an ancestor of the other), (nv, nq) the same for q
        (a free-flyer's position excluded: uniform gravity), and per foot the (nv,) rows its force reaches
        (the foot body's ancestors). A leg's joint torques never see another leg's joints or feet."""
        model = self.model
        bodies = model.nbodies
        ancestors, q_body, v_body = self.tree()
        related = np.array([[i in ancestors[j] or j in ancestors[i] for j in range(bodies)] for i in range(bodies)])
        vv, vq = related[np.ix_(v_body, v_body)], related[np.ix_(v_body, q_body)]
        if model.floating_base:
            vq[:, :3] = False
        reach = {name: np.isin(v_body, list(ancestors[body])) for name, body in self.foot_body.items()}
        return vv, vq, reach


    def contact_rows(self, contacts: Sequence[str]) -> list[tuple[int, np.ndarray, list[int]]]:
        """(body, point, world axes) whose velocities a touchdown of `contacts` stops (eq. 7): each foot's point
        (its vertical axis only when force_dims is 1), and for a flat foot its toe (y, z) and side (z) points,
        which with the centre stop the whole sole (six independent rows)."""
        rows = []
        for name in contacts:
            rows.append((self.foot_body[name], self.foot_point[name], [0, 1, 2] if self.force_dims == 3 else [2]))
            if name in self.flat_feet:
                rows.append((self.foot_body[name], self.foot_point[f"{name}/toe"], [1, 2]))
                rows.append((self.foot_body[name], self.foot_point[f"{name}/side"], [2]))
        return rows

    def row_forces(self, values: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """World forces (B, points, 3) at the `contact_rows` points of the named feet from per-row values (B, r)
        (impulses, slack), zero on the axes a row does not hold."""
        rows = self.contact_rows(contacts)
        out = np.zeros((len(values), len(rows), 3))
        column = 0
        for i, (_, _, axes) in enumerate(rows):
            out[:, i, axes] = values[:, column : column + len(axes)]
            column += len(axes)
        return out

    def start_seen_from(self, k: int) -> Start:
        """The variables of the point after the boundary that ends phase k, as phase k's end sees them (`Start`)."""
        start = self.point_index[(k + 1) % len(self.phases)][0]
        nq, nx = self.nq, self.nx
        if (k + 1) % len(self.phases) or self.mirror is None:
            return Start(start[:nq], np.ones(nq), start[nq:nx], np.ones(self.nv), start[nx : nx + self.nu], np.ones(self.nu))
        mirror = self.mirror
        u_order, u_sign = mirror.control_order(np.asarray(self.actuated, dtype=np.int64))
        return Start(start[mirror.q_order], mirror.q_sign, start[nq + mirror.v_order], mirror.v_sign, start[nx + u_order], u_sign)

    def point_index_u_w(self) -> list[np.ndarray]:
        """Per phase (P, nu, 2): the variable of each actuated torque and of its joint's velocity."""
        return [np.stack([index[:, self.nx : self.nx + self.nu], index[:, self.nq + np.asarray(self.actuated)]], axis=-1)
                for index in self.point_index]

    def point(self, x: object, name: str = "x") -> np.ndarray:
        """x as a point of this problem: finite float64 of shape (n,) (TypeError or ValueError naming `name`)."""
        return float_array(x, name, shape=(self.n,))

    def unpack(self, x: np.ndarray) -> Trajectory:
        """The `Trajectory` of a point x (n,) of this problem (`point` checks it)."""
        x = self.point(x)
        durations = x[self.duration_index].copy()
        starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        t, q, v, u, forces, a, torques, slack = [], [], [], [], [], [], [], []
        for k, index in enumerate(self.point_index):
            z = x[index]
            torques.append(z[:, self.torque_columns[k]].reshape(len(z), -1, 3))
            slack.append(z[:, self.slack_columns[k]])
            t.append(starts[k] + np.linspace(0.0, durations[k], len(index)))
            q.append(z[:, : self.nq])
            v.append(z[:, self.nq : self.nx])
            u.append(z[:, self.nx : self.nx + self.nu])
            forces.append(self.world_forces(z[:, self.force_columns[k]], len(self.phases[k].contacts)))
            a.append(self.accelerations(z, k))
        return Trajectory(t, q, v, u, forces, durations, float(x[self.p1_index]), a, torques, slack)
