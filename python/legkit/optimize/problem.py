"""Multiphase direct collocation of a legged robot's motion with a fixed contact sequence.

The transcription of Hardt & von Stryk (RoboCup 2002; ../shared/seeds/003_8a51da06d878ba35.txt), Sect. 2.3
and 4.1, on legkit's kernels:

* phases with fixed contact sets (the discrete state d(t) of Sect. 4.1), each with its duration as a variable;
* per phase a grid of `intervals` Hermite–Simpson intervals (eq. 14: cubic states, linear controls); at every
  knot and midpoint the variables z = [q, v, u, lambda]: configuration, velocity, actuated torques and the
  world-frame contact forces of the phase's feet;
* dynamics (eq. 1) as forward dynamics with the contact forces as variables: a = aba(q, v, B u, J_c^T lambda)
  (legkit's batched ABA with the forces as external wrenches), the stance feet held on the ground at every
  knot and midpoint (g_c(q) = 0 at position level), so lambda is whatever keeps them there;
* swing-tip height >= 0 (eq. 4), friction cone mu^2 F_z^2 - F_x^2 - F_y^2 >= 0 with F_z >= 0 (eq. 5, squared
  to stay smooth), the inelastic impact map at each touchdown (eq. 7, `lk.impact` with the new phase's feet),
  state/control bounds and the motor torque-speed line |u| <= (w_max - |w|) k (Sect. 2.3, split into its four
  linear faces);
* periodicity (Sect. 2.3: q(t_f) = q(0) up to the travelled distance, velocity after the wrap-around impact)
  or fixed initial/final states.

Jacobians of the dynamics and of every nonlinear point constraint are coloured central differences over
batched kernel calls (`point_jacobian`); the pattern is fixed before solving. Objectives: `objectives.py`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

import legkit as lk
from legkit.optimize.blocks import Block, Linear, Point, equal
from legkit.optimize.collocation import hermite_simpson_defects, point_jacobian
from legkit.optimize.solver import NLP, SolveResult, solve


@dataclass(frozen=True)
class Phase:
    """One contact phase: the feet on the ground, the grid's interval count, and bounds on its duration [s]."""

    contacts: tuple[str, ...] = ()
    intervals: int = 6
    duration: tuple[float, float] = (0.05, 1.0)


@dataclass(frozen=True)
class TorqueSpeedLine:
    """|u_i| <= (max_speed_i - |w_i|) gain_i per actuated joint (file 003 Sect. 2.3: gain = G^2 eta / m)."""

    max_speed: np.ndarray | float  # [rad/s]
    gain: np.ndarray | float  # [N m s / rad]


