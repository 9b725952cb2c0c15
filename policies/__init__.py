"""Who decides where to scan next: the greedy NBS of the paper, the compared methods, learned agents.

Policies see only what the robot measured (its voxel labels, candidates and pose estimate), never a
scene's ground truth; the one exception is the documented ``oracle`` yardstick.
"""
