#!/usr/bin/env bash
# Refresh requirements.lock, the hashed lock that setup_env.sh installs (issue 32), on purpose.
#
#     bash tools/lock.sh              re-resolve after a pyproject.toml change, keeping every pin it can
#     bash tools/lock.sh --upgrade    move every package to the newest version pyproject.toml admits
#     bash tools/lock.sh -P torch     move one package (uv's --upgrade-package), keep the rest
#
# Needs uv (`pip install uv`, any venv). The lock covers pyproject.toml's dependencies plus its dev, ray
# and train extras, for Python 3.12 on every platform (--universal: markers, hashes of every wheel), from
# PyPI (the CUDA torch build on Linux), less what tools/lock-excludes.txt names (opencv-python: one cv2;
# dm-control: gym-aloha's env code, which we never run), with tools/lock-overrides.txt's requirements in
# place of a locked package's own (gym-aloha's mujoco<3.9: its model files run on our mujoco 4).
# uv keeps the pins of the lock it overwrites unless told to move them. A new lock changes what produced
# the published numbers: re-run them (docs/instructors.md, "The versions behind the numbers").
set -euo pipefail
cd "$(dirname "$0")/.."
UV=$(command -v uv || true)
if [ -z "$UV" ]; then
    echo "error: uv not found; install it with: python3 -m pip install uv" >&2
    exit 2
fi
"$UV" pip compile pyproject.toml --extra dev --extra ray --extra train \
    --python-version 3.12 --universal --generate-hashes \
    --custom-compile-command "bash tools/lock.sh" --excludes tools/lock-excludes.txt \
    --overrides tools/lock-overrides.txt \
    -o requirements.lock "$@"
