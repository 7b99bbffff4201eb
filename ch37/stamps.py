"""Ownership, file by file: the stamp this project writes into every folder it fills.

A stamp (scale_data_stamp.json, written with ch37.files.dump_json) says who made the folder and
lists every file it wrote there with its sha256 ("files"). The program deletes or overwrites only
files its stamp lists; a folder without our stamp, or holding files the stamp does not list (a
user's notes beside a demo set), is refused with one line and left exactly as it was.
read_json is the project's one JSON reader.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from pathlib import Path

from ch37.errors import DataError

STAMP_NAME = "scale_data_stamp.json"  # written by this project into every folder it fills
MADE_BY = "ch3.7-scale-data"  # the stamp's "made_by": only files under such a stamp may ever be deleted
LOCK_NAME = ".scale_data.lock"  # ch37.files.lock's file: the pid of the run writing the folder


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_json(path: Path):
    """The JSON value in `path`, or None when it is missing or not JSON."""
    try:
        return json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None


def holds_data(path: Path) -> bool:
    """Whether `path` is a file or a folder holding anything besides our lock file."""
    path = Path(path)
    return path.exists() and (not path.is_dir() or any(p.name != LOCK_NAME for p in path.iterdir()))


def read_stamp(root: Path) -> dict | None:
    stamp = read_json(Path(root) / STAMP_NAME)
    return stamp if isinstance(stamp, dict) else None


def is_ours(stamp: dict | None) -> bool:
    return stamp is not None and stamp.get("made_by") == MADE_BY


def file_list(root: Path) -> list[str]:
    """Every file under `root` (relative, sorted), without our stamp and lock."""
    found = ((Path(d) / n).relative_to(root).as_posix() for d, _, names in os.walk(root) for n in names)
    return sorted(rel for rel in found if rel not in (STAMP_NAME, LOCK_NAME))


def digests(root: Path) -> dict[str, str]:
    """{relative path: sha256} of every file under `root`: the "files" entry of a stamp."""
    return {rel: sha256_file(Path(root) / rel) for rel in file_list(root)}


def owned(stamp: dict | None) -> set[str]:
    """The files (relative paths) our stamp says we wrote; none when the stamp is not ours."""
    listed = stamp.get("files") if is_ours(stamp) else None
    return set(listed) if isinstance(listed, dict) else set()


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


def names(files: list[str], n: int = 3) -> str:
    return ", ".join(files[:n]) + (f" and {len(files) - n} more" if len(files) > n else "")


def check_ours(path: Path, kind: str | None = None) -> dict | None:
    """None if `path` is absent or empty, else its stamp; DataError unless it is a folder under our
    stamp (of `kind`, when given)."""
    path = Path(path)
    if not holds_data(path):
        return None
    stamp = read_stamp(path) if path.is_dir() else None
    if not is_ours(stamp) or kind not in (None, stamp.get("kind")):
        raise DataError(f"{path} holds data this program did not make; move it or pass another --out")
    return stamp


def check_replaceable(path: Path) -> None:
    """DataError unless `path` is absent, empty, or holds only files our stamp lists."""
    stamp = check_ours(path)
    mine = owned(stamp)  # the files not among them are a user's
    if stamp and (foreign := [rel for rel in file_list(path) if rel not in mine]):
        raise DataError(
            f"{path} must be rebuilt but holds files this program did not write ({names(foreign)}); "
            "move them elsewhere and run the same command again (nothing was changed)"
        )


def replace_own_dir(path: Path) -> None:
    """Clear `path` for rewriting if every file in it is one this program wrote; refuse otherwise."""
    path = Path(path)
    check_replaceable(path)
    if not holds_data(path):
        return
    for rel in sorted(owned(read_stamp(path)), reverse=True):
        (path / rel).unlink(missing_ok=True)
    (path / STAMP_NAME).unlink()  # last: a half-cleared folder still says whose files it held
    for dirpath, _, _ in sorted(os.walk(path), key=lambda t: -len(t[0])):  # deepest first
        with contextlib.suppress(OSError):  # only folders left empty; a folder with anything in it stays
            os.rmdir(dirpath)
