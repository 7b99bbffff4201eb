"""Replay or re-solve? The two moves of the data engine side by side, on the chapter's default configuration.

    python -m tools.replay --seeds 5           seeds 0..4 -> OUT/replay_compare.json
    python -m tools.replay --sigma 0.5 1 2     yields as the perturbation grows -> OUT/replay_sigma.json, .png
    python -m tools.replay --smoke --seeds 2   seconds; numbers not meaningful (OUT = outputs/replay-smoke)

--seeds: for each seed, the chapter's 12 source demos are grown both ways with engine.keep_first
(--per_demo kept demos wanted per source demo, at most --tries attempts per wanted demo; re-solve
keeps every attempt, replay what its success filter passes). Where the yields differ the re-solved
set is cut to the replayed set's count per source demo (its first kept ones in attempt order), so the
two "matched" arms hold the same number of generated demos from the same source demos. Four arms
train side by side with the chapter's recipe (ch37.recipe: the measure region's own code) for the
chapter's full budget (--epochs passes over source + all re-solved demos), so every arm takes the
same steps: source alone, source + replayed, source + re-solved (matched), source + re-solved (all).
Each is evaluated on the chapter's held-out starts of that seed. Also: attempts, yield, failures by
reason and start coverage (the emit region's cells) per mode.

--sigma: for each multiplier m, attempts at (m x 0.08 m, m x 0.5 rad) for both modes, --attempts per
source demo over the seeds' source demos; yield, failures by reason, and how far the kept starts lie
from their source start (block position, m).

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ch37 import ROOT
from ch37.files import dump_json, round_floats, write_atomic
from tools.common import ToolError, _rel, parser, provenance, run_cli

POS_SIGMA, YAW_SIGMA = 0.08, 0.5  # the chapter's defaults (scale_data.py --aug_pos_sigma, --aug_yaw_sigma)
ARMS = ("source", "replay", "resolve_matched", "resolve_all")
SMOKE = dict(
    source_episodes=4, per_demo=2, tries=10, epochs=30, hidden_dim=64, batch_size=64, eval_episodes=8
)
DEFAULTS = dict(
    source_episodes=12, per_demo=8, tries=100, epochs=500, hidden_dim=512, batch_size=128, eval_episodes=50
)


def source_set(out: Path, seed: int, episodes: int, quiet: bool) -> dict:
    """The chapter's PushT source demos of `seed` (generated once under OUT/demos, then read back)."""
    from ch37.demos import ensure_demos
    from ch37.lerobot_io import load_arrays
    from gen_demos_pusht import PUSHT

    path = out / "demos" / f"pusht_seed{seed}_ep{episodes}"
    ensure_demos(
        PUSHT, path, user_given=False, episodes=episodes, seed=seed, noise=PUSHT.default_noise, quiet=quiet
    )
    return load_arrays(path)


def grow(
    sources: dict, mode: str, *, seed: int, per_demo: int, tries: int, pos: float, yaw: float, workers: int
):
    """engine.keep_first over `sources` in `mode`: (kept, attempts, failures)."""
    from ch37 import engine
    from ch37.parallel import parallel_map

    def one(job):
        e, k = job
        return engine.attempt(sources[e], k, seed=seed, pos_sigma=pos, yaw_sigma=yaw, mode=mode)

    return engine.keep_first(
        list(sources),
        per_demo,
        lambda jobs: parallel_map(one, jobs, workers=workers, bar=None),
        reasons=engine.FAILURES[mode],
        cap=tries,
    )


