#!/usr/bin/env bash
# Set up .venv if needed (from requirements.lock), then lint and format-check with ruff and run the test
# suite (fast subset; `-m slow` for the full-size checks). Extra arguments go to pytest. Every skip
# prints its reason (-rs in pyproject.toml); on a root Linux machine with Chromium and a checkout others
# can read, none is reached.
set -euo pipefail

# Every check CI runs needs Chromium: tests/test_poster.py's browser checks (the same names that test
# looks for), which no Python lock can install. On a root machine with apt-get (a container, CI) this
# installs it (Debian's package), saying so in one line; elsewhere it is one `error:` line and exit 2.
# $1: the user id (default: this shell's), an argument so that tests can ask for either branch.
ensure_chromium() {
    local uid=${1:-$EUID}
    have_chromium() { command -v chromium >/dev/null || command -v chromium-browser >/dev/null || command -v google-chrome >/dev/null; }
    have_chromium && return 0
    if [ "$uid" = 0 ] && command -v apt-get >/dev/null; then
        echo "installing Chromium for tests/test_poster.py's browser checks: apt-get install -y chromium"
        if { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } >/dev/null && have_chromium; then
            return 0
        fi
        echo "error: apt-get install -y chromium did not install Chromium (tests/test_poster.py's browser checks need it); install it and run again" >&2
        return 2
    fi
    local sudo=$([ "$uid" = 0 ] || echo "sudo ")  # root has no sudo to call
    echo "error: Chromium is missing (tests/test_poster.py's browser checks need it); install it with: ${sudo}apt-get install -y chromium" >&2
    return 2
}

main() {
    ensure_chromium || exit 2
    source "$(dirname "$0")/setup_env.sh"
    .venv/bin/ruff check .
    .venv/bin/ruff format --check .
    set +e
    .venv/bin/python -m pytest -q "$@"
    rc=$?
    set -e
    if [ "$rc" -eq 5 ]; then echo "error: pytest collected no tests" >&2; exit 1; fi
    exit "$rc"
}

if [ "${BASH_SOURCE[0]}" = "$0" ]; then  # run, not sourced (tests source it for ensure_chromium)
    main "$@"
fi
