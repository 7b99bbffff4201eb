"""What a task gives the data engine: MimicGen's env interface, made small.

The engine (datagen.engine: one attempt, keep_first; datagen.shards: the run, its shards, report and
merge) knows no task. Everything about one task lives in one module named for it (datagen/pusht.py,
datagen/aloha.py), and only that module (and the engine's bit-identical fast copies, datagen/fast_*.py)
imports its env and its expert. A task is an instance of a Task subclass that the module registers as
it is imported (TASK = register(MyTask()): known_tasks() finds it; no list names it, and the digests
that guard resumed shards and cached demo sets read its code from what it imports); it provides

    name, title, generator
                         the task's key ("pusht"), its name in messages, the command that
                         makes a source set of it
    start_names          the names of a start's numbers, in the order
                         place() takes them (stored on every kept frame as aug.start)
    state_ranges         {state name: (low, high)} as the env documents them: a source outside is refused
    action_ranges        {action name: (low, high)}: the env's clip range, checked as the states are
    env_module           the env's module: STATE_NAMES, ACTION_NAMES, ENV_STATE_NAMES, FPS, ROBOT_TYPE,
                         TASK (what a LeRobot set of this task records), OBS_DIM, ACT_DIM
    make_env(share=None) a new simulator (one per worker process; place() fully resets it); share:
                         an env of this task to share with: its compiled model, and where the env
                         can (PushT) its MjData, each env keeping its own state (lockstep's lanes)
    perturb(state, rng, perturbation)
                         a start near the source's first observation `state`, drawn from `rng`, or
                         None when no valid draw was found (reason "no_valid_start")
    place(env, start)    the simulator put at `start` with fresh counters; returns the observation
    expert()             the noise-free expert that re-solves a placed start
    object_pose(state)   the pose of the object the task is about, from an observation
    nearest(pool, start) the episode of the source in `pool` ({episode: Source}) whose objects lie
                         nearest `start`'s (MimicGen's nearest source selection, --select nearest)
    segments(source)     the source demo cut into segments, each relative to one object frame
                         (Segment, or the task's own subtask type); replay re-expresses each in the
                         new start's frame
    replay(env, start, source, plans=None)
                         the source's segments re-expressed for `start` and executed open-loop:
                         an Outcome (reason None on success); plans: a dict the caller keeps between
                         attempts (datagen.engine.Simulators.plans) where a task caches its plans
    success(env)         whether the env reports the task done
    failures             {mode: every reason an attempt of that mode can return}

What lockstep (datagen.lockstep: a shard's attempts stepped together) needs, each with a default that
gives the same bytes one attempt at a time:

    max_steps            control steps an episode may last (the env's limit); sizes lockstep's buffers
    batch_expert()       the noise-free expert over a batch: obs (N, obs_dim) float32 -> actions (N,
                         act_dim) float32, row i bit for bit expert().act(obs[i]); None (the default):
                         mode "resolve" runs one attempt at a time
    step_batch(envs, actions)
                         envs[i] stepped with actions[i] -> (obs (N, obs_dim), success (N,), done (N,)),
                         bit for bit env.step per env, which the default does (ch37.parallel.step_each)
    replay_lanes(sources, how)
                         mode "replay" as lanes (begin, decide, finish), or None (the default): replay
                         runs one attempt at a time

A mode is a method name: "resolve" (perturb, re-solve with the expert, keep on success) and
"replay" (perturb, replay the transformed source, keep on success) are defined here once for every
task from the parts above. An executor that steps many attempts in lockstep decides through the
same parts (place, expert, success) over a batch.
"""

from __future__ import annotations

import importlib
import math
import pkgutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ch37.ownership import publish_dir
from ch37.parallel import step_each
from lerobot_v3 import IMAGE_KEY, IMAGE_SIZE, write_set

__all__ = [
    "Outcome",
    "Perturbation",
    "Segment",
    "Source",
    "Task",
    "ended",
    "known_tasks",
    "recorded",
    "register",
    "rollout",
    "rotation",
    "transform_segment",
    "write_dataset",
]


