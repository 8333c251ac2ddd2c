"""Distributed mass-property agents (Moll et al., IROS 2006, Algorithms 1 and 2), one per SuperBot module,
and the message bus between their connectors."""

from legkit.agents.bus import BusConfig, Channel
from legkit.agents.network import AgentNetwork, EstimateErrors, GroundContact, reference_estimates

__all__ = ["AgentNetwork", "BusConfig", "Channel", "EstimateErrors", "GroundContact", "reference_estimates"]
