"""Replay or re-solve? The data engine's two moves side by side (docs/replay.md), a subcommand per study.

    python -m tools.replay compare --seeds 5         PushT, the chapter's recipe: what each move's demos
                                                     buy BC -> OUT/replay_compare.json
    python -m tools.replay compare --sigma 0.5 1 2   PushT: yields as the perturbation grows -> replay_sigma.*
    python -m tools.replay yield --seeds 3           yield by task and mode, every robot -> replay_yield.json
    python -m tools.replay value --task T --seeds 3  what grown demos buy BC, ALOHA or gym-pusht -> T_value

`SUBCOMMAND --help` says what each does. Each checks its --out first: an earlier run's result there may be
replaced, a user's file never. Exit codes: 0 ok, 2 bad input (one `error:` line).
"""

from __future__ import annotations

import functools
import math
import time
from pathlib import Path

import numpy as np

import bc_recipe as bc
import datagen
from ch37 import ROOT, errors
from ch37.cli import pick_device
from ch37.config import DEFAULTS, SMOKE, check
from ch37.errors import DataError
from ch37.parallel import map_jobs
from ch37.seeds import env_seed
from datagen import ALOHA, PUSHT, Perturbation, engine
from datagen.demos import expert_episodes
from datagen.task import Source, Task, failures_of, known_tasks
from datagen.tasks.aloha import WHOLE, Aloha
from datagen.tasks.aloha_insertion import ALOHA_INSERTION
from datagen.tasks.aloha_transfer_cube import ALOHA_TRANSFER_CUBE, AlohaTransferCube
from datagen.tasks.aloha_transfer_cube import WHOLE as CUBE_WHOLE
from datagen.tasks.gym_pusht import GYM_PUSHT, ONTO_GOAL, GymPushT
from datagen.tasks.pusher import PUSHER, Pusher
from datagen.tasks.pusher import WHOLE as PUSHER_WHOLE
from datagen.tasks.pusht import BY_CONTACT, BY_CONTACT_BLOCK, PushT
from lerobot_v3.dataset import load_arrays
from tools.common import check_results, parser, provenance, rel, subcommands, write_result

POS_SIGMA, YAW_SIGMA = DEFAULTS["aug_pos_sigma"], DEFAULTS["aug_yaw_sigma"]  # m, rad


def pooled_and_differences(rows: list[dict], n_eval: int, arms, pairs, signs: bool = False) -> dict:
    """Each arm's successes pooled over seeds (Wilson 95%), and each pair's paired differences (hi - lo per
    seed, their mean; with `signs` how many are positive and negative)."""
    n = n_eval * len(rows)
    pooled, diffs = {}, {}
    for a in arms:
        k = sum(round(r["arms"][a]["success"] * n_eval) for r in rows)
        pooled[a] = {"successes": k, "episodes": n, "rate": k / n, "ci95": bc.wilson(k / n, n)}
    for hi, lo in pairs:
        d = [r["arms"][hi]["success"] - r["arms"][lo]["success"] for r in rows]
        diffs[f"{hi}_vs_{lo}"] = {"per_seed": d, "mean": float(np.mean(d))}
        if signs:
            diffs[f"{hi}_vs_{lo}"] |= {"positive": sum(v > 0 for v in d), "negative": sum(v < 0 for v in d)}
    return {"pooled": pooled, "differences": diffs}


# --- compare: replay against re-solve on the chapter's PushT recipe -------------------------------------
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
    datagen.ensure_demos(
        PUSHT, path, user_given=False, episodes=episodes, seed=seed, noise=noise, quiet=quiet
    )
    return load_arrays(path)


def grow(out: Path, mode: str, sources: dict, seed: int, c: dict, workers: int) -> tuple[dict, dict]:
    """The kept set of `mode` written under OUT/demos and read back (training reads what is on disk),
    and its row: attempts, yield, failures by reason, start coverage."""
    t = time.perf_counter()
    how = Perturbation(seed=seed, **SIGMAS)
    kept, attempts, failures = datagen.grow(
        PUSHT, sources, c["per_demo"], how, mode=mode, cap=c["tries"], workers=workers
    )
    name = f"pusht_seed{seed}_{mode}_k{c['per_demo']}"
    path = out / "demos" / name
    datagen.save(PUSHT, path, kept, repo_id=f"local/{name}", stamp={"kind": "augmented", "seed": seed})
    d = load_arrays(path, keys=datagen.KEPT_KEYS) if kept else datagen.empty_kept(PUSHT)
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


