"""Where does replay work? Yield (kept / attempts) by task and mode, on both robots, at the chapter's
perturbation, and ALOHA replay's yield as the perturbation grows (issue 29's study, first half).

    python -m tools.replay_yield --seeds 3 --attempts 10          -> OUT/replay_yield.json
    python -m tools.replay_yield --seeds 3 --attempts 10 --aloha_sigma 0.25 0.5 1 2 4

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
    onto_goal              gym-pusht only: the one segment with its frame sliding from the block onto the
                           goal over the push (GymPushT(ONTO_GOAL), as PushT's subtasks slide onto the target)
    <mode>_live            PushT and gym-pusht (issue 49 #4): that mode's replay as --aug_mode replay_live
                           runs it, re-anchored on the objects' live poses beyond the task's follow_tol

Gymnasium's Pusher-v5 (--tasks pusher; issue 46: a 7-DoF arm, targets in SE(3)): its object's (x, y)
moved by 0.08 m, kept where Pusher-v5's reset puts it; replay is one segment relative to the object,
subtasks the approach relative to the object and the push sliding onto the goal (the engine's).
--pusher_sigma sweeps its perturbation as --aloha_sigma does ALOHA's.

--tasks picks the tasks (default: pusht, aloha and gym_pusht).

Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np

from ch37 import ROOT, errors
from ch37.config import DEFAULTS, check
from ch37.errors import DataError
from ch37.ownership import check_out_path, check_own_result, dump_json, round_floats, write_atomic
from ch37.parallel import map_jobs
from datagen import ALOHA, PUSHT, Perturbation, engine
from datagen.aloha import WHOLE, Aloha
from datagen.demos import expert_episodes
from datagen.gym_pusht import GYM_PUSHT, ONTO_GOAL, GymPushT
from datagen.pusher import PUSHER, Pusher
from datagen.pusher import WHOLE as PUSHER_WHOLE
from datagen.pusht import BY_CONTACT, BY_CONTACT_BLOCK, PushT
from datagen.task import Source
from tools.common import parser, provenance, rel

POS_SIGMA, YAW_SIGMA = DEFAULTS["aug_pos_sigma"], DEFAULTS["aug_yaw_sigma"]  # m, rad
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
}
DEFAULT_TASKS = ["pusht", "aloha", "gym_pusht"]  # pusher on request (--tasks pusher)


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
        "yaw_sigma": None if task in ("aloha", "pusher") else m * YAW_SIGMA,
        "attempts": len(got),
        "kept": kept,
    }
    row |= {"yield": kept / len(got), "ci95": wilson(kept / len(got), len(got)), "kept_per_seed": per_seed}
    row["failures"] = {why: got.count(why) for why in sorted(set(got) - {"kept"})}
    row["kept_frames_median"] = float(np.median([f for f in frames if f])) if kept else None
    return row | {"seconds": round(time.perf_counter() - t, 1)}


def main(argv: list[str]) -> int:
    p = parser("replay_yield", __doc__)
    p.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 (their source demos and attempts)")
    p.add_argument("--sources", type=int, default=DEFAULTS["source_episodes"], help="source demos per seed")
    p.add_argument("--attempts", type=int, default=10, help="attempts per source demo per seed and mode")
    p.add_argument(
        "--aloha_sigma", type=float, nargs="*", default=[], help="ALOHA sweep: multipliers of 0.08 m"
    )
    p.add_argument(
        "--pusher_sigma", type=float, nargs="*", default=[], help="Pusher sweep: multipliers of 0.08 m"
    )
    p.add_argument("--tasks", nargs="+", choices=list(VARIANTS), default=DEFAULT_TASKS, help="the tasks")
    p.add_argument("--workers", type=int, default=1, help="processes for the attempts")
    p.add_argument("--out", type=Path, default=ROOT / "outputs/replay_yield", help="output folder")
    a = p.parse_args(argv)
    check(a, positive=["seeds", "sources", "attempts", "workers"])
    if any(not (0 < m < 100) for m in a.aloha_sigma + a.pusher_sigma):
        raise DataError("--aloha_sigma and --pusher_sigma multipliers must be in (0, 100)")
    if problem := check_out_path(a.out):  # before the work: an earlier run's result may be replaced,
        raise DataError(problem)  # a user's file never
    check_own_result(a.out / f"{KIND}.json", KIND)
    seeds, work, sims = list(range(a.seeds)), {}, engine.Simulators()  # this run's, passed to cell
    for task in a.tasks:
        for s in seeds:
            work[(task, s)] = sources(sims, task, s, a.sources)
    rows = []
    todo = [(task, mode, 1.0) for task in a.tasks for mode in VARIANTS[task]]
    for task, sweep in (("aloha", a.aloha_sigma), ("pusher", a.pusher_sigma)):
        if task in a.tasks:
            todo += [(task, mode, m) for m in sorted(sweep) if m != 1.0 for mode in SIGMA_MODES]
    for task, mode, m in todo:
        rows.append(r := cell(work, sims, task, mode, seeds, a.sources, a.attempts, m, a.workers))
        got = (
            f"{r['kept']}/{r['attempts']} = {r['yield']:.3f} {r['failures']} frames {r['kept_frames_median']}"
        )
        print(f"{task:9s} x{m:<4g} {mode:22s} {got}", flush=True)
    cmd = f"python -m tools.replay_yield --seeds {a.seeds} --sources {a.sources} --attempts {a.attempts}"
    cmd += " --aloha_sigma " + " ".join(f"{m:g}" for m in a.aloha_sigma) if a.aloha_sigma else ""
    cmd += " --pusher_sigma " + " ".join(f"{m:g}" for m in a.pusher_sigma) if a.pusher_sigma else ""
    cmd += " --tasks " + " ".join(a.tasks) if a.tasks != DEFAULT_TASKS else ""
    res = {"kind": KIND, "command": cmd, "seeds": seeds, "rows": rows} | provenance(a.script)
    a.out.mkdir(parents=True, exist_ok=True)
    f = write_atomic(a.out / f"{KIND}.json", dump_json(round_floats(res, 4)))
    print(f"wrote {rel(f)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
