"""Goswami's foot-rotation indicator (FRI) and the paper's Stability Performance 1, J_s1.

[Hardt 2002, Sect. 3.2, eq. 8-9]. The FRI S of the N_f feet in ground contact is the point
on the ground where the ground reaction would have to act for the feet to stay still, given the motion of the
rest of the robot (Goswami 1999). Eq. 8 sets the tangential moments about S of what acts on the feet to zero:

    sum_j (n_j + SO_j x f_j - SG_j x m_j g)_T = 0,

n_j, f_j the wrench the rest of the robot puts on foot j at its joint O_j, G_j and m_j the foot's COM and
mass. That wrench is the rest's momentum rate minus its weight, so with the feet at rest the ground reaction
R balances
    R   = dh_rest/dt - (m_rest + m_feet) g
    M_o = dL_rest,o/dt - c_rest x m_rest g - sum_j c_j x m_j g       (moments about o on the ground)
and S is the point of zero horizontal moment of (R, M_o). While the feet are flat and still it is the CoP
(= ZMP) and lies in the support; outside it the feet rotate about its edge, and the distance to the support
measures how strongly (the FRI is the ZMP computed without the feet's inertia).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array, is_integer, time_grid
from legkit.stability.zmp import ground_point


def _without_mass_of(model: lk.Model, bodies: list[int]) -> lk.Model:
    """Copy of `model` in which `bodies` carry no mass."""
    for body in bodies:
        model = model.with_body(body, lk.MassProperties.zero())
    return model


def _body_index(model: lk.Model, body: int | str) -> int:
    if isinstance(body, str):
        if body not in model.names:
            raise ValueError(f"foot {body!r} is not a body of the model (bodies: {model.names})")
        return model.names.index(body)
    if not is_integer(body):
        raise TypeError(f"foot must be a body index or name, got {type(body).__name__}")
    if not 0 <= int(body) < model.nbodies:
        raise IndexError(f"foot index {body} is out of range for a model with {model.nbodies} bodies")
    return int(body)


def foot_rotation_indicator(
    model: lk.Model,
    q: npt.ArrayLike,
    v: npt.ArrayLike,
    a: npt.ArrayLike,
    foot: int | str | Sequence[int | str],
    ground_height: float = 0.0,
) -> np.ndarray:
    """FRI point S [Hardt 2002, eq. 8], (..., 3) [m], on the plane z = ground_height for the support foot or
    feet `foot` (an index or name, or a sequence of them: the N_f feet in contact).

    q, v, a: (..., nq), (..., nv), (..., nv) of the whole robot (the feet's own accelerations are ignored, as
    the FRI assumes them still). The feet are the only bodies touching the ground. Compare with the support
    by `polygon_margin(fri, footprint)`: positive (inside) means the feet do not rotate.
    """
    names = [foot] if isinstance(foot, (str, int, np.integer)) else list(foot)
    if not names:
        raise ValueError("foot must name at least one body")
    indices = sorted({_body_index(model, name) for name in names})
    rest = _without_mass_of(model, indices)
    masses = np.array([model.body(i).mass for i in indices])
    m_rest = model.total_mass - float(masses.sum())
    g = model.gravity
    o = np.array([0.0, 0.0, ground_height])
    rate = np.asarray(lk.centroidal_momentum_rate(rest, q, v, a))
    c_rest = np.asarray(lk.center_of_mass(rest, q)) if m_rest > 0.0 else np.zeros(rate.shape[:-1] + (3,))
    poses = np.asarray(lk.forward_kinematics(model, q))
    moment = rate[..., 3:] + np.cross(c_rest - o, rate[..., :3]) - np.cross(c_rest - o, m_rest * g)
    for index, mass in zip(indices, masses):
        pose = poses[..., index, :, :]
        c_foot = np.einsum("...ij,j->...i", pose[..., :3, :3], model.body(index).com) + pose[..., :3, 3]
        moment = moment - np.cross(c_foot - o, mass * g)
    force = rate[..., :3] - model.total_mass * g
    return ground_point(force, moment, ground_height)


def stability_performance_1(points: npt.ArrayLike, reference: npt.ArrayLike, t: npt.ArrayLike) -> float:
    """The paper's Stability Performance 1, J_s1 = integral of |GCoM - S|^2 dt [m^2 s] ([Hardt 2002, eq. 9],
    trapezoidal rule). The text calls it "the average distance" between the two points; the equation, kept
    here, integrates the squared distance and does not divide by t_f.

    points: (T, 2 or 3) ground points over time, the ground projection of the COM (GCoM) in the paper.
    reference: (T, 2 or 3) the point S, in the paper the FRI of the feet in contact (eq. 8,
    `foot_rotation_indicator`); t: (T,) strictly increasing times [s]. Only x and y are compared. Smaller is
    more stable (J_s1 >= 0); this is a cost, the one index here where smaller rather than positive is better.
    """
    p = float_array(points, "points", min_ndim=2)
    s = float_array(reference, "reference", min_ndim=2)
    if p.ndim != 2 or p.shape[-1] not in (2, 3):
        raise ValueError(f"points must be (T, 2) or (T, 3), got shape {p.shape}")
    if s.shape[0] != p.shape[0] or s.ndim != 2 or s.shape[-1] not in (2, 3):
        raise ValueError(f"reference must be (T, 2) or (T, 3) with T = {p.shape[0]}, got shape {s.shape}")
    times = time_grid(t, p.shape[0])
    squared = np.sum((p[:, :2] - s[:, :2]) ** 2, axis=-1)
    return float(np.trapezoid(squared, times))
