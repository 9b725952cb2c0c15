"""Probe 3's nbs train and --set findings: a checkpoint resumed as a run (P7), a total below the steps
done (P8) and a --set value nested thousands of levels deep (P9), each refused before any work."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from train.cli import EXIT_USAGE
from train.cli import main as nbs


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def run(tiny_run, tmp_path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(tiny_run, copy)
    return copy


def _train(argv: list[str], capsys) -> tuple[int, str]:
    from train.ppo import main

    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr().err


# ---------------------------------------------------------------------- P7
def test_a_checkpoint_is_not_resumed_as_a_run(run, capsys):
    checkpoint = run / "checkpoint_8"
    before = _files(checkpoint)
    code, err = _train(["--resume", str(checkpoint), "--timesteps", "24", "--quiet"], capsys)
    assert code == EXIT_USAGE, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"nbs train: error: --resume {checkpoint} is a checkpoint of the run {run}"), err
    assert f"continue the run with --resume {run} " in err and f"--init {checkpoint}" in err, err
    assert _files(checkpoint) == before  # nothing written inside it: no checkpoint_16/, no curve
    assert not [p for p in checkpoint.iterdir() if p.is_dir()]


def test_train_refuses_a_checkpoint_as_the_folder_to_resume(run):
    from nbs_env.errors import ModelFileError
    from train.ppo import resume_config, train

    with pytest.raises(ModelFileError, match="is a checkpoint of the run"):
        train(resume_config(run, timesteps=24), run / "checkpoint_8", progress=False, resume=True)
    assert not (run / "checkpoint_8" / "checkpoint_16").exists()


def test_a_checkpoint_starts_a_new_run_with_init(run, tmp_path):
    """What the refusal offers instead: --init takes a checkpoint folder."""
    from train.ppo import TrainConfig, _load_init

    encoder, scorer = _load_init(str(run / "checkpoint_8"), TrainConfig(rooms=(1, 1), completion="policy").network)
    assert encoder is not None and scorer is not None


def test_a_run_folder_named_like_a_checkpoint_still_resumes(run, tmp_path):
    from train.ppo import checkpoint_problem

    named = tmp_path / "checkpoint_3"
    shutil.copytree(run, named)
    assert checkpoint_problem(named) is None
    assert checkpoint_problem(run) is None
    assert checkpoint_problem(run / "checkpoint_16") is not None


# ---------------------------------------------------------------------- P8
@pytest.mark.parametrize("timesteps", ["8", "16", "0", "-5"])
def test_a_total_not_above_the_steps_done_is_refused(run, capsys, timesteps):
    before = _files(run)
    code, err = _train(["--resume", str(run), "--timesteps", timesteps, "--quiet"], capsys)
    assert code == EXIT_USAGE, err
    assert err.strip() == (
        f"nbs train: error: --timesteps {timesteps}: the run has done 16 steps already; "
        "ask for more (e.g. --timesteps 32)"
    ), err
    assert _files(run) == before


def test_a_run_whose_final_state_was_not_written_may_finish_at_its_total(run, capsys):
    """A full disk at the run's very end leaves its newest state in a checkpoint: resuming it at the
    same total writes the final policy (the advice that error gives), so it is not refused."""
    from train.ppo import latest_state

    for name in ("training_state.json", "training_state.pt", "policy.json", "policy.pt"):
        (run / name).unlink()
    assert latest_state(run)[0] == run / "checkpoint_16"
    code, err = _train(["--resume", str(run), "--timesteps", "16", "--quiet"], capsys)
    assert code == 0, err
    assert latest_state(run)[0] == run and (run / "policy.json").is_file()


# ---------------------------------------------------------------------- P9
DEEP = "[" * 2000 + "]" * 2000
DEEP_OBJECT = '{"a":' * 20000 + "1" + "}" * 20000


@pytest.mark.parametrize(
    "argv",
    [
        ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "1", "--set", f"max_scans={DEEP}"],
        ["scan", "--scene", "l_room", "--set", f"rooms.wall_search.heights={DEEP}"],
        ["compare", "--scenes", "l_room", "--policies", "random", "--out", "c", "--set", f"robot={DEEP_OBJECT}"],
        ["train", "--out", "t", "--timesteps", "8", "--set", f"max_scans={DEEP}"],
    ],
    ids=["scan", "scan-heights", "compare", "train"],
)
def test_a_deeply_nested_set_value_is_refused(argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    try:
        code = nbs(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    key = argv[-1].partition("=")[0]
    assert code == EXIT_USAGE, err
    assert "Traceback" not in err and "RecursionError" not in err, err[-2000:]
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1, err
    assert f"argument --set: {key}: " in errors[0] and "deeper than 64 levels" in errors[0], errors
    assert not any(tmp_path.iterdir())


def test_set_values_within_the_bound_are_read_as_before():
    from train.arguments import _assignment

    deepest = "[" * 64 + "]" * 64
    assert _assignment("a.b=" + deepest)[1] == json.loads(deepest)
    assert _assignment('a=[[1, 2], {"k": "[[["}]') == ("a", [[1, 2], {"k": "[[["}])
    assert _assignment("robot.scanner=vz400") == ("robot.scanner", "vz400")  # a bare word: a string


# ---------------------------------------------------------------------- probe 4: the training state's tensors
class _Marker:
    """A pickle that would create a file if it were ever unpickled."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (self.path,))