@dataclass(frozen=True)
class Perturbation:
    """How far a start is moved: every kept attempt's draw depends on these and (episode, k) alone."""

    seed: int  # >= 0; seeds draw disjoint perturbations (datagen.engine.attempt_rng)
    pos_sigma: float  # m; std of the object's and the robot's xy moves
    yaw_sigma: float  # rad; std of the object's yaw move


@dataclass(frozen=True, eq=False)
class Outcome:
    """What one attempt came to: the one shape every mode, replay and executor returns.

    reason          None when the attempt is kept (the env reported success), else why not (one of
                    the task's failures[mode])
    episode         the frames executed (observation.state, action, next.success arrays, success);
                    from datagen.engine a kept attempt's carry their provenance and a failed one's are
                    dropped (None), so a shard holds only what it writes
    start           the perturbed start (task.start_names), None when no valid draw was found
    source_episode  the source demo the attempt was made from (the one replayed, under --select nearest)
    steps           control steps simulated (frames recorded), 0 when nothing was simulated
    """

    reason: str | None
    episode: dict | None = None
    start: tuple | None = None
    source_episode: int | None = None
    steps: int = 0

    @property
    def kept(self) -> bool:
        return self.reason is None


def ended(ep: dict, reason: str | None, start, source_episode: int) -> Outcome:
    """The Outcome of an attempt that simulated the episode `ep` (its reason None: kept)."""
    return Outcome(reason, ep, start, source_episode, len(ep["action"]))


@dataclass(frozen=True)
class Source:
    """One source demo: its episode index in the source set and its frames, in order."""

    episode: int
    states: np.ndarray  # (T, obs_dim) observation.state; resolve reads only the first row
    actions: np.ndarray  # (T, act_dim) action; kept for modes that reuse the source path


@dataclass(frozen=True)
class Segment:
    """Frames [start, stop) of a source demo, made relative to the object at `pose` (x m, y m, yaw rad)."""

    start: int
    stop: int
    pose: tuple[float, float, float]


def rotation(yaw: float) -> np.ndarray:
    """The 2x2 rotation by `yaw` (rad)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def transform_segment(points, vectors, src_pose, new_pose):
    """Re-express a path that was made relative to an object at `src_pose` for the object at `new_pose`.

    points (T, 2) world positions (m) and vectors (T, 2) world velocities (m/s); poses (x, y, yaw).
    A point is first written in the source object's frame, q = R(-yaw0) (p - xy0), then put back in the
    world from the new pose, p' = R(yaw1) q + xy1; a velocity only rotates, v' = R(yaw1 - yaw0) v.
    The planar SE(2) analog of MimicGen's transform_source_data_segment_using_object_pose.
    Returns (points' (T, 2), vectors' (T, 2)); an identical pose returns the inputs (to float rounding).
    """
    x0, y0, yaw0 = (float(v) for v in src_pose)
    x1, y1, yaw1 = (float(v) for v in new_pose)
    in_object = (np.asarray(points, np.float64) - (x0, y0)) @ rotation(-yaw0).T  # (T, 2) object frame
    moved = in_object @ rotation(yaw1).T + (x1, y1)
    turned = np.asarray(vectors, np.float64) @ rotation(yaw1 - yaw0).T
    return moved, turned


def write_dataset(
    out: Path,
    *,
    repo_id: str,
    fps: int,
    robot_type: str,
    task: str,
    feats: dict,
    episodes,
    stamp: dict,
    **how,
) -> None:
    """Write `episodes` as a LeRobot v3 set (lerobot_v3.write_set) to the new folder `out`, whole or not
    at all, under our stamp listing every file with its sha256 (ch37.ownership.publish_dir). `how`:
    write_set's other options (per_frame)."""
    how |= dict(repo_id=repo_id, fps=fps, robot_type=robot_type, task=task, feats=feats, episodes=episodes)
    with publish_dir(out, stamp) as tmp:
        write_set(tmp, **how)


