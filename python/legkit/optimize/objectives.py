"""Performance indices of [Hardt 2002, Sect. 3.2]
as objectives of a `MultiphaseProblem`; a problem sums its terms, each scaled by its `weight`.

* `Integral` terms, integrated over every phase by the collocation's own Simpson rule (weights h/6 (1, 4, 1)
  per interval) and optionally divided by the distance travelled d = speed x cycle time:
  - `joule_loss`: J_e1 = (1 / d_S) int sum_i R_i (u_i / (G_i K_i))^2 dt (eq. 12);
  - `specific_resistance`: J_e2 = int sum_i |u_i w_i| / (m g v) dt (eq. 13), with |.| smoothed as
    sqrt(x^2 + eps^2) and v the forward velocity of the centre of mass;
  - `effort`: int sum_i w_i u_i^2 dt (a plain control effort, e.g. for a pendulum swing-up);
  - `fri_deviation`: J_s1 = int (GCoM_x - S_x)^2 + (GCoM_y - S_y)^2 dt (eq. 9), S the FRI of the phase's feet
    on the ground (eq. 8, `legkit.stability.foot_rotation_indicator`).
* `MinMaxStability`: J_s2 = -p1 with S_H(t) - p1 >= 0 at every knot and midpoint (eq. 11), S_H as published
  (eq. 10, `legkit.stability.angular_momentum_stability(..., definition="paper")`) or, by default, a smooth
  lower bound of it per phase (below), which IPOPT can converge on. The reported S_H is always the published.

The smooth constraint (`MinMaxStability(smooth=True)`, phases of exactly two feet). The published S_H of a
two-leg support has one edge, tipped over on one side chosen by a case switch, and on a diagonal edge the
case "GCoM before the edge" (d > 0) adds the branch H - H_ref, which vanishes from the min once the GCoM has
passed (d <= 0): S_H jumps there, and the switch makes the constraint non-smooth. Here the contact sequence
fixes, per phase, the diagonal pair and the tipping side (a diagonal pair forward along the direction of
travel, a lateral pair away from the GCoM of the model's neutral pose: the published rule applied once), and
H_ref = m r |d| sqrt(2 g / (r + h)) (the published m r sqrt(2 g (r - h)), rise r - h = d^2 / (r + h)) is
continued through d = 0 with its sign, H_ref,s = m r d sqrt(2 g / (r + h)). The constraints are then

    lateral pair       H_ref,s - H - p1 >= 0, d >= 0                  (= S_H - p1: the second row keeps the
                                                                       GCoM inside the support line, where
                                                                       the published side is the outer one)
    diagonal pair      H - H_ref,s - p1 >= 0,  H_max - H - p1 >= 0    (= S_H - p1 while d > 0; past the
                                                                       edge the first only adds -H_ref,s >= 0)

smooth in (q, v), and they imply S_H - p1 >= 0 (for a diagonal pair the continued branch
H + m r |d| sqrt(...) >= p1 is a small extra demand past the edge, where the published index drops it; a
lateral pair without d >= 0 let the GCoM cross the support line, where the published index turns to the
other side: measured S_H min -0.046 under p1 = 0.045). So p1 stays a lower bound of the published worst case; the optimum's published
S_H is re-evaluated and reported.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

import legkit as lk
from legkit.optimize import kinematics as kin
from legkit.optimize.blocks import Block, Point, group_hessian, group_pattern
from legkit.optimize.collocation import complex_step_jacobian, point_jacobian
from legkit.optimize.contact import ContactModel
from legkit.stability import angular_momentum_stability_of_model, foot_rotation_indicator

#: Smoothing of |x| in J_e2 [W]: sqrt(x^2 + eps^2) keeps the integrand differentiable where a joint's power is 0.
POWER_SMOOTHING = 1e-3

Integrand = Callable[[ContactModel, np.ndarray, int], np.ndarray]


@dataclass(frozen=True)
class Integral:
    """weight x int integrand dt (/ distance travelled if per_distance); integrand(problem, z (P, nz), k) -> (P,)
    at phase k's point variables z."""

    integrand: Integrand
    per_distance: bool = False
    weight: float = 1.0
    #: (problem, z (P, nz), k) -> (P, nz): the integrand's gradient where it has a closed form; else `point_jacobian`'s.
    slopes: Integrand | None = None
    #: problem -> the point variables the integrand depends on nonlinearly (default: all), for the Hessian.
    nonlinear: Callable[[ContactModel], np.ndarray] | None = None


