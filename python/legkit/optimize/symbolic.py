"""A symbolic (casadi SX) mirror of the legkit kernels a transcription needs, for IPOPT's exact Hessian.

Why it exists (docs/optimize.md, "Measured"): with the constraints evaluated by legkit's batched kernels and
differentiated by coloured central differences, IPOPT only has first derivatives and must use L-BFGS, and on
the amble (min-max S_H, eq. 11) L-BFGS crawls for hundreds of iterations. Second derivatives by differences
of differences cost a second order of kernel calls. casadi's algorithmic differentiation of the same
functions, written symbolically, gives exact Jacobians and Hessians at a small fraction of that cost, so the
amble converges in tens of iterations. The price is a second implementation of the dynamics: every function
here is checked against legkit's own kernels (`lk.rnea`, `lk.forward_kinematics`, `lk.center_of_mass`,
`lk.centroidal_momentum`, `lk.impact`) in tests/test_optimize_symbolic.py, and legkit stays the reference:
the solution is re-evaluated by the legkit kernels (`MultiphaseProblem.constraints`).

Conventions are legkit's (DESIGN.md): a body's pose is parent pose x placement x joint motion; free-flyer
q = [x, y, z, qx, qy, qz, qw], v = [v_lin, omega] in the base frame; spatial vectors here are linear-first
([v, omega] and [f, n]) in body coordinates. RNEA is Featherstone's recursive Newton-Euler (file 003 eq. 1 as
inverse dynamics: tau = M a + C v + g - sum J^T f_ext).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

import legkit as lk

if TYPE_CHECKING:
    from legkit.optimize.problem import MultiphaseProblem

#: Relative regularisation of the impact's KKT system (see `SymbolicModel.impact`).
IMPACT_REGULARISATION = 1e-12


def _ca() -> Any:
    import casadi

    return casadi


def _skew(w: Any) -> Any:
    ca = _ca()
    return ca.vertcat(ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]), ca.horzcat(-w[1], w[0], 0))


def quaternion_matrix(quaternion: Any) -> Any:
    """Rotation of an [x, y, z, w] quaternion, normalised (as legkit's `configuration` does)."""
    ca = _ca()
    quaternion = quaternion / ca.norm_2(quaternion)
    x, y, z, w = quaternion[0], quaternion[1], quaternion[2], quaternion[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        ca.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        ca.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


def _axis_rotation(axis: np.ndarray, angle: Any) -> Any:
    ca = _ca()
    k = _skew(ca.DM(axis))
    return ca.DM.eye(3) + ca.sin(angle) * k + (1 - ca.cos(angle)) * (k @ k)


class SymbolicModel:
    """The kinematics and dynamics of a legkit Model as casadi SX expressions (module docstring)."""

    def __init__(self, model: lk.Model) -> None:
        self.model = model
        self.nq, self.nv, self.bodies = model.nq, model.nv, model.nbodies
        self.parents = list(model.parents)
        self.idx_q, self.idx_v = list(model.idx_q), list(model.idx_v)
        self.types = [model.joint_type(i) for i in range(self.bodies)]
        unknown = {t for t in self.types if t not in ("free_flyer", "revolute", "prismatic", "fixed")}
        if unknown:
            raise ValueError(f"model: joint types {sorted(unknown)} have no symbolic form")
        self.axes = [None if model.joint_axis(i) is None else np.asarray(model.joint_axis(i), dtype=np.float64) for i in range(self.bodies)]
        self.placements = [np.asarray(model.placement(i), dtype=np.float64) for i in range(self.bodies)]
        self.inertias = [model.body(i) for i in range(self.bodies)]
        self.gravity = np.asarray(model.gravity, dtype=np.float64)
        self.total_mass = float(model.total_mass)
        self._recent: list[tuple[tuple, Any]] = []  # `_shared`'s last few passes

    # -------------------------------------------------------------- kinematics
    def _joint(self, i: int, q: Any) -> Any:
        """(R, p) of body i in its parent's frame, and the motion subspace S (6, k) in body coordinates."""
        ca = _ca()
        placement = self.placements[i]
        r0, p0 = ca.DM(placement[:3, :3]), ca.DM(placement[:3, 3])
        kind, qi = self.types[i], self.idx_q[i]
        if kind == "free_flyer":
            rotation = quaternion_matrix(q[qi + 3 : qi + 7])
            return r0 @ rotation, p0 + r0 @ q[qi : qi + 3], ca.DM.eye(6)
        if kind == "revolute":
            axis = self.axes[i]
            assert axis is not None  # a revolute joint has an axis
            return r0 @ _axis_rotation(axis, q[qi]), p0, ca.DM(np.r_[np.zeros(3), axis]).reshape((6, 1))
        if kind == "prismatic":
            axis = self.axes[i]
            assert axis is not None  # a prismatic joint has an axis
            return r0, p0 + r0 @ ca.DM(axis) * q[qi], ca.DM(np.r_[axis, np.zeros(3)]).reshape((6, 1))
        return r0, p0, ca.DM(6, 0)

    def _dofs(self, i: int) -> int:
        return {"free_flyer": 6, "revolute": 1, "prismatic": 1, "fixed": 0}[self.types[i]]

    def kinematics(self, q: Any, v: Any = None, a: Any = None) -> Any:
        """Per body: world rotation, world position, and (with v, a) body-frame spatial velocity and
        acceleration (gravity folded in as an upward acceleration of the world when a is given)."""
        ca = _ca()
        rotations, positions, local = self._placements(q)
        if v is None:
            return rotations, positions, [], [], local
        velocities = self._velocities(q, v)
        accelerations: list[Any] = []
        if a is not None:
            for i in range(self.bodies):
                r, p, s = local[i]
                k, vi = self._dofs(i), self.idx_v[i]
                parent = ca.vertcat(ca.DM(-self.gravity), ca.DM.zeros(3)) if i == 0 else accelerations[self.parents[i]]
                acc = self._transform_motion(r, p, parent)
                if k:
                    acc = acc + s @ a[vi : vi + k] + self._cross_motion(velocities[i], s @ v[vi : vi + k])
                accelerations.append(acc)
        return rotations, positions, velocities, accelerations, local

    def _shared(self, inputs: tuple, compute: Any) -> Any:
        """compute(), or its value from an earlier call on the same SX nodes. A point function asks for the
        same kinematics several times (the COM, the momentum, the feet, the wrenches); sharing one pass keeps
        the graph, and above all its Hessian, free of copies (the S_H rows' Hessian on the amble: 2.6 M -> 1.7 M instructions)."""
        ca = _ca()
        for key, value in self._recent:
            if len(key) == len(inputs) and all(ca.is_equal(x, y, 0) for x, y in zip(key, inputs, strict=True)):
                return value
        value = compute()
        self._recent = [(inputs, value), *self._recent[:3]]
        return value

    def _placements(self, q: Any) -> Any:
        """Per body: world rotation and position, and its joint's (R, p, S) in the parent frame."""

        def compute() -> Any:
            local = [self._joint(i, q) for i in range(self.bodies)]
            rotations: list[Any] = []
            positions: list[Any] = []
            for i, (r, p, _) in enumerate(local):
                parent = self.parents[i]
                rotations.append(r if i == 0 else rotations[parent] @ r)
                positions.append(p if i == 0 else positions[parent] + rotations[parent] @ p)
            return rotations, positions, local

        return self._shared((q,), compute)

    def _velocities(self, q: Any, v: Any) -> list[Any]:
        """Per body: body-frame spatial velocity."""
        ca = _ca()
        local = self._placements(q)[2]

        def compute() -> list[Any]:
            velocities: list[Any] = []
            for i, (r, p, s) in enumerate(local):
                k, vi = self._dofs(i), self.idx_v[i]
                vel = self._transform_motion(r, p, ca.DM.zeros(6) if i == 0 else velocities[self.parents[i]])
                velocities.append(vel + s @ v[vi : vi + k] if k else vel)
            return velocities

        return self._shared((q, v), compute)

    @staticmethod
    def _transform_motion(r: Any, p: Any, motion: Any) -> Any:
        """A parent-frame motion [v, w] at the parent origin, expressed at the child origin in child axes."""
        ca = _ca()
        v, w = motion[:3], motion[3:]
        return ca.vertcat(r.T @ (v + ca.cross(w, p)), r.T @ w)

    @staticmethod
    def _cross_motion(m1: Any, m2: Any) -> Any:
        ca = _ca()
        v, w = m1[:3], m1[3:]
        return ca.vertcat(ca.cross(w, m2[:3]) + ca.cross(v, m2[3:]), ca.cross(w, m2[3:]))

    def _momentum(self, i: int, motion: Any) -> Any:
        """Body i's spatial momentum [h, k about the origin] in body coordinates for a motion [v, w]."""
        ca = _ca()
        body = self.inertias[i]
        m, c, inertia = float(body.mass), ca.DM(np.asarray(body.com)), ca.DM(np.asarray(body.inertia))
        v, w = motion[:3], motion[3:]
        linear = m * (v + ca.cross(w, c))
        return ca.vertcat(linear, inertia @ w + ca.cross(c, linear))

    def rnea(self, q: Any, v: Any, a: Any, wrenches: Sequence[tuple[int, object]] = ()) -> Any:
        """tau (nv,) = rnea(q, v, a, f_ext) with f_ext body-frame wrenches [f, n] as (body, 6-vector) pairs."""
        ca = _ca()
        rotations, positions, velocities, accelerations, local = self.kinematics(q, v, a)
        forces = []
        for i in range(self.bodies):
            vel, acc = velocities[i], accelerations[i]
            h = self._momentum(i, vel)
            net = self._momentum(i, acc) + ca.vertcat(ca.cross(vel[3:], h[:3]), ca.cross(vel[3:], h[3:]) + ca.cross(vel[:3], h[:3]))
            forces.append(net)
        for body, wrench in wrenches:
            forces[body] = forces[body] - wrench
        tau = [None] * self.nv
        for i in reversed(range(self.bodies)):
            r, p, s = local[i]
            k, vi = self._dofs(i), self.idx_v[i]
            if k:
                projected = s.T @ forces[i]
                for j in range(k):
                    tau[vi + j] = projected[j]
            parent = self.parents[i]
            if i > 0:
                f, n = r @ forces[i][:3], r @ forces[i][3:]
                forces[parent] = forces[parent] + ca.vertcat(f, n + ca.cross(p, f))
        return ca.vertcat(*tau)

    def foot_wrenches(self, q: Any, feet: Sequence[tuple[int, np.ndarray]], world_forces: Any) -> Any:
        """Body-frame wrenches of world forces (3 per foot, stacked) at foot points (body, point)."""
        ca = _ca()
        rotations = self.kinematics(q)[0]
        wrenches = []
        for c, (body, point) in enumerate(feet):
            local = rotations[body].T @ world_forces[3 * c : 3 * c + 3]
            wrenches.append((body, ca.vertcat(local, ca.cross(ca.DM(point), local))))
        return wrenches

    def points(self, q: Any, feet: Sequence[tuple[int, np.ndarray]]) -> Any:
        """World positions (3 per point, stacked) of body points (body, point)."""
        ca = _ca()
        rotations, positions = self.kinematics(q)[:2]
        return ca.vertcat(*[positions[b] + rotations[b] @ ca.DM(p) for b, p in feet])

    def center_of_mass(self, q: Any) -> Any:
        ca = _ca()
        rotations, positions = self.kinematics(q)[:2]
        total = 0
        for i in range(self.bodies):
            body = self.inertias[i]
            if float(body.mass) > 0.0:
                total = total + float(body.mass) * (positions[i] + rotations[i] @ ca.DM(np.asarray(body.com)))
        return total / self.total_mass

    def centroidal_momentum(self, q: Any, v: Any) -> Any:
        """[h_lin, h_ang about the COM], world-aligned (as `lk.centroidal_momentum`)."""
        ca = _ca()
        rotations, positions, velocities = self.kinematics(q, v)[:3]
        com = self.center_of_mass(q)
        linear, angular = ca.DM.zeros(3), ca.DM.zeros(3)
        for i in range(self.bodies):
            body = self.inertias[i]
            if float(body.mass) == 0.0 and not np.any(np.asarray(body.inertia)):
                continue
            h = self._momentum(i, velocities[i])  # about the body origin, body axes
            r = rotations[i]
            h_world, k_world = r @ h[:3], r @ h[3:]
            linear = linear + h_world
            angular = angular + k_world + ca.cross(positions[i] - com, h_world)
        return ca.vertcat(linear, angular)

    def mass_matrix(self, q: Any) -> Any:
        ca = _ca()
        zero = ca.DM.zeros(self.nv)
        bias = self.rnea_no_gravity(q, zero, zero)
        return ca.horzcat(*[self.rnea_no_gravity(q, zero, ca.DM(np.eye(self.nv)[j])) - bias for j in range(self.nv)])

    @contextmanager
    def _without_gravity(self) -> Iterator[None]:
        saved = self.gravity
        self.gravity = np.zeros(3)
        try:
            yield
        finally:
            self.gravity = saved

    def rnea_no_gravity(self, q: Any, v: Any, a: Any) -> Any:
        with self._without_gravity():
            return self.rnea(q, v, a)

    def point_accelerations(self, q: Any, v: Any, a: Any, feet: Sequence[tuple[int, np.ndarray]]) -> Any:
        """World-axes acceleration J a + dJ/dt v (3 per point, stacked) of body points (body, point), as
        `lk.point_accelerations`: R (a_lin + alpha x r + w x (v_lin + w x r)) from the body's spatial motion."""
        ca = _ca()
        with self._without_gravity():
            rotations, _, velocities, accelerations, _ = self.kinematics(q, v, a)
        out = []
        for body, point in feet:
            r, velocity, acceleration = ca.DM(point), velocities[body], accelerations[body]
            w = velocity[3:]
            local = acceleration[:3] + ca.cross(acceleration[3:], r) + ca.cross(w, velocity[:3] + ca.cross(w, r))
            out.append(rotations[body] @ local)
        return ca.vertcat(*out)

    def impact(self, q: Any, v_minus: Any, feet: Sequence[tuple[int, np.ndarray]]) -> Any:
        """Perfectly inelastic impact (eq. 7): v+ with J v+ = 0 at the feet, M (v+ - v-) = J^T Lambda. The
        KKT system carries IMPACT_REGULARISATION on its impulse block, so directions no joint can move along
        (zero rows of J, e.g. a foot on a vertical slider) get no impulse instead of a singular system; for a
        full-rank J it moves v+ by about that much relative (the differential test bounds it)."""
        ca = _ca()
        m = self.mass_matrix(q)
        jac = self.contact_jacobian(q, feet)
        k = jac.shape[0]
        kkt = ca.vertcat(ca.horzcat(m, -jac.T), ca.horzcat(jac, IMPACT_REGULARISATION * ca.DM.eye(k)))
        return ca.solve(kkt, ca.vertcat(m @ v_minus, ca.DM.zeros(k)))[: self.nv]

    def contact_jacobian(self, q: Any, feet: Sequence[tuple[int, np.ndarray]]) -> Any:
        """(3 k, nv) world-aligned linear Jacobian of body points (body, point): d points / dq Q(q), at any q
        expression (differentiated at a symbol, then called at q)."""
        ca = _ca()
        symbol = ca.SX.sym("q", self.nq)
        jacobian = ca.Function("contact_jacobian", [symbol], [ca.jacobian(self.points(symbol, feet), symbol) @ self.q_rate_matrix(symbol)])
        return jacobian(q)

    def contact_rows_jacobian(self, q: Any, rows: Sequence[tuple[int, np.ndarray, Sequence[int]]]) -> Any:
        """(r, nv): the world axes `axes` of each (body, point, axes) of `MultiphaseProblem.contact_rows`."""
        ca = _ca()
        return ca.vertcat(*[self.contact_jacobian(q, [(body, point)])[list(axes), :] for body, point, axes in rows])

    def q_rate_matrix(self, q: Any) -> Any:
        """dq/dt = Q(q) v (nq, nv): the base position rate R v_lin, the quaternion rate, joint rates."""
        ca = _ca()
        if not self.model.floating_base:
            return ca.DM.eye(self.nv)
        qx, qy, qz, qw = q[3], q[4], q[5], q[6]
        quat = 0.5 * ca.vertcat(ca.horzcat(qw, -qz, qy), ca.horzcat(qz, qw, -qx), ca.horzcat(-qy, qx, qw), ca.horzcat(-qx, -qy, -qz))
        top = ca.horzcat(quaternion_matrix(q[3:7]), ca.DM.zeros(3, self.nv - 3))
        middle = ca.horzcat(ca.DM.zeros(4, 3), quat, ca.DM.zeros(4, self.nv - 6))
        bottom = ca.horzcat(ca.DM.zeros(self.nq - 7, 6), ca.DM.eye(self.nv - 6))
        return ca.vertcat(top, middle, bottom)


# ------------------------------------------------------------------ the transcription, symbolically
@dataclass(frozen=True)
class Mapped:
    """Constraint rows selection @ vec(F(z_1), ..., F(z_P)) (without a selection: the outputs themselves, point-
    major), F a casadi SX Function of one point's variables z_p = x[index[p]]."""

    function: Any
    index: np.ndarray  # (P, k)
    selection: Any = None  # scipy sparse (rows, P * F's outputs) or None

    @property
    def size(self) -> int:
        return self.index.shape[0] * self.function.size1_out(0) if self.selection is None else self.selection.shape[0]

    def rows(self, x: Any) -> Any:
        ca = _ca()
        outputs = ca.vec(self.function.map(self.index.shape[0])(gather(x, self.index)))
        return outputs if self.selection is None else casadi_sparse(self.selection) @ outputs


@dataclass(frozen=True)
class LinearRows:
    """Constraint rows matrix @ x + offset (matrix scipy sparse)."""

    matrix: Any
    offset: np.ndarray

    @property
    def size(self) -> int:
        return self.matrix.shape[0]

    def rows(self, x: Any) -> Any:
        return casadi_sparse(self.matrix) @ x + _ca().DM(self.offset)


@dataclass(frozen=True)
class Transcription:
    """A `MultiphaseProblem`'s NLP as casadi MX: x, f(x), g(x); g's rows in `pieces` (in order), each `Mapped`
    or `LinearRows`."""

    x: Any
    f: Any
    g: Any
    pieces: tuple

    def without_objective(self) -> Transcription:
        return Transcription(self.x, 0.0 * self.x[0], self.g, self.pieces)


def transcription(problem: MultiphaseProblem) -> Transcription:
    """A `MultiphaseProblem`'s NLP as casadi MX: the same rows in the same order as `problem.constraints` (each
    per-point function a casadi Function mapped over the points) and the same objective. Needs the inverse-
    dynamics transcription and symbolic forms of every Point block and integrand."""
    ca = _ca()
    from scipy.sparse import coo_matrix

    from legkit.optimize import problem as transcribed
    from legkit.optimize.blocks import Linear, Point

    model = SymbolicModel(problem.model)
    x = ca.MX.sym("x", problem.n)
    pieces: list = []
    for block in problem.blocks:
        if isinstance(block, Linear):
            pieces.append(LinearRows(_scipy_sparse(block.size, problem.n, block.rows, block.cols, block.coefficients), block.offset))
        elif isinstance(block, Point):
            if block.symbolic is None:
                raise ValueError(f"a constraint block ({block.function}) has no symbolic form")
            z = ca.SX.sym("z", block.index.shape[1])
            pieces.append(Mapped(ca.Function("point", [z], [block.symbolic(model, z)]), block.index))
        elif isinstance(block, transcribed._Defects):
            pieces.append(_defects(problem, model, block))
        elif isinstance(block, transcribed._InverseDynamics):
            z = ca.SX.sym("z", block.index.shape[1])
            for k in block.ks:  # the block's rows phase by phase, point-major
                pieces.append(Mapped(ca.Function("rnea", [z], [residual(problem, model, k, z)]), problem.point_index[k]))
        elif isinstance(block, transcribed._Feet):
            q = ca.SX.sym("q", problem.nq)
            feet = [(problem.foot_body[n], problem.foot_point[n]) for n in block.names]
            outputs = block.index.shape[0] * 3 * len(feet)
            anchored = np.flatnonzero(block._anchor >= 0)
            rows = np.r_[np.arange(block.size), anchored]
            cols = np.r_[block._output, block._anchor[anchored]]
            selection = coo_matrix((np.r_[np.ones(block.size), -np.ones(len(anchored))], (rows, cols)), shape=(block.size, outputs)).tocsr()
            pieces.append(Mapped(ca.Function("feet", [q], [model.points(q, feet)]), block.index, selection))
        else:
            raise ValueError(f"no symbolic form for constraint block {type(block).__name__}")
    g = ca.vertcat(*[piece.rows(x) for piece in pieces])
    return Transcription(x, objective(problem, model, x), g, tuple(pieces))


def residual(problem: MultiphaseProblem, model: SymbolicModel, k: int, z: Any) -> Any:
    """rnea(q, v, a, J_c^T lambda) - B u at phase k's point variables z (the inverse-dynamics rows; lambda: the
    feet's forces and the flat feet's torques)."""
    ca = _ca()
    contacts = problem.phases[k].contacts
    feet = [(problem.foot_body[n], problem.foot_point[n]) for n in contacts]
    forces = z[problem.force_columns[k]]
    if problem.force_dims == 1:
        forces = ca.vertcat(*[ca.vertcat(0, 0, forces[c]) for c in range(len(contacts))])
    q, v, a = z[: problem.nq], z[problem.nq : problem.nx], z[problem.a_columns[k]]
    wrenches = model.foot_wrenches(q, feet, forces) if contacts else []
    torques = z[problem.torque_columns[k]]
    for c, name in enumerate(problem.flat_contacts(contacts)):  # a flat foot's torque, foot frame (`FlatFoot`)
        wrenches.append((problem.foot_body[name], ca.vertcat(0, 0, 0, torques[3 * c : 3 * c + 3])))
    tau = model.rnea(q, v, a, wrenches)
    actuation = np.zeros((problem.nv, problem.nu))
    actuation[problem.actuated, np.arange(problem.nu)] = 1.0
    return tau - ca.DM(actuation) @ z[problem.nx : problem.nx + problem.nu]


def gather(x: Any, index: np.ndarray) -> Any:
    """(k, P) MX of the variables index (P, k), one column per point."""
    ca = _ca()
    return ca.reshape(x[np.asarray(index).ravel().tolist()], index.shape[1], index.shape[0])


def _scipy_sparse(rows: int, columns: int, r: Any, c: Any, values: Any) -> Any:
    """(rows, columns) scipy CSC matrix of triplets, duplicates summed."""
    from scipy.sparse import coo_matrix

    matrix = coo_matrix((np.asarray(values, dtype=np.float64), (np.asarray(r), np.asarray(c))), shape=(rows, columns)).tocsc()
    matrix.sum_duplicates()
    return matrix


def casadi_sparse(matrix: Any) -> Any:
    """casadi DM of a scipy sparse matrix."""
    ca = _ca()
    matrix = matrix.tocsc()
    matrix.sum_duplicates()
    return ca.DM(ca.Sparsity(*matrix.shape, matrix.indptr.tolist(), matrix.indices.tolist()), matrix.data.tolist())


def _defects(problem: MultiphaseProblem, model: SymbolicModel, block: Any) -> Mapped:
    """Phase block.k's Hermite-Simpson defects interval by interval: [interpolation; Simpson] (eq. 14, as
    `hermite_simpson_defects`) of an interval's knot, midpoint and knot variables and the phase's duration."""
    ca = _ca()
    nz, nx = block.index.shape[1], problem.nx
    rows = problem.contact_rows(problem.phases[block.k].contacts)

    def state_and_rate(z: Any) -> tuple[Any, Any]:
        q, v = z[: problem.nq], z[problem.nq : nx]
        if rows:  # the slack's correction (`MultiphaseProblem.rate`)
            v = v + model.contact_rows_jacobian(q, rows).T @ z[problem.slack_columns[block.k]]
        return z[:nx], ca.vertcat(model.q_rate_matrix(q) @ v, z[problem.a_columns[block.k]])

    w = ca.SX.sym("w", 3 * nz + 1)
    (x0, f0), (xm, fm), (x1, f1) = (state_and_rate(w[i * nz : (i + 1) * nz]) for i in range(3))
    h = w[3 * nz] / block.intervals
    interpolation = xm - 0.5 * (x0 + x1) - h * (f0 - f1) / 8.0
    simpson = x1 - x0 - h * (f0 + 4.0 * fm + f1) / 6.0
    interval = np.arange(block.intervals)
    index = np.concatenate([block.index[2 * interval], block.index[2 * interval + 1], block.index[2 * interval + 2],
                            np.full((block.intervals, 1), block.duration)], axis=1)
    return Mapped(ca.Function("defects", [w], [ca.vertcat(interpolation, simpson)]), index)


def objective(problem: MultiphaseProblem, model: SymbolicModel, x: Any) -> Any:
    """The problem's summed objective terms (`objectives.build_objective`) as a casadi expression."""
    ca = _ca()
    from legkit.optimize.objectives import Integral, MinMaxStability, _simpson_weights

    total = 0
    for term in problem.objectives:
        if isinstance(term, MinMaxStability):
            total = total - term.weight * x[problem.p1_index]
            continue
        if not isinstance(term, Integral) or term.symbolic is None:
            raise ValueError(f"objective term {term} has no symbolic form")
        integral: Any = 0  # a casadi expression after the first phase
        for k, index in enumerate(problem.point_index):
            z = ca.SX.sym("z", index.shape[1])
            integrand = ca.Function("integrand", [z], [term.symbolic(problem, model, z, k)]).map(index.shape[0])
            weights = ca.DM(_simpson_weights(problem.phases[k].intervals) / (6.0 * problem.phases[k].intervals))
            integral = integral + x[problem.duration_index[k]] * (integrand(gather(x, index)) @ weights)
        if term.per_distance:
            integral = integral / (abs(problem.speed) * ca.sum1(x[problem.duration_index.tolist()]))
        total = total + term.weight * integral
    return total