def recorded(env_module, states, actions, succ, success: bool) -> dict:
    """A replay's recorded frames as an episode: observation.state (T, OBS_DIM) float32, action
    (T, ACT_DIM) float32, next.success (T, 1) bool (shapes kept for T = 0), and whether it succeeded."""
    return {
        "observation.state": np.asarray(states, np.float32).reshape(-1, env_module.OBS_DIM),
        "action": np.asarray(actions, np.float32).reshape(-1, env_module.ACT_DIM),
        "next.success": np.asarray(succ, bool).reshape(-1, 1),
        "success": success,
    }


def rollout(env, policy, obs, *, render: bool = False) -> dict:
    """Run `policy` from `obs` (what reset or set_start returned) to the end of the episode.

    Frame t pairs the obs before action t with action t.
    Returns arrays: observation.state (T, obs_dim) float32, action (T, act_dim) float32,
    next.success (T, 1) bool, and IMAGE_KEY (T, IMAGE_SIZE, IMAGE_SIZE, 3) uint8 when render is set.
    """
    policy.reset()
    states, actions, succ, frames = [], [], [], []
    done = False
    while not done:
        if render:
            frames.append(env.render(IMAGE_SIZE))
        act = policy.act(obs)
        states.append(obs)
        actions.append(act)
        obs, _, done, info = env.step(act)
        succ.append(bool(info["success"]))
    ep = {
        "observation.state": np.asarray(states, np.float32),
        "action": np.asarray(actions, np.float32),
        "next.success": np.asarray(succ, bool)[:, None],
        "success": bool(succ[-1]),
    }
    if render:
        ep[IMAGE_KEY] = np.asarray(frames, np.uint8)
    return ep


