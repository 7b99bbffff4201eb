"""The data engine's unit of work: one attempt = perturb a source start, re-solve it, keep it if it succeeds.

    attempt(source, k, seed=, pos_sigma=, yaw_sigma=, mode="resolve") -> a kept episode or a reason

is a pure function of its arguments: attempt k of source episode e draws from its own generator,
np.random.default_rng([env_seed(seed, "aug", e), k]), and the sim is fully reset at the perturbed
start, so the result never depends on which process runs it, in what order, or with what else.
scale_data.py's augment region and augment_demos.py (through datagen.shards) call the same function.

The three moves of mode "resolve":
  1. perturb   block x, y and pusher x, y get Gaussian noise of pos_sigma (m), block yaw of
               yaw_sigma (rad); the block must stay on the band R_LO..R_HI m from the target and
               the pusher inside its square and clear of the T (up to TRIES draws, else no_valid_start)
  2. re-solve  env.set_start at that start, then the noise-free PushTExpert to the end of the episode
  3. keep      only if the env reports success (else expert_failed); the kept episode carries its
               provenance on every frame: aug.source_episode and aug.start (the start it was solved from)

Mode "replay" is MimicGen's own move, for when no solver is on tap: the same perturbed start (the
same draw), then
  2. transform the source demo's pusher path and commands, expressed relative to the source block's
               start pose, are re-expressed in the perturbed block's pose (transform_segment: the
               planar SE(2) analog of MimicGen's transform_source_data_segment_using_object_pose)
  3. approach  the pusher moves from its own start to the first transformed waypoint (as MimicGen
               interpolates into a segment), then the transformed commands run open-loop
  4. keep      only if the env reports success; otherwise the reason (REPLAY_FAILURES)

keep_first(...) grows a set the MimicGen way: attempts k = 0, 1, 2, ... per source demo until
per_demo of them are kept (or ATTEMPTS_PER_KEPT x per_demo were tried); the kept set is the first
per_demo successes in k order, whatever batches the attempts ran in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import pusht_env
from ch37.demos import rollout
from ch37.parallel import parallel_map
from ch37.seeds import env_seed
from scripted_expert import PushTExpert

R_LO, R_HI = 0.08, 0.26  # m; the block is kept on a band slightly wider than the spawn annulus
TRIES = 100  # perturbation draws per attempt before giving up with "no_valid_start"
START_NAMES = ("block_x", "block_y", "block_yaw", "pusher_x", "pusher_y")  # what env.set_start takes
PROVENANCE = {  # LeRobot features stored on every frame of a kept episode
    "aug.source_episode": {"dtype": "int64", "shape": (1,), "names": None},
    "aug.start": {"dtype": "float32", "shape": (len(START_NAMES),), "names": list(START_NAMES)},
}


@dataclass(frozen=True)
class Source:
    """One source demo: its episode index in the source set and its frames, in order."""

    episode: int
    states: np.ndarray  # (T, 10) observation.state; resolve reads only the first row
    actions: np.ndarray  # (T, 2) action; kept for modes that reuse the source path


def sources(arrays: dict) -> dict[int, Source]:
    """{episode index: Source} from load_arrays' columns (observation.state, action, episode_index)."""
    out = {}
    for e in np.unique(arrays["episode_index"]):
        rows = np.flatnonzero(arrays["episode_index"] == e)
        out[int(e)] = Source(int(e), arrays["observation.state"][rows], arrays["action"][rows])
    return out


def attempt_rng(seed: int, episode: int, k: int) -> np.random.Generator:
    """The generator of attempt k of source episode `episode`: its own stream, whatever else runs."""
    return np.random.default_rng([env_seed(seed, "aug", episode), k])


