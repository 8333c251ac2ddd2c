"""legkit.optimize: gait trajectory optimisation by multiphase direct collocation on IPOPT ([Hardt 2002, Sect. 4]).

`MultiphaseProblem` transcribes a fixed contact sequence (`Phase`s) by Hermite–Simpson collocation over
legkit's batched dynamics, a whole cycle or, with a `Mirror` (`side_mirror`, `sagittal_mirror`), half of one;
`solve` runs IPOPT (the casadi wheel's) on any `NLP`;
`MultiphaseProblem.refine` carries a solution onto a finer mesh;
`objectives` holds the paper's performance indices J_s1, J_s2, J_e1, J_e2 and a plain control effort;
`interval_drift` measures how far a solution's intervals are from motions of its model.
"""

from legkit.optimize.collocation import hermite_simpson_defects, point_jacobian
from legkit.optimize.definition import FlatFoot, InputPower, Phase, TorqueSpeedLine
from legkit.optimize.layout import Trajectory
from legkit.optimize.mirror import Mirror, sagittal_mirror, side_mirror
from legkit.optimize.objectives import Integral, MinMaxStability, effort, fri_deviation, joule_loss, specific_resistance
from legkit.optimize.problem import MultiphaseProblem
from legkit.optimize.shooting import IntervalDrift, interval_drift
from legkit.optimize.solver import NLP, SolveResult, solve

__all__ = [
    "FlatFoot",
    "Mirror",
    "sagittal_mirror",
    "side_mirror",
    "InputPower",
    "MultiphaseProblem",
    "Phase",
    "TorqueSpeedLine",
    "Trajectory",
    "IntervalDrift",
    "interval_drift",
    "NLP",
    "SolveResult",
    "solve",
    "hermite_simpson_defects",
    "point_jacobian",
    "Integral",
    "MinMaxStability",
    "effort",
    "fri_deviation",
    "joule_loss",
    "specific_resistance",
]
