"""Objective 2, measured: what one policy shared by two robots carries across them, and what it does not.

    python -m tools.embodiment --seeds 3             seeds 0..2 -> outputs/embodiment/embodiment.json
    python -m tools.embodiment --smoke --seeds 1     seconds; numbers not meaningful

The pile is the wrangle region's (scale_data.py): each robot's demos standardized with its own statistics,
actions zero-padded to 6 with an action mask, an embodiment id per row, the masked loss. On it, per seed,
four arms of the chapter's BC recipe (bc_recipe.train: the same MLP, Adam, cosine lr, batch order):

    pusht_only   PushT's rows alone                      rolled out on PushT
    aloha_only   ALOHA's rows alone                      rolled out on ALOHA
    shared       both robots' rows, no embodiment id     rolled out on both
    shared_id    both robots' rows, a one-hot id in      rolled out on both, and on each with the other
                 its input                               robot's id (swapped_id): the same weights told
                                                         to read the state as the other robot's

Every arm reads 12 inputs (the 10 state numbers, then the 2 id columns) and writes the padded 6 actions,
and starts from the same initial weights; shared's id columns are always 0, and a per-robot arm's id is a
constant, so only shared_id can tell the robots apart by its id. State index 2 is block_x in PushT and
right_grip (closedness) in ALOHA: shared must tell them apart from the state alone.

Steps, matched by passes: every arm makes --epochs passes over each of its robots' rows (one shuffle per
pass, so every row is used exactly --epochs times in every arm that has it). A per-robot arm takes
ceil(epochs x its rows / batch) steps; the shared arms ceil(epochs x both robots' rows / batch), the two
per-robot arms' steps together (to a step): one shared network gets the compute of the two it replaces,
and each robot's rows are seen as often as in its own policy. shared and shared_id take identical steps
from identical weights in the same batch order: the id is their only difference.

Demos: episodes 0..--episodes-1 of the chapter's demo generator for each robot at each seed (datagen.
ensure_demos, cached under --demos). Held-out starts: the chapter's, env_seed(seed, "eval", j) for
j < --eval_episodes, each robot's env judging success. Per arm and robot: success pooled over seeds with
its Wilson 95% interval, and the paired per-seed differences (shared - per-robot, shared_id - shared).

Exit codes: 0 ok, 2 bad input (one `error:` line).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ch37 import ROOT, errors
from ch37.config import check
from tools.common import check_results, mean_ci, parser, provenance, rel, write_result

KIND = "embodiment"
ROBOTS = ("pusht", "aloha")  # embodiment id 0, 1: the wrangle region's order
ARMS = {"pusht_only": ("pusht",), "aloha_only": ("aloha",), "shared": ROBOTS, "shared_id": ROBOTS}
PAD = 6  # the widest action (ALOHA's)
DEFAULTS = dict(episodes=108, epochs=64, hidden_dim=256, batch_size=128, lr=1e-3, eval_episodes=50)
SMOKE = dict(episodes=3, epochs=2, hidden_dim=32, batch_size=64, eval_episodes=2)
DIFFS = (  # (arm, baseline, robot): paired per-seed differences
    ("shared", "pusht_only", "pusht"),
    ("shared", "aloha_only", "aloha"),
    ("shared_id", "pusht_only", "pusht"),
    ("shared_id", "aloha_only", "aloha"),
    ("shared_id", "shared", "pusht"),
    ("shared_id", "shared", "aloha"),
)


# --- the pile: the wrangle region's normalization, padding, mask and id -------------------------------
def stats_of(x: np.ndarray) -> dict:
    """Per-dimension mean and std of one robot's (N, D) array (the wrangle region's stats_of, its two keys
    that standardizing reads)."""
    return {"mean": x.mean(0), "std": x.std(0)}


def standardize(x: np.ndarray, st: dict) -> np.ndarray:
    """The wrangle region's standardize: a constant dimension (PushT's target pose) is centred, not / 0."""
    return (x - st["mean"]) / np.where(st["std"] > 1e-8, st["std"], 1.0)


def pile_rows(demo: dict, st: dict, emb_id: int, with_id: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One robot's rows of the pile: inputs (N, 12) = its standardized state and the one-hot id (zeros
    without `with_id`), actions (N, 6) standardized and zero-padded, mask (N, 6) 1 on real dimensions."""
    state = standardize(demo["observation.state"], st["state"])
    act = standardize(demo["action"], st["action"])
    n, act_dim = act.shape
    ids = np.zeros((n, len(ROBOTS)))
    if with_id:
        ids[:, emb_id] = 1.0
    x = np.concatenate([state, ids], 1).astype(np.float32)
    y = np.pad(act, ((0, 0), (0, PAD - act_dim))).astype(np.float32)
    mask = np.repeat((np.arange(PAD) < act_dim).astype(np.float32)[None], n, 0)
    return x, y, mask