def train_and_evaluate(
    data: dict, demos: dict, steps: int, seed: int, c: dict, workers: int, task=None, device="cpu"
):
    """{arm: its demos, frames, success, final loss}: the arms of `data` ({arm: (states, actions, ...)})
    trained side by side from one init (the chapter's recipe at c's sizes) for `steps`, each rolled out on
    the seed's held-out starts of `task` (None: the lesson's PushT env, its default shapes)."""
    shapes = {} if task is None else dict(act_dim=task.spec.act_dim, obs_dim=task.spec.obs_dim)
    init = bc.init_weights(c["hidden_dim"], seed, **shapes)
    hp = dict(batch_size=c["batch_size"], lr=DEFAULTS["lr"], seed=seed, device=device)
    pols, fits = bc.train([xy[:2] for xy in data.values()], steps, init, **hp)
    eval_seeds = [env_seed(seed, "eval", j) for j in range(c["eval_episodes"])]
    env = {} if task is None else {"make_env": task.make_env}
    arms = {}
    for a, pol, fit in zip(data, pols, fits):
        rate = bc.evaluate(pol, eval_seeds, workers=workers, **env)
        arms[a] = {"demos": demos[a], "frames": len(data[a][0]), "success": rate, "final_loss": round(fit, 6)}
    return arms


def train_arms(data: dict, seed: int, c: dict, workers: int) -> dict:
    """The four arms trained side by side from one init for the chapter's full budget (epochs passes
    over source + all re-solved demos), each rolled out on the seed's held-out starts."""
    t = time.perf_counter()
    steps = math.ceil(c["epochs"] * len(data["resolve_all"][0]) / c["batch_size"])
    demos = {a: c["source_episodes"] + data[a][2] for a in ARMS}
    arms = train_and_evaluate({a: data[a] for a in ARMS}, demos, steps, seed, c, workers)
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
    modes = {}
    for mode in MODES:
        got = [r["modes"][mode] for r in rows]
        att, kept = sum(g["attempts"] for g in got), sum(g["kept"] for g in got)
        fails = {why: sum(g["failures"][why] for g in got) for why in got[0]["failures"]}
        modes[mode] = {"attempts": att, "kept": kept, "yield": kept / att if att else 0.0, "failures": fails}
        modes[mode]["coverage_cells_mean"] = float(np.mean([g["coverage_cells"] for g in got]))
    return pooled_and_differences(rows, eval_episodes, ARMS, DIFFS, signs=True) | {"modes": modes}


def sigma_row(srcs: dict, m: float, mode: str, attempts: int, workers: int) -> dict:
    """`attempts` attempts per source demo of every seed in `srcs` at m x the chapter's sigmas."""
    t = time.perf_counter()
    results, shift = [], []  # shift: m, from each kept start's block to its source start's
    for s, sources in srcs.items():
        jobs = [(e, k) for e in sources for k in range(attempts)]
        how = Perturbation(seed=s, pos_sigma=m * POS_SIGMA, yaw_sigma=m * YAW_SIGMA)
        results += (got := datagen.run_attempts(PUSHT, sources, jobs, how, mode=mode, workers=workers))
        for (e, _), r in zip(jobs, got):
            if r.kept:
                shift.append(math.hypot(*(r.episode["aug.start"][0][:2] - sources[e].states[0][2:4])))
    n, kept = len(results), len(shift)
    row = {"multiplier": m, "pos_sigma": m * POS_SIGMA, "yaw_sigma": m * YAW_SIGMA, "mode": mode}
    row |= {"attempts": n, "kept": kept, "yield": kept / n, "ci95": bc.wilson(kept / n, n)}
    reasons = [r.reason for r in results]
    row["failures"] = {why: reasons.count(why) for why in failures_of(PUSHT)[mode]}
    stats = {"median": np.median, "max": np.max}
    row["kept_block_shift_m"] = {k: float(f(shift)) if shift else None for k, f in stats.items()}
    return row | {"seconds": round(time.perf_counter() - t, 1)}


