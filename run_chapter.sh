#!/usr/bin/env bash
# Set up .venv if needed, then run the chapter. Extra arguments go to scale_data.py.
set -euo pipefail
source "$(dirname "$0")/setup_env.sh"
exec .venv/bin/python scale_data.py "$@"
