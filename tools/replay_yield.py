"""Where does replay work? Yield (kept / attempts) by task and mode, on both robots, at the chapter's
perturbation, and ALOHA replay's yield as the perturbation grows (issue 29's study, first half).

    python -m tools.replay_yield --seeds 3 --attempts 10          -> OUT/replay_yield.json
    python -m tools.replay_yield --seeds 3 --attempts 10 --aloha_sigma 0.25 0.5 1 2 4

For each seed, the chapter's 12 source demos of each robot (the demo sets' own seeds and noise:
episode i of seed s from env seed env_seed(s, "demo", i)), and for each source demo `--attempts`
attempts k = 0, 1, ...; attempt k of source episode e draws its start from
engine.attempt_rng(seed, e, k), so every mode of a task meets the same starts (paired). The
chapter's perturbation: PushT block and pusher xy 0.08 m, block yaw 0.5 rad (engine.perturbed_start);
ALOHA cube, target and both end-effectors 0.08 m each (no yaw: the cube is a point), every point
kept in its spawn region (aloha_task.perturbed_start). Modes:

    resolve                the task's noise-free expert solves the start
    replay                 the attempt's own source, one segment relative to the object (PushT:
                           engine.replay, the chapter's replay; ALOHA: aloha_task.whole)
    subtasks               its own source, split into subtasks (pusht_task / aloha_task)
    subtasks_nearest       the source nearest the new start (MimicGen's selection), split into subtasks
    subtasks_block_nearest PushT only: nearest, with the push relative to the block alone

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import aloha_env
import pusht_env
from ch37 import ROOT, errors
from ch37.config import DEFAULTS, check
from ch37.errors import DataError
from ch37.ownership import dump_json, round_floats, write_atomic
from ch37.parallel import map_jobs
from ch37.seeds import env_seed
from datagen import aloha as aloha_task
from datagen import engine
from datagen import pusht as pusht_task
from datagen.task import Source, rollout
from gen_demos_aloha import ALOHA
from gen_demos_pusht import PUSHT
from tools.common import parser, provenance, rel

POS_SIGMA, YAW_SIGMA = DEFAULTS["aug_pos_sigma"], DEFAULTS["aug_yaw_sigma"]  # m, rad
MODES = {
    "pusht": ("resolve", "replay", "subtasks", "subtasks_nearest", "subtasks_block_nearest"),
    "aloha": ("resolve", "replay", "subtasks", "subtasks_nearest"),
}
SIGMA_MODES = ("replay", "subtasks", "subtasks_nearest")  # ALOHA modes of the perturbation sweep

_WORK: dict = {}  # (task, seed) -> {"sources": {e: Source}, "plans": {e: [Subtask]}}, built before forking
_ENVS: dict = {}  # one simulator per task per process


def env_of(task: str):
    if task not in _ENVS:
        _ENVS[task] = pusht_env.PushTEnv() if task == "pusht" else aloha_env.AlohaCubeEnv()
    return _ENVS[task]


def sources(task: str, seed: int, n: int) -> dict:
    """The chapter's n source demos of `task` at `seed`, rolled out as the demo generators do."""
    emb = PUSHT if task == "pusht" else ALOHA
    env, out = env_of(task), {}
    for i in range(n):
        s = env_seed(seed, "demo", i)
        ep = rollout(env, emb.expert_class(noise=emb.default_noise, seed=s), env.reset(s))
        out[i] = Source(i, ep["observation.state"], ep["action"])
    return out


def one(job) -> tuple[str, int]:
    """('kept', frames of the kept episode) or (the failure reason, 0) of one attempt:
    job = (task, mode, seed, episode, k, sigma multiplier)."""
    task, mode, seed, e, k, m = job
    work, env = _WORK[(task, seed)], env_of(task)
    src, pool, rng = work["sources"][e], work["sources"], engine.attempt_rng(seed, e, k)
    if task == "aloha":
        plans = work["plans"] if mode != "replay" else {x: aloha_task.whole(s) for x, s in pool.items()}
        how = dict(pos_sigma=m * POS_SIGMA, mode="resolve" if mode == "resolve" else "replay", plans=plans)
        r = aloha_task.attempt(src, rng, env, pool=pool if mode.endswith("nearest") else None, **how)
        return ("kept", r.steps) if r.kept else (r.reason, 0)
    start = pusht_task.perturbed_start(src.states[0], rng, m * POS_SIGMA, m * YAW_SIGMA)
    if start is None:
        return "no_valid_start", 0
    if mode == "resolve":
        ep = rollout(env, pusht_task.PUSHT.expert(), env.set_start(*start))
        why = None if ep["success"] else "expert_failed"
    elif mode == "replay":
        got = pusht_task.replay(env, start, src)
        ep, why = got.episode, got.reason
    else:
        chosen = pool[pusht_task.nearest(pool, start)] if mode.endswith("nearest") else src
        frame = "block" if mode == "subtasks_block_nearest" else "block+target"
        got = pusht_task.replay_subtasks(env, start, chosen, push_frame=frame)
        ep, why = got.episode, got.reason
    return (why, 0) if why else ("kept", len(ep["action"]))