def arm_data(demos: dict, stats: dict) -> dict:
    """{arm: (inputs, actions, mask)}: each arm's rows of the pile, PushT's first."""
    out = {}
    for arm, robots in ARMS.items():
        with_id = arm != "shared"  # a per-robot arm's id is constant: it can tell nothing apart
        parts = [pile_rows(demos[r], stats[r], ROBOTS.index(r), with_id) for r in robots]
        out[arm] = tuple(np.concatenate(p) for p in zip(*parts))
    return out


def on_robot(pol, st: dict, robot: str, act_dim: int, id_as: str | None):
    """A pile policy as the robot's env needs it: the raw state standardized with the robot's statistics,
    the id columns set to `id_as`'s one-hot (None: zeros), the padded action cut to the robot's width and
    un-standardized. A torch module, so bc_recipe.evaluate rolls it out as it does any policy."""
    import torch

    class OnRobot(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.pol = pol
            f32 = dict(dtype=torch.float32)
            std = {k: np.where(st[k]["std"] > 1e-8, st[k]["std"], 1.0) for k in ("state", "action")}
            self.register_buffer("s_mean", torch.as_tensor(st["state"]["mean"], **f32))
            self.register_buffer("s_std", torch.as_tensor(std["state"], **f32))
            self.register_buffer("a_mean", torch.as_tensor(st["action"]["mean"], **f32))
            self.register_buffer("a_std", torch.as_tensor(std["action"], **f32))
            ids = torch.zeros(len(ROBOTS))
            if id_as is not None:
                ids[ROBOTS.index(id_as)] = 1.0
            self.register_buffer("ids", ids)

        def forward(self, s):
            x = torch.cat([(s - self.s_mean) / self.s_std, self.ids.expand(len(s), -1)], 1)
            return self.pol(x)[:, :act_dim] * self.a_std + self.a_mean

    return OnRobot().eval()


# --- one seed -------------------------------------------------------------------------------------------
def demo_sets(demos_dir: Path, seed: int, episodes: int) -> dict:
    """{robot: arrays} of the chapter's demo generator, episodes 0..episodes-1 at `seed` (cached)."""
    from datagen import ALOHA, PUSHT, ensure_demos
    from lerobot_v3 import load_arrays

    out = {}
    for emb in (PUSHT, ALOHA):
        path = demos_dir / f"{emb.name}_seed{seed}_ep{episodes}"
        noise = emb.default_noise
        ensure_demos(emb, path, user_given=False, episodes=episodes, seed=seed, noise=noise, quiet=True)
        out[emb.name] = load_arrays(path, keys=("observation.state", "action", "episode_index"))
    return out


def steps_of(c: dict, frames: int) -> int:
    return math.ceil(c["epochs"] * frames / c["batch_size"])


def run_seed(seed: int, c: dict, demos_dir: Path, workers: int) -> dict:
    """One seed: its two demo sets, the pile, the four arms trained, every rollout."""
    import bc_recipe as bc
    from ch37.seeds import env_seed
    from datagen import ALOHA, PUSHT

    t0 = time.perf_counter()
    demos = demo_sets(demos_dir, seed, c["episodes"])
    stats = {r: {k: stats_of(demos[r][k]) for k in ("observation.state", "action")} for r in ROBOTS}
    stats = {r: {"state": s["observation.state"], "action": s["action"]} for r, s in stats.items()}
    data = arm_data(demos, stats)
    init = bc.init_weights(c["hidden_dim"], seed, act_dim=PAD, obs_dim=10 + len(ROBOTS))
    hp = dict(batch_size=c["batch_size"], lr=c["lr"], seed=seed)
    groups = (("pusht_only",), ("aloha_only",), ("shared", "shared_id"))  # arms of one group: equal steps
    pols, fits, steps = {}, {}, {}
    for group in groups:
        n = steps_of(c, len(data[group[0]][0]))
        got, fit = bc.train([data[a][:2] for a in group], n, init, masks=[data[a][2] for a in group], **hp)
        pols |= dict(zip(group, got))
        fits |= dict(zip(group, fit))
        steps |= dict.fromkeys(group, n)
    t_train = time.perf_counter() - t0
    eval_seeds = [env_seed(seed, "eval", j) for j in range(c["eval_episodes"])]
    tasks = {"pusht": PUSHT, "aloha": ALOHA}
    act_dim = {r: demos[r]["action"].shape[1] for r in ROBOTS}

    def rate(arm, robot, id_as):
        pol = on_robot(pols[arm], stats[robot], robot, act_dim[robot], id_as)
        return bc.evaluate(pol, eval_seeds, workers=workers, make_env=tasks[robot].make_env)

    success = {
        arm: {r: rate(arm, r, None if arm == "shared" else r) for r in robots} for arm, robots in ARMS.items()
    }
    swapped = {r: rate("shared_id", r, ROBOTS[1 - ROBOTS.index(r)]) for r in ROBOTS}
    return {
        "seed": seed,
        "frames": {r: len(demos[r]["action"]) for r in ROBOTS},
        "steps": steps,
        "final_loss": fits,
        "success": success,
        "swapped_id": swapped,
        "seconds": {"demos_and_train": t_train, "total": time.perf_counter() - t0},
    }


def state_index_2() -> dict:
    """What state index 2 means on each robot, from its env's names."""
    from datagen import ALOHA, PUSHT

    return {t.name: t.spec.state_names[2] for t in (PUSHT, ALOHA)}


# --- the result -----------------------------------------------------------------------------------------
def pooled(rows: list[dict], n_eval: int, arm: str, robot: str, key: str = "success") -> dict:
    """An arm's successes on a robot pooled over seeds, with the Wilson 95% interval of all episodes."""
    import bc_recipe as bc

    got = [r[key][robot] if key == "swapped_id" else r[key][arm][robot] for r in rows]
    k, n = sum(round(v * n_eval) for v in got), n_eval * len(rows)
    return {"per_seed": got, "successes": k, "episodes": n, "rate": k / n, "ci95": bc.wilson(k / n, n)}


def summarize(rows: list[dict], n_eval: int) -> dict:
    out = {"pooled": {a: {r: pooled(rows, n_eval, a, r) for r in robots} for a, robots in ARMS.items()}}
    out["pooled"]["shared_id_swapped"] = {r: pooled(rows, n_eval, "", r, "swapped_id") for r in ROBOTS}
    diffs = {}
    for arm, base, robot in DIFFS:
        d = [r["success"][arm][robot] - r["success"][base][robot] for r in rows]
        mean, _, ci = mean_ci(d)
        diffs[f"{arm}_vs_{base}_on_{robot}"] = {"per_seed": d, "mean": mean, "ci95_over_seeds": ci}
    return out | {"differences": diffs}


def line(name: str, p: dict) -> str:
    return (
        f"{name} {p['successes']}/{p['episodes']} = {p['rate']:.3f} [{p['ci95'][0]:.3f}, {p['ci95'][1]:.3f}]"
    )


def main(argv: list[str]) -> int:
    p = parser("embodiment", __doc__, script=False)
    arg = p.add_argument
    arg("--seeds", type=int, default=3, help="seeds 0..N-1 (default 3)")
    for k, v in DEFAULTS.items():
        arg(f"--{k}", type=type(v), default=None, help=f"default {v} ({SMOKE.get(k, v)} with --smoke)")
    arg(
        "--workers",
        type=int,
        default=2,
        help="processes for the rollouts' physics (results do not depend on it)",
    )
    arg("--smoke", action="store_true", help="tiny sizes for tests (seconds); explicit flags win")
    arg(
        "--out", type=Path, help="folder of embodiment.json (default outputs/embodiment, -smoke with --smoke)"
    )
    arg("--demos", type=Path, help="demo-set cache (default OUT/demos)")
    a = p.parse_args(argv)
    c = (
        DEFAULTS
        | (SMOKE if a.smoke else {})
        | {k: getattr(a, k) for k in DEFAULTS if getattr(a, k) is not None}
    )
    ints = ["seeds", "workers", "episodes", "epochs", "hidden_dim", "batch_size", "eval_episodes"]
    for k, v in c.items():
        setattr(a, k, v)
    check(a, positive=ints, finite_positive=["lr"])
    out = a.out or ROOT / "outputs" / (f"{KIND}-smoke" if a.smoke else KIND)
    check_results(out, KIND)  # before any work: an earlier result of this tool may be replaced, nothing else
    demos_dir = a.demos or out / "demos"
    cmd = f"python -m tools.{KIND} --seeds {a.seeds}" + (" --smoke" if a.smoke else "")
    base = DEFAULTS | (SMOKE if a.smoke else {})
    cmd += "".join(f" --{k} {v}" for k, v in c.items() if v != base[k])
    out.mkdir(parents=True, exist_ok=True)
    prov = provenance(ROOT / "tools" / f"{KIND}.py")
    print(f"{cmd}: {', '.join(f'{k} {v}' for k, v in c.items())}", flush=True)
    rows = []
    for s in range(a.seeds):  # the file is rewritten after every seed: a stopped run keeps its seeds
        rows.append(r := run_seed(s, c, demos_dir, a.workers))
        ok = "; ".join(
            f"{arm} " + " ".join(f"{rb} {v:.2f}" for rb, v in x.items()) for arm, x in r["success"].items()
        )
        swap = " ".join(f"{rb} {v:.2f}" for rb, v in r["swapped_id"].items())
        took = r["seconds"]["total"]
        print(f"seed {s}: steps {r['steps']}; {ok}; shared_id swapped {swap} ({took:.0f} s)", flush=True)
        res = {"kind": KIND, "command": cmd, "config": c, "state_index_2": state_index_2(), "rows": rows}
        res |= summarize(rows, c["eval_episodes"])
        f = write_result(out / f"{KIND}.json", res | prov)
    for arm, by_robot in res["pooled"].items():
        print("  " + "; ".join(line(f"{arm} on {r}", q) for r, q in by_robot.items()))
    print(f"wrote {rel(f)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
