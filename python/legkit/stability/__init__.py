"""legkit.stability: how close a pose or a gait is to falling, what it costs, whether its forces are feasible.

Every index is a NumPy function vectorised over leading time-sample dimensions. Sign convention throughout:
margins and indices are positive when stable/feasible, zero on the boundary, negative when violated (the
costs J_s1 and the energy indices are the exceptions: smaller is better). z is up, units SI.
"""

from legkit.stability.angular_momentum import (
    angular_momentum_stability,
    angular_momentum_stability_of_model,
    worst_case,
)
from legkit.stability.energy import (
    joule_loss_index,
    joule_loss_power,
    specific_resistance,
    torque_speed_margin,
)
from legkit.stability.equilibrium import (
    is_statically_stable,
    static_equilibrium_margin,
    static_equilibrium_region,
)
from legkit.stability.fri import foot_rotation_indicator, stability_performance_1
from legkit.stability.friction import foot_torque_margin, friction_cone_margin
from legkit.stability.simulated import ground_contact_wrench, simulated_center_of_pressure
from legkit.stability.support import (
    SupportEdges,
    distinct_contact_count,
    polygon_margin,
    static_stability_margin,
    support_edges,
    support_polygon,
    support_polygon_centroid,
)
from legkit.stability.zmp import center_of_pressure, ground_point, zmp, zmp_from_momentum_rate

__all__ = [
    "ground_contact_wrench",
    "simulated_center_of_pressure",
    "SupportEdges",
    "support_edges",
    "support_polygon",
    "support_polygon_centroid",
    "distinct_contact_count",
    "static_stability_margin",
    "polygon_margin",
    "zmp",
    "zmp_from_momentum_rate",
    "center_of_pressure",
    "ground_point",
    "foot_rotation_indicator",
    "stability_performance_1",
    "angular_momentum_stability",
    "angular_momentum_stability_of_model",
    "worst_case",
    "joule_loss_power",
    "joule_loss_index",
    "specific_resistance",
    "torque_speed_margin",
    "friction_cone_margin",
    "foot_torque_margin",
    "static_equilibrium_region",
    "static_equilibrium_margin",
    "is_statically_stable",
]
