"""Short greedy trajectories pinned to their recorded positions: a speed-up that means to keep the
method's decisions must keep these (``tests/data/pinned_trajectories.json``).

A change that means to change decisions rewrites the file (``python -m tests.test_pinned``) and
says so in its commit, with the tables it re-ran. Positions are compared to 1 cm: the fast preset's
robot localises perfectly, so every stop is a lattice point or a door centre, and a different
decision moves a stop by half a metre or more.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from nbs_env.env import NBSEnv
from nbs_env.settings import make_config

PINNED = Path(__file__).parent / "data" / "pinned_trajectories.json"
#: (scene, seed, steps): a generated two-room storey through its door, and the paper's scene.
CASES = (("generated:1", 0, 8), ("five_rooms", 0, 8))


def stops(scene: str, seed: int, steps: int) -> list[list[float]]:
    """The estimated xy of every scan of the first ``steps`` greedy steps (door-frame scans included)."""
    env = NBSEnv(make_config("fast", scene=scene, max_scans=40))
    env.reset(seed=seed)
    storey = env.storey
    for _ in range(steps):
        if not storey.open:
            break
        env.step(storey.plan.best())
    return [[round(float(v), 3) for v in s.estimated_position[:2]] for s in storey.scans]


@pytest.mark.parametrize(("scene", "seed", "steps"), CASES)
def test_the_greedy_stops_where_it_stopped_when_pinned(scene, seed, steps):
    pinned = json.loads(PINNED.read_text())[f"{scene}/{seed}/{steps}"]
    got = stops(scene, seed, steps)
    assert len(got) == len(pinned), (got, pinned)
    np.testing.assert_allclose(np.array(got), np.array(pinned), atol=0.01)


if __name__ == "__main__":
    PINNED.write_text(json.dumps({f"{sc}/{se}/{st}": stops(sc, se, st) for sc, se, st in CASES}, indent=1) + "\n")
    print(f"wrote {PINNED}")
