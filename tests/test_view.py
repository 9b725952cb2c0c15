"""``nbs view``: a recording in rerun's native viewer, or served to a browser with ``--web``; the exit
codes when there is no display, no viewer, or no readable recording."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from nbs_env.env import NBSEnv
from train.cli import EXIT_NO_VIEWER, EXIT_SCENE_ERROR, EXIT_USAGE, main

ROOT = Path(__file__).resolve().parents[1]
#: Seconds a subprocess may take to start (the machine may be busy) and to stop.
STARTUP = 90.0
STOP = 30.0


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """A real recording, small: the first scan of l_room on the fast preset."""
    pytest.importorskip("rerun")
    from nbs_env.replay import RunRecorder

    path = tmp_path_factory.mktemp("view") / "l_room.rrd"
    env = NBSEnv("fast", scene="l_room", max_scans=1)
    with RunRecorder(path, "l_room", max_points_per_scan=2000) as recorder:
        env.reset(seed=0)
        recorder.log_step(env)
    return path


def headless() -> dict[str, str]:
    """This environment without a display."""
    return {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")}


def _ctrl_c_as_at_a_terminal() -> None:
    """A child's SIGINT as a terminal's: pytest-xdist's workers ignore SIGINT, a child inherits that,
    and Python then never turns it into KeyboardInterrupt (a user's shell gives the default)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def nbs(*args: str) -> list[str]:
    return [sys.executable, "-m", "train", *args]


def test_without_a_display_the_native_viewer_is_refused_and_web_suggested(recording):
    done = subprocess.run(
        nbs("view", str(recording)), env=headless(), cwd=ROOT, capture_output=True, text=True, timeout=STARTUP
    )
    assert done.returncode == EXIT_NO_VIEWER, done.stderr
    assert "no display" in done.stderr and f"nbs view --web {recording}" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "no recording at"),
        (b"", "not a rerun recording"),
        (b'{"scans": 3}', "not a rerun recording"),
        (b"RRF2" + bytes(range(256)) * 8, "cannot be read as a rerun recording"),
    ],
    ids=["missing", "empty", "json", "garbage after the magic"],
)
def test_a_missing_or_unreadable_recording_exits_1(tmp_path, capsys, content, message):
    pytest.importorskip("rerun")
    path = tmp_path / "run.rrd"
    if content is not None:
        path.write_bytes(content)
    for web in ([], ["--web"]):
        assert main(["view", *web, str(path)]) == EXIT_SCENE_ERROR
        assert message in capsys.readouterr().err


def test_a_recording_cut_short_exits_1(tmp_path, capsys, recording):
    cut = tmp_path / "cut.rrd"
    data = recording.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    assert main(["view", "--web", str(cut)]) == EXIT_SCENE_ERROR
    assert "cannot be read as a rerun recording" in capsys.readouterr().err


def test_server_options_need_web(recording, capsys):
    assert main(["view", "--port", "0", str(recording)]) == EXIT_USAGE
    assert "--port needs --web" in capsys.readouterr().err


def test_a_web_port_in_use_exits_3_naming_the_port(recording, capsys):
    """Found before rerun starts: given a port in use, rerun at times neither exited nor served within
    the timeout, and the message blamed its start-up."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        started = time.monotonic()
        assert main(["view", "--web", "--port", "0", "--web-port", str(port), str(recording)]) == EXIT_NO_VIEWER
        assert time.monotonic() - started < 10
    err = capsys.readouterr().err
    assert f"the web viewer's port (--web-port) {port} on 127.0.0.1: in use" in err, err
    assert "nbs view --web" not in err  # no hint to do what was done


def _serving(recording: Path, out: Path) -> tuple[subprocess.Popen, str]:
    """``nbs view --web`` started, once it prints the URL: the process and the URL."""
    with out.open("w") as stdout:
        process = subprocess.Popen(
            nbs("view", "--web", "--port", "0", "--web-port", "0", str(recording)),
            env=headless(),
            cwd=ROOT,
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=_ctrl_c_as_at_a_terminal,
        )
    deadline = time.monotonic() + STARTUP
    while True:
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            raise AssertionError(f"no URL printed within {STARTUP} s: {process.communicate()[1]}")
        found = re.search(r"open (http://\S+)", out.read_text())
        if found:
            return process, found.group(1)
        time.sleep(0.2)


def test_a_killed_viewer_leaves_no_server(recording, tmp_path):
    """SIGKILL to nbs view --web (no chance to stop rerun itself): rerun's server ends with it."""
    process, url = _serving(recording, tmp_path / "stdout.txt")
    process.kill()
    process.communicate()
    deadline = time.monotonic() + 15
    while True:
        try:
            urllib.request.urlopen(url, timeout=1).close()
        except OSError:
            break
        assert time.monotonic() < deadline, "rerun's server outlived its killed parent"
        time.sleep(0.3)


def test_web_serves_the_recording_until_ctrl_c(recording, tmp_path):
    out = tmp_path / "stdout.txt"
    process, url = _serving(recording, out)
    try:
        # Printed once the web viewer answers: its page is served, and the recording's server listens.
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        grpc = re.search(r"127\.0\.0\.1%3A(\d+)%2Fproxy", url)
        assert grpc, url
        socket.create_connection(("127.0.0.1", int(grpc.group(1))), timeout=10).close()
        assert "Ctrl-C" in out.read_text()
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=STOP)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, err
    assert "Traceback" not in err
    # rerun's server went with it.
    with pytest.raises(OSError):
        urllib.request.urlopen(url, timeout=5)
