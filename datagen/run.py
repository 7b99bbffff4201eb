"""A data-engine run on disk: fixed shards of attempts, each a LeRobot v3 set with a stamp, merged once.

    run(src, out, settings, workers=, ray=, quiet=) -> the generation report   (augment_demos.py)

The run reads in one direction: this module says the order of its steps, starts the workers and times
them; each step lives in a module named for its job, and those alone call ch37.ownership:

    datagen.source_check   which task --src is, whether the engine can grow it, its identity
    datagen.plan           the settings as stamped, the attempts cut into shards, the memory they need
    datagen.resume         --out claimed and judged once (a RunClaim, passed to the later steps), held
                           under its lock, the run's stamp, an earlier run's shards judged
    datagen.shards         a shard made by a worker (a local process or a Ray task: ch37.parallel),
                           saved as it arrives, the shards merged (lerobot_v3.merge_sets), removed
    datagen.report         the generation report

Layout of a run's folder:

    OUT/scale_data_stamp.json          the run's stamp: made_by, kind "engine", its settings, complete
    OUT/.scale_data.lock               held while a run writes OUT (ch37.ownership.lock)
    OUT/shards/shard-00007/            a finished shard: a LeRobot v3 set and its stamp (counts)
    OUT/shards/.shard-00007.partial/   a shard being saved; discarded by the next run
    OUT/shards/.shard-00007.scratch/   a worker's scratch for a shard (local executors)
    OUT/data, OUT/meta                 the merged LeRobot v3 set (merge_sets)
    OUT/generation_report.json         attempts, kept, yield, failures, timing (written last)

The shards are removed once the run is stamped complete; the same command re-run after a kill makes
only the missing shards.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from ch37 import code_digest
from ch37.errors import DataError
from ch37.parallel import map_jobs
from ch37.process import available_memory
from datagen import engine, resume
from datagen.plan import RunConfig, Settings, plan, plan_memory_problem, versions
from datagen.report import REPORT_NAME, describe, report_of
from datagen.shards import SHARDS_DIR, collect, make_shard, many_files_note, merge
from datagen.source_check import read_source, source_identity, successful_only, task_of
from datagen.task import Task, failures_of, known_tasks


def engine_version(task: Task) -> str:
    """A digest of the code a run of `task` runs: this module, the task's module and every project module
    either imports (the run's steps, the engine, the writer and merge, the task's env and expert:
    ch37.code_files reads them from what was imported, no list), so a shard made by other code is never
    mixed into a run. Computed when a run starts, not at import."""
    return code_digest((sys.modules[__name__], sys.modules[type(task).__module__]))


def run(
    src: Path, out: Path, settings: Settings, *, task: str | None = None, workers: int, ray=None, quiet=False
) -> dict:
    """Grow `out` from the set `src` (of the task it names, or `task`: task_of) with `settings` on
    `workers` local processes or on Ray (ch37.parallel.map_jobs): a run cut off earlier is finished, its
    whole shards kept; a complete run is left as it is. A second run on `out` waits for the first.
    Returns the generation report."""
    task = task_of(src, task)
    t0 = time.perf_counter()
    claim = resume.claim(out, src)  # before reading the source: a folder not ours is refused at once
    arrays, note = successful_only(read_source(task, src), src)
    if note:
        print(note, flush=True)
    n_sources = len(np.unique(arrays["episode_index"]))
    problem = plan_memory_problem(n_sources, settings.attempts_per_demo, available_memory())
    if problem:
        raise DataError(problem)
    config = RunConfig(settings, task.name, source_identity(arrays), engine_version(task), versions(task))
    sources = engine.sources(arrays)
    shards = plan(sources, settings.attempts_per_demo, settings.shard_size)
    with resume.taken(claim, config, shards):
        if claim.report:
            print("already complete (same command, same settings); nothing to do")
            return claim.report
        return _generate(src, claim, sources, shards, config, workers=workers, ray=ray, quiet=quiet, t0=t0)


def _generate(src, claim, sources, shards, config: RunConfig, *, workers, ray, quiet, t0) -> dict:
    out, done, settings = claim.out, claim.done, config.settings
    todo = [i for i in range(len(shards)) if i not in done]
    note = many_files_note(len(shards), sum(map(len, shards)), settings.shard_size, out) if todo else None
    if note:
        print(note, flush=True)
    scratch = None if ray not in (None, "local") else str(out / SHARDS_DIR)  # this machine's disk
    (out / SHARDS_DIR).mkdir(exist_ok=True)
    # A shard gets the sources its attempts start from; with --select nearest a replay may choose any
    # source, so every shard gets them all.
    pool = sources if settings.select == "nearest" else None
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
    made = collect(out, results, done, config.versions, total=sum(map(len, shards)), quiet=quiet)
    t_merge = time.perf_counter()
    merged = merge(out, len(shards), claim.stamp)
    seconds = time.perf_counter() - t0
    report = report_of(
        [done[i] for i in range(len(shards))],
        failures_of(known_tasks()[config.task])[settings.mode],
        describe(src, out, config, ray=ray, episodes=merged)
        | {
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
        },
    )
    assert report["kept"] == merged, (report["kept"], merged)
    resume.complete(claim, report)
    if merged == 0:
        print(f"no attempt succeeded: no dataset written, only {out / REPORT_NAME}")
    return report
