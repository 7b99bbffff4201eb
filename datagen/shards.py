"""A run's shards: each a LeRobot v3 set with a stamp, made by a worker, saved by the caller, merged once.

    make_shard(index, jobs, sources, config)   a worker: one shard's attempts (config: a RunConfig), as bytes
    save_shard(out, index, result), collect    the caller: each shard saved as it arrives
    merge(out, n_shards, run_stamp)            the shards into OUT/data and OUT/meta, in one pass
    remove_shards(out)                         once the run is stamped complete

A worker makes one shard (datagen.engine.run_attempts on its attempts, then datagen.engine.save) and
returns its files as bytes; the caller saves them, so a worker on another machine needs no shared disk.
A shard is saved into its .partial folder and renamed into place with its stamp inside, so a shard
folder without the .partial suffix is always whole (datagen.resume judges those a re-run finds).

The merge (merge_sets) reads each shard's data and episodes parquet once, moves its episode and
frame indices by those before it, and writes every file of the set once: data and meta/episodes
files of up to LeRobot's 100 MB (cut by row counts, never where a shard ends, so the data files'
bytes do not depend on --shard_size), tasks, info.json, and stats.json over all frames
(lerobot_v3.frame_stats, counted as the frames are written). It costs one read and one write per
frame, and one or two more reads of the numeric columns for the exact quantiles, where LeRobot's
aggregate_datasets re-read and rewrote its growing episodes file for every shard. LeRobotDataset
reads what either writes the same (tests/test_merge.py).
"""

from __future__ import annotations

import contextlib
import re
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from ch37.errors import DataError
from ch37.ownership import MADE_BY, STAMP_NAME, digests, dump_json, read_json, write_atomic
from datagen import engine, lockstep
from datagen.demos import TASK_FILE, name_task
from datagen.plan import RunConfig, run_key, versions
from datagen.task import known_tasks
from lerobot_v3.merge import merge_sets

SHARDS_DIR = "shards"  # OUT/shards
# What OUT/shards holds: a finished shard, a shard being saved, a worker's scratch for one
SHARD_NAMES = re.compile(r"shard-\d{5}|\.shard-\d{5}\.(partial|scratch)")
MERGE_DIR = ".merged.partial"  # the merge is built here, then its data/ and meta/ are renamed into OUT
# A shard folder holds 6 files (a data and an episodes parquet, info.json, stats.json, tasks.parquet,
# its stamp); the merge opens each shard's, so beyond a few thousand files --shard_size costs time.
FILES_PER_SHARD, MANY_FILES = 6, 5000


def many_files_note(n_shards: int, attempts: int, shard_size: int, out: Path) -> str | None:
    """One line when the plan would leave more than MANY_FILES files under OUT/shards, else None."""
    files = n_shards * FILES_PER_SHARD
    if files <= MANY_FILES:
        return None
    return (
        f"note: --shard_size {shard_size} cuts {attempts:,} attempts into {n_shards:,} shards: up to "
        f"{files:,} files under {Path(out) / SHARDS_DIR} until the merge, which reads each shard's; "
        "a larger --shard_size makes fewer (a new --out: it is part of the settings)"
    )


def shard_dir(out: Path, index: int) -> Path:
    return Path(out) / SHARDS_DIR / f"shard-{index:05d}"


# ----------------------------------------------------------------------------------------------
# Worker side: one shard, returned as bytes
# ----------------------------------------------------------------------------------------------
def make_shard(
    index: int, jobs, sources: dict, config: RunConfig, scratch: str | None = None, sims=None
) -> dict:
    """Run the shard's attempts and write its kept episodes as a LeRobot v3 set (in a temp folder
    under `scratch`, the system's when None), then read it back as bytes. sims: the worker's
    datagen.engine.Simulators, kept between its shards (a new one when None).

    Returns {"files": {relative path: bytes}, "stamp": the shard's stamp}. The stamp holds the
    counts the report needs (attempts, kept, failures by reason, per source, episode lengths) and
    seconds_write, the seconds the worker spent writing the set and reading it back."""
    task, s = known_tasks()[config.task], config.settings
    # = engine.run_attempts', bit for bit (tests/test_lockstep.py), attempts stepped together
    results = lockstep.attempts_lockstep(
        task, sources, jobs, s.perturbation, mode=s.mode, select=s.select, sims=sims
    )
    kept = [r.episode for r in results if r.kept]
    per_source = {}  # source episode -> [attempts, kept]
    for (e, _), r in zip(jobs, results):
        tally = per_source.setdefault(str(e), [0, 0])
        tally[0], tally[1] = tally[0] + 1, tally[1] + r.kept
    stamp = {
        "made_by": MADE_BY,
        "kind": "engine-shard",
        "run": run_key(config),
        "shard": index,
        "attempts": len(jobs),
        "kept": len(kept),
        "frames": sum(len(r["action"]) for r in kept),
        "failures": dict(Counter(r.reason for r in results if not r.kept)),
        "per_source": per_source,
        "lengths": dict(Counter(str(len(r["action"])) for r in kept)),
        "versions": versions(task),
    }
    if not kept:
        return {"files": {STAMP_NAME: dump_json(stamp).encode()}, "stamp": stamp}
    t0 = time.perf_counter()
    with _scratch(scratch, index) as tmp:
        root = tmp / "set"
        engine.save(task, root, kept, repo_id=f"local/{task.name}_aug_shard", stamp=stamp)
        files = {
            p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
        }
    # the report's seconds_write (summed over shards); only in the stamp handed back, not in the
    # shard's files (their stamp is written inside the set, before the write ends)
    return {"files": files, "stamp": stamp | {"seconds_write": time.perf_counter() - t0}}


