# Sourced by run_chapter.sh and run_tests.sh: make .venv (Python 3.12) with the project installed.
# Idempotent: a second call only checks that the install is still there.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
if [ ! -x .venv/bin/python ]; then
    PY=""
    for cand in python3.12 "$HOME/.pyenv/versions/3.12.1/bin/python" python3; do
        if command -v "$cand" >/dev/null 2>&1 && "$cand" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' 2>/dev/null; then
            PY="$cand"; break
        fi
    done
    if [ -z "$PY" ]; then
        echo "error: Python 3.12 not found; install it (pyenv install 3.12) and run again" >&2
        exit 2
    fi
    "$PY" -m venv .venv
fi
# the stamp keys on the lock: a new requirements.lock (bash tools/lock.sh) reinstalls, nothing else does
stamp=.venv/.installed-$(sha256sum requirements.lock | cut -c1-16)
if [ ! -f "$stamp" ]; then
    echo "setting up .venv from requirements.lock (first run downloads lerobot and torch, a few GB, a few minutes)..."
    # exactly the lock: every package the set-up installs (pyproject.toml's dependencies + dev, ray and
    # train extras: the tests run the data engine on a real local Ray and LeRobot's own trainer), pinned
    # with its hashes; the chapter itself runs from this folder. uv when present (faster), pip otherwise.
    if command -v uv >/dev/null 2>&1; then
        uv pip sync -q --python .venv/bin/python requirements.lock
    else
        .venv/bin/python -m pip install -q --require-hashes --no-deps -r requirements.lock
    fi
    rm -f .venv/.installed-*
    touch "$stamp"
fi