@dataclass(frozen=True)
class MinMaxStability:
    """J_s2 (eq. 11): maximise p1 <= S_H(t). diagonal_pairs: pairs of foot names whose support edges are
    diagonal; v_tip_max [m/s]: the swing-leg tip speed of H_max; direction: of travel."""

    v_tip_max: float
    diagonal_pairs: Sequence[tuple[str, str]] = ()
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    weight: float = 1.0
    smooth: bool = True  # the smooth per-phase constraint of the module docstring; False: S_H as published


def effort(weights: ArrayLike = 1.0, weight: float = 1.0) -> Integral:
    """int sum_i weights_i u_i^2 dt."""
    w = np.asarray(weights, dtype=np.float64)

    def slopes(problem: ContactModel, z: np.ndarray, _: int) -> np.ndarray:
        out = np.zeros_like(z)
        out[:, problem.nx : problem.nx + problem.nu] = 2.0 * w * z[:, problem.nx : problem.nx + problem.nu]
        return out

    return Integral(lambda problem, z, _: np.sum(w * z[:, problem.nx : problem.nx + problem.nu] ** 2, axis=1), weight=weight,
                    slopes=slopes, nonlinear=lambda problem: np.arange(problem.nx, problem.nx + problem.nu))


def joule_loss(resistance: ArrayLike, gear_ratio: ArrayLike, torque_constant: ArrayLike, weight: float = 1.0) -> Integral:
    """J_e1 of eq. 12: (1 / d_S) int sum_i R_i (u_i / (G_i K_i))^2 dt, per actuated joint (arrays or scalars)."""
    w = np.asarray(resistance, dtype=np.float64) / (np.asarray(gear_ratio, dtype=np.float64) * np.asarray(torque_constant, dtype=np.float64)) ** 2
    term = effort(w)
    return Integral(term.integrand, per_distance=True, weight=weight, slopes=term.slopes, nonlinear=term.nonlinear)


def specific_resistance(weight: float = 1.0) -> Integral:
    """J_e2 of eq. 13: int sum_i |u_i w_i| / (m g v) dt, v the COM's forward (x) velocity."""

    def integrand(problem: ContactModel, z: np.ndarray, _: int) -> np.ndarray:
        u = z[:, problem.nx : problem.nx + problem.nu]
        w = z[:, problem.nq + np.asarray(problem.actuated)]
        power = np.sum(np.sqrt((u * w) ** 2 + POWER_SMOOTHING**2), axis=1)
        model = problem.model
        momentum = np.asarray(lk.centroidal_momentum(model, problem.configuration(z[:, : problem.nq]), z[:, problem.nq : problem.nx]))
        return power / (model.total_mass * -model.gravity[2] * momentum[:, 0] / model.total_mass)

    return Integral(integrand, weight=weight)


def fri_deviation(weight: float = 1.0) -> Integral:
    """J_s1 of eq. 9 (Stability Performance 1): int (GCoM_x - S_x)^2 + (GCoM_y - S_y)^2 dt [m^2 s], S the FRI
    point of the feet on the ground in each phase (eq. 8), computed by `legkit.stability.foot_rotation_indicator`
    from (q, v, a) at every collocation point, GCoM the ground projection of the centre of mass. As published:
    the squared distance integrated, not divided by the period (the text says "average distance"). Eq. 8 is
    taken with the feet's weight acting downwards (the published "- SG_j x m_j g" reads g as pointing up;
    `legkit.stability.fri` docstring). Every phase needs a foot on the ground (S is undefined in flight)."""

    def integrand(problem: ContactModel, z: np.ndarray, k: int) -> np.ndarray:
        feet = _support_bodies(problem, k)
        q, v = problem.configuration(z[:, : problem.nq]), z[:, problem.nq : problem.nx]
        fri = foot_rotation_indicator(problem.model, q, v, problem.accelerations(z, k), feet)
        gcom = np.asarray(lk.center_of_mass(problem.model, q))
        return np.sum((gcom[:, :2] - fri[:, :2]) ** 2, axis=1)

    return Integral(integrand, weight=weight)


