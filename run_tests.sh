#!/usr/bin/env bash
# Set up .venv if needed, then lint and format-check with ruff and run the test suite
# (fast subset; `-m slow` for the full-size checks). Extra arguments go to pytest.
set -euo pipefail
source "$(dirname "$0")/setup_env.sh"
.venv/bin/ruff check .
.venv/bin/ruff format --check .
set +e
.venv/bin/python -m pytest -q "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then echo "error: pytest collected no tests" >&2; exit 1; fi
exit "$rc"
