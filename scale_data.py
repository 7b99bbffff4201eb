"""Chapter 3.7, Datasets at Scale: wrangle a cross-embodiment pile, grow it, measure what it buys.

Open X-Embodiment and DROID are piles of demos from many robots. Two problems meet you the moment
you pool data: robots disagree on action size and on what a state number means, and a dozen demos
cover too little of the start space for a policy to generalise. This script meets both on two
small MuJoCo robots of our own. It pools PushT (2-D actions) with a bimanual ALOHA cube handoff
(6-D actions), then grows the PushT demos MimicGen-style (perturb the start, re-solve with the
expert, keep only successes; --aug_mode replay makes MimicGen's own move instead) and trains the
same behaviour-cloning MLP with and without the extra demos for the same number of gradient steps,
at two budgets, so what the data buys is read apart from what more training buys.

  1. setup    flags, seeds, device, a two-line banner with the expected wall-clock
  2. wrangle  load both LeRobot sets, per-embodiment stats, normalize, zero-pad + action mask
  3. augment  perturbed PushT starts re-solved by the expert (or replayed), kept only on success
  4. measure  a 2x2: data {source, source+augmented} x budget {short, full}, equal steps per budget
  5. emit     metrics.json, cross_embodiment.json, a PNG figure, an HTML poster and a Rerun recording

Run:    python scale_data.py --seed 0             (python: .venv/bin/python, or with .venv activated)
Smoke:  python scale_data.py --smoke --seed 0     (seconds; two runs give identical metrics.json)
Before the first run, write your prediction in exercises/ex1_predict_scale.py: this run answers it.
"""

# --- region: setup ---
# Imports, the kernel path, the flags (each with its unit and why its default, as CleanRL's Args), the
# seeds and a banner. The data engine's --aug_mode and --aug_tries and the --workers count are the
# engine's and the plumbing's, declared in ch37/config.py; --help lists every flag with its default.
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ch37 import cli

# One path through the matrix kernels on every x86-64 CPU, Intel or AMD, so that one seed trains one
# policy on any machine (docs/reproducibility.md); set before numpy and torch load (a value of yours is kept).
os.environ.update(cli.kernel_path())

import numpy as np
import torch

import bc_recipe as bc  # the network, the training loop and the rollout: open it
import datagen  # the data engine: datagen.grow over a task, here datagen.PUSHT
from ch37 import errors, poster, result_cache, viz  # plumbing and drawing, not the lesson
from ch37.config import (
    FINITE,
    FINITE_POSITIVE,
    NON_NEGATIVE,
    POSITIVE,
    SIGMA_MAX,
    Mode,
    Parallel,
    Tries,
    flag,
)
from ch37.ownership import dump_json, round_floats, write_atomic
from ch37.parallel import progress
from ch37.seeds import MAX_SEED, SEED_BLOCK, env_seed
from exercises import ex1_reminder
from gen_demos_aloha import ALOHA
from gen_demos_pusht import PUSHT
from lerobot_v3 import load_arrays

errors.guard()  # a fixable problem: one line, exit 2; Ctrl-C: exit 130 (demo sets kept, training restarts)
t_start = time.perf_counter()