def sigma_plot(path: Path, table: dict) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ch37.viz import save_png

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
    cmd = f"python -m tools.replay compare --seeds {a.seeds}" + (" --smoke" if a.smoke else "")
    res = {"kind": COMPARE, "command": cmd, "rows": rows, **summarize(rows, c["eval_episodes"])}
    f = write_result(out / f"{COMPARE}.json", res | prov)
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
    cmd = f"python -m tools.replay compare --sigma {mults} --attempts {a.attempts}"
    cmd += f" --sigma_seeds {a.sigma_seeds}"
    res = {"kind": SIGMA, "command": cmd + (" --smoke" if a.smoke else ""), "seeds": seeds}
    res |= {"attempts_per_source": a.attempts, "rows": rows, **prov}
    f = write_result(out / f"{SIGMA}.json", res)
    print(f"wrote {rel(f)} and {rel(sigma_plot(out / f'{SIGMA}.png', res))}")


def compare_main(argv: list[str]) -> int:
    """Replay or re-solve? The two moves of the data engine side by side, on the chapter's default
    configuration.

        python -m tools.replay compare --seeds 5          seeds 0..4 -> OUT/replay_compare.json
        python -m tools.replay compare --sigma 0.5 1 2    yields as the perturbation grows
                                                          -> OUT/replay_sigma.json, .png
        python -m tools.replay compare --smoke --seeds 2  seconds; numbers not meaningful
                                                          (OUT = outputs/replay-smoke)

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
    """
    p = parser("replay compare", compare_main.__doc__)
    arg = p.add_argument
    arg("--seeds", type=int, help="compare the two modes on seeds 0..N-1 (the chapter uses 5)")
    arg("--sigma", type=float, nargs="+", help="perturbation multipliers for the yield table")
    arg("--attempts", type=int, default=20, help="attempts per source demo per seed in --sigma")
    arg("--sigma_seeds", type=int, default=5, help="seeds 0..N-1 whose source demos --sigma uses")
    arg("--smoke", action="store_true", help="tiny configuration (seconds)")
    arg("--workers", type=int, default=2, help="processes for attempts and evaluation physics")
    arg("--out", type=Path, help="default outputs/replay (outputs/replay-smoke with --smoke)")
    a = p.parse_args(argv)
    if not a.seeds and not a.sigma:
        raise DataError("nothing to do: give --seeds N and/or --sigma M [M ...]")
    check(a, positive=["attempts", "sigma_seeds", "workers"] + ["seeds"] * (a.seeds is not None))
    if a.sigma and any(not (0 < m < 100) for m in a.sigma):
        raise DataError("--sigma multipliers must be in (0, 100)")
    c = config(a.smoke)
    out = a.out or ROOT / ("outputs/replay-smoke" if a.smoke else "outputs/replay")
    kinds = [COMPARE] * bool(a.seeds) + [SIGMA] * bool(a.sigma)
    check_results(out, *kinds, beside={SIGMA: [out / f"{SIGMA}.png"]})  # every input, before the demos
    out.mkdir(parents=True, exist_ok=True)
    prov = {"smoke": a.smoke, "config": c, **SIGMAS} | provenance(a.script)
    if a.seeds:
        compare(a, c, out, prov)
    if a.sigma:
        sigma(a, c, out, prov)
    return 0


# --- yield: kept / attempts by task and mode, on every robot --------------------------------------------
KIND = "replay_yield"  # the JSON's "kind" and name: a re-run replaces its own result, never a user's file
SIGMA_MODES = ("replay", "subtasks", "subtasks_nearest")  # ALOHA modes of the perturbation sweep

