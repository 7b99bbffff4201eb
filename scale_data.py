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

Run:    python scale_data.py --seed 0
Smoke:  python scale_data.py --smoke --seed 0     (seconds; two runs give identical metrics.json)
"""

# --- region: setup ---
# Every knob is a flag with its unit and why its default; --smoke sets tiny CPU defaults.
import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from ch37 import cli, errors, result_cache

errors.guard()  # a problem you can fix: one line, exit 2; Ctrl-C: exit 130, and the same command continues
t_start = time.perf_counter()
p = argparse.ArgumentParser(description="Chapter 3.7: Datasets at Scale (see the module docstring).")
flag, on_off = p.add_argument, argparse.BooleanOptionalAction
flag(
    "--out", type=Path, help="output folder (default outputs/ch3.7-scale-data, -smoke appended with --smoke)"
)
flag("--pusht_data", type=Path, help="your own PushT LeRobot set, never modified (default: made under --out)")
flag("--aloha_data", type=Path, help="your own ALOHA LeRobot set, never modified (default: made under --out)")
flag(
    "--source_episodes",
    type=int,
    default=12,
    help="expert demos per robot; 12 is coverage-starved on purpose",
)
flag("--aug_per_demo", type=int, default=8, help="generated demos kept per PushT source demo (0 = none)")
flag(
    "--aug_mode",
    choices=("resolve", "replay"),
    default="resolve",
    help="resolve: the expert solves each perturbed start; replay: MimicGen's move, the source path "
    "transformed into the new block pose and executed open-loop (no solver)",
)
flag(
    "--aug_tries",
    type=int,
    default=100,
    help="attempts per wanted demo before a source demo gives up (replay's success filter rejects most)",
)
flag("--aug_pos_sigma", type=float, default=0.08, help="m; std of block and pusher xy perturbation")
flag("--aug_yaw_sigma", type=float, default=0.5, help="rad; std of block yaw perturbation")
flag("--epochs", type=int, default=500, help="passes over a data set that make a budget (see measure)")
flag(
    "--full_steps", type=int, default=0, help="steps of the full budget (0: --epochs passes over source+aug)"
)
flag("--batch_size", type=int, default=128, help="frames per gradient step")
flag("--lr", type=float, default=1e-3, help="Adam learning rate, cosine-decayed to 0")
flag("--hidden_dim", type=int, default=512, help="width of both hidden layers of the BC MLP")
flag("--eval_episodes", type=int, default=50, help="held-out PushT starts per arm; 50: +-0.14 at worst")
flag("--seed", type=int, default=0, help=">= 0; seeds 0, 1, 2 draw disjoint demos and eval starts")
flag("--device", default="auto", help="auto | cpu | cuda | mps (auto: cuda > mps > cpu)")
flag("--smoke", action="store_true", help="tiny CPU defaults for tests and CI (seconds); explicit flags win")
flag("--rerun", action=on_off, default=True, help="write a Rerun .rrd recording")
flag("--cache", action=on_off, default=True, help="reuse an identical earlier run (same flags and code)")
flag(
    "--workers",
    type=int,
    help="processes for re-solves and evaluation physics (default: cores); same results",
)
args = cli.parse(p)  # every flag checked here: a bad one is one line and exit 2, before any heavy import
cli.claim_out(args)  # --out usable and locked, nothing of yours in the way, our old results there cleared

import torch  # noqa: E402  (after the checks, so --help and flag errors are instant)

args.device = cli.pick_device(args.device)
torch.manual_seed(args.seed)
if args.smoke:
    torch.set_num_threads(
        1
    )  # tiny matrices: a second thread only adds overhead, and 1 is the same everywhere
device = torch.device(args.device)
cli.banner(args)
cache = result_cache.ResultCache(args)
if cache.replay():  # an identical earlier run (same flags, code and data): its outputs are now in --out
    sys.exit(0)
# --- endregion ---

# --- region: wrangle ---
# Pool two robots' demos. Each keeps its own statistics (a PushT velocity and an ALOHA grip
# command share no scale), actions are zero-padded to the widest robot (6) with a mask so the
# padding never teaches anything, and an embodiment id says which robot a row came from.
from ch37.demos import ensure_demos  # noqa: E402
from ch37.errors import DataError, fail  # noqa: E402
from ch37.files import dump_json, round_floats, write_atomic  # noqa: E402
from ch37.lerobot_io import load_arrays  # noqa: E402
from gen_demos_aloha import ALOHA  # noqa: E402
from gen_demos_pusht import PUSHT  # noqa: E402

sets = {}
for emb, given in ((PUSHT, args.pusht_data), (ALOHA, args.aloha_data)):
    path = given or args.out / "demos" / f"{emb.name}_seed{args.seed}_ep{args.source_episodes}"
    try:
        how = ensure_demos(
            emb,
            path,
            user_given=given is not None,
            episodes=args.source_episodes,
            seed=args.seed,
            noise=emb.default_noise,
            quiet=args.smoke,
        )
    except DataError as e:
        fail(str(e))
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
    pile["mask"].append(
        np.repeat((np.arange(PAD) < act_dim).astype(np.float32)[None], n_rows, 0)
    )  # (N, 6) 1 = real
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
    + " and ".join(f"{demo['emb'].env_module.STATE_NAMES[2]} in {name}" for name, demo in sets.items())
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
cross = {
    "padded_action_dim": PAD,
    "embodiments": [
        {
            "name": name,
            "id": i,
            "act_dim": int(demo["action"].shape[1]),
            "frames": int(len(demo["action"])),
            "state_names": list(demo["emb"].env_module.STATE_NAMES),
            "action_names": list(demo["emb"].env_module.ACTION_NAMES),
            "mask_density": float(density[name]),
            "stats": {
                part: {k: [float(x) for x in v] for k, v in st.items()} for part, st in demo["stats"].items()
            },
        }
        for i, (name, demo) in enumerate(sets.items())
    ],
    "state_index_2_means": {name: demo["emb"].env_module.STATE_NAMES[2] for name, demo in sets.items()},
    "padded_dim_max_grad": pad_grad,
    "quantiles": "q01/q99 over all frames; LeRobot's meta/stats.json averages per-episode quantiles instead",
}
write_atomic(args.out / "cross_embodiment.json", dump_json(round_floats(cross, 6)))
# --- endregion ---

# --- region: augment ---
# MimicGen-style growth: take each source demo's first state, perturb the block pose and pusher,
# put the simulator there and let the same expert solve it; keep the demo only if it succeeds.
# No action is invented. Each (source demo, k) draws from its own seeded stream, and a source demo
# keeps its first --aug_per_demo successes in k order, so the set for aug_per_demo=4 is a subset of
# the set for 8 and the scaling curve compares nested data. --aug_mode replay has no solver: it
# replays the source path in the new block pose, and the success filter decides what is kept.
import pusht_env  # noqa: E402
from ch37 import engine  # noqa: E402
from ch37.demos import progress  # noqa: E402
from ch37.parallel import parallel_map  # noqa: E402
from ch37.seeds import env_seed  # noqa: E402
from ch37.stamps import MADE_BY, replace_own_dir  # noqa: E402

pusht = sets["pusht"]
sources = engine.sources(pusht)  # {episode: its frames}; re-solving reads only the first state
first = {e: src.states[0] for e, src in sources.items()}


def grow(job):  # (source episode, k) -> a demo from a perturbed start, or why there is none
    e, k = job
    # ch37.engine.attempt makes the moves (augment_demos.py scales the same function out):
    #   perturb   first[e]: block xy, yaw and pusher xy, drawn from this (demo, k)'s own stream
    #   re-solve  put the simulator there; the noise-free expert solves it in the real physics
    #             (replay: transform the source path into the new block pose, execute it open-loop)
    #   keep      the demo, with its provenance, only if the env reports success (else the reason)
    return engine.attempt(
        sources[e], k, seed=args.seed, pos_sigma=args.aug_pos_sigma, yaw_sigma=args.aug_yaw_sigma,
        mode=args.aug_mode,
    )  # fmt: skip


wanted = len(first) * args.aug_per_demo
bar = progress(None, total=wanted, desc=f"augment ({args.aug_mode})", quiet=args.smoke)
kept, attempts, failures = engine.keep_first(
    first,
    args.aug_per_demo,
    lambda jobs: parallel_map(grow, jobs, workers=args.workers, bar=bar),
    reasons=engine.FAILURES[args.aug_mode],
    cap=args.aug_tries,
)  # fmt: skip  (attempts k = 0, 1, ... per source demo, in rounds, until its demos are kept)
bar.close()
yield_ = len(kept) / attempts if attempts else 0.0
print(
    f"augment ({args.aug_mode}): {attempts} attempts, {len(kept)} kept of {wanted} wanted, yield {yield_:.2f}"
)
if attempts > len(kept):  # the success filter at work: what it threw away, and why
    print(f"  the success filter rejected {attempts - len(kept)} of {attempts} attempts: " + ", ".join(
        f"{why} {n}" for why, n in failures.items() if n))  # fmt: skip
aug_path = args.out / "demos" / cli.aug_dir_name(args.seed, len(first), args.aug_per_demo, args.aug_mode)
try:
    replace_own_dir(aug_path)
except DataError as e:
    fail(str(e))
aug = {
    "observation.state": np.zeros((0, pusht_env.OBS_DIM), np.float32),
    "action": np.zeros((0, pusht_env.ACT_DIM), np.float32),
    "episode_index": np.zeros(0, np.int64),
    "aug.start": np.zeros((0, len(engine.START_NAMES)), np.float32),
}
if kept:
    stamp = {"made_by": MADE_BY, "kind": "augmented", "seed": args.seed}
    engine.write_kept(aug_path, kept, repo_id="local/pusht_aug", stamp=stamp)  # a LeRobot v3 set
    aug = load_arrays(aug_path, keys=tuple(aug))  # train on what is on disk
# --- endregion ---

# --- region: measure ---
# What does the extra data buy? A first recipe trained each arm for 500 epochs of its own data, so
# the augmented arm also took 7x the gradient steps, and data and compute moved together. Here a
# 2x2 pulls them apart: data {source, source+augmented} x budget {short = --epochs passes over the
# source set, full = --epochs passes over source+augmented}. The two arms of a budget take exactly
# the same steps from the same initial weights and batch-order seed: within a budget the data is
# the only difference. Every policy rolls out on the same held-out starts, in lockstep.
from ch37.ensemble import BatchOrder, MLPStack  # noqa: E402  (arms side by side, see its docstring)
from ch37.parallel import LockstepEnvs  # noqa: E402


def mlp(hidden):  # the BC network: 10 -> hidden -> hidden -> 2, ReLU
    return torch.nn.Sequential(
        torch.nn.Linear(pusht_env.OBS_DIM, hidden), torch.nn.ReLU(),
        torch.nn.Linear(hidden, hidden), torch.nn.ReLU(),
        torch.nn.Linear(hidden, pusht_env.ACT_DIM),
    )  # fmt: skip


class BCPolicy(torch.nn.Module):
    def __init__(self, states, actions, net):
        super().__init__()
        self.net = net
        for name, x in (("s", states), ("a", actions)):  # min-max ranges of the arm's own data
            lo, hi = torch.as_tensor(x.min(0)), torch.as_tensor(x.max(0))
            self.register_buffer(f"{name}_lo", lo)
            self.register_buffer(f"{name}_span", torch.where(hi - lo > 1e-6, hi - lo, torch.ones_like(lo)))

    def norm_s(self, s):  # -> [-1, 1]
        return 2 * (s - self.s_lo) / self.s_span - 1

    def norm_a(self, a):
        return 2 * (a - self.a_lo) / self.a_span - 1

    def forward(self, s):  # raw state (B, 10) -> raw action (B, 2), m/s
        return (self.net(self.norm_s(s)) + 1) / 2 * self.a_span + self.a_lo


torch.manual_seed(args.seed)
init_weights = mlp(args.hidden_dim).state_dict()  # every arm starts from these


def train(datasets, steps):
    """One BCPolicy per (states, actions) in `datasets`, trained side by side for exactly `steps`
    steps of --batch_size rows; returns the policies and each one's final MSE on its own data."""
    pols = [BCPolicy(x, y, mlp(args.hidden_dim)).to(device) for x, y in datasets]
    tensors = [
        (p.norm_s(torch.as_tensor(x, device=device)), p.norm_a(torch.as_tensor(y, device=device)))
        for p, (x, y) in zip(pols, datasets)
    ]  # fmt: skip  (normalized once, not per batch)
    orders = [BatchOrder(len(x), args.batch_size, args.seed) for x, _ in tensors]  # same seed for every arm
    model = MLPStack([init_weights] * len(pols)).to(device)  # arm e = slice e of every weight
    opt = torch.optim.Adam(model.parameters(), lr=args.lr, fused=device.type in ("cpu", "cuda"))  # one kernel
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps)  # lr cosine-decayed to 0
    bar = progress(None, total=steps, desc="train", quiet=args.smoke)
    for _ in range(steps):
        idx = [o.next() for o in orders]
        xb = torch.stack([x[i] for (x, _), i in zip(tensors, idx)])  # (arms, B, 10)
        yb = torch.stack([y[i] for (_, y), i in zip(tensors, idx)])  # (arms, B, 2)
        loss = ((model(xb) - yb) ** 2).mean(dim=(1, 2)).sum()  # each arm's MSE; the sum keeps them apart
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        bar.update()
    bar.close()
    with torch.no_grad():  # fit on each arm's whole training set, a digit-level fingerprint of the run
        fits = [torch.nn.functional.mse_loss(model.load_into(p.net, e)(x), y).item()
                for e, (p, (x, y)) in enumerate(zip(pols, tensors))]  # fmt: skip
    return [p.eval() for p in pols], fits


