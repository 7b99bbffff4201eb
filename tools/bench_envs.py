"""Speed and competence of the two embodiments and their experts. Prints figures; asserts nothing.

    python -m tools.bench_envs              # 50 seeded starts per expert and noise level
    python -m tools.bench_envs --starts 10  # quicker

For each env: control steps per second under random actions, the expert's success count and
median episode length with and without action noise, and demo generation frames per second
(rollout + LeRobot v3 write, through the same code as gen_demos_*.py).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import gen_demos_aloha
import gen_demos_pusht
from ch37 import errors
from ch37.config import check, parser
from datagen import demos, rollout

NOISE = {"pusht": 0.08, "aloha": 0.05}  # the noisy-expert levels the success targets are stated at


def steps_per_second(emb, n: int = 3000) -> float:
    env, rng = emb.make_env(), np.random.default_rng(0)
    env.reset(0)
    acts = rng.uniform(-1, 1, (n, len(emb.spec.action_names))).astype(np.float32)
    t0 = time.perf_counter()
    for a in acts:
        if env.step(a)[2]:
            env.reset(int(rng.integers(1 << 30)))
    return n / (time.perf_counter() - t0)


def expert_record(emb, starts: int, noise: float) -> tuple[int, float]:
    env, wins, lengths = emb.make_env(), 0, []
    for s in range(starts):
        ep = rollout(env, emb.expert_class(noise=noise, seed=s), env.reset(s))
        wins += ep["success"]
        lengths.append(len(ep["action"]))
    return wins, statistics.median(lengths)


def generation_fps(emb, episodes: int = 12) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        s = demos.generate(
            emb, Path(tmp) / "set", episodes=episodes, seed=0, noise=emb.default_noise, quiet=True
        )
        return s["frames"] / (time.perf_counter() - t0)


def main(argv: list[str]) -> int:
    p = parser(__doc__, prog="python -m tools.bench_envs")
    p.add_argument("--starts", type=int, default=50, help="seeded starts per expert and noise level")
    a = p.parse_args(argv)
    check(a, positive=["starts"])
    warm = Path(tempfile.mkdtemp()) / "warm"  # the first set pays for the imports and the encoder
    demos.generate(gen_demos_pusht.PUSHT, warm, episodes=1, seed=0, noise=0.0, quiet=True)
    head = f"{'expert (noise 0)':>22s} {'expert (noisy)':>26s} {'demo gen frames/s':>18s}"
    print(f"{'env':6s} {'steps/s':>9s} {head}")
    for emb in (gen_demos_pusht.PUSHT, gen_demos_aloha.ALOHA):
        sps = steps_per_second(emb)
        w0, m0 = expert_record(emb, a.starts, 0.0)
        wn, mn = expert_record(emb, a.starts, NOISE[emb.name])
        fps = generation_fps(emb)
        print(
            f"{emb.name:6s} {sps:9.0f} {f'{w0}/{a.starts}, median {m0:g} steps':>22s} "
            f"{f'{wn}/{a.starts} at {NOISE[emb.name]}, median {mn:g}':>26s} {fps:18.0f}"
        )
    return 0


if __name__ == "__main__":
    errors.main(main)