def quaternion_rate(quaternion: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """d/dt of an [x, y, z, w] quaternion turning at body-frame angular velocity omega: q (x) [omega, 0] / 2.
    Tangent to the sphere |q| = const, so the collocated quaternion keeps its norm up to the defects' error."""
    vector, w = quaternion[..., :3], quaternion[..., 3:]
    return 0.5 * np.concatenate([w * omega + np.cross(vector, omega), -np.sum(vector * omega, axis=-1, keepdims=True)], axis=-1)


def rotation(quaternion: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation of a (not necessarily unit) [x, y, z, w] quaternion."""
    x, y, z, w = np.moveaxis(quaternion / np.linalg.norm(quaternion, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


@dataclass
class Trajectory:
    """The variables of a transcription, per phase: times t (P,), q (P, nq), v (P, nv), u (P, nu), forces
    (P, c, 3) on the phase's feet (world frame), and the phase durations."""

    t: list[np.ndarray]
    q: list[np.ndarray]
    v: list[np.ndarray]
    u: list[np.ndarray]
    forces: list[np.ndarray]
    durations: np.ndarray
    stability_bound: float = 0.0  # p1 of the min-max objective J_s2 (0 when unused)

    def stacked(self) -> dict[str, np.ndarray]:
        """Every point of every phase in time order (the shared phase-boundary instants appear twice)."""
        return {"t": np.concatenate(self.t), "q": np.concatenate(self.q), "v": np.concatenate(self.v),
                "u": np.concatenate(self.u), "phase": np.concatenate([np.full(len(t), k) for k, t in enumerate(self.t)])}


@dataclass
class MultiphaseProblem:
    """Multiphase Hermite–Simpson transcription of a legged robot's motion (module docstring).

    feet: contact points by name, (body, point in body frame). actuated: v indices driven by u (default: every
    joint, i.e. v[6:] for a free-flyer, all of v otherwise). periodic: q, v wrap around (the travel coordinate
    q[travel_index] advancing by speed x cycle time); otherwise initial/final (q, v) fix the ends (NaN: free).
    period: the cycle time, fixed (float) or bounded (lo, hi). force_dims: 3 (friction cone) or 1 (normal force
    only, for models that cannot push sideways). q/v/u_bounds: (lower, upper) arrays.
    objectives: terms from `legkit.optimize.objectives`, summed.
    """

    model: lk.Model
    phases: Sequence[Phase]
    feet: Mapping[str, tuple[int | str, Sequence[float]]] = field(default_factory=dict)
    objectives: Sequence = ()
    actuated: Sequence[int] | None = None
    periodic: bool = True
    speed: float = 0.0
    travel_index: int | None = None
    period: float | tuple[float, float] | None = None
    initial: tuple[np.ndarray, np.ndarray] | None = None
    final: tuple[np.ndarray, np.ndarray] | None = None
    friction: float = 0.8
    force_dims: int = 3
    q_bounds: tuple[np.ndarray, np.ndarray] | None = None
    v_bounds: tuple[np.ndarray, np.ndarray] | None = None
    u_bounds: tuple[np.ndarray, np.ndarray] | None = None
    torque_speed: TorqueSpeedLine | None = None
    continuous_controls: bool = False

    def __post_init__(self) -> None:
        self._validate()
        model = self.model
        self.nq, self.nv = model.nq, model.nv
        self.nx = self.nq + self.nv
        self.nu = len(self.actuated)
        self.foot_names = list(self.feet)
        self.foot_body = {name: (model.names.index(b) if isinstance(b, str) else int(b)) for name, (b, _) in self.feet.items()}
        self.foot_point = {name: np.asarray(p, dtype=np.float64) for name, (_, p) in self.feet.items()}
        # Variable layout: per phase a (P, nz) block of point variables, then the durations, then p1.
        self.point_index: list[np.ndarray] = []
        offset = 0
        for phase in self.phases:
            nz = self.nx + self.nu + self.force_dims * len(phase.contacts)
            points = 2 * phase.intervals + 1
            self.point_index.append(offset + np.arange(points * nz).reshape(points, nz))
            offset += points * nz
        self.duration_index = offset + np.arange(len(self.phases))
        self.p1_index = offset + len(self.phases)
        self.n = self.p1_index + 1
        self._build()

    # ------------------------------------------------------------------ validation
    def _validate(self) -> None:
        model = self.model
        if not isinstance(model, lk.Model):
            raise TypeError(f"model must be a legkit.Model, got {type(model).__name__}")
        if len(self.phases) == 0:
            raise ValueError("phases must hold at least one Phase")
        if self.force_dims not in (1, 3):
            raise ValueError(f"force_dims must be 1 or 3, got {self.force_dims}")
        if not self.friction > 0.0:
            raise ValueError(f"friction must be > 0, got {self.friction}")
        for i, phase in enumerate(self.phases):
            if phase.intervals < 1:
                raise ValueError(f"phases[{i}].intervals must be >= 1, got {phase.intervals}")
            lo, hi = phase.duration
            if not 0.0 < lo <= hi:
                raise ValueError(f"phases[{i}].duration must satisfy 0 < lower <= upper, got {phase.duration}")
            unknown = [c for c in phase.contacts if c not in self.feet]
            if unknown:
                raise ValueError(f"phases[{i}].contacts names unknown feet {unknown}; feet are {list(self.feet)}")
            if len(set(phase.contacts)) != len(phase.contacts):
                raise ValueError(f"phases[{i}].contacts repeats a foot: {phase.contacts}")
        for name, (body, _) in self.feet.items():
            if isinstance(body, str) and body not in model.names:
                raise ValueError(f"feet[{name!r}] names body {body!r}, which the model does not have")
        sequence = [frozenset(p.contacts) for p in self.phases]
        pairs = [(i, i - 1) for i in range(1, len(sequence))]
        if self.periodic and len(sequence) > 1:
            pairs.append((0, len(sequence) - 1))  # the cycle wraps around
        for i, j in pairs:
            if sequence[i] == sequence[j]:
                raise ValueError(f"phases[{i}] has the same contacts as phases[{j}]: an inconsistent contact sequence "
                                 "(a phase boundary must change the contacts; merge the two phases)")
        self.actuated = list(range(6 if model.floating_base else 0, model.nv)) if self.actuated is None else [int(i) for i in self.actuated]
        if any(not 0 <= i < model.nv for i in self.actuated) or len(set(self.actuated)) != len(self.actuated):
            raise ValueError(f"actuated must list distinct v indices in [0, {model.nv}), got {self.actuated}")
        if self.travel_index is None and model.floating_base:
            self.travel_index = 0
        if self.speed != 0.0:
            if not self.periodic or self.travel_index is None:
                raise ValueError("speed needs a periodic problem with a travel_index (a free-flyer's x by default)")
            self._check_reach()
        if self.period is not None:
            lo, hi = (self.period, self.period) if np.isscalar(self.period) else self.period
            if not 0.0 < lo <= hi:
                raise ValueError(f"period must be > 0 (or bounds 0 < lower <= upper), got {self.period}")
            if sum(p.duration[1] for p in self.phases) < lo or sum(p.duration[0] for p in self.phases) > hi:
                raise ValueError(f"period {self.period} cannot be met by the phases' duration bounds "
                                 f"(their sums lie in [{sum(p.duration[0] for p in self.phases)}, {sum(p.duration[1] for p in self.phases)}])")
        if not self.periodic and (self.initial is None and self.final is None):
            raise ValueError("a non-periodic problem needs initial and/or final states")

    def _check_reach(self) -> None:
        """A foot on the ground for a time T lets its hip travel speed x T under it; more than the leg's
        diameter of reach (twice the length of the chain from the base to the foot) is unreachable."""
        model = self.model
        for name, (body, point) in self.feet.items():
            down = [name in p.contacts for p in self.phases]
            if all(down):
                raise ValueError(f"speed {self.speed} m/s is unreachable: foot {name!r} never leaves the ground in phases, "
                                 "so it cannot move with the body (an inconsistent contact sequence for a moving gait)")
            index = model.names.index(body) if isinstance(body, str) else int(body)
            reach = float(np.linalg.norm(point))
            while index > 0:
                reach += float(np.linalg.norm(np.asarray(model.placement(index))[:3, 3]))
                index = model.parents[index]
            # The shortest contiguous stance of this foot, the phase list read cyclically from a swing phase.
            first_swing = down.index(False)
            runs, run = [], 0.0
            for k in range(first_swing, first_swing + len(down) + 1):
                phase = self.phases[k % len(down)]
                if name in phase.contacts:
                    run += phase.duration[0]
                elif run > 0.0:
                    runs, run = runs + [run], 0.0
            if runs and abs(self.speed) * min(runs) > 2.0 * reach:
                raise ValueError(f"speed {self.speed} m/s is unreachable: foot {name!r} stays down at least {min(runs):.3g} s, "
                                 f"while its hip moves {abs(self.speed) * min(runs):.3g} m, beyond the leg's reach of 2 x {reach:.3g} m")

    # ------------------------------------------------------------------ kernels
    def configuration(self, q: np.ndarray) -> np.ndarray:
        """q with a unit base quaternion: the kernels see a valid configuration whatever the iterate's norm."""
        if not self.model.floating_base:
            return q
        q = q.copy()
        q[..., 3:7] /= np.linalg.norm(q[..., 3:7], axis=-1, keepdims=True)
        return q

    def q_rate(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """dq/dt (..., nq): base position rate R v_lin, quaternion rate, joint rates."""
        if not self.model.floating_base:
            return v
        position = np.einsum("...ij,...j->...i", rotation(q[..., 3:7]), v[..., :3])
        return np.concatenate([position, quaternion_rate(q[..., 3:7], v[..., 3:6]), v[..., 6:]], axis=-1)

    def foot_positions(self, q: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """World positions (..., len(names), 3) of the named feet."""
        poses = np.asarray(lk.forward_kinematics(self.model, self.configuration(q)))
        return np.stack([np.einsum("...ij,j->...i", poses[..., self.foot_body[n], :3, :3], self.foot_point[n])
                         + poses[..., self.foot_body[n], :3, 3] for n in names], axis=-2)

    def world_forces(self, forces: np.ndarray, count: int) -> np.ndarray:
        """(B, count, 3) world forces from the (B, count * force_dims) force variables."""
        forces = forces.reshape(forces.shape[0], count, self.force_dims)
        if self.force_dims == 3:
            return forces
        return np.concatenate([np.zeros(forces.shape[:-1] + (2,)), forces], axis=-1)

    def state_rate(self, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
        """[dq/dt, a] (B, nx) at point variables z (B, nz): eq. 1 with the forces as external wrenches."""
        q, v = self.configuration(z[:, : self.nq]), z[:, self.nq : self.nx]
        tau = np.zeros((len(z), self.nv))
        tau[:, self.actuated] = z[:, self.nx : self.nx + self.nu]
        f_ext = None
        if contacts:
            poses = np.asarray(lk.forward_kinematics(self.model, q))
            forces = self.world_forces(z[:, self.nx + self.nu :], len(contacts))
            f_ext = np.zeros((len(z), self.model.nbodies, 6))
            for c, name in enumerate(contacts):  # a few feet; each line is batched over all points
                body = self.foot_body[name]
                local = np.einsum("bji,bj->bi", poses[:, body, :3, :3], forces[:, c])
                f_ext[:, body, :3] += local
                f_ext[:, body, 3:] += np.cross(self.foot_point[name], local)
        a = np.asarray(lk.aba(self.model, q, v, tau, f_ext))
        return np.concatenate([self.q_rate(z[:, : self.nq], v), a], axis=1)

    # ------------------------------------------------------------------ NLP assembly
    def _build(self) -> None:
        from legkit.optimize.objectives import build_objective

        blocks: list[Block] = []
        nq, nx, nu = self.nq, self.nx, self.nu
        count = len(self.phases)
        for k, phase in enumerate(self.phases):
            index = self.point_index[k]
            blocks.append(_Defects(self, k))
            u = slice(nx, nx + nu)
            if nu:  # linear controls on each interval (eq. 14): u_m = (u_k + u_k+1) / 2
                rows = np.arange(phase.intervals * nu)
                blocks.append(Linear(len(rows), np.tile(rows, 3), np.concatenate([index[1::2, u].ravel(), index[0:-1:2, u].ravel(), index[2::2, u].ravel()]),
                                     np.r_[np.ones(len(rows)), -0.5 * np.ones(2 * len(rows))]))
            blocks.extend(self._contact_blocks(k))
        for k in range(count if self.periodic else count - 1):
            after = (k + 1) % count
            end, start = self.point_index[k][-1], self.point_index[after][0]
            if self.periodic and after == 0 and self.travel_index is not None:
                # q_start = q_end - speed * sum(T) on the travel coordinate, equal elsewhere.
                keep = [i for i in range(nq) if i != self.travel_index]
                blocks.append(equal(len(keep), start[keep], end[keep]))
                blocks.append(Linear(1, np.zeros(count + 2, dtype=np.int64),
                                     np.r_[start[self.travel_index], end[self.travel_index], self.duration_index],
                                     np.r_[1.0, -1.0, np.full(count, self.speed)]))
            else:
                blocks.append(equal(nq, start[:nq], end[:nq]))
            blocks.append(self._velocity_transition(k, after))
            if self.continuous_controls and nu:
                blocks.append(equal(nu, start[nx : nx + nu], end[nx : nx + nu]))
        if self.period is not None:
            lo, hi = (self.period, self.period) if np.isscalar(self.period) else self.period
            blocks.append(Linear(1, np.zeros(count, dtype=np.int64), self.duration_index, np.ones(count), lower=lo, upper=hi))
        if self.model.floating_base:  # fixes the scale gauge of the quaternion (kernels normalise it)
            first = self.point_index[0][0]
            blocks.append(Point(first[None, 3:7], lambda quat: np.sum(quat * quat, axis=1, keepdims=True) - 1.0, 1))
        if self.torque_speed is not None and nu:
            blocks.extend(self._torque_speed_blocks())
        objective, gradient, extra = build_objective(self, self.objectives)
        self.uses_p1 = bool(extra)
        self.stability_blocks = extra
        blocks.extend(extra)
        self.blocks = blocks
        self.objective, self.gradient = objective, gradient
        offsets = np.cumsum([0] + [b.size for b in blocks])
        rows = np.concatenate([b.rows + o for b, o in zip(blocks, offsets)])
        cols = np.concatenate([b.cols for b in blocks])
        # Entries sharing (row, col) are summed into one nonzero of the fixed pattern.
        key, self._entry = np.unique(rows * self.n + cols, return_inverse=True)
        self.jac_rows, self.jac_cols = key // self.n, key % self.n
        self.m = int(offsets[-1])

    def _contact_blocks(self, k: int) -> list[Block]:
        phase, index = self.phases[k], self.point_index[k]
        nq, start = self.nq, self.nx + self.nu
        contacts, swing = list(phase.contacts), [n for n in self.foot_names if n not in phase.contacts]
        blocks: list[Block] = []
        if contacts:
            blocks.append(Point(index[:, :nq], lambda q: self.foot_positions(q, contacts)[..., 2], len(contacts)))
            if self.force_dims == 3 and len(index) > 1:  # the foothold stays where the phase began
                pairs = np.concatenate([index[1:, :nq], np.repeat(index[:1, :nq], len(index) - 1, axis=0)], axis=1)
                blocks.append(Point(pairs, lambda qq: (self.foot_positions(qq[:, :nq], contacts)
                                                       - self.foot_positions(qq[:, nq:], contacts))[..., :2].reshape(len(qq), -1),
                                    2 * len(contacts)))
            if self.force_dims == 3:
                mu2 = self.friction**2
                blocks.append(Point(index[:, start:], lambda f: (mu2 * f.reshape(len(f), -1, 3)[..., 2] ** 2
                                                               - np.sum(f.reshape(len(f), -1, 3)[..., :2] ** 2, axis=-1)),
                                    len(contacts), 0.0, np.inf))
        if swing:
            blocks.append(Point(index[:, :nq], lambda q: self.foot_positions(q, swing)[..., 2], len(swing), 0.0, np.inf))
        return blocks

    def _velocity_transition(self, k: int, after: int) -> Block:
        """v after the boundary: the impact map (eq. 7) when feet touch down, else continuity."""
        end, start = self.point_index[k][-1], self.point_index[after][0]
        nq, nx = self.nq, self.nx
        landing = set(self.phases[after].contacts) - set(self.phases[k].contacts)
        if not landing:
            return equal(self.nv, start[nq:nx], end[nq:nx])
        contacts = [(self.foot_body[n], self.foot_point[n]) for n in self.phases[after].contacts]

        def jump(z: np.ndarray) -> np.ndarray:
            v_plus, _ = lk.impact(self.model, self.configuration(z[:, :nq]), z[:, nq:nx], contacts)
            return z[:, nx:] - np.asarray(v_plus)

        return Point(np.concatenate([end[:nx], start[nq:nx]])[None], jump, self.nv)

    def _torque_speed_blocks(self) -> list[Block]:
        """(w_max - |w|) k - |u| >= 0 as four linear faces per actuated joint and point."""
        line = self.torque_speed
        w_max = np.broadcast_to(np.asarray(line.max_speed, dtype=np.float64), (self.nu,))
        gain = np.broadcast_to(np.asarray(line.gain, dtype=np.float64), (self.nu,))
        index = np.concatenate(self.point_index_u_w(), axis=0)  # (P, nu, 2): (u, w) columns
        points = len(index)
        blocks = []
        for su in (1.0, -1.0):
            for sw in (1.0, -1.0):
                rows = np.arange(points * self.nu)
                coeff_u = np.full(points * self.nu, -su)
                coeff_w = np.tile(-sw * gain, points)
                blocks.append(Linear(len(rows), np.r_[rows, rows], np.r_[index[..., 0].ravel(), index[..., 1].ravel()],
                                     np.r_[coeff_u, coeff_w], offset=np.tile(w_max * gain, points), lower=0.0, upper=np.inf))
        return blocks

    def point_index_u_w(self) -> list[np.ndarray]:
        """Per phase (P, nu, 2): the variable of each actuated torque and of its joint's velocity."""
        return [np.stack([index[:, self.nx : self.nx + self.nu], index[:, self.nq + np.asarray(self.actuated)]], axis=-1)
                for index in self.point_index]

    # ------------------------------------------------------------------ NLP interface
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lower, upper = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        for k, phase in enumerate(self.phases):
            index = self.point_index[k]
            for part, bounds in ((slice(0, self.nq), self.q_bounds), (slice(self.nq, self.nx), self.v_bounds),
                                 (slice(self.nx, self.nx + self.nu), self.u_bounds)):
                if bounds is not None:
                    lower[index[:, part]] = np.asarray(bounds[0], dtype=np.float64)
                    upper[index[:, part]] = np.asarray(bounds[1], dtype=np.float64)
            normal = index[:, self.nx + self.nu + self.force_dims - 1 :: self.force_dims]
            lower[normal] = 0.0  # unilateral contact (eq. 5)
            lower[self.duration_index[k]], upper[self.duration_index[k]] = phase.duration
        for state, point in ((self.initial, self.point_index[0][0]), (self.final, self.point_index[-1][-1])):
            if state is not None:
                values = np.concatenate([np.asarray(state[0], dtype=np.float64), np.asarray(state[1], dtype=np.float64)])
                if values.shape != (self.nx,):
                    raise ValueError(f"initial/final must be (q (nq,), v (nv,)), got {values.shape[0]} values for nq + nv = {self.nx}")
                fixed = ~np.isnan(values)
                lower[point[: self.nx][fixed]] = upper[point[: self.nx][fixed]] = values[fixed]
        if not self.uses_p1:
            lower[self.p1_index] = upper[self.p1_index] = 0.0
        return lower, upper

    def constraints(self, x: np.ndarray) -> np.ndarray:
        return np.concatenate([b.values(x) for b in self.blocks])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        values = np.concatenate([b.jacobian(x) for b in self.blocks])
        return np.bincount(self._entry, weights=values, minlength=len(self.jac_rows))

    def nlp(self) -> NLP:
        lower, upper = self.bounds()
        return NLP(lower, upper, np.concatenate([b.lower for b in self.blocks]), np.concatenate([b.upper for b in self.blocks]),
                   self.objective, self.gradient, self.constraints, self.jacobian, self.jac_rows, self.jac_cols)

    def solve(self, guess: Trajectory | np.ndarray, **options) -> tuple[Trajectory, SolveResult]:
        """Solve from a guess (a Trajectory or a variable vector); options go to `legkit.optimize.solver.solve`."""
        x0 = self.pack(guess) if isinstance(guess, Trajectory) else np.asarray(guess, dtype=np.float64)
        result = solve(self.nlp(), x0, **options)
        return self.unpack(result.x), result

    def stability_index(self, x: np.ndarray) -> list[np.ndarray]:
        """S_H (eq. 10) at every point of every phase, for a problem with a MinMaxStability objective."""
        if not self.stability_blocks:
            raise ValueError("stability_index needs a problem whose objectives hold a MinMaxStability term")
        return [b.values(x) + x[self.p1_index] for b in self.stability_blocks]

    # ------------------------------------------------------------------ packing
    def pack(self, trajectory: Trajectory) -> np.ndarray:
        """The variable vector of a trajectory (an initial guess or a neighbouring problem's solution)."""
        x = np.zeros(self.n)
        for k, index in enumerate(self.point_index):
            parts = [trajectory.q[k], trajectory.v[k], trajectory.u[k]]
            count = len(self.phases[k].contacts)
            forces = np.asarray(trajectory.forces[k], dtype=np.float64).reshape(len(index), count, 3)
            parts.append((forces if self.force_dims == 3 else forces[..., 2:]).reshape(len(index), -1))
            z = np.concatenate([np.asarray(p, dtype=np.float64).reshape(len(index), -1) for p in parts], axis=1)
            if z.shape != index.shape:
                raise ValueError(f"trajectory phase {k} has {z.shape} point values, the problem needs {index.shape}")
            x[index] = z
        x[self.duration_index] = trajectory.durations
        x[self.p1_index] = trajectory.stability_bound
        return x

    def unpack(self, x: np.ndarray) -> Trajectory:
        durations = x[self.duration_index].copy()
        starts = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
        t, q, v, u, forces = [], [], [], [], []
        for k, index in enumerate(self.point_index):
            z = x[index]
            t.append(starts[k] + np.linspace(0.0, durations[k], len(index)))
            q.append(z[:, : self.nq])
            v.append(z[:, self.nq : self.nx])
            u.append(z[:, self.nx : self.nx + self.nu])
            forces.append(self.world_forces(z[:, self.nx + self.nu :], len(self.phases[k].contacts)))
        return Trajectory(t, q, v, u, forces, durations, float(x[self.p1_index]))


class _Defects:
    """The Hermite–Simpson defects of one phase (`collocation` docstring); h = T / intervals, T a variable."""

    def __init__(self, problem: MultiphaseProblem, k: int) -> None:
        self.problem, self.contacts = problem, list(problem.phases[k].contacts)
        index = problem.point_index[k]
        self.index, self.duration, self.intervals = index, problem.duration_index[k], problem.phases[k].intervals
        nx, nz = problem.nx, index.shape[1]
        self.size = 2 * nx * self.intervals
        self.lower = self.upper = np.zeros(self.size)
        # Structural pattern of one interval: rows [interpolation; Simpson] x cols [z_a, z_m, z_b, T].
        dependence = np.ones((nx, nz), dtype=bool)
        dependence[: problem.nq, nx:] = False  # dq/dt does not depend on u or the forces
        self.dependence = dependence
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

    def _split(self, x: np.ndarray, rates: np.ndarray):
        z = x[self.index]
        states = z[:, : self.problem.nx]
        return states[0::2], states[1::2], rates[0::2], rates[1::2], x[self.duration] / self.intervals

    def values(self, x: np.ndarray) -> np.ndarray:
        rates = self.problem.state_rate(x[self.index], self.contacts)
        interpolation, simpson = hermite_simpson_defects(*self._split(x, rates))
        return np.concatenate([interpolation, simpson], axis=1).ravel()

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        nx, n_int = self.problem.nx, self.intervals
        rates, jac = point_jacobian(lambda z: self.problem.state_rate(z, self.contacts), x[self.index])
        h = x[self.duration] / n_int
        nz = jac.shape[2]
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
