"""Experiments and the ``nbs`` command line: the top floor, importing everything below it."""