def on_disk(out: Path, name: str, kept: list, seed: int) -> dict:
    """Write kept episodes as a LeRobot v3 set under OUT/demos/NAME and read them back (train on disk)."""
    import pusht_env
    from ch37 import engine
    from ch37.lerobot_io import load_arrays
    from ch37.stamps import MADE_BY, replace_own_dir

    keys = ("observation.state", "action", "episode_index", "aug.source_episode", "aug.start")
    if not kept:
        return {
            "observation.state": np.zeros((0, pusht_env.OBS_DIM), np.float32),
            "action": np.zeros((0, pusht_env.ACT_DIM), np.float32),
            "episode_index": np.zeros(0, np.int64),
            "aug.source_episode": np.zeros((0, 1), np.int64),
            "aug.start": np.zeros((0, len(engine.START_NAMES)), np.float32),
        }
    path = out / "demos" / name
    replace_own_dir(path)
    engine.write_kept(
        path, kept, repo_id=f"local/{name}", stamp={"made_by": MADE_BY, "kind": "augmented", "seed": seed}
    )
    return load_arrays(path, keys=keys)


def per_source(d: dict) -> dict[int, int]:
    _, first = np.unique(d["episode_index"], return_index=True)
    e, n = np.unique(d["aug.source_episode"].reshape(-1)[first], return_counts=True)
    return {int(a): int(b) for a, b in zip(e, n)}


def compare_seed(out: Path, seed: int, c: dict, workers: int, quiet: bool) -> dict:
    from ch37 import engine, recipe
    from ch37.seeds import env_seed

    t0 = time.perf_counter()
    src = source_set(out, seed, c["source_episodes"], quiet)
    sources = engine.sources(src)
    row, sets = {"seed": seed, "modes": {}}, {}
    for mode in ("resolve", "replay"):
        t = time.perf_counter()
        kept, attempts, failures = grow(
            sources,
            mode,
            seed=seed,
            per_demo=c["per_demo"],
            tries=c["tries"],
            pos=POS_SIGMA,
            yaw=YAW_SIGMA,
            workers=workers,
        )
        d = sets[mode] = on_disk(out, f"pusht_seed{seed}_{mode}_k{c['per_demo']}", kept, seed)
        _, first = np.unique(d["episode_index"], return_index=True)
        cells, outside = recipe.coverage().cells(d["aug.start"][first, :2])
        row["modes"][mode] = {
            "attempts": attempts,
            "kept": len(kept),
            "wanted": len(sources) * c["per_demo"],
            "yield": len(kept) / attempts if attempts else 0.0,
            "failures": failures,
            "coverage_cells": len(cells),
            "outside_annulus": outside,
            "seconds": round(time.perf_counter() - t, 1),
        }
    src_cells, _ = recipe.coverage().cells(np.array([s.states[0][2:4] for s in sources.values()]))
    row["coverage_source"] = len(src_cells)
    match = per_source(sets["replay"])  # replay keeps fewer: cut re-solve to its count per source demo
    m = engine.first_per_source(
        sets["resolve"]["episode_index"], sets["resolve"]["aug.source_episode"], match
    )
    x, y = src["observation.state"], src["action"]

    def plus(d, rows=slice(None)):
        return np.concatenate([x, d["observation.state"][rows]]), np.concatenate([y, d["action"][rows]])

    data = {
        "source": (x, y),
        "replay": plus(sets["replay"]),
        "resolve_matched": plus(sets["resolve"], m),
        "resolve_all": plus(sets["resolve"]),
    }
    steps = math.ceil(
        c["epochs"] * len(data["resolve_all"][0]) / c["batch_size"]
    )  # the chapter's full budget
    r = recipe.load(
        hidden_dim=c["hidden_dim"], batch_size=c["batch_size"], lr=1e-3, seed=seed, workers=workers
    )
    t = time.perf_counter()
    pols, fits = r.train([data[a] for a in ARMS], steps)
    eval_seeds = [env_seed(seed, "eval", j) for j in range(c["eval_episodes"])]
    n_gen = {
        "source": 0,
        "replay": len(np.unique(sets["replay"]["episode_index"])),
        "resolve_matched": len(np.unique(sets["resolve"]["episode_index"][m])),
        "resolve_all": len(np.unique(sets["resolve"]["episode_index"])),
    }
    row["steps"], row["arms"] = steps, {}
    for a, pol, fit in zip(ARMS, pols, fits):
        rate = r.evaluate(pol, eval_seeds)
        row["arms"][a] = {
            "demos": c["source_episodes"] + n_gen[a],
            "frames": len(data[a][0]),
            "success": rate,
            "final_loss": round(fit, 6),
        }
    row["train_eval_seconds"] = round(time.perf_counter() - t, 1)
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def summarize(rows: list[dict], eval_episodes: int) -> dict:
    from ch37.recipe import interval

    wilson = interval()
    n = eval_episodes * len(rows)
    pooled = {}
    for a in ARMS:
        k = sum(round(r["arms"][a]["success"] * eval_episodes) for r in rows)
        pooled[a] = {"successes": k, "episodes": n, "rate": k / n, "ci95": wilson(k / n, n)}
    diffs = {}
    for name, (hi, lo) in {
        "replay_vs_source": ("replay", "source"),
        "resolve_matched_vs_source": ("resolve_matched", "source"),
        "resolve_matched_vs_replay": ("resolve_matched", "replay"),
        "resolve_all_vs_source": ("resolve_all", "source"),
    }.items():
        d = [r["arms"][hi]["success"] - r["arms"][lo]["success"] for r in rows]
        diffs[name] = {
            "per_seed": d,
            "mean": float(np.mean(d)),
            "positive": sum(v > 0 for v in d),
            "negative": sum(v < 0 for v in d),
        }
    modes = {}
    for mode in ("resolve", "replay"):
        att = sum(r["modes"][mode]["attempts"] for r in rows)
        kept = sum(r["modes"][mode]["kept"] for r in rows)
        fails: dict[str, int] = {}
        for r in rows:
            for why, v in r["modes"][mode]["failures"].items():
                fails[why] = fails.get(why, 0) + v
        modes[mode] = {
            "attempts": att,
            "kept": kept,
            "yield": kept / att if att else 0.0,
            "failures": fails,
            "coverage_cells_mean": float(np.mean([r["modes"][mode]["coverage_cells"] for r in rows])),
        }
    return {"pooled": pooled, "differences": diffs, "modes": modes}


