"""The result cache: a finished run is reused when its flags, every file that shapes it, the
package versions and the user's own data all match (ch37.CODE_FILES lists the files).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from importlib.metadata import version
from pathlib import Path

from ch37 import CODE_FILES, ROOT
from ch37.cli import NOT_IN_KEY
from ch37.files import write_atomic

RESULT_FILES = ("metrics.json", "cross_embodiment.json", "scale_data.png", "scale_data.rrd")


def cache_root() -> Path:
    return Path(os.environ.get("CH37_CACHE_DIR", ROOT / "outputs" / ".result_cache"))


def _tree_digest(h, path: Path) -> None:
    for p in sorted(Path(path).rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path)).encode())
            h.update(p.read_bytes())


def result_key(config: dict) -> str:
    """sha256 of the configuration, the code that shapes the result, package versions and user data."""
    h = hashlib.sha256(
        json.dumps({k: str(v) for k, v in config.items() if k not in NOT_IN_KEY}, sort_keys=True).encode()
    )
    for name in CODE_FILES:
        h.update(name.encode())
        h.update((ROOT / name).read_bytes())
    for pkg in ("torch", "lerobot", "mujoco", "numpy"):
        h.update(f"{pkg}=={version(pkg)}".encode())
    for key in ("pusht_data", "aloha_data"):  # a user's own set: its bytes are part of the input
        if config.get(key):
            _tree_digest(h, Path(config[key]))
    return h.hexdigest()[:24]


class ResultCache:
    """One run's entry: `replay()` in setup (True: the outputs are in place, stop), `store()` in emit."""

    def __init__(self, args) -> None:
        self.enabled, self.out = args.cache, Path(args.out)
        self.key = result_key(vars(args))

    def replay(self) -> bool:
        """Copy a cached run's outputs into --out and print its summary; False if there is none."""
        src = cache_root() / self.key
        if not self.enabled or not (src / "metrics.json").exists():
            return False
        self.out.mkdir(parents=True, exist_ok=True)
        for name in RESULT_FILES:
            if (src / name).exists():
                write_atomic(self.out / name, (src / name).read_bytes())
        print(
            f"reusing the result of an identical earlier run (same flags and code, cache key {self.key}; "
            "--no-cache runs it again)"
        )
        print((src / "summary.txt").read_text().replace("{out}", str(self.out)), end="")
        return True

    def store(self, written: list[Path], summary: str) -> None:
        """Keep exactly the files this run wrote (`written`, inside --out) and its summary."""
        dst = cache_root() / self.key
        tmp = dst.with_name(f".{self.key}.tmp-{os.getpid()}")
        tmp.mkdir(parents=True, exist_ok=True)
        for path in written:
            shutil.copyfile(path, tmp / Path(path).name)
        (tmp / "summary.txt").write_text(summary.replace(str(self.out), "{out}"))
        if dst.exists():
            shutil.rmtree(dst)  # our own cache entry for the same key
        tmp.rename(dst)
