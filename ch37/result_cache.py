"""The result cache: a finished run is reused when its flags, the package versions and the user's own
data (the key), and every project file the run imported (recorded in the entry) all match.

An entry holds exactly the files its run wrote into --out, its summary, the sha256 of every project
file the run had loaded when it finished (code.json: each module under the repository, the model
files an env names), and a manifest with the sha256 of each. An entry whose code differs from the
files here now is stale: it is not replayed, and the run's own result replaces it. A replay verifies
every file before copying any; an entry that fails is discarded (one warning line) and the run
computes the result again. The cache never breaks a run: a cache
folder that cannot be read or written is skipped with one warning line.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import sys
from importlib.metadata import version
from pathlib import Path

from ch37 import ROOT, code_files
from ch37.cli import mkl_branch
from ch37.config import NOT_IN_KEY, RESULT_FILES
from ch37.errors import DataError
from ch37.ownership import (
    STAMP_NAME,
    dump_json,
    partial_dir,
    sha256_bytes,
    sweep_leftovers,
    temp_path,
    write_atomic,
)

MANIFEST, SUMMARY, CODE = "manifest.json", "summary.txt", "code.json"
# summary.txt keeps each written file as NUL + its name + NUL (NUL is in no path and no number), so a
# replay rebuilds exactly the paths under its own --out, whatever --out's name also matches in the text.
# Part of the key: an entry in an older summary format is never replayed.
CACHE_FORMAT = "3"  # 3: the code recorded per entry (code.json), not in the key


def cache_root() -> Path:
    return Path(os.environ.get("CH37_CACHE_DIR", ROOT / "outputs" / ".result_cache"))


def _tree_digest(h, path: Path) -> None:
    try:
        for p in sorted(Path(path).rglob("*")):
            if p.is_file():
                h.update(str(p.relative_to(path)).encode())
                h.update(p.read_bytes())
    except OSError as e:
        raise DataError(
            f"{path}: {e.filename or ''} cannot be read ({e.strerror}); check its permissions"
        ) from e


def result_key(config: dict) -> str:
    """sha256 of the configuration, package versions and user data (the code is checked per entry)."""
    h = hashlib.sha256(
        json.dumps({k: str(v) for k, v in config.items() if k not in NOT_IN_KEY}, sort_keys=True).encode()
    )
    h.update(f"cache format {CACHE_FORMAT}".encode())
    # The kernels decide the bits (docs/reproducibility.md): OpenBLAS's the training's, MKL's branch the
    # rollouts'; a run on others is another result, never this one replayed. The kernels in force, not
    # the variables as set now: both read them once per process (a notebook's %env changes nothing)
    h.update(f"MKL branch={mkl_branch()}".encode())
    from ch37.ensemble import blas_core  # here, not at the top: it loads torch, and flags are read before

    h.update(f"OpenBLAS kernels={blas_core()}".encode())
    for pkg in ("torch", "lerobot", "mujoco", "numpy"):
        h.update(f"{pkg}=={version(pkg)}".encode())
    for key in ("pusht_data", "aloha_data"):  # a user's own set: its bytes are part of the input
        if config.get(key):
            _tree_digest(h, Path(config[key]))
    return h.hexdigest()[:24]


def recorded_code(entry: Path):
    """The code the run of `entry` recorded (its code_files()), None if it has none."""
    try:
        return json.loads((Path(entry) / CODE).read_text())
    except (OSError, ValueError):
        return None


def stale_code(recorded) -> bool:
    """Whether the code an entry recorded (code_files() of its run) differs from the files here now."""
    if not isinstance(recorded, dict) or not recorded:
        return True
    for rel, digest in recorded.items():
        try:
            if sha256_bytes((ROOT / rel).read_bytes()) != digest:
                return True
        except OSError:
            return True
    return False


def _warn(msg: str) -> None:
    print(f"warning: {msg}", file=sys.stderr, flush=True)


def read_entry(entry: Path) -> dict[str, bytes] | str | None:
    """{name: bytes} of a verified entry; None if there is no entry; else why it is bad (one phrase)."""
    if not entry.exists():
        return None
    if (
        entry.is_symlink() or not entry.is_dir()
    ):  # the cache writes real folders; it never reads through a link
        return "it is a link or a file, not a folder this cache wrote"
    try:
        manifest = json.loads((entry / MANIFEST).read_text())
        if not isinstance(manifest, dict) or SUMMARY not in manifest or "metrics.json" not in manifest:
            return f"its {MANIFEST} is incomplete"
        out = {}
        for name, digest in manifest.items():
            if Path(name).name != name or name not in (*RESULT_FILES, SUMMARY, CODE):
                return f"its {MANIFEST} names an unexpected file {name!r}"
            data = (entry / name).read_bytes()
            if sha256_bytes(data) != digest:
                return f"{name} fails its checksum"
            out[name] = data
        out.pop(CODE, None)  # checked like the rest; read again by recorded_code
        return out
    except FileNotFoundError as e:
        return f"{Path(e.filename).name} is missing"
    except (OSError, UnicodeDecodeError, ValueError) as e:
        return f"it cannot be read ({type(e).__name__})"


def summary_template(summary: str, written: list[Path]) -> str:
    """`summary` with each written file's path (exactly as printed) replaced by NUL name NUL."""
    paths = sorted({str(p): Path(p).name for p in written}.items(), key=lambda kv: -len(kv[0]))
    if not paths:
        return summary
    names = dict(paths)
    return re.sub("|".join(re.escape(p) for p, _ in paths), lambda m: f"\0{names[m.group(0)]}\0", summary)


