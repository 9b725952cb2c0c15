"""What ``nbs scan`` and ``nbs compare`` leave on disk when the disk fills or a signal stops them:
every file whole (the previous one, or the new one, never a truncated one), the finished work kept,
one line saying so, and the exit code of the signal."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import nbs_env.atomic
from nbs_env.atomic import replacing, write_text
from train.cli import EXIT_SCENE_ERROR, main

ROOT = Path(__file__).resolve().parents[1]
#: The bundled scene at the fast preset, a few scans: a report in seconds.
FAST = ["--preset", "fast", "--max-scans", "3", "--quiet"]


def full_disk(monkeypatch) -> list[int]:
    """Make every write of :mod:`nbs_env.atomic` put half its bytes down, then fail as a full disk does;
    returns the sizes it was asked to write."""
    asked: list[int] = []

    def write(fd: int, data: memoryview) -> int:
        asked.append(len(data))
        os.write(fd, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(nbs_env.atomic, "_write", write)
    return asked


def leftovers(folder: Path) -> list[str]:
    """The temporary files of :mod:`nbs_env.atomic` under ``folder``."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob(".*.tmp*"))


# ---------------------------------------------------------------------- whole or not at all
def test_a_full_disk_leaves_the_previous_file_and_no_partial_one(tmp_path, monkeypatch):
    path = tmp_path / "metrics.json"
    write_text(path, '{"scans": 3}\n')
    assert leftovers(tmp_path) == [] and path.read_text() == '{"scans": 3}\n'
    asked = full_disk(monkeypatch)
    with pytest.raises(OSError) as raised:
        write_text(path, json.dumps({"scans": list(range(1000))}))
    assert asked, "the write never reached the disk"
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(path)
    assert path.read_text() == '{"scans": 3}\n'  # the previous file, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]  # and nothing else
    # A new file that cannot be written is no file at all.
    with pytest.raises(OSError):
        write_text(tmp_path / "table.md", "| a |\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_a_library_s_file_is_renamed_only_once_written(tmp_path):
    """libE57, laspy and matplotlib write to a temporary path with the file's suffix; an error or a
    signal in the middle leaves the previous file."""
    path = tmp_path / "cloud.laz"
    path.write_bytes(b"previous")
    with pytest.raises(KeyboardInterrupt), replacing(path) as temporary:
        assert temporary.parent == tmp_path and temporary.suffix == ".laz" and temporary.name.startswith(".")
        temporary.write_bytes(b"half of a new")
        raise KeyboardInterrupt
    assert path.read_bytes() == b"previous" and leftovers(tmp_path) == []
    with replacing(path) as temporary:
        temporary.write_bytes(b"new")
    assert path.read_bytes() == b"new" and leftovers(tmp_path) == []


#: A child process that writes a scan project (E57) and a LAZ cloud under a file-size limit, so that
#: the libraries themselves meet a failed write() halfway, as on a full disk or over a quota; it
#: prints how each write ended. In a child: libE57 once crashed the process (a segmentation fault).
LIMITED_WRITER = """
import resource, signal, sys
import numpy as np
from pathlib import Path
from nbs_env.export import write_e57, write_las
from nbs_env.storey import ScanPoints

signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
folder = Path(sys.argv[1])
n = 200_000
points = np.random.default_rng(0).normal(size=(n, 3)).astype(np.float32)
scan = ScanPoints(points=points, rows=(np.arange(n) % 100).astype(np.uint16),
                  cols=(np.arange(n) // 100).astype(np.uint16), pose=np.eye(4))
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
writers = (
    ("scans.e57", lambda p: write_e57(p, [scan])),
    ("cloud.laz", lambda p: write_las(p, points, np.ones(n, "u1"))),
)
for name, write in writers:
    try:
        write(folder / name)
        print(name, "written")
    except OSError as exc:
        print(name, "OSError", exc.errno, exc.filename, exc.strerror)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX file-size limits")
def test_a_library_writer_that_fails_halfway_raises_an_oserror_naming_the_file(tmp_path):
    """libE57 and lazrs report a failed write with their own exceptions, and libE57 crashed the
    process when its writer was freed after the file was cancelled: each now raises an OSError that
    names the file (what ``nbs scan`` prints in one line), leaves no partial file, and the process lives."""
    pytest.importorskip("pye57")
    done = subprocess.run(
        [sys.executable, "-c", LIMITED_WRITER, str(tmp_path)], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert done.returncode == 0, done.stderr[-2000:]
    lines = dict(line.split(" ", 1) for line in done.stdout.strip().splitlines())
    assert lines["scans.e57"].startswith(f"OSError {errno.EIO} {tmp_path / 'scans.e57'} could not be written ("), lines
    # laspy meets the limit in Python (EFBIG); on a full disk lazrs raises its own error instead (both
    # are an OSError naming the file now).
    kind, _, named, _ = lines["cloud.laz"].split(" ", 3)
    assert (kind, named) == ("OSError", str(tmp_path / "cloud.laz")), lines
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing partial, nothing temporary


def test_a_library_s_own_error_on_a_nearly_full_disk_is_a_full_disk(tmp_path, monkeypatch):
    """Which error a library raises when the disk fills is its own; with (almost) nothing left on the
    disk it is reported as the full disk it is, naming the file."""

    class LibraryError(Exception):
        pass

    path = tmp_path / "scans.e57"
    monkeypatch.setattr(nbs_env.atomic.shutil, "disk_usage", lambda folder: _usage(0))
    with pytest.raises(OSError) as raised, replacing(path) as temporary:
        temporary.write_bytes(b"part")
        raise LibraryError("write failed")
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(path)
    assert "LibraryError" in raised.value.strerror and not path.exists() and leftovers(tmp_path) == []
    # With room left, a library's error is its own (a bug to see, not a disk to blame).
    monkeypatch.setattr(nbs_env.atomic.shutil, "disk_usage", lambda folder: _usage(10**12))
    with pytest.raises(LibraryError), replacing(path) as temporary:
        raise LibraryError("write failed")


def _usage(free: int):
    """What ``shutil.disk_usage`` answers for a 1 TB disk with ``free`` bytes left."""
    from collections import namedtuple

    return namedtuple("usage", "total used free")(10**12, 10**12 - free, free)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs fifos")
def test_an_output_that_is_a_fifo_is_refused_and_a_link_is_written_through(tmp_path, capsys):
    """Renamed onto, a device (``/dev/full``), a fifo or a link was replaced by a plain file."""
    fifo = tmp_path / "plan.json"
    os.mkfifo(fifo)
    code = main(["scenes", "generate", "--seed", "1", "--rooms", "2", "--out", str(fifo)])
    assert code == 2 and "is not a regular file" in capsys.readouterr().err
    assert fifo.is_fifo()
    with pytest.raises(OSError, match="not a regular file"):
        write_text(fifo, "{}")
    target, link = tmp_path / "target.json", tmp_path / "link.json"
    link.symlink_to(target)
    assert main(["scenes", "generate", "--seed", "1", "--rooms", "2", "--out", str(link)]) == 0
    assert link.is_symlink() and json.loads(target.read_text())["rooms"]


def test_nbs_scan_on_a_full_disk_keeps_the_previous_report_and_names_the_file(tmp_path, monkeypatch, capsys):
    out = tmp_path / "report"
    out.mkdir()
    (out / "metrics.json").write_text('{"previous": true}\n')
    full_disk(monkeypatch)
    code = main(["scan", "--scene", "l_room", *FAST, "--no-steps", "--out", str(out), "--force"])
    err = capsys.readouterr().err
    assert code == EXIT_SCENE_ERROR, err
    assert err == f"nbs scan: error: {out / 'metrics.json'}: No space left on device\n"
    assert (out / "metrics.json").read_text() == '{"previous": true}\n'
    assert leftovers(out) == []


def test_nbs_scenes_generate_on_a_full_disk_leaves_no_half_a_plan(tmp_path, monkeypatch, capsys):
    """It once exited 0 with an empty plan file."""
    full_disk(monkeypatch)
    plan = tmp_path / "plan.json"
    code = main(["scenes", "generate", "--seed", "1", "--rooms", "2", "--out", str(plan)])
    assert (code, capsys.readouterr().err) == (EXIT_SCENE_ERROR, f"nbs: error: {plan}: No space left on device\n")
    assert list(tmp_path.iterdir()) == []


def test_nbs_compare_on_a_full_disk_stops_and_names_the_file(tmp_path, monkeypatch, capsys):
    out = tmp_path / "grid"
    full_disk(monkeypatch)
    code = main(["compare", "--scenes", "l_room", "--policies", "random", "--seeds", "0,1", *FAST, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == EXIT_SCENE_ERROR, err
    metrics = out / "runs" / "l_room" / "random" / "seed0" / "metrics.json"
    assert err == f"nbs compare: error: {metrics}: No space left on device\n"
    assert not metrics.exists() and leftovers(out) == []
    assert not (out / "runs" / "l_room" / "random" / "seed1").exists()  # the grid stopped there


# ---------------------------------------------------------------------- signals
def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (Linux's /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has ended; only its parent's reaper is late


def _start(args: list[str], folder: Path, ready: str, group: bool = False) -> subprocess.Popen:
    """``python -m train ARGS``, once a file matching ``folder / ready`` exists (the first scan or
    run recorded); ``group``: in a process group of its own, as a terminal's foreground job."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "train", *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=group,
    )
    deadline = time.monotonic() + 120
    while not (folder.is_dir() and any(folder.glob(ready))):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"{folder / ready} never appeared: {proc.communicate()}")
        time.sleep(0.02)
    return proc


