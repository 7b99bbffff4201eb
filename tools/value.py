"""What are generated demos worth? The chapter's BC recipe (bc_recipe: its MLP, each arm's own min-max
statistics) on up to four arms per seed, every arm at the same gradient steps from the same initial
weights (issue 29's study on ALOHA, issue 49's on LeRobot's gym-pusht):

    python -m tools.value --task aloha --seeds 3      -> OUT/aloha_value.json (default outputs/aloha_value)
    python -m tools.value --task gym_pusht --seeds 3  -> OUT/gym_pusht_value.json (outputs/gym_pusht_value)
    python -m tools.value --smoke --seeds 1           seconds; numbers not meaningful

    source     the seed's 12 expert demos (env_seed(seed, "demo", i), i < 12, the task's noise-free expert,
               as gen_demos.py rolls them out)
    replayed   the 12 + 96 replayed: 8 kept per source demo by the engine's subtask replay
               (datagen.replay) of its own source, attempts k = 0, 1, ... (engine.attempt_rng(seed, e, k))
               until 8 pass
    resolved   the 12 + 96 re-solved: the same attempts, the expert solving each perturbed start
    fresh      108 expert demos (i < 108: the 12 sources and 96 more from fresh reset starts)

The arms by task (--arms to choose): ALOHA all four; gym-pusht source, resolved and fresh (its replay keeps
none of 360 attempts at the chapter's perturbation: docs/replay.md). Perturbation: the chapter's sigmas in
the task's own units (ALOHA: 0.08 m on cube, target and both end-effectors; gym-pusht: the task's px
scale, datagen.gym_pusht). Steps: the chapter's epochs (500) passes over the largest arm's frames at batch
128 (lr 1e-3 cosine, hidden 512). The MLP reads the task's observation vector (ALOHA's 10 numbers;
gym-pusht's agent x, y and the block's 8 keypoints, as lerobot/pusht_keypoints records them) and gives
its action (ALOHA's 6 velocities; gym-pusht's position target, px). Each arm rolls out on the seed's 100
held-out starts (env_seed(seed, "eval", j): the env's reset(seed)), judged by the env's own success
(gym-pusht's: 95% of the goal covered); the pooled rates carry Wilson 95% intervals, the paired
differences their per-seed values.

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ch37 import ROOT, errors
from ch37.cli import pick_device
from ch37.config import DEFAULTS, SMOKE, check
from ch37.ownership import check_out_path, check_own_result, dump_json, round_floats, write_atomic
from ch37.seeds import env_seed
from datagen import Perturbation
from datagen import grow as grow_demos
from datagen.demos import expert_episodes
from datagen.task import Source, Task, known_tasks
from tools.common import parser, provenance, rel

ARMS = ("source", "replayed", "resolved", "fresh")
TASKS = {"aloha": ARMS, "gym_pusht": ("source", "resolved", "fresh")}  # each task's arms by default
DIFFS = (("replayed", "source"), ("resolved", "source"), ("resolved", "replayed"), ("fresh", "resolved"))
DIFFS += (("fresh", "replayed"),)


def kind(task: Task) -> str:
    """Marks the JSON as this tool's (for this task), so a re-run may replace it and nothing else."""
    return f"{task.name}_value"


def config(smoke: bool) -> dict:
    c = dict(DEFAULTS, eval_episodes=100, source_episodes=12, per_demo=8, tries=10)
    if smoke:
        c |= {k: SMOKE[k] for k in ("epochs", "hidden_dim", "batch_size")}
        c |= dict(source_episodes=2, per_demo=2, eval_episodes=4)
    return c


def grow(task: Task, sources: dict, mode: str, seed: int, c: dict) -> tuple[list[dict], dict]:
    """The first per_demo kept attempts (k order) of each source demo in `mode` (datagen.grow: at most
    tries x per_demo attempts each), and the counts."""
    how = Perturbation(seed, c["aug_pos_sigma"], c["aug_yaw_sigma"])  # ALOHA reads no yaw
    kept, attempts, failures = grow_demos(task, sources, c["per_demo"], how, mode=mode, cap=c["tries"])
    seen = {reason: n for reason, n in failures.items() if n}
    return kept, {"attempts": attempts, "kept": len(kept), "failures": seen}


