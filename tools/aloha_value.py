"""What are generated ALOHA demos worth? The chapter's BC recipe (bc_recipe: its MLP, 6-D actions, each
arm's own min-max statistics) on four arms per seed, every arm at the same gradient steps from the same
initial weights (issue 29's study, second half):

    python -m tools.aloha_value --seeds 3             -> OUT/aloha_value.json (default outputs/aloha_value)
    python -m tools.aloha_value --smoke --seeds 1     seconds; numbers not meaningful

    source     the seed's 12 expert demos (env_seed(seed, "demo", i), i < 12, noise-free AlohaExpert)
    replayed   the 12 + 96 replayed: 8 kept per source demo by the engine's subtask replay
               (datagen.replay) of its own source, attempts k = 0, 1, ... (engine.attempt_rng(seed, e, k))
               until 8 pass
    resolved   the 12 + 96 re-solved: the same attempts, the expert solving each perturbed start
    fresh      108 expert demos (i < 108: the 12 sources and 96 more from fresh reset starts)

Perturbation: the chapter's 0.08 m on cube, target and both end-effectors (datagen.aloha.perturbed_start).
Steps: the chapter's epochs (500) passes over the largest arm's frames at batch 128 (lr 1e-3 cosine,
hidden 512). Each arm rolls out on the seed's 100 held-out starts (env_seed(seed, "eval", j)); the
pooled rates carry Wilson 95% intervals, the paired differences their per-seed values.

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

import aloha_env
from ch37 import ROOT, errors
from ch37.cli import pick_device
from ch37.config import DEFAULTS, SMOKE, check
from ch37.ownership import check_out_path, check_own_result, dump_json, round_floats, write_atomic
from ch37.seeds import env_seed
from datagen import ALOHA, Perturbation, engine
from datagen.task import Source, rollout
from scripted_expert import AlohaExpert
from tools.common import parser, provenance, rel

KIND = "aloha_value"  # marks the JSON as this tool's, so a re-run may replace it and nothing else
ARMS = ("source", "replayed", "resolved", "fresh")
DIFFS = (("replayed", "source"), ("resolved", "source"), ("resolved", "replayed"), ("fresh", "resolved"))
DIFFS += (("fresh", "replayed"),)


def config(smoke: bool) -> dict:
    c = dict(DEFAULTS, eval_episodes=100, source_episodes=12, per_demo=8, tries=10)
    if smoke:
        c |= {k: SMOKE[k] for k in ("epochs", "hidden_dim", "batch_size")}
        c |= dict(source_episodes=2, per_demo=2, eval_episodes=4)
    return c


def expert_demos(env, seed: int, n: int) -> list[dict]:
    """Episodes 0..n-1 of the seed's ALOHA demo set, as gen_demos_aloha.py rolls them out."""
    eps = []
    for i in range(n):
        s = env_seed(seed, "demo", i)
        eps.append(rollout(env, AlohaExpert(noise=0.0, seed=s), env.reset(s)))
    return eps


def grow(env, sources: dict, mode: str, seed: int, c: dict) -> tuple[list[dict], dict]:
    """The first per_demo kept attempts (k order) of each source demo in `mode`, and the counts."""
    sims = engine.Simulators()  # the sources' cut, made once
    how = Perturbation(seed, c["aug_pos_sigma"], c["aug_yaw_sigma"])  # ALOHA reads no yaw
    kept, attempts, failures = [], 0, {}
    for e, src in sources.items():
        n = 0
        for k in range(c["tries"] * c["per_demo"]):
            if n == c["per_demo"]:
                break
            attempts += 1
            r = engine.attempt(ALOHA, src, k, how, mode=mode, env=env, sims=sims)
            if r.kept:
                kept.append(r.episode)
                n += 1
            else:
                failures[r.reason] = failures.get(r.reason, 0) + 1
    return kept, {"attempts": attempts, "kept": len(kept), "failures": failures}


