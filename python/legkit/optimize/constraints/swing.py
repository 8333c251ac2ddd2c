"""Eq. 4 of [Hardt 2002] between the collocation points: the swing tips above the ground on the state's Hermite
cubic (`clearance_blocks`); at the points themselves `stance.Feet` holds them."""

from __future__ import annotations

import numpy as np

from legkit.optimize import kinematics as kin
from legkit.optimize.blocks import Block, Point
from legkit.optimize.collocation import hermite_basis
from legkit.optimize.contact import ContactModel

#: Where on each interval (fractions of it) `clearance_blocks` holds the swing tips above the ground.
CLEARANCE_FRACTIONS = (0.25, 0.75)

def clearance_blocks(problem: ContactModel, k: int) -> list[Block]:
    """Eq. 4 between the collocation points of phase k: each swing tip (and sole point) at or above the ground
    at `CLEARANCE_FRACTIONS` of every interval, on the state's Hermite cubic through the interval's knots
    with their rates [dq/dt] scaled by the interval's length (the curve `legkit.optimize.replay` samples).
    At the points alone, the converged amble's swing feet dipped up to 11 mm below the ground between them,
    and a replay stumbled on them."""
    contacts = problem.phases[k].contacts
    swing = [n for n in problem.foot_names + list(problem.sole_points) if problem.sole_points.get(n, n) not in contacts]
    if not swing:
        return []
    nq, nv, intervals = problem.nq, problem.nv, problem.phases[k].intervals
    # The swing feet's chains: a height is the same wherever in x, y and whatever the other legs do.
    ancestors, q_body, v_body = problem.tree()
    chain = list(set().union(*(ancestors[problem.foot_body[n]] for n in swing)))
    q_columns = np.flatnonzero(np.isin(q_body, chain))
    q_columns = q_columns[q_columns >= (2 if problem.model.floating_base else 0)]
    v_columns = np.flatnonzero(np.isin(v_body, chain))
    index = problem.point_index[k]
    groups = np.concatenate([index[0:-1:2][:, q_columns], index[0:-1:2][:, nq + v_columns], index[2::2][:, q_columns],
                             index[2::2][:, nq + v_columns], np.full((intervals, 1), problem.duration_index[k])], axis=1)
    c, cv = len(q_columns), len(v_columns)
    spans = ((0, c), (c, c + cv), (c + cv, 2 * c + cv), (2 * c + cv, 2 * (c + cv)))  # q0, v0, q1, v1; then the duration
    basis = [hermite_basis(s) for s in CLEARANCE_FRACTIONS]

    def full(part: np.ndarray, columns: np.ndarray = q_columns, size: int = nq) -> np.ndarray:  # zero elsewhere
        out = np.zeros((len(part), size))
        out[:, columns] = part
        return out

    def states(g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        q0, v0, q1, v1 = (g[:, a:b] for a, b in spans)
        return full(q0), full(v0, v_columns, nv), full(q1), full(v1, v_columns, nv), g[:, -1:] / intervals

    def heights(g: np.ndarray) -> np.ndarray:
        q0, v0, q1, v1, h = states(g)
        r0, r1 = h * problem.q_rate(q0, v0), h * problem.q_rate(q1, v1)
        q = np.stack([b[0] * q0 + b[1] * r0 + b[2] * q1 + b[3] * r1 for b in basis], axis=1)  # (B, fractions, nq)
        return problem.foot_positions(q, swing)[..., 2].reshape(len(g), -1)

    swing_points = [(problem.foot_body[n], problem.foot_point[n]) for n in swing]
    state_columns = np.r_[q_columns, nq + v_columns]
    end_columns = (np.r_[spans[0][0] : spans[1][1]], np.r_[spans[2][0] : spans[3][1]])

    def curve(g: np.ndarray) -> tuple[np.ndarray, list, list]:
        """h, and per end of the interval (q, v, its rate, the rate's d/dq and d/dv, its group columns), and per
        fraction q_s = b0 q0 + b1 h rate0 + b2 q1 + b3 h rate1 with its slope D = dq_s/dg (B, nq, columns)."""
        q0, v0, q1, v1, h = states(g)
        ends = [(q, v, problem.q_rate(q, v), *kin.q_rate_derivatives(problem.model, q, v), columns)
                for q, v, columns in ((q0, v0, end_columns[0]), (q1, v1, end_columns[1]))]
        points = []
        for b in basis:
            slope = np.zeros((len(g), nq, g.shape[1]))
            for identity, weight, (_, _, _, dq, dv, columns) in zip((b[0], b[2]), (b[1], b[3]), ends):
                slope[:, :, columns] = np.concatenate([identity * np.eye(nq)[:, q_columns] + weight * h[:, :, None] * dq[:, :, q_columns],
                                                       weight * h[:, :, None] * dv[:, :, v_columns]], axis=2)
            slope[:, :, -1] = (b[1] * ends[0][2] + b[3] * ends[1][2]) / intervals
            points.append((b[0] * q0 + b[1] * h * ends[0][2] + b[2] * q1 + b[3] * h * ends[1][2], slope))
        return h, ends, points

    def fraction_weights(weights: np.ndarray, f: int) -> np.ndarray:
        """(B, swing, 3): fraction f's multipliers on the swing points' heights (z)."""
        out = np.zeros((len(weights), len(swing), 3))
        out[:, :, 2] = weights[:, f * len(swing) : (f + 1) * len(swing)]
        return out

    def height_gradient(g: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """weights (B, fractions x swing) . d heights / dg (B, columns): the heights' raw gradient at each q_s times D."""
        _, _, points = curve(g)
        out = np.zeros_like(g)
        for f, (q, slope) in enumerate(points):
            height = kin.point_jacobians(problem.model, problem.configuration(q), swing_points)[:, :, :3]
            on_q = kin.raw(problem.model, q, np.einsum("bsr,bsrj->bj", fraction_weights(weights, f), height)[:, None])[:, 0]
            out += kin.vecmat(on_q, slope)
        return out

    def height_curvature(g: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(B, k, k): the Hessian of weights . heights: at each fraction D^T H D with H the heights' raw-q Hessian
        (`kinematics.position_curvature`), plus the curve's own curvature h (b1 d2rate0 + b3 d2rate1) weighted by the
        heights' raw gradient (`kinematics.q_rate_hessian`), and its cross slopes with h (h = T / intervals)."""
        h, ends, points = curve(g)
        out = np.zeros((len(g), g.shape[1], g.shape[1]))
        for f, (b, (q, slope)) in enumerate(zip(basis, points)):
            curvature, on_q = kin.position_curvature(problem.model, q, swing_points, fraction_weights(weights, f))
            out += np.swapaxes(slope, 1, 2) @ curvature @ slope
            for weight, (qe, ve, _, dq, dv, columns) in zip((b[1], b[3]), ends):
                rate_curvature = kin.q_rate_hessian(problem.model, qe, ve, on_q)[:, state_columns][:, :, state_columns]
                out[:, columns[:, None], columns] += weight * h[:, :, None] * rate_curvature
                by_h = weight * kin.vecmat(on_q, np.concatenate([dq[:, :, q_columns], dv[:, :, v_columns]], axis=2)) / intervals
                out[:, columns, -1] += by_h
                out[:, -1, columns] += by_h
        return out

    # A tip's height depends on its own leg's and the base's columns only.
    reaches = [list(ancestors[problem.foot_body[n]]) for n in swing]
    mask = np.tile([np.r_[np.tile(np.r_[np.isin(q_body[q_columns], reach), np.isin(v_body[v_columns], reach)], 2), True] for reach in reaches],
                   (len(basis), 1))
    return [Point(groups, heights, len(basis) * len(swing), 0.0, np.inf, gradient=height_gradient, curvature=height_curvature, mask=mask)]