needs_proc = pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads processes from Linux's /proc")


@pytest.mark.parametrize(
    "sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP (terminal closed)"]
)
def test_a_signal_during_nbs_scan_writes_the_report_of_the_scans_taken(tmp_path, sig):
    out = tmp_path / "report"
    args = ["scan", "--scene", "l_room", "--preset", "fast", "--max-scans", "30", "--quiet", "--out", str(out)]
    proc = _start(args, out, ".steps-*/step_000.png")  # the pictures wait there until the report is written
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert 1 <= metrics["scans"] < 30 and not metrics["complete"]
    name = signal.Signals(sig).name
    assert stderr == f"nbs scan: stopped by {name} after {metrics['scans']} scans; wrote their report to {out}/\n"
    assert f"storey complete: no (stopped by {name})" in stdout
    for file in ("scans.e57", "cloud.laz", "cloud.ply", "samples.npz", "topdown.png"):
        assert (out / file).stat().st_size > 0, file
    assert len(list((out / "steps").glob("step_*.png"))) == metrics["scans"] and leftovers(out) == []
    assert not list(out.glob(".steps-*"))


def test_a_second_signal_waits_while_the_work_writes_what_it_keeps():
    """Outside ``hold()`` a second signal raises at once (the user will not wait); inside it, it is
    only noted, so a report or a training state is not left half-written."""
    from train.stopping import DUPLICATE_S, StopRequest

    with StopRequest() as stop:
        with stop.hold():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(2 * DUPLICATE_S)
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        assert stop.signal == signal.SIGINT
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)


