"""Lockstep attempts: a worker runs a batch of the engine's attempts together, one env per live attempt,
and the expert (or replay) decides for all of them in one call.

    attempts_lockstep(task, sources, jobs, how, mode=, select=, lanes=) -> [result per job]

returns exactly what [datagen.engine.attempt(task, sources[e], k, how, ...) for (e, k) in jobs]
returns, frame for frame and bit for bit (tests/test_lockstep.py), at a fraction of the Python cost
per frame: the engine's one-at-a-time path pays the expert's ~40 small numpy calls for every frame of
every attempt, where here they are paid once per control step for up to `lanes` attempts (the task's
batch_expert: datagen.fast_experts), and the env steps them all in one call where it can (the task's
step_batch: datagen.fast_pusht.step_many). Each attempt still gets its own simulator state, fully
reset at its start (PushT's lanes keep theirs apart in one shared MjData: fast_pusht.SharedPushTEnv),
so its frames do not depend on what shares its batch, on the lane it runs in, or on when it was started.

The runner (run_lanes) knows no task. A mode hands it
    envs                         the lanes' envs, each with step(action) -> (obs, reward, done,
                                    info["success"]); made by the caller (datagen.engine.Simulators:
                                    sharing the first's model, and PushT's MjData) and reused between
                                    calls: begin resets an env fully
    step(envs, actions)          -> (obs, success, done) for the live lanes' envs in one call: the
                                    task's step_batch (PushT's: datagen.fast_pusht.step_many; by
                                    default env.step per env), ch37.parallel.step_envs when not given
    begin(job, env)              -> a Lane placed at its start (lane.obs: its first observation), or a
                                    final result (an Outcome) when there is nothing to simulate
    decide(lanes, envs, obs)     -> (actions (N, act_dim) float32, stop (N,) bool or None): one call for
                                    every live lane; a stopped lane ends before this step (replay's
                                    segment ran out) and is not stepped
    finish(lane, env, episode, last_obs)
                                 -> the attempt's result, from the frames recorded for it (last_obs: the
                                    observation after its last step)
and the runner keeps `lanes` envs busy, refilling a lane as soon as its attempt ends, recording every
frame into preallocated arrays (lanes x max_frames), and returns the results in job order.
Mode "resolve" is built here for every task from its parts (perturb, place, batch_expert, step_batch,
max_steps: the Task contract, datagen.task); mode "replay" is the engine's one replay as lanes
(replay_lanes: each lane runs datagen.replay's generator, as one attempt does), for both --select, for
a task that steps its envs as one batch (its own step_batch). A task without a batch expert runs
"resolve", and one without a batch step "replay", one attempt at a time through datagen.engine.attempt,
the same bytes.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ch37.parallel import step_envs
from datagen import engine, replay
from datagen.task import Outcome, Perturbation, Task

__all__ = [
    "LANES",
    "Lane",
    "attempts_lockstep",
    "kept_or_not",
    "replay_lanes",
    "resolve_lanes",
    "run_lanes",
    "start_of_job",
]

LANES = 256  # attempts stepped together per worker (ALOHA's lane: an MjData, 0.44 MiB, ~1 ms to make)


class Lane:
    """One live attempt: its job, its first observation, and what its task keeps between steps."""

    def __init__(self, job, obs, **state):
        self.job, self.obs = job, obs
        self.__dict__.update(state)


def run_lanes(
    jobs,
    *,
    envs: list,
    begin,
    decide,
    finish,
    max_frames: int,
    obs_dim: int,
    act_dim: int,
    lanes: int,
    step=step_envs,
):
    """[result of job] for every job, in order, with up to `lanes` attempts stepped together (see the
    module docstring). Frame t of a lane pairs the observation before action t with action t and
    next.success after it, as datagen.task.rollout records them."""
    results = [None] * len(jobs)
    todo = deque(range(len(jobs)))
    width = max(1, min(lanes, len(jobs), len(envs)))
    envs = envs[:width]
    obs_buf = np.zeros((width, max_frames + 1, obs_dim), np.float32)  # +1: the obs after the last step
    act_buf = np.zeros((width, max_frames, act_dim), np.float32)
    succ_buf = np.zeros((width, max_frames), bool)
    live: dict[int, tuple[int, Lane]] = {}  # slot -> (job index, lane)
    t = np.zeros(width, int)  # frames recorded per slot

    def fill(slot: int) -> None:
        while todo:
            i = todo.popleft()
            got = begin(jobs[i], envs[slot])
            if not isinstance(got, Lane):
                results[i] = got
                continue
            live[slot], t[slot] = (i, got), 0
            obs_buf[slot, 0] = got.obs
            return

    def end(slot: int) -> None:
        i, lane = live.pop(slot)
        n = t[slot]
        episode = {
            "observation.state": obs_buf[slot, :n].copy(),
            "action": act_buf[slot, :n].copy(),
            "next.success": succ_buf[slot, :n, None].copy(),
        }
        results[i] = finish(lane, envs[slot], episode, obs_buf[slot, n])
        fill(slot)

    for slot in range(width):
        fill(slot)
    while live:
        slots = np.fromiter(live, int, len(live))
        at = t[slots]
        obs = obs_buf[slots, at]  # (N, obs_dim): each live lane's current observation
        ids = slots.tolist()
        actions, stop = decide([live[s][1] for s in ids], [envs[s] for s in ids], obs)
        act_buf[slots, at] = actions  # a stopped lane's row lies past its frames: never read
        if stop is not None and stop.any():  # ended before this step, not stepped
            for slot in slots[stop].tolist():
                end(slot)
            slots, at, actions = slots[~stop], at[~stop], actions[~stop]
            if not len(slots):
                continue
        o, success, done = step([envs[s] for s in slots.tolist()], actions)
        obs_buf[slots, at + 1] = o
        succ_buf[slots, at] = success
        t[slots] = at + 1
        for slot in slots[done].tolist():
            end(slot)
    return results


# ----------------------------------------------------------------------------------------------
# The modes as lanes, for any task
# ----------------------------------------------------------------------------------------------
def start_of_job(task: Task, sources: dict, job, how: Perturbation):
    """The perturbed start of attempt (e, k), drawn as datagen.engine.attempt draws it, or None."""
    e, k = job
    return task.perturb(sources[e].states[0], engine.attempt_rng(how.seed, e, k), how)


def kept_or_not(lane: Lane, episode: dict, success: bool, reason: str) -> Outcome:
    """The Outcome datagen.engine.attempt gives for the frames `episode` recorded for `lane`: kept with
    its provenance when `success` (for resolve: the last frame's, as rollout's), else `reason`."""
    e, steps = lane.job[0], len(episode["action"])
    if not success:
        return Outcome(reason, None, lane.start, e, steps)
    episode = engine.with_provenance(episode | {"success": success}, e, lane.start)
    return Outcome(None, episode, lane.start, e, steps)


def resolve_lanes(task: Task, sources: dict, how: Perturbation) -> dict:
    """Mode "resolve": the task's noise-free expert from each perturbed start, kept on success."""
    act_batch = task.batch_expert()

    def begin(job, env):
        start = start_of_job(task, sources, job, how)
        if start is None:
            return Outcome("no_valid_start", source_episode=job[0])
        return Lane(job, task.place(env, start), start=start)

    def decide(lanes, envs, obs):
        return act_batch(obs), None

    def finish(lane, env, episode, last_obs):
        return kept_or_not(lane, episode, bool(episode["next.success"][-1, 0]), "expert_failed")

    return {"begin": begin, "decide": decide, "finish": finish}


