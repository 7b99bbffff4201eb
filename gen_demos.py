"""The demo generators' command line, shared by gen_demos_pusht.py and gen_demos_aloha.py:
main(embodiment, argv) parses and checks the flags (ch37.config), then datagen.demos.generate.
Every problem a user can fix is one line and exit 2, Ctrl-C 130.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ch37 import config
from ch37.errors import DataError, run_main
from ch37.seeds import MAX_SEED, SEED_BLOCK
from datagen import Embodiment, check_gl, generate
from lerobot_v3 import IMAGE_SIZE


def main(emb: Embodiment, argv=None) -> int:
    """The generators' command line; every problem a user can fix is one line and exit 2, Ctrl-C 130."""
    return run_main(_main, emb, argv)


def _main(emb: Embodiment, argv=None) -> int:
    from ch37.ownership import check_out_path, holds_data

    p = config.parser(f"Generate {emb.name} expert demos as a local LeRobot v3 dataset.")
    p.add_argument("--episodes", type=int, default=50, help="number of episodes to roll out (default 50)")
    p.add_argument("--seed", type=int, default=0, help="dataset seed >= 0; seeds never share an episode")
    p.add_argument("--out", type=Path, default=Path(f"outputs/demos/{emb.name}"), help="a new dataset folder")
    p.add_argument("--noise", type=float, default=emb.default_noise, help="std of Gaussian action noise, m/s")
    p.add_argument(
        "--video",
        action=argparse.BooleanOptionalAction,
        default=False,
        help=f"also record a {IMAGE_SIZE}x{IMAGE_SIZE} top-down video (needs a headless GL backend)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    a = p.parse_args(argv)
    if not 0 < a.episodes <= SEED_BLOCK:
        raise DataError(
            f"--episodes must be in [1, {SEED_BLOCK}] (the demo seeds of one --seed), got {a.episodes}"
        )
    if not 0 <= a.seed <= MAX_SEED:
        raise DataError(f"--seed must be in [0, {MAX_SEED}] (every env seed fits in 63 bits), got {a.seed}")
    config.check(a, finite=("noise",))
    if holds_data(a.out):
        raise DataError(f"{a.out} already holds data; pick another --out (nothing was touched)")
    if problem := check_out_path(a.out, "--out") or (check_gl() if a.video else None):
        raise DataError(problem)
    s = generate(emb, a.out, episodes=a.episodes, seed=a.seed, noise=a.noise, video=a.video, quiet=a.quiet)
    wrote = f"wrote {s['episodes']} {emb.name} episodes, {s['frames']} frames to {a.out}"
    print(f"{wrote} (expert successes {s['successes']}/{s['episodes']})")
    return 0
