"""LeRobot's own policies on the chapter's data (docs/lerobot.md): one entry point, a subcommand per job.

    python -m tools.lerobot eval --policy DIR   a LeRobot checkpoint on the lesson's held-out PushT starts
                                                (--task: in another task's env, e.g. aloha_transfer_cube)
    python -m tools.lerobot lab [FLAGS]         LeRobot's diffusion policy trained on the Scale Lab's points
    python -m tools.lerobot table OUT           a LeRobot row (tools/lerobot_row.sh TASK OUT)

`python -m tools.lerobot SUBCOMMAND --help` says what each one does and takes.

Exit codes: 0 ok, 2 bad input (one `error:` line).
"""

from __future__ import annotations

import inspect
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import pusht_env
from bc_recipe import wilson  # the lesson's 95% interval
from ch37 import ROOT, config, errors
from ch37.cli import pick_device
from ch37.config import DEFAULTS, NON_NEGATIVE, POSITIVE, check, flag
from ch37.errors import DataError
from ch37.ownership import check_out_path, check_own_result
from ch37.parallel import map_jobs
from ch37.seeds import MAX_SEED, SEED_BLOCK, env_seed
from lerobot_v3.dataset import ENV_STATE_KEY, columns
from tools.common import mean_ci, parser, subcommands, write_result

# --- eval: a LeRobot checkpoint in our PushT env (or a task's), on the lesson's held-out starts ---------
EVAL_KIND = "lerobot_eval"  # marks the JSON as this tool's, so a re-run may replace it and nothing else
PUSHT = "pusht"  # eval's default task: the lesson's own env, through Gymnasium (gym_envs)
# --task's choices: tasks of the engine's registry (datagen.known_tasks) whose env gives the columns of
# their sets, no images (tests/test_lerobot.py rolls each out)
EVAL_TASKS = (PUSHT, "aloha", "aloha_transfer_cube", "aloha_insertion", "gym_pusht", "pusher")


def task_env(task: str):
    """(env, spec) of `task`, its env on the engine's protocol (reset(seed) -> obs, step(action) -> (obs,
    reward, done, info with "success"); datagen.task.GymnasiumEnv): PushT's is gym_envs' ch37/PushT-v0,
    whose reset(seed=s) is the lesson's start s and whose terminated is the lesson's success; any other
    task's is its own make_env(), its success the task's (transfer-cube: gym-aloha's top reward stage)."""
    from datagen import known_tasks
    from datagen.task import GymnasiumEnv

    t = known_tasks()[task]
    if task != PUSHT:
        return t.make_env(), t.spec
    import gymnasium as gym

    import gym_envs

    return GymnasiumEnv(gym.make(gym_envs.PUSHT_ID), lambda o: np.asarray(o, np.float32), "success"), t.spec


def shown(task: str) -> str:
    """The task's name in printed lines and refusals: our PushT's as the lesson says it."""
    return "PushT" if task == PUSHT else task


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


def observation_builder(policy, spec, name: str):
    """obs float32 (D,) or (B, D), the env's observation vector of the task `spec` (datagen.task.EnvSpec;
    our PushT's: 10) -> the batch the policy reads: its input features of it, as the task's sets record
    them (observation.state: the spec's state_names; observation.environment_state: its env_state_names),
    (B, d) each. `name` names the env in a refusal."""
    names = spec.obs_names or spec.state_names  # the observation vector's entries
    ours = {"observation.state": columns(names, spec.state_names)}
    if spec.env_state_names:
        ours[ENV_STATE_KEY] = columns(names, spec.env_state_names)
    act_dim, text = spec.act_dim, spec.task
    feats = policy.config.input_features
    for key, f in feats.items():
        if key not in ours:
            raise DataError(f"the policy reads {key!r}; our {name} env gives {sorted(ours)} (no images)")
        if tuple(f.shape) != (len(ours[key]),):
            raise DataError(f"the policy's {key} has shape {tuple(f.shape)}; {name}'s is ({len(ours[key])},)")
    act = policy.config.output_features.get("action")
    if act is None or tuple(act.shape) != (act_dim,):
        raise DataError(f"the policy's action has shape {act and tuple(act.shape)}; {name}'s is ({act_dim},)")
    device = policy.config.device

    def build(obs):  # (D,) or (B, D)
        x = torch.as_tensor(np.atleast_2d(obs), dtype=torch.float32)
        batch = {key: x[:, ours[key]].to(device) for key in feats}
        return batch | {"task": [text] * len(x)}

    return build


