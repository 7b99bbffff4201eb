"""Ownership: output folders claimed, locked and owned file by file; whole files or none.

The project's one ownership model. A stamp (STAMP_NAME, written with dump_json) says who made a
folder and lists every file it wrote there with its sha256 ("files"); the program deletes or
overwrites only files its stamp lists, and a folder without our stamp, or holding files the stamp
does not list (a user's notes beside a demo set), is refused with one line and left as it was.

write_atomic is the one way this project writes a file, dump_json its one JSON writer (stable:
sorted keys, one-space indent, a final newline) and read_json its one JSON reader. A run takes its
--out with claim() before any work and passes the Claim it gets to every write into that folder
(write_atomic(path, data, claim=c)): the write then refuses to overwrite a file the program did not
write and records the file, with its sha256, in the folder's stamp. publish_dir builds a folder
beside its target (our stamp inside from its first moment) and renames it into place whole.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
from pathlib import Path

from ch37.errors import DataError

try:
    import fcntl
except ImportError:  # Windows: no advisory locks here; runs on one folder must then be kept apart by hand
    fcntl = None

# What a crashed run of this project can leave beside its target: .NAME.ch37-tmp-PID (a file) and
# .NAME.ch37-partial-PID (a folder holding our stamp from its first moment, see partial_dir). The
# "ch37-" token is ours: a user's .NAME.tmp-N or .NAME.old-N never matches.
TOKEN = "ch37"
LEFTOVER = re.compile(rf"^\.(.+)\.{TOKEN}-(tmp|partial)-(\d+)$")
_HELD: dict[Path, int] = {}  # folder (resolved) -> the descriptor of its lock file, held by this process


STAMP_NAME = "scale_data_stamp.json"  # written by this project into every folder it fills
MADE_BY = "ch3.7-scale-data"  # the stamp's "made_by": only files under such a stamp may ever be deleted
LOCK_NAME = ".scale_data.lock"  # ch37.ownership.lock's file: the pid of the run writing the folder


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


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


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


def place(tmp: Path, path: Path, claim: Claim | None = None) -> Path:
    """Rename the finished file `tmp` onto `path` (same folder); when `path` lies directly in the folder
    of `claim`, only over a file of ours, and recorded in its stamp. `tmp` is removed if anything
    goes wrong."""
    path = Path(path)
    owner = claim if claim is not None and claim.out.resolve() == path.parent.resolve() else None
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


def temp_path(path: Path, kind: str = "tmp") -> Path:
    """Where this process builds `path` (a file: kind "tmp"; a folder: "partial"), beside it."""
    path = Path(path)
    return path.with_name(f".{path.name}.{TOKEN}-{kind}-{os.getpid()}")


def partial_dir(path: Path) -> Path:
    """A new folder beside `path` to build it in, marked as ours (our stamp inside) before anything else
    is put there, so that sweep_leftovers can tell it from a user's folder of a similar name."""
    tmp = temp_path(path, "partial")
    if tmp.exists() or tmp.is_symlink():  # left by a crashed run that had this pid, if it is ours
        if not _ours_to_sweep(tmp):
            raise DataError(f"{tmp} is in the way and was not made by this program; move it and run again")
        _remove(tmp)
    tmp.mkdir(parents=True)
    (tmp / STAMP_NAME).write_text(dump_json({"made_by": MADE_BY, "kind": "partial"}))
    return tmp


@contextlib.contextmanager
def publish_dir(out: Path, stamp: dict):
    """Build the new folder `out` whole or not at all: yields a folder to fill (in a sibling partial
    folder marked as ours, partial_dir), then writes our stamp into it, listing every file with its
    sha256, and renames it onto `out`. `out` must not hold data; what a killed run left for `out` is
    removed here, and nothing else beside it. An interrupted build never leaves a half folder."""
    out = Path(out)
    if holds_data(out):
        raise DataError(f"{out} already holds data; pick another --out or remove it yourself")
    if problem := dangling(out):
        raise DataError(problem)
    # a link to an empty folder is written through, as every --out is (claim's mkdir follows it): the set
    # is built beside the folder it points to and renamed onto that folder, the link left as it is
    out = out.resolve() if out.is_symlink() else out
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_leftovers(out.parent, out.name)  # a killed run's partial `out` only: the parent is not ours
    work = partial_dir(out)  # .NAME.ch37-partial-PID, our stamp inside; the folder is built in work/set
    tmp = work / "set"
    try:
        yield tmp
        (tmp / STAMP_NAME).write_text(dump_json(dict(stamp, files=digests(tmp))))
        try:
            if out.exists():
                out.rmdir()  # empty directory (holds_data checked above)
            tmp.rename(out)
        except OSError as e:  # ENOTEMPTY/EEXIST: another process wrote `out` meanwhile
            if not holds_data(out):
                raise
            raise DataError(
                f"{out} was written by another run at the same time; run the same command again"
            ) from e
    finally:
        shutil.rmtree(work, ignore_errors=True)


