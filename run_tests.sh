#!/usr/bin/env bash
# Set up .venv if needed (from requirements.lock), then lint and format-check with ruff and run the test
# suite (fast subset; `-m slow` for the full-size checks). Extra arguments go to pytest. Every skip
# prints its reason (-rs in pyproject.toml); on a root Linux machine with Chromium and a checkout others
# can read, none is reached.
set -euo pipefail
# Every check CI runs, or one line naming what is missing: tests/test_poster.py's browser checks need
# Chromium (the same names that test looks for), which no Python lock can install.
if ! command -v chromium >/dev/null && ! command -v chromium-browser >/dev/null && ! command -v google-chrome >/dev/null; then
    sudo=$([ "${EUID:-0}" = 0 ] || echo "sudo ")  # root (CI, a container) has no sudo to call
    echo "error: Chromium is missing (tests/test_poster.py's browser checks need it); install it with: ${sudo}apt-get install -y chromium" >&2
    exit 2
fi
source "$(dirname "$0")/setup_env.sh"
.venv/bin/ruff check .
.venv/bin/ruff format --check .
set +e
.venv/bin/python -m pytest -q "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then echo "error: pytest collected no tests" >&2; exit 1; fi
exit "$rc"
