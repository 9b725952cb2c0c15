"""Short greedy trajectories pinned to their recorded positions: a speed-up that means to keep the
method's decisions must keep these (``tests/data/pinned_trajectories.json``).

Each case holds one or more recorded trajectories. The same commit gives the same trajectory bit
for bit on one machine, but not on every machine: on 2026-12-05 a fresh machine (an Intel Xeon
with AVX-512) placed a stop 1 cm off the recorded one at f2e682b, and the storey diverged from
there; it did so still with open3d, numpy, scipy, shapely, scikit-learn, trimesh and numba each at
its previous release (the cause is not traced). Both recordings come from the same code, so a run
must match one of them; a changed decision matches neither.

A change that means to change decisions rewrites the file (``python -m tests.test_pinned``) and
says so in its commit, with the tables it re-ran; ``python -m tests.test_pinned --add`` adds this
machine's trajectories to the recorded ones, for a machine whose run of an unchanged commit differs.
Positions are compared to 1 cm: the fast preset's robot localises perfectly, so every stop is a
lattice point or a door centre, and a different decision moves a stop by half a metre or more.
The pinned robot is the fast preset's without the searches for doors no scan faced and with its
NVPs on the lattice alone, casting thin rays (the paper's method, as ``--preset paper`` runs it), so
that the recordings pin the greedy's own decisions.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from nbs_env.config import make_config
from nbs_env.env import NBSEnv

PINNED = Path(__file__).parent / "data" / "pinned_trajectories.json"
#: (scene, seed, steps): a generated two-room storey through its door, and the paper's scene.
CASES = (("generated:1", 0, 8), ("five_rooms", 0, 8))


def stops(scene: str, seed: int, steps: int) -> list[list[float]]:
    """The estimated xy of every scan of the first ``steps`` greedy steps (door-frame scans included)."""
    paper = {"rooms.wall_search.scans": 0, "robot.navigation.snap": False, "robot.scanner.beam_divergence": 0.0}
    env = NBSEnv(make_config("fast", scene=scene, max_scans=40, **paper))
    env.reset(seed=seed)
    storey = env.storey
    for _ in range(steps):
        if not storey.open:
            break
        env.step(storey.plan.best())
    return [[round(float(v), 3) for v in s.estimated_position[:2]] for s in storey.scans]


def _matches(got: list[list[float]], pinned: list[list[float]]) -> bool:
    return len(got) == len(pinned) and bool(np.allclose(np.array(got), np.array(pinned), rtol=0.0, atol=0.01))


@pytest.mark.parametrize(("scene", "seed", "steps"), CASES)
def test_the_greedy_stops_where_it_stopped_when_pinned(scene, seed, steps):
    recorded = json.loads(PINNED.read_text())[f"{scene}/{seed}/{steps}"]
    assert recorded and all(len(t) >= steps for t in recorded)
    got = stops(scene, seed, steps)
    assert any(_matches(got, pinned) for pinned in recorded), (got, recorded)


def test_a_changed_decision_matches_no_recording():
    """The comparison the pin rests on: a stop half a metre off, or a stop missing, matches none."""
    recorded = json.loads(PINNED.read_text())["generated:1/0/8"]
    moved = [list(p) for p in recorded[0]]
    moved[-1][0] += 0.5
    assert _matches(recorded[0], recorded[0])
    assert not any(_matches(moved, pinned) for pinned in recorded)
    assert not any(_matches(recorded[0][:-1], pinned) for pinned in recorded)


if __name__ == "__main__":
    current = {f"{sc}/{se}/{st}": stops(sc, se, st) for sc, se, st in CASES}
    if "--add" in sys.argv[1:]:
        old = json.loads(PINNED.read_text())
        merged = {k: old.get(k, []) + [t for t in [v] if not any(_matches(t, p) for p in old.get(k, []))]
                  for k, v in current.items()}  # fmt: skip
    else:
        merged = {k: [v] for k, v in current.items()}
    PINNED.write_text(json.dumps(merged, indent=1) + "\n")
    print(f"wrote {PINNED}")