def _support_bodies(problem: ContactModel, k: int) -> list[int]:
    """The distinct bodies of phase k's feet on the ground: the feet of eq. 8."""
    contacts = problem.phases[k].contacts
    if not contacts:
        raise ValueError(f"fri_deviation (J_s1, eq. 9) needs a foot on the ground in every phase; phases[{k}] has none")
    return sorted({problem.foot_body[name] for name in contacts})


def _simpson_weights(intervals: int) -> np.ndarray:
    """Simpson weights of the 2N + 1 points of N intervals, in units of h / 6."""
    c = np.tile([2.0, 4.0], intervals + 1)[: 2 * intervals + 1]
    c[0] = c[-1] = 1.0
    return c


def build_objective(problem: ContactModel, terms: Sequence) -> tuple[Callable, Callable, list[IntegralCurvature], list[Block]]:
    """(objective(x), gradient(x), the integrals' curvatures, extra constraint blocks) of the summed terms."""
    integrals = [t for t in terms if isinstance(t, Integral)]
    stability = [t for t in terms if isinstance(t, MinMaxStability)]
    unknown = [t for t in terms if not isinstance(t, (Integral, MinMaxStability))]
    if unknown:
        raise TypeError(f"objectives must be Integral or MinMaxStability terms, got {type(unknown[0]).__name__}")
    if len(stability) > 1:
        raise ValueError("objectives may hold one MinMaxStability term")
    if any(t.per_distance for t in integrals) and problem.speed == 0.0:
        raise ValueError("a per-distance objective (J_e1) needs speed != 0")
    weights = [_simpson_weights(p.intervals) / (6.0 * p.intervals) for p in problem.phases]  # x T gives the quadrature

    def integral(term: Integral, x: np.ndarray, gradient: np.ndarray | None) -> float:
        total, by_duration = 0.0, np.zeros(len(problem.phases))
        for k, index in enumerate(problem.point_index):
            duration = x[problem.duration_index[k]]
            z = x[index]
            if gradient is None:
                values = term.integrand(problem, z, k)
            elif term.slopes is not None:
                values = term.integrand(problem, z, k)
                np.add.at(gradient, index, duration * weights[k][:, None] * term.slopes(problem, z, k))
            else:
                def phase_integrand(zz: np.ndarray, phase: int = k) -> np.ndarray:
                    return term.integrand(problem, zz, phase)[:, None]

                values, jac = point_jacobian(phase_integrand, z)
                values = values[:, 0]
                np.add.at(gradient, index, duration * weights[k][:, None] * jac[:, 0])
            by_duration[k] = weights[k] @ values
            total += duration * by_duration[k]
        scale = term.weight
        if term.per_distance:
            distance = abs(problem.speed) * np.sum(x[problem.duration_index])
            if gradient is not None:
                gradient[problem.duration_index] += by_duration
                gradient *= scale / distance
                gradient[problem.duration_index] -= scale * total * abs(problem.speed) / distance**2
            return scale * total / distance
        if gradient is not None:
            gradient[problem.duration_index] += by_duration
            gradient *= scale
        return scale * total

    def objective(x: np.ndarray) -> float:
        value = sum(integral(t, x, None) for t in integrals)
        return value - sum(t.weight * x[problem.p1_index] for t in stability)

    def gradient(x: np.ndarray) -> np.ndarray:
        total = np.zeros(problem.n)
        for term in integrals:
            part = np.zeros(problem.n)
            integral(term, x, part)
            total += part
        for stable in stability:
            total[problem.p1_index] -= stable.weight
        return total

    blocks = [_stability_block(problem, k, stability[0]) for k in range(len(problem.phases))] if stability else []
    return objective, gradient, [IntegralCurvature(problem, term, weights) for term in integrals], blocks


