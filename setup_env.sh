# Sourced by run_chapter.sh and run_tests.sh: make .venv (Python 3.12) with the project installed.
# Idempotent: a second call only checks that the install is still there. It recovers by itself from a
# set-up that was stopped: a .venv without pip (killed while `python -m venv` ran) is completed in place,
# and a stamped .venv missing a locked package (python -m tools.lock --missing) is installed again.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
# A .venv this set-up cannot use as it is (a file, a dangling link, a venv of another Python) is the user's:
# one line saying what to do, exit 2, nothing in it touched (venv would fail on it, or pip after the download).
venv_problem() {
    if [ -L .venv ] && [ ! -e .venv ]; then
        echo "error: .venv is a link to $(readlink .venv), which does not exist; remove the link (rm .venv) or point it at a Python 3.12 venv, and run again"
    elif [ -e .venv ] && [ ! -d .venv ]; then
        echo "error: .venv is a file, not a folder; move it aside (mv .venv .venv.bak) and run again"
    elif [ -f .venv/pyvenv.cfg ]; then
        local made
        made=$(sed -n 's/^version\(_info\)\? *= *\([0-9]*\.[0-9]*\).*/\2/p' .venv/pyvenv.cfg | head -n 1)
        if [ -n "$made" ] && [ "$made" != 3.12 ]; then
            echo "error: .venv was made with Python $made; requirements.lock is for Python 3.12; move it aside (mv .venv .venv-$made) and run again"
        fi
    fi
}
problem=$(venv_problem)
if [ -n "$problem" ]; then
    echo "$problem" >&2
    exit 2
fi
if ! .venv/bin/python -c 'import pip' >/dev/null 2>&1; then
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
    # a new .venv, or one a stopped set-up left without pip: venv completes an existing folder in place
    [ -e .venv ] && echo "repairing .venv (no working pip in it: a set-up was stopped while making it)..."
    "$PY" -m venv .venv
fi
# the stamp keys on the lock: a new requirements.lock (bash tools/lock.sh) reinstalls, and so does a
# locked package gone missing since (a set-up stopped mid-install, a package removed by hand)
stamp=.venv/.installed-$(sha256sum requirements.lock | cut -c1-16)
if [ -f "$stamp" ] && ! gone=$(.venv/bin/python -m tools.lock --missing 2>&1); then
    echo "reinstalling .venv from requirements.lock: $(echo "$gone" | head -n 1)"
    rm -f "$stamp"
fi
if [ ! -f "$stamp" ]; then
    echo "setting up .venv from requirements.lock (first run downloads lerobot and torch, a few GB, a few minutes)..."
    # exactly the lock: every package the set-up installs (pyproject.toml's dependencies + dev, ray and
    # train extras: the tests run the data engine on a real local Ray, LeRobot's own trainer and its PushT,
    # gym-pusht), pinned with its hashes; the chapter itself runs from this folder. uv when present
    # (faster), pip otherwise.
    if command -v uv >/dev/null 2>&1; then
        uv pip sync -q --python .venv/bin/python requirements.lock
    else
        .venv/bin/python -m pip install -q --require-hashes --no-deps -r requirements.lock
    fi
    rm -f .venv/.installed-*
    touch "$stamp"
fi
