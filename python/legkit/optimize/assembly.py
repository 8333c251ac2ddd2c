"""The NLP of a multiphase transcription (`Assembly`): its constraint families (`legkit.optimize.constraints`) and
objective terms (`legkit.optimize.objectives`) assembled into one vector of rows, with the fixed sparsity patterns
of their Jacobian and of the Hessian of the Lagrangian, the variables' bounds, and the `solver.NLP` IPOPT is given."""

from __future__ import annotations

import numpy as np

from legkit.optimize.blocks import Block
from legkit.optimize.constraints.dynamics import Defects, control_blocks, inverse_dynamics_blocks
from legkit.optimize.constraints.limits import input_power_blocks, torque_speed_blocks, yaw_blocks
from legkit.optimize.constraints.links import boundary_blocks, period_blocks, quaternion_gauge_blocks
from legkit.optimize.constraints.rates import dense_rate_blocks, load_rate_blocks
from legkit.optimize.constraints.stance import Feet, foot_torque_blocks, friction_cone_blocks, stance_blocks
from legkit.optimize.constraints.swing import clearance_blocks
from legkit.optimize.contact import ContactModel
from legkit.optimize.objectives import build_objective
from legkit.optimize.solver import NLP

#: `MultiphaseProblem.nlp`'s second derivatives: IPOPT's L-BFGS approximation, or the Hessian of the Lagrangian from
#: legkit's kernels (`MultiphaseProblem.hessian`); the Jacobian is exact in both.
DERIVATIVES = ("legkit", "exact")


