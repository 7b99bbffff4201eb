"""Grow a PushT or ALOHA demo set: perturbed starts of every source demo, re-solved or replayed, kept on
success.

    python augment_demos.py --src my_pusht --per_demo 100 --out big [--workers N | --ray [ADDRESS]]

--src is any LeRobot v3 set of a task the engine knows (datagen.TASKS), the task read from the set's
robot_type (or its widths): PushT (observation.state float32[10], action float32[2], laid out as in
pusht_env.py; gen_demos_pusht.py) or the ALOHA handoff (float32[10], float32[6], aloha_env.py;
gen_demos_aloha.py), one made by those commands or your own. It is only read. --out becomes a
LeRobot v3 set of the kept demos, every frame carrying its provenance (aug.source_episode: the source
episode it was made from, the one replayed; aug.start: the task's start it was solved from, for PushT
block x, y, yaw, pusher x, y), with generation_report.json beside it.

The same command gives the same bytes with any --workers, with --ray, and after a killed run is
re-run (finished shards are kept, only the missing ones are made). The engine lives in datagen/:
engine.py (one attempt), pusht.py and aloha.py (the tasks), shards.py (the run: shards, stats, report);
the merge in lerobot_v3/merge.py, local processes or Ray in ch37.parallel.map_jobs.
"""

from __future__ import annotations

import os
from pathlib import Path

from ch37 import config, errors
from ch37.seeds import MAX_SEED, SEED_BLOCK

SHARD_SIZE = 100  # attempts per shard: a small parquet set, seconds of one core (docs/engine.md)


def parse(argv=None):
    p = config.parser(__doc__.split("\n\n")[0], prog="augment_demos.py")
    p.add_argument("--src", type=Path, required=True, help="source LeRobot v3 PushT set (never modified)")
    p.add_argument(
        "--per_demo",
        type=int,
        default=10,
        help=f"attempts (perturbed starts) per source episode (default 10, at most {SEED_BLOCK:,})",
    )
    p.add_argument(
        "--out", type=Path, required=True, help="output folder: new, or a run of this command to finish"
    )
    p.add_argument("--seed", type=int, default=0, help=">= 0; seeds draw disjoint perturbations (default 0)")
    sigmas = config.CHAPTER.aug_pos_sigma, config.CHAPTER.aug_yaw_sigma
    most = f"(at most {config.SIGMA_MAX:g})"
    p.add_argument(
        "--pos_sigma", type=float, default=sigmas[0], help=f"m; block and pusher xy noise std {most}"
    )
    p.add_argument("--yaw_sigma", type=float, default=sigmas[1], help=f"rad; block yaw noise std {most}")
    p.add_argument(
        "--mode",
        choices=("resolve", "replay"),  # datagen.Task.modes (not imported here: --help stays instant)
        default="resolve",
        help="resolve: the expert solves each start; replay: the source path transformed into the new "
        "object poses, executed open-loop, kept only on success (MimicGen's move; on PushT most attempts "
        "fail here; ALOHA replays subtask by subtask)",
    )
    p.add_argument(
        "--select",
        choices=("own", "nearest"),  # datagen.engine.SELECTS
        default="own",
        help="the source a replay transforms: own (the attempt's own source demo, the default) or nearest "
        "(the source demo whose objects start nearest the new start: MimicGen's selection); --mode replay",
    )
    p.add_argument(
        "--workers", type=int, default=min(8, os.cpu_count() or 1), help="local processes (default: cores)"
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="run on Ray: alone, a local Ray with --workers CPUs; with ADDRESS, join that cluster",
    )
    p.add_argument(
        "--shard_size",
        type=int,
        default=SHARD_SIZE,
        help="attempts per shard (default 100); part of the run's settings",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    a = p.parse_args(argv)
    positive, finite = ("per_demo", "workers", "shard_size"), ("pos_sigma", "yaw_sigma")
    at_most = {"seed": MAX_SEED, "pos_sigma": config.SIGMA_MAX, "yaw_sigma": config.SIGMA_MAX}
    at_most["per_demo"] = SEED_BLOCK  # an attempt index stays in one seed block, like an episode's
    config.check(a, positive=positive, non_negative=("seed",), finite=finite, at_most=at_most)
    if a.select != "own" and a.mode != "replay":
        p.error("--select nearest chooses the source a replay transforms; use it with --mode replay")
    return a


def main(argv=None) -> int:
    a = parse(argv)
    from datagen import shards

    settings = {k: getattr(a, k) for k in shards.SETTINGS}
    r = shards.run(shards.task_of(a.src), a.src, a.out, settings, workers=a.workers, ray=a.ray, quiet=a.quiet)
    made, reused = r.get("kept_this_run", r["kept"]), r["shards"]["reused"]
    rate = f" in {r['seconds']:.1f} s ({r['demos_per_s']:.1f} demos/s)"
    if reused:  # a resumed run: what it made now (and its rate) apart from what an earlier run made
        rate = f"; {made} made now{rate}, {r['kept'] - made} resumed from {reused} shards of an earlier run"
    print(
        f"augment_demos: {r['attempts']} attempts, {r['kept']} kept (yield {r['yield']:.3f}), "
        f"{r['frames']} frames{rate} -> {a.out} (LeRobot v3; report {a.out / shards.REPORT_NAME})"
    )
    return 0


if __name__ == "__main__":
    errors.main(main)
