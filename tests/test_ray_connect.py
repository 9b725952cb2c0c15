"""Ray as users run it (train/ray_connect.py): an address where nothing listens is refused at once with
the address, a cluster already running is joined (not asked for CPUs it refuses), and a local instance
starts only when none is named or recorded.

No test here joins a Ray instance it did not start: this machine may run others (a training run's). The
address rules are checked with ``ray.init`` replaced and Ray's record of ``ray start`` clusters pointed
elsewhere; the one test that joins a real cluster starts its own, with its own temporary folder."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from nbs_env.errors import ConfigError
from train import ray_connect
from train.ray_connect import RayConnection, RayConnectionError, connect_ray, resolve_address

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def listening():
    """``host:port`` of a TCP socket that accepts connections (a stand-in for a head node's port)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    yield f"127.0.0.1:{server.getsockname()[1]}"
    server.close()


@pytest.fixture
def closed():
    """``host:port`` where nothing listens: a port the system gave out and took back."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return f"127.0.0.1:{port}"


@pytest.fixture
def isolated(monkeypatch, tmp_path):
    """No RAY_ADDRESS, and Ray's record of a ``ray start`` cluster read from an empty folder."""
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
    monkeypatch.setattr(ray_connect, "_recorded_cluster", lambda: None)
    return monkeypatch


def test_which_cluster_an_address_names(isolated, listening, closed):
    """The rules of --address, RAY_ADDRESS and a recorded cluster, without joining anything."""
    assert resolve_address(None) == RayConnection(None, "local")
    assert resolve_address("local") == RayConnection(None, "local")
    assert resolve_address(listening) == RayConnection(listening, "--address")
    assert resolve_address(f"ray://{listening}") == RayConnection(f"ray://{listening}", "--address")
    refused = rf"--address {closed}: nothing answers at {closed} \(Connection refused\); start the cluster there"
    with pytest.raises(RayConnectionError, match=refused):
        resolve_address(closed)
    for bad in ("nohost", "host:", ":6379", "host:http", "host:70000"):
        with pytest.raises(RayConnectionError, match=rf"--address '{bad}': expected HOST:PORT"):
            resolve_address(bad)
    # RAY_ADDRESS stands in for --address, and says so.
    isolated.setenv("RAY_ADDRESS", listening)
    assert resolve_address(None) == RayConnection(listening, "RAY_ADDRESS")
    assert resolve_address("local") == RayConnection(None, "local")  # --address wins
    isolated.setenv("RAY_ADDRESS", closed)
    with pytest.raises(RayConnectionError, match=rf"RAY_ADDRESS={closed}: nothing answers .* unset RAY_ADDRESS"):
        resolve_address(None)
    isolated.delenv("RAY_ADDRESS")
    # The cluster `ray start` recorded is joined when it answers; a record it outlived starts a local one.
    isolated.setattr(ray_connect, "_recorded_cluster", lambda: listening)
    assert resolve_address(None) == RayConnection(listening, "ray start")
    isolated.setattr(ray_connect, "_recorded_cluster", lambda: closed)
    assert resolve_address(None) == RayConnection(None, "local")
    assert issubclass(RayConnectionError, ConfigError)  # the commands' exit 2, one line


def test_ray_start_s_record_is_read_where_ray_keeps_it(monkeypatch, tmp_path, listening):
    """The record is Ray's own (``$RAY_TMPDIR/ray/ray_current_cluster``, what ``ray.init()`` reads)."""
    pytest.importorskip("ray")
    monkeypatch.setenv("RAY_TMPDIR", str(tmp_path))
    assert ray_connect._recorded_cluster() is None
    (tmp_path / "ray").mkdir()
    (tmp_path / "ray" / "ray_current_cluster").write_text(listening + "\n")
    assert ray_connect._recorded_cluster() == listening


def test_cpus_go_only_to_an_instance_started_here(isolated, listening):
    """ray.init(num_cpus=N) refuses to join a running cluster: the count is passed only to a local
    instance, which is a new one ("local") even where Ray would find another."""
    ray = pytest.importorskip("ray")
    calls = []
    isolated.setattr(ray, "init", lambda **kwargs: calls.append(kwargs))
    assert connect_ray(None, num_cpus=3).local
    assert calls[-1] == {"address": "local", "num_cpus": 3, "include_dashboard": False, "log_to_driver": False}
    isolated.setenv("RAY_ADDRESS", listening)
    assert connect_ray(None, num_cpus=3) == RayConnection(listening, "RAY_ADDRESS")
    assert calls[-1] == {"address": listening, "log_to_driver": False}
    assert connect_ray(listening, num_cpus=3).address == listening and "num_cpus" not in calls[-1]
    # The cluster `ray start` recorded is joined as ray.init() joins it (its token authentication too).
    isolated.delenv("RAY_ADDRESS")
    isolated.setattr(ray_connect, "_recorded_cluster", lambda: listening)
    assert connect_ray(None, num_cpus=3) == RayConnection(listening, "ray start")
    assert calls[-1] == {"address": None, "log_to_driver": False}

    def refuses(**kwargs):
        raise ConnectionError("Could not read 'session_name' from GCS\nand more")

    isolated.setattr(ray, "init", refuses)
    isolated.delenv("RAY_AUTH_MODE", raising=False)
    with pytest.raises(RayConnectionError, match=rf"--address {listening}: Ray could not join .*GCS\); .*=token$"):
        connect_ray(listening, num_cpus=3)
    isolated.setenv("RAY_AUTH_MODE", "token")
    with pytest.raises(RayConnectionError, match=r"from GCS\)$"):
        connect_ray(listening, num_cpus=3)


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """``nbs ARGS`` in a process of its own: one that waits on Ray fails the test by its timeout, not hangs it."""
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env["PYTHONPATH"] = str(ROOT)
    command = [sys.executable, "-m", "train.cli", *args]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=90)


