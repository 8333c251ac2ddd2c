"""legkit.robots."""
