"""The engine's one attempt runner: every attempt, in either mode, one at a time or many stepped
together, goes through run_lanes. One attempt = draw its perturbed start, place the env there, act
until the episode ends, keep it on success; the frames, the attempt's start and its provenance are
recorded here and nowhere else.

    attempts_lockstep(task, sources, jobs, how, mode=, select=, lanes=) -> [Outcome per job]
    one_lane(task, env, jobs, mode)     -> their Outcomes, one attempt at a time (datagen.engine.attempt)
    replay_from(task, env, start, source) -> a replay from a given start (datagen.check, the tests)

attempts_lockstep returns exactly what [datagen.engine.attempt(task, sources[e], k, how, ...) for (e, k)
in jobs] returns, frame for frame and bit for bit (tests/test_lockstep.py): it is the same runner with
more lanes. Where the task decides for a batch (resolve: its expert.batch, PushTExpert itself or
datagen.tasks.fast_experts' AlohaBatch; replay:
a task that steps its envs as one batch, its step_batch, PushT's datagen.tasks.fast_pusht.step_many), up to
`lanes` attempts are stepped together and the expert's ~40 small numpy calls per frame are paid once
per control step for all of them; otherwise the runner runs one lane, each attempt in turn. Each attempt
still gets its own simulator state, fully reset at its start (PushT's lanes keep theirs apart in one
shared MjData: fast_pusht.SharedPushTEnv), so its frames do not depend on what shares its batch, on the
lane it runs in, or on when it was started.

The runner (run_lanes) knows no task. A Mode object (mode_parts: Resolve, Replaying; Rollout) gives it
    envs                         the lanes' envs, each with step(action) -> (obs, reward, done,
                                    info["success"]); made by the caller (Simulators: sharing the first's
                                    model, and PushT's MjData) and reused between calls: begin resets an
                                    env fully
    step(envs, actions)          -> (obs, success, done) for the live lanes' envs in one call: the
                                    task's step_batch where lanes run together, env.step per env
                                    (ch37.parallel.step_each) for one lane
    begin(job, env)              -> a Lane placed at its start (lane.obs: its first observation), or a
                                    final result (an Outcome) when there is nothing to simulate
    decide(lanes, envs, obs)     -> (actions (N, act_dim), stop (N,) bool or None): one call for every
                                    live lane; a stopped lane ends before this step (replay's plan ran
                                    out) and is not stepped
    finish(lane, env, episode, last_obs)
                                 -> the attempt's result, from the frames recorded for it (last_obs: the
                                    observation after its last step)
and the runner keeps `lanes` envs busy, refilling a lane as soon as its attempt ends, recording every
frame into preallocated arrays (lanes x max_steps), and returns the results in job order. The demo
generators' episodes go through it too, one lane at a time (mode Rollout: the expert with its action noise,
every episode kept, with --video's frames; datagen.demos.rollout).
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np

from ch37.errors import DataError
from ch37.parallel import step_each, step_envs
from ch37.seeds import env_seed
from datagen import replay
from datagen.task import Outcome, Perturbation, Source, Task, owed
from lerobot_v3 import IMAGE_KEY, IMAGE_SIZE

__all__ = [
    "LANES",
    "Lane",
    "Simulators",
    "attempt_rng",
    "attempts_lockstep",
    "kept_or_not",
    "Mode",
    "Replaying",
    "Resolve",
    "Rollout",
    "mode_parts",
    "one_lane",
    "replay_from",
    "run_lanes",
    "start_of_job",
    "with_provenance",
]

LANES = 256  # attempts stepped together per worker (ALOHA's lane: an MjData, 0.44 MiB, ~1 ms to make)


class Simulators:
    """What a worker keeps between the attempts it runs: per task, the env of attempts one at a time
    (env), the envs of the lanes (lanes), and the sources' replay plans (plans, a cache the task's
    replay fills: ALOHA's subtasks). Each attempt fully resets its env (task.place), so reuse changes no
    bit. Made by whoever runs the attempts (run_attempts, a run's shards) and passed down explicitly;
    a copy sent to another process (pickled: Ray) arrives empty, and a forked worker fills its own."""

    def __init__(self):
        self._env: dict[str, object] = {}  # task name -> its env for attempts one at a time
        self._lanes: dict[str, list] = {}  # task name -> the lanes' envs, the first shared by the rest
        self.plans: dict = {}  # the task's key for a source -> its replay plan

    def env(self, task: Task):
        if task.name not in self._env:
            self._env[task.name] = task.make_env()
        return self._env[task.name]

    def lanes(self, task: Task, n: int) -> list:
        """n envs of `task` for the lanes, made once and reused. One compiled model for all (a load is
        ~4 ms), and where the env can, one MjData (~1 ms each to make, and 256 of them compete for the
        cache): the lanes share the first env (task.make_env(share=))."""
        pool = self._lanes.setdefault(task.name, [])
        if not pool:
            pool.append(task.make_env())
        pool += [task.make_env(share=pool[0]) for _ in range(n - len(pool))]
        return pool[:n]

    def __getstate__(self):
        return {}

    def __setstate__(self, state):
        self.__init__()


class Lane:
    """One live attempt: its job, its first observation, and what its task keeps between steps."""

    def __init__(self, job, obs, **state):
        self.job, self.obs = job, obs
        self.__dict__.update(state)


class _Frames:
    """Each lane slot's recorded frames: observations (one more than actions: the obs after the last
    step), actions, next.success, and next.reward/next.done where the task records its reward."""

    def __init__(self, width: int, max_frames: int, obs_dim: int, act_dim: int, rewards: bool):
        self.obs = np.zeros((width, max_frames + 1, obs_dim), np.float32)
        self.act = np.zeros((width, max_frames, act_dim), np.float32)
        self.succ = np.zeros((width, max_frames), bool)
        self.rew = np.zeros((width, max_frames), np.float32) if rewards else None
        self.done = np.zeros((width, max_frames), bool) if rewards else None

    def episode(self, slot: int, n: int) -> dict:
        """The slot's first n frames, as datagen.demos.rollout records an episode."""
        ep = {
            "observation.state": self.obs[slot, :n].copy(),
            "action": self.act[slot, :n].copy(),
            "next.success": self.succ[slot, :n, None].copy(),
        }
        if self.rew is not None:
            ep["next.reward"] = self.rew[slot, :n, None].copy()
            ep["next.done"] = self.done[slot, :n, None].copy()
        return ep