@dataclass(frozen=True)
class Args(Mode, Tries, Parallel):
    """Chapter 3.7: Datasets at Scale (see the module docstring)."""

    seed: int = flag(
        0, ">= 0; seeds 0, 1, 2 draw disjoint demos and eval starts", bound=NON_NEGATIVE, at_most=MAX_SEED
    )
    source_episodes: int = flag(
        12, "expert demos per robot; 12 is coverage-starved on purpose", bound=POSITIVE, at_most=SEED_BLOCK
    )
    aug_per_demo: int = flag(8, "generated demos kept per PushT source demo (0 = none)", bound=NON_NEGATIVE)
    aug_pos_sigma: float = flag(
        0.08,
        f"m; std of block and pusher xy moves: about half the spawn annulus' width, so starts reach new "
        f"cells (<= {SIGMA_MAX:g})",
        bound=FINITE,
        at_most=SIGMA_MAX,
        aliases=("pos_sigma",),
    )
    aug_yaw_sigma: float = flag(
        0.5,
        f"rad; std of block yaw moves: about 29 degrees, new headings for the same push (<= {SIGMA_MAX:g})",
        bound=FINITE,
        at_most=SIGMA_MAX,
        aliases=("yaw_sigma",),
    )
    epochs: int = flag(
        500,
        "passes over a data set that make a budget: short over the source set, full over source + "
        "augmented (see measure)",
        bound=POSITIVE,
    )
    batch_size: int = flag(128, "frames per gradient step", bound=POSITIVE)
    lr: float = flag(1e-3, "Adam learning rate, cosine-decayed to 0", bound=FINITE_POSITIVE, at_most=1.0)
    hidden_dim: int = flag(512, "width of both hidden layers of the BC MLP", bound=POSITIVE)
    eval_episodes: int = flag(
        50,
        "held-out PushT starts per arm; 50: a success rate's 95%% interval is about +-0.1 at this chapter's "
        "rates (+-0.14 at worst, a rate of 0.5)",
        bound=POSITIVE,
        at_most=SEED_BLOCK,
    )
    full_steps: int = flag(
        0, "steps of the full budget (0: --epochs passes over source+aug)", bound=NON_NEGATIVE
    )
    out: Path = flag(
        None, "output folder (default outputs/ch3.7-scale-data, -smoke appended with --smoke)", type=Path
    )
    pusht_data: Path = flag(
        None, "your own PushT LeRobot set, never modified (default: made under --out)", type=Path
    )
    aloha_data: Path = flag(
        None, "your own ALOHA LeRobot set, never modified (default: made under --out)", type=Path
    )
    device: str = flag("auto", "auto | cpu | cuda | mps (auto: cuda > mps > cpu)")
    smoke: bool = flag(False, "tiny CPU defaults for tests and CI (seconds); explicit flags win")
    rerun: bool = flag(True, "write a Rerun .rrd recording")
    cache: bool = flag(True, "reuse an identical earlier run (same flags and code)")


args = cli.parse(Args)  # every flag checked here: a bad one is one line and exit 2, before any work
args.device = cli.pick_device(args.device)
# Your --pusht_data/--aloha_data are checked before anything is removed (the wrangle region reuses the
# answer); then --out is claimed: usable, locked, nothing of yours in the way, our old results cleared.
given = {PUSHT: args.pusht_data, ALOHA: args.aloha_data}  # None: a set made under --out
datagen.check_given_sets(given, episodes=args.source_episodes, seed=args.seed)
claim = cli.claim_out(args)
device = torch.device(args.device)
torch.manual_seed(args.seed)
if args.smoke:  # tiny matrices: a second thread only adds overhead, and 1 is the same everywhere
    torch.set_num_threads(1)
cli.banner(args, ex1_reminder)  # and, until you have written it, a reminder of exercise 1
cache = result_cache.ResultCache(args, claim)
if cache.replay():  # an identical earlier run (same flags, code and data): its outputs are now in --out
    sys.exit(0)
# --- endregion ---

# --- region: wrangle ---
# Pool two robots' demos. Each keeps its own statistics (a PushT velocity and an ALOHA grip
# command share no scale), actions are zero-padded to the widest robot (6) with a mask so the
# padding never teaches anything, and an embodiment id says which robot a row came from.
# The pile is what a cross-embodiment policy would train on; it is not what trains below. The
# measure region trains a PushT-only BC policy that min-max scales its own data (bc_recipe.Policy),
# so there are two normalizations: the pile standardizes per robot, the policy scales PushT alone.
sets = {}
for emb, yours in given.items():
    path = yours or args.out / "demos" / f"{emb.name}_seed{args.seed}_ep{args.source_episodes}"
    how = datagen.ensure_demos(
        emb,
        path,
        user_given=yours is not None,
        episodes=args.source_episodes,
        seed=args.seed,
        noise=emb.default_noise,
        quiet=args.smoke,
    )
    d = load_arrays(path)  # read back through LeRobotDataset, as any LeRobot user would
    sets[emb.name] = dict(d, path=path, emb=emb)
    lo, hi = d["action"].min(0), d["action"].max(0)
    print(
        f"{emb.name:6s} {len(np.unique(d['episode_index'])):3d} episodes {len(d['action']):6d} frames "
        f"act_dim {d['action'].shape[1]}  action range [{lo.min():+.2f}, {hi.max():+.2f}]  ({how})"
    )


