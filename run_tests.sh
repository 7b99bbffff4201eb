#!/usr/bin/env bash
# Set up .venv if needed, then run the test suite (fast subset; `-m slow` for the full-size checks).
set -euo pipefail
source "$(dirname "$0")/setup_env.sh"
set +e
.venv/bin/python -m pytest -q "$@"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then echo "error: pytest collected no tests" >&2; exit 1; fi
exit "$rc"
