"""Ownership, file by file: the stamp this project writes into every folder it fills.

A stamp (scale_data_stamp.json) says who made the folder and lists every file it wrote there with
its sha256 ("files"). The program deletes or overwrites only files its stamp lists; a folder
without our stamp, or holding files the stamp does not list (a user's notes beside a demo set), is
refused with one line and left exactly as it was.
"""

from __future__ import annotations

import fnmatch
import json
import os
from pathlib import Path

from ch37.errors import DataError
from ch37.files import sha256_file

STAMP_NAME = "scale_data_stamp.json"  # written by this project into every folder it fills
MADE_BY = "ch3.7-scale-data"  # the stamp's "made_by": only files under such a stamp may ever be deleted
LOCK_NAME = ".scale_data.lock"  # ch37.outputs' lock file, ours too
# Stamps written before stamps listed their files: the LeRobot v3 layout is what such a set holds.
LEGACY_LAYOUT = (
    "meta/info.json",
    "meta/stats.json",
    "meta/tasks.parquet",
    "meta/episodes/chunk-*/file-*.parquet",
    "data/chunk-*/file-*.parquet",
    "videos/*/chunk-*/file-*.mp4",
)


def holds_data(path: Path) -> bool:
    path = Path(path)
    return path.exists() and (not path.is_dir() or any(path.iterdir()))


def read_stamp(root: Path) -> dict | None:
    try:
        stamp = json.loads((Path(root) / STAMP_NAME).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return stamp if isinstance(stamp, dict) else None


def is_ours(stamp: dict | None) -> bool:
    return stamp is not None and stamp.get("made_by") == MADE_BY


def stamp_text(stamp: dict) -> str:
    return json.dumps(stamp, sort_keys=True, indent=1) + "\n"


def file_list(root: Path) -> list[str]:
    """Every file under `root` (relative, sorted), without our stamp and lock."""
    root = Path(root)
    out = []
    for dirpath, _, names in os.walk(root):
        for name in names:
            rel = (Path(dirpath) / name).relative_to(root).as_posix()
            if rel not in (STAMP_NAME, LOCK_NAME):
                out.append(rel)
    return sorted(out)


def digests(root: Path) -> dict[str, str]:
    """{relative path: sha256} of every file under `root`: the "files" entry of a stamp."""
    return {rel: sha256_file(Path(root) / rel) for rel in file_list(root)}


def owned(root: Path, stamp: dict) -> set[str]:
    """The files under `root` that our stamp says we wrote."""
    if isinstance(stamp.get("files"), dict):
        return set(stamp["files"])
    return {rel for rel in file_list(root) if any(fnmatch.fnmatch(rel, pat) for pat in LEGACY_LAYOUT)}


def foreign_files(root: Path, stamp: dict | None) -> list[str]:
    """Files under `root` this program did not write (all of them when the stamp is not ours)."""
    mine = owned(root, stamp) if is_ours(stamp) else set()
    return [rel for rel in file_list(root) if rel not in mine]


def changed_files(root: Path, stamp: dict) -> list[str]:
    """Files our stamp lists that are missing or whose bytes differ from what was written."""
    bad = []
    for rel, digest in sorted((stamp.get("files") or {}).items()):
        p = Path(root) / rel
        try:
            if sha256_file(p) != digest:
                bad.append(rel)
        except OSError:
            bad.append(rel)
    return bad


def _names(files: list[str], n: int = 3) -> str:
    return ", ".join(files[:n]) + (f" and {len(files) - n} more" if len(files) > n else "")


def check_replaceable(path: Path) -> None:
    """DataError unless `path` is absent, empty, or holds only files our stamp lists."""
    path = Path(path)
    if not holds_data(path):
        return
    if not path.is_dir():
        raise DataError(f"{path} is a file, not a folder this program made; move it or pass another --out")
    stamp = read_stamp(path)
    if not is_ours(stamp):
        raise DataError(f"{path} holds data this program did not make; move it or pass another --out")
    foreign = foreign_files(path, stamp)
    if foreign:
        raise DataError(
            f"{path} must be rebuilt but holds files this program did not write ({_names(foreign)}); "
            "move them elsewhere and run the same command again (nothing was changed)"
        )


def replace_own_dir(path: Path) -> None:
    """Clear `path` for rewriting if every file in it is one this program wrote; refuse otherwise."""
    path = Path(path)
    check_replaceable(path)
    if not path.exists():
        return
    stamp = read_stamp(path)
    for rel in sorted(owned(path, stamp), reverse=True):
        (path / rel).unlink(missing_ok=True)
    (path / STAMP_NAME).unlink()  # last: a half-cleared folder still says whose files it held
    for dirpath, _, _ in sorted(os.walk(path), key=lambda t: -len(t[0])):  # deepest first
        try:
            os.rmdir(dirpath)  # only folders left empty; a folder with anything in it stays
        except OSError:
            pass