def test_one_signal_delivered_twice_is_one_request():
    """`timeout` and a closing terminal send the signal to the process and then to its group: the
    two deliveries, handled apart, once read as a second Ctrl-C (a KeyboardInterrupt mid-shutdown,
    then a segmentation fault). The same signal again within DUPLICATE_S is the same request."""
    from train.stopping import StopRequest

    with StopRequest() as stop:
        os.kill(os.getpid(), signal.SIGHUP)
        os.kill(os.getpid(), signal.SIGHUP)
        time.sleep(0.01)
        assert stop.signal == signal.SIGHUP


def test_a_stop_between_runs_keeps_the_finished_ones(tmp_path):
    """One job: the run in progress when the stop comes ends at its next step and is no result."""
    from train.compare import GridStoppedError, grid, load_finished, run_grid, write_record

    specs = grid("l_room", "random", "0,1", "fast", {"max_scans": 3})
    done: list[dict] = []

    def on_done(kind: str, record: dict) -> None:
        write_record(tmp_path, kind, record)
        done.append(record)

    with pytest.raises(GridStoppedError) as stopped:
        run_grid(specs, jobs=1, progress=False, on_done=on_done, stop=lambda: bool(done))
    assert (stopped.value.finished, stopped.value.total) == (1, 3)  # two runs and the oracle
    assert [r["spec"]["seed"] for r in done] == [0]
    assert list(load_finished(tmp_path, specs)["runs"]) == [specs[0].key]


