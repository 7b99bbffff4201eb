"""Replay or re-solve? The two moves of the data engine side by side, on the chapter's default configuration.

    python -m tools.replay --seeds 5           seeds 0..4 -> OUT/replay_compare.json
    python -m tools.replay --sigma 0.5 1 2     yields as the perturbation grows -> OUT/replay_sigma.json, .png
    python -m tools.replay --smoke --seeds 2   seconds; numbers not meaningful (OUT = outputs/replay-smoke)

--seeds: for each seed, the chapter's source demos are grown both ways with datagen.grow (the chapter's
kept demos per source demo and attempts per wanted demo; re-solve keeps every attempt, replay what its
success filter passes). Where the yields differ the re-solved set is cut to the replayed set's count
per source demo (its first kept ones in attempt order), so the two "matched" arms hold the same number
of generated demos from the same source demos. Four arms train side by side with the chapter's recipe
(bc_recipe) for the chapter's full budget (epochs passes over source + all re-solved demos), so every
arm takes the same steps: source alone, source + replayed, source + re-solved (matched), source +
re-solved (all). Each is evaluated on the chapter's held-out starts of that seed. Also: attempts,
yield, failures by reason and start coverage (bc_recipe.cells) per mode.

--sigma: for each multiplier m, attempts at m x the chapter's sigmas (0.08 m, 0.5 rad) for both modes,
--attempts per source demo over the seeds' source demos; yield, failures by reason, and how far the
kept starts lie from their source start (block position, m).

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

import bc_recipe as bc
import datagen
from ch37 import ROOT, errors
from ch37.config import DEFAULTS, SMOKE, check
from ch37.errors import DataError
from ch37.ownership import check_out_path, check_own_result, dump_json, round_floats, write_atomic
from ch37.seeds import env_seed
from ch37.viz import save_png
from datagen import ensure_demos
from gen_demos_pusht import PUSHT
from lerobot_v3.dataset import load_arrays
from tools.common import parser, provenance, rel

POS_SIGMA, YAW_SIGMA = DEFAULTS["aug_pos_sigma"], DEFAULTS["aug_yaw_sigma"]  # m, rad
SIGMAS = dict(pos_sigma=POS_SIGMA, yaw_sigma=YAW_SIGMA)
MODES = ("resolve", "replay")
ARMS = ("source", "replay", "resolve_matched", "resolve_all")
DIFFS = (("replay", "source"), ("resolve_matched", "source"), ("resolve_matched", "replay"))
DIFFS += (("resolve_all", "source"),)
COMPARE, SIGMA = "replay_compare", "replay_sigma"  # each JSON's "kind" and name: a re-run replaces its own
KEYS = ("source_episodes", "per_demo", "tries", "epochs", "hidden_dim", "batch_size", "eval_episodes")


def config(smoke: bool) -> dict:
    """KEYS from the chapter's settings (SMOKE's with --smoke, at most 10 attempts per wanted demo)."""
    c = DEFAULTS | (SMOKE | {"aug_tries": 10} if smoke else {})
    return {k: c[{"per_demo": "aug_per_demo", "tries": "aug_tries"}.get(k, k)] for k in KEYS}


def source_set(out: Path, seed: int, episodes: int, quiet: bool) -> dict:
    """The chapter's PushT source demos of `seed` (generated once under OUT/demos, then read back)."""
    path = out / "demos" / f"pusht_seed{seed}_ep{episodes}"
    noise = PUSHT.default_noise
    ensure_demos(PUSHT, path, user_given=False, episodes=episodes, seed=seed, noise=noise, quiet=quiet)
    return load_arrays(path)