def evaluate(policy, pre, post, seeds, name: str = "the policy", task: str = PUSHT) -> list[dict]:
    """One episode per env seed in `task`'s env (task_env: PushT's through Gymnasium, whose reset(seed=s)
    is the lesson's start s): {"seed", "success", "steps", "max_reward"}, the task's success rule (PushT's:
    the lesson's, terminated = success), the episode ending there or at the env's limit; max_reward is the
    most the env's reward reached (transfer-cube: gym-aloha's stage, 0..4: how far a failure got). A
    non-finite action is the checkpoint's problem (`name` it), a DataError, never the env's ValueError."""
    env, spec = task_env(task)
    build = observation_builder(policy, spec, shown(task))
    episodes = []
    with torch.inference_mode():
        for s in seeds:
            torch.manual_seed(s)  # diffusion's sampling noise: a pure function of the start
            policy.reset()  # empties the action queue and the observation history
            obs, done, steps, best = env.reset(s), False, 0, -math.inf
            while not done:
                action = post(policy.select_action(pre(build(obs))))[0].cpu().numpy().astype(np.float32)
                if not np.all(np.isfinite(action)):  # the task's units
                    raise DataError(
                        f"{name} gives a non-finite action {action} (start seed {s}, step {steps}): its "
                        "weights or normalization statistics hold NaN or inf; pass another checkpoint"
                    )
                obs, reward, done, info = env.step(action)
                steps, best = steps + 1, max(best, float(reward))
            episodes.append({"seed": s, "success": bool(info["success"]), "steps": steps, "max_reward": best})
    inner = getattr(env, "env", None)  # a Gymnasium env inside (PushT's, gym-pusht's) is closed
    if hasattr(inner, "close"):
        inner.close()
    return episodes


@dataclass(frozen=True)
class Args:
    """A LeRobot policy checkpoint in our PushT env (or a task's), on the lesson's held-out starts."""

    policy: Path = flag(None, "a pretrained_model folder from lerobot-train", type=Path, required=True)
    task: str = flag(
        PUSHT, "the env it rolls out in, and its success rule (default: our PushT)", choices=EVAL_TASKS
    )
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


def eval_main(argv: list[str] | None = None) -> int:
    """A LeRobot policy checkpoint in our PushT env, on the lesson's held-out starts, judged by the lesson's
    rule; or, with --task, in that task's env, judged by its own rule.

        python -m tools.lerobot eval --policy OUT/checkpoints/last/pretrained_model --eval_episodes 50
        python -m tools.lerobot eval --task aloha_transfer_cube --policy DIR --eval_episodes 50

    --policy is a `pretrained_model` folder that lerobot-train wrote (diffusion, ACT, ... trained on a set
    this project wrote: observation.state [10] and observation.environment_state [8], no images). Episode
    j starts from gymnasium.make("ch37/PushT-v0").reset(seed=ch37.seeds.env_seed(seed, "eval", j)), the
    starts the lesson's measure region evaluates its MLP on (gym_envs.py); it succeeds when the env says
    terminated (the lesson's success rule) and ends there or truncated (300 control steps). The policy is
    reset and torch is seeded with that start's seed before each episode, so an episode's outcome does not
    depend on the ones before it. Prints the success rate with the lesson's 95% Wilson interval and writes
    it as JSON beside the policy folder (--out to choose): lerobot_eval_seed{S}_n{N}.json.

    --task T (a task of the engine's registry: aloha, aloha_transfer_cube, aloha_insertion, gym_pusht,
    pusher) rolls the policy out in T's own env (the task's make_env, as gen_demos.py --task T records
    its sets) from reset(env_seed(seed, "eval", j)), and judges it by T's success, which ends the
    episode; else it ends at T's limit (transfer-cube: gym-aloha's AlohaTransferCube-v0 starts and its
    top reward stage, 400 steps, in datagen/tasks/aloha_sim.py: gym-aloha's own env code cannot run on mujoco
    4). The policy must read what T's sets hold, no images: observation.state (transfer-cube: 14
    joints) and, if it reads it, observation.environment_state (the cube's pose, 7); the JSON is
    lerobot_eval_T_seed{S}_n{N}.json, with "task": T.
    """
    doc = inspect.cleandoc(eval_main.__doc__)
    a = config.parse(Args, argv, prog="python -m tools.lerobot eval", description=doc)
    if not a.policy.is_dir():
        raise DataError(f"--policy {a.policy} is not a folder")
    named = "" if a.task == PUSHT else f"_{a.task}"  # PushT's keeps the name it always had
    out = a.out or a.policy.parent / f"{EVAL_KIND}{named}_seed{a.seed}_n{a.eval_episodes}.json"
    check_own_result(out, EVAL_KIND)  # ours from an earlier run may be replaced; anything else is the user's

    device = pick_device(a.device)
    policy, pre, post = load_policy(a.policy, device)
    seeds = [env_seed(a.seed, "eval", j) for j in range(a.eval_episodes)]
    t0 = time.perf_counter()
    episodes = evaluate(policy, pre, post, seeds, name=f"--policy {a.policy}", task=a.task)
    k, n = sum(e["success"] for e in episodes), len(episodes)
    result = {
        "kind": EVAL_KIND,
        "policy": str(a.policy.resolve()),
        "policy_type": policy.config.type,
        "task": a.task,
        "device": device,
        "seed": a.seed,
        "episodes": n,
        "successes": k,
        "success": k / n,
        "ci95": wilson(k / n, n),
        "per_episode": episodes,
    }
    write_result(out, result)
    lo, hi = result["ci95"]
    print(
        f"{policy.config.type} on {n} held-out {shown(a.task)} starts (seed {a.seed}): success {k / n:.2f} "
        f"[{lo:.2f}, {hi:.2f}] ({k}/{n}, {time.perf_counter() - t0:.0f} s on {device})"
    )
    print(f"wrote {out}")
    return 0