def stack(eps: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    return (np.concatenate([e["observation.state"] for e in eps]), np.concatenate([e["action"] for e in eps]))


def one_seed(task: Task, arms: tuple, seed: int, c: dict, workers: int, device: str = "cpu") -> dict:
    import bc_recipe as bc

    t0 = time.perf_counter()
    env = task.make_env()
    n_src, n_all = c["source_episodes"], c["source_episodes"] * (1 + c["per_demo"])
    fresh = list(expert_episodes(task, env, seed, n_all))
    src_eps = fresh[:n_src]
    sources = {i: Source(i, e["observation.state"], e["action"]) for i, e in enumerate(src_eps)}
    data, row = {"source": stack(src_eps), "fresh": stack(fresh)}, {"seed": seed}
    grown = {}
    for arm, mode in (("replayed", "replay"), ("resolved", "resolve")):
        if arm in arms:
            grown[arm], row[mode] = grow(task, sources, mode, seed, c)
            data[arm] = stack(src_eps + grown[arm])
    steps = math.ceil(c["epochs"] * max(len(data[a][0]) for a in arms) / c["batch_size"])
    init = bc.init_weights(c["hidden_dim"], seed, act_dim=task.spec.act_dim, obs_dim=task.spec.obs_dim)
    hp = dict(batch_size=c["batch_size"], lr=c["lr"], seed=seed)
    pols, fits = bc.train([data[a] for a in arms], steps, init, device=device, **hp)
    eval_seeds = [env_seed(seed, "eval", j) for j in range(c["eval_episodes"])]
    row["steps"], row["arms"] = steps, {}
    for a, pol, fit in zip(arms, pols, fits):
        rate = bc.evaluate(pol, eval_seeds, workers=workers, make_env=task.make_env)
        demos = {"source": n_src, "fresh": n_all}.get(a) or n_src + len(grown[a])
        row["arms"][a] = {
            "demos": demos,
            "frames": len(data[a][0]),
            "success": rate,
            "final_loss": round(fit, 6),
        }
    return row | {"seconds": round(time.perf_counter() - t0, 1)}


def summarize(rows: list[dict], n_eval: int, arms: tuple) -> dict:
    from bc_recipe import wilson

    n = n_eval * len(rows)
    pooled, diffs = {}, {}
    for a in arms:
        k = sum(round(r["arms"][a]["success"] * n_eval) for r in rows)
        pooled[a] = {"successes": k, "episodes": n, "rate": k / n, "ci95": wilson(k / n, n)}
    for hi, lo in (d for d in DIFFS if set(d) <= set(arms)):
        d = [r["arms"][hi]["success"] - r["arms"][lo]["success"] for r in rows]
        diffs[f"{hi}_vs_{lo}"] = {"per_seed": d, "mean": float(np.mean(d))}
    return {"pooled": pooled, "differences": diffs}


def main(argv: list[str]) -> int:
    p = parser("value", __doc__)
    p.add_argument("--task", default="aloha", choices=sorted(TASKS), help="the task (default aloha)")
    p.add_argument("--arms", nargs="+", choices=ARMS, help="which arms (default: the task's, above)")
    p.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1")
    p.add_argument("--smoke", action="store_true", help="tiny configuration (seconds)")
    p.add_argument("--workers", type=int, default=2, help="processes for the evaluation physics")
    p.add_argument(
        "--device",
        default="cpu",
        choices=("auto", "cpu", "cuda", "mps"),
        help="torch device for the training (see docs/replay.md for its cost)",
    )
    p.add_argument(
        "--out", type=Path, help="default outputs/TASK_value (outputs/TASK_value-smoke with --smoke)"
    )
    a = p.parse_args(argv)
    check(a, positive=["seeds", "workers"])
    task, c = known_tasks()[a.task], config(a.smoke)
    arms = tuple(x for x in ARMS if x in (a.arms or TASKS[a.task]))
    name = f"{a.task}_value"
    out = a.out or ROOT / "outputs" / (f"{name}-smoke" if a.smoke else name)
    if problem := check_out_path(out):  # every input checked before the demos are made
        raise errors.DataError(problem)
    check_own_result(out / f"{name}.json", kind(task))  # an earlier run's may be replaced, a user's never
    device = pick_device(a.device)
    cmd = f"python -m tools.value --task {a.task} --seeds {a.seeds}" + (" --smoke" if a.smoke else "")
    cmd += f" --arms {' '.join(arms)}" if a.arms else ""
    out.mkdir(parents=True, exist_ok=True)
    rows, prov = [], provenance(a.script)
    for s in range(a.seeds):  # the file is rewritten after every seed: a stopped run keeps its seeds
        rows.append(r := one_seed(task, arms, s, c, a.workers, device))
        rates = " ".join(f"{k} {v['success']:.2f}" for k, v in r["arms"].items())
        grown = " ".join(f"{m} {r[m]['kept']}/{r[m]['attempts']}" for m in ("replay", "resolve") if m in r)
        print(f"seed {s}: {grown} kept, {rates} ({r['seconds']} s)", flush=True)
        res = {"kind": kind(task), "command": cmd, "config": c, "arms": list(arms), "rows": rows}
        res |= summarize(rows, c["eval_episodes"], arms)
        f = write_atomic(out / f"{name}.json", dump_json(round_floats(res | prov, 4)))
    print(f"wrote {rel(f)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
