"""Ground reaction wrench and centre of pressure from the contacts of an `lk.Simulation` step.

`Simulation.contacts()` reports, for the last step, every contact point with its unit normal (pointing
into the robot body), the normal force magnitude and the tangential (friction) force vector, both being
the solver's impulse of that step divided by dt. Only ground contacts (``other == -1``) enter here;
body-body contacts are internal to the robot and cancel in its momentum balance.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from legkit._validation import float_array
from legkit.stability.zmp import center_of_pressure

_KEYS = ("other", "point", "normal", "normal_force", "tangential_force")


def _ground_forces(contacts: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(points (k, 3), forces on the robot (k, 3)) of the ground contacts, checked."""
    if not isinstance(contacts, Mapping):
        raise TypeError(f"contacts must be the dict returned by Simulation.contacts(), got {type(contacts).__name__}")
    missing = [key for key in _KEYS if key not in contacts]
    if missing:
        raise ValueError(f"contacts is missing the entries {missing} (expected the dict of Simulation.contacts())")
    other = np.asarray(contacts["other"])
    if other.ndim != 1:
        raise ValueError(f"contacts['other'] must be one-dimensional, got shape {other.shape}")
    k = other.shape[0]
    point = float_array(contacts["point"], "contacts['point']", last=3, min_ndim=2)
    normal = float_array(contacts["normal"], "contacts['normal']", last=3, min_ndim=2)
    normal_force = float_array(contacts["normal_force"], "contacts['normal_force']")
    tangential = float_array(contacts["tangential_force"], "contacts['tangential_force']", last=3, min_ndim=2)
    shapes = {"point": point.shape, "normal": normal.shape, "normal_force": normal_force.shape, "tangential_force": tangential.shape}
    expected = {"point": (k, 3), "normal": (k, 3), "normal_force": (k,), "tangential_force": (k, 3)}
    if shapes != expected:
        raise ValueError(f"contacts entries disagree on the number of contacts ({k} in 'other'): shapes {shapes}")
    ground = other == -1
    if not np.any(ground):
        raise ValueError("contacts holds no ground contact (other == -1): the robot is in the air")
    forces = normal[ground] * normal_force[ground, None] + tangential[ground]
    return point[ground], forces


def ground_contact_wrench(contacts: Mapping[str, np.ndarray], ground_height: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Resultant wrench the ground exerts on the robot during the step `contacts` was read after.

    contacts: the dict of `Simulation.contacts()`. Returns (force (3,) [N], moment (3,) [N m] about the
    point (0, 0, ground_height)), world frame, normal plus tangential forces of every ground contact.
    Feed it to `legkit.stability.ground_point` for the CoP (after averaging over steps if wanted: the
    wrench, unlike the CoP, is linear in the forces). Raises ValueError without ground contact.
    """
    points, forces = _ground_forces(contacts)
    lever = points - np.array([0.0, 0.0, ground_height])
    return forces.sum(axis=0), np.cross(lever, forces).sum(axis=0)


def simulated_center_of_pressure(contacts: Mapping[str, np.ndarray], ground_height: float = 0.0) -> np.ndarray:
    """Centre of pressure (3,) [m] on z = ground_height of the ground contact forces (normal plus
    tangential) of one simulation step; contacts is the dict of `Simulation.contacts()`. Contact points
    below the plane (penetration) are accounted for exactly through the full moment. Raises ValueError
    without ground contact or when the ground does not push up (total vertical force <= 0)."""
    points, forces = _ground_forces(contacts)
    return center_of_pressure(points, forces, ground_height)