class Assembly(ContactModel):
    """A `ContactModel`'s constraint rows in their fixed order (per phase its defects, controls and contacts; the
    inverse dynamics; the boundaries; the period and gauge; the rate, yaw, torque-speed and power limits; the
    objective's constraint rows), their values, Jacobian and Hessian on fixed patterns, its bounds and its `nlp`."""

    def __post_init__(self) -> None:
        super().__post_init__()
        self._build()

    def _build(self) -> None:
        blocks: list[Block] = []
        nu = self.nu
        for k in range(len(self.phases)):
            blocks.append(Defects(self, k))
            blocks.extend(control_blocks(self, k))
            blocks.extend(self._contact_blocks(k))
        blocks.extend(inverse_dynamics_blocks(self))
        blocks.extend(boundary_blocks(self))
        blocks.extend(period_blocks(self))
        blocks.extend(quaternion_gauge_blocks(self))
        blocks.extend(load_rate_blocks(self))
        blocks.extend(dense_rate_blocks(self))
        blocks.extend(yaw_blocks(self))
        if self.torque_speed is not None and nu:
            blocks.extend(torque_speed_blocks(self))
        if self.input_power is not None and nu:
            blocks.extend(input_power_blocks(self))
        objective, gradient, self.curvatures, extra = build_objective(self, self.objectives)
        self.uses_p1 = bool(extra)
        self.stability_blocks = extra
        blocks.extend(extra)
        self.blocks = blocks
        self.objective, self.gradient = objective, gradient
        self._offsets = np.cumsum([0] + [b.size for b in blocks])
        rows = np.concatenate([b.rows + o for b, o in zip(blocks, self._offsets)])
        cols = np.concatenate([b.cols for b in blocks])
        # Entries sharing (row, col) are summed into one nonzero of the fixed pattern.
        key, self._entry = np.unique(rows * self.n + cols, return_inverse=True)
        self.jac_rows, self.jac_cols = key // self.n, key % self.n
        self.m = int(self._offsets[-1])
        # The Hessian of the Lagrangian's lower triangle, likewise: each entry folded below the diagonal.
        rows = np.concatenate([b.hessian_rows for b in blocks] + [c.rows for c in self.curvatures])
        cols = np.concatenate([b.hessian_cols for b in blocks] + [c.cols for c in self.curvatures])
        key, self._hessian_entry = np.unique(np.maximum(rows, cols) * self.n + np.minimum(rows, cols), return_inverse=True)
        self.hess_rows, self.hess_cols = key // self.n, key % self.n

    def _contact_blocks(self, k: int) -> list[Block]:
        """Phase k's feet: on the ground or above it at the points (`Feet`), at rest at the knots, clear of the ground
        between the points, in the friction cone, a flat foot's torques within eq. 6."""
        blocks: list[Block] = [Feet(self, k)] if self.foot_names else []
        blocks.extend(stance_blocks(self, k))
        blocks.extend(clearance_blocks(self, k))
        blocks.extend(friction_cone_blocks(self, k))
        blocks.extend(foot_torque_blocks(self, k))
        return blocks

    # ------------------------------------------------------------------ NLP interface
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) (n,) of the variables: q, v, u bounds at every point, the stance force floor, the slack zero at
        the knots, the durations', the fixed ends', the impulses', the translation gauge and p1 zero when unused."""
        lower, upper = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        for k, phase in enumerate(self.phases):
            index = self.point_index[k]
            for part, bounds in ((slice(0, self.nq), self.q_bounds), (slice(self.nq, self.nx), self.v_bounds),
                                 (slice(self.nx, self.nx + self.nu), self.u_bounds)):
                if bounds is not None:
                    lower[index[:, part]] = np.asarray(bounds[0], dtype=np.float64)
                    upper[index[:, part]] = np.asarray(bounds[1], dtype=np.float64)
            normal = index[:, self.force_columns[k]][:, self.force_dims - 1 :: self.force_dims]
            lower[normal] = self.min_normal_force  # unilateral contact (eq. 5), with its margin
            lower[index[0::2, self.slack_columns[k]]] = upper[index[0::2, self.slack_columns[k]]] = 0.0  # the slack acts at the midpoints
            lower[self.duration_index[k]], upper[self.duration_index[k]] = phase.duration
        for state, point in ((self.initial, self.point_index[0][0]), (self.final, self.point_index[-1][-1])):
            if state is not None:
                values = np.concatenate([np.asarray(state[0], dtype=np.float64), np.asarray(state[1], dtype=np.float64)])
                if values.shape != (self.nx,):
                    raise ValueError(f"initial/final must be (q (nq,), v (nv,)), got {values.shape[0]} values for nq + nv = {self.nx}")
                fixed = ~np.isnan(values)
                lower[point[: self.nx][fixed]] = upper[point[: self.nx][fixed]] = values[fixed]
        for index in self.impulse_index.values():
            lower[index], upper[index] = -self.max_impulse, self.max_impulse
        if self.translation_gauge:
            lower[self.point_index[0][0, :2]] = upper[self.point_index[0][0, :2]] = 0.0
        if not self.uses_p1:
            lower[self.p1_index] = upper[self.p1_index] = 0.0
        return lower, upper

    @property
    def translation_gauge(self) -> bool:
        """A periodic free-flyer gait is invariant to horizontal translation (flat ground, feet free to land
        anywhere): the base starts at x = y = 0, which makes its optimum isolated (`solve` moves the guess)."""
        return self.periodic and self.model.floating_base and self.initial is None and self.final is None

    def gauged(self, x: np.ndarray) -> np.ndarray:
        """x translated horizontally so that the base starts at x = y = 0 (`translation_gauge`)."""
        x = np.array(x, dtype=np.float64)
        if self.translation_gauge:
            shift = x[self.point_index[0][0, :2]].copy()
            for index in self.point_index:
                x[index[:, :2]] -= shift
        return x

    def constraints(self, x: np.ndarray) -> np.ndarray:
        """The rows (m,) at x, block after block."""
        return np.concatenate([b.values(x) for b in self.blocks])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """The rows' Jacobian at x on (jac_rows, jac_cols)."""
        values = np.concatenate([b.jacobian(x) for b in self.blocks])
        return np.bincount(self._entry, weights=values, minlength=len(self.jac_rows))

    def hessian(self, x: np.ndarray, objective_factor: float, multipliers: np.ndarray) -> np.ndarray:
        """The lower triangle of objective_factor d2f/dx2 + sum_i multipliers_i d2g_i/dx2 on (hess_rows, hess_cols):
        each block's curvature by central differences of its exact Jacobian (`blocks.group_hessian`)."""
        values = [b.hessian(x, multipliers[start:stop]) for b, start, stop in zip(self.blocks, self._offsets, self._offsets[1:])]
        if objective_factor != 0.0:
            values += [objective_factor * c.values(x) for c in self.curvatures]
        else:
            values += [np.zeros(len(c.rows)) for c in self.curvatures]
        return np.bincount(self._hessian_entry, weights=np.concatenate(values), minlength=len(self.hess_rows))

    def nlp(self, derivatives: str = "legkit", objective: bool = True) -> NLP:
        """The NLP: objective, constraints and their exact Jacobian from legkit's kernels. derivatives="legkit": IPOPT
        approximates the Hessian of the Lagrangian by L-BFGS; "exact": it is given `hessian`. objective=False: the
        constraints alone (objective 0)."""
        if derivatives not in DERIVATIVES:
            raise ValueError(f"derivatives must be one of {DERIVATIVES}, got {derivatives!r}")
        lower, upper = self.bounds()
        f, gradient = (self.objective, self.gradient) if objective else (lambda x: 0.0, lambda x: np.zeros(self.n))
        hessian = None
        if derivatives == "exact":
            hessian = self.hessian if objective else (lambda x, _, multipliers: self.hessian(x, 0.0, multipliers))
        return NLP(lower, upper, np.concatenate([b.lower for b in self.blocks]), np.concatenate([b.upper for b in self.blocks]),
                   f, gradient, self.constraints, self.jacobian, self.jac_rows, self.jac_cols, hessian, self.hess_rows, self.hess_cols)

    def p1_held(self, derivatives: str, p1: float) -> NLP:
        """The NLP with p1 held at `p1`: the constraints, every S_H row at least p1 (J_s2 then constant)."""
        nlp = self.nlp(derivatives)
        nlp.x_lower[self.p1_index] = nlp.x_upper[self.p1_index] = p1
        return nlp