def perturbed_start(first_state, rng, pos_sigma: float, yaw_sigma: float, tries: int = TRIES):
    """(block x, y, yaw, pusher x, y) near the start `first_state` (an obs), or None if no draw was valid."""
    px, py, bx, by, s, c = (float(v) for v in first_state[:6])
    for _ in range(tries):
        nbx, nby = bx + rng.normal(0, pos_sigma), by + rng.normal(0, pos_sigma)
        yaw = math.atan2(s, c) + rng.normal(0, yaw_sigma)
        npx, npy = np.clip(
            [px + rng.normal(0, pos_sigma), py + rng.normal(0, pos_sigma)],
            -pusht_env.PUSHER_HALF,
            pusht_env.PUSHER_HALF,
        )
        if R_LO <= math.hypot(nbx, nby) <= R_HI and pusht_env.pusher_clear(nbx, nby, yaw, npx, npy):
            return (nbx, nby, math.atan2(math.sin(yaw), math.cos(yaw)), float(npx), float(npy))
    return None


def resolve(env, start) -> dict:
    """The noise-free expert's episode from `start` (see START_NAMES), in the real physics."""
    return rollout(env, PushTExpert(noise=0.0), env.set_start(*start))


def _resolve_mode(source: Source, rng, pos_sigma: float, yaw_sigma: float, env):
    start = perturbed_start(source.states[0], rng, pos_sigma, yaw_sigma)  # 1. perturb
    if start is None:
        return "no_valid_start"
    ep = resolve(env, start)  # 2. re-solve
    if not ep["success"]:  # 3. keep only on success
        return "expert_failed"
    return ep, start


def block_pose(state) -> np.ndarray:
    """(x m, y m, yaw rad) of the block in a PushT observation."""
    return np.array([state[2], state[3], math.atan2(state[4], state[5])])


