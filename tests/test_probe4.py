"""Probe 4's findings, by class: checkpoint tensors that pass torch's tensors-only reader and are not
weights (meta, sparse, quantized, of another type, keyed by a number), a training setting recorded
in a checkpoint and refused, unreadable files, an env used after close or after its episode ended, a
policy's seed, legal names too long for their temporary names, options that do not apply, and
library log records on stderr."""

from __future__ import annotations

import json
import pickle
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from nbs_env.atomic import temporary_path, write_text  # noqa: E402
from nbs_env.config import make_config  # noqa: E402
from nbs_env.env import NBSEnv  # noqa: E402
from nbs_env.errors import ConfigError, ModelFileError  # noqa: E402
from policies import make_policy  # noqa: E402
from policies.learned import BUNDLED, LearnedPolicy, check_tensors, read_tensors  # noqa: E402
from train.cli import main as nbs  # noqa: E402

REFERENCE = BUNDLED["reference"]


def _reference_state() -> dict:
    return torch.load(REFERENCE / "policy.pt", map_location="cpu", weights_only=True)


def _checkpoint(folder: Path, state=None, raw: bytes | None = None, training: dict | None = None) -> Path:
    """The bundled checkpoint with other weights (``state`` saved by torch, or ``raw`` bytes) or another
    recorded training, its checksum made to match: what a checksum cannot catch."""
    folder.mkdir(parents=True)
    document = json.loads((REFERENCE / "policy.json").read_text())
    weights = folder / "policy.pt"
    if raw is not None:
        weights.write_bytes(raw)
    elif state is not None:
        torch.save(state, weights)
    else:
        shutil.copy(REFERENCE / "policy.pt", weights)
    import hashlib

    document["sha256"] = hashlib.sha256(weights.read_bytes()).hexdigest()
    if training is not None:
        document["training"] = training
    (folder / "policy.json").write_text(json.dumps(document))
    return folder


