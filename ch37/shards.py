"""A data-engine run on disk: fixed shards of attempts, each a LeRobot v3 set with a stamp, merged once.

    run(src, out, settings, workers=, ray=, quiet=) -> the generation report   (augment_demos.py)

The attempts (source episode e, k) are listed e-major and cut into shards of `shard_size`
attempts, so a shard's contents depend on the run's settings alone, never on the worker count
or the executor. A worker makes one shard (ch37.engine.run_attempts on its attempts, then
ch37.engine.save) and returns its files as bytes; the caller saves them, so a worker on another
machine needs no shared disk. Layout of a run's folder:

    OUT/scale_data_stamp.json          the run's stamp: made_by, kind "engine", its settings, complete
    OUT/.scale_data.lock               held while a run writes OUT (ch37.files.lock)
    OUT/shards/shard-00007/            a finished shard: a LeRobot v3 set and its stamp (counts)
    OUT/shards/.shard-00007.partial/   a shard being saved; discarded by the next run
    OUT/shards/.shard-00007.scratch/   a worker's scratch for a shard (local executors)
    OUT/data, OUT/meta                 the merged LeRobot v3 set (merge_sets)
    OUT/generation_report.json         attempts, kept, yield, failures, timing (written last)

The merge (merge_sets) reads each shard's data and episodes parquet once, moves its episode and
frame indices by those before it, and writes every file of the set once: data and meta/episodes
files of up to LeRobot's 100 MB (cut by row counts, never where a shard ends, so the data files'
bytes do not depend on --shard_size), tasks, info.json, and stats.json over all frames
(ch37.frame_stats, counted as the frames are written). It costs one read and one write per
frame, and one or two more reads of the numeric columns for the exact quantiles, where LeRobot's
aggregate_datasets re-read and rewrote its growing episodes file for every shard. LeRobotDataset
reads what either writes the same (tests/test_merge.py).

A shard is saved into its .partial folder and renamed into place with its stamp inside, so a
shard folder without the .partial suffix is always whole. The shards are removed once the run is
stamped complete; the same command re-run after a kill makes only the missing shards. What a run
writes is known: these names, each shard's files (its stamp), data/ and meta/ (listed in the run's
stamp before they are renamed into OUT); a resume that finds anything else refuses, changing nothing.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import platform
import re
import shlex
import shutil
import sys
import tempfile
import time
from collections import Counter
from importlib.metadata import version
from pathlib import Path

import numpy as np

import pusht_env
from ch37 import DATA_CODE, engine, executors
from ch37.cli import available_memory
from ch37.demos import code_digest
from ch37.errors import DataError
from ch37.files import LEFTOVER, check_out_path, dump_json, lock, round_floats, unlock, write_atomic
from ch37.frame_stats import FrameStats, write_frame_stats
from ch37.lerobot_io import PARQUET, check_hf_cache, fps_problem, frames_problem, load_arrays, schema_problem
from ch37.seeds import SEED_BLOCK
from ch37.stamps import (
    LOCK_NAME,
    MADE_BY,
    STAMP_NAME,
    changed_files,
    check_ours,
    digests,
    file_list,
    is_ours,
    names,
    read_json,
    read_stamp,
)

SHARDS_DIR = "shards"
REPORT_NAME = "generation_report.json"
MERGE_DIR = ".merged.partial"  # the merge is built here, then its data/ and meta/ are renamed into OUT
# What a run writes directly in OUT and in OUT/shards (both its own, under its lock); anything else
# there is the user's, and a resume refuses to start rather than delete it (ch37.shards.foreign).
RUN_NAMES = {STAMP_NAME, LOCK_NAME, REPORT_NAME, SHARDS_DIR, "data", "meta", MERGE_DIR}
SHARD_NAMES = re.compile(r"shard-\d{5}|\.shard-\d{5}\.(partial|scratch)")
SETTINGS = ("mode", "per_demo", "seed", "pos_sigma", "yaw_sigma", "shard_size")  # a run's flags
# The engine's own code: a shard made by other code is never mixed into a run.
ENGINE_VERSION = code_digest(DATA_CODE + ("ch37/engine.py", "ch37/shards.py", "ch37/frame_stats.py"))


def versions() -> dict:
    """The packages whose versions can change a shard's bytes."""
    return {name: version(name) for name in ("lerobot", "mujoco", "numpy", "pyarrow")}


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