def run_lanes(
    jobs,
    mode: Mode,
    *,
    envs: list,
    max_frames: int,
    obs_dim: int,
    act_dim: int,
    lanes: int,
    step=step_envs,
    reward_of=None,
):
    """[result of job] for every job, in order, with up to `lanes` attempts stepped together (see the
    module docstring). Frame t of a lane pairs the observation before action t with action t and
    next.success after it, as datagen.demos.rollout records them; `actions` reach step as decide made
    them (their dtype too), and are recorded as float32. reward_of(env): the step's reward, recorded as
    next.reward with next.done (whether the step ended the episode) for a task with records_reward."""
    results = [None] * len(jobs)
    todo = deque(range(len(jobs)))
    width = max(1, min(lanes, len(jobs), len(envs)))
    envs = envs[:width]
    f = _Frames(width, max_frames, obs_dim, act_dim, rewards=reward_of is not None)
    live: dict[int, tuple[int, Lane]] = {}  # slot -> (job index, lane)
    t = np.zeros(width, int)  # frames recorded per slot

    def fill(slot: int) -> None:
        while todo:
            i = todo.popleft()
            got = mode.begin(jobs[i], envs[slot])
            if not isinstance(got, Lane):
                results[i] = got
                continue
            live[slot], t[slot] = (i, got), 0
            f.obs[slot, 0] = got.obs
            return

    def end(slot: int) -> None:
        i, lane = live.pop(slot)
        results[i] = mode.finish(lane, envs[slot], f.episode(slot, t[slot]), f.obs[slot, t[slot]])
        fill(slot)

    for slot in range(width):
        fill(slot)
    while live:
        slots = np.fromiter(live, int, len(live))
        at = t[slots]
        obs = f.obs[slots, at]  # (N, obs_dim): each live lane's current observation
        ids = slots.tolist()
        stepped = [envs[s] for s in ids]
        actions, stop = mode.decide([live[s][1] for s in ids], stepped, obs)
        f.act[slots, at] = actions  # a stopped lane's row lies past its frames: never read
        if stop is not None and stop.any():  # ended before this step, not stepped
            for slot in slots[stop].tolist():
                end(slot)
            slots, at, actions = slots[~stop], at[~stop], actions[~stop]
            if not len(slots):
                continue
            stepped = [envs[s] for s in slots.tolist()]
        o, success, done = step(stepped, actions)
        f.obs[slots, at + 1] = o
        f.succ[slots, at] = success
        if reward_of is not None:
            f.rew[slots, at] = [reward_of(envs[s]) for s in slots.tolist()]
            f.done[slots, at] = done
        t[slots] = at + 1
        full = at + 1 >= max_frames
        if full.any() and not done[full].all():
            raise DataError(  # a user's task: one line (augment_demos.py, datagen.check), not a traceback
                f"an episode ran past {max_frames} steps without ending: the task's max_steps must be "
                "the env's own episode limit"
            )
        for slot in slots[done].tolist():
            end(slot)
    return results