def stats_of(x):  # (N, D) -> per-dimension statistics, the same keys LeRobot's meta/stats.json uses
    return {
        "min": x.min(0),
        "max": x.max(0),
        "mean": x.mean(0),
        "std": x.std(0),
        "q01": np.quantile(x, 0.01, axis=0),
        "q99": np.quantile(x, 0.99, axis=0),
    }


def standardize(x, st):  # a constant dimension (PushT's target pose) is left centred, not divided by 0
    return (x - st["mean"]) / np.where(st["std"] > 1e-8, st["std"], 1.0)


PAD = max(demo["action"].shape[1] for demo in sets.values())  # 6: the widest action wins
pile = {"state": [], "action": [], "mask": [], "emb_id": []}
for emb_id, demo in enumerate(sets.values()):
    demo["stats"] = {"state": stats_of(demo["observation.state"]), "action": stats_of(demo["action"])}
    state = standardize(demo["observation.state"], demo["stats"]["state"])  # (N, 10), own stats
    act = standardize(demo["action"], demo["stats"]["action"])  # (N, act_dim), own stats
    n_rows, act_dim = act.shape
    pile["state"].append(state.astype(np.float32))
    pile["action"].append(np.pad(act, ((0, 0), (0, PAD - act_dim))).astype(np.float32))  # (N, 6) zero-padded
    real = (np.arange(PAD) < act_dim).astype(np.float32)  # (6,) 1 = a real dim, 0 = padding
    pile["mask"].append(np.repeat(real[None], n_rows, 0))  # (N, 6)
    pile["emb_id"].append(np.full(n_rows, emb_id, np.int64))
pile = {k: np.concatenate(v) for k, v in pile.items()}
STATE_DIM = pile["state"].shape[1]  # 10 for both robots: the same width, different meanings
density = {name: pile["mask"][pile["emb_id"] == i].mean() for i, name in enumerate(sets)}
print(
    f"pile: {len(pile['state'])} rows, state (N, {STATE_DIM}), actions padded to (N, {PAD}), "
    f"mask density PushT {density['pusht']:.3f} ALOHA {density['aloha']:.3f}"
)
print(
    "state index 2 is "
    + " and ".join(f"{demo['emb'].spec.state_names[2]} in {name}" for name, demo in sets.items())
    + ": a shared network carries structure across robots, not the meaning of a raw state number"
)


def masked_mse(pred, target, mask):  # padded dims contribute nothing to the loss, hence no gradient
    return ((pred - target) ** 2 * mask).sum() / mask.sum().clamp(min=1)


# The mask must reach the gradient, not just the printout: one shared linear head on the pile.
PROBE_ROWS = 64  # rows per robot in the check
head = torch.nn.Linear(STATE_DIM, PAD)
rows = torch.from_numpy(np.concatenate([np.flatnonzero(pile["emb_id"] == e)[:PROBE_ROWS] for e in (0, 1)]))
pred = head(torch.from_numpy(pile["state"][rows]))
pred.retain_grad()
masked_mse(pred, torch.from_numpy(pile["action"][rows]), torch.from_numpy(pile["mask"][rows])).backward()
pusht_grad = pred.grad[:PROBE_ROWS]  # (64, 6): PushT rows; dims 0..1 are real, 2..5 padding
pusht_act = sets["pusht"]["action"].shape[1]
pad_grad = pusht_grad[:, pusht_act:].abs().max().item()
print(
    f"masked loss: largest gradient on PushT's padded dims = {pad_grad:.1f} "
    f"(real dims: {pusht_grad[:, :pusht_act].abs().max().item():.2e})"
)
print("the pile shows the wrangling; the policy below trains on PushT alone, with its own min-max scaling")
cross = {
    "padded_action_dim": PAD,
    "embodiments": [
        {
            "name": name,
            "id": i,
            "act_dim": int(demo["action"].shape[1]),
            "frames": int(len(demo["action"])),
            "state_names": list(demo["emb"].spec.state_names),
            "action_names": list(demo["emb"].spec.action_names),
            "mask_density": float(density[name]),
            "stats": {
                part: {k: [float(x) for x in v] for k, v in st.items()} for part, st in demo["stats"].items()
            },
        }
        for i, (name, demo) in enumerate(sets.items())
    ],
    "state_index_2_means": {name: demo["emb"].spec.state_names[2] for name, demo in sets.items()},
    "padded_dim_max_grad": pad_grad,
    "quantiles": "q01/q99 over all frames; LeRobot's meta/stats.json averages per-episode quantiles instead",
}
cross_path = write_atomic(args.out / "cross_embodiment.json", dump_json(round_floats(cross, 6)), claim)
# --- endregion ---