# Memory the plan holds per attempt: its (e, k) tuple and slot, measured ~100 B (tracemalloc: 97 MB
# for plan(range(10), 100000, 100)), doubled for the shard tasks and results that follow it.
ATTEMPT_BYTES = 200


def plan_memory_problem(n_sources: int, per_demo: int, free: int | None) -> str | None:
    """None if a plan of n_sources x per_demo attempts fits in `free` bytes (None: unknown), else why."""
    attempts = n_sources * per_demo
    if free is None or attempts * ATTEMPT_BYTES <= free:
        return None
    return (
        f"--per_demo {per_demo:,} x {n_sources} source episodes = {attempts:,} attempts need about "
        f"{attempts * ATTEMPT_BYTES / 2**30:,.1f} GB of memory to plan, more than the "
        f"{free / 2**30:,.1f} GB available here; lower --per_demo (or run it in parts with --seed)"
    )


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
    counts the report needs (attempts, kept, failures by reason, per source, episode lengths) and
    seconds_write, the seconds the worker spent writing the set and reading it back."""
    how = {k: config[k] for k in ("seed", "pos_sigma", "yaw_sigma", "mode")}
    results = engine.run_attempts(sources, jobs, workers=1, **how)
    kept = [r for r in results if not isinstance(r, str)]
    per_source = {}  # source episode -> [attempts, kept]
    for (e, _), r in zip(jobs, results):
        tally = per_source.setdefault(str(e), [0, 0])
        tally[0], tally[1] = tally[0] + 1, tally[1] + (not isinstance(r, str))
    stamp = {
        "made_by": MADE_BY,
        "kind": "engine-shard",
        "run": run_key(config),
        "shard": index,
        "attempts": len(jobs),
        "kept": len(kept),
        "frames": sum(len(r["action"]) for r in kept),
        "failures": dict(Counter(r for r in results if isinstance(r, str))),
        "per_source": per_source,
        "lengths": dict(Counter(str(len(r["action"])) for r in kept)),
        "versions": versions(),
    }
    if not kept:
        return {"files": {STAMP_NAME: dump_json(stamp).encode()}, "stamp": stamp}
    t0 = time.perf_counter()
    with _scratch(scratch, index) as tmp:
        root = tmp / "set"
        engine.save(root, kept, repo_id="local/pusht_aug_shard", stamp=stamp)
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


def foreign(out: Path, stamp: dict) -> list[str]:
    """What under the run folder `out` (of run stamp `stamp`) this command did not write, as paths
    relative to `out`: names outside RUN_NAMES, SHARD_NAMES and our temp files; files in a stamped
    shard its stamp does not list; files in data/ and meta/ the merge did not record in `stamp`."""
    out, bad = Path(out), []
    merged = stamp.get("merged") if isinstance(stamp.get("merged"), dict) else {}
    for p in sorted(out.iterdir()):
        folder = p.name in ("data", "meta", SHARDS_DIR, MERGE_DIR)
        if p.is_symlink() or folder != p.is_dir() or (p.name not in RUN_NAMES and not LEFTOVER.match(p.name)):
            bad.append(p.name)
        elif p.name in ("data", "meta"):
            bad += [f"{p.name}/{rel}" for rel in file_list(p) if f"{p.name}/{rel}" not in merged]
        elif p.name == SHARDS_DIR:
            for q in sorted(p.iterdir()):
                st = read_stamp(q) if q.is_dir() else None
                if q.is_symlink() or not q.is_dir() or not SHARD_NAMES.fullmatch(q.name):
                    bad.append(f"{SHARDS_DIR}/{q.name}")
                elif is_ours(st) and isinstance(st.get("files", {}), dict):
                    listed = st.get("files", {})
                    bad += [f"{SHARDS_DIR}/{q.name}/{r}" for r in file_list(q) if r not in listed]
    return bad


def finished(out: Path, config: dict, n_shards: int) -> dict[int, dict]:
    """{shard index: stamp} of the whole shards of this run whose files still have the sha256 their
    stamp records; the rest of shards/ is removed (a damaged shard with one printed line).

    Only called on a run folder of `config` that foreign() found clean: all under shards/ is ours."""
    root = Path(out) / SHARDS_DIR
    done = {}
    if not root.is_dir():
        return done
    key = run_key(config)
    for path in sorted(root.iterdir()):
        m = re.fullmatch(r"shard-(\d{5})", path.name)
        stamp = read_stamp(path) if m else None
        if is_ours(stamp) and stamp.get("run") == key and int(m.group(1)) < n_shards:
            damaged = changed_files(path, stamp)  # its files against the sha256 its stamp recorded
            if not damaged:
                done[int(m.group(1))] = stamp
                continue
            print(f"shard {m.group(1)} is damaged ({names(damaged)} differs from its stamp); making it again")
            shutil.rmtree(path)
        else:
            shutil.rmtree(path)  # a shard cut off mid-save, one from other settings, a killed scratch
    return done


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
        listing = digests(tmp)
        run_stamp["merged"] = {rel: d for rel, d in listing.items() if rel.split("/")[0] in ("data", "meta")}
        write_atomic(out / STAMP_NAME, dump_json(run_stamp))
        (tmp / "data").rename(out / "data")
        (tmp / "meta").rename(out / "meta")
        shutil.rmtree(tmp)
    return episodes


# Episode rows per row group of meta/episodes: a fixed count, so the row groups never depend on how
# the episodes were cut into shards (LeRobot's own writer buffers a few episodes per group).
EPISODE_ROWS = 1000
DATA_GROUP_ROWS = 2**16  # frames per row group of a data file
SHIFTED_STATS = ("min", "max", "mean", "q01", "q10", "q50", "q90", "q99")  # move with their column


class _Files:
    """A series of parquet files `pattern` (chunk, file) under `root`, each written once, in order.

    A file holds at most `limit` rows, where limit = max_bytes / the Arrow size of a row (every row
    here has the same size: fixed-width columns and lists of fixed length), and a block placed with
    place() (an episode, or a block of episode rows) never straddles two files. After chunks_size
    files the next chunk begins (LeRobot's update_chunk_file_indices). Rows go to disk in row groups
    of group_rows rows (the last of a file shorter); LeRobot writes one per episode, which at 10^4
    episodes means 10^4 writes and as many metadata entries to parse on every read. Files and row
    groups are cut by row counts alone, so where they end never depends on the shards."""

    def __init__(self, root: Path, pattern: str, max_bytes: int, chunks_size: int, group_rows: int):
        self.root, self.pattern, self.max_bytes, self.chunks_size = root, pattern, max_bytes, chunks_size
        self.group_rows, self.buffer, self.buffered = group_rows, [], 0  # rows not yet written
        self.chunk = self.file = self.placed = 0  # rows placed in the current file
        self.limit = self.writer = self.open_at = None

    def place(self, rows: int, row_bytes: int) -> tuple[int, int]:
        """Where the next block of `rows` rows goes: (chunk, file), starting a new file if needed."""
        if self.limit is None:
            self.limit = max(1, self.max_bytes // max(1, row_bytes))
        if self.placed and self.placed + rows > self.limit:
            from lerobot.datasets.utils import update_chunk_file_indices

            self.chunk, self.file = update_chunk_file_indices(self.chunk, self.file, self.chunks_size)
            self.placed = 0
        self.placed += rows
        return self.chunk, self.file

    def write(self, table, where: tuple[int, int]) -> None:
        """Append `table` (rows placed in order) to file `where`, the place() they were given."""
        import pyarrow.parquet as pq

        if where != self.open_at:
            self.close()
            path = self.root / self.pattern.format(chunk_index=where[0], file_index=where[1])
            path.parent.mkdir(parents=True, exist_ok=True)
            self.writer = pq.ParquetWriter(path, table.schema, **PARQUET)
            self.open_at = where
        self.buffer.append(table)
        self.buffered += table.num_rows
        while self.buffered >= self.group_rows:
            self._flush(self.group_rows)

    def _flush(self, rows: int) -> None:
        import pyarrow as pa

        table = pa.concat_tables(self.buffer)
        self.writer.write_table(table.slice(0, rows))
        rest = table.slice(rows)
        self.buffer, self.buffered = ([rest] if rest.num_rows else []), rest.num_rows

    def close(self) -> None:
        if self.writer is not None:
            if self.buffered:
                self._flush(self.buffered)
            self.writer.close()
            self.writer = self.open_at = None


def _shifted(table, name: str, by: int, *, fill: bool = False):
    """`table` with `by` added to its column `name` (int64, or a list<double> of per-episode stats,
    added in float64 as LeRobot's aggregate does), or every value set to `by` (fill); type kept."""
    import pyarrow as pa
    import pyarrow.compute as pc

    i = table.schema.get_field_index(name)
    col = table.column(i).combine_chunks()
    if pa.types.is_list(col.type):
        by = pa.scalar(float(by), col.type.value_type)
        values = pc.if_else(True, by, col.values) if fill else pc.add(col.values, by)
        new = pa.ListArray.from_arrays(col.offsets, values, type=col.type)
    else:
        new = pc.add(col, pa.scalar(by, col.type))
    return table.set_column(i, table.schema.field(i), new)


def _read_set(root: Path) -> tuple:
    """A shard's episodes table and data table (all its parquet files, in order), checked to be a fresh
    LeRobot v3 set of one task: episodes 0..n-1, frames 0..N-1 in episode order."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    # ParquetFile.read: read_table's dataset path costs ~10x more on a 100-row-group file (95 ms, 10 ms)
    eps = pa.concat_tables(pq.ParquetFile(f).read() for f in sorted(root.glob("meta/episodes/*/*.parquet")))
    data = pa.concat_tables(pq.ParquetFile(f).read() for f in sorted(root.glob("data/*/*.parquet")))
    n = eps.num_rows
    ep = eps.column("episode_index").to_numpy()
    lo, hi = eps.column("dataset_from_index").to_numpy(), eps.column("dataset_to_index").to_numpy()
    length = eps.column("length").to_numpy()
    ok = (ep == np.arange(n)).all() and lo[0] == 0 and (lo[1:] == hi[:-1]).all() and (hi - lo == length).all()
    ok = ok and data.num_rows == hi[-1] and (data.column("index").to_numpy() == np.arange(hi[-1])).all()
    ok = ok and (data.column("task_index").to_numpy() == 0).all()
    if not ok:
        raise RuntimeError(f"{root} is not a LeRobot v3 set of one task with episodes in order")
    return eps, data


def _moved_episodes(eps, n_eps: int, n_frames: int, places: list[tuple[int, int]]):
    """A shard's episodes table as rows of the merged set: episode and frame indices (and their
    per-episode stats, as aggregate's update_meta_data moves them) shifted by the n_eps episodes and
    n_frames frames before it; data/chunk_index and data/file_index set to each episode's place."""
    import pyarrow as pa

    shifts = {"episode_index": n_eps, "dataset_from_index": n_frames, "dataset_to_index": n_frames}
    for name, by in (("episode_index", n_eps), ("index", n_frames)):
        shifts |= {f"stats/{name}/{stat}": by for stat in SHIFTED_STATS}
    for name, by in shifts.items():
        if name in eps.column_names:
            eps = _shifted(eps, name, by)
    for stat in ("std", *SHIFTED_STATS):
        # aggregate recomputes these from the episode's task ids (the one task: 0), where the
        # shard's writer estimated quantiles from a histogram (q01 = 4e-16, not 0)
        if f"stats/task_index/{stat}" in eps.column_names:
            eps = _shifted(eps, f"stats/task_index/{stat}", 0, fill=True)
    for j, name in enumerate(("data/chunk_index", "data/file_index")):
        i = eps.schema.get_field_index(name)
        eps = eps.set_column(i, eps.schema.field(i), pa.array([p[j] for p in places], pa.int64()))
    return eps


def merge_sets(roots: list[Path], dest: Path, *, max_bytes: int | None = None, chunks_size=None) -> int:
    """Merge the LeRobot v3 sets `roots` (each of one task, no videos) into the new set `dest`, in one
    pass: each set's data and episodes parquet is read once, its episode and frame indices (and the
    episodes table's per-episode index stats) moved by the episodes and frames before it, and written
    into data/chunk-XXX/file-YYY.parquet files of up to the first set's data_files_size_in_mb
    (`max_bytes` to override; row groups of DATA_GROUP_ROWS frames) and meta/episodes files the
    same way (row groups of EPISODE_ROWS episodes); tasks, info.json and stats.json (exact over all
    frames, write_frame_stats) once each. No file is written twice. Returns the episodes merged.

    What LeRobotDataset reads is what LeRobot's aggregate_datasets + write_frame_stats give for the
    same sets (tests/test_merge.py); only the file layout differs, and it depends on the frames alone."""
    import pandas as pd
    import pyarrow as pa
    from lerobot.datasets.io_utils import load_info, write_info, write_tasks
    from lerobot.datasets.utils import DEFAULT_DATA_PATH, DEFAULT_EPISODES_PATH

    dest = Path(dest)
    info = load_info(roots[0])
    if any(ft["dtype"] in ("video", "image") for ft in info.features.values()):
        raise RuntimeError("merge_sets merges sets without images or videos")
    max_bytes = max_bytes or info.data_files_size_in_mb * 2**20  # LeRobot's MB are MiB
    chunks_size = chunks_size or info.chunks_size
    template = _stats_template(roots)
    stats = FrameStats({k: sorted(st) for k, st in template.items() if k in info.features})
    data_out = _Files(dest, DEFAULT_DATA_PATH, max_bytes, chunks_size, group_rows=DATA_GROUP_ROWS)
    meta_out = _Files(dest, DEFAULT_EPISODES_PATH, max_bytes, chunks_size, group_rows=EPISODE_ROWS)
    n_eps = n_frames = 0
    task, pending = None, []  # episode rows not yet written (fewer than EPISODE_ROWS)

    def flush(rows: int) -> None:  # write the first `rows` pending episode rows as one row group
        nonlocal pending
        table = pa.concat_tables(pending)
        block, rest = table.slice(0, rows), table.slice(rows)
        chunk, file = meta_out.place(rows, block.slice(0, 1).nbytes)
        for name, value in (("meta/episodes/chunk_index", chunk), ("meta/episodes/file_index", file)):
            i = block.schema.get_field_index(name)
            block = block.set_column(i, block.schema.field(i), pa.array([value] * rows, pa.int64()))
        meta_out.write(block, (chunk, file))
        pending = [rest] if rest.num_rows else []

    try:
        for root in roots:
            eps, data = _read_set(root)
            tasks = eps.column("tasks").to_pylist()
            task = task if task is not None else tasks[0]
            if any(t != task for t in tasks):
                raise RuntimeError(f"{root}: tasks {tasks[0]} differ from {task}; merge_sets takes one task")
            data = _shifted(_shifted(data, "episode_index", n_eps), "index", n_frames)
            lengths = eps.column("dataset_to_index").to_numpy() - eps.column("dataset_from_index").to_numpy()
            row_bytes = data.slice(0, 1).nbytes
            places = [data_out.place(int(n), row_bytes) for n in lengths]  # (chunk, file) per episode
            start = 0
            for where, run in itertools.groupby(zip(places, lengths, strict=True), key=lambda p: p[0]):
                rows = int(sum(n for _, n in run))  # consecutive episodes bound for one file: one block
                data_out.write(data.slice(start, rows), where)
                start += rows
            stats.add(data)  # counted as it is written; the quantiles read back only a few bins
            pending.append(_moved_episodes(eps, n_eps, n_frames, places))
            n_eps, n_frames = n_eps + eps.num_rows, n_frames + data.num_rows
            while sum(t.num_rows for t in pending) >= EPISODE_ROWS:
                flush(EPISODE_ROWS)
        if pending:
            flush(sum(t.num_rows for t in pending))
    finally:
        data_out.close()
        meta_out.close()
    tasks = [task[0]] if task else []
    write_tasks(pd.DataFrame({"task_index": range(len(tasks))}, index=pd.Index(tasks, name="task")), dest)
    info.total_episodes, info.total_frames, info.total_tasks = n_eps, n_frames, len(tasks)
    info.splits = {"train": f"0:{n_eps}"}
    write_info(info, dest)
    write_frame_stats(dest, template, stats)
    return n_eps


def _stats_template(roots: list[Path]) -> dict:
    """The stats.json entries write_frame_stats fills: the first set's keys and stat names; a key that
    is no data feature (none in the engine's sets) gets LeRobot's aggregate of every set's stats."""
    from lerobot.datasets.io_utils import load_info

    first = read_json(roots[0] / "meta" / "stats.json")
    other = [k for k in first if k not in load_info(roots[0]).features]
    if not other:
        return first
    from lerobot.datasets.compute_stats import aggregate_stats
    from lerobot.datasets.io_utils import load_stats
    from lerobot.datasets.utils import serialize_dict

    agg = aggregate_stats([{k: v for k, v in load_stats(r).items() if k in other} for r in roots])
    return first | serialize_dict(agg)


def remove_shards(out: Path) -> None:
    """Once the run's stamp says complete: the shards are in the merged set."""
    shutil.rmtree(Path(out) / SHARDS_DIR, ignore_errors=True)


# ----------------------------------------------------------------------------------------------
# The run: its checks, its plan (resumed where a run stopped), its report
# ----------------------------------------------------------------------------------------------
def read_source(src: Path) -> dict:
    """The source set's columns, or DataError with one line saying what is wrong with it."""
    import datasets
    import pyarrow.parquet as pq

    if not src.is_dir():
        raise DataError(f"--src {src} is not a folder; make a PushT set with gen_demos_pusht.py")
    problem = schema_problem(src, pusht_env.OBS_DIM, pusht_env.ACT_DIM)
    if problem:
        raise DataError(f"--src {problem} (a PushT set has state [10] and action [2])")
    feats = read_json(src / "meta" / "info.json")["features"]
    for key, want in (("observation.state", pusht_env.STATE_NAMES), ("action", pusht_env.ACTION_NAMES)):
        names = feats[key].get("names")
        if names is not None and list(names) != list(want):
            raise DataError(f"--src {src}: {key} names {names} are not PushT's {list(want)}")
    problem = fps_problem(src, pusht_env.FPS)
    if problem:
        raise DataError(f"--src {problem}")
    for f in sorted(src.glob("data/*/*.parquet")) + sorted(src.glob("meta/episodes/*/*.parquet")):
        try:
            pq.read_metadata(f)
        except Exception as e:  # pyarrow's errors for a broken file vary by what is broken
            raise DataError(
                f"--src {src}: {f.relative_to(src)} is not a readable parquet file ({e})"
            ) from None
    datasets.logging.set_verbosity(datasets.logging.CRITICAL)  # a failure below is our one line, not a log
    check_hf_cache()  # a cache we cannot write is named as the cause, not the set
    try:
        arrays = load_arrays(src, keys=("observation.state", "action", "episode_index"))
    except Exception as e:  # pyarrow, datasets and lerobot each raise their own kinds for a broken set
        first = (str(e).strip().splitlines() or [""])[0][:160]
        raise DataError(
            f"--src {src} could not be read as a LeRobot dataset ({type(e).__name__}: {first})"
        ) from None
    if len(arrays["action"]) == 0:
        raise DataError(f"--src {src} holds no frames")
    problem = frames_problem(src, arrays)
    if problem:
        raise DataError(f"--src {problem}")
    if arrays["episode_index"].max() >= SEED_BLOCK:
        raise DataError(f"--src {src}: episode indices must be below {SEED_BLOCK:,} (the seed block)")
    return arrays


def check_out(out: Path, src: Path, config: dict | None = None) -> dict | None:
    """None for a new run; the run's stamp for a run of this command (with `config`, when given);
    DataError for anything else: --out overlapping --src, data this program did not make, other settings."""
    o, s = out.resolve(), src.resolve()
    if o == s or s in o.parents or o in s.parents:
        raise DataError(f"--out {out} overlaps --src {src}; the source is never written: pick another --out")
    stamp = check_ours(out, "engine")
    if stamp is None or config is None or stamp.get("config") == config:
        return stamp
    old = stamp.get("config") or {}
    diff = ", ".join(
        f"{k} differs" if isinstance(v, dict) else f"{k}={old.get(k)} (now {v})"
        for k, v in config.items()
        if old.get(k) != v
    )
    raise DataError(f"{out} holds a run with other settings ({diff}); pass another --out")


def length_stats(hist: dict) -> dict:
    """min, max, mean, median and p90 of episode lengths from {length: count}."""
    if not hist:
        return {}
    x = np.repeat([int(n) for n in hist], list(hist.values()))
    return {
        "min": int(x.min()),
        "max": int(x.max()),
        "mean": float(x.mean()),
        "median": float(np.median(x)),
        "p90": float(np.quantile(x, 0.9)),
    }


def report_of(stamps: list[dict], failures_known, base: dict) -> dict:
    """The generation report from the shard stamps (so a resumed run reports the whole run)."""
    failures, lengths = Counter(dict.fromkeys(failures_known, 0)), Counter()
    per_source = {}  # source episode -> [attempts, kept]
    for st in stamps:
        failures.update(st["failures"])
        lengths.update(st["lengths"])
        for e, (att, kept) in st["per_source"].items():
            t = per_source.setdefault(e, [0, 0])
            t[0], t[1] = t[0] + att, t[1] + kept
    attempts, kept = sum(st["attempts"] for st in stamps), sum(st["kept"] for st in stamps)
    return base | {
        "attempts": attempts,
        "kept": kept,
        "yield": kept / attempts if attempts else 0.0,
        "failures": dict(failures),
        "frames": sum(st["frames"] for st in stamps),
        "episode_length": length_stats(lengths),
        "per_source": {
            e: {"attempts": a, "kept": k, "yield": k / a}
            for e, (a, k) in sorted(per_source.items(), key=lambda kv: int(kv[0]))
        },
    }


def run(src: Path, out: Path, settings: dict, *, workers: int, ray: str | None = None, quiet=False) -> dict:
    """Grow `out` from the PushT set `src` with `settings` (SETTINGS) on `workers` local processes or
    on Ray (ch37.executors.run): a run cut off earlier is finished, its whole shards kept; a complete
    run is left as it is. A second run on `out` waits for the first. Returns the generation report."""
    t0 = time.perf_counter()
    problem = check_out_path(out)  # a path the file system or pyarrow cannot take, before anything
    if problem:
        raise DataError(problem)
    check_out(out, src)  # before reading the source: a folder that is not ours is refused at once
    arrays = read_source(src)
    n_sources = len(np.unique(arrays["episode_index"]))
    problem = plan_memory_problem(n_sources, settings["per_demo"], available_memory())
    if problem:
        raise DataError(problem)
    config = settings | {"source": source_identity(arrays), "engine": ENGINE_VERSION, "versions": versions()}
    check_out(out, src, config)  # every refusal comes before anything is created
    out.mkdir(parents=True, exist_ok=True)
    lock(out)
    try:
        stamp = check_out(out, src, config)  # again: a run waited for may have changed the folder
        bad = foreign(out, stamp) if stamp else []
        if bad:  # before anything is written: a resume deletes what a killed run left, never these
            raise DataError(
                f"{out} holds files this command did not write ({names(bad)}); move them elsewhere "
                "and run the same command again (nothing was changed)"
            )
        old = read_json(out / REPORT_NAME) if stamp and stamp.get("complete") else None
        if old:
            remove_shards(out)  # left over if a run was stopped right after its stamp
            print("already complete (same command, same settings); nothing to do")
            return old
        return _generate(
            src, out, engine.sources(arrays), config, workers=workers, ray=ray, quiet=quiet, t0=t0
        )
    finally:
        unlock(out)  # the lock file left empty: a finished run's folder is the same bytes every time


def _generate(src, out, sources, config, *, workers, ray, quiet, t0) -> dict:
    run_stamp = {"made_by": MADE_BY, "kind": "engine", "config": config, "complete": False}
    write_atomic(out / STAMP_NAME, dump_json(run_stamp))  # the folder is ours from here on
    shards = plan(sources, config["per_demo"], config["shard_size"])
    done = finished(out, config, len(shards))
    todo = [i for i in range(len(shards)) if i not in done]
    scratch = None if ray not in (None, "local") else str(out / SHARDS_DIR)  # this machine's disk
    (out / SHARDS_DIR).mkdir(exist_ok=True)
    tasks = [
        (i, shards[i], {e: sources[e] for e in sorted({e for e, _ in shards[i]})}, config, scratch)
        for i in todo
    ]
    timing = {"start_s": 0.0}  # of seconds_generate: starting or joining Ray
    if not tasks:
        executor = "none (every shard was already made)"
    elif ray is None:
        executor = f"local processes ({min(workers, len(tasks))})"
    else:
        executor = f"ray {f'local, {workers} CPUs' if ray == 'local' else ray}"
    results = executors.run(make_shard, tasks, workers=workers, ray=ray, timing=timing) if tasks else []
    t_gen = time.perf_counter()
    made = _collect(out, results, done, config["versions"], total=sum(map(len, shards)), quiet=quiet)
    t_merge = time.perf_counter()
    merged = merge(out, len(shards), run_stamp)
    seconds = time.perf_counter() - t0
    vers = {"python": platform.python_version(), **config["versions"]}
    if ray is not None:
        vers["ray"] = version("ray")
    report = report_of(
        [done[i] for i in range(len(shards))],
        engine.FAILURES[config["mode"]],
        {
            "source": {"path": str(src.resolve()), **config["source"]},
            "settings": {k: config[k] for k in SETTINGS},
            "shards": {"total": len(shards), "made_this_run": len(todo), "reused": len(shards) - len(todo)},
            "executor": executor,
            "seconds": seconds,
            "seconds_generate": t_merge - t_gen,
            "seconds_start_executor": timing["start_s"],
            "seconds_merge": time.perf_counter() - t_merge,
            # worker seconds (summed over the shards made by this run) inside seconds_generate
            "seconds_write": sum(done[i].get("seconds_write", 0.0) for i in todo),
            "demos_per_s": made / seconds,
            "command": " ".join(shlex.quote(x) for x in [Path(sys.executable).name, *sys.argv]),
            "versions": vers,
            "dataset": {  # pyav: torchcodec without system FFmpeg logs a long traceback before falling back
                "episodes": merged,
                "load": f"LeRobotDataset('local/pusht_aug', root='{out}', video_backend='pyav')",
            },
        },
    )
    assert report["kept"] == merged, (report["kept"], merged)
    write_atomic(out / REPORT_NAME, dump_json(round_floats(report, 4)))
    write_atomic(out / STAMP_NAME, dump_json(run_stamp | {"complete": True}))
    remove_shards(out)
    if merged == 0:
        print(f"no attempt succeeded: no dataset written, only {out / REPORT_NAME}")
    return report


def _collect(out: Path, results, done: dict, versions: dict, *, total: int, quiet: bool) -> int:
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
