"""Grow a demo set of any task the engine knows (PushT, ALOHA, LeRobot's gym-pusht): perturbed starts of
every source demo, re-solved or replayed, kept on success.

    python augment_demos.py --src my_pusht --attempts_per_demo 100 --out big [--workers N | --ray [ADDRESS]]

--src is any LeRobot v3 set of a task the engine knows (datagen.known_tasks()), grown as the task the set
names (meta/engine_task.json, in every set this project writes), or as --task NAME; a set written elsewhere
is matched by its robot_type (or its widths): PushT (observation.state float32[10], action float32[2],
laid out as in pusht_env.py; gen_demos_pusht.py), the ALOHA handoff (float32[10], float32[6], aloha_env.py;
gen_demos_aloha.py) or LeRobot's gym-pusht (observation.state float32[2] and
observation.environment_state float32[16] as lerobot/pusht_keypoints records them, action float32[2];
gen_demos.py --task gym_pusht), one made by those commands or your own. It is only read. --out becomes a
LeRobot v3 set of the kept demos, every frame carrying its provenance (aug.source_episode: the source
episode it was made from, the one replayed; aug.start: the task's start it was solved from, for PushT
block x, y, yaw, pusher x, y), with generation_report.json beside it.

The same command gives the same bytes with any --workers, with --ray, and after a killed run is
re-run (finished shards are kept, only the missing ones are made). The engine lives in datagen/:
engine.py (one attempt), pusht.py and aloha.py (the tasks), run.py (the run, in the order of its steps:
source_check.py, plan.py, resume.py, shards.py, report.py); the merge in lerobot_v3/merge.py, local
processes or Ray in ch37.parallel.map_jobs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ch37 import config, errors
from ch37.config import NON_NEGATIVE, POSITIVE, flag
from ch37.seeds import MAX_SEED, SEED_BLOCK

SHARD_SIZE = 300  # attempts per shard: ~1 MB of parquet, 1-2 s of one core (PushT; docs/engine.md)


@dataclass(frozen=True)
class Args(config.Perturbation, config.Mode, config.Ray):
    """Grow a demo set of any task the engine knows (PushT, ALOHA, LeRobot's gym-pusht): perturbed starts
    of every source demo, re-solved or replayed, kept on success."""

    src: Path = flag(
        None, "source LeRobot v3 set of a task the engine knows (never modified)", type=Path, required=True
    )
    # Attempts, not kept demos: every perturbed start is tried once and kept only on success, so a run
    # keeps yield x this many per source (the lesson's --aug_per_demo counts kept demos instead).
    attempts_per_demo: int = flag(
        10,
        f"attempts (perturbed starts) per source episode, every one made (at most {SEED_BLOCK:,})",
        bound=POSITIVE,
        at_most=SEED_BLOCK,  # an attempt index stays in one seed block, like an episode's
        aliases=("per_demo",),
    )
    task: str = flag(
        None,
        "the engine task --src is grown as (default: the task the set names in meta/engine_task.json, as "
        "every set this project writes does; a set written elsewhere: the one task its robot_type and widths "
        "fit)",
    )
    out: Path = flag(None, "output folder: new, or a run of this command to finish", type=Path, required=True)
    seed: int = flag(0, ">= 0; seeds draw disjoint perturbations", bound=NON_NEGATIVE, at_most=MAX_SEED)
    select: str = flag(
        "own",
        "the source a replay transforms: own (the attempt's own source demo) or nearest (the source demo "
        "whose objects start nearest the new start: MimicGen's selection); --aug_mode replay or replay_live",
        choices=("own", "nearest"),  # datagen.engine.SELECTS
    )
    shard_size: int = flag(SHARD_SIZE, "attempts per shard; part of the run's settings", bound=POSITIVE)
    quiet: bool = flag(False, "no progress bar")


def parse(argv=None):
    a = config.parse(Args, argv, prog="augment_demos.py", description=__doc__.split("\n\n")[0])
    a.workers = config.default_workers() if a.workers is None else a.workers
    if a.select != "own" and a.aug_mode == "resolve":
        raise errors.DataError(
            "--select nearest chooses the source a replay transforms; use it with --aug_mode replay or "
            "replay_live (see --help)"
        )
    return a


def settings(a):
    """The run's settings (datagen.plan.Settings) from the flags: the engine's own names for them."""
    from datagen.plan import Settings

    return Settings(
        mode=a.aug_mode,
        select=a.select,
        attempts_per_demo=a.attempts_per_demo,
        seed=a.seed,
        pos_sigma=a.aug_pos_sigma,
        yaw_sigma=a.aug_yaw_sigma,
        shard_size=a.shard_size,
    )


def main(argv=None) -> int:
    a = parse(argv)
    from datagen.report import REPORT_NAME
    from datagen.run import run

    r = run(a.src, a.out, settings(a), task=a.task, workers=a.workers, ray=a.ray, quiet=a.quiet)
    made, reused = r.get("kept_this_run", r["kept"]), r["shards"]["reused"]
    rate = f" in {r['seconds']:.1f} s ({r['demos_per_s']:.1f} demos/s)"
    if reused:  # a resumed run: what it made now (and its rate) apart from what an earlier run made
        rate = f"; {made} made now{rate}, {r['kept'] - made} resumed from {reused} shards of an earlier run"
    print(
        f"augment_demos: {r['attempts']} attempts, {r['kept']} kept (yield {r['yield']:.3f}), "
        f"{r['frames']} frames{rate} -> {a.out} (LeRobot v3; report {a.out / REPORT_NAME})"
    )
    return 0


if __name__ == "__main__":
    errors.main(main)
