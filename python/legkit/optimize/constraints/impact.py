"""The inelastic impact of a touchdown (eq. 7 of [Hardt 2002]) in implicit form with the impulses as variables
(`impact_rows`, `impact_derivative`), and the velocity across a phase boundary (`velocity_transition`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import legkit as lk
from legkit.optimize import kinematics as kin
from legkit.optimize.blocks import Block, Point, equal
from legkit.optimize.contact import ContactModel
from legkit.optimize.layout import Start


def impact_rows(problem: ContactModel, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
    """The inelastic impact (eq. 7, as `lk.impact`) in implicit form at z = [q-, v-, v+, Lambda] (B, .):
    M(q) (v+ - v-) - J^T Lambda (nv rows) and J v+ (force_dims k rows), J = `contact_jacobian`."""
    nq, nv = problem.nq, problem.nv
    q, v_minus, v_plus, impulses = z[:, :nq], z[:, nq : nq + nv], z[:, nq + nv : nq + 2 * nv], z[:, nq + 2 * nv :]
    mass = np.asarray(lk.crba(problem.model, problem.configuration(q)))
    jac = problem.contact_jacobian(q, contacts)
    return np.concatenate([np.einsum("bij,bj->bi", mass, v_plus - v_minus) - np.einsum("bji,bj->bi", jac, impulses),
                           np.einsum("bij,bj->bi", jac, v_plus)], axis=1)


def impact_derivative(problem: ContactModel, z: np.ndarray, contacts: Sequence[str]) -> np.ndarray:
    """The Jacobian (B, rows, columns of z) of `impact_rows`: affine in v-, v+ and Lambda (-M, [M; J] and -J^T);
    d/dq of M(q) w by `kinematics.mass_slope`, of J^T Lambda by `kinematics.force_slope`, of J v+ by the
    points' velocity derivatives."""
    nq, nv, model = problem.nq, problem.nv, problem.model
    q = problem.configuration(z[:, :nq])
    v_minus, v_plus, impulses = z[:, nq : nq + nv], z[:, nq + nv : nq + 2 * nv], z[:, nq + 2 * nv :]
    points, full, contact = problem.contact_frames(q, contacts)
    mass = np.asarray(lk.crba(model, q))
    jac = np.zeros((len(z), nv + impulses.shape[1], z.shape[1]))
    top = kin.mass_slope(model, q, v_plus - v_minus) - kin.force_slope(model, q, points, problem.row_forces(impulses, contacts), full)
    bottom = np.concatenate([kin.point_velocity_derivatives(model, q, v_plus, body, point)[0][:, axes]
                             for body, point, axes in problem.contact_rows(contacts)], axis=1)
    jac[:, :, :nq] = kin.raw(model, z[:, :nq], np.concatenate([top, bottom], axis=1))
    jac[:, :nv, nq : nq + nv] = -mass
    jac[:, :nv, nq + nv : nq + 2 * nv] = mass
    jac[:, nv:, nq + nv : nq + 2 * nv] = contact
    jac[:, :nv, nq + 2 * nv :] = -contact.transpose(0, 2, 1)
    return jac


def impact_curvature(problem: ContactModel, z: np.ndarray, contacts: Sequence[str], weights: np.ndarray) -> np.ndarray:
    """(B, columns of z, columns of z): the Hessian of weights . `impact_rows` = w_M . M(q) (v+ - v-) - (J(q) w_M) .
    Lambda + w_J . J(q) v+, bilinear in q and the rest: w_M . M(q) dv curves in q as the RNEA at v = 0, a = dv less
    gravity (`lk.rnea_second_order_derivatives`, whose d2tau/da dq is dM/dq for the cross with v+ and v-); the
    loads' virtual powers Lambda . J(q) w_M and w_J . J(q) v+ by `lk.point_velocity_hessian`, crossing with Lambda by
    the points' velocity derivatives at w_M and with v+ along `lk.kinematic_hessian`."""
    nq, nv, model = problem.nq, problem.nv, problem.model
    q_raw, count = z[:, :nq], len(z)
    q = problem.configuration(q_raw)
    v_minus, v_plus, impulses = z[:, nq : nq + nv], z[:, nq + nv : nq + 2 * nv], z[:, nq + 2 * nv :]
    by_mass, by_rows = weights[:, :nv], weights[:, nv:]
    zero, change = np.zeros_like(v_plus), v_plus - v_minus
    moved, _, _, mass_turn = (np.einsum("bi,bijk->bjk", by_mass, np.asarray(t)) for t in lk.rnea_second_order_derivatives(model, q, zero, change))
    gravity = np.einsum("bi,bijk->bjk", by_mass, np.asarray(lk.rnea_second_order_derivatives(model, q, zero, zero)[0]))
    by_qq, by_q = moved - gravity, kin.vecmat(by_mass, kin.mass_slope(model, q, change))
    impulse_loads, row_loads = problem.row_forces(impulses, contacts), problem.row_forces(by_rows, contacts)
    by_v_plus, by_impulses = mass_turn.copy(), []  # [v+ or Lambda, dq]
    for c, (body, point, axes) in enumerate(problem.contact_rows(contacts)):  # a few points; each call batched
        impulse_qq, impulse_q = lk.point_velocity_hessian(model, q, by_mass, body, point, impulse_loads[:, c])
        rows_qq, rows_q = lk.point_velocity_hessian(model, q, v_plus, body, point, row_loads[:, c])
        by_qq, by_q = by_qq - np.asarray(impulse_qq) + np.asarray(rows_qq), by_q - np.asarray(impulse_q) + np.asarray(rows_q)
        by_v_plus += np.einsum("br,brad->bad", row_loads[:, c], np.asarray(lk.kinematic_hessian(model, q, body, point))[:, :3])
        by_impulses.append(-kin.point_velocity_derivatives(model, q, by_mass, body, point)[0][:, axes])
    tangent = kin.tangent_map(model, q_raw)
    out = np.zeros((count, z.shape[1], z.shape[1]))
    out[:, :nq, :nq] = kin.raw_hessian(model, q_raw, by_qq, by_q)
    for columns, block in [(slice(nq, nq + nv), -mass_turn), (slice(nq + nv, nq + 2 * nv), by_v_plus),
                           (slice(nq + 2 * nv, None), np.concatenate(by_impulses, axis=1))]:
        out[:, columns, :nq] = block @ tangent
        out[:, :nq, columns] = np.swapaxes(out[:, columns, :nq], 1, 2)
    return out


def velocity_transition(problem: ContactModel, k: int, start: Start) -> Block:
    """v after the boundary: the impact map (eq. 7) when feet touch down, else continuity. The impact is
    stated implicitly with the impulses as variables (`impact_rows`, bilinear in q and v+, v-, Lambda): the
    explicit map v+ = impact(q, v-) solves a KKT system whose second derivatives are far larger."""
    end = problem.point_index[k][-1]
    nq, nx, nv = problem.nq, problem.nx, problem.nv
    if k not in problem.impulse_index:
        return equal(nv, start.v, end[nq:nx], start.v_sign)
    contacts = problem.contacts_after(k)
    signs = np.r_[np.ones(nx), start.v_sign, np.ones(len(problem.impulse_index[k]))]
    index = np.concatenate([end[:nx], start.v, problem.impulse_index[k]])[None]
    return Point(index, lambda z: impact_rows(problem, signs * z, contacts), nv + len(problem.impulse_index[k]),
                 derivative=lambda z: impact_derivative(problem, signs * z, contacts) * signs, nonlinear=problem.q_without_translation,
                 curvature=lambda z, w: impact_curvature(problem, signs * z, contacts, w) * signs[:, None] * signs)
