"""How far a transcription's solution is from a motion of its model, interval by interval.

Collocation meets the dynamics at the knots and midpoints only. From each knot, `interval_drift` integrates the
dynamics the transcription constrains (the phase's feet held as `Layout.contact_rows` hold them,
bilaterally; the controls interpolated linearly through knot, midpoint and knot, as the replay samples them) to
the interval's end, and compares the result with the next knot. On a mesh fine enough for the motion the
drift is small; on the Fig. 3 amble at 4 intervals per phase the 0.47 s lateral supports drifted by up to 47 deg
in the torso's attitude within one 0.117 s interval, against 0.8 deg at 16 intervals."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

import legkit as lk
from legkit._validation import count
from legkit.optimize.contact import ContactModel
from legkit.optimize.kinematics import rotation

#: Rates beyond this [rad/s, m/s] count as a blown-up integration (`interval_drift` reports inf there).
DIVERGED = 1e6
#: The most RK4 steps per interval `interval_drift` takes: the drift of a 16-interval plan has converged long before.
MAX_SUBSTEPS = 10_000


@dataclass
class IntervalDrift:
    """Per phase, (intervals, nv) arrays of the integrated state minus the next knot: `configuration` in the tangent
    space (a free-flyer base: position in world axes [m], then the rotation vector of R_knot^T R [rad]; joints
    [rad or m]) and `velocity` (nv)."""

    configuration: list[np.ndarray]
    velocity: list[np.ndarray]

    def worst(self, floating_base: bool) -> dict[str, float]:
        """The largest drift over all intervals: base position [m], attitude [deg] and base velocities (linear,
        angular) for a free-flyer base, then joints and joint rates."""
        q, v = np.concatenate(self.configuration), np.concatenate(self.velocity)
        summary: dict[str, float] = {}
        if floating_base:
            summary = {"base position [m]": float(np.max(np.linalg.norm(q[:, :3], axis=1))),
                       "attitude [deg]": float(np.degrees(np.max(np.linalg.norm(q[:, 3:6], axis=1)))),
                       "base velocity [m/s]": float(np.max(np.linalg.norm(v[:, :3], axis=1))),
                       "base angular velocity [rad/s]": float(np.max(np.linalg.norm(v[:, 3:6], axis=1)))}
            q, v = q[:, 6:], v[:, 6:]
        summary["joints"] = float(np.max(np.abs(q), initial=0.0))
        summary["joint rates"] = float(np.max(np.abs(v), initial=0.0))
        return summary


def constrained_accelerations(problem: ContactModel, k: int, q: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(B, nv) accelerations with phase k's `contact_rows` held (J a + dJ/dt v = 0) under controls u (B, nu):
    M a + h = S^T u + J^T lambda."""
    model, nv = problem.model, problem.nv
    q = problem.configuration(q)
    tau = np.zeros((len(q), nv))
    tau[:, problem.actuated] = u
    bias = np.asarray(lk.rnea(model, q, v, np.zeros_like(v)))
    rows = problem.contact_rows(problem.phases[k].contacts)
    if not rows:
        return np.asarray(lk.aba(model, q, v, tau))
    jac = problem.contact_jacobian(q, problem.phases[k].contacts)
    drift = np.concatenate([np.asarray(lk.point_accelerations(model, q, v, np.zeros_like(v), [(body, point)]))[:, 0, axes]
                            for body, point, axes in rows], axis=1)
    # The Delassus form, its pseudo-inverse for the forces: a straight leg or a redundant sole row leaves J rank-deficient.
    mass_inverse = np.asarray(lk.minv(model, q))
    free = np.einsum("bij,bj->bi", mass_inverse, tau - bias)
    projected = jac @ mass_inverse
    delassus = projected @ np.swapaxes(jac, 1, 2)
    forces = np.einsum("bij,bj->bi", np.linalg.pinv(delassus, rcond=1e-12, hermitian=True), -drift - np.einsum("bij,bj->bi", jac, free))
    return free + np.einsum("bji,bj->bi", projected, forces)


