"""Perception: the dynamic region of interest (RoI) and structural-element (SE) classification.

Everything here sees only what the robot measured: registered points and its own pose estimates.
"""
