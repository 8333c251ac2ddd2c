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

    def height_gradient(g: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """weights (B, fractions x swing) . d heights / dg (B, columns), through q_s = b0 q0 + b1 h rate0 + b2 q1
        + b3 h rate1 at each fraction."""
        q0, v0, q1, v1, h = states(g)
        (dq0, dv0), (dq1, dv1) = kin.q_rate_derivatives(problem.model, q0, v0), kin.q_rate_derivatives(problem.model, q1, v1)
        dv0, dv1 = dv0[:, :, v_columns], dv1[:, :, v_columns]
        rate0, rate1 = problem.q_rate(q0, v0), problem.q_rate(q1, v1)
        out = np.zeros_like(g)
        for f, b in enumerate(basis):
            q = b[0] * q0 + b[1] * h * rate0 + b[2] * q1 + b[3] * h * rate1
            height = kin.point_jacobians(problem.model, problem.configuration(q), swing_points)[:, :, 2]  # (B, swing, nv)
            on_q = kin.raw(problem.model, q, np.einsum("bs,bsj->bj", weights[:, f * len(swing) : (f + 1) * len(swing)], height)[:, None])[:, 0]
            out[:, spans[0][0] : spans[0][1]] += (b[0] * on_q + b[1] * h * kin.vecmat(on_q, dq0))[:, q_columns]
            out[:, spans[1][0] : spans[1][1]] += b[1] * h * kin.vecmat(on_q, dv0)
            out[:, spans[2][0] : spans[2][1]] += (b[2] * on_q + b[3] * h * kin.vecmat(on_q, dq1))[:, q_columns]
            out[:, spans[3][0] : spans[3][1]] += b[3] * h * kin.vecmat(on_q, dv1)
            out[:, -1] += np.sum(on_q * (b[1] * rate0 + b[3] * rate1), axis=1) / intervals
        return out

    return [Point(groups, heights, len(basis) * len(swing), 0.0, np.inf, gradient=height_gradient)]
