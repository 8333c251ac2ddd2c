"""Joint control for modular robots: PID banks, the seed paper's gain schedules, and the per-joint centre of
mass balancing controller driven by the mass-property agents."""

from legkit.control.balance import BalanceController, BalanceKernel, JointDecisions
from legkit.control.gains import KD0, KI0, KP0, SCHEMES, GainSchedule
from legkit.control.pid import PID

__all__ = ["BalanceController", "BalanceKernel", "JointDecisions", "GainSchedule", "PID", "SCHEMES", "KP0", "KI0", "KD0"]
