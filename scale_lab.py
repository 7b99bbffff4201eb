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

Run:    python scale_lab.py                          (the full lab; docs/scale_lab.md has its wall time)
        python scale_lab.py --n 12 108               (two points)
        python scale_lab.py --ray [ADDRESS]          (on a private local Ray, or a cluster)
Smoke:  python scale_lab.py --smoke                  (seconds; N = 12, 24, 36, seeds 0 and 1)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from ch37 import cli, config
from ch37.config import CHAPTER as D
from ch37.config import NON_NEGATIVE, POSITIVE, flag
from ch37.errors import DataError, main
from ch37.seeds import MAX_SEED, SEED_BLOCK

CURVES = ("fresh", "resolve", "replay", "resolve_fixed")
MODES = ("resolve", "replay")  # the engine modes behind the generated curves
SOURCES = D.source_episodes  # the seed set every generated curve grows from
N_DEFAULT = (12, 36, 108, 324, 972)  # the curve's points: total PushT demos
FIXED_N = SOURCES * (1 + D.aug_per_demo)  # the chapter's default point (108): its steps are the fixed budget
SMOKE = dict(n=[12, 24, 36], seeds=[0, 1], eval_episodes=4, hidden_dim=32, epochs=5, batch_size=64)
INTERVAL = "per point: Wilson 95% over its eval starts; per curve: Wilson over all seeds' episodes pooled"
RESULTS = ("scale_lab.json", "scale_lab.png", "scale_lab.html", "scale_lab.rrd")
SHAPING = (
    *"n seeds eval_episodes epochs batch_size lr hidden_dim".split(),
    *"aug_pos_sigma aug_yaw_sigma replay_tries smoke".split(),
)
# scale_lab.json's "config" keeps the perturbation's first names (its flags were --pos_sigma, --yaw_sigma,
# still accepted): the same bytes as before the rename, for readers of earlier results.
STORED = {"aug_pos_sigma": "pos_sigma", "aug_yaw_sigma": "yaw_sigma"}


# --- 1. parse ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Args(config.Recipe, config.Perturbation, config.Ray):
    """The Scale Lab: the chapter's BC recipe at many demo counts, for fresh demos and two data engines."""

    # every N >= 12 with N - 12 divisible by 12 (checked in parse(), with why)
    n: list[int] = flag(list(N_DEFAULT), "total demos per point (N)", at_most=SEED_BLOCK, nargs="+")
    seeds: list[int] = flag(
        [0, 1, 2],
        "each draws disjoint demos and eval starts",
        bound=NON_NEGATIVE,
        at_most=MAX_SEED,
        nargs="+",
    )
    eval_episodes: int = flag(
        100, "held-out starts per point; 100: +-0.1 at worst", bound=POSITIVE, at_most=SEED_BLOCK
    )
    replay_tries: int = flag(10, "replay attempts per wanted demo (yield ~2%% here)", bound=POSITIVE)
    out: Path = flag(
        None, "output folder (default outputs/scale_lab, -smoke appended with --smoke)", type=Path
    )
    rerun: bool = flag(True, "write scale_lab.rrd")
    smoke: bool = flag(False, "tiny settings for tests (seconds); explicit flags win")


def parser(smoke: bool = False):
    """The lab's flags; with `smoke`, SMOKE's values are their defaults."""
    p = config.parser_of(Args)
    p.set_defaults(**(SMOKE if smoke else {}))
    return p


def parse(argv=None):
    """The flags, checked; a problem is a DataError (one line, exit 2)."""
    a = config.parse(Args, argv, smoke=SMOKE)
    a.out = a.out if a.out is not None else Path("outputs/scale_lab" + ("-smoke" if a.smoke else ""))
    a.workers = config.default_workers() if a.workers is None else a.workers
    if bad := [n for n in a.n if n < SOURCES or (n - SOURCES) % SOURCES]:
        raise DataError(
            f"--n {bad[0]}: every N must be >= {SOURCES} with N - {SOURCES} divisible by {SOURCES} "
            f"({SOURCES} source demos, each grown by the same count), e.g. 12 36 108"
        )
    a.n, a.seeds = sorted(set(a.n)), sorted(set(a.seeds))
    # one training task, checked as the lesson checks its own before any work: one arm on the largest
    # point's frames (every episode at its step limit); a task that cannot fit alone fails in every worker
    cli.check_memory(cli.training_memory(a, max(a.n) * cli.PUSHT_MAX_STEPS, "--n", arms=1))
    return a


