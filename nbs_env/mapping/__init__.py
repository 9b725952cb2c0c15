"""Mapping: the labelled voxel space V(t)."""
