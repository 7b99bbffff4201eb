"""The demo generators' command line, for any task of the engine with an expert:

    python gen_demos.py --task gym_pusht --episodes 50 --seed 0 --out DIR [--noise N] [--video]

main(task, argv) parses and checks the flags (ch37.config), then datagen.demos.generate;
gen_demos_pusht.py and gen_demos_aloha.py are main(PUSHT) and main(ALOHA). --task picks a task of
datagen.known_tasks() by name. Every problem a user can fix is one line and exit 2, Ctrl-C 130.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

if __name__ == "__main__":
    from ch37.process import headless_gl

    headless_gl()  # --video renders headless: before the imports below load mujoco

from ch37 import config
from ch37.config import FINITE, NON_NEGATIVE, POSITIVE, flag
from ch37.errors import DataError, run_main
from ch37.seeds import MAX_SEED, SEED_BLOCK
from datagen import Task, generate, known_tasks, video_problem
from lerobot_v3 import IMAGE_SIZE


@dataclass(frozen=True)
class Args:
    """Generate expert demos as a local LeRobot v3 dataset."""

    episodes: int = flag(
        50,
        "number of episodes to roll out (default 50)",
        bound=POSITIVE,
        at_most=SEED_BLOCK,
        why="the demo seeds of one --seed",
    )
    seed: int = flag(
        0,
        "dataset seed >= 0; seeds never share an episode",
        bound=NON_NEGATIVE,
        at_most=MAX_SEED,
        why="every env seed fits in 63 bits",
    )
    out: Path = flag(None, "a new dataset folder", type=Path)
    noise: float = flag(0.0, "std of Gaussian action noise, m/s", bound=FINITE)
    video: bool = flag(
        False,
        f"also record a {IMAGE_SIZE}x{IMAGE_SIZE} top-down video (needs a headless GL backend)",
        action=argparse.BooleanOptionalAction,
    )
    quiet: bool = flag(False, "no progress bar")


def main(emb: Task, argv=None) -> int:
    """The generators' command line; every problem a user can fix is one line and exit 2, Ctrl-C 130."""
    return run_main(_main, emb, argv)


def _main(emb: Task, argv=None) -> int:
    from ch37.ownership import check_out_path, holds_data

    doc = f"Generate {emb.name} expert demos as a local LeRobot v3 dataset."
    a = config.parse(
        Args,
        argv,
        description=doc,
        defaults=dict(out=Path(f"outputs/demos/{emb.name}"), noise=emb.default_noise),
    )
    if holds_data(a.out):
        raise DataError(f"{a.out} already holds data; pick another --out (nothing was touched)")
    if problem := check_out_path(a.out, "--out") or (video_problem(emb) if a.video else None):
        raise DataError(problem)
    s = generate(emb, a.out, episodes=a.episodes, seed=a.seed, noise=a.noise, video=a.video, quiet=a.quiet)
    wrote = f"wrote {s['episodes']} {emb.name} episodes, {s['frames']} frames to {a.out}"
    print(f"{wrote} (expert successes {s['successes']}/{s['episodes']})")
    return 0


def by_task(argv=None) -> int:
    """`python gen_demos.py --task NAME ...`: main with the engine's task of that name."""
    return run_main(_by_task, argv)


def _by_task(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--task")
    got, rest = p.parse_known_args(argv)
    tasks = {name: t for name, t in known_tasks().items() if t.expert_class is not None}
    if got.task not in tasks:
        given = "no --task" if got.task is None else f"--task {got.task!r}"
        raise DataError(f"{given}: pick one of {', '.join(tasks)} (the engine's tasks with an expert)")
    return _main(tasks[got.task], rest)


if __name__ == "__main__":
    sys.exit(by_task())
