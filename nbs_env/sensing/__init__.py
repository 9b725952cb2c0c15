"""Sensing: the simulated scanner, odometry, and registration into the accumulated cloud S(t)."""