# mode -> (the task as that mode describes it, the source a replay transforms)
VARIANTS = {
    "pusht": {
        "resolve": (PUSHT, "own"),
        "replay": (PUSHT, "own"),
        "subtasks": (PushT(BY_CONTACT), "own"),
        "subtasks_nearest": (PushT(BY_CONTACT), "nearest"),
        "subtasks_block_nearest": (PushT(BY_CONTACT_BLOCK), "nearest"),
        "replay_live": (PUSHT, "own"),
        "subtasks_live": (PushT(BY_CONTACT), "own"),
        "subtasks_nearest_live": (PushT(BY_CONTACT), "nearest"),
    },
    "aloha": {
        "resolve": (ALOHA, "own"),
        "replay": (Aloha(WHOLE), "own"),
        "subtasks": (ALOHA, "own"),
        "subtasks_nearest": (ALOHA, "nearest"),
    },
    "gym_pusht": {  # LeRobot's own PushT (issue 40): one segment relative to the block, as the engine's
        "resolve": (GYM_PUSHT, "own"),
        "replay": (GYM_PUSHT, "own"),
        "replay_nearest": (GYM_PUSHT, "nearest"),
        "replay_live": (GYM_PUSHT, "own"),
        "replay_nearest_live": (GYM_PUSHT, "nearest"),
        "onto_goal": (GymPushT(ONTO_GOAL), "own"),
        "onto_goal_live": (GymPushT(ONTO_GOAL), "own"),
    },
    "pusher": {  # Gymnasium's Pusher-v5 (issue 46): the engine's replay in SE(3)
        "resolve": (PUSHER, "own"),
        "replay": (Pusher(PUSHER_WHOLE), "own"),
        "subtasks": (PUSHER, "own"),
        "subtasks_nearest": (PUSHER, "nearest"),
    },
    "aloha_transfer_cube": {  # LeRobot's bimanual ALOHA sim (issue 50): gym-aloha's ViperX arms in 3-D
        "resolve": (ALOHA_TRANSFER_CUBE, "own"),
        "replay": (AlohaTransferCube(CUBE_WHOLE), "own"),
        "subtasks": (ALOHA_TRANSFER_CUBE, "own"),
        "subtasks_nearest": (ALOHA_TRANSFER_CUBE, "nearest"),
    },
    "aloha_insertion": {
        "resolve": (ALOHA_INSERTION, "own"),
        "subtasks": (ALOHA_INSERTION, "own"),
        "subtasks_nearest": (ALOHA_INSERTION, "nearest"),
    },
}
DEFAULT_TASKS = ["pusht", "aloha", "gym_pusht"]  # pusher and the ALOHA sim tasks on request (--tasks)
# gym-aloha's starts lie in 0.1-0.2 m squares: these tasks run every mode at each --sim_sigma multiplier
SIM_TASKS = ("aloha_transfer_cube", "aloha_insertion")
NO_YAW = ("aloha", "pusher", *SIM_TASKS)  # their perturbation moves positions only


def sources(sims: engine.Simulators, task: str, seed: int, n: int) -> dict:
    """The chapter's n source demos of `task` at `seed`, rolled out as the demo generators do."""
    t = VARIANTS[task]["resolve"][0]
    eps = expert_episodes(t, sims.env(t), seed, n, noise=t.default_noise)
    return {i: Source(i, ep["observation.state"], ep["action"]) for i, ep in enumerate(eps)}


def one(work: dict, sims: engine.Simulators, job) -> tuple[str, int]:
    """('kept', frames of the kept episode) or (the failure reason, 0) of one attempt:
    job = (task, mode, seed, episode, k, sigma multiplier); work: (task, seed) -> {e: Source}, built
    before forking; sims: the envs and cut sources the attempts reuse (a forked worker fills its own)."""
    task, mode, seed, e, k, m = job
    pool = work[(task, seed)]
    t, select = VARIANTS[task][mode]
    how = Perturbation(seed, m * POS_SIGMA, m * YAW_SIGMA)
    run = "resolve" if mode == "resolve" else "replay_live" if mode.endswith("_live") else "replay"
    r = engine.attempt(t, pool[e], k, how, mode=run, pool=pool if select == "nearest" else None, sims=sims)
    return ("kept", r.steps) if r.kept else (r.reason, 0)


def cell(
    work: dict, sims, task: str, mode: str, seeds, n: int, attempts: int, m: float, workers: int
) -> dict:
    """Yield of one (task, mode, sigma multiplier) over seeds x n sources x attempts, with its reasons.
    work and sims: one's, handed to the workers with it (map_jobs forks them; nothing is pickled)."""
    from bc_recipe import wilson

    t = time.perf_counter()
    jobs = [(task, mode, s, e, k, m) for s in seeds for e in range(n) for k in range(attempts)]
    got, frames = zip(*list(map_jobs(functools.partial(one, work, sims), jobs, workers=workers)))
    kept = got.count("kept")
    per_seed = {s: got[i * n * attempts : (i + 1) * n * attempts].count("kept") for i, s in enumerate(seeds)}
    row = {"task": task, "mode": mode, "multiplier": m, "pos_sigma": m * POS_SIGMA}
    row |= {
        "yaw_sigma": None if task in NO_YAW else m * YAW_SIGMA,
        "attempts": len(got),
        "kept": kept,
    }
    row |= {"yield": kept / len(got), "ci95": wilson(kept / len(got), len(got)), "kept_per_seed": per_seed}
    row["failures"] = {why: got.count(why) for why in sorted(set(got) - {"kept"})}
    row["kept_frames_median"] = float(np.median([f for f in frames if f])) if kept else None
    return row | {"seconds": round(time.perf_counter() - t, 1)}


