"""Reference gaits of legged robots and their analysis by the stability and energy indices of [Hardt 2002].

`references`: the quadruped amble of Fig. 3 and a biped walk, sampled from foot placements;
`analysis`: contact inverse dynamics along a reference and every index over it (`analyse`).
"""

from legkit.gaits.analysis import (
    ContactInverseDynamics,
    GaitAnalysis,
    analyse,
    biped_extras,
    constrained_acceleration_gap,
    contact_inverse_dynamics,
)
from legkit.gaits.references import AMBLE_HIP_HEIGHT, AMBLE_QUADRUPED, GaitReference, biped_walk, periodic_lip, quadruped_amble

__all__ = [
    "AMBLE_HIP_HEIGHT", "AMBLE_QUADRUPED", "ContactInverseDynamics", "GaitAnalysis", "GaitReference", "analyse", "biped_extras",
    "biped_walk", "constrained_acceleration_gap", "contact_inverse_dynamics", "periodic_lip", "quadruped_amble",
]