def replay_lanes(task: Task, sources: dict, how: Perturbation, pool: dict | None, plans: dict) -> dict:
    """The engine's one replay as lanes: each lane runs datagen.replay.Replay.steps, so a lane's frames
    are datagen.replay.replay's, bit for bit (tests/test_lockstep.py). pool: the sources --select
    nearest chooses from (None: the attempt's own); plans: the worker's cut sources."""

    def begin(job, env):
        start = start_of_job(task, sources, job, how)
        if start is None:
            return Outcome("no_valid_start", source_episode=job[0])
        source = pool[replay.nearest(task, pool, start)] if pool else sources[job[0]]
        try:
            plan = replay.plan_of(task, source, plans)
        except ValueError:
            return Outcome("source_not_split", None, start, source.episode)
        run = replay.Replay(task, source, plan, start)
        obs = task.place(env, start)
        gen = run.steps(env)
        next(gen)
        return Lane(job, obs, run=run, gen=gen)

    def decide(lanes, envs, obs):
        actions = np.zeros((len(lanes), task.env_module.ACT_DIM), np.float32)
        stop = np.zeros(len(lanes), bool)
        for j, lane in enumerate(lanes):
            try:
                actions[j] = lane.gen.send(obs[j])
            except StopIteration:
                stop[j] = True
        return actions, stop

    def finish(lane, env, episode, last_obs):
        got = lane.run.outcome(env, last_obs, episode)
        kept = engine.with_provenance(got.episode, got.source_episode, got.start) if got.kept else None
        return Outcome(got.reason, kept, got.start, got.source_episode, got.steps)

    return {"begin": begin, "decide": decide, "finish": finish}


def attempts_lockstep(
    task: Task,
    sources: dict,
    jobs,
    how: Perturbation,
    *,
    mode="resolve",
    select="own",
    lanes=LANES,
    sims: engine.Simulators | None = None,
) -> list:
    """[datagen.engine.attempt(task, sources[e], k, how, mode=mode, pool=...) for (e, k) in jobs], the
    same bytes, stepped in lockstep where the mode has lanes (else one attempt at a time). sims: the
    worker's Simulators (its lanes' envs, kept between shards; a new one when None)."""
    sims = engine.Simulators() if sims is None else sims
    jobs = list(jobs)
    parts = None
    if mode == "resolve" and task.batch_expert() is not None:
        parts = resolve_lanes(task, sources, how)
    # a replay decides lane by lane: lanes pay where the task steps its envs as one batch (PushT's
    # step_many); stepped env by env (the default step_batch) they cost more than one at a time
    if mode == "replay" and type(task).step_batch is not Task.step_batch:
        parts = replay_lanes(task, sources, how, sources if select == "nearest" else None, sims.plans)
    if parts is None:  # no lanes for this task and mode: the same results, one at a time
        return engine.run_attempts(task, sources, jobs, how, mode=mode, select=select, workers=1, sims=sims)
    m = task.env_module
    return run_lanes(
        jobs,
        envs=sims.lanes(task, max(1, min(lanes, len(jobs)))),
        step=task.step_batch,
        **parts,
        max_frames=task.max_steps,
        obs_dim=m.OBS_DIM,
        act_dim=m.ACT_DIM,
        lanes=lanes,
    )