def sigma_table(
    out: Path, mults: list[float], seeds: list[int], c: dict, attempts: int, workers: int, quiet: bool
) -> dict:
    from ch37 import engine
    from ch37.parallel import parallel_map
    from ch37.recipe import interval

    wilson = interval()
    srcs = {s: engine.sources(source_set(out, s, c["source_episodes"], quiet)) for s in seeds}
    rows = []
    for m in mults:
        for mode in ("resolve", "replay"):
            t = time.perf_counter()
            jobs = [(s, e, k) for s in seeds for e in srcs[s] for k in range(attempts)]

            def one(job, mode=mode, m=m):
                s, e, k = job
                return engine.attempt(
                    srcs[s][e], k, seed=s, pos_sigma=m * POS_SIGMA, yaw_sigma=m * YAW_SIGMA, mode=mode
                )

            res = parallel_map(one, jobs, workers=workers, bar=None)
            kept = [(j, r) for j, r in zip(jobs, res) if not isinstance(r, str)]
            shift = [
                math.hypot(*(r["aug.start"][0][:2] - srcs[s][e].states[0][2:4])) for (s, e, _), r in kept
            ]
            fails = {why: sum(r == why for r in res) for why in engine.FAILURES[mode]}
            rows.append(
                {
                    "multiplier": m,
                    "pos_sigma": m * POS_SIGMA,
                    "yaw_sigma": m * YAW_SIGMA,
                    "mode": mode,
                    "attempts": len(jobs),
                    "kept": len(kept),
                    "yield": len(kept) / len(jobs),
                    "ci95": wilson(len(kept) / len(jobs), len(jobs)),
                    "failures": fails,
                    "kept_block_shift_m": {
                        "median": float(np.median(shift)) if shift else None,
                        "max": float(np.max(shift)) if shift else None,
                    },
                    "seconds": round(time.perf_counter() - t, 1),
                }
            )
            print(
                f"sigma x{m:g} {mode:8s} yield {rows[-1]['yield']:.3f} ({len(kept)}/{len(jobs)}) {fails}",
                flush=True,
            )
    return {"rows": rows}


