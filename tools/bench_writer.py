"""Seconds to write N PushT demos with lerobot_v3.dataset.write_dataset: the one-pass writer vs
LeRobot's per-frame path (what write_dataset did before issue 19), alternating. Asserts nothing.

    python -m tools.bench_writer                 # 1,000 demos of 30 frames, 3 rounds, medians
    python -m tools.bench_writer --demos 200 --rounds 1

The demos are synthetic float32 arrays of the PushT set's features (gen_demos_pusht.py's, with
observation.environment_state filled from the state), so the time is the writer's alone. The
LeRobot path is taken through the same write_dataset (folder, stamp, rename) with per_frame=True.
"""

from __future__ import annotations

import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import gen_demos_pusht
from ch37 import errors
from ch37.config import parser
from ch37.errors import DataError
from datagen import write_dataset
from lerobot_v3 import features


def demos(n: int, frames: int, seed: int = 0) -> list[dict]:
    m = gen_demos_pusht.PUSHT.spec
    rng = np.random.default_rng(seed)
    return [
        {
            "observation.state": rng.standard_normal((frames, len(m.state_names))).astype(np.float32),
            "action": rng.standard_normal((frames, len(m.action_names))).astype(np.float32),
            "next.success": (np.arange(frames) == frames - 1)[:, None],
        }
        for _ in range(n)
    ]


def write_seconds(eps: list[dict], root: Path, per_frame: bool = False) -> float:
    """Seconds to write `eps` with write_dataset (per_frame: every feature through LeRobot's path)."""
    m = gen_demos_pusht.PUSHT.spec
    feats = features(m.state_names, m.action_names, env_state_names=m.env_state_names)
    t = time.perf_counter()
    write_dataset(
        root,
        repo_id="local/bench",
        fps=m.fps,
        robot_type=m.robot_type,
        task=m.task,
        feats=feats,
        episodes=eps,
        stamp={},
        per_frame=per_frame,
    )
    seconds = time.perf_counter() - t
    shutil.rmtree(root)
    return seconds


def main(argv: list[str]) -> int:
    ap = parser(__doc__, prog="python -m tools.bench_writer")
    ap.add_argument("--demos", type=int, default=1000)
    ap.add_argument("--frames", type=int, default=30, help="frames per demo")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    if min(args.demos, args.frames, args.rounds) < 1:
        raise DataError("--demos, --frames and --rounds must be positive")
    eps = demos(args.demos, args.frames)
    times = {"lerobot": [], "direct": []}
    with tempfile.TemporaryDirectory() as tmp:
        write_seconds(eps[:2], Path(tmp) / "warm")  # imports and caches, not timed
        for r in range(args.rounds):
            times["lerobot"].append(write_seconds(eps, Path(tmp) / f"lerobot{r}", per_frame=True))
            times["direct"].append(write_seconds(eps, Path(tmp) / f"direct{r}"))
            print(
                f"round {r}: lerobot {times['lerobot'][-1]:.2f} s, direct {times['direct'][-1]:.2f} s",
                flush=True,
            )
    old, new = (statistics.median(times[k]) for k in ("lerobot", "direct"))
    n = args.demos
    print(f"{n} demos x {args.frames} frames, median of {args.rounds} rounds:")
    print(f"  LeRobot per-frame path {old:.2f} s ({1e3 * old / n:.1f} ms/demo)")
    print(f"  one-pass writer        {new:.2f} s ({1e3 * new / n:.2f} ms/demo), {old / new:.1f}x faster")
    return 0


if __name__ == "__main__":
    errors.main(main)
