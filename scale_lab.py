"""The Scale Lab: the chapter's BC recipe at many demo counts, for fresh demos and two data engines.

scale_data.py measures one point: 12 source demos against 12 + 96 re-solved ones. This command draws
the curve: success against N total PushT demos (default N = 12, 36, 108, 324, 972) for four curves,
each over seeds 0..2 and 100 held-out starts per seed.

  fresh           N expert demos from the chapter's demo generator (episodes 0..N-1 of each seed)
  resolve         the 12 source demos grown to N by the data engine, mode "resolve" (the chapter's)
  replay          the same with mode "replay" (MimicGen's move); its yield is low, so it is capped by
                  --replay_tries and plotted at the demos it actually kept
  resolve_fixed   resolve, but every N trained for the chapter's full budget (N = 108's steps)

Budget: at each N every curve takes the same gradient steps, --epochs passes over the resolve set at
that N (so resolve at N = 108 is exactly the chapter's augmented_full arm). Replay usually keeps
fewer than N demos (its success filter rejects most attempts); its point then sits at the demos it
kept and trains --epochs passes over them, the same rule at its own N. resolve_fixed holds the
steps at N = 108's for every N (computed from the resolve set at 108 even when 108 is not in --n):
resolve against resolve_fixed reads data apart from compute.

  1. parse     flags, checked in one place; --out claimed (only files this program wrote are replaced)
  2. generate  phase 1, one task per (engine, seed): the data engine's keep_first at the largest N;
               fresh demo sets and the expert's own success (the ceiling) beside them
  3. train     phase 2, one task per (curve, N, seed): the recipe's train + evaluate, largest first
  4. emit      scale_lab.json (sorted, rounded, atomic), scale_lab.png, scale_lab.html and scale_lab.rrd

Every task is a pure function of its arguments with one torch thread, so local processes (the
default) and Ray (--ray, --ray ADDRESS) give the same scale_lab.json, up to its "seconds" fields.

Run:    python scale_lab.py                          (the full lab; see the README for its wall time)
        python scale_lab.py --n 12 108               (two points)
        python scale_lab.py --ray [ADDRESS]          (on a private local Ray, or a cluster)
Smoke:  python scale_lab.py --smoke                  (seconds; N = 12, 24, 36, seeds 0 and 1)
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

from ch37.errors import DataError, run_main

CURVES = ("fresh", "resolve", "replay", "resolve_fixed")
MODES = ("resolve", "replay")  # the engine modes behind the generated curves
SOURCES = 12  # the chapter's --source_episodes: the seed set every generated curve grows from
FIXED_N = 108  # the chapter's default point: 12 sources + 8 re-solves each; its steps are the fixed budget
SMOKE_DEFAULTS = dict(n=[12, 24, 36], seeds=[0, 1], eval_episodes=4, hidden_dim=32, epochs=5, batch_size=64)
RESULTS = ("scale_lab.json", "scale_lab.png", "scale_lab.html", "scale_lab.rrd")


# --- 1. parse ---------------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    flag = p.add_argument
    flag(
        "--n",
        type=int,
        nargs="+",
        default=[12, 36, 108, 324, 972],
        help="total demos per point; >= 12 and N - 12 divisible by 12 (12 sources, equal growth each)",
    )
    flag(
        "--seeds",
        type=int,
        nargs="+",
        default=[0, 1, 2],
        help="seeds >= 0; each draws its own demos and eval starts, disjoint from the others'",
    )
    flag(
        "--eval_episodes",
        type=int,
        default=100,
        help="held-out starts per point (the chapter's 50 are the first 50); 100: +-0.1 at worst",
    )
    flag("--epochs", type=int, default=500, help="passes over the resolve set at N that make N's step budget")
    flag("--batch_size", type=int, default=128, help="frames per gradient step (the chapter's)")
    flag("--lr", type=float, default=1e-3, help="Adam learning rate, cosine-decayed to 0 (the chapter's)")
    flag(
        "--hidden_dim",
        type=int,
        default=512,
        help="width of both hidden layers of the BC MLP (the chapter's)",
    )
    flag(
        "--pos_sigma",
        type=float,
        default=0.08,
        help="m; the engine's block and pusher xy noise (the chapter's)",
    )
    flag("--yaw_sigma", type=float, default=0.5, help="rad; the engine's block yaw noise (the chapter's)")
    flag(
        "--replay_tries",
        type=int,
        default=10,
        help="replay attempts per wanted demo before a source gives up (yield is ~2%% at these sigmas)",
    )
    flag("--out", type=Path, help="output folder (default outputs/scale_lab, -smoke appended with --smoke)")
    flag(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="local processes, or CPUs of a local Ray (default: cores); same results",
    )
    flag(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="run on Ray: alone, a private local Ray with --workers CPUs; with ADDRESS, join that cluster",
    )
    flag("--rerun", action=argparse.BooleanOptionalAction, default=True, help="write scale_lab.rrd")
    flag(
        "--smoke",
        action="store_true",
        help="tiny settings for tests (seconds): N 12 24 36, seeds 0 1, 4 starts; explicit flags win",
    )
    return p


def parse(argv=None) -> argparse.Namespace:
    """The flags, checked; a problem is a DataError (one line, exit 2)."""
    p = parser()

    def error(msg):
        raise DataError(f"{msg} (see --help)")

    p.error = error
    a = p.parse_args(argv)
    if a.smoke:
        p.set_defaults(**SMOKE_DEFAULTS)
        a = p.parse_args(argv)
    a.out = a.out if a.out is not None else Path("outputs/scale_lab" + ("-smoke" if a.smoke else ""))
    if str(a.out).strip() == "":
        raise DataError("--out must not be empty")
    bad = [n for n in a.n if n < SOURCES or (n - SOURCES) % SOURCES]
    if bad:
        raise DataError(
            f"--n {bad[0]}: every N must be >= {SOURCES} with N - {SOURCES} divisible by {SOURCES} "
            f"({SOURCES} source demos, each grown by the same count), e.g. 12 36 108"
        )
    a.n = sorted(set(a.n))
    from ch37.seeds import MAX_SEED, SEED_BLOCK

    if any(not 0 <= s <= MAX_SEED for s in a.seeds):
        raise DataError(f"--seeds must be in [0, {MAX_SEED}], got {a.seeds}")
    a.seeds = sorted(set(a.seeds))
    for name in ("eval_episodes", "epochs", "batch_size", "hidden_dim", "replay_tries", "workers"):
        if getattr(a, name) <= 0:
            raise DataError(f"--{name} must be a positive integer, got {getattr(a, name)}")
    if max(a.n) > SEED_BLOCK or a.eval_episodes > SEED_BLOCK:
        raise DataError(f"--n and --eval_episodes must be at most {SEED_BLOCK} (one seed block)")
    for name in ("pos_sigma", "yaw_sigma", "lr"):
        v = getattr(a, name)
        if not math.isfinite(v) or v < 0 or (name == "lr" and v == 0):
            raise DataError(f"--{name} must be a finite {'positive' if name == 'lr' else 'non-negative'} "
                            f"number, got {v}")  # fmt: skip
    return a


def config(a: argparse.Namespace) -> dict:
    """The settings that shape the numbers (not where they go, nor how fast they come)."""
    keys = ("n", "seeds", "eval_episodes", "epochs", "batch_size", "lr", "hidden_dim", "pos_sigma",
            "yaw_sigma", "replay_tries", "smoke")  # fmt: skip
    return {k: getattr(a, k) for k in keys} | {"sources": SOURCES, "fixed_n": FIXED_N}


def command(a: argparse.Namespace) -> str:
    """The command that gives these numbers, with only the result-shaping flags that differ from their
    defaults (so the local and the Ray run write the same line)."""
    p = parser()
    if a.smoke:
        p.set_defaults(**SMOKE_DEFAULTS)
    parts = ["python scale_lab.py"] + (["--smoke"] if a.smoke else [])
    for k, v in config(a).items():
        if k in ("smoke", "sources", "fixed_n") or v == p.get_default(k):
            continue
        parts.append(f"--{k} " + (" ".join(map(str, v)) if isinstance(v, list) else str(v)))
    return " ".join(parts)


# --- 2. generate (phase 1) ---------------------------------------------------------------------------
def per_source(n: int) -> int:
    """Generated demos per source demo at N total demos."""
    return (n - SOURCES) // SOURCES


def grow(mode: str, seed: int, srcs: dict, per_demo: int, cap: int, pos_sigma: float, yaw_sigma: float):
    """The data engine's first `per_demo` kept attempts per source in (episode, k) order, in this process.

    Pure: attempt k of source e draws from its own seeded stream (ch37.engine), so the result does not
    depend on where this runs. Returns (mode, seed, kept episodes, attempts, failures, seconds)."""
    from ch37 import engine

    t0 = time.perf_counter()

    def run_jobs(jobs):
        return [engine.attempt(srcs[e], k, seed=seed, pos_sigma=pos_sigma, yaw_sigma=yaw_sigma, mode=mode)
                for e, k in jobs]  # fmt: skip

    kept, attempts, failures = engine.keep_first(
        sorted(srcs), per_demo, run_jobs, reasons=engine.FAILURES[mode], cap=cap
    )
    return mode, seed, kept, attempts, failures, time.perf_counter() - t0


def expert_success(seed: int, eval_seeds: list[int]):
    """The noise-free expert's own success on these eval starts: the ceiling a BC policy aims at."""
    import pusht_env
    from ch37.demos import rollout
    from scripted_expert import PushTExpert

    t0 = time.perf_counter()
    env = pusht_env.PushTEnv()
    wins = sum(rollout(env, PushTExpert(noise=0.0), env.reset(s))["success"] for s in eval_seeds)
    return "expert", seed, wins, time.perf_counter() - t0


