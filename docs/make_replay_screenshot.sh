#!/usr/bin/env bash
# Regenerates docs/img/replay.png: a greedy scan of five_rooms (default preset, seed 0) recorded with
# nbs_env.replay.RunRecorder and shown in rerun's native viewer, on a virtual X server (Xvfb) and
# rendered in software by Mesa's lavapipe Vulkan driver: no GPU or screen needed.
#
# Needs the project's venv with rerun-sdk (pip install -e ".[viz]") and, from Debian/Ubuntu, xvfb,
# xauth, mesa-vulkan-drivers and libvulkan1, which this script apt-installs (as root) when Xvfb or the
# lavapipe driver is missing.
#
# Usage: docs/make_replay_screenshot.sh [SCANS] [RECORDING]
#   SCANS      stop after the step that reaches this many scans (default 14)
#   RECORDING  where the .rrd goes (default: a temporary file); `nbs view RECORDING` replays it.
set -euo pipefail
cd "$(dirname "$0")/.."
SCANS=${1:-14}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
RRD=${2:-$WORK/five_rooms.rrd}

if ! command -v Xvfb >/dev/null || [ ! -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq xvfb xauth mesa-vulkan-drivers libvulkan1
fi

# The episode stops while it is still open: the viewer opens at the last scan, and a finished episode
# has no candidates left to show.
python - "$SCANS" "$RRD" <<'PY'
import sys

from nbs_env.env import NBSEnv
from nbs_env.replay import RunRecorder
from nbs_env.settings import make_config
from policies import make_policy
from train.episode import config_for

scans, path = int(sys.argv[1]), sys.argv[2]
policy = make_policy("greedy", 0)
env = NBSEnv(config_for(make_config("default", scene="five_rooms"), policy))
with RunRecorder(path, "five_rooms") as recorder:
    obs, info = env.reset(seed=0)
    policy.reset()
    recorder.log_step(env)
    while info["scans"] < scans and env.storey.open:
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        recorder.log_step(env)
        if terminated or truncated:
            break
print(f"recorded {info['scans']} scans, room {info['room'] + 1}, SE sensed {info['structure_sensed_pct']:.1f}%: {path}")
PY

RERUN=$(python -c "import os, rerun_cli; print(os.path.join(os.path.dirname(rerun_cli.__file__), 'rerun'))")
# A fresh home: no viewer state or blueprint remembered from an earlier session (and analytics stay in
# their first, silent session).
export HOME=$WORK/home XDG_RUNTIME_DIR=$WORK/run
mkdir -p "$HOME" "$XDG_RUNTIME_DIR" && chmod 700 "$XDG_RUNTIME_DIR"
# --screenshot-to: the viewer loads the recording, draws it, saves the window and quits.
xvfb-run -a -s "-screen 0 1600x1000x24" env WGPU_BACKEND=vulkan \
    "$RERUN" --screenshot-to "$WORK/replay.png" --window-size 1600x1000 "$RRD"
# The viewer saves at twice the window's size; 1200 pixels wide in 256 colours is enough for the
# README (about a quarter of the full-colour file).
python -c "
from PIL import Image
image = Image.open('$WORK/replay.png').convert('RGB')
image = image.resize((1200, round(1200 * image.height / image.width)), Image.LANCZOS)
image.quantize(256, dither=Image.Dither.NONE).save('docs/img/replay.png', optimize=True)
"
echo "wrote docs/img/replay.png"