def write_atomic(path: Path, data: str | bytes, claim: Claim | None = None) -> Path:
    """Write `data` to `path` through a temp file in the same folder and a rename: a reader sees the
    old file or the new one, never half of one. Creates the parent folder. With the `claim` on the
    folder (claim()), a file not ours is never overwritten and the write is recorded (place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path(path)
    try:
        tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return place(tmp, path, claim)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, another user's
        return True
    return True


def _ours_to_sweep(p: Path) -> bool:
    """A temp file of ours (the name says so), or a partial folder of ours: our stamp inside, or
    nothing at all (cut off between its mkdir and its stamp; removing it loses nothing)."""
    if p.is_symlink() or not p.is_dir():
        return not p.is_symlink() and LEFTOVER.match(p.name).group(2) == "tmp"
    return is_ours(read_stamp(p)) or not any(p.iterdir())


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        p.unlink(missing_ok=True)


def sweep_leftovers(folder: Path, name: str | None = None) -> list[str]:
    """Remove what a killed run of this project left in `folder` (of `name` only, when given): temp
    files .NAME.ch37-tmp-PID and partial folders .NAME.ch37-partial-PID holding our stamp, whose
    process is gone. Nothing else, whatever its name. Returns the names removed."""
    removed = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for p in entries:
        m = LEFTOVER.match(p.name)
        if not m or (name is not None and m.group(1) != name):
            continue
        pid = int(m.group(3))
        if pid == os.getpid() or pid_alive(pid) or not _ours_to_sweep(p):
            continue
        _remove(p)
        removed.append(p.name)
    return removed


def check_own_result(path: Path, kind: str, flag: str = "--out", beside=()) -> None:
    """DataError unless `path` is absent or a JSON result of this tool (its "kind" is `kind`): a tool's
    re-run may replace its own result file, never a file of the user's. `beside`: files the tool writes
    after that result (a figure of it), which hold no mark of their own: replaced only beside a result
    of this tool, never where there is none."""
    path = Path(path)
    if path.exists() or path.is_symlink():
        data = read_json(path) if path.is_file() and not path.is_symlink() else None
        if not isinstance(data, dict) or data.get("kind") != kind:
            raise DataError(f"{path} exists and was not written by this tool; pass another {flag}")
        return
    for other in map(Path, beside):
        if other.exists() or other.is_symlink():
            raise DataError(f"{other} exists and was not written by this tool; pass another {flag}")


def dangling(path: Path, flag: str = "--out") -> str | None:
    """One line when `path` is a link to nothing, else None. Nothing is made through such a link: the
    folder it names may be a typo, or on a disk not mounted now."""
    path = Path(path)
    if path.is_symlink() and not path.exists():
        return (
            f"{flag} {path} is a link to {os.readlink(path)}, which does not exist; make that folder or "
            f"pass another {flag}"
        )
    return None


def check_out_path(path: Path, flag: str = "--out") -> str | None:
    """None if `path` can hold this program's output, else one line saying why not. Creates nothing:
    it writes and removes a probe file in `path`, or in its nearest existing parent folder; so a caller
    checks first that `path` is not inside a folder it only reads (claim's inputs, the engine's --src)."""
    path = Path(path)
    if str(path) == "":
        return f"{flag} must not be empty"
    try:  # a non-UTF-8 name (a byte such as \xff) reaches Python as surrogates; pyarrow cannot take it
        str(path.absolute()).encode("utf-8")
    except UnicodeEncodeError:
        shown = os.fsencode(path).decode("utf-8", "backslashreplace")
        return f"{flag} {shown} is not a UTF-8 path (pyarrow cannot write it); pass a folder name in UTF-8"
    if problem := dangling(path, flag):
        return problem
    if path.exists() and not path.is_dir():
        return f"{flag} {path} is a file, not a folder; pass a folder path"
    where = path
    while not where.exists() and where != where.parent:
        where = where.parent
    if not where.is_dir():
        return f"{flag} {path} cannot be created: {where} is a file, not a folder"
    probe = temp_path(where / (path.name or "out"))
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        return f"{flag} {path} cannot be written ({e.strerror} in {where}); choose a folder you can write to"
    return None


def lock(folder: Path) -> None:
    """Hold folder/LOCK_NAME (it names this process) until unlock(folder) or the process ends; a second
    run on the folder waits here, saying so, until the first ends. A file system without locks: no-op."""
    if fcntl is None:
        return
    unlock(folder)  # this process locked it before (a notebook re-running its setup cell)
    fd = os.open(Path(folder) / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        waiting = f"waiting: another run (pid {holder}) is writing to {folder}"
        print(f"{waiting}; this one starts when it ends", flush=True)
        fcntl.flock(fd, fcntl.LOCK_EX)
    except OSError as e:
        os.close(fd)
        if e.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
            return
        raise
    except BaseException:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    _HELD[Path(folder).resolve()] = fd


def unlock(folder: Path) -> None:
    """Release lock(folder), leaving the lock file empty (nobody holds it)."""
    fd = _HELD.pop(Path(folder).resolve(), None)
    if fd is not None:
        os.ftruncate(fd, 0)
        os.close(fd)


def _close_locks_in_child() -> None:  # a forked worker must never keep a run's lock alive
    for fd in _HELD.values():
        with contextlib.suppress(OSError):
            os.close(fd)
    _HELD.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_close_locks_in_child)


class Claim:
    """This process's hold on an output folder; see the module docstring."""

    def __init__(self, out: Path) -> None:
        self.out = Path(out)
        self.written: set[str] = set()  # names written by this run
        self.files: dict[str, str] = {}  # name -> sha256, every file of ours in the folder
        self.pending: dict[str, str] = {}  # name -> sha256 of a write in flight (crash-safe record)

    def _save(self) -> None:  # not through write_atomic: that would consult this claim
        stamp = {"made_by": MADE_BY, "kind": "results", "files": self.files, "pending": self.pending}
        tmp = temp_path(self.out / STAMP_NAME)
        tmp.write_text(dump_json(stamp))
        os.replace(tmp, self.out / STAMP_NAME)

    def is_own(self, path: Path) -> bool:
        """Whether the file at `path` is one this program wrote (its bytes as written)."""
        name, path = Path(path).name, Path(path)
        accepted = {self.files.get(name), self.pending.get(name)} - {None}
        if not accepted or not path.is_file() or path.is_symlink():
            return False
        try:
            return sha256_file(path) in accepted
        except OSError:
            return False

    def refuse(self, path: Path) -> None:
        """DataError if a file that is not ours sits at `path`."""
        if (path.exists() or path.is_symlink()) and not self.is_own(path):
            raise DataError(
                f"{path} was not written by this program (or was changed since); move it or pass "
                "another --out (nothing was changed)"
            )

    def before(self, path: Path, digest: str) -> None:
        """A write of `path` is about to happen: refuse if a file not ours is there, else record it."""
        self.refuse(Path(path))
        self.pending[Path(path).name] = digest
        self._save()

    def after(self, path: Path, digest: str) -> None:
        self.files[path.name] = digest
        self.pending.pop(path.name, None)
        self.written.add(path.name)
        self._save()

    def in_the_way(self, results, reuses, replaces) -> set[str]:
        """Read the folder's stamp; DataError if a file or folder not ours sits where this run writes.
        Returns the names of this program's files in the folder."""
        out, stamp = self.out, read_stamp(self.out)
        self.files, self.pending = {}, {}
        if is_ours(stamp) and stamp.get("kind") == "results":
            self.files = {k: v for k, v in (stamp.get("files") or {}).items() if isinstance(v, str)}
            self.pending = {k: v for k, v in (stamp.get("pending") or {}).items() if isinstance(v, str)}
        mine = {name for name in set(self.files) | set(self.pending) if self.is_own(out / name)}
        if others := sorted(mine - set(results)):  # another command's (scale_lab.py or scale_data.py)
            raise DataError(
                f"--out {out} holds another command's results ({names(others)}); pass another --out or move "
                "them (nothing was changed)"
            )
        for name in results:
            if name not in mine:
                self.refuse(out / name)
        for path in reuses:
            check_ours(path)
        for path in replaces:
            check_replaceable(path)
        return mine

    def release(self) -> None:
        """Give the folder back (the lock too); the process ending does the same."""
        unlock(self.out)