def grow(out: Path, mode: str, sources: dict, seed: int, c: dict, workers: int) -> tuple[dict, dict]:
    """The kept set of `mode` written under OUT/demos and read back (training reads what is on disk),
    and its row: attempts, yield, failures by reason, start coverage."""
    t = time.perf_counter()
    how = datagen.Perturbation(seed=seed, **SIGMAS)
    kept, attempts, failures = datagen.grow(
        datagen.PUSHT, sources, c["per_demo"], how, mode=mode, cap=c["tries"], workers=workers
    )
    name = f"pusht_seed{seed}_{mode}_k{c['per_demo']}"
    path = out / "demos" / name
    datagen.save(
        datagen.PUSHT, path, kept, repo_id=f"local/{name}", stamp={"kind": "augmented", "seed": seed}
    )
    d = load_arrays(path, keys=datagen.KEPT_KEYS) if kept else datagen.empty_kept(datagen.PUSHT)
    _, first = np.unique(d["episode_index"], return_index=True)
    cells, outside = bc.cells(d["aug.start"][first, :2])
    row = {"attempts": attempts, "kept": len(kept), "wanted": len(sources) * c["per_demo"]}
    row |= {"yield": len(kept) / attempts if attempts else 0.0, "failures": failures}
    row |= {"coverage_cells": len(cells), "outside_annulus": outside}
    return row | {"seconds": round(time.perf_counter() - t, 1)}, d


def arm_data(src: dict, sets: dict) -> dict:
    """{arm: (states, actions, generated demos)}: the source demos plus the arm's rows of a grown set.
    Replay keeps fewer, so resolve_matched takes per source demo as many re-solved demos as replay kept."""
    res, rep = sets["resolve"], sets["replay"]
    _, first = np.unique(rep["episode_index"], return_index=True)
    e, n = np.unique(rep["aug.source_episode"].reshape(-1)[first], return_counts=True)
    take = dict(zip(e.tolist(), n.tolist()))  # {source episode: demos replay kept from it}
    matched = datagen.first_per_source(res["episode_index"], res["aug.source_episode"], take)
    every, none = slice(None), slice(0)
    rows = {"source": (res, none), "replay": (rep, every), "resolve_matched": (res, matched)}
    rows["resolve_all"] = (res, every)
    out = {}
    for arm, (d, m) in rows.items():
        x = np.concatenate([src["observation.state"], d["observation.state"][m]])
        y = np.concatenate([src["action"], d["action"][m]])
        out[arm] = (x, y, len(np.unique(d["episode_index"][m])))
    return out


def train_arms(data: dict, seed: int, c: dict, workers: int) -> dict:
    """The four arms trained side by side from one init for the chapter's full budget (epochs passes
    over source + all re-solved demos), each rolled out on the seed's held-out starts."""
    t = time.perf_counter()
    steps = math.ceil(c["epochs"] * len(data["resolve_all"][0]) / c["batch_size"])
    init = bc.init_weights(c["hidden_dim"], seed)
    hp = dict(batch_size=c["batch_size"], lr=DEFAULTS["lr"], seed=seed)
    pols, fits = bc.train([data[a][:2] for a in ARMS], steps, init, **hp)
    eval_seeds = [env_seed(seed, "eval", j) for j in range(c["eval_episodes"])]
    arms = {}
    for a, pol, fit in zip(ARMS, pols, fits):
        x, _, generated = data[a]
        rate = bc.evaluate(pol, eval_seeds, workers=workers)
        arms[a] = {"demos": c["source_episodes"] + generated, "frames": len(x), "success": rate}
        arms[a]["final_loss"] = round(fit, 6)
    return {"steps": steps, "arms": arms, "train_eval_seconds": round(time.perf_counter() - t, 1)}