def summary_for(template: str, out: Path) -> str:
    """The summary of a stored `template` with its file names placed under `out`."""
    parts = template.split("\0")
    return "".join(str(out / part) if i % 2 else part for i, part in enumerate(parts))


def _recorded(entry: Path) -> list[str]:
    """The files a damaged entry's manifest records (of the names an entry can hold), and the manifest;
    with no whole manifest, the names an entry can hold (store() puts nothing else in one)."""
    allowed = (*RESULT_FILES, SUMMARY, CODE)
    try:
        manifest = json.loads((entry / MANIFEST).read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        manifest = None
    if not isinstance(manifest, dict) or SUMMARY not in manifest or "metrics.json" not in manifest:
        return [*allowed, MANIFEST]  # not a manifest store() wrote: what it records is unknown
    return [name for name in allowed if name in manifest] + [MANIFEST]


def discard_entry(entry: Path) -> bool:
    """Remove the files a damaged entry recorded (_recorded) and the folder if then empty; True if the
    entry is gone. Never through a link: an entry that is a link (or a file) is left as it is, and a
    recorded name that is a link loses the link alone (Path.unlink never follows one)."""
    if entry.is_symlink() or not entry.is_dir():
        return False
    for name in _recorded(entry):
        with contextlib.suppress(OSError):
            (entry / name).unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        entry.rmdir()
    return not entry.exists()


class ResultCache:
    """One run's entry: `replay()` in setup (True: the outputs are in place, stop), `store()` in emit."""

    def __init__(self, args, claim=None) -> None:
        self.enabled, self.out, self.claim = args.cache, Path(args.out), claim  # claim: the run's, on --out
        self.key = result_key(vars(args))

    def replay(self) -> bool:
        """Copy a cached run's outputs into --out and print its summary; False if there is none (or the
        entry failed its check and was discarded: the run then computes the result again)."""
        if not self.enabled:
            return False
        entry = cache_root() / self.key
        got = read_entry(entry)
        if got is None:
            return False
        if isinstance(got, str):
            gone = discard_entry(entry)
            if gone:
                what = "discarded"
            elif entry.is_symlink() or not entry.is_dir():
                what = "left as it is (remove it yourself if it is not yours)"
            else:
                what = "it could not be removed (remove it yourself)"
            _warn(f"the cached result {entry} was damaged ({got}); {what}; computing it again")
            return False
        if stale_code(recorded_code(entry)):  # made by other code than this: ours to replace
            discard_entry(entry)
            return False
        self.out.mkdir(parents=True, exist_ok=True)
        for name, data in got.items():
            if name != SUMMARY:
                write_atomic(self.out / name, data, self.claim)
        why = f"same flags and code, cache key {self.key}; --no-cache runs it again"
        print(f"reusing the result of an identical earlier run ({why})")
        print(summary_for(got[SUMMARY].decode(), self.out), end="")
        return True

    def store(self, written: list[Path], summary: str) -> None:
        """Keep exactly the files this run wrote (`written`, inside --out) and its summary."""
        claim = self.claim
        names = [Path(p).name for p in written]
        if claim is not None and not set(names) <= claim.written:
            _warn(
                f"not caching this result: {sorted(set(names) - claim.written)} were not written by this run"
            )
            return
        root = cache_root()
        dst = root / self.key
        tmp = temp_path(dst, "partial")
        try:
            root.mkdir(parents=True, exist_ok=True)
            sweep_leftovers(root)
            tmp = partial_dir(dst)  # marked as ours, so a crash here leaves nothing the sweep cannot tell
            manifest = {}
            for path, name in zip(written, names):
                data = Path(path).read_bytes()
                (tmp / name).write_bytes(data)
                manifest[name] = sha256_bytes(data)
            code = dump_json(code_files()).encode()  # every project file this run imported, at its end
            (tmp / CODE).write_bytes(code)
            manifest[CODE] = sha256_bytes(code)
            text = summary_template(summary, written).encode()
            (tmp / SUMMARY).write_bytes(text)
            manifest[SUMMARY] = sha256_bytes(text)
            (tmp / MANIFEST).write_text(dump_json(manifest))
            (tmp / STAMP_NAME).unlink()  # an entry holds exactly its manifest's files
            old = read_entry(dst)
            if isinstance(old, str) or (old and stale_code(recorded_code(dst))):  # damaged or stale: ours
                discard_entry(dst)
            with contextlib.suppress(OSError):  # a good entry for this key exists (another run stored it)
                os.rename(tmp, dst)
        except OSError as e:
            _warn(
                f"could not store this result in the cache {root} ({e.strerror}); the run itself is complete"
            )
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