@contextlib.contextmanager
def _scratch(scratch: str | None, index: int):
    """A folder to write one shard in: OUT/shards/.shard-NNNNN.scratch (a name SHARD_NAMES knows, so
    a killed run's is recognised and removed), or a fresh one in the system's temp folder."""
    if scratch is None:
        with tempfile.TemporaryDirectory(prefix="ch37-shard-") as tmp:
            yield Path(tmp)
        return
    tmp = Path(scratch) / f".shard-{index:05d}.scratch"
    shutil.rmtree(tmp, ignore_errors=True)  # a killed run's (OUT/shards is this run's, under its lock)
    tmp.mkdir()
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


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


def collect(out: Path, results, done: dict, versions: dict, *, total: int, quiet: bool) -> int:
    """Save each shard as it arrives (into `done`: shard index -> stamp), with a progress bar of
    attempts. Returns the demos kept by this run."""
    from tqdm import tqdm

    initial = sum(st["attempts"] for st in done.values())
    hide = quiet or not sys.stderr.isatty()
    bar = tqdm(total=total, initial=initial, desc="augment", unit="attempt", leave=False, disable=hide)
    attempts = kept = 0
    t0 = time.perf_counter()
    for r in results:
        st = r["stamp"]
        if st["versions"] != versions:
            raise DataError(
                f"a worker has {st['versions']}, this machine {versions}: install the same versions"
            )
        save_shard(out, st["shard"], r)
        done[st["shard"]] = st
        attempts, kept = attempts + st["attempts"], kept + st["kept"]
        bar.update(st["attempts"])
        rate = kept / max(time.perf_counter() - t0, 1e-9)
        bar.set_postfix_str(f"{rate:.1f} demos/s, yield {kept / attempts:.3f}")
    bar.close()
    return kept


def merge(out: Path, n_shards: int, run_stamp: dict) -> int:
    """Merge the shards that hold episodes into OUT/data and OUT/meta in one pass (merge_sets), with
    meta/stats.json over all frames. The shards stay until the run is stamped complete. Before data/
    and meta/ are renamed into OUT, their files and sha256 are recorded in the run's stamp
    (`run_stamp` gains "merged"), so a resume knows them as ours.
    Returns the number of merged episodes (0: nothing kept, no set)."""
    out = Path(out)
    roots = [
        shard_dir(out, i) for i in range(n_shards) if (shard_dir(out, i) / "meta" / "info.json").exists()
    ]
    tmp = out / MERGE_DIR
    for stale in (tmp, out / "data", out / "meta"):  # ours: a merge cut off earlier in this folder
        if stale.exists():
            shutil.rmtree(stale)
    episodes = merge_sets(roots, tmp) if roots else 0
    if roots:
        name_task(tmp, read_json(roots[0] / TASK_FILE)["task"])  # the task the shards name (engine.save)
        listing = digests(tmp)
        run_stamp["merged"] = {rel: d for rel, d in listing.items() if rel.split("/")[0] in ("data", "meta")}
        write_atomic(out / STAMP_NAME, dump_json(run_stamp))
        (tmp / "data").rename(out / "data")
        (tmp / "meta").rename(out / "meta")
        shutil.rmtree(tmp)
    return episodes


def remove_shards(out: Path) -> None:
    """Once the run's stamp says complete: the shards are in the merged set."""
    shutil.rmtree(Path(out) / SHARDS_DIR, ignore_errors=True)
