"""legkit: Rust-accelerated physics for legged and modular robots.

Conventions: SI units, right-handed frames with z up, gravity (0, 0, -9.81)
(``STANDARD_GRAVITY``) unless a Model is given another; a rigid transform maps child to parent coordinates,
``x_parent = R @ x_child + t``. Every array argument is float64 (lists accepted),
and leading batch dimensions broadcast; batches run in Rust on all cores with the GIL released.
A floating base uses q = [x, y, z, qx, qy, qz, qw] and v = [v_lin, v_ang] in the base frame, as Pinocchio.
"""

from legkit._build import check_cpu  # noqa: F401 (imported first: it checks the CPU before the extension loads)
from legkit._core import (
    Ground,
    MassProperties,
    Mjcf,
    MjcfWarning,
    Model,
    Simulation,
    SimulationBatch,
    UrdfWarning,
    aba,
    aba_derivatives,
    center_of_mass,
    center_of_mass_hessian,
    center_of_mass_jacobian,
    centroidal_derivatives,
    centroidal_map,
    centroidal_momentum,
    centroidal_momentum_hessian,
    centroidal_momentum_rate,
    contact_dynamics,
    contact_dynamics_derivatives,
    crba,
    difference,
    difference_jacobians,
    forward_kinematics,
    frame_acceleration,
    frame_acceleration_derivatives,
    frame_velocity,
    frame_velocity_derivatives,
    free_rollout,
    impact,
    impact_derivatives,
    integrate,
    integrate_jacobians,
    jacobian,
    jacobian_time_variation,
    kinematic_hessian,
    kinetic_energy,
    load_mjcf,
    minv,
    point_acceleration_hessian,
    point_accelerations,
    point_velocity_hessian,
    potential_energy,
    reduced_dynamics,
    resolve_mesh,
    rnea,
    rnea_derivatives,
    rnea_second_order_derivatives,
    subtree_mass_properties,
)
from legkit.geometry import CircleLineResult, circle_line, rotation_toward_line

STANDARD_GRAVITY: float = float(-Model().gravity[2])
"""Magnitude [m/s^2] of the core's default gravity (0, 0, -STANDARD_GRAVITY), read from a default ``Model``
so that the number lives in one place. Code that has a Model uses ``model.gravity``; this is the default
only where no model is at hand."""

__all__ = [
    "STANDARD_GRAVITY",
    "MassProperties",
    "Model",
    "UrdfWarning",
    "Mjcf",
    "MjcfWarning",
    "load_mjcf",
    "resolve_mesh",
    "CircleLineResult",
    "circle_line",
    "rotation_toward_line",
    "forward_kinematics",
    "rnea",
    "crba",
    "aba",
    "rnea_derivatives",
    "rnea_second_order_derivatives",
    "aba_derivatives",
    "centroidal_derivatives",
    "center_of_mass_jacobian",
    "minv",
    "jacobian",
    "jacobian_time_variation",
    "kinematic_hessian",
    "point_velocity_hessian",
    "point_acceleration_hessian",
    "center_of_mass_hessian",
    "centroidal_momentum_hessian",
    "frame_velocity",
    "frame_acceleration",
    "frame_velocity_derivatives",
    "frame_acceleration_derivatives",
    "center_of_mass",
    "subtree_mass_properties",
    "centroidal_map",
    "centroidal_momentum",
    "centroidal_momentum_rate",
    "kinetic_energy",
    "potential_energy",
    "contact_dynamics",
    "impact",
    "contact_dynamics_derivatives",
    "impact_derivatives",
    "point_accelerations",
    "reduced_dynamics",
    "integrate",
    "difference",
    "integrate_jacobians",
    "difference_jacobians",
    "free_rollout",
    "Simulation",
    "SimulationBatch",
    "Ground",
]


def __getattr__(name: str) -> object:
    """``lk.viewer`` is imported on first use (it is not needed for computing)."""
    if name == "viewer":
        import importlib

        return importlib.import_module("legkit.viewer")
    raise AttributeError(f"module 'legkit' has no attribute {name!r}")