class IntegralCurvature:
    """The Hessian of an `Integral` term J = scale sum_k T_k S_k (over the distance s D, D = sum_k T_k, s = |speed|,
    if per_distance), S_k = sum_p w_kp phi(z_kp) the phase's quadrature: T_k w_kp d2 phi / dz2 per point (by
    `group_hessian` of phi's gradient), the durations' w_kp d phi / dz, and with per_distance the terms of 1 / D.
    rows, cols: the entries' variables; values(x) in that order."""

    def __init__(self, problem: ContactModel, term: Integral, weights: list[np.ndarray]) -> None:
        self.problem, self.term, self.weights = problem, term, weights
        phases = len(problem.phases)
        rows, cols = [], []
        self._local = []
        self._columns = []
        for k, index in enumerate(problem.point_index):
            columns = np.arange(index.shape[1]) if term.nonlinear is None else np.asarray(term.nonlinear(problem), dtype=np.int64)
            r, c, local = group_pattern(index, columns)
            rows.append(r)
            cols.append(c)
            self._local.append(local)
            self._columns.append(columns)
            for j in range(phases) if term.per_distance else [k]:  # d2 J / dT_j dz_kp
                rows.append(np.full(index[:, columns].size, problem.duration_index[j]))
                cols.append(index[:, columns].ravel())
        if term.per_distance:
            first, second = np.tril_indices(phases)
            rows.append(problem.duration_index[first])
            cols.append(problem.duration_index[second])
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)

    def slopes(self, z: np.ndarray, k: int) -> np.ndarray:
        """(P, nz): d phi / dz at phase k's points z."""
        term, problem = self.term, self.problem
        if term.slopes is not None:
            return term.slopes(problem, z, k)
        return point_jacobian(lambda zz: term.integrand(problem, zz, k)[:, None], z)[1][:, 0]

    def values(self, x: np.ndarray) -> np.ndarray:
        problem, term = self.problem, self.term
        durations = x[problem.duration_index]
        total_time, speed = float(np.sum(durations)), abs(problem.speed)
        scale = term.weight / (speed * total_time) if term.per_distance else term.weight
        out, sums = [], np.zeros(len(durations))
        for k, index in enumerate(problem.point_index):
            z, w, columns = x[index], self.weights[k], self._columns[k]
            sums[k] = w @ term.integrand(problem, z, k)
            def phase_slopes(zz: np.ndarray, weight: np.ndarray, k: int = k) -> np.ndarray:
                return weight * self.slopes(zz, k)

            curvature = group_hessian(phase_slopes, z, w[:, None], columns, exact=term.slopes is not None)
            out.append(scale * durations[k] * curvature.ravel()[self._local[k]])
            gradient = (w[:, None] * self.slopes(z, k))[:, columns].ravel()
            if term.per_distance:
                out.extend(scale * gradient * ((j == k) - durations[k] / total_time) for j in range(len(durations)))
            else:
                out.append(scale * gradient)
        if term.per_distance:
            i, j = np.tril_indices(len(durations))
            weighted = float(durations @ sums)
            out.append(scale * (2.0 * weighted / total_time**2 - (sums[i] + sums[j]) / total_time))
        return np.concatenate(out)


