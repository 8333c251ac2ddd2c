"""Goswami's foot-rotation indicator (FRI) and the paper's Stability Performance 1, J_s1.

The FRI of a foot in (single) ground contact is the point on the ground where the ground reaction would
have to act for the foot to stay still, given the motion of the rest of the robot (Goswami 1999). With the
foot at rest, the ground reaction R balances gravity on the foot and the wrench the rest of the robot puts
through the ankle, which equals that rest's momentum rate minus its weight:

    R   = dh_rest/dt - (m_rest + m_foot) g
    M_o = dL_rest,o/dt - c_rest x m_rest g - c_foot x m_foot g       (moments about o on the ground)

and the FRI is the point of zero horizontal moment of (R, M_o). While the foot is flat and still it is the
CoP (= ZMP) and lies in the footprint; outside the footprint the foot rotates about its edge, and the
distance to the footprint measures how strongly (the FRI is the ZMP computed without the foot's inertia).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array
from legkit.stability._validation import time_grid
from legkit.stability.zmp import ground_point


def _without_mass_of(model: lk.Model, body: int) -> lk.Model:
    """Copy of `model` (same bodies, joints, placements, gravity) in which `body` carries no mass."""
    def mass_of(i: int) -> lk.MassProperties:
        return lk.MassProperties.zero() if i == body else model.body(i)

    copy = lk.Model(
        floating_base=model.floating_base, base=mass_of(0), base_name=model.names[0], gravity=model.gravity
    )
    for i in range(1, model.nbodies):
        kind, parent, placement = model.joint_type(i), model.parents[i], model.placement(i)
        if kind == "revolute":
            copy.add_revolute(parent, model.joint_axis(i), placement, mass_of(i), model.names[i])
        elif kind == "prismatic":
            copy.add_prismatic(parent, model.joint_axis(i), placement, mass_of(i), model.names[i])
        else:
            copy.add_fixed(parent, placement, mass_of(i), model.names[i])
    return copy


def _body_index(model: lk.Model, body: int | str) -> int:
    if isinstance(body, str):
        if body not in model.names:
            raise ValueError(f"foot {body!r} is not a body of the model (bodies: {model.names})")
        return model.names.index(body)
    if isinstance(body, (bool, np.bool_)) or not isinstance(body, (int, np.integer)):
        raise TypeError(f"foot must be a body index or name, got {type(body).__name__}")
    if not 0 <= int(body) < model.nbodies:
        raise ValueError(f"foot index {body} is out of range for a model with {model.nbodies} bodies")
    return int(body)


def foot_rotation_indicator(
    model: lk.Model,
    q: npt.ArrayLike,
    v: npt.ArrayLike,
    a: npt.ArrayLike,
    foot: int | str,
    ground_height: float = 0.0,
) -> np.ndarray:
    """FRI point (..., 3) [m] on the plane z = ground_height for the support foot `foot` (index or name).

    q, v, a: (..., nq), (..., nv), (..., nv) of the whole robot (the foot's own acceleration is ignored, as
    the FRI assumes it still). The foot is the only body touching the ground. Compare with the footprint by
    `polygon_margin(fri, footprint)`: positive (inside) means the foot does not rotate.
    """
    index = _body_index(model, foot)
    rest = _without_mass_of(model, index)
    m_foot = model.body(index).mass
    m_rest = model.total_mass - m_foot
    g = model.gravity
    o = np.array([0.0, 0.0, ground_height])
    rate = np.asarray(lk.centroidal_momentum_rate(rest, q, v, a))
    c_rest = np.asarray(lk.center_of_mass(rest, q)) if m_rest > 0.0 else np.zeros(rate.shape[:-1] + (3,))
    pose = np.asarray(lk.forward_kinematics(model, q))[..., index, :, :]
    c_foot = np.einsum("...ij,j->...i", pose[..., :3, :3], model.body(index).com) + pose[..., :3, 3]
    force = rate[..., :3] - (m_rest + m_foot) * g
    moment = (
        rate[..., 3:]
        + np.cross(c_rest - o, rate[..., :3])
        - np.cross(c_rest - o, m_rest * g)
        - np.cross(c_foot - o, m_foot * g)
    )
    return ground_point(force, moment, ground_height)


def stability_performance_1(points: npt.ArrayLike, reference: npt.ArrayLike, t: npt.ArrayLike) -> float:
    """The paper's Stability Performance 1, J_s1 = integral of |GCoM - S|^2 dt [m^2 s] (trapezoidal rule).

    points: (T, 2 or 3) ground points over time, the ground projection of the COM (GCoM) in the paper; the
    FRI or ZMP may be passed instead. reference: (T, 2 or 3) the point S they should stay close to, e.g.
    `support_polygon_centroid`; t: (T,) strictly increasing times [s]. Only x and y are compared. Smaller is
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