def _replace_state(run: Path, write) -> None:
    """``run``'s training_state.pt rewritten by ``write(path)``, its recorded checksum made to match."""
    import hashlib

    state, description = run / "training_state.pt", run / "training_state.json"
    write(state)
    document = json.loads(description.read_text())
    document["sha256"] = hashlib.sha256(state.read_bytes()).hexdigest()
    description.write_text(json.dumps(document))
    for checkpoint in run.glob("checkpoint_*"):  # the run's own state is the newest
        shutil.rmtree(checkpoint)


def test_a_pickle_as_the_training_state_is_refused_unread_in_one_line(run, capsys, tmp_path):
    import pickle

    marker = tmp_path / "PWNED"
    _replace_state(run, lambda path: path.write_bytes(pickle.dumps(_Marker(marker), protocol=4)))
    code, err = _train(["--resume", str(run), "--timesteps", "24", "--quiet"], capsys)
    assert code == EXIT_USAGE and not marker.exists(), err
    assert err == (
        f"nbs train: error: --resume: {run}/training_state.pt: not a tensors-only file (torch's tensors-only "
        "reader refused it: UnpicklingError)\n"
    )


def test_a_training_state_of_meta_tensors_is_refused_in_one_line(run, capsys):
    import torch

    def meta(path: Path) -> None:
        state = torch.load(path, weights_only=True)
        state["policy"] = {k: v.to("meta") for k, v in state["policy"].items()}
        torch.save(state, path)

    _replace_state(run, meta)
    code, err = _train(["--resume", str(run), "--timesteps", "24", "--quiet"], capsys)
    assert code == EXIT_USAGE and err.count("\n") == 1, err
    assert err.startswith(f"nbs train: error: --resume: {run}/training_state.pt: policy.") and "'meta' device" in err


def test_a_fifo_in_the_run_folder_is_refused_before_the_run_resumes(run, capsys):
    """A fifo as the learning curve blocked the run's end for ever, deaf to SIGTERM: the steps trained were lost."""
    import os

    if not hasattr(os, "mkfifo"):
        pytest.skip("POSIX fifos")
    curve = run / "learning_curve.jsonl"
    curve.unlink(missing_ok=True)
    os.mkfifo(curve)
    code, err = _train(["--resume", str(run), "--timesteps", "24", "--quiet"], capsys)
    assert code == EXIT_USAGE and err.count("\n") == 1, err
    assert err.startswith(f"nbs train: error: --resume {run}: {curve} is not a regular file"), err