def command(a) -> str:
    """The command that gives these numbers, with only the result-shaping flags that differ from their
    defaults (so the local and the Ray run write the same line)."""
    p = parser(a.smoke)
    parts = ["python scale_lab.py"] + (["--smoke"] if a.smoke else [])
    for k in SHAPING[:-1]:
        v = getattr(a, k)
        if v != p.get_default(k):
            parts.append(f"--{k} " + (" ".join(map(str, v)) if isinstance(v, list) else str(v)))
    return " ".join(parts)


# --- 2. generate (phase 1) ---------------------------------------------------------------------------
def per_source(n: int) -> int:
    """Generated demos per source demo at N total demos."""
    return (n - SOURCES) // SOURCES


def max_per_source(mode: str, max_n: int) -> int:
    """Attempts per source demo the lab makes for `mode` when its largest point is max_n: each
    point's set is the first kept demos of each source (resolve also feeds the fixed-budget point)."""
    return max(per_source(max_n), per_source(FIXED_N)) if mode == "resolve" else per_source(max_n)


def grow(mode: str, seed: int, srcs: dict, per_demo: int, cap: int, pos_sigma: float, yaw_sigma: float):
    """The data engine's set for (mode, seed), in this process (a pure function: see datagen.engine)."""
    import datagen

    how = datagen.Perturbation(seed=seed, pos_sigma=pos_sigma, yaw_sigma=yaw_sigma)
    return (mode, seed, *datagen.grow(datagen.PUSHT, srcs, per_demo, how, mode=mode, cap=cap))


def expert_success(seed: int, eval_seeds: list[int]):
    """The noise-free expert's own success on these eval starts: the ceiling a BC policy aims at."""
    import pusht_env
    from datagen import PUSHT, rollout
    from scripted_expert import PushTExpert

    env = pusht_env.PushTEnv()
    wins = sum(rollout(PUSHT, env, PushTExpert(), env.reset(s))["success"] for s in eval_seeds)
    return "expert", seed, wins


def generate(a, srcs: dict, eval_seeds: dict, gen_paths: dict, max_per: dict):
    """Phase 1: the engine's sets, one task per (mode, seed), written as LeRobot sets and read back;
    the expert's ceiling per seed beside them. Returns (expert wins, generation report, sets)."""
    import operator

    import datagen
    from ch37.parallel import map_jobs
    from lerobot_v3 import load_arrays

    cap = {"resolve": datagen.ATTEMPTS_PER_KEPT, "replay": a.replay_tries}
    tasks = [
        (grow, m, s, srcs[s], max_per[m], cap[m], a.aug_pos_sigma, a.aug_yaw_sigma) for m, s in gen_paths
    ]
    tasks += [(expert_success, s, eval_seeds[s]) for s in a.seeds]  # the long ones first
    expert, generation, generated = {}, {}, {}
    for got in map_jobs(operator.call, tasks, workers=a.workers, ray=a.ray, ordered=False, star=True):
        if got[0] == "expert":
            expert[got[1]] = got[2]
            continue
        mode, s, kept, attempts, failures = got
        stamp = {"kind": "augmented", "seed": s, "mode": mode}
        datagen.save(datagen.PUSHT, gen_paths[(mode, s)], kept, repo_id=f"local/pusht_{mode}", stamp=stamp)
        g = {"attempts": attempts, "kept": len(kept), "yield": len(kept) / attempts if attempts else 0.0}
        g |= {"failures": failures, "per_demo_wanted": max_per[mode], "cap": cap[mode] * max_per[mode]}
        generation.setdefault(mode, {})[str(s)] = g
        if kept:  # train on what is on disk
            generated[(mode, s)] = load_arrays(gen_paths[(mode, s)], keys=datagen.KEPT_KEYS)
    for mode, by_seed in sorted(generation.items()):
        kept_of = ", ".join(f"seed {s} kept {g['kept']}/{g['attempts']}" for s, g in sorted(by_seed.items()))
        print(f"{mode}: {kept_of}")
    return expert, {m: dict(sorted(g.items())) for m, g in sorted(generation.items())}, generated


# --- 3. train (phase 2) ------------------------------------------------------------------------------
def train_point(key: tuple, x, y, steps: int, seed: int, eval_seeds: list[int], hp: dict) -> tuple:
    """One (curve, N, seed): the chapter's recipe trained on (x, y) for `steps` steps, rolled out on
    `eval_seeds`. One torch thread, evaluation in this process: a pure function of its arguments."""
    import torch

    import bc_recipe as bc

    torch.set_num_threads(1)
    t0 = time.perf_counter()
    init = bc.init_weights(hp["hidden_dim"], seed)
    (pol,), (fit,) = bc.train([(x, y)], steps, init, seed=seed, batch_size=hp["batch_size"], lr=hp["lr"])
    rate = bc.evaluate(pol, eval_seeds)
    out = {"success": rate, "ci95": bc.wilson(rate, len(eval_seeds)), "final_loss": fit}
    return key, out | {"seconds": time.perf_counter() - t0}


