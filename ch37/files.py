"""Writing results: whole files or nothing, stable JSON, and no leftovers.

write_atomic is the one way this project writes a file. In a folder claimed by ch37.outputs (a
run's --out), it also refuses to overwrite a file the program did not write there and records
every file it writes, so the next run knows which files are its own.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from pathlib import Path

# folder (resolved) -> its owner (ch37.outputs.Claim): before(path, digest) checks and records the
# write about to happen, after(path, digest) confirms it. Set by ch37.outputs.claim only.
CLAIMED: dict[Path, object] = {}
# what a crashed run can leave beside its target: .NAME.tmp-PID, .NAME.partial-PID, .NAME.old-PID
LEFTOVER = re.compile(r"^\..+\.(tmp|partial|old)-(\d+)$")


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def place(tmp: Path, path: Path) -> Path:
    """Rename the finished file `tmp` onto `path` (same folder), with the ownership check and record of
    a claimed folder. `tmp` is removed if anything goes wrong."""
    path = Path(path)
    owner = CLAIMED.get(path.parent.resolve())
    try:
        digest = sha256_file(tmp) if owner else None
        if owner:
            owner.before(path, digest)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    if owner:
        owner.after(path, digest)
    return path


def write_atomic(path: Path, data: str | bytes) -> Path:
    """Write `data` to `path` through a temp file in the same folder and a rename: a reader sees the
    old file or the new one, never half of one. Creates the parent folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return place(tmp, path)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


def sweep_leftovers(folder: Path) -> list[str]:
    """Remove what a killed run of this project left in `folder`: temp files and half-written sets named
    .NAME.tmp-PID / .NAME.partial-PID / .NAME.old-PID whose process is gone. Returns their names."""
    removed = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for p in entries:
        m = LEFTOVER.match(p.name)
        if not m or int(m.group(2)) == os.getpid() or pid_alive(int(m.group(2))):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p.name)
    return removed


def dump_json(obj) -> str:
    return json.dumps(obj, sort_keys=True, indent=1) + "\n"


def round_floats(obj, digits: int = 4):
    """Round every float in a nested structure so metrics.json is stable and readable."""
    if isinstance(obj, float):
        return round(obj, digits)
    if isinstance(obj, dict):
        return {k: round_floats(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [round_floats(v, digits) for v in obj]
    return obj