def compare_seed(out: Path, seed: int, c: dict, workers: int, quiet: bool) -> dict:
    """One seed: both modes grown from its source demos, then the four arms trained and evaluated."""
    t0 = time.perf_counter()
    src = source_set(out, seed, c["source_episodes"], quiet)
    sources = datagen.sources(src)
    row, sets = {"seed": seed, "modes": {}}, {}
    for mode in MODES:
        row["modes"][mode], sets[mode] = grow(out, mode, sources, seed, c, workers)
    row["coverage_source"] = len(bc.cells(np.array([s.states[0][2:4] for s in sources.values()]))[0])
    row |= train_arms(arm_data(src, sets), seed, c, workers)
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def summarize(rows: list[dict], eval_episodes: int) -> dict:
    """Each arm's successes pooled over seeds (Wilson 95%), the paired differences, each mode's totals."""
    n = eval_episodes * len(rows)
    pooled, diffs, modes = {}, {}, {}
    for a in ARMS:
        k = sum(round(r["arms"][a]["success"] * eval_episodes) for r in rows)
        pooled[a] = {"successes": k, "episodes": n, "rate": k / n, "ci95": bc.wilson(k / n, n)}
    for hi, lo in DIFFS:
        d = [r["arms"][hi]["success"] - r["arms"][lo]["success"] for r in rows]
        diffs[f"{hi}_vs_{lo}"] = {"per_seed": d, "mean": float(np.mean(d))}
        diffs[f"{hi}_vs_{lo}"] |= {"positive": sum(v > 0 for v in d), "negative": sum(v < 0 for v in d)}
    for mode in MODES:
        got = [r["modes"][mode] for r in rows]
        att, kept = sum(g["attempts"] for g in got), sum(g["kept"] for g in got)
        fails = {why: sum(g["failures"][why] for g in got) for why in got[0]["failures"]}
        modes[mode] = {"attempts": att, "kept": kept, "yield": kept / att if att else 0.0, "failures": fails}
        modes[mode]["coverage_cells_mean"] = float(np.mean([g["coverage_cells"] for g in got]))
    return {"pooled": pooled, "differences": diffs, "modes": modes}


def sigma_row(srcs: dict, m: float, mode: str, attempts: int, workers: int) -> dict:
    """`attempts` attempts per source demo of every seed in `srcs` at m x the chapter's sigmas."""
    t = time.perf_counter()
    results, shift = [], []  # shift: m, from each kept start's block to its source start's
    for s, sources in srcs.items():
        jobs = [(e, k) for e in sources for k in range(attempts)]
        how = datagen.Perturbation(seed=s, pos_sigma=m * POS_SIGMA, yaw_sigma=m * YAW_SIGMA)
        results += (
            got := datagen.run_attempts(datagen.PUSHT, sources, jobs, how, mode=mode, workers=workers)
        )
        for (e, _), r in zip(jobs, got):
            if r.kept:
                shift.append(math.hypot(*(r.episode["aug.start"][0][:2] - sources[e].states[0][2:4])))
    n, kept = len(results), len(shift)
    row = {"multiplier": m, "pos_sigma": m * POS_SIGMA, "yaw_sigma": m * YAW_SIGMA, "mode": mode}
    row |= {"attempts": n, "kept": kept, "yield": kept / n, "ci95": bc.wilson(kept / n, n)}
    reasons = [r.reason for r in results]
    row["failures"] = {why: reasons.count(why) for why in datagen.PUSHT.failures[mode]}
    stats = {"median": np.median, "max": np.max}
    row["kept_block_shift_m"] = {k: float(f(shift)) if shift else None for k, f in stats.items()}
    return row | {"seconds": round(time.perf_counter() - t, 1)}