# --- region: augment ---
# MimicGen-style growth: take each source demo's first state, perturb the block pose and pusher,
# put the simulator there and let the same expert solve it; keep the demo only if it succeeds.
# No action is invented. Each (source demo, k) draws from its own seeded stream, and a source demo
# keeps its first --aug_per_demo successes in k order, so the set for aug_per_demo=4 is a subset of
# the set for 8 and the scaling curve compares nested data. --aug_mode replay has no solver: it
# replays the source path in the new block pose, and the success filter decides what is kept.
# At the default settings the expert solves every perturbed start (yield 1.00), so the filter
# rejects nothing here; under replay it rejects most attempts (docs/replay.md).
pusht = sets["pusht"]
sources = datagen.sources(pusht)  # {episode: its frames}; re-solving reads only the first state
wanted = len(sources) * args.aug_per_demo
bar = progress(None, total=wanted, desc=f"augment ({args.aug_mode})", quiet=args.smoke)
# datagen.grow makes the moves for every attempt k = 0, 1, ... of each source demo, in rounds, on
# --workers processes (augment_demos.py scales the same engine out):
#   perturb   the first state: block xy, yaw and pusher xy, drawn from this (demo, k)'s own stream
#   re-solve  put the simulator there; the noise-free expert solves it in the real physics
#             (replay: transform the source path into the new block pose, execute it open-loop)
#   keep      the demo, with its provenance, only if the env reports success (else the reason)
perturb = datagen.Perturbation(seed=args.seed, pos_sigma=args.aug_pos_sigma, yaw_sigma=args.aug_yaw_sigma)
kept, attempts, failures = datagen.grow(
    datagen.PUSHT,  # the task: PushT's env, expert and replay (datagen/tasks/pusht.py)
    sources,
    args.aug_per_demo,
    perturb,  # m, m, rad
    mode=args.aug_mode,
    cap=args.aug_tries,
    workers=args.workers,
    bar=bar,
)
bar.close()
yield_ = len(kept) / attempts if attempts else 0.0
if not wanted:  # --aug_per_demo 0: nothing tried, so no yield to report; both data arms are the source set
    print("augment: no augmentation (--aug_per_demo 0); source + augmented is the source set alone")
else:
    print(
        f"augment ({args.aug_mode}): {attempts} attempts, {len(kept)} kept of {wanted} wanted, "
        f"yield {yield_:.2f}"
    )
if attempts > len(kept):  # the success filter at work: what it threw away, and why
    why = ", ".join(f"{reason} {n}" for reason, n in failures.items() if n)
    print(f"  the success filter rejected {attempts - len(kept)} of {attempts} attempts: {why}")
elif attempts:
    print(
        "  the success filter rejected none: the expert solved every start; under --aug_mode replay it bites"
    )
aug_path = args.out / "demos" / cli.aug_dir_name(args.seed, len(sources), args.aug_per_demo, args.aug_mode)
datagen.save(
    datagen.PUSHT, aug_path, kept, repo_id="local/pusht_aug", stamp={"kind": "augmented", "seed": args.seed}
)
# train on what is on disk: the kept demos read back as any LeRobot user would
aug = load_arrays(aug_path, keys=datagen.KEPT_KEYS) if kept else datagen.empty_kept(datagen.PUSHT)
# --- endregion ---

