"""Ownership of folders: the stamp this project writes into every set it makes.

A folder is deleted or rewritten only when its stamp says this project made it; anything else
in the way is refused with one line.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from ch37.errors import DataError

STAMP_NAME = "scale_data_stamp.json"  # written by this project into every set it makes
MADE_BY = "ch3.7-scale-data"  # the stamp's "made_by": only a set carrying it may ever be deleted


def holds_data(path: Path) -> bool:
    path = Path(path)
    return path.exists() and (not path.is_dir() or any(path.iterdir()))


def read_stamp(root: Path) -> dict | None:
    try:
        return json.loads((Path(root) / STAMP_NAME).read_text())
    except (OSError, json.JSONDecodeError):
        return None


def stamp_text(stamp: dict) -> str:
    return json.dumps(stamp, sort_keys=True, indent=1) + "\n"


def replace_own_dir(path: Path) -> None:
    """Clear `path` for rewriting if this project made it; refuse if it holds anything else."""
    if not holds_data(path):
        return
    stamp = read_stamp(path)
    if stamp is None or stamp.get("made_by") != MADE_BY:
        raise DataError(f"{path} holds data this program did not make; move it or pass another --out")
    shutil.rmtree(path)