def sigma_plot(path: Path, table: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=120)
    for mode, color in (("resolve", "tab:blue"), ("replay", "tab:orange")):
        rows = [r for r in table["rows"] if r["mode"] == mode]
        xs = [r["multiplier"] for r in rows]
        ax.plot(xs, [r["yield"] for r in rows], "o-", color=color, label=mode)
        lo, hi = zip(*[r["ci95"] for r in rows])
        ax.fill_between(xs, lo, hi, color=color, alpha=0.2)
    ax.axvline(1.0, color="gray", ls=":", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("perturbation (x the chapter's 0.08 m, 0.5 rad)")
    ax.set_ylabel("yield (kept / attempts)")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title("How far can you push the start before the task stops being the task?", fontsize=9)
    ax.legend()
    fig.tight_layout()
    return save_png(fig, path)


def compare(a, c: dict, out: Path, prov: dict) -> None:
    rows = []
    for s in range(a.seeds):
        rows.append(r := compare_seed(out, s, c, a.workers, a.smoke))
        rates = " ".join(f"{k} {v['success']:.2f}" for k, v in r["arms"].items())
        rep, took = r["modes"]["replay"], f"({r['seconds']} s)"
        print(f"seed {s}: replay {rep['kept']}/{rep['attempts']} kept, {rates} {took}", flush=True)
    cmd = f"python -m tools.replay --seeds {a.seeds}" + (" --smoke" if a.smoke else "")
    res = {"kind": COMPARE, "command": cmd, "rows": rows, **summarize(rows, c["eval_episodes"])}
    f = write_atomic(out / f"{COMPARE}.json", dump_json(round_floats(res | prov, 4)))
    print(f"wrote {rel(f)}")


def sigma(a, c: dict, out: Path, prov: dict) -> None:
    seeds = list(range(a.sigma_seeds))
    srcs = {s: datagen.sources(source_set(out, s, c["source_episodes"], a.smoke)) for s in seeds}
    rows = []
    for m in sorted(a.sigma):
        for mode in MODES:
            rows.append(r := sigma_row(srcs, m, mode, a.attempts, a.workers))
            got = f"yield {r['yield']:.3f} ({r['kept']}/{r['attempts']}) {r['failures']}"
            print(f"sigma x{m:g} {mode:8s} {got}", flush=True)
    mults = " ".join(f"{m:g}" for m in a.sigma)
    cmd = f"python -m tools.replay --sigma {mults} --attempts {a.attempts} --sigma_seeds {a.sigma_seeds}"
    res = {"kind": SIGMA, "command": cmd + (" --smoke" if a.smoke else ""), "seeds": seeds}
    res |= {"attempts_per_source": a.attempts, "rows": rows, **prov}
    f = write_atomic(out / f"{SIGMA}.json", dump_json(round_floats(res, 4)))
    print(f"wrote {rel(f)} and {rel(sigma_plot(out / f'{SIGMA}.png', res))}")


def main(argv: list[str]) -> int:
    p = parser("replay", __doc__)
    p.add_argument("--seeds", type=int, help="compare the two modes on seeds 0..N-1 (the chapter uses 5)")
    p.add_argument("--sigma", type=float, nargs="+", help="perturbation multipliers for the yield table")
    p.add_argument("--attempts", type=int, default=20, help="attempts per source demo per seed in --sigma")
    p.add_argument("--sigma_seeds", type=int, default=5, help="seeds 0..N-1 whose source demos --sigma uses")
    p.add_argument("--smoke", action="store_true", help="tiny configuration (seconds)")
    p.add_argument("--workers", type=int, default=2, help="processes for attempts and evaluation physics")
    p.add_argument("--out", type=Path, help="default outputs/replay (outputs/replay-smoke with --smoke)")
    a = p.parse_args(argv)
    if not a.seeds and not a.sigma:
        raise DataError("nothing to do: give --seeds N and/or --sigma M [M ...]")
    check(a, positive=["attempts", "sigma_seeds", "workers"] + ["seeds"] * (a.seeds is not None))
    if a.sigma and any(not (0 < m < 100) for m in a.sigma):
        raise DataError("--sigma multipliers must be in (0, 100)")
    c = config(a.smoke)
    out = a.out or ROOT / ("outputs/replay-smoke" if a.smoke else "outputs/replay")
    if problem := check_out_path(out):  # every input checked before the demos are made
        raise DataError(problem)
    if a.seeds:  # an earlier run's results may be replaced, a user's files never
        check_own_result(out / f"{COMPARE}.json", COMPARE)
    if a.sigma:
        check_own_result(out / f"{SIGMA}.json", SIGMA, beside=[out / f"{SIGMA}.png"])
    out.mkdir(parents=True, exist_ok=True)
    prov = {"smoke": a.smoke, "config": c, **SIGMAS} | provenance(a.script)
    if a.seeds:
        compare(a, c, out, prov)
    if a.sigma:
        sigma(a, c, out, prov)
    return 0


if __name__ == "__main__":
    errors.main(main)
