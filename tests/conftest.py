from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import two_room_plan

DATA = Path(__file__).parent / "data"


@pytest.fixture
def plan_dict() -> dict:
    """A small valid two-room plan as a JSON dict, to be broken by the bad-input tests."""
    return two_room_plan()


@pytest.fixture
def write_json(tmp_path: Path):
    def write(data: object, name: str = "plan.json") -> Path:
        path = tmp_path / name
        path.write_text(json.dumps(data))
        return path

    return write