# ----------------------------------------------------------------------------------------------
# The modes as lanes, for any task
# ----------------------------------------------------------------------------------------------
def attempt_rng(seed: int, episode: int, k: int) -> np.random.Generator:
    """The generator of attempt k of source episode `episode`: its own stream, whatever else runs."""
    return np.random.default_rng([env_seed(seed, "aug", episode), k])


def start_of_job(task: Task, sources: dict, job, how: Perturbation):
    """The perturbed start of attempt (e, k): task.perturb of source e's first state with attempt (e, k)'s
    own generator (attempt_rng), or None when the task finds no valid start."""
    e, k = job
    start = task.perturb(sources[e].states[0], attempt_rng(how.seed, e, k), how)
    return start if start is None else owed(task, "perturb", start, (len(task.start_names),))


def with_provenance(ep: dict, source_episode: int, start) -> dict:
    """`ep` with its provenance on every frame: aug.source_episode (n, 1), the source it was made from,
    and aug.start (n, len(start_names)), the start it was made from."""
    n = len(ep["action"])
    ep["aug.source_episode"] = np.full((n, 1), source_episode, np.int64)
    ep["aug.start"] = np.repeat(np.float32(start)[None], n, axis=0)
    return ep


def kept_or_not(lane: Lane, episode: dict, success: bool, reason: str) -> Outcome:
    """The Outcome of the frames `episode` recorded for `lane`: kept with its provenance when `success`
    (for resolve: the last frame's), else `reason` and no frames."""
    e, steps = lane.job[0], len(episode["action"])
    if not success:
        return Outcome(reason, None, lane.start, e, steps)
    episode = with_provenance(episode | {"success": success}, e, lane.start)
    return Outcome(None, episode, lane.start, e, steps)


class Mode:
    """What the runner (run_lanes) asks of an attempt's kind: begin, decide, finish (the module docstring
    says each). Resolve, Replaying and Rollout are the engine's; a test may write its own."""

    def begin(self, job, env):
        raise NotImplementedError

    def decide(self, lanes, envs, obs):
        raise NotImplementedError

    def finish(self, lane, env, episode, last_obs):
        raise NotImplementedError

    def step(self, envs, actions):
        """The step of a run in one lane (one_lane): env.step per env."""
        return step_each(envs, actions)


class Resolve(Mode):
    """Mode "resolve": the task's noise-free expert from each perturbed start, kept on success.
    act_batch (its expert.batch's act_batch) decides for all lanes in one call; without it each lane
    runs its own expert (task.expert.cls, noise-free), reset at its start (the same bits: the batch
    expert is the expert's act over a batch). start_for(job): a given start instead of the drawn one."""

    def __init__(self, task: Task, sources: dict, how: Perturbation, act_batch=None, start_for=None):
        self.task, self.act_batch = task, act_batch
        self.start_for = start_for or (lambda job: start_of_job(task, sources, job, how))

    def begin(self, job, env):
        start = self.start_for(job)
        if start is None:
            return Outcome("no_valid_start", source_episode=job[0])
        if self.act_batch is not None:
            return Lane(job, self.task.place(env, start), start=start)
        expert = self.task.expert.cls(noise=0.0)
        lane = Lane(job, self.task.place(env, start), start=start, expert=expert)
        expert.reset()
        return lane

    def decide(self, lanes, envs, obs):
        if self.act_batch is not None:
            return self.act_batch(obs), None
        return np.stack([lane.expert.act(o) for lane, o in zip(lanes, obs)]), None

    def finish(self, lane, env, episode, last_obs):
        return kept_or_not(lane, episode, bool(episode["next.success"][-1, 0]), "expert_failed")