def cell(task: str, mode: str, seeds, n: int, attempts: int, m: float, workers: int) -> dict:
    """Yield of one (task, mode, sigma multiplier) over seeds x n sources x attempts, with its reasons."""
    from bc_recipe import wilson

    t = time.perf_counter()
    jobs = [(task, mode, s, e, k, m) for s in seeds for e in range(n) for k in range(attempts)]
    got, frames = zip(*list(map_jobs(one, jobs, workers=workers)))
    kept = got.count("kept")
    per_seed = {s: got[i * n * attempts : (i + 1) * n * attempts].count("kept") for i, s in enumerate(seeds)}
    row = {"task": task, "mode": mode, "multiplier": m, "pos_sigma": m * POS_SIGMA}
    row |= {"yaw_sigma": m * YAW_SIGMA if task == "pusht" else None, "attempts": len(got), "kept": kept}
    row |= {"yield": kept / len(got), "ci95": wilson(kept / len(got), len(got)), "kept_per_seed": per_seed}
    row["failures"] = {why: got.count(why) for why in sorted(set(got) - {"kept"})}
    row["kept_frames_median"] = float(np.median([f for f in frames if f])) if kept else None
    return row | {"seconds": round(time.perf_counter() - t, 1)}


def main(argv: list[str]) -> int:
    p = parser("replay_yield", __doc__)
    p.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 (their source demos and attempts)")
    p.add_argument("--sources", type=int, default=DEFAULTS["source_episodes"], help="source demos per seed")
    p.add_argument("--attempts", type=int, default=10, help="attempts per source demo per seed and mode")
    p.add_argument(
        "--aloha_sigma", type=float, nargs="*", default=[], help="ALOHA sweep: multipliers of 0.08 m"
    )
    p.add_argument("--workers", type=int, default=1, help="processes for the attempts")
    p.add_argument("--out", type=Path, default=ROOT / "outputs/replay_yield", help="output folder")
    a = p.parse_args(argv)
    check(a, positive=["seeds", "sources", "attempts", "workers"])
    if any(not (0 < m < 100) for m in a.aloha_sigma):
        raise DataError("--aloha_sigma multipliers must be in (0, 100)")
    seeds = list(range(a.seeds))
    for task in MODES:
        for s in seeds:
            src = sources(task, s, a.sources)
            plans = {e: aloha_task.plan(env_of(task), x) for e, x in src.items()} if task == "aloha" else {}
            _WORK[(task, s)] = {"sources": src, "plans": plans}
    rows = []
    todo = [(task, mode, 1.0) for task, modes in MODES.items() for mode in modes]
    todo += [("aloha", mode, m) for m in sorted(a.aloha_sigma) if m != 1.0 for mode in SIGMA_MODES]
    for task, mode, m in todo:
        rows.append(r := cell(task, mode, seeds, a.sources, a.attempts, m, a.workers))
        got = (
            f"{r['kept']}/{r['attempts']} = {r['yield']:.3f} {r['failures']} frames {r['kept_frames_median']}"
        )
        print(f"{task:5s} x{m:<4g} {mode:22s} {got}", flush=True)
    cmd = f"python -m tools.replay_yield --seeds {a.seeds} --sources {a.sources} --attempts {a.attempts}"
    cmd += " --aloha_sigma " + " ".join(f"{m:g}" for m in a.aloha_sigma) if a.aloha_sigma else ""
    res = {"kind": "replay_yield", "command": cmd, "seeds": seeds, "rows": rows} | provenance(a.script)
    a.out.mkdir(parents=True, exist_ok=True)
    f = write_atomic(a.out / "replay_yield.json", dump_json(round_floats(res, 4)))
    print(f"wrote {rel(f)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
