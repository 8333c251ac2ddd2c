"""legkit.strain: leg strain models, benchtop data, tripod body pose and synthetic walking streams.

Reproduces Lin, Komsuoglu and Koditschek (ICRA 2003): a polynomial map from the strain of RHex's compliant
four-bar legs to leg length and deflection (``model``), its calibration data handling (``benchtop``), body
pose from three stance toes (``pose``), and walking streams with ground truth (``walking``; a kinematic,
quasi-static generator that a simulation-backed source can replace).
"""

from legkit.strain.benchtop import (
    BenchtopData,
    BenchtopSweep,
    CompliantFourBarLeg,
    StrainSensor,
    average_by_group,
    grid_average,
    leg_frame_loads,
    physically_relevant,
    quantize,
    resample_evenly,
    synthetic_benchtop,
)
from legkit.strain.model import (
    CrossValidation,
    LegModel,
    OrderSelectionRow,
    cross_validate,
    format_order_table,
    kfold_indices,
    nrmse,
    order_selection_table,
)
from legkit.strain.pose import (
    TripodPose,
    coplanarity,
    euler_zyx,
    hip_to_body,
    plane_residual,
    stance_intervals,
    toe_in_body,
    toe_in_leg,
    tripod_pose,
)
from legkit.strain.simulated import simulated_walk
from legkit.strain.walking import (
    ClockGait,
    PoseEstimate,
    WalkingSource,
    WalkingStream,
    estimate_body_pose,
    kinematic_walk,
    tripod_clock_signal,
)

__all__ = [
    "BenchtopData",
    "BenchtopSweep",
    "CompliantFourBarLeg",
    "StrainSensor",
    "average_by_group",
    "grid_average",
    "leg_frame_loads",
    "physically_relevant",
    "quantize",
    "resample_evenly",
    "synthetic_benchtop",
    "CrossValidation",
    "LegModel",
    "OrderSelectionRow",
    "cross_validate",
    "format_order_table",
    "kfold_indices",
    "nrmse",
    "order_selection_table",
    "TripodPose",
    "coplanarity",
    "euler_zyx",
    "hip_to_body",
    "plane_residual",
    "stance_intervals",
    "toe_in_body",
    "toe_in_leg",
    "tripod_pose",
    "ClockGait",
    "PoseEstimate",
    "WalkingSource",
    "WalkingStream",
    "estimate_body_pose",
    "kinematic_walk",
    "simulated_walk",
    "tripod_clock_signal",
]
