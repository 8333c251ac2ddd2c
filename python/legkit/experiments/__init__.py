"""legkit.experiments."""
