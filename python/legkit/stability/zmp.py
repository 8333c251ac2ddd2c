"""Zero-moment point from the dynamics, and centre of pressure from contact forces.

Both are the point p on the horizontal ground plane z = ground_height about which the horizontal moment of
the ground reaction wrench vanishes. For a ground reaction force F and moment M_o about the plane point
o = (0, 0, ground_height):  p_x = -M_o,y / F_z,  p_y = M_o,x / F_z  (from M_p = M_o - (p - o) x F).
The ZMP gets (F, M_o) from the robot's momentum balance (Newton-Euler of the whole robot), the CoP from
the measured or simulated contact forces; when the contact forces are the ones that produce the motion,
the two coincide. Both require F_z > 0 (the robot pushes on the ground), otherwise they do not exist and a
ValueError is raised rather than returning NaN.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array, positive_scalar

_MIN_NORMAL_FORCE = 1e-12


def ground_point(force: np.ndarray, moment: np.ndarray, ground_height: float = 0.0) -> np.ndarray:
    """Point (..., 3) on z = ground_height where the wrench (force, moment about (0, 0, ground_height)) has
    no horizontal moment. force, moment: (..., 3) world [N], [N m]. Raises ValueError when F_z <= 0."""
    force = float_array(force, "force", last=3)
    moment = float_array(moment, "moment", last=3)
    normal = force[..., 2]
    if np.any(normal <= _MIN_NORMAL_FORCE):
        first = np.argwhere(np.atleast_1d(normal <= _MIN_NORMAL_FORCE))[0]
        raise ValueError(
            f"vertical ground reaction must be > 0 for a ZMP/CoP to exist; it is {np.atleast_1d(normal)[tuple(first)]:.6g} N "
            f"at sample {tuple(int(i) for i in first)} (the robot is in flight or pulling on the ground)"
        )
    x = -moment[..., 1] / normal
    y = moment[..., 0] / normal
    return np.stack([x, y, np.full_like(x, ground_height)], axis=-1)


def zmp_from_momentum_rate(
    com: npt.ArrayLike,
    momentum_rate: npt.ArrayLike,
    mass: float,
    gravity: npt.ArrayLike = (0.0, 0.0, -lk.STANDARD_GRAVITY),
    ground_height: float = 0.0,
) -> np.ndarray:
    """ZMP (..., 3) [m] from the rate of centroidal momentum.

    com: (..., 3) world COM [m]; momentum_rate: (..., 6) [d/dt linear momentum (N), d/dt angular momentum
    about the COM (N m)], world-aligned, gravity *not* included (as `lk.centroidal_momentum_rate`);
    mass [kg]; gravity (3,) [m/s^2] (for a model, ``model.gravity``, as `zmp` passes it). The ground reaction
    is F = dh/dt - m g and its moment about the COM is dk/dt, so about o: M_o = dk/dt + (c - o) x F.
    """
    c = float_array(com, "com", last=3)
    rate = float_array(momentum_rate, "momentum_rate", last=6)
    m = positive_scalar(mass, "mass")
    g = float_array(gravity, "gravity", last=3)
    force = rate[..., :3] - m * g
    lever = c - np.array([0.0, 0.0, ground_height])
    moment = rate[..., 3:] + np.cross(lever, force)
    return ground_point(force, moment, ground_height)


def zmp(model: lk.Model, q: npt.ArrayLike, v: npt.ArrayLike, a: npt.ArrayLike, ground_height: float = 0.0) -> np.ndarray:
    """ZMP (..., 3) [m] of a model moving with (q, v, a) (each (..., nq/nv)), from the core's
    `centroidal_momentum_rate` and `center_of_mass`, with the model's own gravity vector."""
    return zmp_from_momentum_rate(
        lk.center_of_mass(model, q),
        lk.centroidal_momentum_rate(model, q, v, a),
        model.total_mass,
        model.gravity,
        ground_height,
    )


def center_of_pressure(contact_points: npt.ArrayLike, forces: npt.ArrayLike, ground_height: float = 0.0) -> np.ndarray:
    """Centre of pressure (..., 3) [m] of point contact forces.

    contact_points: (..., k, 3) world [m]; forces: (..., k, 3) world [N], the forces the ground exerts on
    the robot (as `lk.contact_dynamics` returns). For contacts on the plane it is the F_z-weighted mean of
    the contact points; for contacts off the plane the full moment is used, so it is the point where the
    resultant wrench crosses the plane. Raises ValueError when the total vertical force is <= 0.
    """
    points = float_array(contact_points, "contact_points", last=3, min_ndim=2)
    f = float_array(forces, "forces", last=3, min_ndim=2)
    if points.shape[-2] < 1:
        raise ValueError("contact_points must hold at least one contact")
    try:
        shape = np.broadcast_shapes(points.shape, f.shape)
    except ValueError as error:
        raise ValueError(f"forces shape {f.shape} does not match contact_points shape {points.shape}") from error
    f = np.broadcast_to(f, shape)
    lever = np.broadcast_to(points - np.array([0.0, 0.0, ground_height]), shape)
    return ground_point(np.sum(f, axis=-2), np.sum(np.cross(lever, f), axis=-2), ground_height)