def tangent_difference(problem: ContactModel, q: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(B, nv): q minus reference in the tangent space (`IntervalDrift`)."""
    if not problem.model.floating_base:
        return q - reference
    relative = np.einsum("bji,bjk->bik", rotation(reference[:, 3:7]), rotation(q[:, 3:7]))
    return np.concatenate([q[:, :3] - reference[:, :3], Rotation.from_matrix(relative).as_rotvec(), q[:, 7:] - reference[:, 7:]], axis=1)


def tangent_add(problem: ContactModel, reference: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(B, nq): reference moved by d (B, nv) in the tangent space; the inverse of `tangent_difference`."""
    if not problem.model.floating_base:
        return reference + d
    q = np.array(np.broadcast_to(reference, d.shape[:-1] + reference.shape[-1:]), dtype=np.float64)
    q[:, :3] += d[:, :3]
    q[:, 3:7] = Rotation.from_matrix(rotation(q[:, 3:7]) @ Rotation.from_rotvec(d[:, 3:6]).as_matrix()).as_quat()
    q[:, 7:] += d[:, 6:]
    return q


def interval_drift(problem: ContactModel, x: np.ndarray, substeps: int = 32) -> IntervalDrift:
    """Integrate each interval of solution x from its first knot (classical Runge-Kutta, `substeps` steps, all
    intervals of a phase at once; q advanced by `lk.integrate`) and compare with its last knot; inf for an
    interval whose integration blows up."""
    count(substeps, "substeps", 1, MAX_SUBSTEPS)
    x = problem.point(x)
    trajectory = problem.unpack(x)
    nq, nx, nu = problem.nq, problem.nx, problem.nu
    configuration, velocity = [], []
    for k in range(len(problem.phases)):
        z = x[problem.point_index[k]]
        times, u = np.asarray(trajectory.t[k]), z[:, nx : nx + nu]
        q, v = problem.configuration(z[0:-1:2, :nq]), z[0:-1:2, nq:nx].copy()
        t0 = times[0:-1:2]
        h = (times[2::2] - t0) / substeps
        diverged = np.zeros(len(q), dtype=bool)
        for step in range(substeps):  # RK4, each stage's configuration moved from q along the previous stage's rate
            t = t0 + step * h
            a1 = constrained_accelerations(problem, k, q, v, _linear_controls(times, u, t))
            v2 = v + 0.5 * h[:, None] * a1
            a2 = constrained_accelerations(problem, k, _advance(problem, q, v, 0.5 * h), v2, _linear_controls(times, u, t + 0.5 * h))
            v3 = v + 0.5 * h[:, None] * a2
            a3 = constrained_accelerations(problem, k, _advance(problem, q, v2, 0.5 * h), v3, _linear_controls(times, u, t + 0.5 * h))
            v4 = v + h[:, None] * a3
            a4 = constrained_accelerations(problem, k, _advance(problem, q, v3, h), v4, _linear_controls(times, u, t + h))
            rate = (v + 2.0 * v2 + 2.0 * v3 + v4) / 6.0
            v = v + h[:, None] * (a1 + 2.0 * a2 + 2.0 * a3 + a4) / 6.0
            # An interval that blows up (an iterate far from feasible) drifts by inf; it restarts from its knot
            # only so that the kernels see finite input for the others.
            blown = ~np.all(np.isfinite(v) & (np.abs(v) < DIVERGED), axis=1) | ~np.all(np.isfinite(rate) & (np.abs(rate) < DIVERGED), axis=1)
            diverged |= blown
            rate[diverged], v[diverged] = 0.0, 0.0
            q = _advance(problem, np.where(diverged[:, None], problem.configuration(z[0:-1:2, :nq]), q), rate, h)
        configuration.append(np.where(diverged[:, None], np.inf, tangent_difference(problem, q, problem.configuration(z[2::2, :nq]))))
        velocity.append(np.where(diverged[:, None], np.inf, v - z[2::2, nq:nx]))
    return IntervalDrift(configuration, velocity)


def _linear_controls(times: np.ndarray, u: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(intervals, nu): the controls at t (one instant per interval), linear through each interval's knot, midpoint
    and knot (times, u: a phase's points), as the replay samples them."""
    start, middle, end = times[0:-1:2], times[1:-1:2], times[2::2]
    second = t > middle
    left, right = np.where(second, middle, start), np.where(second, end, middle)
    first_value = np.where(second[:, None], u[1:-1:2], u[0:-1:2])
    last_value = np.where(second[:, None], u[2::2], u[1:-1:2])
    return first_value + ((t - left) / (right - left))[:, None] * (last_value - first_value)


def _advance(problem: ContactModel, q: np.ndarray, rate: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """q (+) rate dt, one dt per row."""
    return problem.configuration(np.asarray(lk.integrate(problem.model, q, rate * dt[:, None], 1.0)))