# --- lab: LeRobot's diffusion policy beside the chapter's MLP on three of the Scale Lab's points --------
SOURCES = DEFAULTS["source_episodes"]  # 12
N = 108  # the lab's point where the MLP's exchange rate is 0.65
POINTS = ("source", "fresh", "resolve")
# LeRobot 0.6.1's DiffusionConfig with the Diffusion Policy paper's PushT horizons (2 observations,
# 16 actions predicted, 8 executed; its default is 64 / 32) and a 2-level U-Net (default 3 levels
# of 512-2048 channels, ~250 M parameters, ~6 s a step here): 1.28 M parameters, 64 ms a step at
# batch 64 on one core. 10 denoising steps at rollout (100 in training).
CONFIG = dict(horizon=16, n_action_steps=8, n_obs_steps=2, down_dims=(64, 128), num_inference_steps=10)
BATCH = 64
LR = 1e-4  # LeRobot's DiffusionConfig.optimizer_lr
LAB_KIND = "lerobot_lab"


def point_episodes(point: str, seed: int, cache: Path) -> list[dict]:
    """The lab's data at (point, seed) as episodes: {"observation.state": (T, 10), "action": (T, 2)}."""
    import datagen
    import scale_lab
    from lerobot_v3 import load_arrays

    path = cache / f"pusht_seed{seed}_ep{N}"
    scale_lab.fresh_demos(path, seed, N)  # the lab's fresh set (made once, then read)
    f = load_arrays(path, keys=("observation.state", "action", "episode_index"))
    episodes = [
        {k: f[k][f["episode_index"] == e] for k in ("observation.state", "action")}
        for e in range(N if point == "fresh" else SOURCES)
    ]
    if point == "resolve":  # the lab's nested prefix: its largest per-source count, then the first 8
        srcs = datagen.sources({k: v[f["episode_index"] < SOURCES] for k, v in f.items()})
        per = scale_lab.per_source(N)
        kept, _, _ = datagen.grow(
            datagen.PUSHT,
            srcs,
            scale_lab.max_per_source("resolve", max(scale_lab.N_DEFAULT)),  # the lab's attempts
            datagen.Perturbation(seed, DEFAULTS["aug_pos_sigma"], DEFAULTS["aug_yaw_sigma"]),
            mode="resolve",
        )
        taken: dict[int, int] = {}  # kept is in (source, k) order: the first `per` of each source
        for ep in kept:
            src = int(np.asarray(ep["aug.source_episode"]).flat[0])
            taken[src] = taken.get(src, 0) + 1
            if taken[src] <= per:
                episodes.append({k: ep[k] for k in ("observation.state", "action")})
    return episodes


def samples(lengths, cfg) -> dict:
    """Index arrays of every training sample, as LeRobotDataset and its EpisodeAwareSampler make them.

    lengths: frames per episode, in order. Returns rows (S,) of the frame t each sample starts at,
    obs (S, n_obs) and act (S, horizon) frame rows clamped to the episode, and their pad masks."""
    starts = np.cumsum([0, *lengths[:-1]])
    rows, lo, hi = [], [], []
    for b, n in zip(starts, lengths, strict=True):
        t = np.arange(b, b + max(n - cfg.drop_n_last_frames, 0))
        rows.append(t)
        lo.append(np.full(len(t), b))
        hi.append(np.full(len(t), b + n - 1))
    t, lo, hi = (np.concatenate(x) for x in (rows, lo, hi))
    obs = t[:, None] + np.asarray(cfg.observation_delta_indices)[None]  # (S, 2)
    act = t[:, None] + np.asarray(cfg.action_delta_indices)[None]  # (S, 16)
    clamp = lambda q: np.clip(q, lo[:, None], hi[:, None])  # noqa: E731
    pad = lambda q: (q < lo[:, None]) | (q > hi[:, None])  # noqa: E731
    return {"rows": t, "obs": clamp(obs), "act": clamp(act), "obs_pad": pad(obs), "act_pad": pad(act)}


def policy_and_processors(stats: dict, seed: int):
    """A fresh LeRobot DiffusionPolicy (CONFIG) with its pre/post processors normalizing by `stats`."""
    from lerobot_v3 import hub_offline

    hub_offline()  # before LeRobot's policies import huggingface_hub
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from lerobot.policies.factory import make_pre_post_processors

    cfg = DiffusionConfig(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (pusht_env.OBS_DIM,)),
            ENV_STATE_KEY: PolicyFeature(FeatureType.ENV, (len(pusht_env.ENV_STATE_NAMES),)),
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (pusht_env.ACT_DIM,))},
        device="cpu",
        **CONFIG,
    )
    torch.manual_seed(seed)  # the network's initial weights
    policy = DiffusionPolicy(cfg)
    pre, post = make_pre_post_processors(cfg, dataset_stats=stats)
    return policy, pre, post


def frame_arrays(episodes) -> dict:
    """The set's frames: observation.state (F, 10), its environment_state columns (F, 8), action (F, 2)."""
    x = np.concatenate([e["observation.state"] for e in episodes]).astype(np.float32)
    env_cols = columns(pusht_env.STATE_NAMES, pusht_env.ENV_STATE_NAMES)
    y = np.concatenate([e["action"] for e in episodes]).astype(np.float32)
    return {"observation.state": x, ENV_STATE_KEY: np.ascontiguousarray(x[:, env_cols]), "action": y}


