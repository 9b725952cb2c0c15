from __future__ import annotations

import json
from pathlib import Path

import pytest

DATA = Path(__file__).parent / "data"


@pytest.fixture
def plan_dict() -> dict:
    """A small valid two-room plan as a JSON dict, to be broken by the bad-input tests."""
    return {
        "format": "nbs-floorplan",
        "version": 1,
        "name": "two_rooms",
        "ceiling_height": 2.6,
        "wall_thickness": 0.2,
        "rooms": [
            {"name": "a", "polygon": [[0, 0], [5, 0], [5, 4], [0, 4]]},
            {"name": "b", "polygon": [[5, 0], [9, 0], [9, 4], [5, 4]]},
        ],
        "doors": [{"rooms": ["a", "b"], "position": [5, 2], "width": 0.9, "height": 2.0}],
        "clutter": [{"kind": "cabinet", "position": [1.0, 3.6], "size": [1.2, 0.5, 1.9], "yaw": 0}],
        "start": [2.0, 1.5],
    }


@pytest.fixture
def write_json(tmp_path: Path):
    def write(data: object, name: str = "plan.json") -> Path:
        path = tmp_path / name
        path.write_text(json.dumps(data))
        return path

    return write