class Data:
    """The training data of every point: nested prefixes of the fresh and the generated sets."""

    def __init__(self, a, fresh: dict, generated: dict):
        self.a, self.fresh, self.generated = a, fresh, generated

    def at(self, curve: str, n: int, s: int):
        """(states, actions, actual demos) of a curve at nominal N."""
        import numpy as np

        from datagen import first_per_source

        f = self.fresh[s]
        if curve == "fresh" or n == SOURCES:
            rows = f["episode_index"] < n
            return f["observation.state"][rows], f["action"][rows], n
        src = f["episode_index"] < SOURCES
        g = self.generated.get(("resolve" if curve == "resolve_fixed" else curve, s))
        if g is None:
            return f["observation.state"][src], f["action"][src], SOURCES
        rows = first_per_source(g["episode_index"], g["aug.source_episode"], per_source(n))
        x = np.concatenate([f["observation.state"][src], g["observation.state"][rows]])
        y = np.concatenate([f["action"][src], g["action"][rows]])
        return x, y, SOURCES + len(np.unique(g["episode_index"][rows]))

    def steps_at(self, n: int, s: int) -> int:  # the budget at N: --epochs passes over the resolve set
        return math.ceil(self.a.epochs * len(self.at("resolve", n, s)[0]) / self.a.batch_size)

    def points(self):
        """Every (curve, N, seed) point and the distinct (data, steps, seed) runs behind them."""
        a, points, units = self.a, [], {}
        for s in a.seeds:
            fixed = self.steps_at(FIXED_N, s)
            for curve in CURVES:
                for n in a.n:
                    x, y, demos = self.at(curve, n, s)
                    if curve == "resolve_fixed":
                        steps = fixed
                    elif demos < n:  # replay fell short of N: --epochs passes over the demos it kept
                        steps = math.ceil(a.epochs * len(x) / a.batch_size)
                    else:
                        steps = self.steps_at(n, s)
                    if curve == "fresh" or demos == SOURCES:  # N = 12, or an engine that kept nothing
                        same = ("fresh", demos)
                    else:
                        same = ("resolve" if curve == "resolve_fixed" else curve, n)
                    unit = (*same, s, steps)
                    units.setdefault(unit, (x, y))
                    point = dict(curve=curve, n=n, demos=demos, seed=s)
                    points.append(point | dict(frames=len(x), steps=steps, unit=unit))
        return points, units


def train_all(a, points: list, units: dict, eval_seeds: dict) -> dict:
    """Phase 2: one task per distinct run, largest budget first (so the last task is short)."""
    from ch37.parallel import map_jobs

    hp = {"hidden_dim": a.hidden_dim, "batch_size": a.batch_size, "lr": a.lr}
    order = sorted(units, key=lambda u: (-u[3], u))
    tasks = [(u, units[u][0], units[u][1], u[3], u[2], eval_seeds[u[2]], hp) for u in order]
    print(f"training: {len(points)} points, {len(tasks)} distinct runs, {sum(u[3] for u in order):,} steps")
    results = {}
    jobs = map_jobs(train_point, tasks, workers=a.workers, ray=a.ray, ordered=False, star=True)
    for i, (u, r) in enumerate(jobs, 1):
        results[tuple(u)] = r
        names = ", ".join(f"{p['curve']} N={p['n']}" for p in points if p["unit"] == u)
        done = f"success {r['success']:.2f} ({r['seconds']:.1f} s)"
        print(f"  [{i}/{len(tasks)}] seed {u[2]}, {u[3]} steps: {names}: {done}", flush=True)
    return results


# --- 4. emit ------------------------------------------------------------------------------------------
def pooled(successes: list[float], n_each: int) -> tuple[float, list[float]]:
    """Mean success over seeds and the Wilson interval of all their episodes pooled."""
    from bc_recipe import wilson

    mean = sum(successes) / len(successes)
    return mean, wilson(mean, n_each * len(successes))


def curves_of(a, points: list) -> dict:
    curves = {}
    for curve in CURVES:
        curves[curve] = {}
        for n in a.n:
            pts = [p for p in points if p["curve"] == curve and p["n"] == n]
            mean, ci = pooled([p["success"] for p in pts], a.eval_episodes)
            row = {"success": mean, "ci95": ci, "demos": sum(p["demos"] for p in pts) / len(pts)}
            row |= {"steps": [p["steps"] for p in pts], "frames": [p["frames"] for p in pts]}
            curves[curve][str(n)] = row
    return curves


