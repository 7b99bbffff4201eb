"""What a run finds in its --out, and what it leaves there for a re-run to finish.

    claim(out, src) -> RunClaim     before the source is read: --out judged, nothing created; the one
                                    object the later steps get of the folder
    taken(claim, config, shards)    held under its lock while the run writes (judged again there): the
                                    claim then holds a complete run's report, or the run's stamp and
                                    the whole shards of an earlier run of these settings
    complete(claim, report)         the report written, the run stamped complete, its shards removed

A run's stamp (OUT/scale_data_stamp.json: made_by, kind "engine", its settings, complete) is what a
re-run reads: the same command on the same --out finishes the run (only the missing shards are made)
or, once complete, leaves it as it is; other settings are refused. A shard is kept only if its files
have the sha256 its stamp records and the stamp's counts agree with them (stamp_problem). What a run
writes is known: RUN_NAMES in OUT, SHARD_NAMES in OUT/shards, each shard's files (its stamp), data/ and
meta/ (listed in the run's stamp before they are renamed into OUT); a resume that finds anything else
refuses, changing nothing (foreign).
"""

from __future__ import annotations

import contextlib
import re
import shutil
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ch37.errors import DataError
from ch37.ownership import (
    LEFTOVER,
    LOCK_NAME,
    MADE_BY,
    STAMP_NAME,
    changed_files,
    check_ours,
    check_out_path,
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
from datagen.plan import RunConfig, run_key
from datagen.report import REPORT_NAME
from datagen.shards import MERGE_DIR, SHARD_NAMES, SHARDS_DIR, remove_shards
from datagen.task import failures_of, known_tasks

# What a run writes directly in OUT and in OUT/shards (both its own, under its lock); anything else
# there is the user's, and a resume refuses to start rather than delete it (foreign).
RUN_NAMES = {STAMP_NAME, LOCK_NAME, REPORT_NAME, SHARDS_DIR, "data", "meta", MERGE_DIR}


@dataclass
class RunClaim:
    """An engine run's --out as judged (ch37.ownership.Claim is a results folder's): claim() makes it,
    taken() fills it in under the lock, the steps that write the run read it."""

    out: Path
    stamp: dict | None  # the run's stamp: an earlier run's as found (None: a new run); this run's once begun
    report: dict | None = None  # the report of a run already complete: nothing to do
    done: dict[int, dict] = field(default_factory=dict)  # {shard index: stamp}: an earlier run's whole shards

    def refuse_other_settings(self, run: RunConfig) -> None:
        """DataError if the folder holds a run of settings other than `run`'s."""
        config = run.stored()
        if self.stamp is None or self.stamp.get("config") == config:
            return
        old = self.stamp.get("config") or {}
        diff = ", ".join(
            f"{k} differs" if isinstance(v, dict) else f"{k}={old.get(k)} (now {v})"
            for k, v in config.items()
            if old.get(k) != v
        )
        raise DataError(f"{self.out} holds a run with other settings ({diff}); pass another --out")


def claim(out: Path, src: Path) -> RunClaim:
    """Before the source is read, creating nothing: DataError (one line) unless `out` and `src` are apart
    (the source is never written, not even a probe file), `out` is a path this program can write, and it
    is new or a run of this command."""
    o, s = out.resolve(), src.resolve()
    if o == s or s in o.parents or o in s.parents:
        raise DataError(f"--out {out} overlaps --src {src}; the source is never written: pick another --out")
    problem = check_out_path(out)  # a path the file system or pyarrow cannot take, before anything
    if problem:
        raise DataError(problem)
    return RunClaim(out, check_ours(out, "engine"))


@contextlib.contextmanager
def taken(c: RunClaim, config: RunConfig, shards: list):
    """Hold c.out for a run of `config` (ch37.ownership.lock; a second run on it waits for the first),
    judged again under the lock (a run waited for may have changed the folder); files this command did
    not write are refused before anything is written (foreign). c then holds the report of a run already
    complete, or the whole shards of `shards` (the plan) an earlier run made and this run's stamp. The
    lock file is left empty at the end: a finished run's folder is the same bytes every time."""
    c.refuse_other_settings(config)  # every refusal comes before anything is created
    c.out.mkdir(parents=True, exist_ok=True)
    lock(c.out)
    try:
        c.stamp = check_ours(c.out, "engine")  # again: a run waited for may have changed the folder
        c.refuse_other_settings(config)
        bad = foreign(c.out, c.stamp) if c.stamp else []
        if bad:  # before anything is written: a resume deletes what a killed run left, never these
            raise DataError(
                f"{c.out} holds files this command did not write ({names(bad)}); move them elsewhere "
                "and run the same command again (nothing was changed)"
            )
        c.report = read_json(c.out / REPORT_NAME) if c.stamp and c.stamp.get("complete") else None
        if c.report:
            remove_shards(c.out)  # left over if a run was stopped right after its stamp
        else:
            c.done = finished(c.out, config, shards)
            # this run's stamp, not yet complete (the merge records the files it writes in it)
            c.stamp = {"made_by": MADE_BY, "kind": "engine", "config": config.stored(), "complete": False}
            write_atomic(c.out / STAMP_NAME, dump_json(c.stamp))
        yield c
    finally:
        unlock(c.out)


def complete(c: RunClaim, report: dict) -> None:
    """Write the run's report (floats rounded to 4 places), then stamp the run complete, then remove its
    shards: they are in the merged set."""
    write_atomic(c.out / REPORT_NAME, dump_json(round_floats(report, 4)))
    write_atomic(c.out / STAMP_NAME, dump_json(c.stamp | {"complete": True}))
    remove_shards(c.out)


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


def finished(out: Path, config: RunConfig, shards: list) -> dict[int, dict]:
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
                path,
                stamp,
                shards[int(m.group(1))],
                failures_of(known_tasks()[config.task])[config.settings.mode],
            )
            if not why:
                done[int(m.group(1))] = stamp
                continue
            print(f"shard {m.group(1)} is damaged ({why}); making it again")
            shutil.rmtree(path)
        else:
            shutil.rmtree(path)  # a shard cut off mid-save, one from other settings, a killed scratch
    return done
