"""The contract for bad input: one clear line on stderr and exit 2, never a traceback."""

from __future__ import annotations

import sys


class DataError(Exception):
    """A problem with a demo folder or an output folder that the user must fix (printed as one line)."""


def fail(msg: str, code: int = 2):
    """Print `error: msg` on stderr and exit with `code`."""
    print(f"error: {msg}", file=sys.stderr)
    sys.exit(code)
