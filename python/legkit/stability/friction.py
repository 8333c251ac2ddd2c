"""Contact-force feasibility: the friction cone (the paper's eq. 5) and the foot-torque limits (eq. 6).

Forces are those the ground exerts on the robot. Margins are in newtons / newton-metres, positive when the
force is feasible, zero on the boundary, negative by how much the limit is violated.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from legkit._validation import float_array, friction_coefficient, unit_vectors


def friction_cone_margin(forces: npt.ArrayLike, normals: npt.ArrayLike, mu: npt.ArrayLike) -> np.ndarray:
    """Margin (..., k) [N] of point-contact forces to the Coulomb cone |f_t| <= mu f_n, f_n >= 0 (eq. 5).

    forces: (..., k, 3) [N]; normals: (..., k, 3) unit contact normals pointing into the robot (ValueError if
    not unit to 1e-6); mu >= 0, scalar or broadcasting to (..., k). Returns min(mu f_n - |f_t|, f_n): the
    first term is the friction condition, the second the unilateral one (the ground only pushes).
    """
    f = float_array(forces, "forces", last=3)
    n = unit_vectors(normals, "normals")
    friction = friction_coefficient(mu)
    normal_force = np.sum(f * n, axis=-1)
    tangential = np.linalg.norm(f - normal_force[..., None] * n, axis=-1)
    return np.minimum(friction * normal_force - tangential, normal_force)


def foot_torque_margin(
    force: npt.ArrayLike, torque: npt.ArrayLike, sole: tuple[float, float, float, float]
) -> np.ndarray:
    """Margins (..., 4) [N m] of a flat foot's contact wrench to the foot-torque limits (eq. 6).

    force, torque: (..., 3) ground reaction on the foot and its moment about the foot reference point, in the
    foot frame (z along the sole normal, the reference point on the sole). sole = (x_back, x_front,
    y_right, y_left): the sole extends over x_back <= x <= x_front, y_right <= y <= y_left in that frame
    (x_back < x_front, y_right < y_left). The wrench can be produced by pressure on the sole iff its centre of
    pressure (-tau_y / f_z, tau_x / f_z) lies on the sole, i.e.

        x_back f_z <= -tau_y <= x_front f_z,      y_right f_z <= tau_x <= y_left f_z,

    returned as [x_front f_z + tau_y, -tau_y - x_back f_z, y_left f_z - tau_x, tau_x - y_right f_z]
    (toe, heel, left, right). With f_z <= 0 no bound can hold with positive margin.
    """
    f = float_array(force, "force", last=3)
    tau = float_array(torque, "torque", last=3)
    bounds = float_array(sole, "sole")
    if bounds.shape != (4,):
        raise ValueError(f"sole must be (x_back, x_front, y_right, y_left), got shape {bounds.shape}")
    x_back, x_front, y_right, y_left = bounds
    if not (x_back < x_front and y_right < y_left):
        raise ValueError(f"sole must satisfy x_back < x_front and y_right < y_left, got {tuple(bounds)}")
    fz = f[..., 2]
    return np.stack(
        [x_front * fz + tau[..., 1], -tau[..., 1] - x_back * fz, y_left * fz - tau[..., 0], tau[..., 0] - y_right * fz],
        axis=-1,
    )