class _Marker:
    """A pickle that would create a file if it were ever unpickled."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (self.path,))


# ---------------------------------------------------------------------- checkpoint tensors
TENSORS = {
    "meta": (lambda v: v.to("meta"), "tensor on the 'meta' device"),
    "sparse": (lambda v: v.to_sparse(), "sparse_coo tensor, not a dense one"),
    "int64": (lambda v: v.to(torch.int64), "of type int64"),
    "float16": (lambda v: v.half(), "of type float16"),
    "complex": (lambda v: v.to(torch.complex64), "of type complex64"),
    "bool": (lambda v: v.bool(), "of type bool"),
    "qint8": (lambda v: torch.quantize_per_tensor(v.float(), 0.1, 0, torch.qint8), "of type qint8"),
}


@pytest.mark.parametrize("kind", list(TENSORS))
def test_weights_that_are_not_dense_finite_floats_are_refused_in_one_line(kind, tmp_path):
    """Each passes torch.load(weights_only=True); each once crashed (meta, sparse), leaked torch's
    warnings (quantized, complex) or ran as another network (int, half, bool)."""
    convert, message = TENSORS[kind]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch deprecates making quantized tensors
        state = {k: convert(v) for k, v in _reference_state().items()}
    folder = _checkpoint(tmp_path / kind, state)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(ModelFileError, match=rf"policy\.pt: encoder\.net\.0\.weight is (a )?{message}"):
            make_policy(f"ppo:{folder}")
    assert [str(w.message) for w in caught] == []


def test_weights_keyed_by_anything_but_names_of_the_network_are_refused(tmp_path):
    state = _reference_state()
    with pytest.raises(ModelFileError, match="not a dict of tensors by name"):
        LearnedPolicy(_checkpoint(tmp_path / "int_key", {**state, 1: torch.zeros(1)}))
    with pytest.raises(ModelFileError, match=r"tensors of no part of the network \(zzz\.extra\)"):
        LearnedPolicy(_checkpoint(tmp_path / "extra", {**state, "zzz.extra": torch.zeros(3)}))


def test_a_raw_pickle_as_weights_is_refused_unread_in_one_line(tmp_path):
    marker = tmp_path / "PWNED"
    folder = _checkpoint(tmp_path / "pickle", raw=pickle.dumps(_Marker(marker), protocol=4))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(ModelFileError, match="not a tensors-only file") as refused:
            LearnedPolicy(folder)
    assert "weights_only" not in str(refused.value) and "\n" not in str(refused.value)
    assert [str(w.message) for w in caught] == [] and not marker.exists()


def test_check_tensors_names_the_first_bad_tensor_of_a_nest(tmp_path):
    good = {"policy": {"a": torch.zeros(2)}, "optimizer": {"state": {0: {"step": torch.tensor(3.0)}}}}
    check_tensors(good, tmp_path / "f.pt")  # an optimiser's state is keyed by parameter index
    bad = {"policy": {"a": torch.zeros(2)}, "optimizer": {"state": {0: {"exp_avg": torch.zeros(2, dtype=torch.int8)}}}}
    with pytest.raises(ModelFileError, match=r"f\.pt: optimizer\.state\.0\.exp_avg is of type int8"):
        check_tensors(bad, tmp_path / "f.pt")
    with pytest.raises(ModelFileError, match=r"a key of policy is a tuple"):
        check_tensors({"policy": {(1, 2): torch.zeros(1)}}, tmp_path / "f.pt")
    with pytest.raises(ModelFileError, match=r"policy\.a is not finite"):
        check_tensors({"policy": {"a": torch.tensor([1.0, float("inf")])}}, tmp_path / "f.pt")


@pytest.mark.skipif(not Path("/proc/self/mem").exists(), reason="Linux's /proc")
def test_an_unreadable_checkpoint_is_a_model_file_error_naming_it():
    with pytest.raises(ModelFileError, match=r"^/proc/self/mem: cannot be read \(Input/output error\)$"):
        make_policy("ppo:/proc/self/mem")
    with pytest.raises(ModelFileError, match="cannot be read"):
        read_tensors(Path("/proc/self/mem"))


# ---------------------------------------------------------------------- recorded training settings
@pytest.mark.parametrize(
    "rooms, inputs, message",
    [
        ({}, {"cell": 1e300}, r"observation\.cell must be within \[0\.01, 10\] metres, got 1e\+300"),
        ({}, {"below_floor": float("inf")}, r"observation\.below_floor must be a finite number"),
        ({"zzz_unknown": 5}, {}, r"the configuration has no 'rooms\.zzz_unknown'"),
        ({"wall_search": {"scans": -3}}, {}, r"rooms\.wall_search\.scans must be an integer >= 0"),
    ],
)
def test_a_refused_training_setting_is_blamed_on_the_checkpoint(rooms, inputs, message, tmp_path):
    """The value comes from policy.json, not from an option the user typed: the message names the file."""
    document = json.loads((REFERENCE / "policy.json").read_text())
    training = document["training"]
    training["config"]["rooms"].update(rooms)
    training["config"]["observation"].update(inputs)
    folder = _checkpoint(tmp_path / "ck", training=json.loads(json.dumps(training)))
    with pytest.raises(
        ModelFileError, match=rf"^{folder}/policy\.json: a training setting it records is refused: {message}"
    ):
        make_policy(f"ppo:{folder}")


def test_the_bundled_checkpoint_records_settings_the_default_robot_takes():
    assert make_policy("ppo:reference").requires["observation.cell"] == 0.2


# ---------------------------------------------------------------------- the env after its end
def test_an_env_after_close_or_after_its_episode_ended_refuses_to_step():
    import gymnasium as gym

    env = NBSEnv(make_config("fast", scene="l_room", max_scans=2))
    _, info = env.reset(seed=0)
    _, _, terminated, truncated, info = env.step(int(np.flatnonzero(info["action_mask"])[0]))
    assert truncated and not terminated
    with pytest.raises(gym.error.ResetNeeded, match="the episode has ended"):
        env.step(0)
    env.reset(seed=0)  # a reset starts again
    env.close()
    with pytest.raises(gym.error.ResetNeeded):
        env.step(0)
    env.render_mode = "rgb_array"
    with pytest.raises(gym.error.ResetNeeded):
        env.render()
    assert env.storey is None and env.scene is None


def test_an_episode_that_ends_at_reset_ends_at_the_first_step():
    """max_scans=1: reset takes the only scan; the first step reports the end (reset cannot), with no
    scan and reward 0, and a second step is refused."""
    import gymnasium as gym

    env = NBSEnv(make_config("fast", scene="l_room", max_scans=1))
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(0)
    assert (reward, terminated, truncated, info["scans"]) == (0.0, False, True, 1)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(0)


# ---------------------------------------------------------------------- a policy's seed
@pytest.mark.parametrize("seed", [-1, "x", float("nan"), 1.5, True])
def test_a_seed_that_numpy_would_refuse_is_a_config_error(seed):
    with pytest.raises(ConfigError, match="seed must be a non-negative integer"):
        make_policy("random", seed=seed)


def test_seeds_numpy_takes_are_taken():
    for seed in (0, np.int64(3), 2**70, np.random.default_rng(0), None):
        make_policy("random", seed=seed)


# ---------------------------------------------------------------------- names of 255 bytes
def test_a_temporary_name_fits_beside_a_legal_name_of_255_bytes(tmp_path):
    for name in ("a" * 251 + ".svg", "é" * 125 + ".json", "x." + "s" * 253, "plain"):
        temporary = temporary_path(tmp_path / name)
        assert len(temporary.name.encode()) <= 255 and temporary.name.startswith(".")
        assert temporary.name.endswith(Path(name).suffix) or len(Path(name).suffix) > 200
        write_text(tmp_path / name, "whole")
        assert (tmp_path / name).read_text() == "whole"
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_nbs_writes_pictures_and_plans_of_legal_long_names(tmp_path, capsys):
    picture, plan = tmp_path / ("a" * 251 + ".svg"), tmp_path / ("g" * 250 + ".json")
    assert nbs(["scenes", "show", "l_room", "--out", str(picture)]) == 0, capsys.readouterr().err
    assert nbs(["scenes", "generate", "--seed", "1", "--out", str(plan)]) == 0, capsys.readouterr().err
    assert picture.stat().st_size > 0 and json.loads(plan.read_text())


# ---------------------------------------------------------------------- options that do not apply
@pytest.mark.parametrize(
    "argv, message",
    [
        (
            ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0", "--address", "127.0.0.1:1"],
            "nbs compare: error: --address applies to --backend ray only (this run is --backend local)",
        ),
        (
            ["train", "--timesteps", "64", "--out", "{tmp}/t", "--address", "127.0.0.1:1"],
            "nbs train: error: --address applies to --backend ray only (this run is --backend local)",
        ),
        (
            ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0,"],
            "nbs compare: error: --seeds '0,' has an empty item",
        ),
        (
            ["compare", "--scenes", "l_room,,five_rooms", "--policies", "random", "--seeds", "0"],
            "nbs compare: error: --scenes 'l_room,,five_rooms' has an empty item",
        ),
        (
            ["compare", "--scenes", "l_room", "--policies", "random,", "--seeds", "0"],
            "nbs compare: error: --policies 'random,' has an empty item",
        ),
        (
            ["train", "--timesteps", "64", "--out", "{tmp}/t", "--bc-teacher", "ppo:reference"],
            "nbs train: error: bc_teacher must name a greedy (greedy or greedy:OPTIONS), got 'ppo:reference'",
        ),
    ],
)
def test_options_that_do_not_apply_are_refused_before_the_work(argv, message, tmp_path, capsys):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    if argv[0] == "compare":
        argv += ["--preset", "fast", "--max-scans", "1", "--quiet", "--out", str(tmp_path / "c")]
    assert nbs(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count("\n") == 1, err
    assert not (tmp_path / "c").exists() and not (tmp_path / "t").exists()


# ---------------------------------------------------------------------- library log records
def test_a_library_log_record_is_one_prefixed_line(tmp_path, capsys):
    """matplotlib logs (not warns) that PostScript has no transparency; Python's last resort printed
    the bare message as a stray line."""
    assert nbs(["scenes", "show", "l_room", "--out", str(tmp_path / "x.eps")]) == 0
    err = capsys.readouterr().err
    assert err == (
        "nbs: warning: The PostScript backend does not support transparency; partially transparent artists "
        "will be rendered opaque.\n"
    )
    assert (tmp_path / "x.eps").stat().st_size > 0