def batch_of(frames: dict, s: dict, idx) -> dict:
    """LeRobotDataset's items for the samples `idx`, stacked: (B, 2, D) observations, (B, 16, 2) actions."""
    b = {k: torch.from_numpy(v[s["obs"][idx]]) for k, v in frames.items() if k != "action"}
    b |= {f"{k}_is_pad": torch.from_numpy(s["obs_pad"][idx]) for k in list(b)}
    b["action"] = torch.from_numpy(frames["action"][s["act"][idx]])
    b["action_is_pad"] = torch.from_numpy(s["act_pad"][idx])
    return b


def train(episodes, steps: int, seed: int, lr: float, log_every: int = 100, check=None, check_every: int = 0):
    """LeRobot's diffusion training step on our batches, its optimizer and schedule presets at peak
    learning rate `lr`: (policy, pre, post, [(step, mean loss)]). check(step, policy, pre, post) runs
    in eval mode after every check_every-th step (0: never); it must leave torch's global RNG as it
    found it (the training's noise and timesteps come from it), so a checked run trains as an
    unchecked one."""
    frames = frame_arrays(episodes)
    stats = {
        k: {"min": v.min(0), "max": v.max(0), "mean": v.mean(0), "std": v.std(0)} for k, v in frames.items()
    }
    policy, pre, post = policy_and_processors(stats, seed)
    cfg = policy.config
    cfg.optimizer_lr = lr  # read by the optimizer preset
    s = samples([len(e["action"]) for e in episodes], cfg)
    opt = cfg.get_optimizer_preset().build(policy.parameters())
    sched = cfg.get_scheduler_preset().build(opt, steps)
    gen = torch.Generator().manual_seed(seed)  # the batch order: shuffled epochs, like a DataLoader
    order, curve, window = torch.empty(0, dtype=torch.long), [], []
    policy.train()
    for step in range(1, steps + 1):
        if len(order) < BATCH:
            order = torch.cat([order, torch.randperm(len(s["rows"]), generator=gen)])
        idx, order = order[:BATCH].numpy(), order[BATCH:]
        loss, _ = policy.forward(pre(batch_of(frames, s, idx)))
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), cfg.get_optimizer_preset().grad_clip_norm)
        opt.step()
        sched.step()
        window.append(loss.item())
        if check_every and step % check_every == 0:
            check(step, policy.eval(), pre, post)
            policy.train()
        if step % log_every == 0 or step == steps:
            curve.append((step, float(np.mean(window))))
            window = []
    return policy.eval(), pre, post, curve


def rollouts(policy, pre, post, seeds: list[int]) -> list[dict]:
    """All episodes at once, one env per start, the policy batched over them (as LeRobot's own eval
    runs vectorised envs): {"seed", "success", "steps"} per start, the lesson's success rule. An
    episode that has ended keeps its last observation and its env is not stepped again. The denoising
    noise is drawn for the whole batch, so an outcome depends on the batch it ran in (the seeds);
    `lerobot eval` runs one episode at a time instead, ~50x slower here."""
    from datagen.tasks.pusht import PUSHT as PUSHT_TASK  # its spec: the columns our PushT sets record

    envs, build = [pusht_env.PushTEnv() for _ in seeds], observation_builder(policy, PUSHT_TASK.spec, "PushT")
    obs = np.stack([env.reset(s) for env, s in zip(envs, seeds, strict=True)])  # (B, 10)
    done, steps, success = np.zeros(len(seeds), bool), np.zeros(len(seeds), int), np.zeros(len(seeds), bool)
    torch.manual_seed(seeds[0])
    policy.reset()
    with torch.inference_mode():
        while not done.all():
            action = post(policy.select_action(pre(build(obs)))).cpu().numpy().astype(np.float32)  # (B, 2)
            for i in np.flatnonzero(~done):
                obs[i], _, done[i], info = envs[i].step(action[i])
                success[i], steps[i] = bool(info["success"]), steps[i] + 1
    return [
        {"seed": s, "success": bool(w), "steps": int(n)}
        for s, w, n in zip(seeds, success, steps, strict=True)
    ]


