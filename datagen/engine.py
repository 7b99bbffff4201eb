"""The data engine's unit of work, for any task (datagen.task.Task): one attempt = perturb a source
start, re-solve or replay it, keep it if it succeeds.

    attempt(task, source, k, how, mode="resolve") -> an Outcome (datagen.task.Outcome: kept or why not)

is a pure function of its arguments: attempt k of source episode e draws from its own generator,
np.random.default_rng([env_seed(seed, "aug", e), k]) (attempt_rng), and the sim is fully reset at the
perturbed start (task.place), so the result never depends on which process runs it, in what order, or
with what else. Every attempt runs through the engine's one runner (datagen.lockstep: one lane here,
many lanes where a worker runs a batch), which records the frames and attaches the provenance:
aug.source_episode and aug.start (the start it was made from) on every frame of a kept episode. The
modes are the engine's (resolve: the task's expert; replay: datagen.replay), the parts they use the
task's (datagen.task.Task).

keep_first(...) grows a set the MimicGen way: attempts k = 0, 1, 2, ... per source demo until
per_source of them are kept (or cap x per_source were tried); the kept set is the first per_source
successes in k order, whatever batches the attempts ran in. grow() is keep_first over run_attempts,
the lesson's path (scale_data.py's augment region); augment_demos.py's shards (datagen.shards) run
the same attempts_lockstep on their workers.
"""

from __future__ import annotations

import math

import numpy as np

from ch37.parallel import map_jobs
from datagen import lockstep
from datagen.lockstep import Simulators, attempt_rng, with_provenance
from datagen.task import Outcome, Perturbation, Source, Task, failures_of

__all__ = [
    "ATTEMPTS_PER_KEPT",
    "RUNS_PER_WORKER",
    "Simulators",
    "KEPT_KEYS",
    "SELECTS",
    "attempt",
    "attempt_rng",
    "empty_kept",
    "first_per_source",
    "grow",
    "keep_first",
    "provenance",
    "run_attempts",
    "save",
    "sources",
    "with_provenance",
]

KEPT_KEYS = ("observation.state", "action", "episode_index", "aug.source_episode", "aug.start")
SELECTS = ("own", "nearest")  # which source a replay transforms: the attempt's own, or MimicGen's nearest
ATTEMPTS_PER_KEPT = 10  # keep_first gives up on a source demo after this many attempts per wanted demo
RUNS_PER_WORKER = 4  # run_attempts' cuts per worker: lanes wide enough to pay, a bar that still moves


def provenance(task: Task) -> dict:
    """The LeRobot features stored on every frame of a kept episode of `task`."""
    return {
        "aug.source_episode": {"dtype": "int64", "shape": (1,), "names": None},
        "aug.start": {"dtype": "float32", "shape": (len(task.start_names),), "names": list(task.start_names)},
    }


def sources(arrays: dict) -> dict[int, Source]:
    """{episode index: Source} from load_arrays' columns (observation.state, action, episode_index)."""
    out = {}
    for e in np.unique(arrays["episode_index"]):
        rows = np.flatnonzero(arrays["episode_index"] == e)
        out[int(e)] = Source(int(e), arrays["observation.state"][rows], arrays["action"][rows])
    return out


def empty_kept(task: Task) -> dict:
    """KEPT_KEYS' columns of a set of `task` with no episode, for a run that kept none."""
    m = task.spec
    widths = {"observation.state": m.obs_dim, "action": m.act_dim, "aug.start": len(task.start_names)}
    out = {k: np.zeros((0, w), np.float32) for k, w in widths.items()}
    return out | {"episode_index": np.zeros(0, np.int64), "aug.source_episode": np.zeros((0, 1), np.int64)}


def attempt(
    task: Task,
    source: Source,
    k: int,
    how: Perturbation,
    *,
    mode: str = "resolve",
    env=None,
    pool=None,
    sims: Simulators | None = None,
) -> Outcome:
    """Attempt k from `source`: its Outcome, a kept one's episode with its provenance on every frame
    (arrays per frame), a failed one's without frames (episode None; steps says how many ran). Run by
    the engine's one attempt runner in one lane (datagen.lockstep.one_lane).
    pool: {episode: Source} a replay chooses its source from (the nearest, MimicGen's selection);
    None replays the attempt's own. aug.source_episode is the source actually replayed.
    env: the simulator to use (else sims' env for the task, else a new one); sims: what a worker keeps
    between attempts (Simulators: its env and the replay plans). Neither changes a bit of the result."""
    if env is None:
        env = sims.env(task) if sims is not None else task.make_env()
    plans = sims.plans if sims is not None else None
    kind, _ = lockstep.mode_parts(
        task, {source.episode: source}, how, mode, pool=pool, plans=plans, lanes=False
    )
    return lockstep.one_lane(task, env, [(source.episode, k)], kind)[0]


