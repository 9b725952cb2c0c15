"""Property-based test of the numeric options of ``nbs scan``, ``nbs compare`` and ``nbs train``.

Any value a user may type (negative, zero, huge, NaN, inf, not a number, empty, a range written
backwards) either reaches the work with a configuration its own checks accept, or is refused with exit
code 2 and a message naming the option, before anything is built: never a traceback, a hang, or an
allocation the options did not bound. The work itself (the episode, the grid, the training envs) is
replaced by a sentinel that records the configuration and stops: what is under test is the door, and
the work behind it has its own tests. The examples are drawn deterministically, few enough for the
default suite.
"""

from __future__ import annotations

import pytest

hypothesis = pytest.importorskip("hypothesis")
from helpers import time_limit  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from train.cli import EXIT_USAGE, main  # noqa: E402

SETTINGS = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

#: A command that takes longer than this to accept or refuse its options counts as a hang.
SECONDS = 30


class ReachedError(Exception):
    """The options were accepted and the work was about to start."""


def numbers() -> st.SearchStrategy[str]:
    """What a user types where a number belongs."""
    return st.one_of(
        st.integers(-(10**30), 10**30).map(str),
        st.integers(-3, 100).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
        st.floats(-1e3, 1e3).map(lambda x: f"{x:.4g}"),
        st.sampled_from(["", " ", "nan", "-inf", "1e309", "-0", "0x10", "1_000", "٣", "1e-320", "5e-324"]),
        st.text(alphabet="0123456789.-e+x ,", max_size=10),
    )


def ranges() -> st.SearchStrategy[str]:
    """``A-B`` as typed: backwards, huge, negative, one-sided."""
    return st.one_of(numbers(), st.tuples(numbers(), numbers()).map(lambda ab: f"{ab[0]}-{ab[1]}"))


#: The robot options every command shares (train.arguments.add_robot_arguments).
ROBOT = ["--resolution", "--voxel", "--wall-search", "--max-scans", "--min-density", "--max-incidence"]
SCAN = ["--seed", "--start", *ROBOT]
COMPARE = ["--jobs", "--seeds", *ROBOT]
TRAIN = [
    "--timesteps",
    "--envs",
    "--seed",
    "--eval-every",
    "--checkpoint-every",
    "--bc-steps",
    "--eval-storeys",
    "--learning-rate",
    "--n-steps",
    "--metre-cost",
    "--scan-cost",
    "--ent-coef",
    "--max-episode-steps",
    *ROBOT,
]
RANGES = {"--rooms", "--cell-size"}


def command_lines(options: list[str], extra: list[str] | None = None) -> st.SearchStrategy[list[tuple[str, str]]]:
    names = st.sampled_from(options + (extra or []))
    return st.lists(st.tuples(names, ranges()), min_size=1, max_size=3)


def _argv(pairs: list[tuple[str, str]]) -> list[str]:
    # --opt=VALUE so that a value starting with '-' is a value, as a user would write it.
    return [f"{name}={value}" for name, value in pairs]


def _check_outcome(command: str, argv: list[str], capsys) -> str:
    """Run ``nbs COMMAND ARGV``; 'accepted' when the work was reached, 'refused' on a clean refusal."""
    try:
        with time_limit(SECONDS):
            code = main([command, *argv])
    except ReachedError:
        return "accepted"
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert code == EXIT_USAGE, (argv, code, err)
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"nbs {command}: error: "), err
    return "refused"


@pytest.fixture
def stubbed(monkeypatch, tmp_path):
    """The work of the three commands replaced by :class:`ReachedError`, after the configuration is checked."""
    import train.cli
    import train.compare

    seen: list = []

    def scan(args, policy, out, config, stop):
        seen[:] = [config]
        raise ReachedError

    def run_grid(specs, jobs, *args, **kwargs):
        assert 1 <= len(specs) <= 100_000 and jobs >= 1
        seen[:] = [specs]
        raise ReachedError

    monkeypatch.setattr(train.cli, "_scan", scan)
    monkeypatch.setattr(train.compare, "run_grid", run_grid)
    try:
        import train.ppo

        def envs(config, seed=None):
            seen[:] = [config]
            raise ReachedError

        monkeypatch.setattr(train.ppo, "make_training_envs", envs)
    except ImportError:
        pass
    monkeypatch.chdir(tmp_path)
    return seen


@SETTINGS
@given(pairs=command_lines(SCAN))
def test_any_numeric_option_of_scan_is_accepted_or_refused_in_one_line(pairs, stubbed, capsys, tmp_path):
    argv = ["--scene", "l_room", "--no-steps", "--quiet", "--force", "--out", str(tmp_path / "r"), *_argv(pairs)]
    _check_outcome("scan", argv, capsys)


@SETTINGS
@given(pairs=command_lines(COMPARE, ["--scenes"]))
def test_any_numeric_option_of_compare_is_accepted_or_refused_in_one_line(pairs, stubbed, capsys, tmp_path):
    scenes = [f"generated:{v}" for n, v in pairs if n == "--scenes"]
    pairs = [(n, v) for n, v in pairs if n != "--scenes"]
    argv = ["--scenes", scenes[0] if scenes else "l_room", "--policies", "greedy", "--force", "--quiet"]
    _check_outcome("compare", [*argv, "--out", str(tmp_path / "c"), *_argv(pairs)], capsys)


@SETTINGS
@given(pairs=command_lines(TRAIN, sorted(RANGES)))
def test_any_numeric_option_of_train_is_accepted_or_refused_in_one_line(pairs, stubbed, capsys, tmp_path):
    pytest.importorskip("sb3_contrib")
    out = tmp_path / "run"
    if out.exists():  # an accepted example made the folder; the next one starts afresh
        import shutil

        shutil.rmtree(out)
    _check_outcome("train", ["--out", str(out), "--quiet", *_argv(pairs)], capsys)


def test_the_sentinel_is_reached_by_valid_options(stubbed, capsys, tmp_path):
    """The property tests above can fail: valid options do reach the work (the stub), bad ones do not."""
    assert _check_outcome("scan", ["--scene", "l_room", "--out", str(tmp_path / "r"), "--voxel=0.1"], capsys) == (
        "accepted"
    )
    assert _check_outcome("scan", ["--scene", "l_room", "--out", str(tmp_path / "r"), "--voxel=nan"], capsys) == (
        "refused"
    )
    argv = ["--scenes", "generated:0-3", "--policies", "greedy", "--out", str(tmp_path / "c"), "--seeds=0,1"]
    assert _check_outcome("compare", argv, capsys) == "accepted"
    assert len(stubbed[-1]) == 8