def yield_main(argv: list[str]) -> int:
    """Where does replay work? Yield (kept / attempts) by task and mode, on both robots, at the chapter's
    perturbation, and ALOHA replay's yield as the perturbation grows (issue 29's study, first half).

        python -m tools.replay yield --seeds 3 --attempts 10          -> OUT/replay_yield.json
        python -m tools.replay yield --seeds 3 --attempts 10 --aloha_sigma 0.25 0.5 1 2 4

    For each seed, the chapter's 12 source demos of each robot (the demo sets' own seeds and noise:
    episode i of seed s from env seed env_seed(s, "demo", i)), and for each source demo `--attempts`
    attempts k = 0, 1, ...; attempt k of source episode e draws its start from
    engine.attempt_rng(seed, e, k), so every mode of a task meets the same starts (paired). The
    chapter's perturbation: PushT block and pusher xy 0.08 m, block yaw 0.5 rad; ALOHA cube, target and
    both end-effectors 0.08 m each (no yaw: the cube is a point), every point kept in its spawn region (the
    tasks' perturb). Every attempt is datagen.engine.attempt, the engine's one replay (datagen.replay) on
    the task as the mode describes it (VARIANTS). Modes:

        resolve                the task's noise-free expert solves the start
        replay                 the attempt's own source, one segment relative to the object (PushT: the
                               engine's replay, PUSHT; ALOHA: Aloha(WHOLE), both arms relative to the cube)
        subtasks               its own source, cut into subtasks (PushT(BY_CONTACT); ALOHA)
        subtasks_nearest       the source nearest the new start (MimicGen's selection), cut into subtasks
        subtasks_block_nearest PushT only: nearest, with the push relative to the block alone
        replay_nearest         gym-pusht only (LeRobot's PushT, --tasks gym_pusht): the one-segment replay
                               from the source nearest the new start
        onto_goal              gym-pusht only: the one segment with its frame sliding from the block onto
                               the goal over the push (GymPushT(ONTO_GOAL), as PushT's subtasks slide onto
                               the target)
        <mode>_live            PushT and gym-pusht (issue 49 #4): that mode's replay as --aug_mode replay_live
                               runs it, re-anchored on the objects' live poses beyond the task's follow_tol

    Gymnasium's Pusher-v5 (--tasks pusher; issue 46: a 7-DoF arm, targets in SE(3)): its object's (x, y)
    moved by 0.08 m, kept where Pusher-v5's reset puts it; replay is one segment relative to the object,
    subtasks the approach relative to the object and the push sliding onto the goal (the engine's).
    --pusher_sigma sweeps its perturbation as --aloha_sigma does ALOHA's.

    LeRobot's bimanual ALOHA sim (--tasks aloha_transfer_cube aloha_insertion; issue 50: gym-aloha's
    ViperX arms): the sources are gen_demos.py --task T --seed S's; the cube's (or the peg's and the
    socket's) (x, y) moved, kept in gym-aloha's start ranges. Their starts lie in squares 0.1-0.2 m wide,
    so every mode runs at each --sim_sigma multiplier (default 1, the chapter's 0.08 m) rather than at x1
    plus a sweep. replay is one segment with both arms relative to the cube (transfer-cube only),
    subtasks the engine's (transfer-cube: pick, the right arm relative to the cube, then hand-over
    relative to the world; insertion: grasp, each arm relative to its part, then insert relative to the
    world).

    --tasks picks the tasks (default: pusht, aloha and gym_pusht).
    """
    p = parser("replay yield", yield_main.__doc__)
    arg = p.add_argument
    arg("--seeds", type=int, default=3, help="seeds 0..N-1 (their source demos and attempts)")
    arg("--sources", type=int, default=DEFAULTS["source_episodes"], help="source demos per seed")
    arg("--attempts", type=int, default=10, help="attempts per source demo per seed and mode")
    arg("--aloha_sigma", type=float, nargs="*", default=[], help="ALOHA sweep: multipliers of 0.08 m")
    arg("--pusher_sigma", type=float, nargs="*", default=[], help="Pusher sweep: multipliers of 0.08 m")
    sim_help = "ALOHA sim tasks: every mode at each multiplier of 0.08 m"
    arg("--sim_sigma", type=float, nargs="+", default=[1.0], help=sim_help)
    arg("--tasks", nargs="+", choices=list(VARIANTS), default=DEFAULT_TASKS, help="the tasks")
    arg("--workers", type=int, default=1, help="processes for the attempts")
    arg("--out", type=Path, default=ROOT / "outputs/replay_yield", help="output folder")
    a = p.parse_args(argv)
    check(a, positive=["seeds", "sources", "attempts", "workers"])
    if any(not (0 < m < 100) for m in a.aloha_sigma + a.pusher_sigma + a.sim_sigma):
        raise DataError("--aloha_sigma, --pusher_sigma and --sim_sigma multipliers must be in (0, 100)")
    check_results(a.out, KIND)  # before the work
    seeds, work, sims = list(range(a.seeds)), {}, engine.Simulators()  # this run's, passed to cell
    for task in a.tasks:
        for s in seeds:
            work[(task, s)] = sources(sims, task, s, a.sources)
    rows = []
    each = {t: sorted(a.sim_sigma) if t in SIM_TASKS else [1.0] for t in a.tasks}
    todo = [(task, mode, m) for task in a.tasks for m in each[task] for mode in VARIANTS[task]]
    for task, sweep in (("aloha", a.aloha_sigma), ("pusher", a.pusher_sigma)):
        if task in a.tasks:
            todo += [(task, mode, m) for m in sorted(sweep) if m != 1.0 for mode in SIGMA_MODES]
    for task, mode, m in todo:
        rows.append(r := cell(work, sims, task, mode, seeds, a.sources, a.attempts, m, a.workers))
        got = (
            f"{r['kept']}/{r['attempts']} = {r['yield']:.3f} {r['failures']} frames {r['kept_frames_median']}"
        )
        print(f"{task:9s} x{m:<4g} {mode:22s} {got}", flush=True)
    cmd = f"python -m tools.replay yield --seeds {a.seeds} --sources {a.sources} --attempts {a.attempts}"
    cmd += " --aloha_sigma " + " ".join(f"{m:g}" for m in a.aloha_sigma) if a.aloha_sigma else ""
    cmd += " --pusher_sigma " + " ".join(f"{m:g}" for m in a.pusher_sigma) if a.pusher_sigma else ""
    cmd += " --sim_sigma " + " ".join(f"{m:g}" for m in a.sim_sigma) if a.sim_sigma != [1.0] else ""
    cmd += " --tasks " + " ".join(a.tasks) if a.tasks != DEFAULT_TASKS else ""
    res = {"kind": KIND, "command": cmd, "seeds": seeds, "rows": rows} | provenance(a.script)
    a.out.mkdir(parents=True, exist_ok=True)
    f = write_result(a.out / f"{KIND}.json", res)
    print(f"wrote {rel(f)}")
    return 0