def one_run(job) -> dict:
    """(point, seed, steps, lr, eval_episodes, out): train (or read the model a run with these
    steps and lr saved), roll out; one JSON under out."""
    point, seed, steps, lr, n_eval, out = job
    torch.set_num_threads(1)
    folder = out / f"{point}_seed{seed}"
    trained = folder / "train.json"
    if trained.exists() and same_run(json.loads(trained.read_text()), steps, lr):
        record = json.loads(trained.read_text())
        policy, pre, post = load_policy(folder / "pretrained_model", "cpu")
    else:
        t0 = time.perf_counter()
        episodes = point_episodes(point, seed, out / "demos")
        policy, pre, post, curve = train(episodes, steps, seed, lr)
        for part in (policy, pre, post):
            part.save_pretrained(folder / "pretrained_model")
        record = {
            "steps": steps,
            "lr": lr,
            "demos": len(episodes),
            "frames": int(sum(len(e["action"]) for e in episodes)),
            "final_loss": curve[-1][1],
            "loss_curve": curve,
            "seconds_train": time.perf_counter() - t0,
        }
        write_result(trained, record)
    t0 = time.perf_counter()
    eps = rollouts(policy, pre, post, [env_seed(seed, "eval", j) for j in range(n_eval)])
    k = sum(e["success"] for e in eps)
    result = {"kind": LAB_KIND, "point": point, "seed": seed, **record, "batch_size": BATCH}
    result |= {
        "config": {k: list(v) if isinstance(v, tuple) else v for k, v in CONFIG.items()},
        "successes": k,
        "episodes": n_eval,
        "success": k / n_eval,
        "ci95": wilson(k / n_eval, n_eval),
        "seconds_eval": time.perf_counter() - t0,
        "per_episode": eps,
    }
    write_result(out / f"{point}_seed{seed}.json", result)
    return result


def same_run(record: dict, steps: int, lr: float) -> bool:
    """Whether a saved record was trained with these steps and peak learning rate."""
    return (record["steps"], record.get("lr", LR)) == (steps, lr)


def rollout_check(starts: list[int], record: list, label: str = ""):
    """A check for train(): the policy's success on `starts` appended to `record` (and printed after
    `label`), torch's global RNG put back as it was."""

    def check(step, policy, pre, post):
        rng = torch.get_rng_state()  # the rollouts seed torch; the training goes on as if unchecked
        k, n = sum(e["success"] for e in rollouts(policy, pre, post, starts)), len(starts)
        torch.set_rng_state(rng)
        record.append({"step": step, "successes": k, "success": k / n, "ci95": wilson(k / n, n)})
        print(f"{label} step {step:6d}: {k}/{n} successes", flush=True)

    return check


def pilot(job) -> dict:
    """(point, seed, steps, lr, eval_every, eval_episodes, out): one long run's loss curve and, every
    eval_every steps (0: never), its success on the held-out starts, mid-schedule (the learning rate
    decays to zero at `steps`): how long a run must be. Written to OUT/pilot_{point}_seed{seed}.json."""
    point, seed, steps, lr, every, n_eval, out = job
    torch.set_num_threads(1)
    t0, checks = time.perf_counter(), []
    rolls = rollout_check(
        [env_seed(seed, "eval", j) for j in range(n_eval)], checks, f"{point:8s} seed {seed}"
    )
    episodes = point_episodes(point, seed, out / "demos")
    _, _, _, curve = train(episodes, steps, seed, lr, log_every=250, check=rolls, check_every=every)
    record = {"kind": LAB_KIND, "point": point, "seed": seed, "steps": steps, "lr": lr, "episodes": n_eval}
    record |= {"loss_curve": curve, "checkpoints": checks, "seconds": time.perf_counter() - t0}
    write_result(out / f"pilot_{point}_seed{seed}.json", record)
    return record


def fresh_equivalent(rate: float, r12: float, r108: float) -> float:
    """Fresh demos that reach `rate`, log-linear in N between the fresh points at 12 and 108."""
    if r108 <= r12:
        return math.nan
    frac = (rate - r12) / (r108 - r12)
    return SOURCES * (N / SOURCES) ** frac


def table(results: list[dict], seeds: list[int]) -> dict:
    """Pooled success per point (mean over seeds, Wilson over all episodes) and the exchange rate."""
    rows = {}
    for p in POINTS:
        got = [r for r in results if r["point"] == p]
        if len(got) != len(seeds):
            continue
        n = sum(r["episodes"] for r in got)
        rate = sum(r["successes"] for r in got) / n
        rows[p] = {
            "success": rate,
            "ci95": wilson(rate, n),
            "per_seed": {str(r["seed"]): r["success"] for r in got},
        }
    if len(rows) == len(POINTS):
        eq = fresh_equivalent(rows["resolve"]["success"], rows["source"]["success"], rows["fresh"]["success"])
        rows["exchange_rate"] = {"fresh_equivalent": eq, "per_generated_demo": (eq - SOURCES) / (N - SOURCES)}
    return rows