# --- region: measure ---
# What does the extra data buy? Training each arm for --epochs passes over its own data would give
# the augmented arm 7x the gradient steps, and data and compute would move together. A 2x2 pulls
# them apart: data {source, source+augmented} x budget {short = --epochs passes over the source set,
# full = --epochs passes over source+augmented}. The two arms of a budget take exactly the same
# steps from the same initial weights and batch-order seed: within a budget the data is the only
# difference. Every policy rolls out on the same held-out starts. The network, the training loop
# (forward, loss.backward(), optimizer.step()) and the rollout are in bc_recipe.py: open it.
# The table shows each arm's final training loss beside its success because they can disagree:
# a network can fit 12 demos almost exactly (a low loss) and still solve none of the held-out
# starts. That is overfitting, and only the rollouts show it: read success, not loss.
data = {
    "source": (pusht["observation.state"], pusht["action"]),
    "augmented": (np.concatenate([pusht["observation.state"], aug["observation.state"]]),
                  np.concatenate([pusht["action"], aug["action"]])),
}  # fmt: skip
budgets = {  # gradient steps: --epochs passes over a data set, --batch_size rows a step
    "short": math.ceil(args.epochs * len(data["source"][0]) / args.batch_size),
    "full": args.full_steps or math.ceil(args.epochs * len(data["augmented"][0]) / args.batch_size),
}
eval_seeds = [env_seed(args.seed, "eval", j) for j in range(args.eval_episodes)]  # disjoint from demos
init = bc.init_weights(args.hidden_dim, args.seed)  # every arm of both budgets starts from these
recipe = dict(batch_size=args.batch_size, lr=args.lr, seed=args.seed, device=device)
arms = {}
# With no augmented demo the two data arms are one (the same data, steps, init and batch order): it
# trains and rolls out once, and both rows report it.
trained = list(data.values()) if len(aug["action"]) else [data["source"]]
for budget, steps in budgets.items():
    t0 = time.perf_counter()
    # both data arms of this budget, side by side: same steps, same init, same batch order
    pols, fits = bc.train(trained, steps, init, quiet=args.smoke, **recipe)
    rates = [bc.evaluate(pol, eval_seeds, workers=args.workers) for pol in pols]
    for i, (name, (x, _)) in enumerate(data.items()):
        fit, rate = fits[min(i, len(pols) - 1)], rates[min(i, len(pols) - 1)]
        arms[f"{name}_{budget}"] = {"data": name, "budget": budget, "frames": len(x), "steps": steps,
                                    "final_loss": round(fit, 6), "success": rate,
                                    "ci95": bc.wilson(rate, len(eval_seeds))}  # fmt: skip
    each = "for each data arm" if len(pols) > 1 else "for the one data arm (no augmented data)"
    print(f"budget {budget}: {steps} steps {each} ({time.perf_counter() - t0:.1f} s)")
steps_named = " | ".join(f"{b} = {n} steps" for b, n in budgets.items())
print(f"success (95% interval), training loss, on {len(eval_seeds)} held-out starts | {steps_named}")
label = {"source": "source only", "augmented": "source + augmented"}  # the arm named "augmented" has both
for name, (x, _) in data.items():
    row = [arms[f"{name}_{b}"] for b in budgets]
    print(
        f"  {label[name]:18s} {len(x):6d} frames | "
        + " | ".join(
            f"{a['success']:.2f} [{a['ci95'][0]:.2f}, {a['ci95'][1]:.2f}] loss {a['final_loss']:.4f}"
            for a in row
        )
    )
print(
    "  a lower training loss is not a higher success: fitting a few demos closely is not solving new starts"
)
effects = {  # success differences, each between two arms that differ in one thing only
    "data_full": arms["augmented_full"]["success"] - arms["source_full"]["success"],  # the headline
    "data_short": arms["augmented_short"]["success"] - arms["source_short"]["success"],
    "compute_source": arms["source_full"]["success"] - arms["source_short"]["success"],
    "compute_augmented": arms["augmented_full"]["success"] - arms["augmented_short"]["success"],
}
# --- endregion ---

