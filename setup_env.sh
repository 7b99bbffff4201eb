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
stamp=.venv/.installed-$(sha256sum pyproject.toml | cut -c1-16)
if [ ! -f "$stamp" ]; then
    echo "setting up .venv (first run downloads lerobot and torch, a few GB, a few minutes)..."
    .venv/bin/python -m pip install -q --upgrade pip
    # the dependencies of pyproject.toml (runtime + dev + ray + train: the tests run the data engine
    # on a real local Ray and LeRobot's own trainer); the chapter itself runs from this folder
    mapfile -t deps < <(.venv/bin/python -c 'import tomllib; p = tomllib.load(open("pyproject.toml", "rb"))["project"]; x = p["optional-dependencies"]; print("\n".join(p["dependencies"] + x["dev"] + x["ray"] + x["train"]))')
    .venv/bin/python -m pip install -q "${deps[@]}"
    touch "$stamp"
fi