# --- value: what grown demos buy the chapter's BC recipe on ALOHA and gym-pusht -------------------------
VALUE_ARMS = ("source", "replayed", "resolved", "fresh")
VALUE_TASKS = {  # each task's arms
    "aloha": VALUE_ARMS,
    "gym_pusht": ("source", "resolved", "fresh"),
    "aloha_transfer_cube": ("source", "replayed", "fresh"),
}
# A task's own sizes where the chapter's do not fit it. Transfer-cube's 400-frame episodes (about 295 kept)
# make the chapter's step rule (500 epochs over the largest arm, about 63,000 frames) some 250,000 steps: a
# fixed 5,000 steps for every arm instead, about 2.5 minutes for the three arms on 2 EPYC cores
VALUE_SIZES = {
    "aloha_transfer_cube": dict(source_episodes=10, per_demo=20, eval_episodes=50, steps=5000),
}
VALUE_SMOKE = dict(source_episodes=2, per_demo=2, eval_episodes=4)
VALUE_DIFFS = (
    ("replayed", "source"),
    ("resolved", "source"),
    ("resolved", "replayed"),
    ("fresh", "resolved"),
)
VALUE_DIFFS += (("fresh", "replayed"), ("fresh", "source"))


def value_config(task: str, smoke: bool) -> dict:
    """The study's sizes for `task`: the chapter's (12 sources, 8 kept per source, 100 held-out starts,
    steps from its epochs), a task's VALUE_SIZES over them; with `smoke` tiny ones (a fixed-step task
    then trains 50 steps)."""
    c = dict(DEFAULTS, eval_episodes=100, source_episodes=12, per_demo=8, tries=10, steps=None)
    c |= VALUE_SIZES.get(task, {})
    if smoke:
        c |= {k: SMOKE[k] for k in ("epochs", "hidden_dim", "batch_size")} | VALUE_SMOKE
        c["steps"] = c["steps"] and 50
    return c


