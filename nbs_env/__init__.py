"""The robot's side of nbs-env: scanner, registration, perception, voxel labels, planning, the env.

It reads buildings from :mod:`scenes` (the floor below) and never imports :mod:`policies` or
:mod:`train` (the floors above). Only the simulator and evaluation parts of this package may read a
scene's ground truth.
"""

__version__ = "0.1.0"
