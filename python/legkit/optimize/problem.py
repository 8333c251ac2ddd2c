"""Multiphase direct collocation of a legged robot's motion with a fixed contact sequence.

The transcription of [Hardt 2002, Sect. 2.3 and 4.1], on legkit's kernels:

* phases with fixed contact sets (the discrete state d(t) of Sect. 4.1), each with its duration as a variable;
* per phase a grid of `intervals` Hermite–Simpson intervals (eq. 14: cubic states, linear controls); at every
  knot and midpoint the variables z = [q, v, u, lambda, slack]: configuration, velocity, actuated torques,
  the world-frame contact forces of the phase's feet and the stance feet's slack (below);
* dynamics (eq. 1) in inverse-dynamics form: the accelerations a are variables too (z = [q, v, u, lambda, a,
  slack]), the state rate is [dq/dt(q, v), a], and at every point the RNEA residual rnea(q, v, a, J_c^T lambda)
  - B u = 0 (legkit's batched RNEA with the forces as external wrenches) closes the dynamics (Ferrolho et al.,
  ICRA 2021, found this form converging in fewer iterations than collocating the forward dynamics; its
  Jacobian is also sparser: a joint's torque depends on its own leg and the base only). The stance feet are
  held in DIRCON's form (Posa, Kuindersma & Tedrake 2016): at every knot on the ground, at rest and not
  accelerating (`constraints.stance.stance_blocks`), the midpoints freed from the contact manifold by a slack in the
  configuration rate (`rate`). Held at position level at every point instead, the forces were free to
  alternate between knots and midpoints (`stance_accelerations`);
* swing-tip height >= 0 (eq. 4) at the points and at fractions of every interval between them
  (`constraints.swing.clearance_blocks`), friction cone mu^2 F_z^2 - F_x^2 - F_y^2 >= 0 with F_z >= 0 (eq. 5, squared
  to stay smooth), for flat feet (`FlatFoot`) a contact torque T about the sole's centre within the foot-torque
  limits of eq. 6 and the whole sole held flat on the ground, the inelastic impact map at each touchdown (eq. 7, `lk.impact` with the new
  phase's feet),
  state/control bounds and the motor torque-speed line |u| <= (w_max - |w|) k (Sect. 2.3, split into its four
  linear faces); optionally each motor's input power within a limit (`InputPower`, Sect. 6);
* periodicity (Sect. 2.3: q(t_f) = q(0) up to the travelled distance, velocity after the wrap-around impact),
  or mirror periodicity over half a cycle for symmetric gaits (`mirror`: the phases are the first half, and
  the second half, the first's mirror image, begins where it ends: q(t_f) = mirror(q(0)) up to the travelled
  distance; `full_cycle` unrolls a solution), or fixed initial/final states.

The constraint Jacobian is exact, from the core's analytic derivatives (`lk.rnea_derivatives`, `lk.crba`, frame
Jacobians and their velocity and acceleration derivatives) in the variables' raw coordinates (`kinematics`);
its pattern, from the model's tree, is fixed before solving. So is the Hessian of the Lagrangian of the dynamics, the
feet's positions, velocities and accelerations, the swing clearance, the touchdown's impact and the smooth S_H margin
(`lk.rnea_second_order_derivatives`, `lk.kinematic_hessian`, `lk.point_velocity_hessian`,
`lk.point_acceleration_hessian`, `lk.center_of_mass_hessian`, `lk.centroidal_momentum_hessian`, through
`kinematics.raw_hessian`); the other blocks' curvature is differenced from their exact Jacobians
(`blocks.group_hessian`). Objectives: `objectives.py`.

The house, importing downward only: `definition` (the fields, checked) <- `layout` (the variables) <- `contact` (contact
kinematics at the point variables) <- `constraints` (one module per family) <- `assembly` (the NLP) <- `strategy` (how
it is solved) <- this module's `MultiphaseProblem`, the user-facing problem (its solves and the published S_H).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from legkit._validation import instance
from legkit.optimize import strategy
from legkit.optimize.assembly import Assembly
from legkit.optimize.layout import Trajectory
from legkit.optimize.objectives import MinMaxStability, published_stability
from legkit.optimize.solver import SolveResult
from legkit.optimize.strategy import REFINE_STABILITY


class MultiphaseProblem(Assembly):
    """Multiphase Hermite–Simpson transcription of a legged robot's motion (module docstring).

    feet: contact points by name, (body, point in body frame). actuated: v indices driven by u (default: every
    joint, i.e. v[6:] for a free-flyer, all of v otherwise). periodic: q, v wrap around (the travel coordinate
    q[travel_index] advancing by speed x cycle time); otherwise initial/final (q, v) fix the ends (NaN: free).
    mirror (periodic problems; `legkit.optimize.mirror`): the phases are half a cycle, the other half their
    mirror image. period: the cycle time (the whole cycle's, with a mirror), fixed (float) or bounded (lo, hi).
    force_dims: 3 (friction cone) or 1 (normal force only, for models that cannot push sideways). flat_feet:
    `FlatFoot` soles by foot name (eq. 6; needs force_dims 3). q/v/u_bounds: (lower, upper) arrays.
    max_impulse: a bound [N s] on every component of every touchdown impulse (eq. 7, the impulse variables); 0
    makes every touchdown soft, the landing feet arriving at rest and v continuous (a gait whose impacts carry
    the robot's momentum cannot be replayed by joint tracking). min_normal_force [N]: a floor
    on every stance foot's normal force at every point (eq. 5 with a margin: the min-max S_H optimum otherwise
    balances on one foot of two, leaving a tracking controller nothing to push with on the other).
    objectives: terms from `legkit.optimize.objectives`, summed. dense_rates (with a torque_speed line): each actuated
    joint's rate within the line's no-load speed over every interval, on the velocity's Hermite cubic, not only at
    the points (`constraints.rates.dense_rate_blocks`: its Bernstein control points bounded). max_yaw [rad]: a
    free-flyer's yaw (its heading about the world's z) within +-max_yaw at every point. max_force_rate [N/s], max_torque_rate [N m/s]:
    bounds on how fast the foot forces and the torques change, across phase boundaries too (a lifting foot unloads,
    a landing foot loads, within the half interval beside the switch): `constraints.rates.load_rate_blocks`.
    """

    def solve(self, guess: Trajectory | np.ndarray | SolveResult, derivatives: str = "exact", feasibility_first: bool = False,
              polish: bool = False, polish_max_iter: int = 1000, **options: Any) -> tuple[Trajectory, SolveResult]:
        """Solve from a guess (a Trajectory, a variable vector, or a neighbouring problem's `SolveResult`: a primal-dual warm
        start), with the exact Hessian or L-BFGS, optionally feasibility first and polished (`strategy.solve_problem`)."""
        return strategy.solve_problem(self, guess, derivatives, feasibility_first, polish, polish_max_iter, **options)

    def refined(self, coarse: MultiphaseProblem, x: np.ndarray) -> np.ndarray:
        """`x`, a point of `coarse` (this problem on other intervals per phase), on this problem's mesh (`strategy.refined`)."""
        instance(coarse, MultiphaseProblem, "coarse")
        return strategy.refined(self, coarse, x)

    def refine(self, coarse: MultiphaseProblem, result: SolveResult, stability_fraction: float = REFINE_STABILITY,
               derivatives: str = "exact", **options: Any) -> tuple[Trajectory, SolveResult]:
        """Mesh refinement: `result`, solved on `coarse`, made a solution of this problem (`strategy.refine`)."""
        instance(coarse, MultiphaseProblem, "coarse")
        return strategy.refine(self, coarse, result, stability_fraction, derivatives, **options)

    def continued(self, result: SolveResult, speed: float) -> SolveResult:
        """`result`, solved at `speed` [m/s], as a warm start at this problem's speed (`strategy.continued`)."""
        return strategy.continued(self, result, speed)

    def stability_index(self, x: np.ndarray) -> list[np.ndarray]:
        """S_H as published (eq. 10) at every point of every phase, for a problem with a MinMaxStability
        objective (whatever form its constraint takes)."""
        terms = [t for t in self.objectives if isinstance(t, MinMaxStability)]
        if not terms:
            raise ValueError("stability_index needs a problem whose objectives hold a MinMaxStability term")
        return [published_stability(self, k, terms[0], x[index]) for k, index in enumerate(self.point_index)]
