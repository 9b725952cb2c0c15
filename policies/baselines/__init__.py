"""The methods the paper compares against (METHOD §10), and the floors of the comparison.

Each keeps its own state, built from the robot's measurements (``info["belief"]``, never ground
truth), ends a room by its own rule, and documents its source and what was adapted.
"""

from policies.baselines.blaer_allen import BlaerAllenPolicy
from policies.baselines.frontier import NearestFrontierPolicy
from policies.baselines.information_gain import FORMULATIONS, InformationGainPolicy, PotthastSukhatmePolicy
from policies.baselines.stachniss_burgard import StachnissBurgardPolicy

__all__ = [
    "FORMULATIONS",
    "BlaerAllenPolicy",
    "InformationGainPolicy",
    "NearestFrontierPolicy",
    "PotthastSukhatmePolicy",
    "StachnissBurgardPolicy",
]