def lab_main(argv: list[str] | None = None) -> int:
    """LeRobot's diffusion policy beside the chapter's MLP on three of the Scale Lab's points.

        python -m tools.lerobot lab                       # 3 points x seeds 0..2, 40,000 steps, 100 starts
        python -m tools.lerobot lab --pilot 40000 --eval_every 5000 --points fresh resolve --seeds 0
                                                          # the length: loss curves, success at checkpoints
        python -m tools.lerobot lab --steps 30 --seeds 0 --eval_episodes 2 --out /tmp/ll  # seconds: pipeline

    The points and their data are the lab's own (scale_lab.py): `source` (N = 12: episodes 0..11 of the
    chapter's PushT demo generator at the seed), `fresh` (N = 108: episodes 0..107) and `resolve` (12 +
    96: the 12 sources and the first 8 re-solved demos of each, exactly the lab's resolve point at 108).
    Each is trained with LeRobot's DiffusionPolicy (its config, network, noise scheduler, normalizer and
    optimizer and LR-scheduler presets, `policy.forward` + `loss.backward()`), a configuration small
    enough for a 2-core CPU (CONFIG below: the Diffusion Policy paper's PushT horizons, a 2-level U-Net),
    then rolled out through `lerobot eval`'s code on the lab's held-out starts with the lesson's success
    rule and Wilson interval.

    What is ours is the data loader: lerobot-train reads each sample through LeRobotDataset (about 7 ms
    a sample here, 0.43 s of a 0.7 s step at batch 64), so this tool builds the same samples from the
    arrays: for frame t of an episode, observations at t-1, t and actions at t-1 .. t+14, clamped to
    the episode with `*_is_pad` flags, never the last `drop_n_last_frames` frames of an episode as a
    start (LeRobot's EpisodeAwareSampler). tests/test_lerobot.py checks them against LeRobotDataset's
    own items. Each run saves a `pretrained_model` folder (policy and processors) that `lerobot eval`
    and lerobot's own tools read. One JSON per (point, seed) under --out, kept across runs (a re-run
    skips what is done), and OUT/lerobot_lab.json with the pooled table.
    """
    a = lab_args(argv)
    import scale_lab

    for s in a.seeds:  # the lab's fresh set, made here before the workers that read it
        scale_lab.fresh_demos(a.out / "demos" / f"pusht_seed{s}_ep{N}", s, N)
    return lab_pilots(a) if a.pilot else lab_runs(a)


def lab_args(argv: list[str] | None):
    """lab's flags, checked; --out made once it can be."""
    p = parser("lerobot lab", lab_main.__doc__, script=False)
    arg = p.add_argument
    arg("--steps", type=int, default=40000, help="steps a run (success levels off by 30-40k)")
    arg("--lr", type=float, default=1e-3, help="peak learning rate (docs/lerobot.md; LeRobot's preset: 1e-4)")
    arg("--seeds", type=int, nargs="+", default=[0, 1, 2], help="the lab's seeds")
    arg("--points", nargs="+", choices=POINTS, default=list(POINTS), help="which points")
    arg("--eval_episodes", type=int, default=100, help="held-out starts per run (the lab's 100)")
    arg("--workers", type=int, default=2, help="runs at once, one torch thread each")
    arg("--pilot", type=int, default=0, help="instead: runs this many steps long, their loss curves")
    arg("--eval_every", type=int, default=0, help="with --pilot: roll out every this many steps (0: never)")
    arg("--out", type=Path, default=ROOT / "outputs" / "lerobot_lab", help="results folder")
    a = p.parse_args(argv)
    check(
        a,
        positive=("steps", "workers", "eval_episodes"),
        non_negative=("pilot", "eval_every", "seeds"),
        finite_positive=("lr",),
        at_most={"eval_episodes": 1000, "seeds": MAX_SEED},
    )
    if a.lr >= 1:
        raise DataError(f"--lr must be below 1, got {a.lr}")
    problem = check_out_path(a.out)  # a file, a folder that cannot be written: one line, before any work
    if problem:
        raise DataError(problem)
    a.out.mkdir(parents=True, exist_ok=True)
    return a


def lab_pilots(a) -> int:
    """--pilot: each (point, seed)'s long run, its loss curve and checkpoints (pilot)."""
    jobs = [(p, s, a.pilot, a.lr, a.eval_every, a.eval_episodes, a.out) for p in a.points for s in a.seeds]
    for r in map_jobs(pilot, jobs, workers=min(a.workers, len(jobs)), ordered=False):
        print(f"{r['point']:8s} seed {r['seed']}: loss {r['loss_curve'][-1][1]:.4f}, {r['seconds']:.0f} s")
    return 0


def lab_runs(a) -> int:
    """Every (point, seed) not done yet with these flags (one_run), then OUT/lerobot_lab.json's table."""

    def done(point, seed):
        path = a.out / f"{point}_seed{seed}.json"
        if not path.exists():
            return None
        r = json.loads(path.read_text())
        return r if same_run(r, a.steps, a.lr) and r["episodes"] == a.eval_episodes else None

    results, jobs = [], []
    for s in a.seeds:
        for point in sorted(a.points, key=("fresh", "resolve", "source").index):  # the long ones first
            r = done(point, s)
            results.append(r) if r else jobs.append((point, s, a.steps, a.lr, a.eval_episodes, a.out))
    for r in map_jobs(one_run, jobs, workers=min(a.workers, max(len(jobs), 1)), ordered=False):
        print(
            f"{r['point']:8s} seed {r['seed']}: {r['successes']}/{r['episodes']} successes, "
            f"loss {r['final_loss']:.4f}, train {r['seconds_train']:.0f} s, eval {r['seconds_eval']:.0f} s",
            flush=True,
        )
        results.append(r)
    rows = table(results, a.seeds)
    summary = {"kind": LAB_KIND, "steps": a.steps, "lr": a.lr, "seeds": a.seeds, "table": rows}
    write_result(a.out / "lerobot_lab.json", summary)
    for k, v in rows.items():
        print(k, v)
    return 0