class Task:
    """The contract between the engine and a task, in MimicGen's division of work: the task describes
    (its env, starts and their perturbation, the expert, the source's segments and their replay,
    success), the engine runs (the modes below, lockstep, shards, resume, report, merge). A subclass sets
    the attributes and defines every method that raises NotImplementedError; the lockstep hooks below
    them have defaults. See the module docstring."""

    name: str  # "pusht": its key in known_tasks(), recorded in a run's settings
    title: str  # "PushT": how messages name it
    generator: str  # the command that makes a source set of this task ("gen_demos_pusht.py")
    start_names: tuple[str, ...]
    state_ranges: dict[str, tuple[float, float]]
    action_ranges: dict[str, tuple[float, float]]
    env_module: object
    failures: dict[str, tuple[str, ...]]
    max_steps: int  # control steps an episode may last: the env's limit

    # ---- what every task must provide (each raises until the task defines it) ----
    def make_env(self, share=None):
        """A new simulator of this task: reset(seed) and step(action) -> (obs (obs_dim,) float32,
        reward, done, info["success"]). share: an env of this task whose compiled model (and, where the
        env can, simulator memory) the new one may share; every env keeps its own state."""
        raise NotImplementedError

    def perturb(self, first_state, rng, how: Perturbation):
        """A start near a source's first observation `first_state` ((obs_dim,) float32): a tuple of
        floats in start_names' order and units (m, rad), drawn from `rng` alone with how.pos_sigma (m)
        and how.yaw_sigma (rad); None when no valid draw was found (reason "no_valid_start")."""
        raise NotImplementedError

    def place(self, env, start):
        """Put `env` at `start` (perturb's tuple) with fresh counters, fully (nothing of an earlier attempt
        may survive); returns the first observation ((obs_dim,) float32)."""
        raise NotImplementedError

    def expert(self):
        """The noise-free expert that re-solves a placed start: reset() and act(obs) -> (act_dim,)
        float32 action, in the env's action units (velocities, m/s, for our two robots)."""
        raise NotImplementedError

    def object_pose(self, state) -> np.ndarray:
        """(x m, y m, yaw rad) of the object the task is about, read from an observation."""
        raise NotImplementedError

    def nearest(self, pool: dict, start) -> int:
        """The episode of the source in `pool` ({episode: Source}) whose objects start nearest `start`'s
        (MimicGen's nearest source selection); ties to the lowest episode."""
        raise NotImplementedError

    def segments(self, source: Source) -> list:
        """The source demo cut into subtasks, each with its frames [start, stop) and the object frame
        its motion is relative to (Segment, or the task's own subtask type)."""
        raise NotImplementedError

    def replay(self, env, start, source: Source, plans: dict | None = None) -> Outcome:
        """The source's segments re-expressed for `start` and executed open-loop in `env` (placed here):
        an Outcome whose episode holds the frames actually executed, reason None when the env reports
        success, else one of failures["replay"]. plans: the caller's cache for segments (may be None)."""
        raise NotImplementedError

    def success(self, env) -> bool:
        """Whether `env` reports the task done (its latched success)."""
        raise NotImplementedError

    # ---- what lockstep needs; each default runs the same bytes one attempt (or one env) at a time ----
    def batch_expert(self):
        """expert() over a batch, obs (N, obs_dim) float32 -> actions (N, act_dim) float32, each row bit for
        bit expert().act of that row; None: mode "resolve" is run one attempt at a time."""
        return None

    def step_batch(self, envs, actions):
        """envs[i] stepped with actions[i]: (obs (N, obs_dim), success (N,) bool, done (N,) bool), bit for
        bit env.step per env (what this default does)."""
        return step_each(envs, actions)

    def replay_lanes(self, sources: dict, how: Perturbation) -> dict | None:
        """Mode "replay" as lockstep lanes (datagen.lockstep: begin, decide, finish), bit-identical to
        replay_mode with the attempt's own source; None: the engine replays one attempt at a time."""
        return None

    # ---- the modes, the same for every task ----
    def resolve(self, source: Source, rng, how: Perturbation, env, pool=None, plans=None) -> Outcome:
        """1. perturb the source's first state, 2. re-solve with the expert, 3. keep only on success.
        The expert solves the start itself: no source is replayed, so `pool` is not read."""
        start = self.perturb(source.states[0], rng, how)
        if start is None:
            return Outcome("no_valid_start", source_episode=source.episode)
        ep = rollout(env, self.expert(), self.place(env, start))
        return ended(ep, None if ep["success"] else "expert_failed", start, source.episode)

    def replay_mode(self, source: Source, rng, how: Perturbation, env, pool=None, plans=None) -> Outcome:
        """1. perturb (the same draw as resolve), 2. replay the transformed source (the attempt's own, or
        given `pool` ({episode: Source}) the pool's nearest to the new start), 3. keep on success.
        plans: the caller's cache of replay plans (datagen.engine.Simulators.plans), None: none kept."""
        start = self.perturb(source.states[0], rng, how)
        if start is None:
            return Outcome("no_valid_start", source_episode=source.episode)
        chosen = pool[self.nearest(pool, start)] if pool else source
        return self.replay(env, start, chosen, plans)

    def run_mode(
        self, mode: str, source: Source, rng, how: Perturbation, env, pool=None, plans=None
    ) -> Outcome:
        """The Outcome of one attempt of `mode` (its source_episode: the source it was made from). pool:
        the sources --select nearest chooses from (None: the attempt's own); plans: the caller's cache
        of replay plans (None: none kept)."""
        run = {"resolve": self.resolve, "replay": self.replay_mode}[mode]
        return run(source, rng, how, env, pool, plans)

    @property
    def modes(self) -> tuple[str, ...]:
        return tuple(self.failures)


# ---- the tasks the engine knows: each registers itself when its module is imported ----
_REGISTERED: dict[str, Task] = {}


def register(task: Task) -> Task:
    """Make `task` known to the engine under task.name; a task module calls it as it is imported
    (PUSHT = register(PushT())), as MimicGen's env interfaces register through their metaclass."""
    old = _REGISTERED.setdefault(task.name, task)
    if old is not task and type(old) is not type(task):
        raise ValueError(f"two tasks named {task.name!r}: {type(old).__name__} and {type(task).__name__}")
    return old


def known_tasks() -> dict[str, Task]:
    """{name: task} of every task the engine knows, by name. Every module of this package is imported
    first, so a task module found here registers itself: a new task is one module in datagen/, listed
    nowhere else."""
    for m in pkgutil.iter_modules([str(Path(__file__).parent)]):
        importlib.import_module(f"{__package__}.{m.name}")
    return dict(sorted(_REGISTERED.items()))