def claim(
    out: Path,
    *,
    inputs: dict[str, Path | None] | None = None,
    results: tuple[str, ...] = (),
    reuses: list[Path] = (),
    replaces: list[Path] = (),
) -> Claim:
    """Take `out` for this run; DataError (one line) if anything of the user's is in the way, in which
    case nothing was created or changed. The folder must be usable (creatable, writable, not a file,
    not a dataset); lock() makes a second run on it wait until the first ends (the lock goes with the
    process); what a killed run left is removed, and this program's results of an earlier run are
    cleared, so the folder never mixes two runs.

    inputs    {flag: path} of datasets the run reads: `out` may not be one of them or inside one
    results   the file names the run will write directly in `out`
    reuses    demo-set folders the run reuses when valid: each must be absent or made by this program
    replaces  folders the run will rebuild: each must hold only files this program wrote
    """
    out = Path(out)
    for flag, given in (inputs or {}).items():  # before check_out_path's probe file, which would land there
        if given is not None and out.resolve().is_relative_to(Path(given).resolve()):
            raise DataError(
                f"--out {out} is inside {flag} {given}: results would be written into your dataset; "
                "pass another --out"
            )
    if problem := check_out_path(out):
        raise DataError(problem)
    stamp = read_stamp(out)
    if (out / "meta" / "info.json").exists() or (is_ours(stamp) and stamp.get("kind") != "results"):
        raise DataError(f"--out {out} is a dataset folder; results would mix into it: pass another --out")
    c = Claim(out)
    c.in_the_way(results, reuses, replaces)  # before anything is created
    out.mkdir(parents=True, exist_ok=True)
    lock(out)
    try:
        sweep_leftovers(out)
        if (out / "demos").is_dir():
            sweep_leftovers(out / "demos")
        mine = c.in_the_way(results, reuses, replaces)  # again: a run we waited for may have changed it
        for name in sorted(mine):  # this program's results of an earlier run: never mixed with this one's
            (out / name).unlink()
        c.files, c.pending = {}, {}
        c._save()
    except BaseException:
        c.release()
        raise
    return c