# --- table: a LeRobot row (docs/gym_pusht.md's, docs/engine.md's) from its evaluations' own files -------
ROWS = {  # tools/lerobot_row.sh's three training sets by task, and the evaluation file each run leaves
    "gym_pusht": (("sources", "resolved", "fresh"), "eval_info.json"),  # lerobot-eval's own
    "aloha_transfer_cube": (("sources", "replayed", "fresh"), f"{EVAL_KIND}.json"),  # this tool's eval
}
TABLE_KIND = "lerobot_pusht_table"  # both rows' tables: the name the first one was written with


def eval_info(path: Path) -> dict:
    """A run's evaluation -> successes, episodes, mean max reward and each start's: lerobot-eval's
    eval_info.json (gym-pusht's reward: its coverage / 0.95, at most 1) or this tool's eval JSON (the
    task's reward; transfer-cube: gym-aloha's stage 0..4), and the starts' env seeds where the file names
    them (this tool's), else None. A file that is not one, or one whose episodes a count would misread (no
    episode, a success that is not true or false, a max reward that is not a finite number, a count that
    disagrees with its episodes), is a DataError naming it: the table never recounts it silently."""
    what = "lerobot-eval's eval_info.json" if path.name == "eval_info.json" else f"{EVAL_KIND}'s JSON"
    try:
        r = json.loads(path.read_text())
        if path.name == "eval_info.json":
            m = r["per_task"][0]["metrics"]
            wins, best, starts = list(m["successes"]), list(m["max_rewards"]), None
            if len(wins) != len(best):
                raise ValueError(f"{len(wins)} successes against {len(best)} max rewards")
        else:
            wins = [e["success"] for e in r["per_episode"]]
            best = [e["max_reward"] for e in r["per_episode"]]
            starts = [e["seed"] for e in r["per_episode"]]
    except (OSError, ValueError, KeyError, IndexError, TypeError) as e:
        raise DataError(f"{path} is not {what} ({type(e).__name__}: {e})") from e
    if not wins:
        raise DataError(f"{path} holds no episodes: it scores no start (rerun its evaluation)")
    for j, (w, b) in enumerate(zip(wins, best, strict=True)):
        if type(w) is not bool:  # bool("false") is True: a word would count as a success
            raise DataError(f"{path}: episode {j}'s success is {w!r}, not true or false")
        if type(b) not in (int, float) or not math.isfinite(b):
            raise DataError(f"{path}: episode {j}'s max reward is {b!r}, not a finite number")
    stated = {k: r[k] for k in ("episodes", "successes") if path.name != "eval_info.json" and k in r}
    counted = {"episodes": len(wins), "successes": sum(wins)}
    if any(stated[k] != counted[k] for k in stated):
        raise DataError(f"{path} states {stated} but its per_episode holds {counted}")
    return {
        "successes": sum(wins),
        "episodes": len(wins),
        "max_reward": sum(best) / len(best),
        "best": [float(b) for b in best],
        "starts": starts,
    }


def same_starts(evals: dict[str, dict], paths: dict[str, Path]) -> None:
    """A seed's three sets are scored on the same starts (the table pairs them start by start): a set
    scored on other starts, or on a different number of them, is a DataError naming its file (the one
    the other two disagree with; the first set's against the second where all three differ)."""
    key = {k: e["starts"] or e["episodes"] for k, e in evals.items()}  # the seeds where the file names them
    ks = list(evals)
    common = next((key[k] for k in ks if sum(key[k] == key[j] for j in ks) > 1), key[ks[0]])
    for k in ks:
        if key[k] != common:
            ref = next(j for j in ks if key[j] == common)
            n, m = evals[k]["episodes"], evals[ref]["episodes"]
            raise DataError(
                f"{paths[k]} scores {n} starts, {paths[ref].parent.name}'s {m}"
                + (" (other seeds)" if n == m else "")
                + ": a seed's sets are scored on the same starts; remove that eval_ folder and run "
                "tools/lerobot_row.sh again"
            )


def final_loss(log: Path) -> float | None:
    """The last `loss:` lerobot-train logged (a mean over its last --log_freq steps), or None when the log
    has none; a `loss:` without a number (a log cut as it was written) is a DataError naming the log."""
    found = (
        [w for w in log.read_text(errors="replace").split() if w.startswith("loss:")] if log.is_file() else []
    )
    if not found:
        return None
    try:
        return float(found[-1][5:])
    except ValueError:
        raise DataError(
            f"{log}: its last `loss:` reads {found[-1]!r}, not a number (a log cut short?)"
        ) from None