def test_train_refuses_an_address_where_nothing_listens(tmp_path, closed):
    """`nbs train --backend ray --address 127.0.0.1:PORT` with nothing there once waited on ray.init
    without a word; now it exits 2 at once, naming the address, before the run folder is made."""
    pytest.importorskip("sb3_contrib")
    pytest.importorskip("ray")
    started = time.monotonic()
    p = _cli("train", "--backend", "ray", "--address", closed, "--out", "run", "--quiet", cwd=tmp_path)
    assert p.returncode == 2, p.stderr
    assert f"--address {closed}: nothing answers at {closed}" in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert time.monotonic() - started < 60 and not (tmp_path / "run").exists()


def test_compare_refuses_an_address_where_nothing_listens(tmp_path, closed):
    """The same for `nbs compare --backend ray` (train/compare.py joins Ray through connect_ray)."""
    pytest.importorskip("ray")
    p = _cli(
        "compare", "--scenes", "l_room", "--policies", "random", "--backend", "ray", "--address", closed,
        "--out", "grid", "--quiet", cwd=tmp_path,
    )  # fmt: skip
    assert p.returncode == 2, p.stderr
    assert f"--address {closed}: nothing answers at {closed}" in p.stderr and "Traceback" not in p.stderr


#: A cluster of its own for the test: one CPU, the smallest object store Ray takes, its own folder.
_HEAD = """
import sys, ray
ray.init(num_cpus=1, include_dashboard=False, object_store_memory=80 * 2**20, _temp_dir=sys.argv[1])
print(ray.get_runtime_context().gcs_address, flush=True)
sys.stdin.read()
ray.shutdown()
"""
#: A command joining it as nbs does, asked for two CPUs as a local instance would be.
_JOIN = """
import ray
from train.ray_connect import connect_ray
connection = connect_ray(None, num_cpus=2)
print(connection.source, int(ray.cluster_resources()["CPU"]), flush=True)
ray.shutdown()
"""


@pytest.mark.expensive
def test_a_running_cluster_is_joined_not_asked_for_cpus():
    """With a cluster running (here one started for the test, RAY_ADDRESS naming it), ray.init(num_cpus=2)
    raised "When connecting to an existing cluster, num_cpus and num_gpus must not be provided"; the
    command joins it and runs on its one CPU."""
    pytest.importorskip("ray")
    # Short: Ray's socket paths under it must stay within the 107 bytes a Unix socket's name may have.
    folder = tempfile.mkdtemp(prefix="nbsray", dir="/tmp")
    # Without token authentication, which Ray turns on for a named address only when asked (RAY_AUTH_MODE).
    env = {**os.environ, "PYTHONPATH": str(ROOT), "RAY_TMPDIR": folder, "RAY_AUTH_MODE": "disabled"}
    env.pop("RAY_ADDRESS", None)
    head = subprocess.Popen(
        [sys.executable, "-c", _HEAD, folder], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        address = head.stdout.readline().strip()
        assert address, "the test's cluster did not start"
        join = subprocess.run(
            [sys.executable, "-c", _JOIN], env={**env, "RAY_ADDRESS": address}, capture_output=True, text=True,
            timeout=300,
        )  # fmt: skip
        assert join.returncode == 0, join.stderr
        assert join.stdout.split() == ["RAY_ADDRESS", "1"], join.stdout
    finally:
        head.stdin.close()  # the head shuts its cluster down and exits
        try:
            head.wait(timeout=120)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait()
        shutil.rmtree(folder, ignore_errors=True)