# --- region: emit ---
# Coverage is one reason extra demos can help: count which cells of the spawn annulus (3 rings x 12
# sectors) hold a block start. A perturbed start may lie a little outside the annulus (the engine
# keeps blocks on a wider band): it is kept and trained on, but counted in no cell. Then metrics.json
# (sorted, rounded, atomic; "scale_effect" repeats effects.data_full, the headline, under the name
# the exercises read), a PNG figure, a poster and a Rerun recording, and the headline last: the
# data effect at equal steps, beside the five-seed reference in meta.yaml when this is its setting.
src_starts = np.array([src.states[0][2:4] for src in sources.values()])  # (12, 2) block xy
_, first_rows = np.unique(aug["episode_index"], return_index=True)  # each augmented episode's first frame
aug_starts = aug["aug.start"][first_rows, :2]  # (kept, 2) block xy
c_src, out_src = bc.cells(src_starts)  # bc_recipe.cells: which (ring, sector) a start is in
c_aug, out_aug = bc.cells(aug_starts)
metrics = {
    "seed": args.seed, "smoke": args.smoke, "config": cli.result_config(args),
    "action_dims": {name: int(demo["action"].shape[1]) for name, demo in sets.items()},
    "padded_action_dim": PAD, "source_demos": len(sources), "source_frames": len(data["source"][0]),
    "aug_mode": args.aug_mode, "attempts": attempts, "kept": len(first_rows), "yield": yield_,
    "augment_failures": failures,
    "augmented_frames": len(aug["action"]),
    "budgets": budgets, "arms": arms, "effects": effects, "scale_effect": effects["data_full"],
    "coverage": {"cells": bc.RINGS * bc.SECTORS, "source": len(c_src), "augmented": len(c_aug),
                 "union": len(c_src | c_aug), "outside_annulus": {"source": out_src, "augmented": out_aug}},
}  # fmt: skip
metrics_path = write_atomic(args.out / "metrics.json", dump_json(round_floats(metrics, 6)), claim)
written = [cross_path, metrics_path]
written.append(viz.figure(args.out / "scale_data.png", src_starts, aug_starts, metrics, bc.ANNULUS, claim))
ref = cli.five_seed_reference(metrics["config"])  # meta.yaml's sweep, None unless this configuration
ref_words = "" if args.smoke else cli.reference_words(ref, args.seed, effects["data_full"])
written.append(
    poster.chapter(
        args.out / "scale_data.html", metrics, cross, src_starts, aug_starts, bc.ANNULUS, ref_words, claim
    )
)
if args.rerun:
    shown = [  # a few augmented trajectories
        {"observation.state": aug["observation.state"][aug["episode_index"] == e]}
        for e in aug["episode_index"][first_rows[:8]]
    ]
    rrd = viz.recording(
        args.out / "scale_data.rrd", metrics, src_starts, aug_starts, shown, bc.ANNULUS, claim
    )
    written.append(rrd)
rate = {name: arm["success"] for name, arm in arms.items()}
opens = {".json": "JSON", ".png": "open as an image", ".html": "any browser", ".rrd": "open with: rerun {}"}
files_named = ", ".join(f"{f} ({opens[f.suffix].format(f)})" for f in written)
summary = (
    f"headline: at equal steps ({budgets['full']} each), source only {rate['source_full']:.2f} -> source + "
    f"augmented {rate['augmented_full']:.2f} ({effects['data_full'] * 100:+.0f} points)\n"
    + (f"one seed is one draw: {ref_words}\n" if ref_words else "")
    + f"at the short budget ({budgets['short']} steps): {rate['source_short']:.2f} -> "
    f"{rate['augmented_short']:.2f} ({effects['data_short'] * 100:+.0f}); more steps alone: source only "
    f"{effects['compute_source'] * 100:+.0f}, source + augmented {effects['compute_augmented'] * 100:+.0f}; "
    f"coverage {len(c_src)} -> {len(c_src | c_aug)} of {bc.RINGS * bc.SECTORS} cells (augmented starts "
    f"just outside the annulus, kept but in no cell: {out_aug})\nwrote {files_named}\n"
)
cache.store(written, summary)
print(f"finished in {time.perf_counter() - t_start:.0f} s")
print(summary, end="", flush=True)
# --- endregion ---