def rotation(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def transform_segment(points, vectors, src_pose, new_pose):
    """Re-express a path that was made relative to an object at `src_pose` for the object at `new_pose`.

    points (T, 2) world positions (m) and vectors (T, 2) world velocities (m/s); poses (x, y, yaw).
    A point is first written in the source object's frame, q = R(-yaw0) (p - xy0), then put back in the
    world from the new pose, p' = R(yaw1) q + xy1; a velocity only rotates, v' = R(yaw1 - yaw0) v.
    Returns (points' (T, 2), vectors' (T, 2)); an identical pose returns the inputs (to float rounding).
    """
    x0, y0, yaw0 = (float(v) for v in src_pose)
    x1, y1, yaw1 = (float(v) for v in new_pose)
    in_object = (np.asarray(points, np.float64) - (x0, y0)) @ rotation(-yaw0).T  # (T, 2) object frame
    moved = in_object @ rotation(yaw1).T + (x1, y1)
    turned = np.asarray(vectors, np.float64) @ rotation(yaw1 - yaw0).T
    return moved, turned


APPROACH_GAIN = 10.0  # 1/s: approach speed per m of distance to the first waypoint
APPROACH_SPEED = 0.8  # m/s, the expert's own top speed
APPROACH_TOL = 0.002  # m: close enough to the first waypoint to start the segment
APPROACH_STEPS = 60  # control steps (6 s) before the segment starts regardless
MOVED_TOL = (0.002, 0.02)  # m, rad: the approach "hit the block" if it moved it more than this
REACH = pusht_env.WALL_INNER - pusht_env.PUSHER_RADIUS  # m: the pusher centre's reach from the centre


def replay(env, start, source: Source) -> tuple[dict, str | None]:
    """Replay `source` from `start` (see START_NAMES): approach, then its transformed commands open-loop.

    Returns the episode (the frames and actions actually executed, as ch37.demos.rollout returns them)
    and, when the env did not report success, the reason: approach_blocked (the approach moved the
    block), path_off_table (a transformed waypoint lies beyond the walls), out_of_time (the episode
    ended before the segment did), or finished_off_target (the segment ran to its end off target).
    """
    path, commands = transform_segment(
        source.states[:, :2], source.actions, block_pose(source.states[0]), start[:3]
    )
    obs = env.set_start(*start)
    states, actions, succ = [], [], []
    done = False

    def act(a):
        nonlocal obs, done
        a = np.asarray(a, np.float32)
        states.append(obs)
        actions.append(a)
        obs, _, done, info = env.step(a)
        succ.append(bool(info["success"]))

    before = env.block_pose
    for _ in range(APPROACH_STEPS):  # 3. approach the first waypoint on a straight line
        gap = path[0] - env.pusher_pos
        dist = float(np.hypot(*gap))
        if dist <= APPROACH_TOL or done:
            break
        act(gap / dist * min(APPROACH_GAIN * dist, APPROACH_SPEED))
    shift = env.block_pose - before
    blocked = (
        math.hypot(shift[0], shift[1]) > MOVED_TOL[0] or abs(pusht_env.wrap_angle(shift[2])) > MOVED_TOL[1]
    )
    executed = 0
    for a in commands:  # the transformed segment, open-loop: the object is never looked at again
        if done:
            break
        act(a)
        executed += 1
    ep = {
        "observation.state": np.asarray(states, np.float32).reshape(-1, pusht_env.OBS_DIM),
        "action": np.asarray(actions, np.float32).reshape(-1, pusht_env.ACT_DIM),
        "next.success": np.asarray(succ, bool).reshape(-1, 1),
        "success": env.success,
    }
    if env.success:
        return ep, None
    if blocked:
        return ep, "approach_blocked"
    if np.any(np.abs(path) > REACH):
        return ep, "path_off_table"
    if executed < len(commands):
        return ep, "out_of_time"
    return ep, "finished_off_target"


def _replay_mode(source: Source, rng, pos_sigma: float, yaw_sigma: float, env):
    start = perturbed_start(source.states[0], rng, pos_sigma, yaw_sigma)  # 1. perturb (the same draw)
    if start is None:
        return "no_valid_start"
    ep, why = replay(env, start, source)  # 2-3. transform, approach, execute
    return why or (ep, start)  # 4. keep only on the env's success


MODES = {
    "resolve": _resolve_mode,
    "replay": _replay_mode,
}  # (source, rng, sigmas, env) -> (ep, start) | reason
FAILURES = {  # every reason a mode can return
    "resolve": ("expert_failed", "no_valid_start"),
    "replay": ("approach_blocked", "path_off_table", "out_of_time", "finished_off_target", "no_valid_start"),
}
KEPT_KEYS = ("observation.state", "action", "episode_index", "aug.source_episode", "aug.start")


def empty_kept() -> dict:
    """KEPT_KEYS' columns of a set with no episode, for a run that kept none."""
    widths = {
        "observation.state": pusht_env.OBS_DIM,
        "action": pusht_env.ACT_DIM,
        "aug.start": len(START_NAMES),
    }
    out = {k: np.zeros((0, w), np.float32) for k, w in widths.items()}
    return out | {"episode_index": np.zeros(0, np.int64), "aug.source_episode": np.zeros((0, 1), np.int64)}


ATTEMPTS_PER_KEPT = 10  # keep_first gives up on a source demo after this many attempts per wanted demo

_ENV = None  # one simulator per process, fully reset by set_start before every attempt


def attempt(
    source: Source,
    k: int,
    *,
    seed: int,
    pos_sigma: float,
    yaw_sigma: float,
    mode: str = "resolve",
    env=None,
):
    """Attempt k from `source`: a kept episode (arrays per frame, with provenance) or a failure reason."""
    global _ENV
    if env is None:
        _ENV = _ENV or pusht_env.PushTEnv()
        env = _ENV
    got = MODES[mode](source, attempt_rng(seed, source.episode, k), pos_sigma, yaw_sigma, env)
    if isinstance(got, str):
        return got
    ep, start = got
    n = len(ep["action"])
    ep["aug.source_episode"] = np.full((n, 1), source.episode, np.int64)  # provenance, on every frame
    ep["aug.start"] = np.tile(np.float32(start), (n, 1))
    return ep


def keep_first(episodes, per_demo: int, run_jobs, *, reasons, cap: int = ATTEMPTS_PER_KEPT):
    """The first `per_demo` kept attempts (k = 0, 1, ...) of each source episode, the MimicGen way.

    run_jobs([(episode, k), ...]) -> [attempt result, ...] in the same order (any executor).
    Attempts run in rounds: k < per_demo first, then, for an episode still short, more k's sized by
    its yield so far. Whatever the rounds, the kept set is the first per_demo successes in k order
    and `attempts` counts k's up to the last one kept (all cap x per_demo when an episode falls
    short), so kept, attempts and failures are pure functions of the arguments.
    Returns (kept episodes in (episode, k) order, attempts, {reason: count} over counted attempts).
    """
    limit = cap * per_demo
    done = {e: [] for e in episodes}  # episode -> results for k = 0, 1, ... in order
    while True:
        jobs = []
        for e, got in done.items():
            n_kept = sum(not isinstance(r, str) for r in got)
            if n_kept >= per_demo or len(got) >= limit:
                continue
            rate = max(n_kept / len(got), 1 / cap) if got else 1.0
            more = min(math.ceil((per_demo - n_kept) / rate), limit - len(got))
            jobs += [(e, k) for k in range(len(got), len(got) + more)]
        if not jobs:
            break
        for (e, _), r in zip(jobs, run_jobs(jobs)):
            done[e].append(r)
    kept, attempts, failures = [], 0, dict.fromkeys(reasons, 0)
    for got in done.values():
        n = 0
        for r in got:
            if n == per_demo:
                break  # attempted in a round, but beyond the last one this episode keeps: not counted
            attempts += 1
            if isinstance(r, str):
                failures[r] += 1
            else:
                kept.append(r)
                n += 1
    return kept, attempts, failures


def first_per_source(episode_index, source_episode, take) -> np.ndarray:
    """Row mask of a kept set: the first `take` episodes (in episode order) of each source demo.

    episode_index (N,) and source_episode (N,) or (N, 1) are the set's columns (aug.source_episode);
    take is one count for every source demo, or {source episode: count} (absent: 0). Because
    keep_first keeps in attempt order, this is the set keep_first would have kept with that count."""
    ep, first = np.unique(episode_index, return_index=True)
    src = np.asarray(source_episode).reshape(-1)[first]  # each episode's source demo
    rank = np.zeros(len(ep), int)  # its place among its source demo's episodes
    for e in np.unique(src):
        rank[src == e] = np.arange((src == e).sum())
    limit = np.array([take.get(int(e), 0) for e in src]) if isinstance(take, dict) else take
    return np.isin(episode_index, ep[rank < limit])


def run_attempts(sources: dict, jobs, *, seed, pos_sigma, yaw_sigma, mode="resolve", workers=1, bar=None):
    """[attempt(sources[e], k, ...) for (e, k) in jobs], in order, on `workers` forked processes."""

    def one(job):
        e, k = job
        return attempt(sources[e], k, seed=seed, pos_sigma=pos_sigma, yaw_sigma=yaw_sigma, mode=mode)

    return parallel_map(one, jobs, workers=workers, bar=bar)


def grow(sources: dict, per_demo: int, *, mode="resolve", cap=ATTEMPTS_PER_KEPT, workers=1, bar=None, **how):
    """The engine's one entry: the first `per_demo` kept attempts of every source demo (keep_first),
    attempted in `mode` with the perturbation `how` (seed, pos_sigma, yaw_sigma) on `workers` processes.
    Returns (kept episodes in (episode, k) order, attempts, {reason: count})."""
    return keep_first(
        sorted(sources),
        per_demo,
        lambda jobs: run_attempts(sources, jobs, mode=mode, workers=workers, bar=bar, **how),
        reasons=FAILURES[mode],
        cap=cap,
    )


def save(root, kept: list[dict], *, repo_id: str, stamp: dict) -> None:
    """Write kept episodes (with their provenance) to `root` as one LeRobot v3 PushT set under our
    stamp; what was at `root` must be ours (ch37.stamps.replace_own_dir), and nothing is written
    when nothing was kept."""
    from ch37.stamps import MADE_BY, replace_own_dir
    from lerobot_v3.dataset import features, write_dataset

    replace_own_dir(root)
    if kept:
        feats = features(
            pusht_env.STATE_NAMES,
            pusht_env.ACTION_NAMES,
            PROVENANCE,
            env_state_names=pusht_env.ENV_STATE_NAMES,
        )
        write_dataset(
            root,
            repo_id=repo_id,
            fps=pusht_env.FPS,
            robot_type=pusht_env.ROBOT_TYPE,
            task=pusht_env.TASK,
            feats=feats,
            episodes=kept,
            stamp={"made_by": MADE_BY} | stamp,
        )
