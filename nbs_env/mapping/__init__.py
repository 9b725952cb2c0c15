"""Mapping: the accumulated cloud S(t) and the labelled voxel space V(t)."""