def keep_first(episodes, per_source: int, run_jobs, *, reasons, cap: int = ATTEMPTS_PER_KEPT):
    """The first `per_source` kept attempts (k = 0, 1, ...) of each source episode, the MimicGen way.

    run_jobs([(episode, k), ...]) -> [Outcome, ...] in the same order (any executor).
    Attempts run in rounds: k < per_source first, then, for an episode still short, more k's sized by
    its yield so far. Whatever the rounds, the kept set is the first per_source successes in k order
    and `attempts` counts k's up to the last one kept (all cap x per_source when an episode falls
    short), so kept, attempts and failures are pure functions of the arguments.
    Returns (kept episodes in (episode, k) order, attempts, {reason: count} over counted attempts).
    """
    limit = cap * per_source
    done = {e: [] for e in episodes}  # episode -> results for k = 0, 1, ... in order
    while True:
        jobs = []
        for e, got in done.items():
            n_kept = sum(r.kept for r in got)
            if n_kept >= per_source or len(got) >= limit:
                continue
            rate = max(n_kept / len(got), 1 / cap) if got else 1.0
            more = min(math.ceil((per_source - n_kept) / rate), limit - len(got))
            jobs += [(e, k) for k in range(len(got), len(got) + more)]
        if not jobs:
            break
        for (e, _), r in zip(jobs, run_jobs(jobs)):
            done[e].append(r)
    kept, attempts, failures = [], 0, dict.fromkeys(reasons, 0)
    for got in done.values():
        n = 0
        for r in got:
            if n == per_source:
                break  # attempted in a round, but beyond the last one this episode keeps: not counted
            attempts += 1
            if r.kept:
                kept.append(r.episode)
                n += 1
            else:
                failures[r.reason] += 1
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


def run_attempts(
    task: Task,
    sources: dict,
    jobs,
    how: Perturbation,
    *,
    mode="resolve",
    select="own",
    workers=1,
    bar=None,
    sims: Simulators | None = None,
):
    """[attempt(task, sources[e], k, how, mode=mode) for (e, k) in jobs], in order, on `workers`
    processes: the jobs cut into a few runs per worker, each run by the engine's one runner in lanes
    (datagen.lockstep.attempts_lockstep, the same bytes). select "nearest": each replay transforms the
    source of `sources` nearest its start (SELECTS). bar: advanced once per attempt. sims: the
    Simulators the attempts reuse (a new one when None; a forked worker fills its own copy)."""
    sims = Simulators() if sims is None else sims
    jobs = list(jobs)
    size = max(1, math.ceil(len(jobs) / (RUNS_PER_WORKER * workers)))
    runs = [jobs[i : i + size] for i in range(0, len(jobs), size)]

    def one(run):
        return lockstep.attempts_lockstep(task, sources, run, how, mode=mode, select=select, sims=sims)

    out = []
    for got in map_jobs(one, runs, workers=workers):
        out += got
        if bar is not None:
            bar.update(len(got))
    return out


def grow(
    task: Task,
    sources: dict,
    per_source: int,
    how: Perturbation,
    *,
    mode="resolve",
    select="own",
    cap=ATTEMPTS_PER_KEPT,
    workers=1,
    bar=None,
):
    """The engine's one entry: the first `per_source` kept attempts of every source demo (keep_first),
    attempted in `mode` with the perturbation `how` on `workers` processes.
    Returns (kept episodes in (episode, k) order, attempts, {reason: count})."""
    return keep_first(
        sorted(sources),
        per_source,
        lambda jobs: run_attempts(
            task, sources, jobs, how, mode=mode, select=select, workers=workers, bar=bar
        ),
        reasons=failures_of(task)[mode],
        cap=cap,
    )


def save(task: Task, root, kept: list[dict], *, repo_id: str, stamp: dict) -> None:
    """Write kept episodes (with their provenance) to `root` as one LeRobot v3 set of `task` under our
    stamp; what was at `root` must be ours (ch37.ownership.replace_own_dir), and nothing is written
    when nothing was kept."""
    from ch37.ownership import MADE_BY, replace_own_dir
    from datagen.demos import REWARD_FEATURES, write_dataset
    from lerobot_v3 import features

    replace_own_dir(root)
    if kept:
        m = task.spec
        extra = (
            provenance(task)
            | (REWARD_FEATURES if task.spec.records_reward else {})
            | task.spec.frame_features
        )
        feats = features(m.state_names, m.action_names, extra, env_state_names=m.env_state_names)
        if task.spec.frame_features:
            kept = [ep | task.frame_columns(ep["observation.state"], ep["action"]) for ep in kept]
        write_dataset(
            root,
            task_name=task.name,
            repo_id=repo_id,
            fps=m.fps,
            robot_type=m.robot_type,
            task=m.task,
            feats=feats,
            episodes=kept,
            stamp={"made_by": MADE_BY} | stamp,
            # the frames' observations: the set's state (and env state) columns
            obs_names=task.spec.observation_names,
        )
