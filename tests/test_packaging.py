"""What a plain `pip install .` gets: every package and subpackage, and the data files they read."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TOP = ("scenes", "nbs_env", "policies", "train")


def test_the_wheel_holds_every_package_and_its_data(tmp_path):
    # A clean copy: a stale build/ folder would hide packages the configuration leaves out.
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    for top in TOP:
        shutil.copytree(ROOT / top, src / top, ignore=shutil.ignore_patterns("__pycache__"))
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(src)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    (wheel,) = (tmp_path / "dist").glob("nbs_env-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    packages = [p.parent.relative_to(ROOT).as_posix() for top in TOP for p in (ROOT / top).rglob("__init__.py")]
    missing = [p for p in packages if f"{p}/__init__.py" not in names]
    assert not missing, f"packages left out of the wheel: {missing}"
    for data in (
        "scenes/data/five_rooms.json",
        "nbs_env/perception/data/se_svm.json",
        "policies/data/ppo_reference/policy.json",
        "policies/data/ppo_reference/policy.pt",
        "policies/data/ppo_reference/learning_curve.png",
    ):
        assert data in names, data
    # Every corpus file the project ships (local-only entries are read from elsewhere).
    import json

    entries = json.loads((ROOT / "scenes" / "data" / "corpus" / "corpus.json").read_text())["entries"]
    shipped = {f"scenes/data/corpus/{e['file']}" for e in entries if e.get("file") and not e.get("local")}
    assert shipped and not shipped - names, sorted(shipped - names)
