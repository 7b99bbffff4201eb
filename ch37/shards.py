"""A generation run on disk: fixed shards of attempts, each a LeRobot v3 set with a stamp, merged by LeRobot.

The attempts (source episode e, k) are listed e-major and cut into shards of `shard_size`
attempts, so a shard's contents depend on the run's settings alone, never on the worker count
or the executor. A worker makes one shard (ch37.engine.attempt on each of its attempts, then
ch37.lerobot_io.write_dataset) and returns its files as bytes; the caller saves them, so a
worker on another machine needs no shared disk. Layout of a run's folder:

    OUT/scale_data_stamp.json          the run's stamp: made_by, kind "engine", its settings, complete
    OUT/shards/shard-00007/            a finished shard: a LeRobot v3 set and its stamp (counts)
    OUT/shards/.shard-00007.partial/   a shard being saved; discarded by the next run
    OUT/data, OUT/meta                 the merged LeRobot v3 set (LeRobot's aggregate_datasets)
    OUT/generation_report.json         attempts, kept, yield, failures, timing (written last)

A shard is saved into its .partial folder and renamed into place with its stamp inside, so a
shard folder without the .partial suffix is always whole. The shards are removed once the run is
stamped complete.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ch37 import DATA_CODE
from ch37.demos import code_digest
from ch37.stamps import MADE_BY, STAMP_NAME, read_stamp, stamp_text

SHARD_SIZE = 100  # attempts per shard: ~0.4 MB of parquet, a few seconds of one core
SHARDS_DIR = "shards"
REPORT_NAME = "generation_report.json"
RUN_KIND = "engine"
# The engine's own code: a shard made by other code is never mixed into a run.
ENGINE_VERSION = code_digest(DATA_CODE + ("ch37/engine.py", "ch37/shards.py"))


def versions() -> dict:
    """The packages whose versions can change a shard's bytes."""
    import lerobot
    import mujoco
    import pyarrow

    return {"lerobot": lerobot.__version__, "mujoco": mujoco.__version__, "numpy": np.__version__,
            "pyarrow": pyarrow.__version__}  # fmt: skip


def source_identity(arrays: dict) -> dict:
    """What a run was grown from, independent of where the set lives: a digest of the frames read."""
    h = hashlib.sha256()
    for key in ("episode_index", "observation.state", "action"):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return {
        "sha256": h.hexdigest(),
        "episodes": int(len(np.unique(arrays["episode_index"]))),
        "frames": int(len(arrays["action"])),
    }