#: The stopped grid's runs: enough that some are left when the first is recorded (about a second each).
SEEDS = 6


def _compare_stopped_by(sig: int, tmp_path: Path, group: bool = False) -> tuple[list[str], Path, str]:
    """Start a grid of two jobs, stop it by ``sig`` after its first run (sent to its whole process
    group with ``group``, as a closing terminal or ``timeout`` sends it); check what it kept."""
    out = tmp_path / "grid"
    args = ["compare", "--scenes", "l_room", "--policies", "random", "--seeds", ",".join(map(str, range(SEEDS)))]
    args += ["--preset", "fast", "--max-scans", "2", "--jobs", "2", "--quiet", "--out", str(out)]
    proc = _start(args, out, "runs/l_room/random/seed*/run.json", group=group)
    workers = _children(proc.pid)
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, stderr
    kept = sorted(p.parent.name for p in out.glob("runs/l_room/random/seed*/run.json"))
    assert 1 <= len(kept) < SEEDS, (kept, stderr)
    name = signal.Signals(sig).name
    assert stderr.startswith(f"nbs compare: stopped by {name}: ") and stderr.count("\n") == 1, stderr
    assert f"kept in {out}; continue with the same command and --resume" in stderr
    for seed in kept:  # every run kept is whole
        record = json.loads((out / "runs" / "l_room" / "random" / seed / "run.json").read_text())
        assert record["ok"] and json.loads((out / "runs" / "l_room" / "random" / seed / "metrics.json").read_text())
    assert leftovers(out) == [] and not (out / "table.md").exists()
    deadline = time.monotonic() + 10
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [pid for pid in workers if _alive(pid)], "a worker process outlived nbs compare"
    return args, out, stdout


@needs_proc
def test_sigterm_during_nbs_compare_ends_its_workers_and_keeps_the_finished_runs(tmp_path):
    _compare_stopped_by(signal.SIGTERM, tmp_path)


@needs_proc
@pytest.mark.skipif(not hasattr(signal, "SIGHUP"), reason="POSIX signals")
def test_a_closing_terminal_stops_nbs_compare_with_one_line(tmp_path):
    """SIGHUP to the whole process group once killed multiprocessing's resource tracker too, whose
    successor printed a leak warning and a traceback per semaphore after the one line."""
    _compare_stopped_by(signal.SIGHUP, tmp_path, group=True)


@needs_proc
@pytest.mark.expensive
def test_ctrl_c_during_nbs_compare_then_resume_finishes_the_grid(tmp_path):
    """Two grids' worth of worker start-ups, about half a minute on 2 busy cores."""
    args, out, _ = _compare_stopped_by(signal.SIGINT, tmp_path)
    kept = {p: p.read_text() for p in out.glob("runs/l_room/random/seed*/metrics.json")}
    proc = subprocess.run(
        [sys.executable, "-m", "train", *args, "--resume"], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr
    assert f"{SEEDS} of {SEEDS} runs ok" in proc.stdout
    # Reused, not run again: a run again would have taken other times.
    assert {p: json.loads(p.read_text()) for p in kept} == {p: json.loads(text) for p, text in kept.items()}
    assert len(list(out.glob("runs/l_room/random/seed*/metrics.json"))) == SEEDS and (out / "table.md").is_file()