def stack(eps: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    return (np.concatenate([e["observation.state"] for e in eps]), np.concatenate([e["action"] for e in eps]))


def one_seed(seed: int, c: dict, workers: int, device: str = "cpu") -> dict:
    import bc_recipe as bc

    t0 = time.perf_counter()
    env = aloha_env.AlohaCubeEnv()
    n_src, n_all = c["source_episodes"], c["source_episodes"] * (1 + c["per_demo"])
    fresh = expert_demos(env, seed, n_all)
    src_eps = fresh[:n_src]
    sources = {i: Source(i, e["observation.state"], e["action"]) for i, e in enumerate(src_eps)}
    replayed, rep_row = grow(env, sources, "replay", seed, c)
    resolved, res_row = grow(env, sources, "resolve", seed, c)
    data = {"source": stack(src_eps), "replayed": stack(src_eps + replayed)}
    data |= {"resolved": stack(src_eps + resolved), "fresh": stack(fresh)}
    steps = math.ceil(c["epochs"] * max(len(x) for x, _ in data.values()) / c["batch_size"])
    init = bc.init_weights(c["hidden_dim"], seed, act_dim=aloha_env.ACT_DIM)
    hp = dict(batch_size=c["batch_size"], lr=c["lr"], seed=seed)
    pols, fits = bc.train([data[a] for a in ARMS], steps, init, device=device, **hp)
    eval_seeds = [env_seed(seed, "eval", j) for j in range(c["eval_episodes"])]
    arms = {}
    for a, pol, fit in zip(ARMS, pols, fits):
        rate = bc.evaluate(pol, eval_seeds, workers=workers, make_env=aloha_env.AlohaCubeEnv)
        arms[a] = {
            "demos": {"source": n_src, "fresh": n_all}.get(
                a, n_src + len(replayed if a == "replayed" else resolved)
            )
        }
        arms[a] |= {"frames": len(data[a][0]), "success": rate, "final_loss": round(fit, 6)}
    row = {"seed": seed, "steps": steps, "replay": rep_row, "resolve": res_row, "arms": arms}
    return row | {"seconds": round(time.perf_counter() - t0, 1)}


def summarize(rows: list[dict], n_eval: int) -> dict:
    from bc_recipe import wilson

    n = n_eval * len(rows)
    pooled, diffs = {}, {}
    for a in ARMS:
        k = sum(round(r["arms"][a]["success"] * n_eval) for r in rows)
        pooled[a] = {"successes": k, "episodes": n, "rate": k / n, "ci95": wilson(k / n, n)}
    for hi, lo in DIFFS:
        d = [r["arms"][hi]["success"] - r["arms"][lo]["success"] for r in rows]
        diffs[f"{hi}_vs_{lo}"] = {"per_seed": d, "mean": float(np.mean(d))}
    return {"pooled": pooled, "differences": diffs}


def main(argv: list[str]) -> int:
    p = parser("aloha_value", __doc__)
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
        "--out", type=Path, help="default outputs/aloha_value (outputs/aloha_value-smoke with --smoke)"
    )
    a = p.parse_args(argv)
    check(a, positive=["seeds", "workers"])
    c = config(a.smoke)
    out = a.out or ROOT / ("outputs/aloha_value-smoke" if a.smoke else "outputs/aloha_value")
    if problem := check_out_path(out):  # every input checked before the demos are made
        raise errors.DataError(problem)
    check_own_result(out / "aloha_value.json", KIND)  # an earlier run's may be replaced, a user's never
    device = pick_device(a.device)
    cmd = f"python -m tools.aloha_value --seeds {a.seeds}" + (" --smoke" if a.smoke else "")
    out.mkdir(parents=True, exist_ok=True)
    rows, prov = [], provenance(a.script)
    for s in range(a.seeds):  # the file is rewritten after every seed: a stopped run keeps its seeds
        rows.append(r := one_seed(s, c, a.workers, device))
        rates = " ".join(f"{k} {v['success']:.2f}" for k, v in r["arms"].items())
        kept = f"{r['replay']['kept']}/{r['replay']['attempts']}"
        print(f"seed {s}: replay {kept} kept, {rates} ({r['seconds']} s)", flush=True)
        res = {"kind": KIND, "command": cmd, "config": c, "rows": rows}
        res |= summarize(rows, c["eval_episodes"])
        f = write_atomic(out / "aloha_value.json", dump_json(round_floats(res | prov, 4)))
    print(f"wrote {rel(f)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