def phase1(fn, *args):  # noqa: D401
    """One phase-1 task (a module-level entry, so Ray and worker processes can import it)."""
    return fn(*args)


def fresh_demos(path: Path, seed: int, episodes: int) -> str:
    """Episodes 0..episodes-1 of the chapter's PushT demo generator at `seed` (its private cache)."""
    from ch37.demos import ensure_demos
    from gen_demos_pusht import PUSHT

    return ensure_demos(PUSHT, path, user_given=False, episodes=episodes, seed=seed,
                        noise=PUSHT.default_noise, quiet=True)  # fmt: skip


# --- 3. train (phase 2) ------------------------------------------------------------------------------
def train_point(key: tuple, x, y, steps: int, seed: int, eval_seeds: list[int], hp: dict) -> tuple:
    """One (curve, N, seed): the chapter's recipe trained on (x, y) for `steps` steps, rolled out on
    `eval_seeds`. One torch thread, evaluation in this process: a pure function of its arguments."""
    import torch

    torch.set_num_threads(1)
    from ch37 import recipe

    t0 = time.perf_counter()
    r = recipe.load(seed=seed, device="cpu", workers=1, **hp)
    (pol,), (fit,) = r.train([(x, y)], steps)
    rate = r.evaluate(pol, eval_seeds)
    out = {"success": rate, "ci95": r.wilson(rate, len(eval_seeds)), "final_loss": fit}
    return key, out | {"seconds": time.perf_counter() - t0}