def run_key(config: dict) -> str:
    """A short digest of a run's settings; every shard stamp carries it."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:16]


def plan(episodes, per_demo: int, shard_size: int) -> list[list[tuple[int, int]]]:
    """The attempts (e, k), e-major, cut into shards of shard_size (the last may be shorter)."""
    jobs = [(int(e), k) for e in episodes for k in range(per_demo)]
    return [jobs[i : i + shard_size] for i in range(0, len(jobs), shard_size)]


def shard_dir(out: Path, index: int) -> Path:
    return Path(out) / SHARDS_DIR / f"shard-{index:05d}"


# ----------------------------------------------------------------------------------------------
# Worker side: one shard, returned as bytes
# ----------------------------------------------------------------------------------------------
def make_shard(index: int, jobs, sources: dict, config: dict, scratch: str | None = None) -> dict:
    """Run the shard's attempts and write its kept episodes as a LeRobot v3 set (in a temp folder
    under `scratch`, the system's when None), then read it back as bytes.

    Returns {"files": {relative path: bytes}, "stamp": the shard's stamp}. The stamp holds the
    counts the report needs (attempts, kept, failures by reason, per source, episode lengths)."""
    from ch37 import engine

    kept, failures, per_source, lengths = [], {}, {}, {}
    for e, k in jobs:
        r = engine.attempt(
            sources[e], k, seed=config["seed"], pos_sigma=config["pos_sigma"],
            yaw_sigma=config["yaw_sigma"], mode=config["mode"],
        )  # fmt: skip
        tally = per_source.setdefault(str(e), [0, 0])  # [attempts, kept]
        tally[0] += 1
        if isinstance(r, str):
            failures[r] = failures.get(r, 0) + 1
            continue
        tally[1] += 1
        n = str(len(r["action"]))
        lengths[n] = lengths.get(n, 0) + 1
        kept.append(r)
    stamp = {
        "made_by": MADE_BY,
        "kind": "engine-shard",
        "run": run_key(config),
        "shard": index,
        "attempts": len(jobs),
        "kept": len(kept),
        "frames": sum(len(r["action"]) for r in kept),
        "failures": failures,
        "per_source": per_source,
        "lengths": lengths,
        "versions": versions(),
    }
    if not kept:
        return {"files": {STAMP_NAME: stamp_text(stamp).encode()}, "stamp": stamp}
    with tempfile.TemporaryDirectory(prefix=".scratch-", dir=scratch) as tmp:
        root = Path(tmp) / "set"
        engine.write_kept(root, kept, repo_id="local/pusht_aug_shard", stamp=stamp)
        files = {
            p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
        }
    return {"files": files, "stamp": stamp}


# ----------------------------------------------------------------------------------------------
# Caller side: save, find, merge
# ----------------------------------------------------------------------------------------------
def save_shard(out: Path, index: int, result: dict) -> None:
    """Write a shard's files into its .partial folder, then rename it into place (stamp inside)."""
    final = shard_dir(out, index)
    tmp = final.with_name(f".{final.name}.partial")
    if tmp.exists():
        shutil.rmtree(tmp)
    for rel, data in result["files"].items():
        path = tmp / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    if final.exists():
        shutil.rmtree(final)  # a stale shard of this run's folder (checked by the caller)
    tmp.rename(final)


def finished(out: Path, config: dict, n_shards: int) -> dict[int, dict]:
    """{shard index: stamp} of the whole shards of this run; partial and foreign shards are removed.

    Only called on a folder whose run stamp matches `config`, so everything under shards/ is ours."""
    root = Path(out) / SHARDS_DIR
    done = {}
    if not root.is_dir():
        return done
    key = run_key(config)
    for path in sorted(root.iterdir()):
        m = re.fullmatch(r"shard-(\d{5})", path.name)
        stamp = read_stamp(path) if m and path.is_dir() else None
        if stamp and stamp.get("run") == key and int(m.group(1)) < n_shards:
            done[int(m.group(1))] = stamp
        elif path.is_dir():
            shutil.rmtree(path)  # a shard cut off mid-save, or one from other settings
        else:
            path.unlink()
    return done


def merge(out: Path, n_shards: int) -> int:
    """Merge the shards that hold episodes into OUT/data and OUT/meta with LeRobot's
    aggregate_datasets and recompute meta/stats.json over all frames. The shards stay until the
    run is stamped complete. Returns the number of merged episodes (0: nothing kept, no set)."""
    from lerobot.datasets.aggregate import aggregate_datasets

    out = Path(out)
    roots = [
        shard_dir(out, i) for i in range(n_shards) if (shard_dir(out, i) / "meta" / "info.json").exists()
    ]
    tmp = out / ".merged.partial"
    for stale in (tmp, out / "data", out / "meta"):  # ours: a merge cut off earlier in this folder
        if stale.exists():
            shutil.rmtree(stale)
    if roots:
        with contextlib.redirect_stderr(io.StringIO()):  # aggregate_datasets' own tqdm bars
            # one data file per shard: appending would re-read and rewrite the merged file for
            # every shard (30 shards of 100: 67 s instead of 34 s here, and memory growing with N)
            aggregate_datasets(
                [f"local/shard-{i:05d}" for i in range(len(roots))],
                "local/pusht_aug",
                roots=roots,
                aggr_root=tmp,
                concatenate_data=False,
            )
        write_frame_stats(tmp)
        (tmp / "data").rename(out / "data")
        (tmp / "meta").rename(out / "meta")
        shutil.rmtree(tmp)
    return sum(json.loads((r / "meta" / "info.json").read_text())["total_episodes"] for r in roots)


def remove_shards(out: Path) -> None:
    """Once the run's stamp says complete: the shards are in the merged set."""
    shutil.rmtree(Path(out) / SHARDS_DIR, ignore_errors=True)


# ----------------------------------------------------------------------------------------------
# Statistics over all frames
# ----------------------------------------------------------------------------------------------
def column(files, key: str) -> np.ndarray:
    """One feature over all frames of the parquet `files`, as float64 (frames, dims)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    parts = []
    for f in files:
        col = pq.read_table(f, columns=[key]).column(key).combine_chunks()
        if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
            parts.append(
                col.flatten().to_numpy(zero_copy_only=False).astype(np.float64).reshape(len(col), -1)
            )
        else:
            parts.append(col.to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, 1))
    return np.concatenate(parts)


def frame_stats(x: np.ndarray, names) -> dict:
    """LeRobot's stats.json entries for one feature, computed over every frame (x: (frames, dims))."""
    quantiles = {name: float(name[1:]) / 100 for name in names if re.fullmatch(r"q\d\d", name)}
    out = {
        "min": x.min(0),
        "max": x.max(0),
        "mean": x.mean(0),
        "std": x.std(0),
        **{name: np.quantile(x, q, axis=0) for name, q in quantiles.items()},
    }
    stats = {name: [float(v) for v in out[name]] for name in names if name in out}
    if "count" in names:
        stats["count"] = [int(len(x))]
    return stats


def write_frame_stats(root: Path) -> None:
    """Rewrite root/meta/stats.json with every numeric feature's stats over all frames.

    LeRobot 0.6.1's aggregate_datasets (and recompute_stats) combine per-episode statistics, and
    their q01..q99 are averages of per-episode quantiles (lerobot issue 4156), not quantiles of the
    data; min, max, mean and std are recomputed here too, from the frames, in float64. Keys sorted."""
    import pyarrow.parquet as pq

    root = Path(root)
    path = root / "meta" / "stats.json"
    old = json.loads(path.read_text())
    files = sorted((root / "data").rglob("*.parquet"))
    columns = set(pq.read_schema(files[0]).names)
    new = {
        key: frame_stats(column(files, key), sorted(st)) if key in columns else st for key, st in old.items()
    }
    path.write_text(json.dumps(new, indent=4, sort_keys=True, ensure_ascii=False))


def read_json(path: Path):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError):
        return None
