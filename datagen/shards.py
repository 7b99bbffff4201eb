"""A data-engine run on disk: fixed shards of attempts, each a LeRobot v3 set with a stamp, merged once.

    run(src, out, settings, workers=, ray=, quiet=) -> the generation report   (augment_demos.py)

The attempts (source episode e, k) are listed e-major and cut into shards of `shard_size`
attempts, so a shard's contents depend on the run's settings alone, never on the worker count
or the executor. A worker makes one shard (datagen.engine.run_attempts on its attempts, then
datagen.engine.save) and returns its files as bytes; the caller saves them, so a worker on another
machine needs no shared disk. Layout of a run's folder:

    OUT/scale_data_stamp.json          the run's stamp: made_by, kind "engine", its settings, complete
    OUT/.scale_data.lock               held while a run writes OUT (ch37.ownership.lock)
    OUT/shards/shard-00007/            a finished shard: a LeRobot v3 set and its stamp (counts)
    OUT/shards/.shard-00007.partial/   a shard being saved; discarded by the next run
    OUT/shards/.shard-00007.scratch/   a worker's scratch for a shard (local executors)
    OUT/data, OUT/meta                 the merged LeRobot v3 set (merge_sets)
    OUT/generation_report.json         attempts, kept, yield, failures, timing (written last)

The merge (merge_sets) reads each shard's data and episodes parquet once, moves its episode and
frame indices by those before it, and writes every file of the set once: data and meta/episodes
files of up to LeRobot's 100 MB (cut by row counts, never where a shard ends, so the data files'
bytes do not depend on --shard_size), tasks, info.json, and stats.json over all frames
(lerobot_v3.frame_stats, counted as the frames are written). It costs one read and one write per
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
import functools
import hashlib
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

from ch37 import code_digest
from ch37.errors import DataError
from ch37.ownership import (
    LEFTOVER,
    LOCK_NAME,
    MADE_BY,
    STAMP_NAME,
    changed_files,
    check_ours,
    check_out_path,
    digests,
    dump_json,
    file_list,
    is_ours,
    lock,
    names,
    read_json,
    read_stamp,
    round_floats,
    unlock,
    write_atomic,
)
from ch37.parallel import map_jobs
from ch37.process import available_memory
from ch37.seeds import SEED_BLOCK
from datagen import engine, lockstep
from datagen.task import Perturbation, Task, known_tasks
from lerobot_v3.dataset import check_hf_cache, fps_problem, frames_problem, load_arrays, schema_problem
from lerobot_v3.merge import merge_sets

SHARDS_DIR = "shards"
REPORT_NAME = "generation_report.json"
MERGE_DIR = ".merged.partial"  # the merge is built here, then its data/ and meta/ are renamed into OUT
# What a run writes directly in OUT and in OUT/shards (both its own, under its lock); anything else
# there is the user's, and a resume refuses to start rather than delete it (datagen.shards.foreign).
RUN_NAMES = {STAMP_NAME, LOCK_NAME, REPORT_NAME, SHARDS_DIR, "data", "meta", MERGE_DIR}
SHARD_NAMES = re.compile(r"shard-\d{5}|\.shard-\d{5}\.(partial|scratch)")
# A run's settings in the engine's names (augment_demos.py maps its flags onto them): attempts_per_demo is
# the attempts per source episode, every one made (datagen.engine.grow's per_source counts kept demos).
SETTINGS = ("mode", "select", "attempts_per_demo", "seed", "pos_sigma", "yaw_sigma", "shard_size")
# How a run's stamps and its report store them (OUT's stamp, every shard's, generation_report.json; a
# resume compares them): attempts_per_demo under its first name "per_demo", kept so that what a run
# writes stays the same bytes, for readers of earlier runs. Nothing but this mapping reads "per_demo".
STORED = {"attempts_per_demo": "per_demo"}
STORED_SETTINGS = tuple(STORED.get(k, k) for k in SETTINGS)


def stored(settings: dict) -> dict:
    """`settings` (SETTINGS' names) as a run's stamps store them (STORED_SETTINGS' names)."""
    return {STORED.get(k, k): v for k, v in settings.items()}


def attempts_per_demo(config: dict) -> int:
    """The attempts per source episode of a run's stored config."""
    return config[STORED["attempts_per_demo"]]


def engine_version(task: Task) -> str:
    """A digest of the code a run of `task` runs: this module, the task's module and every project module
    either imports (the engine, the writer and merge, the task's env and expert: ch37.code_files reads
    them from what was imported, no list), so a shard made by other code is never mixed into a run.
    Computed when a run starts, not at import."""
    return code_digest((sys.modules[__name__], sys.modules[type(task).__module__]))


def versions() -> dict:
    """The packages whose versions can change a shard's bytes (read once per process: every shard's
    stamp names them, and each lookup parses the package's metadata, ~5 ms)."""
    return dict(_versions())


@functools.cache
def _versions() -> tuple:
    return tuple((name, version(name)) for name in ("lerobot", "mujoco", "numpy", "pyarrow"))


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


# Memory the plan holds per attempt (bytes): its (e, k) tuple and slot, about 100 B measured (docs/engine.md,
# "Figures behind constants"), doubled for the shard tasks and results that follow it.
ATTEMPT_BYTES = 200


def plan_memory_problem(
    n_sources: int, attempts_per_demo: int, free: int | None, flag: str = "--attempts_per_demo"
) -> str | None:
    """None if a plan of n_sources x attempts_per_demo attempts fits in `free` bytes (None: unknown), else
    why, naming the command's `flag` for attempts_per_demo."""
    attempts = n_sources * attempts_per_demo
    if free is None or attempts * ATTEMPT_BYTES <= free:
        return None
    return (
        f"{flag} {attempts_per_demo:,} x {n_sources} source episodes = {attempts:,} attempts need about "
        f"{attempts * ATTEMPT_BYTES / 2**30:,.1f} GB of memory to plan, more than the "
        f"{free / 2**30:,.1f} GB available here; lower {flag} (or run it in parts with --seed)"
    )


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


def plan(episodes, attempts_per_demo: int, shard_size: int) -> list[list[tuple[int, int]]]:
    """The attempts (e, k), e-major, cut into shards of shard_size (the last may be shorter)."""
    jobs = [(int(e), k) for e in episodes for k in range(attempts_per_demo)]
    return [jobs[i : i + shard_size] for i in range(0, len(jobs), shard_size)]


def shard_dir(out: Path, index: int) -> Path:
    return Path(out) / SHARDS_DIR / f"shard-{index:05d}"


# ----------------------------------------------------------------------------------------------
# Worker side: one shard, returned as bytes
# ----------------------------------------------------------------------------------------------
def make_shard(index: int, jobs, sources: dict, config: dict, scratch: str | None = None, sims=None) -> dict:
    """Run the shard's attempts and write its kept episodes as a LeRobot v3 set (in a temp folder
    under `scratch`, the system's when None), then read it back as bytes. sims: the worker's
    datagen.engine.Simulators, kept between its shards (a new one when None).

    Returns {"files": {relative path: bytes}, "stamp": the shard's stamp}. The stamp holds the
    counts the report needs (attempts, kept, failures by reason, per source, episode lengths) and
    seconds_write, the seconds the worker spent writing the set and reading it back."""
    task = known_tasks()[config["task"]]
    how = Perturbation(config["seed"], config["pos_sigma"], config["yaw_sigma"])
    # = engine.run_attempts', bit for bit (tests/test_lockstep.py), attempts stepped together
    results = lockstep.attempts_lockstep(
        task, sources, jobs, how, mode=config["mode"], select=config["select"], sims=sims
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
        "versions": versions(),
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


def stamp_problem(path: Path, stamp: dict, jobs, reasons) -> str | None:
    """None if a shard stamp's own fields agree with the shard's files and its place in the plan, else
    what disagrees. The run's report is built from these fields, so each is checked: attempts and the
    attempts per source against the shard's `jobs`; kept and frames against its info.json (whose
    sha256 the stamp's files check); failures (of `reasons`) + kept = attempts; the episode lengths'
    histogram against kept and frames; kept per source within its attempts, summing to kept."""
    info = read_json(path / "meta" / "info.json") if (path / "meta" / "info.json").exists() else {}
    try:
        failures = {str(k): int(v) for k, v in stamp["failures"].items()}
        lengths = {int(n): int(c) for n, c in stamp["lengths"].items()}
        per_source = {str(e): (int(a), int(k)) for e, (a, k) in stamp["per_source"].items()}
        attempts, kept, frames = (stamp[k] for k in ("attempts", "kept", "frames"))
        ok = (
            attempts == len(jobs)
            and kept == info.get("total_episodes", 0)
            and frames == info.get("total_frames", 0)
            and set(failures) <= set(reasons)
            and min(failures.values(), default=0) >= 0
            and sum(failures.values()) + kept == attempts
            and min([*lengths, *lengths.values()], default=1) > 0
            and sum(lengths.values()) == kept
            and sum(n * c for n, c in lengths.items()) == frames
            and {e: a for e, (a, _) in per_source.items()} == dict(Counter(str(e) for e, _ in jobs))
            and all(0 <= k <= a for a, k in per_source.values())
            and sum(k for _, k in per_source.values()) == kept
        )
    except (AttributeError, KeyError, TypeError, ValueError):  # a field missing or of the wrong kind
        ok = False
    return None if ok else "its stamp's counts disagree with its files"


def finished(out: Path, config: dict, shards: list) -> dict[int, dict]:
    """{shard index: stamp} of the whole shards of this run (`shards`: its plan) whose files still have
    the sha256 their stamp records and whose stamp's counts agree with them (stamp_problem); the rest of
    shards/ is removed (a damaged shard with one printed line).

    Only called on a run folder of `config` that foreign() found clean: all under shards/ is ours."""
    root = Path(out) / SHARDS_DIR
    done = {}
    if not root.is_dir():
        return done
    key = run_key(config)
    for path in sorted(root.iterdir()):
        m = re.fullmatch(r"shard-(\d{5})", path.name)
        stamp = read_stamp(path) if m else None
        if is_ours(stamp) and stamp.get("run") == key and int(m.group(1)) < len(shards):
            damaged = changed_files(path, stamp)  # its files against the sha256 its stamp recorded
            why = f"{names(damaged)} differs from its stamp" if damaged else None
            why = why or stamp_problem(
                path, stamp, shards[int(m.group(1))], known_tasks()[config["task"]].failures[config["mode"]]
            )
            if not why:
                done[int(m.group(1))] = stamp
                continue
            print(f"shard {m.group(1)} is damaged ({why}); making it again")
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


def remove_shards(out: Path) -> None:
    """Once the run's stamp says complete: the shards are in the merged set."""
    shutil.rmtree(Path(out) / SHARDS_DIR, ignore_errors=True)


# ----------------------------------------------------------------------------------------------
# The run: its checks, its plan (resumed where a run stopped), its report
# ----------------------------------------------------------------------------------------------
# The episodes table's columns that say where each episode's frames are (LeRobot v3)
EPISODE_COLUMNS = ("episode_index", "length", "dataset_from_index", "dataset_to_index")
EPISODE_COLUMNS += ("data/chunk_index", "data/file_index")


def state_range_problem(
    task: Task, src: Path, states: np.ndarray, actions: np.ndarray | None = None
) -> str | None:
    """None if every state (N, obs_dim) and action (N, act_dim) lies in the task's documented ranges
    (task.state_ranges, task.action_ranges; 1e-6 of slack: float32 rounding), else the first dimension
    outside, how many frames and the first row. A value outside is no state or action of the task: its
    attempts could only fail."""
    for key, values, ranges in (
        ("observation.state", states, task.state_ranges),
        ("action", actions, task.action_ranges),
    ):
        for i, (name, (lo, hi)) in enumerate(ranges.items() if values is not None else ()):
            bad = (values[:, i] < lo - 1e-6) | (values[:, i] > hi + 1e-6)
            if bad.any():
                row, what = int(np.argmax(bad)), key.split(".")[-1]
                return (
                    f"--src {src}: {key} {name} (index {i}) is {float(values[row, i]):g} in "
                    f"{int(bad.sum())} frames, the first at row {row}; the {task.title} env's range for it "
                    f"is [{lo:g}, {hi:g}]: this is not a {task.title} {what}"
                )
    return None


def task_of(src: Path) -> Task:
    """The task whose sets `src` is (of datagen.task.known_tasks()), read from its meta/info.json: the task
    whose env's ROBOT_TYPE the set records, or, for a set without one, the one task whose state and action
    widths it has. DataError (one line) for a set that fits no task. A folder without a readable
    info.json is left to read_source's checks (as PushT's, the engine's first task), which name what is
    wrong with it."""
    try:
        info = json.loads((Path(src) / "meta" / "info.json").read_text())
        feats = info["features"]
        shapes = tuple(list(feats[k]["shape"]) for k in ("observation.state", "action"))
    except (OSError, ValueError, KeyError, TypeError):
        return known_tasks()["pusht"]
    robot = info.get("robot_type")
    if robot:
        fits = [t for t in known_tasks().values() if t.env_module.ROBOT_TYPE == robot]
    else:
        fits = [
            t for t in known_tasks().values() if shapes == ([t.env_module.OBS_DIM], [t.env_module.ACT_DIM])
        ]
    if len(fits) == 1:
        return fits[0]
    known = "; ".join(
        f"{t.title}: robot_type '{t.env_module.ROBOT_TYPE}', observation.state [{t.env_module.OBS_DIM}], "
        f"action [{t.env_module.ACT_DIM}] (make one with {t.generator})"
        for t in known_tasks().values()
    )
    raise DataError(
        f"--src {src} fits no task of the engine (robot_type {robot!r}, observation.state {shapes[0]}, "
        f"action {shapes[1]}); it grows {known}"
    )


def read_source(task: Task, src: Path) -> dict:
    """The source set's columns (a set of `task`), or DataError with one line saying what is wrong with it."""
    import datasets
    import pyarrow.parquet as pq

    m, title = task.env_module, task.title
    if not src.is_dir():
        raise DataError(f"--src {src} is not a folder; make a {title} set with {task.generator}")
    problem = schema_problem(src, m.OBS_DIM, m.ACT_DIM)
    if problem:
        raise DataError(f"--src {problem} (a {title} set has state [{m.OBS_DIM}] and action [{m.ACT_DIM}])")
    feats = read_json(src / "meta" / "info.json")["features"]
    for key, want in (("observation.state", m.STATE_NAMES), ("action", m.ACTION_NAMES)):
        names = feats[key].get("names")
        if names is not None and list(names) != list(want):
            raise DataError(f"--src {src}: {key} names {names} are not {title}'s {list(want)}")
    problem = fps_problem(src, m.FPS)
    if problem:
        raise DataError(f"--src {problem}")
    for f in sorted(src.glob("data/*/*.parquet")) + sorted(src.glob("meta/episodes/*/*.parquet")):
        try:
            schema = pq.read_schema(f)
        except Exception as e:  # pyarrow's errors for a broken file vary by what is broken
            raise DataError(
                f"--src {src}: {f.relative_to(src)} is not a readable parquet file ({e})"
            ) from None
        missing = (
            [c for c in EPISODE_COLUMNS if c not in schema.names]
            if f.relative_to(src).parts[1] == "episodes"
            else []
        )
        if missing:
            raise DataError(
                f"--src {src}: {f.relative_to(src)} lacks the columns {', '.join(missing)} (a LeRobot v3 "
                "episodes table says where each episode's frames are); regenerate or repair the set"
            )
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
    problem = state_range_problem(task, src, arrays["observation.state"], arrays["action"])
    if problem:
        raise DataError(problem)
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


def run(
    task: Task, src: Path, out: Path, settings: dict, *, workers: int, ray: str | None = None, quiet=False
) -> dict:
    """Grow `out` from the set `src` of `task` with `settings` (SETTINGS) on `workers` local processes or
    on Ray (ch37.parallel.map_jobs): a run cut off earlier is finished, its whole shards kept; a complete
    run is left as it is. A second run on `out` waits for the first. Returns the generation report."""
    t0 = time.perf_counter()
    problem = check_out_path(out)  # a path the file system or pyarrow cannot take, before anything
    if problem:
        raise DataError(problem)
    check_out(out, src)  # before reading the source: a folder that is not ours is refused at once
    arrays = read_source(task, src)
    n_sources = len(np.unique(arrays["episode_index"]))
    problem = plan_memory_problem(n_sources, settings["attempts_per_demo"], available_memory())
    if problem:
        raise DataError(problem)
    config = stored(settings) | {
        "task": task.name,
        "source": source_identity(arrays),
        "engine": engine_version(task),
    }
    config["versions"] = versions()
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
    shards = plan(sources, attempts_per_demo(config), config["shard_size"])
    done = finished(out, config, shards)
    todo = [i for i in range(len(shards)) if i not in done]
    note = many_files_note(len(shards), sum(map(len, shards)), config["shard_size"], out) if todo else None
    if note:
        print(note, flush=True)
    scratch = None if ray not in (None, "local") else str(out / SHARDS_DIR)  # this machine's disk
    (out / SHARDS_DIR).mkdir(exist_ok=True)
    # A shard gets the sources its attempts start from; with --select nearest a replay may choose any
    # source, so every shard gets them all.
    pool = sources if config["select"] == "nearest" else None
    # One Simulators for every shard: a forked worker fills its own copy and keeps it between its shards
    # (its lanes' envs are made once); on Ray each shard's task gets an empty one.
    sims = engine.Simulators()
    tasks = [
        (
            i,
            shards[i],
            pool or {e: sources[e] for e in sorted({e for e, _ in shards[i]})},
            config,
            scratch,
            sims,
        )
        for i in todo
    ]
    timing = {"start_s": 0.0}  # of seconds_generate: starting or joining Ray
    if not tasks:
        executor = "none (every shard was already made)"
    elif ray is None:
        executor = f"local processes ({min(workers, len(tasks))})"
    else:
        executor = f"ray {f'local, {workers} CPUs' if ray == 'local' else ray}"
    how = dict(workers=workers, ray=ray, ordered=False, star=True, timing=timing)
    results = map_jobs(make_shard, tasks, **how) if tasks else []
    t_gen = time.perf_counter()
    made = _collect(out, results, done, config["versions"], total=sum(map(len, shards)), quiet=quiet)
    t_merge = time.perf_counter()
    merged = merge(out, len(shards), run_stamp)
    seconds = time.perf_counter() - t0
    vers = {"python": platform.python_version(), **config["versions"]}
    if ray is not None:
        vers["ray"] = version("ray")
    task = config["task"]
    report = report_of(
        [done[i] for i in range(len(shards))],
        known_tasks()[task].failures[config["mode"]],
        {
            "source": {"path": str(src.resolve()), **config["source"]},
            "settings": {k: config[k] for k in STORED_SETTINGS},
            "shards": {"total": len(shards), "made_this_run": len(todo), "reused": len(shards) - len(todo)},
            "executor": executor,
            "seconds": seconds,
            "seconds_generate": t_merge - t_gen,
            "seconds_start_executor": timing["start_s"],
            "seconds_merge": time.perf_counter() - t_merge,
            # worker seconds (summed over the shards made by this run) inside seconds_generate
            "seconds_write": sum(done[i].get("seconds_write", 0.0) for i in todo),
            "kept_this_run": made,  # the rest of "kept" was made by an earlier run (its shards reused)
            "demos_per_s": made / seconds,  # this run's: the demos it made over its seconds
            "command": " ".join(shlex.quote(x) for x in [Path(sys.executable).name, *sys.argv]),
            "versions": vers,
            "dataset": {  # pyav: torchcodec without system FFmpeg logs a long traceback before falling back
                "episodes": merged,
                "load": f"LeRobotDataset('local/{config['task']}_aug', root='{out}', video_backend='pyav')",
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
