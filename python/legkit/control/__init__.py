"""Joint control for modular robots: PID banks, the seed paper's gain schedules, the per-joint centre of mass
balancing controller driven by the mass-property agents, and its closed loop on a simulated plant."""

from legkit.control.balance import BalanceController, BalanceKernel, JointDecisions
from legkit.control.closed_loop import PLANTS, FreePlant, Plant, RunResult, RunSpec, initial_angles, make_plant, pose_on_ground, run_balance
from legkit.control.gains import KD0, KI0, KP0, SCHEMES, GainSchedule
from legkit.control.pid import PID

__all__ = [
    "BalanceController", "BalanceKernel", "JointDecisions", "GainSchedule", "PID", "SCHEMES", "KP0", "KI0", "KD0",
    "PLANTS", "FreePlant", "Plant", "RunResult", "RunSpec", "initial_angles", "make_plant", "pose_on_ground", "run_balance",
]
