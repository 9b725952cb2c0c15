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


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    """A finished run of 16 steps with checkpoints at 8 and 16 (the cheapest run with a checkpoint)."""
    pytest.importorskip("sb3_contrib")
    from train.ppo import TrainConfig, train

    out = tmp_path_factory.mktemp("probe3") / "run"
    config = TrainConfig(
        timesteps=16, envs=1, seed=0, rooms=(1, 1), n_steps=8, batch_size=8, completion="policy", checkpoint_every=8
    )
    train(config, out, progress=False)
    assert (out / "checkpoint_8" / "training_state.json").is_file()
    return out