def published_stability(problem: ContactModel, k: int, term: MinMaxStability, z: np.ndarray) -> np.ndarray:
    """S_H as published (eq. 10, `definition="paper"`) at phase k's point variables z (P, nz)."""
    contacts = list(problem.phases[k].contacts)
    pairs = np.array([(contacts.index(a), contacts.index(b)) for a, b in term.diagonal_pairs if a in contacts and b in contacts],
                     dtype=np.int64).reshape(-1, 2)
    q = z[:, : problem.nq]
    return angular_momentum_stability_of_model(
        problem.model, problem.configuration(q), z[:, problem.nq : problem.nx], problem.foot_positions(q, contacts),
        v_tip_max=term.v_tip_max, definition="paper", direction=term.direction, diagonal_pairs=pairs)


def _smooth_edge(problem: ContactModel, k: int, term: MinMaxStability) -> tuple[list[str], bool]:
    """Phase k's edge (start, end), ordered so that n = (dy, -dx) / |.| points to the side tipped over, and
    whether it is diagonal (module docstring); the side is fixed from the model's neutral pose."""
    contacts = list(problem.phases[k].contacts)
    if len(contacts) != 2:
        raise ValueError(f"MinMaxStability(smooth=True) needs exactly two feet on the ground per phase; phases[{k}] has "
                         f"{contacts} (use smooth=False for S_H as published)")
    diagonal = any(set(pair) == set(contacts) for pair in term.diagonal_pairs)
    q = np.asarray(problem.model.neutral(), dtype=np.float64)[None]
    start, end = problem.foot_positions(q, contacts)[0]
    normal = np.array([end[1] - start[1], start[0] - end[0]])
    if diagonal:  # tipped over forward
        side = float(normal @ np.asarray(term.direction, dtype=np.float64)[:2])
    else:  # away from the GCoM
        side = -float(normal @ (np.asarray(lk.center_of_mass(problem.model, q))[0, :2] - start[:2]))
    if side == 0.0:
        raise ValueError(f"phases[{k}]: the edge {contacts} is parallel to the direction of travel or passes through the "
                         "GCoM in the model's neutral pose; its tipping side is undefined")
    return (contacts if side > 0.0 else contacts[::-1]), diagonal


