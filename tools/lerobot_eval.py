"""A LeRobot policy checkpoint in our PushT env, on the lesson's held-out starts, judged by the lesson's rule.

    python -m tools.lerobot_eval --policy OUT/checkpoints/last/pretrained_model --seed 0 --eval_episodes 50

--policy is a `pretrained_model` folder that lerobot-train wrote (diffusion, ACT, ... trained on a set
this project wrote: observation.state [10] and observation.environment_state [8], no images). Episode
j starts from gymnasium.make("ch37/PushT-v0").reset(seed=ch37.seeds.env_seed(seed, "eval", j)), the
starts the lesson's measure region evaluates its MLP on (gym_envs.py); it succeeds when the env says
terminated (the lesson's success rule) and ends there or truncated (300 control steps). The policy is
reset and torch is seeded with that start's seed before each episode, so an episode's outcome does not
depend on the ones before it. Prints the success rate with the lesson's 95% Wilson interval and writes
it as JSON beside the policy folder (--out to choose): lerobot_eval_seed{S}_n{N}.json.

Exit codes: 0 ok, 2 bad input (one `error:` line).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bc_recipe import wilson  # the lesson's 95% interval
from ch37 import config
from ch37.config import NON_NEGATIVE, POSITIVE, flag
from ch37.errors import DataError
from ch37.errors import main as run
from ch37.ownership import check_own_result, dump_json, round_floats, write_atomic
from ch37.seeds import MAX_SEED, SEED_BLOCK

KIND = "lerobot_eval"  # marks the JSON as this tool's, so a re-run may replace it and nothing else


def load_policy(path: Path, device: str):
    """(policy, preprocessor, postprocessor) from a `pretrained_model` folder, moved to `device`."""
    if not (path / "config.json").is_file():
        raise DataError(f"--policy {path} is not a LeRobot pretrained_model folder (no config.json)")
    from lerobot_v3 import hub_offline

    hub_offline()  # a file missing from the folder is an error, never a download from the Hub
    try:
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        cfg = PreTrainedConfig.from_pretrained(path)
        cfg.device = device
        policy = get_policy_class(cfg.type).from_pretrained(path, config=cfg)
        pre, post = make_pre_post_processors(
            cfg, pretrained_path=str(path), preprocessor_overrides={"device_processor": {"device": device}}
        )
    except (KeyboardInterrupt, MemoryError):
        raise
    except Exception as e:  # draccus, safetensors and torch each raise their own kinds on a bad folder
        why = " ".join(str(e).split())[:160]
        raise DataError(f"--policy {path} cannot be loaded ({type(e).__name__}: {why})") from e
    return policy.eval(), pre, post


def observation_builder(policy):
    """obs float32 (10,) or (B, 10) -> the batch the policy reads: its input features of our state, (B, D)"""
    import torch

    import pusht_env
    from lerobot_v3.dataset import ENV_STATE_KEY, columns

    ours = {
        "observation.state": list(range(pusht_env.OBS_DIM)),
        ENV_STATE_KEY: columns(pusht_env.STATE_NAMES, pusht_env.ENV_STATE_NAMES),
    }
    feats = policy.config.input_features
    for key, f in feats.items():
        if key not in ours:
            raise DataError(f"the policy reads {key!r}; our PushT env gives {sorted(ours)} (no images)")
        if tuple(f.shape) != (len(ours[key]),):
            raise DataError(f"the policy's {key} has shape {tuple(f.shape)}; PushT's is ({len(ours[key])},)")
    act = policy.config.output_features.get("action")
    if act is None or tuple(act.shape) != (pusht_env.ACT_DIM,):
        raise DataError(f"the policy's action has shape {act and tuple(act.shape)}; PushT's is (2,)")
    device = policy.config.device

    def build(obs):  # (10,) or (B, 10)
        x = torch.as_tensor(np.atleast_2d(obs), dtype=torch.float32)
        batch = {key: x[:, ours[key]].to(device) for key in feats}
        return batch | {"task": [pusht_env.TASK] * len(x)}

    return build


def evaluate(policy, pre, post, seeds, name: str = "the policy") -> list[dict]:
    """One episode per env seed through Gymnasium (gym_envs' ch37/PushT-v0, whose reset(seed=s) is the
    lesson's start s): {"seed", "success", "steps"}, the lesson's success rule (terminated = success).
    A non-finite action is the checkpoint's problem (`name` it), a DataError, never the env's ValueError."""
    import gymnasium as gym
    import torch

    import gym_envs

    env, build = gym.make(gym_envs.PUSHT_ID), observation_builder(policy)
    episodes = []
    with torch.inference_mode():
        for s in seeds:
            torch.manual_seed(s)  # diffusion's sampling noise: a pure function of the start
            policy.reset()  # empties the action queue and the observation history
            (obs, _), terminated, truncated, steps = env.reset(seed=s), False, False, 0
            while not (terminated or truncated):
                action = post(policy.select_action(pre(build(obs))))[0].cpu().numpy().astype(np.float32)
                if not np.all(np.isfinite(action)):  # m/s
                    raise DataError(
                        f"{name} gives a non-finite action {action} (start seed {s}, step {steps}): its "
                        "weights or normalization statistics hold NaN or inf; pass another checkpoint"
                    )
                obs, _, terminated, truncated, _ = env.step(action)
                steps += 1
            episodes.append({"seed": s, "success": bool(terminated), "steps": steps})
    env.close()
    return episodes


@dataclass(frozen=True)
class Args:
    """A LeRobot policy checkpoint in our PushT env, on the lesson's held-out starts."""

    policy: Path = flag(None, "a pretrained_model folder from lerobot-train", type=Path, required=True)
    seed: int = flag(
        0,
        "the lesson's --seed: which held-out starts",
        bound=NON_NEGATIVE,
        at_most=MAX_SEED,
        why="every env seed fits in 63 bits",
    )
    eval_episodes: int = flag(
        50,
        "held-out starts (the lesson's --eval_episodes)",
        bound=POSITIVE,
        at_most=SEED_BLOCK,
        why="one seed block",
        aliases=("episodes",),
    )
    device: str = flag("auto", "auto: cuda > mps > cpu", choices=("auto", "cpu", "cuda", "mps"))
    out: Path = flag(None, "JSON path (default: beside --policy)", type=Path)


def main(argv: list[str] | None = None) -> int:
    a = config.parse(Args, argv, prog="python -m tools.lerobot_eval", description=__doc__)
    if not a.policy.is_dir():
        raise DataError(f"--policy {a.policy} is not a folder")
    out = a.out or a.policy.parent / f"{KIND}_seed{a.seed}_n{a.eval_episodes}.json"
    check_own_result(out, KIND)  # ours from an earlier run may be replaced; anything else is the user's
    from ch37.cli import pick_device
    from ch37.seeds import env_seed

    device = pick_device(a.device)
    policy, pre, post = load_policy(a.policy, device)
    seeds = [env_seed(a.seed, "eval", j) for j in range(a.eval_episodes)]
    t0 = time.perf_counter()
    episodes = evaluate(policy, pre, post, seeds, name=f"--policy {a.policy}")
    k, n = sum(e["success"] for e in episodes), len(episodes)
    result = {
        "kind": KIND,
        "policy": str(a.policy.resolve()),
        "policy_type": policy.config.type,
        "device": device,
        "seed": a.seed,
        "episodes": n,
        "successes": k,
        "success": k / n,
        "ci95": wilson(k / n, n),
        "per_episode": episodes,
    }
    write_atomic(out, dump_json(round_floats(result)))
    lo, hi = result["ci95"]
    print(
        f"{policy.config.type} on {n} held-out PushT starts (seed {a.seed}): success {k / n:.2f} "
        f"[{lo:.2f}, {hi:.2f}] ({k}/{n}, {time.perf_counter() - t0:.0f} s on {device})"
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    run(main)