@torch.no_grad()
def evaluate(pol, seeds):
    """Success rate of `pol` on PushT starts env.reset(seed), all episodes stepped in lockstep."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a (N, 10) batch needs no second thread; leave the cores to the physics workers
    with LockstepEnvs(pusht_env.PushTEnv, seeds, workers=args.workers) as envs:
        obs = envs.reset()  # (N, 10)
        live, success = np.ones(len(seeds), bool), np.zeros(len(seeds), bool)
        while live.any():
            idx = np.flatnonzero(live)
            act = pol(torch.as_tensor(obs[idx], device=device)).cpu().numpy()  # one call for every live env
            obs[idx], done, success[idx] = envs.step(idx, act)
            live[idx] = ~done
    torch.set_num_threads(threads)
    return float(success.mean())


def wilson(p_hat, n, z=1.96):  # 95% interval for a success rate from n episodes
    centre = (p_hat + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p_hat * (1 - p_hat) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [max(0.0, centre - half), min(1.0, centre + half)]


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
arms = {}
for budget, steps in budgets.items():
    t0 = time.perf_counter()
    pols, fits = train(list(data.values()), steps)  # both data arms of this budget, side by side
    for (name, (x, _)), pol, fit in zip(data.items(), pols, fits):
        rate = evaluate(pol, eval_seeds)
        arms[f"{name}_{budget}"] = {"data": name, "budget": budget, "frames": len(x), "steps": steps,
                                    "final_loss": round(fit, 6), "success": rate,
                                    "ci95": wilson(rate, len(eval_seeds))}  # fmt: skip
    print(f"budget {budget}: {steps} steps for each data arm ({time.perf_counter() - t0:.1f} s)")
print(f"success (95% interval) on {len(eval_seeds)} held-out starts | " + " | ".join(
    f"{b} = {n} steps" for b, n in budgets.items()))  # fmt: skip
for name, (x, _) in data.items():
    row = [arms[f"{name}_{b}"] for b in budgets]
    print(
        f"  {name:9s} {len(x):6d} frames | "
        + " | ".join(f"{a['success']:.2f} [{a['ci95'][0]:.2f}, {a['ci95'][1]:.2f}]" for a in row)
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
# sectors) hold a block start. Then metrics.json (sorted, rounded, atomic), a PNG figure and a
# Rerun recording, and the headline last: the data effect at equal steps.
RINGS, SECTORS = 3, 12
R_MIN, R_MAX = pusht_env.SPAWN_R_MIN, pusht_env.SPAWN_R_MAX  # m, the spawn annulus


def cells(starts):  # (N, 2) block xy -> set of (ring, sector) inside the annulus, and the count outside
    r, th = np.hypot(starts[:, 0], starts[:, 1]), np.arctan2(starts[:, 1], starts[:, 0]) % (2 * np.pi)
    inside = (r >= R_MIN) & (r <= R_MAX)
    ring = np.minimum(((r - R_MIN) / (R_MAX - R_MIN) * RINGS).astype(int), RINGS - 1)
    sector = np.minimum((th / (2 * np.pi) * SECTORS).astype(int), SECTORS - 1)
    return {(int(i), int(j)) for i, j, ok in zip(ring, sector, inside) if ok}, int((~inside).sum())


src_starts = np.array([first[e][2:4] for e in first])  # (12, 2) block xy
_, first_rows = np.unique(aug["episode_index"], return_index=True)  # each augmented episode's first frame
aug_starts = aug["aug.start"][first_rows, :2]  # (kept, 2) block xy
c_src, out_src = cells(src_starts)
c_aug, out_aug = cells(aug_starts)
metrics = {
    "seed": args.seed, "smoke": args.smoke, "config": cli.result_config(args),
    "action_dims": {name: int(demo["action"].shape[1]) for name, demo in sets.items()},
    "padded_action_dim": PAD, "source_demos": len(first), "source_frames": len(data["source"][0]),
    "aug_mode": args.aug_mode, "attempts": attempts, "kept": len(first_rows), "yield": yield_,
    "augment_failures": failures,
    "augmented_frames": len(aug["action"]),
    "budgets": budgets, "arms": arms, "effects": effects, "scale_effect": effects["data_full"],
    "coverage": {"cells": RINGS * SECTORS, "source": len(c_src), "augmented": len(c_aug),
                 "union": len(c_src | c_aug), "outside_annulus": {"source": out_src, "augmented": out_aug}},
}  # fmt: skip
metrics_path = write_atomic(args.out / "metrics.json", dump_json(round_floats(metrics, 6)))
written = [args.out / "cross_embodiment.json", metrics_path]
from ch37 import poster, viz  # noqa: E402  (the drawing code: PNG, HTML poster, Rerun; not the lesson)

annulus = (R_MIN, R_MAX, RINGS, SECTORS)
written.append(viz.figure(args.out / "scale_data.png", src_starts, aug_starts, metrics, annulus))
written.append(poster.chapter(args.out / "scale_data.html", metrics, cross, src_starts, aug_starts, annulus))
if args.rerun:
    shown = [
        {"observation.state": aug["observation.state"][aug["episode_index"] == e]}
        for e in aug["episode_index"][first_rows[:8]]
    ]  # fmt: skip  (a few augmented trajectories)
    rrd = viz.recording(args.out / "scale_data.rrd", metrics, src_starts, aug_starts, shown, annulus)
    written.append(rrd)
rate = {name: arm["success"] for name, arm in arms.items()}
opens = {".json": "JSON", ".png": "open as an image", ".html": "any browser", ".rrd": "open with: rerun {}"}
summary = (
    f"headline: at equal steps ({budgets['full']} each), source {rate['source_full']:.2f} -> source+aug "
    f"{rate['augmented_full']:.2f} ({effects['data_full'] * 100:+.0f} points)\n"
    f"at the short budget ({budgets['short']} steps): {rate['source_short']:.2f} -> "
    f"{rate['augmented_short']:.2f} ({effects['data_short'] * 100:+.0f}); more steps alone: source "
    f"{effects['compute_source'] * 100:+.0f}, source+augmented {effects['compute_augmented'] * 100:+.0f}; "
    f"coverage {len(c_src)} -> {len(c_src | c_aug)} of {RINGS * SECTORS} cells\n"
    + "wrote " + ", ".join(f"{f} ({opens[f.suffix].format(f)})" for f in written) + "\n"
)  # fmt: skip
cache.store(written, summary)
print(f"finished in {time.perf_counter() - t_start:.0f} s")
print(summary, end="", flush=True)
# --- endregion ---
