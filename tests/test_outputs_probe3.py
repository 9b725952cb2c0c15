"""Output handling found wanting by the third robustness probe: ``nbs compare --resume`` wrote through
links in its folder to files outside it (P5), an error writing stdout did not say it was stdout (P12),
and ``--out gdir/`` quietly became a file named ``gdir`` (P13)."""

from __future__ import annotations

import errno
import io
import json
import os
import shutil
from pathlib import Path

import pytest

from nbs_env.atomic import replacing, write_text
from train.cli import EXIT_USAGE, main
from train.outputs import NamedStream, Output, OutputError, check_outputs, output_path

GRID = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0"]
GRID += ["--preset", "fast", "--max-scans", "1", "--quiet"]


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A one-run comparison folder, made once."""
    out = tmp_path_factory.mktemp("grid") / "c0"
    assert main([*GRID, "--out", str(out)]) == 0
    return out


def _linked_copy(finished: Path, tmp_path: Path) -> tuple[Path, dict[Path, bytes]]:
    """A copy of ``finished`` whose metrics.json and table.md are links to files outside it."""
    out = tmp_path / "c12"
    shutil.copytree(finished, out)
    victims = {}
    for k, part in enumerate([Path("runs/l_room/random/seed0/metrics.json"), Path("table.md")]):
        victim = tmp_path / f"victim{k}.txt"
        victim.write_bytes(f"precious user data {k}\n".encode())
        victims[victim] = victim.read_bytes()
        (out / part).unlink()
        (out / part).symlink_to(victim)
    return out, victims


# ---------------------------------------------------------------------- P5: links in --out
@pytest.mark.parametrize("flag", ["--resume", "--force"])
def test_a_link_in_the_comparison_folder_is_refused_before_the_work(finished, tmp_path, capsys, flag):
    out, victims = _linked_copy(finished, tmp_path)
    capsys.readouterr()
    code = main([*GRID, flag, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE, err
    assert err.count("\n") == 1 and err.startswith("nbs compare: error: --out "), err
    assert f"{out / 'table.md'} is a symbolic link" in err  # the first found, top level first
    for victim, before in victims.items():
        assert victim.read_bytes() == before  # byte for byte
    assert (out / "table.md").is_symlink()  # nothing in the folder was touched either


def test_a_linked_folder_in_the_comparison_folder_is_refused(finished, tmp_path, capsys):
    out = tmp_path / "c"
    shutil.copytree(finished, out)
    elsewhere = tmp_path / "elsewhere"
    shutil.move(out / "runs" / "l_room", elsewhere)
    (out / "runs" / "l_room").symlink_to(elsewhere, target_is_directory=True)
    before = {p: p.read_bytes() for p in elsewhere.rglob("*") if p.is_file()}
    assert main([*GRID, "--resume", "--out", str(out)]) == EXIT_USAGE
    assert f"{out / 'runs' / 'l_room'} is a symbolic link" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in elsewhere.rglob("*") if p.is_file()} == before


def test_a_resumed_comparison_without_links_still_runs(finished, tmp_path, capsys):
    out = tmp_path / "c"
    shutil.copytree(finished, out)
    (out / "table.md").unlink()
    assert main([*GRID, "--resume", "--out", str(out)]) == 0, capsys.readouterr().err
    assert (out / "table.md").is_file() and not (out / "table.md").is_symlink()


def test_the_folder_writer_replaces_a_link_and_leaves_its_target(tmp_path):
    """A link made while the grid runs (after the check) is replaced, not written through."""
    victim, link = tmp_path / "victim.txt", tmp_path / "table.md"
    victim.write_text("precious\n")
    link.symlink_to(victim)
    write_text(link, "| a |\n", follow_links=False)
    assert not link.is_symlink() and link.read_text() == "| a |\n"
    assert victim.read_text() == "precious\n"
    link.unlink()
    link.symlink_to(victim)
    with replacing(link, follow_links=False) as temporary:
        temporary.write_text("figure")
    assert not link.is_symlink() and link.read_text() == "figure" and victim.read_text() == "precious\n"
    # A link to a fifo is replaced too; a fifo itself is still refused.
    link.unlink()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    link.symlink_to(fifo)
    write_text(link, "x", follow_links=False)
    assert link.read_text() == "x" and fifo.is_fifo()
    with pytest.raises(OSError, match="not a regular file"):
        write_text(fifo, "x", follow_links=False)


def test_compare_writes_its_records_without_following_links(tmp_path):
    import train.compare as compare

    victim = tmp_path / "victim.json"
    victim.write_text('{"precious": 1}\n')
    out = tmp_path / "out"
    out.mkdir()
    (out / "oracle.json").symlink_to(victim)
    compare.write_record(out, "oracle", {"scene": "l_room", "ok": False})
    assert victim.read_text() == '{"precious": 1}\n'
    assert not (out / "oracle.json").is_symlink()
    assert json.loads((out / "oracle.json").read_text()) == {"l_room": {"scene": "l_room", "ok": False}}


# ---------------------------------------------------------------------- P12: stdout named
class _FullStream(io.StringIO):
    def write(self, text: str) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def flush(self) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


class _GoneStream(io.StringIO):
    def write(self, text: str) -> int:
        raise BrokenPipeError(errno.EPIPE, os.strerror(errno.EPIPE))


def test_an_error_writing_stdout_names_it():
    stream = NamedStream(_FullStream())
    for act in (lambda: stream.write("x"), stream.flush, lambda: print("x", file=stream)):
        with pytest.raises(OSError) as raised:
            act()
        assert raised.value.errno == errno.ENOSPC and raised.value.filename == "stdout"
        assert f"{raised.value.filename}: {raised.value.strerror}" == "stdout: No space left on device"
    with pytest.raises(BrokenPipeError) as gone:  # still the reader gone away, for main's handler
        NamedStream(_GoneStream()).write("x")
    assert gone.value.filename == "stdout"
    good = NamedStream(io.StringIO())
    print("fine", file=good)
    assert good.getvalue() == "fine\n"


# ---------------------------------------------------------------------- P13: `--out gdir/`
def test_a_file_output_typed_as_a_folder_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = main(["scenes", "generate", "--seed", "1", "--rooms", "2", "--out", "gdir/"])
    err = capsys.readouterr().err
    assert code == EXIT_USAGE
    assert err.count("\n") == 1
    assert err.startswith("nbs scenes generate: error: --out gdir/: ends with a separator, so it names a folder")
    assert list(tmp_path.iterdir()) == []  # no file named gdir
    # Without the separator it is a file, as before; a folder output may end with one.
    assert main(["scenes", "generate", "--seed", "1", "--rooms", "2", "--out", "gdir.json"]) == 0
    assert (tmp_path / "gdir.json").is_file()
    check_outputs([Output("--out", output_path("reports/"), "folder")])
    with pytest.raises(OutputError, match=r"--record r/: .* name a file in it \(e\.g\. r/run\.rrd\)"):
        check_outputs([Output("--record", output_path("r/"), "file", example="run.rrd")])


def test_an_output_path_typed_with_a_separator_is_still_the_same_path():
    path = output_path("gdir/")
    assert path == Path("gdir") and str(path) == "gdir" and path / "a.json" == Path("gdir/a.json")
    assert type(output_path("gdir")) is type(Path("gdir"))