class Replaying(Mode):
    """Mode "replay": the engine's one replay (datagen.replay.Replay.act, one per lane) of the attempt's
    own source, or of the pool's nearest to its start (MimicGen's selection; pool None: its own). plans:
    the worker's cut sources (None: cut for this call). start_for(job): a given start instead of the drawn
    one. follow: (length, rad), mode "replay_live" (task.replay.follow_tol): each lane re-anchors the rest
    of a segment on the object's live pose once it drifts that far (None: open loop)."""

    def __init__(self, task: Task, sources: dict, how, pool=None, plans=None, start_for=None, follow=None):
        self.task, self.sources, self.pool, self.plans, self.follow = task, sources, pool, plans, follow
        self.start_for = start_for or (lambda job: start_of_job(task, sources, job, how))

    def begin(self, job, env):
        task, pool = self.task, self.pool
        start = self.start_for(job)
        if start is None:
            return Outcome("no_valid_start", source_episode=job[0])
        source = pool[replay.nearest(task, pool, start)] if pool else self.sources[job[0]]
        try:
            plan = replay.plan_of(task, source, self.plans)
        except ValueError:
            return Outcome("source_not_split", None, start, source.episode)
        run = replay.Replay(task, source, plan, start, self.follow)
        return Lane(job, task.place(env, start), run=run)

    def decide(self, lanes, envs, obs):
        act_dim = self.task.spec.act_dim
        actions = [lane.run.act(o, env) for lane, env, o in zip(lanes, envs, obs)]
        made = [a for a in actions if a is not None]
        stop = None if len(made) == len(actions) else np.array([a is None for a in actions], bool)
        if not made:  # nothing is stepped: the rows are never read
            return np.zeros((len(lanes), act_dim), np.float32), stop
        if stop is not None:
            blank = np.zeros_like(made[0])  # a stopped lane's row
            actions = [blank if a is None else a for a in actions]
        try:
            out = np.stack(actions)  # as made, their dtype too
        except (TypeError, ValueError):
            out = None
        # a user's conversion that returns a NaN or the wrong width: one line (owed's), not a traceback in
        # the env; checked on the stack, each action only when the stack is not (N, act_dim) finite numbers
        if (
            out is None
            or out.shape[1:] != (act_dim,)
            or out.dtype.kind not in "fiu"
            or not np.isfinite(out).all()
        ):
            for a in made:
                owed(self.task, "replay.action.to_action", a, (act_dim,))
        return out, stop

    def finish(self, lane, env, episode, last_obs):
        got = lane.run.outcome(env, last_obs, episode)
        kept = with_provenance(got.episode, got.source_episode, got.start) if got.kept else None
        return replace(got, episode=kept)