def table_main(argv: list[str] | None = None) -> int:
    """A LeRobot row from a `bash tools/lerobot_row.sh TASK OUT` run (issue 49's in docs/gym_pusht.md,
    issue 50's in docs/engine.md):

        python -m tools.lerobot table OUT [--json FILE]

    Reads each seed's evaluations, OUT/seed*/eval_SET/: gym-pusht's sets sources, resolved and fresh,
    lerobot-eval's eval_info.json; transfer-cube's sources, replayed and fresh, tools.lerobot eval's JSON.
    Prints per seed each set's successes and mean max reward (its maximum over the episode: gym-pusht's,
    the goal's coverage over 95%, at most 1; transfer-cube's, gym-aloha's stage: 1 the right gripper
    touches the cube, 2 lifts it, 3 both grippers touch it, 4 the left holds it alone) and lerobot-train's
    last logged loss; the pooled success with the lesson's 95% Wilson interval; the paired per-seed
    differences, and the max reward's difference paired start by start (each seed's three sets are
    scored on the same starts) over all seeds, with its 95% t-interval (tools.common.mean_ci). --json
    writes the same as one JSON. Only seeds with all three sets evaluated are counted. Every file is
    checked before a line is printed: an evaluation with no episode, a success that is not true or
    false, a max reward that is not a finite number, counts that disagree with its episodes, a set scored
    on other starts than its seed's other sets, or a train log whose last `loss:` has no number, is one
    `error:` line naming the file (exit 2), never a silent recount.
    """
    p = parser("lerobot table", table_main.__doc__, script=False)
    p.add_argument("out", type=Path, help="the folder tools/lerobot_row.sh wrote")
    p.add_argument("--json", type=Path, help="also write the table here")
    a = p.parse_args(argv)
    seeds = sorted(int(d.name[4:]) for d in a.out.glob("seed*") if d.name[4:].isdigit())
    for task, (sets, file) in ROWS.items():
        done = [s for s in seeds if all((a.out / f"seed{s}" / f"eval_{k}" / file).is_file() for k in sets)]
        if done:
            break
    else:
        wanted = "; ".join(f"{t}: eval_{{{','.join(k)}}}/{f}" for t, (k, f) in ROWS.items())
        raise DataError(f"{a.out} holds no seed with its three sets evaluated ({wanted})")
    rows = {}
    for s in done:  # every file read and checked before a line is printed
        d = a.out / f"seed{s}"
        paths = {k: d / f"eval_{k}" / file for k in sets}
        rows[s] = {k: eval_info(paths[k]) | {"loss": final_loss(d / f"train_{k}.log")} for k in sets}
        same_starts(rows[s], paths)
    pooled = {}
    for k in sets:
        wins, n = sum(r[k]["successes"] for r in rows.values()), sum(r[k]["episodes"] for r in rows.values())
        best = sum(r[k]["max_reward"] for r in rows.values()) / len(rows)
        pooled[k] = {
            "successes": wins,
            "episodes": n,
            "success": wins / n,
            "ci95": wilson(wins / n, n),
            "max_reward": best,
        }
        every = [x for r in rows.values() for x in r[k]["best"]]
        if all(x == int(x) for x in every):  # a staged reward (transfer-cube's): how many starts reached each
            pooled[k]["reached"] = {
                str(g): sum(x >= g for x in every) for g in range(1, int(max(every, default=0)) + 1)
            }
        lo, hi = pooled[k]["ci95"]
        per = " / ".join(
            f"{r[k]['successes']}/{r[k]['episodes']} ({r[k]['max_reward']:.3f}, loss {r[k]['loss']})"
            for r in rows.values()
        )
        reached = " ".join(f">={g}: {c}" for g, c in pooled[k].get("reached", {}).items())
        print(
            f"{k:9s} {per}  pooled {wins}/{n} = {wins / n:.3f} [{lo:.3f}, {hi:.3f}]  max reward {best:.3f}"
            + (f"  stages reached {reached}" if reached else "")
        )
    diffs = {}
    grown = sets[1]
    for x, y in ((grown, "sources"), ("fresh", grown), ("fresh", "sources")):
        rate = {s: {k: r[k]["successes"] / r[k]["episodes"] for k in (x, y)} for s, r in rows.items()}
        each = [a - b for r in rows.values() for a, b in zip(r[x]["best"], r[y]["best"], strict=True)]
        d = diffs[f"{x} - {y}"] = {
            "success": {str(s): v[x] - v[y] for s, v in rate.items()},
            "max_reward": {str(s): r[x]["max_reward"] - r[y]["max_reward"] for s, r in rows.items()},
            "max_reward_paired": dict(zip(("mean", "std", "ci95"), mean_ci(each))) | {"episodes": len(each)},
        }
        pm = d["max_reward_paired"]
        lo, hi = pm["ci95"] or (math.nan, math.nan)  # one start: no interval
        print(
            f"{x} - {y}: success",
            " ".join(f"{v:+.2f}" for v in d["success"].values()),
            "| max reward",
            " ".join(f"{v:+.3f}" for v in d["max_reward"].values()),
            f"| paired over {pm['episodes']} starts {pm['mean']:+.3f} [{lo:+.3f}, {hi:+.3f}]",
        )
    if a.json:
        res = {
            "kind": TABLE_KIND,
            "task": task,
            "seeds": {
                str(s): {k: {n: v for n, v in e.items() if n not in ("best", "starts")} for k, e in r.items()}
                for s, r in rows.items()
            },
            "pooled": pooled,
            "paired": diffs,
        }
        check_own_result(a.json, TABLE_KIND)
        write_result(a.json, res)
        print(f"wrote {a.json}")
    return 0


SUBCOMMANDS = {"eval": eval_main, "lab": lab_main, "table": table_main}


def main(argv: list[str]) -> int:
    return subcommands("lerobot", SUBCOMMANDS, argv, __doc__)


if __name__ == "__main__":
    errors.main(main)
