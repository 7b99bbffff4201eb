"""How good is the scripted expert on LeRobot's own PushT? GymPushTExpert (datagen/gym_pusht_expert.py) on
gym-pusht (LeRobot's `pusht` extra), judged by gym-pusht's own success (info["is_success"]: more than 95% of
the goal T covered). Prints figures; writes nothing.

    python -m tools.gym_pusht_expert                          # 50 seeded starts, seeds 0..49
    python -m tools.gym_pusht_expert --episodes 200 --seed 1000 --noise 5

Episode i starts from env.reset(seed=SEED + i), gym-pusht's own random start (agent anywhere in
[50, 450]^2, block in [100, 400]^2 at any angle), and runs until success ends it or gym-pusht's
episode limit (300 control steps at 10 Hz, as lerobot-eval's) cuts it. The observation is
"environment_state_agent_pos", flattened as the expert reads it: agent_pos then environment_state.

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ch37 import errors
from ch37.config import check, parser
from datagen.gym_pusht_expert import GymPushTExpert

ENV_ID = "gym_pusht/PushT-v0"
OBS_TYPE = "environment_state_agent_pos"


def flat(obs: dict) -> np.ndarray:
    """gym-pusht's observation as the expert reads it: agent x, y then the 16 keypoint coordinates."""
    return np.concatenate([obs["agent_pos"], obs["environment_state"]])


def episode(env, expert, seed: int) -> dict:
    """One episode from env.reset(seed=seed): success, control steps, final coverage, start pose."""
    obs, info = env.reset(seed=seed)
    start = info["block_pose"]
    expert.reset()
    steps, done = 0, False
    while not done:
        obs, _, terminated, truncated, info = env.step(expert.act(flat(obs)))
        steps += 1
        done = terminated or truncated
    return {
        "seed": seed,
        "success": bool(info["is_success"]),
        "steps": steps,
        "coverage": float(info["coverage"]),
        "start": [round(float(v), 2) for v in start],
    }


def main(argv: list[str]) -> int:
    p = parser(__doc__, prog="python -m tools.gym_pusht_expert")
    p.add_argument("--episodes", type=int, default=50, help="seeded starts")
    p.add_argument("--seed", type=int, default=0, help="episode i resets with seed SEED + i")
    p.add_argument("--noise", type=float, default=0.0, help="std (px) of Gaussian noise on every target")
    a = p.parse_args(argv)
    check(a, positive=["episodes"], non_negative=["seed"], finite=["noise"])
    import gymnasium

    with warnings.catch_warnings():  # pygame (gym-pusht draws with it): pkg_resources is deprecated
        warnings.simplefilter("ignore", UserWarning)
        import gym_pusht  # noqa: F401  (registers gym_pusht/PushT-v0)

        env = gymnasium.make(ENV_ID, obs_type=OBS_TYPE)
    expert = GymPushTExpert(noise=a.noise, seed=a.seed)
    t0 = time.perf_counter()
    runs = [episode(env, expert, a.seed + i) for i in range(a.episodes)]
    wall = time.perf_counter() - t0
    env.close()
    won = [r for r in runs if r["success"]]
    limit = env.spec.max_episode_steps
    print(f"gym-pusht {ENV_ID} ({OBS_TYPE}), episode limit {limit} steps, noise {a.noise:g} px")
    seeds = f"seeds {a.seed}..{a.seed + a.episodes - 1}"
    print(f"success {len(won)}/{a.episodes} = {len(won) / a.episodes:.3f} ({seeds})")
    if won:
        steps = [r["steps"] for r in won]
        print(f"steps to success: mean {np.mean(steps):.1f}, median {np.median(steps):g}, max {max(steps)}")
    for r in runs:
        if not r["success"]:
            print(f"failed: seed {r['seed']}, start block {r['start']}, final coverage {r['coverage']:.3f}")
    print(f"{wall:.1f} s, {sum(r['steps'] for r in runs) / wall:.0f} steps/s")
    return 0


if __name__ == "__main__":
    errors.main(main)