class Rollout(Mode):
    """The demo generators' mode (datagen.demos: gen_demos.py's episodes, datagen.check's, the tests'
    rollout): a policy, the task's expert with its seeded action noise, from the start its env was placed
    at, to the episode's end. Every episode is the result, solved or not ("success": its last
    next.success), with the frames drawn before each action (render: IMAGE_KEY, IMAGE_SIZE square) and,
    with an env whose step says whether its simulation blew up (info["unstable"]: the ALOHA sims, which
    end the episode there), "unstable". start(job, env) -> (the policy, the first observation)."""

    def __init__(self, start, *, render: bool = False):
        self.start, self.render = start, render
        self._unstable: dict[int, bool | None] = {}  # id(env) -> a step blew its sim up (None: unsaid)

    def begin(self, job, env):
        policy, obs = self.start(job, env)
        policy.reset()
        self._unstable[id(env)] = None
        return Lane(job, obs, policy=policy, frames=[])

    def decide(self, lanes, envs, obs):
        if self.render:
            for lane, env in zip(lanes, envs):
                lane.frames.append(env.render(IMAGE_SIZE))
        return np.stack([lane.policy.act(o) for lane, o in zip(lanes, obs)]), None

    def step(self, envs, actions):
        """step_each, noting each step's info["unstable"] where the env says it."""
        infos = []
        got = step_each(envs, actions, infos)
        for env, info in zip(envs, infos):
            if "unstable" in info:
                self._unstable[id(env)] = bool(self._unstable[id(env)]) or bool(info["unstable"])
        return got

    def finish(self, lane, env, episode, last_obs):
        ep = {k: episode.pop(k) for k in ("observation.state", "action", "next.success")}
        ep["success"] = bool(ep["next.success"][-1, 0])
        ep |= episode  # next.reward and next.done, for a task that records its reward
        if self.render:
            ep[IMAGE_KEY] = np.asarray(lane.frames, np.uint8)
        if (unstable := self._unstable.pop(id(env))) is not None:
            ep["unstable"] = unstable
        return ep


def mode_parts(
    task: Task, sources: dict, how: Perturbation, mode: str, *, pool=None, plans=None, lanes: bool = True
) -> tuple[Mode, bool]:
    """(the Mode object for `mode`, whether its lanes can run together): resolve with the task's
    batch expert (expert.batch), replay where the task steps its envs as one batch (its own step_batch). A
    replay decides lane by lane, so its lanes pay only where the envs step as one batch; stepped env by env
    they cost more than one at a time. lanes False: a Mode for one lane (resolve: the plain expert, faster
    on one row than the batch expert, which is then not made)."""
    if mode == "resolve":
        batch = task.expert.batch if lanes else None
        act_batch = batch().act_batch if batch is not None else None
        return Resolve(task, sources, how, act_batch), act_batch is not None
    follow = task.replay.follow_tol if mode == "replay_live" else None
    kind = Replaying(task, sources, how, pool, plans, follow=follow)
    return kind, type(task).step_batch is not Task.step_batch


def _dims(task: Task) -> dict:
    m = task.spec
    reward_of = (lambda env: env.reward) if m.records_reward else None
    return {"max_frames": m.max_steps, "obs_dim": m.obs_dim, "act_dim": m.act_dim, "reward_of": reward_of}


def one_lane(task: Task, env, jobs, mode: Mode) -> list:
    """[result of job] for `jobs`, each attempt in turn through the runner in one lane on `env`, stepped
    by the mode's step (env.step)."""
    return run_lanes(jobs, mode, envs=[env], step=mode.step, lanes=1, **_dims(task))


def replay_from(task: Task, env, start, source: Source, plans: dict | None = None) -> Outcome:
    """One replay of `source` from the given `start` (not a drawn one), in `env`: its Outcome, the
    frames executed with the provenance of a kept attempt (datagen.check's zero-perturbation replay,
    the tests). plans: a cache of cut sources (None: cut now)."""
    kind = Replaying(task, {source.episode: source}, None, None, plans, start_for=lambda job: start)
    return one_lane(task, env, [(source.episode, 0)], kind)[0]


def attempts_lockstep(
    task: Task,
    sources: dict,
    jobs,
    how: Perturbation,
    *,
    mode="resolve",
    select="own",
    lanes=LANES,
    sims: Simulators | None = None,
) -> list:
    """[datagen.engine.attempt(task, sources[e], k, how, mode=mode, pool=...) for (e, k) in jobs], the
    same bytes, up to `lanes` stepped together where the mode's lanes can run together (else one lane).
    sims: the worker's Simulators (its envs, kept between shards; a new one when None)."""
    sims = Simulators() if sims is None else sims
    jobs = list(jobs)
    pool = sources if select == "nearest" else None
    kind, together = mode_parts(task, sources, how, mode, pool=pool, plans=sims.plans)
    if not together:  # one lane, each attempt in turn on the worker's env
        return one_lane(task, sims.env(task), jobs, kind)
    width = max(1, min(lanes, len(jobs)))
    envs = sims.lanes(task, width)
    return run_lanes(jobs, kind, envs=envs, step=task.step_batch, lanes=width, **_dims(task))