def sigma_plot(path: Path, table: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=120)
    for mode, color in (("resolve", "tab:blue"), ("replay", "tab:orange")):
        rows = [r for r in table["rows"] if r["mode"] == mode]
        xs = [r["multiplier"] for r in rows]
        ax.plot(xs, [r["yield"] for r in rows], "o-", color=color, label=mode)
        ax.fill_between(
            xs, [r["ci95"][0] for r in rows], [r["ci95"][1] for r in rows], color=color, alpha=0.2
        )
    ax.axvline(1.0, color="gray", ls=":", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("perturbation (x the chapter's 0.08 m, 0.5 rad)")
    ax.set_ylabel("yield (kept / attempts)")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title("How far can you push the start before the task stops being the task?", fontsize=9)
    ax.legend()
    fig.tight_layout()
    from ch37.viz import save_png

    return save_png(fig, path)


def main(argv: list[str] | None = None) -> int:
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
        raise ToolError("nothing to do: give --seeds N and/or --sigma M [M ...]")
    if (a.seeds is not None and a.seeds < 1) or a.attempts < 1 or a.sigma_seeds < 1 or a.workers < 1:
        raise ToolError("--seeds, --attempts, --sigma_seeds and --workers must be >= 1")
    if a.sigma and any(not (0 < m < 100) for m in a.sigma):
        raise ToolError("--sigma multipliers must be in (0, 100)")
    c = SMOKE if a.smoke else DEFAULTS
    out = a.out or ROOT / ("outputs/replay-smoke" if a.smoke else "outputs/replay")
    out.mkdir(parents=True, exist_ok=True)
    prov = {
        "smoke": a.smoke,
        "config": c,
        "pos_sigma": POS_SIGMA,
        "yaw_sigma": YAW_SIGMA,
        **provenance(a.script),
    }
    if a.seeds:
        rows = []
        for s in range(a.seeds):
            rows.append(compare_seed(out, s, c, a.workers, a.smoke))
            r = rows[-1]
            print(
                f"seed {s}: replay {r['modes']['replay']['kept']}/{r['modes']['replay']['attempts']} kept, "
                + " ".join(f"{k} {v['success']:.2f}" for k, v in r["arms"].items())
                + f" ({r['seconds']} s)",
                flush=True,
            )
        res = {
            "kind": "replay_compare",
            "command": f"python -m tools.replay --seeds {a.seeds}" + (" --smoke" if a.smoke else ""),
            "rows": rows,
            **summarize(rows, c["eval_episodes"]),
            **prov,
        }
        f = write_atomic(out / "replay_compare.json", dump_json(round_floats(res, 4)))
        print(f"wrote {_rel(f)}")
    if a.sigma:
        seeds = list(range(a.sigma_seeds))
        table = sigma_table(out, sorted(a.sigma), seeds, c, a.attempts, a.workers, a.smoke)
        mults = " ".join(f"{m:g}" for m in a.sigma)
        cmd = f"python -m tools.replay --sigma {mults} --attempts {a.attempts} --sigma_seeds {a.sigma_seeds}"
        res = {
            "kind": "replay_sigma",
            "command": cmd + (" --smoke" if a.smoke else ""),
            "seeds": seeds,
            "attempts_per_source": a.attempts,
            **table,
            **prov,
        }
        f = write_atomic(out / "replay_sigma.json", dump_json(round_floats(res, 4)))
        print(f"wrote {_rel(f)} and {_rel(sigma_plot(out / 'replay_sigma.png', res))}")
    return 0


if __name__ == "__main__":
    run_cli(main)