def value_grow(
    task: Task, sources: dict, mode: str, seed: int, c: dict, workers: int = 1
) -> tuple[list[dict], dict]:
    """The first per_demo kept attempts (k order) of each source demo in `mode` (datagen.grow: at most
    tries x per_demo attempts each, on `workers` processes: the same demos for any), and the counts."""
    how = Perturbation(seed, c["aug_pos_sigma"], c["aug_yaw_sigma"])  # ALOHA reads no yaw
    kept, attempts, failures = datagen.grow(
        task, sources, c["per_demo"], how, mode=mode, cap=c["tries"], workers=workers
    )
    seen = {reason: n for reason, n in failures.items() if n}
    return kept, {"attempts": attempts, "kept": len(kept), "failures": seen}


def stack(eps: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    return (np.concatenate([e["observation.state"] for e in eps]), np.concatenate([e["action"] for e in eps]))


def value_seed(task: Task, arms: tuple, seed: int, c: dict, workers: int, device: str = "cpu") -> dict:
    """One seed: its source and fresh demos, the grown arms, all trained and rolled out side by side."""
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
            grown[arm], row[mode] = value_grow(task, sources, mode, seed, c, workers)
            data[arm] = stack(src_eps + grown[arm])
    steps = c["steps"] or math.ceil(c["epochs"] * max(len(data[a][0]) for a in arms) / c["batch_size"])
    demos = {a: {"source": n_src, "fresh": n_all}.get(a) or n_src + len(grown[a]) for a in arms}
    row["steps"] = steps
    row["arms"] = train_and_evaluate({a: data[a] for a in arms}, demos, steps, seed, c, workers, task, device)
    return row | {"seconds": round(time.perf_counter() - t0, 1)}


def value_main(argv: list[str]) -> int:
    """What are generated demos worth? The chapter's BC recipe (bc_recipe: its MLP, each arm's own min-max
    statistics) on up to four arms per seed, every arm at the same gradient steps from the same initial
    weights (issue 29's study on ALOHA, issue 49's on LeRobot's gym-pusht):

        python -m tools.replay value --task aloha --seeds 3      -> OUT/aloha_value.json (outputs/aloha_value)
        python -m tools.replay value --task gym_pusht --seeds 3  -> OUT/gym_pusht_value.json
        python -m tools.replay value --task aloha_transfer_cube --seeds 3
                                                                 -> OUT/aloha_transfer_cube_value.json
        python -m tools.replay value --smoke --seeds 1           seconds; numbers not meaningful

        source     the seed's 12 expert demos (env_seed(seed, "demo", i), i < 12, the task's noise-free
                   expert, as gen_demos.py rolls them out)
        replayed   the 12 + 96 replayed: 8 kept per source demo by the engine's subtask replay
                   (datagen.replay) of its own source, attempts k = 0, 1, ... (engine.attempt_rng(seed, e, k))
                   until 8 pass
        resolved   the 12 + 96 re-solved: the same attempts, the expert solving each perturbed start
        fresh      108 expert demos (i < 108: the 12 sources and 96 more from fresh reset starts)

    The arms by task (--arms to choose): ALOHA all four; gym-pusht source, resolved and fresh (its replay
    keeps none of 360 attempts at the chapter's perturbation: docs/replay.md); LeRobot's ALOHA
    transfer-cube (gym-aloha's ViperX sim) source, replayed and fresh at its own sizes: 10 sources, 20
    kept per source (10 + 200 replayed, 210 fresh), 50 held-out starts. Perturbation: the chapter's
    sigmas in the task's own units (ALOHA: 0.08 m on cube, target and both end-effectors; transfer-cube:
    0.08 m on the cube's x, y; gym-pusht: the task's px scale, datagen.tasks.gym_pusht). Steps: the chapter's
    epochs (500) passes over the largest arm's frames at batch 128 (lr 1e-3 cosine, hidden 512), except
    transfer-cube: a fixed 5,000 steps for every arm (VALUE_SIZES), sized to a 2-core CPU (about 2.5
    minutes for its three arms; the chapter's rule would be some 250,000 steps over its 400-frame
    episodes). The MLP reads the task's observation vector (ALOHA's 10 numbers; gym-pusht's agent x, y
    and the block's 8 keypoints, as lerobot/pusht_keypoints records them; transfer-cube's 14 joints of
    observation.state and the cube's pose of observation.environment_state, 21) and gives its action
    (ALOHA's 6 velocities; gym-pusht's position target, px; transfer-cube's 14 joint and gripper
    targets). Each arm rolls out on the seed's held-out starts (env_seed(seed, "eval", j): the env's
    reset(seed)), judged by the env's own success (gym-pusht's: 95% of the goal covered; transfer-cube's:
    gym-aloha's top reward stage); the pooled rates carry Wilson 95% intervals, the paired differences
    their per-seed values.
    """
    p = parser("replay value", value_main.__doc__)
    arg = p.add_argument
    arg("--task", default="aloha", choices=sorted(VALUE_TASKS), help="the task (default aloha)")
    arg("--arms", nargs="+", choices=VALUE_ARMS, help="which arms (default: the task's, above)")
    arg("--seeds", type=int, default=3, help="seeds 0..N-1")
    arg("--smoke", action="store_true", help="tiny configuration (seconds)")
    arg("--workers", type=int, default=2, help="processes for the evaluation physics")
    devices = ("auto", "cpu", "cuda", "mps")
    arg("--device", default="cpu", choices=devices, help="torch device for the training")
    arg("--out", type=Path, help="default outputs/TASK_value (outputs/TASK_value-smoke with --smoke)")
    a = p.parse_args(argv)
    check(a, positive=["seeds", "workers"])
    task, c = known_tasks()[a.task], value_config(a.task, a.smoke)
    arms = tuple(x for x in VALUE_ARMS if x in (a.arms or VALUE_TASKS[a.task]))
    name = f"{task.name}_value"  # the JSON's "kind" and name: a re-run replaces its own, never a user's
    out = a.out or ROOT / "outputs" / (f"{name}-smoke" if a.smoke else name)
    check_results(out, name)  # every input checked before the demos are made
    device = pick_device(a.device)
    cmd = f"python -m tools.replay value --task {a.task} --seeds {a.seeds}" + (" --smoke" if a.smoke else "")
    cmd += f" --arms {' '.join(arms)}" if a.arms else ""
    out.mkdir(parents=True, exist_ok=True)
    rows, prov = [], provenance(a.script)
    for s in range(a.seeds):  # the file is rewritten after every seed: a stopped run keeps its seeds
        rows.append(r := value_seed(task, arms, s, c, a.workers, device))
        rates = " ".join(f"{k} {v['success']:.2f}" for k, v in r["arms"].items())
        grown = " ".join(f"{m} {r[m]['kept']}/{r[m]['attempts']}" for m in ("replay", "resolve") if m in r)
        print(f"seed {s}: {grown} kept, {rates} ({r['seconds']} s)", flush=True)
        res = {"kind": name, "command": cmd, "config": c, "arms": list(arms), "rows": rows}
        pairs = [d for d in VALUE_DIFFS if set(d) <= set(arms)]
        res |= pooled_and_differences(rows, c["eval_episodes"], arms, pairs)
        f = write_result(out / f"{name}.json", res | prov)
    print(f"wrote {rel(f)}")
    return 0


SUBCOMMANDS = {"compare": compare_main, "yield": yield_main, "value": value_main}


def main(argv: list[str]) -> int:
    return subcommands("replay", SUBCOMMANDS, argv, __doc__)


if __name__ == "__main__":
    errors.main(main)