def _smooth_margin(problem: ContactModel, k: int, term: MinMaxStability) -> tuple[Callable, int, Callable, Callable]:
    """The smooth constraint rows (module docstring) as a function of (B, nx + 1) = [q, v, p1], their number, their
    Jacobian (B, rows, nx + 1) and their curvature ((B, nx + 1), weights (B, rows)) -> (B, nx + 1, nx + 1)."""
    edge, diagonal = _smooth_edge(problem, k, term)
    model, nq, nv, nx = problem.model, problem.nq, problem.nv, problem.nx
    m, g = model.total_mass, -float(model.gravity[2])
    outputs = 2  # rows per point, on either kind of pair
    p1_slopes = np.array([-1.0, -1.0 if diagonal else 0.0])
    basis = np.eye(15)  # d of each geometry variable: c, start, end, h
    d_o = basis[0:3] - basis[3:6]  # o = c - start
    d_edge = basis[6:8] - basis[3:5]  # (dx, dy) = end - start
    d_h = basis[9:]

    def primitives(geometry: np.ndarray) -> tuple[np.ndarray, ...]:
        """(H, d, H_ref, r) at geometry (B, 15) = [c, start, end, h] and their slopes (B, 15) in it: H = e_l . (k_G +
        o x P), the momentum about the edge, with o = c - start; d = e_l x o the GCoM's distance inside the edge;
        r = |(d, o_z)|; H_ref = m r d sqrt(2 g / (r + o_z)). Closed form, complex-analytic (`complex_step_jacobian`)."""
        c, start, end, h = geometry[:, 0:3], geometry[:, 3:6], geometry[:, 6:9], geometry[:, 9:]
        dx, dy = end[:, 0] - start[:, 0], end[:, 1] - start[:, 1]
        length = np.sqrt(dx * dx + dy * dy)
        ax, ay = dx / length, dy / length  # e_l; its slope is n n^T / length along (dx, dy), n = (ay, -ax)
        ox, oy, oz = (c - start).T
        turn = (ay[:, None] * d_edge[0] - ax[:, None] * d_edge[1]) / length[:, None]  # (B, 15): d e_l = turn (ay, -ax)
        d_ax, d_ay = ay[:, None] * turn, -ax[:, None] * turn
        kx, ky = h[:, 3] + oy * h[:, 2] - oz * h[:, 1], h[:, 4] + oz * h[:, 0] - ox * h[:, 2]
        momentum = ax * kx + ay * ky
        d_kx = d_h[3] + oy[:, None] * d_h[2] + h[:, 2, None] * d_o[1] - oz[:, None] * d_h[1] - h[:, 1, None] * d_o[2]
        d_ky = d_h[4] + oz[:, None] * d_h[0] + h[:, 0, None] * d_o[2] - ox[:, None] * d_h[2] - h[:, 2, None] * d_o[0]
        d_momentum = d_ax * kx[:, None] + d_ay * ky[:, None] + ax[:, None] * d_kx + ay[:, None] * d_ky
        d = ax * oy - ay * ox
        d_d = d_ax * oy[:, None] + ax[:, None] * d_o[1] - d_ay * ox[:, None] - ay[:, None] * d_o[0]
        r = np.sqrt(d * d + oz * oz)
        d_r = (d[:, None] * d_d + oz[:, None] * d_o[2]) / r[:, None]
        root = np.sqrt(2.0 * g / (r + oz))
        d_root = -0.5 * root[:, None] * (d_r + d_o[2]) / (r + oz)[:, None]
        h_ref = m * r * d * root  # eq. 10's H_ref, continued with the sign of d
        d_h_ref = m * (d_r * (d * root)[:, None] + d_d * (r * root)[:, None] + d_root * (r * d)[:, None])
        return momentum, d, h_ref, r, d_momentum, d_d, d_h_ref, d_r

    def rows(geometry: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """(B, 2): the rows at geometry (B, 15) and p1 (B,)."""
        momentum, d, h_ref, r = primitives(geometry)[:4]
        if diagonal:
            return np.stack([momentum - h_ref - p1, m * r * term.v_tip_max - momentum - p1], axis=1)
        return np.stack([h_ref - momentum - p1, d], axis=1)  # d >= 0: the GCoM stays on the side the published rule reads

    def slopes(geometry: np.ndarray) -> np.ndarray:
        """(B, 2, 15): the rows' slopes in the geometry (p1's are `p1_slopes`)."""
        _, _, _, _, d_momentum, d_d, d_h_ref, d_r = primitives(geometry)
        if diagonal:
            return np.stack([d_momentum - d_h_ref, m * term.v_tip_max * d_r - d_momentum], axis=1)
        return np.stack([d_h_ref - d_momentum, d_d], axis=1)

    points = [(problem.foot_body[n], problem.foot_point[n]) for n in edge]

    def geometry_of(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(unit q, the geometry (B, 15) = [c, start, end, h])."""
        q = problem.configuration(z[:, :nq])
        c = np.asarray(lk.center_of_mass(model, q))
        h = np.asarray(lk.centroidal_momentum(model, q, z[:, nq:nx]))
        feet = problem.foot_positions(z[:, :nq], edge)
        return q, np.concatenate([c, feet.reshape(len(z), 6), h], axis=1)

    def margin(z: np.ndarray) -> np.ndarray:
        return rows(geometry_of(z)[1], z[:, nx])

    def geometry_slopes(z: np.ndarray, q: np.ndarray) -> np.ndarray:
        """(B, 15, nx): the geometry's Jacobian in the raw (q, v) from the kernels (h = A_G(q) v; its q slope by
        `lk.centroidal_derivatives`)."""
        out = np.zeros((len(z), 15, nx))
        centroidal = np.asarray(lk.centroidal_derivatives(model, q, z[:, nq:nx], np.zeros((len(z), nv)))[0])
        tangent = np.concatenate([np.asarray(lk.center_of_mass_jacobian(model, q)),
                                  kin.point_jacobians(model, q, points)[:, :, :3].reshape(len(z), 6, nv), centroidal], axis=1)
        out[:, :, :nq] = kin.raw(model, z[:, :nq], tangent)
        out[:, 9:, nq:] = np.asarray(lk.centroidal_map(model, q))
        return out

    def derivative(z: np.ndarray) -> np.ndarray:
        """The rows' closed-form slopes in the geometry chained with its Jacobian from the kernels; p1 enters with
        `p1_slopes`. A free-flyer's position drops out of every difference."""
        q, geometry = geometry_of(z)
        by_state = slopes(geometry) @ geometry_slopes(z, q)
        return np.concatenate([by_state, np.broadcast_to(p1_slopes[:, None], (len(z), outputs, 1))], axis=2)

    def curvature(z: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(B, nx + 1, nx + 1): the Hessian of weights . rows = sum_r w_r rows_r(g(q, v)) - p1 terms:
        J_g^T (d2/dg2) J_g + (d/dg) . d2 g/dx2. The rows' d2/dg2 by complex steps of their closed-form slopes along c and
        the feet (they are affine in h); g's curvature from the kernels: `lk.center_of_mass_hessian`,
        `lk.centroidal_momentum_hessian` and the feet's `kin.tangent_position_curvature`, through `kin.raw_hessian`."""
        q, geometry = geometry_of(z)
        count = len(z)
        by_geometry = np.einsum("br,brk->bk", weights, slopes(geometry))  # (B, 15)
        columns = np.arange(9)

        def weighted(gg: np.ndarray) -> np.ndarray:
            return np.einsum("br,brk->bk", np.repeat(weights, len(columns), axis=0), slopes(gg))

        second = np.zeros((count, 15, 15))
        second[:, :, columns] = complex_step_jacobian(weighted, geometry, columns)
        second[:, columns, 9:] = np.swapaxes(second[:, 9:, columns], 1, 2)
        jac = geometry_slopes(z, q)
        out = np.zeros((count, nx + 1, nx + 1))
        out[:, :nx, :nx] = np.swapaxes(jac, 1, 2) @ second @ jac
        com_qq, com_q = (np.asarray(x) for x in lk.center_of_mass_hessian(model, q, by_geometry[:, :3]))
        momentum_qq, momentum_qv, momentum_q = (np.asarray(x) for x in lk.centroidal_momentum_hessian(model, q, z[:, nq:nx], by_geometry[:, 9:]))
        feet_qq, feet_q = kin.tangent_position_curvature(model, q, points, by_geometry[:, 3:9].reshape(count, 2, 3))
        out[:, :nq, :nq] += kin.raw_hessian(model, z[:, :nq], com_qq + momentum_qq + feet_qq, com_q + momentum_q + feet_q)
        cross = np.swapaxes(kin.tangent_map(model, z[:, :nq]), 1, 2) @ momentum_qv  # [q_raw, v]
        out[:, :nq, nq:nx] += cross
        out[:, nq:nx, :nq] += np.swapaxes(cross, 1, 2)
        return out

    return margin, outputs, derivative, curvature


def _stability_block(problem: ContactModel, k: int, term: MinMaxStability) -> Block:
    """S_H(q, v) - p1 >= 0 at every point of phase k (eq. 11): published, or its smooth lower bound."""
    contacts = list(problem.phases[k].contacts)
    if len(contacts) < 2:
        raise ValueError(f"MinMaxStability needs two feet on the ground in every phase (S_H, eq. 10); phases[{k}] has {contacts}")
    index = problem.point_index[k]
    columns = np.concatenate([index[:, : problem.nx], np.full((len(index), 1), problem.p1_index)], axis=1)
    if term.smooth:
        margin, rows, derivative, curvature = _smooth_margin(problem, k, term)
        return Point(columns, margin, rows, 0.0, np.inf, derivative=derivative, nonlinear=problem.q_without_translation,
                     curvature=curvature)
    nx = problem.nx
    return Point(columns, lambda z: (published_stability(problem, k, term, z) - z[:, nx])[:, None], 1, 0.0, np.inf)