def executor(a: argparse.Namespace, fn, tasks: list):
    """fn(*task) for every task, results in completion order: local processes or Ray."""
    from ch37 import executors

    if a.ray is None:
        return executors.run_local(fn, tasks, workers=a.workers)
    return executors.run_ray(fn, tasks, address=None if a.ray == "local" else a.ray, workers=a.workers)


def pooled(successes: list[float], n_each: int, wilson) -> tuple[float, list[float]]:
    """Mean success over seeds and the Wilson interval of all their episodes pooled."""
    mean = sum(successes) / len(successes)
    return mean, wilson(mean, n_each * len(successes))


def run(a: argparse.Namespace) -> int:
    t_start = time.perf_counter()
    from ch37.outputs import claim

    demos_dir = a.out / "demos"
    max_n = max(a.n)
    max_per = {"resolve": max(per_source(max_n), per_source(FIXED_N)), "replay": per_source(max_n)}
    fresh_paths = {s: demos_dir / f"pusht_seed{s}_ep{max_n}" for s in a.seeds}
    gen_paths = {(m, s): demos_dir / f"pusht_{m}_seed{s}_src{SOURCES}_per{max_per[m]}"
                 for m in MODES for s in a.seeds if max_per[m] > 0}  # fmt: skip
    claim(a.out, results=RESULTS, reuses=list(fresh_paths.values()), replaces=list(gen_paths.values()))
    import numpy as np

    import scale_lab as lab  # this file as a module: its functions are what workers and Ray import
    from ch37 import engine
    from ch37.files import dump_json, round_floats, write_atomic
    from ch37.lerobot_io import load_arrays
    from ch37.seeds import env_seed
    from ch37.stamps import MADE_BY, replace_own_dir

    where = "local processes" if a.ray is None else f"ray {a.ray}"
    print(f"scale lab: N {a.n}, seeds {a.seeds}, {a.eval_episodes} eval starts, on {where} ({a.workers})")
    eval_seeds = {s: [env_seed(s, "eval", j) for j in range(a.eval_episodes)] for s in a.seeds}

    # fresh demo sets: files on this machine, made here (or found in the chapter's demo cache)
    t0 = time.perf_counter()
    fresh = {}
    for s in a.seeds:
        how = fresh_demos(fresh_paths[s], s, max_n)
        fresh[s] = load_arrays(fresh_paths[s], keys=("observation.state", "action", "episode_index"))
        print(f"fresh demos, seed {s}: {max_n} episodes, {len(fresh[s]['action'])} frames ({how})")
    print(f"fresh demos ready in {time.perf_counter() - t0:.1f} s")

    # phase 1: the engine's sets, one task per (mode, seed), and the expert's ceiling per seed
    t0 = time.perf_counter()
    srcs = {s: engine.sources({k: v[fresh[s]["episode_index"] < SOURCES] for k, v in fresh[s].items()})
            for s in a.seeds}  # fmt: skip
    tasks = [(lab.expert_success, s, eval_seeds[s]) for s in a.seeds]
    cap = {"resolve": engine.ATTEMPTS_PER_KEPT, "replay": a.replay_tries}
    tasks += [(lab.grow, m, s, srcs[s], max_per[m], cap[m], a.pos_sigma, a.yaw_sigma)
              for m, s in gen_paths]  # fmt: skip
    tasks.sort(key=lambda t: t[0] is lab.expert_success)  # the long ones first
    expert, generation, kept_sets = {}, {}, {}
    for got in lab.executor(a, lab.phase1, tasks):
        if got[0] == "expert":
            expert[got[1]] = got[2]
            continue
        mode, s, kept, attempts, failures, _ = got
        path = gen_paths[(mode, s)]
        replace_own_dir(path)
        if kept:
            stamp = {"made_by": MADE_BY, "kind": "augmented", "seed": s, "mode": mode}
            engine.write_kept(path, kept, repo_id=f"local/pusht_{mode}", stamp=stamp)
        generation.setdefault(mode, {})[str(s)] = {
            "attempts": attempts, "kept": len(kept), "yield": len(kept) / attempts if attempts else 0.0,
            "failures": failures, "per_demo_wanted": max_per[mode],
            "cap": cap[mode] * max_per[mode],
        }  # fmt: skip
        kept_sets[(mode, s)] = len(kept)
    keys = ("observation.state", "action", "episode_index", "aug.source_episode")
    generated = {ms: load_arrays(gen_paths[ms], keys=keys) for ms, k in kept_sets.items() if k}  # on disk
    for mode, by_seed in generation.items():
        kept_of = ", ".join(f"seed {s} kept {g['kept']}/{g['attempts']}" for s, g in by_seed.items())
        print(f"{mode}: {kept_of}")
    print(f"generated in {time.perf_counter() - t0:.1f} s")

    def data(curve: str, n: int, s: int):
        """(states, actions, actual demos) of a curve at nominal N: nested prefixes of the sets above."""
        f = fresh[s]
        if curve == "fresh" or n == SOURCES:
            rows = f["episode_index"] < n
            return f["observation.state"][rows], f["action"][rows], n
        src = f["episode_index"] < SOURCES
        g = generated.get(("resolve" if curve == "resolve_fixed" else curve, s))
        if g is None:
            return f["observation.state"][src], f["action"][src], SOURCES
        rows = engine.first_per_source(g["episode_index"], g["aug.source_episode"], per_source(n))
        x = np.concatenate([f["observation.state"][src], g["observation.state"][rows]])
        y = np.concatenate([f["action"][src], g["action"][rows]])
        return x, y, SOURCES + len(np.unique(g["episode_index"][rows]))

    def steps_at(n: int, s: int) -> int:
        frames = len(data("resolve", n, s)[0])
        return math.ceil(a.epochs * frames / a.batch_size)

    # phase 2: one task per distinct (data, steps, seed); the same data and steps are trained once
    hp = {"hidden_dim": a.hidden_dim, "batch_size": a.batch_size, "lr": a.lr}
    points, units = [], {}
    for s in a.seeds:
        fixed = steps_at(FIXED_N, s)
        for curve in CURVES:
            for n in a.n:
                x, y, demos = data(curve, n, s)
                if curve == "resolve_fixed":
                    steps = fixed
                elif demos < n:  # replay fell short of N: --epochs passes over the demos it kept
                    steps = math.ceil(a.epochs * len(x) / a.batch_size)
                else:
                    steps = steps_at(n, s)
                if curve == "fresh" or demos == SOURCES:  # N = 12, or an engine that kept nothing
                    same = ("fresh", demos)
                else:
                    same = ("resolve" if curve == "resolve_fixed" else curve, n)
                unit = (*same, s, steps)
                units.setdefault(unit, (x, y))
                points.append({"curve": curve, "n": n, "demos": demos, "seed": s, "frames": len(x),
                               "steps": steps, "unit": unit})  # fmt: skip
    order = sorted(units, key=lambda u: (-u[3], u))  # largest budget first: the last task is short
    tasks = [(u, units[u][0], units[u][1], u[3], u[2], eval_seeds[u[2]], hp) for u in order]
    print(f"training: {len(points)} points, {len(tasks)} distinct runs, {sum(u[3] for u in order):,} steps")
    t0 = time.perf_counter()
    results = {}
    for i, (u, r) in enumerate(lab.executor(a, lab.train_point, tasks), 1):
        results[tuple(u)] = r
        names = ", ".join(f"{p['curve']} N={p['n']}" for p in points if p["unit"] == u)
        print(f"  [{i}/{len(tasks)}] seed {u[2]}, {u[3]} steps: {names}: success {r['success']:.2f} "
              f"({r['seconds']:.1f} s)", flush=True)  # fmt: skip
    t_train = time.perf_counter() - t0

    # --- 4. emit ------------------------------------------------------------------------------------
    from ch37.recipe import interval

    wilson = interval()  # the measure region's Wilson interval
    for p in points:
        p.update(results[p.pop("unit")])
    points.sort(key=lambda p: (CURVES.index(p["curve"]), p["n"], p["seed"]))
    curves = {}
    for curve in CURVES:
        rows = {}
        for n in a.n:
            pts = [p for p in points if p["curve"] == curve and p["n"] == n]
            mean, ci = pooled([p["success"] for p in pts], a.eval_episodes, wilson)
            rows[str(n)] = {
                "success": mean,
                "ci95": ci,
                "demos": sum(p["demos"] for p in pts) / len(pts),
                "steps": [p["steps"] for p in pts],
                "frames": [p["frames"] for p in pts],
            }
        curves[curve] = rows
    ceiling = {str(s): expert[s] / a.eval_episodes for s in a.seeds}
    e_mean, e_ci = pooled(list(ceiling.values()), a.eval_episodes, wilson)
    result = {
        "kind": "scale_lab",
        "command": command(a),
        "config": config(a),
        "smoke": a.smoke,
        "fixed_steps": {str(s): steps_at(FIXED_N, s) for s in a.seeds},
        "expert": {"per_seed": ceiling, "success": e_mean, "ci95": e_ci},
        "generation": generation,
        "curves": curves,
        "points": points,
        "interval": "per point: Wilson 95% over its eval starts; per curve: Wilson over all seeds' "
        "episodes pooled",
        "seconds": {"total": time.perf_counter() - t_start, "train": t_train},
    }
    result = round_floats(result, 6)
    written = [write_atomic(a.out / "scale_lab.json", dump_json(result))]
    from ch37 import poster, viz

    written.append(viz.scale_lab_figure(a.out / "scale_lab.png", result))
    written.append(poster.lab(a.out / "scale_lab.html", result))
    if a.rerun:
        written.append(viz.scale_lab_recording(a.out / "scale_lab.rrd", result))
    print(f"expert ceiling {e_mean:.2f}; success by N (mean over seeds):")
    for curve, rows in curves.items():
        print(f"  {curve:13s} " + "  ".join(f"{n}: {r['success']:.2f}" for n, r in rows.items()))
    print(f"finished in {time.perf_counter() - t_start:.0f} s; wrote " + ", ".join(map(str, written)))
    return 0


def main(argv=None) -> int:
    return run_main(lambda: run(parse(argv)))


if __name__ == "__main__":
    sys.exit(main())