def emit(a, own, points, results, expert, generation, data, t_start, t_train) -> None:
    """scale_lab.json (sorted, rounded, atomic), the figure and the recording, and the curves printed;
    `own` is the run's Claim on --out (ch37.ownership.claim), every write recorded in it."""
    from ch37 import poster, viz
    from ch37.ownership import dump_json, round_floats, write_atomic

    for p in points:
        p.update(results[p.pop("unit")])
    points.sort(key=lambda p: (CURVES.index(p["curve"]), p["n"], p["seed"]))
    curves = curves_of(a, points)
    ceiling = {str(s): expert[s] / a.eval_episodes for s in a.seeds}
    e_mean, e_ci = pooled(list(ceiling.values()), a.eval_episodes)
    result = round_floats(
        {
            "kind": "scale_lab",
            "command": command(a),
            "smoke": a.smoke,
            "config": {STORED.get(k, k): getattr(a, k) for k in SHAPING}
            | {"sources": SOURCES, "fixed_n": FIXED_N},
            "fixed_steps": {str(s): data.steps_at(FIXED_N, s) for s in a.seeds},
            "expert": {"per_seed": ceiling, "success": e_mean, "ci95": e_ci},
            "generation": generation,
            "curves": curves,
            "points": points,
            "interval": INTERVAL,
            "seconds": {"total": time.perf_counter() - t_start, "train": t_train},
        },
        6,
    )
    written = [write_atomic(a.out / "scale_lab.json", dump_json(result), own)]
    written.append(viz.scale_lab_figure(a.out / "scale_lab.png", result, own))
    written.append(poster.lab(a.out / "scale_lab.html", result, own))
    if a.rerun:
        written.append(viz.scale_lab_recording(a.out / "scale_lab.rrd", result, own))
    print(f"expert ceiling {e_mean:.2f}; success by N (mean over seeds):")
    for curve, rows in curves.items():
        print(f"  {curve:13s} " + "  ".join(f"{n}: {r['success']:.2f}" for n, r in rows.items()))
    print(f"finished in {time.perf_counter() - t_start:.0f} s; wrote " + ", ".join(map(str, written)))


def run(a) -> int:
    t_start = time.perf_counter()
    from ch37.ownership import claim
    from ch37.seeds import env_seed
    from datagen import sources
    from lerobot_v3 import load_arrays

    max_n = max(a.n)
    max_per = {m: max_per_source(m, max_n) for m in MODES}
    fresh_paths = {s: a.out / "demos" / f"pusht_seed{s}_ep{max_n}" for s in a.seeds}
    gen_paths = {
        (m, s): a.out / "demos" / f"pusht_{m}_seed{s}_src{SOURCES}_per{max_per[m]}"
        for m in MODES
        for s in a.seeds
        if max_per[m] > 0
    }
    own = claim(a.out, results=RESULTS, reuses=list(fresh_paths.values()), replaces=list(gen_paths.values()))
    where = "local processes" if a.ray is None else f"ray {a.ray}"
    print(f"scale lab: N {a.n}, seeds {a.seeds}, {a.eval_episodes} eval starts, on {where} ({a.workers})")
    eval_seeds = {s: [env_seed(s, "eval", j) for j in range(a.eval_episodes)] for s in a.seeds}
    fresh = {}
    for s in a.seeds:  # fresh demo sets: made here, or found in the chapter's demo cache
        how = fresh_demos(fresh_paths[s], s, max_n)
        fresh[s] = load_arrays(fresh_paths[s], keys=("observation.state", "action", "episode_index"))
        print(f"fresh demos, seed {s}: {max_n} episodes, {len(fresh[s]['action'])} frames ({how})")
    t0 = time.perf_counter()
    srcs = {
        s: sources({k: v[fresh[s]["episode_index"] < SOURCES] for k, v in fresh[s].items()}) for s in a.seeds
    }
    expert, generation, generated = generate(a, srcs, eval_seeds, gen_paths, max_per)
    print(f"generated in {time.perf_counter() - t0:.1f} s")
    data = Data(a, fresh, generated)
    points, units = data.points()
    t0 = time.perf_counter()
    results = train_all(a, points, units, eval_seeds)
    t_train = time.perf_counter() - t0
    emit(a, own, points, results, expert, generation, data, t_start, t_train)
    return 0


def fresh_demos(path: Path, seed: int, episodes: int) -> str:
    """Episodes 0..episodes-1 of the chapter's PushT demo generator at `seed` (its private cache)."""
    from datagen import ensure_demos
    from gen_demos_pusht import PUSHT

    return ensure_demos(
        PUSHT, path, user_given=False, episodes=episodes, seed=seed, noise=PUSHT.default_noise, quiet=True
    )


if __name__ == "__main__":
    main(lambda argv: run(parse(argv)))
