"""The demo generators' command line, for any task of the engine with an expert:

    python gen_demos.py --task gym_pusht --episodes 50 --seed 0 --out DIR [--noise N] [--video]

main(task, argv) parses and checks the flags (ch37.config), then datagen.demos.generate;
gen_demos_pusht.py and gen_demos_aloha.py are main(PUSHT) and main(ALOHA). --task picks a task of
datagen.known_tasks() by name (--help lists them, each with its noise unit, and needs none). Every problem
a user can fix is one line and exit 2, Ctrl-C 130.
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
    """the demo set: its episodes, their seed and noise, where it goes, its video"""

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
    noise: float = flag(0.0, "std of Gaussian action noise, in the task's action units", bound=FINITE)
    video: bool = flag(
        False,
        f"also record a {IMAGE_SIZE}x{IMAGE_SIZE} top-down video (a MuJoCo task renders with EGL unless "
        "MUJOCO_GL names another backend)",
        action=argparse.BooleanOptionalAction,
    )
    quiet: bool = flag(False, "no progress bar")


@dataclass(frozen=True)
class ByTask(Args):
    """gen_demos.py's flags: Args and the task (its choices and units are known at run time)."""

    task: str = flag(None, "the task whose expert is rolled out")


def main(emb: Task, argv=None) -> int:
    """The generators' command line; every problem a user can fix is one line and exit 2, Ctrl-C 130."""
    return run_main(_main, emb, argv)


def _main(emb: Task | None, argv=None, tasks: dict | None = None) -> int:
    """Generate demos of `emb`. tasks: {name: task} that gen_demos.py's --task picks from (None: a
    generator of the one task emb); with tasks, emb None stands for a --task missing or not among them,
    where --help is answered (every task's units listed) and anything else refused."""
    from ch37.ownership import check_out_path, holds_data

    noise = "std of Gaussian action noise"
    if emb is not None:
        doc = f"Generate {emb.name} expert demos as a local LeRobot v3 dataset."
        defaults = dict(out=Path(f"outputs/demos/{emb.name}"), noise=emb.default_noise)
        helps = dict(noise=f"{noise}, {emb.expert.noise_unit}")
    else:
        doc = "Generate expert demos of a task of the engine (--task) as a local LeRobot v3 dataset."
        units = "; ".join(f"{name} {t.expert.noise_unit}" for name, t in tasks.items())
        defaults = {}
        helps = dict(noise=f"{noise}, in the task's units ({units}); default: the task's own")
        helps["out"] = "a new dataset folder (default: outputs/demos/TASK)"
    if tasks is not None:
        helps["task"] = "the task whose expert is rolled out: " + ", ".join(
            f"{name} ({t.title})" for name, t in tasks.items()
        )
    a = config.parse(Args if tasks is None else ByTask, argv, description=doc, defaults=defaults, helps=helps)
    if emb is None:
        given = "no --task" if a.task is None else f"--task {a.task!r}"
        raise DataError(f"{given}: pick one of {', '.join(tasks)} (the engine's tasks with an expert)")
    if holds_data(a.out):
        raise DataError(f"{a.out} already holds data; pick another --out (nothing was touched)")
    if problem := check_out_path(a.out, "--out") or (video_problem(emb) if a.video else None):
        raise DataError(problem)
    s = generate(emb, a.out, episodes=a.episodes, seed=a.seed, noise=a.noise, video=a.video, quiet=a.quiet)
    wrote = f"wrote {s['episodes']} {emb.name} episodes, {s['frames']} frames to {a.out}"
    lost = (
        f"; {s['unstable']} more blew the simulation up (unstable) and were not written"
        if s["unstable"]
        else ""
    )
    print(f"{wrote} (expert successes {s['successes']}/{s['episodes']}{lost})")
    return 0


def by_task(argv=None) -> int:
    """`python gen_demos.py --task NAME ...`: main with the engine's task of that name."""
    return run_main(_by_task, argv)


def _by_task(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    tasks = {name: t for name, t in known_tasks().items() if t.expert is not None}
    # the task first (its units and defaults are the help's), then every flag in one parse, --task with them
    p = argparse.ArgumentParser(add_help=False, allow_abbrev=False, exit_on_error=False)
    p.add_argument("--task")
    try:
        name = p.parse_known_args(argv)[0].task
    except argparse.ArgumentError:  # "--task" without a name: the full parse says so
        name = None
    return _main(tasks.get(name), argv, tasks)


if __name__ == "__main__":
    sys.exit(by_task())
