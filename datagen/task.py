"""What a task gives the data engine: MimicGen's env interface, made small.

The engine (datagen.engine: one attempt in either mode; datagen.replay: the one replay; datagen.lockstep;
datagen.run: a run, its shards, resume, report and merge) knows no task. Everything about one task lives in
one module named for it (datagen/tasks/pusht.py, datagen/tasks/aloha.py), and only that module (and the
engine's bit-identical fast copies, datagen/tasks/fast_*.py) imports its env and its expert. A task is an
instance of a Task subclass that its module registers as it is imported (TASK = register(MyTask())):
known_tasks() finds it, no list names it, and the digests that guard resumed shards and cached demo sets read
its code from what the run imported.

In MimicGen's division of work, a task only describes. Task (below, an abstract base) has eight required
members and twelve with defaults; its settings come in three frozen groups, each one idea:

    spec     EnvSpec: its env and what its sets record (names, fps, robot_type, episode limit, the ranges
             a source may hold, the simulator packages, next.reward, extra per-frame columns)
    replay   ReplaySpec (MimicGen's task_spec): its arms, their reach, its subtasks, how bridges move,
             the hold, the live-follow tolerance and the action kind (how an action becomes a world-frame
             target and back: VelocityCommand, PositionTarget, PoseTarget, DeltaCommand, or one of its
             own); None: the task only re-solves
    expert   ExpertSpec: its scripted expert, the noise its demo sets carry and its unit, its batched
             copy; None: the task only replays

    required             name, spec, start_names, replay; make_env (our envs, or a Gymnasium env through
                         GymnasiumEnv), start_of (the start an observation shows), perturb (a start near a
                         source's first observation), object_pose
    defaults             title, expert, default_noise; place (env.set_start), success (env.success: an
                         env's info key through GymnasiumEnv's success_key), state_problem; frame_pose
                         (the object frames its subtasks live in), start_distance, signals (its subtasks'
                         end signals), arm_pose; frame_columns; step_batch

Poses are SE(3) (datagen.poses); a planar task's (x, y, yaw) frames and (x, y) points are the special case.
python -m datagen.check TASK runs what a task must satisfy before a long run.

and the engine does the rest: the modes ("resolve": perturb, the expert re-solves, keep on success;
"replay": perturb, the source's subtasks re-expressed in the new object frames and executed, keep on
success: datagen.replay; "replay_live": the same, re-expressed again from the objects' live poses once
they drift beyond replay.follow_tol), lockstep, shards, resume, report and merge.
"""

from __future__ import annotations

import abc
import functools
import importlib
import math
import pkgutil
import sys
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ch37.parallel import step_each
from datagen.poses import quat_of, rotations_of

__all__ = [
    "REQUIRED_ATTRIBUTES",
    "ActionKind",
    "DeltaCommand",
    "EnvSpec",
    "ExpertSpec",
    "GymnasiumEnv",
    "Outcome",
    "Perturbation",
    "PoseTarget",
    "PositionTarget",
    "ReplaySpec",
    "Source",
    "Subtask",
    "Task",
    "VelocityCommand",
    "contract_problem",
    "ended",
    "failures_of",
    "known_tasks",
    "modes_of",
    "owed",
    "register",
]


@dataclass(frozen=True)
class EnvSpec:
    """What a task's env is and what its LeRobot sets record, in one typed place (a task's `spec`).
    EnvSpec.of(module, **more) reads an env module's constants (pusht_env, aloha_env: STATE_NAMES,
    ACTION_NAMES, ENV_STATE_NAMES, FPS, ROBOT_TYPE, TASK, MAX_STEPS, and OBS_NAMES where it has them)."""

    state_names: tuple[str, ...]  # observation.state's entries, in order
    action_names: tuple[str, ...]  # action's entries, in order
    fps: int  # control steps per second: the set's fps
    robot_type: str  # the set's robot_type (meta/info.json)
    task: str  # the set's one task, in words
    max_steps: int  # the env's episode limit, in control steps (datagen.check compares the env's own)
    env_state_names: tuple[str, ...] = ()  # observation.environment_state's entries: names of state_names
    # entries (our envs: the objects' share of the state), or, with obs_names, the entries the observation
    # vector holds beside state_names (lerobot/pusht_keypoints' keypoints)
    obs_names: tuple[str, ...] = ()  # the env's observation vector where it is more than observation.state
    # {name: (low, high)} of observation_names / action_names: a source set holding a value outside is
    # refused (a block at 1e30 m is no start); the action ranges are the env's clip range
    state_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    action_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    # the third-party packages whose versions can change its frames (its simulator), named in the digest
    # of its demo sets (datagen.demos) and in every shard's stamp (datagen.plan.versions)
    packages: tuple[str, ...] = ("mujoco",)
    # its sets carry next.reward (the env's reward, float32) and next.done (the env ended the episode there)
    # beside next.success, as the hub's sets of its env do (lerobot/pusht_keypoints); the env keeps its last
    # step's reward as env.reward (GymnasiumEnv does)
    records_reward: bool = False
    # LeRobot features of per-frame columns its sets carry beyond state, action and success (the ALOHA
    # transfer-cube's end-effector targets), each computed from an episode's frames by Task.frame_columns
    frame_features: dict[str, dict] = field(default_factory=dict)

    def __post_init__(self):
        for name in ("state_names", "action_names", "env_state_names", "obs_names", "packages"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not self.state_names or not self.action_names:
            raise TypeError("an EnvSpec needs state_names and action_names")
        if int(self.fps) <= 0 or int(self.max_steps) <= 0:
            raise TypeError(
                f"an EnvSpec's fps and max_steps must be positive, not {self.fps}, {self.max_steps}"
            )

    @property
    def observation_names(self) -> tuple[str, ...]:
        """The names of the observation vector's entries: obs_names where the env's observation holds more
        than a set's observation.state (its env_state_names beside it, as lerobot/pusht_keypoints records
        them), else state_names."""
        return self.obs_names or self.state_names

    @property
    def obs_dim(self) -> int:
        """Entries of the env's observation vector."""
        return len(self.observation_names)

    @property
    def act_dim(self) -> int:
        return len(self.action_names)

    @classmethod
    def of(cls, module, **more) -> EnvSpec:
        """The spec an env module's constants say, with `more` (the fields no module constant gives); a
        missing constant is a TypeError naming it."""
        need = ("STATE_NAMES", "ACTION_NAMES", "FPS", "ROBOT_TYPE", "TASK", "MAX_STEPS")
        if missing := [c for c in need if not hasattr(module, c)]:
            raise TypeError(f"{getattr(module, '__name__', module)} has no {', '.join(missing)}")
        return cls(
            state_names=module.STATE_NAMES,
            action_names=module.ACTION_NAMES,
            fps=module.FPS,
            robot_type=module.ROBOT_TYPE,
            task=module.TASK,
            max_steps=module.MAX_STEPS,
            env_state_names=getattr(module, "ENV_STATE_NAMES", ()),
            obs_names=getattr(module, "OBS_NAMES", ()),
            **more,
        )


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
    detail          where a replay failed, in words: the subtask and the waypoint (datagen.check shows
                    it; a run's report counts reasons only)
    """

    reason: str | None
    episode: dict | None = None
    start: tuple | None = None
    source_episode: int | None = None
    steps: int = 0
    detail: str | None = None

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


class GymnasiumEnv:
    """A Gymnasium env (reset(seed=, options=) -> (obs, info); step -> (obs, reward, terminated,
    truncated, info)) as the engine steps one: reset(seed, options) -> obs, set_start(*start) -> obs (the
    task's place), step(action) -> (obs, reward, done, info with "success"), success (latched), reward
    (the last step's: what a set's next.reward records, spec.records_reward), render(size) (--video's
    frames).

    observe(obs) -> the task's observation vector ((obs_dim,) float32). What the task is done means:
    success_key, the info key that says so ("is_success"), or for an env that reports none, success(obs,
    info) -> bool, a predicate of the task's observation vector and the step's info, which also ends the
    episode (an env that knows no success does not stop at it). How a start is set:
    set_start(env, start) -> the env's own observation, for an env whose reset cannot take one (Gymnasium's
    MuJoCo envs: env.unwrapped.set_state); by default reset(options={"reset_to_state": start})."""

    def __init__(self, env, observe, success_key: str = "is_success", *, success=None, set_start=None):
        self.env, self.observe, self.success_key = env, observe, success_key
        self.done_when, self.setter = success, set_start
        self.success, self.reward = False, 0.0

    def reset(self, seed=None, options=None) -> np.ndarray:
        obs, _ = self.env.reset(seed=seed, options=options)
        self.success = False
        return self.observe(obs)

    def set_start(self, *start) -> np.ndarray:
        """The env put at `start` (fully, its counters fresh): its first observation vector."""
        if self.setter is None:
            return self.reset(options={"reset_to_state": list(start)})
        self.env.reset(seed=0)  # fresh counters (time limit, latched state); the setter then sets every state
        self.success = False
        return self.observe(self.setter(self.env, start))

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        seen = self.observe(obs)
        self.success |= bool(info[self.success_key] if self.done_when is None else self.done_when(seen, info))
        # an env that reports no success does not end at it either: the predicate's success ends the
        # episode, as gym-pusht's own does
        done = terminated or truncated or (self.done_when is not None and self.success)
        self.reward = float(reward)
        return seen, reward, bool(done), info | {"success": self.success}

    def render(self, size: int) -> np.ndarray:
        """The env's own frame, (size, size, 3) uint8: Gymnasium's render() of an env its task made with
        render_mode "rgb_array", drawing at that size. ValueError for an env that draws no such frame."""
        if self.env.render_mode != "rgb_array":
            raise ValueError(f"its env was made with render_mode={self.env.render_mode!r}, not 'rgb_array'")
        frame = np.asarray(self.env.render())
        if frame.shape != (size, size, 3):
            raise ValueError(f"its env draws frames of shape {frame.shape}, not {(size, size, 3)}")
        return frame.astype(np.uint8, copy=False)


@dataclass(frozen=True)
class Subtask:
    """One of a task's subtasks, as MimicGen's task config names them: its name, the object frame each arm's
    motion is relative to (task.replay.arms order; names of task.frame_pose), the signal (task.signals) whose
    rise ends it (None: it runs to the source's end), whether it is entered by interpolation from where
    the arms are (bridge), and, per arm, a frame the arm's frame slides onto over the subtask (onto;
    None: it stays put). Every arm moves through every subtask in step (a coordination subtask is one
    whose frames all agree)."""

    name: str
    frames: tuple[str, ...]
    ends: str | None = None
    bridge: bool = True
    onto: tuple[str | None, ...] | None = None


class ActionKind(abc.ABC):
    """How a task's action becomes a world-frame target per arm and back (a ReplaySpec's `action`). The
    engine re-expresses the targets in new object frames and asks for the action that follows them. Our
    kinds: VelocityCommand, PositionTarget, PoseTarget, DeltaCommand; a task whose action is none of these
    (joint targets through inverse kinematics: datagen/tasks/aloha_transfer_cube.py) writes its own."""

    @abc.abstractmethod
    def to_target(self, task: Task, states, actions) -> dict:
        """A source's frames (states (T, obs_dim), actions (T, act_dim)) as world-frame targets, per arm:
        {arm: (waypoints (T, d), velocities (T, d) or None, gripper commands (T,) or None[, orientations
        (T, 3, 3)])}: planar, d = 2 and no orientation; in SE(3), d = 3 and the orientations of the arm's
        frame (a position-controlled arm gives velocities None). The gripper rides along."""

    @abc.abstractmethod
    def to_action(self, task: Task, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        """The action ((act_dim,) float32) that takes each arm from where `obs` shows it towards its
        `waypoints[arm]` ((d,)) moving at `velocities[arm]` ((d,) or None), turned to `orientations[arm]`
        ((3, 3); None for a planar task), with `grips[arm]` (None: no grippers) its gripper command."""


def _grip(actions, grips: dict, arm: str):
    return actions[:, grips[arm]] if arm in grips else None


@dataclass(frozen=True)
class VelocityCommand(ActionKind):
    """Each arm's action is its point's velocity (length unit / s) in `columns[arm]` (our PushT and ALOHA):
    a source's waypoints are where the point was, its velocities what was commanded; a replayed step
    commands the segment's velocity plus `gain` times the waypoint error, clipped to +-limit. Gripper
    commands (grips[arm]: a column of the action) ride along."""

    columns: dict[str, slice]  # {arm: its velocity's columns of the action}
    gain: float  # 1/s: velocity added per length unit of waypoint error
    limit: float  # |action| at most this, per number (the env's clip)
    grips: dict[str, int] = field(default_factory=dict)  # {arm: its gripper command's column}

    def to_target(self, task, states, actions) -> dict:
        arms = task.replay.arms
        return {
            arm: (states[:, arms[arm]], actions[:, c], _grip(actions, self.grips, arm))
            for arm, c in self.columns.items()
        }

    def to_action(self, task, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        a = np.zeros(task.spec.act_dim)
        for arm, cols in self.columns.items():
            here = np.asarray(obs[task.replay.arms[arm]], np.float64)
            a[cols] = velocities[arm] + self.gain * (waypoints[arm] - here)  # track the waypoint
            if arm in self.grips:
                a[self.grips[arm]] = grips[arm]
        return np.clip(a, -self.limit, self.limit).astype(np.float32)


@dataclass(frozen=True)
class PositionTarget(ActionKind):
    """Each arm's action is its point's position target in `columns[arm]` (gym-pusht's agent): a source's
    waypoints are its targets (velocities zero), a replayed step sends the re-expressed target, clipped to
    [low, high]."""

    columns: dict[str, slice]  # {arm: its target's columns of the action}
    low: float = -math.inf
    high: float = math.inf

    def to_target(self, task, states, actions) -> dict:
        return {
            arm: (actions[:, c], np.zeros((len(actions), c.stop - c.start)), None)
            for arm, c in self.columns.items()
        }

    def to_action(self, task, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        a = np.zeros(task.spec.act_dim)
        for arm, cols in self.columns.items():
            a[cols] = waypoints[arm]
        return np.clip(a, self.low, self.high).astype(np.float32)


@dataclass(frozen=True)
class PoseTarget(ActionKind):
    """Each arm's action is its frame's pose target (Pusher's hand, through the robot's controller): in
    `columns[arm]`, a position (3) then an orientation quaternion (w, x, y, z), world frame. A replayed
    step sends the re-expressed pose as it is."""

    columns: dict[str, slice]  # {arm: its 7 columns of the action}

    def to_target(self, task, states, actions) -> dict:
        a = np.asarray(actions, np.float64)
        out = {}
        for arm, c in self.columns.items():
            pose = a[:, c]
            out[arm] = (pose[:, :3], None, None, rotations_of(pose[:, 3:7]))
        return out

    def to_action(self, task, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        a = np.zeros(task.spec.act_dim)
        for arm, cols in self.columns.items():
            a[cols] = np.r_[waypoints[arm], quat_of(orientations[arm])]
        return a.astype(np.float32)


@dataclass(frozen=True)
class DeltaCommand(ActionKind):
    """Each arm's action is a step of its point's position target, taken from where the point is now, as
    MimicGen's OSC delta pose and a mocap move take it: target = point + scale * action[columns[arm]]
    (`scale` length units per action unit). A source's waypoints are where each arm's point was at each
    frame, its velocity the step the source commanded there, per second; a replayed step is the step that
    takes the point from where it is now to its waypoint and on by that velocity, clipped to +-limit, so
    at zero perturbation each step is the source's own. Gripper commands (grips[arm]) ride along.
    Orientation steps are not covered: an arm that turns gives its own kind."""

    columns: dict[str, slice]  # {arm: its step's columns of the action}
    scale: float = 1.0  # length units per action unit
    limit: float = 1.0  # |action| at most this, per number (the env's clip)
    grips: dict[str, int] = field(default_factory=dict)  # {arm: its gripper command's column}

    def to_target(self, task, states, actions) -> dict:
        states, actions = np.asarray(states, np.float64), np.asarray(actions, np.float64)
        per_second, arms = self.scale * task.spec.fps, task.replay.arms
        return {
            arm: (states[:, arms[arm]], per_second * actions[:, c], _grip(actions, self.grips, arm))
            for arm, c in self.columns.items()
        }

    def to_action(self, task, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        action = np.zeros(task.spec.act_dim)
        here, fps = np.asarray(obs, np.float64), task.spec.fps
        for arm, cols in self.columns.items():
            gap = (
                np.asarray(waypoints[arm], np.float64) - here[task.replay.arms[arm]]
            )  # to where it should be
            action[cols] = (gap + np.asarray(velocities[arm], np.float64) / fps) / self.scale
            if arm in self.grips and grips is not None:
                action[self.grips[arm]] = grips[arm]
        return np.clip(action, -self.limit, self.limit).astype(np.float32)


@dataclass(frozen=True)
class ReplaySpec:
    """How the engine replays a task's sources (modes "replay" and "replay_live": datagen.replay), in one
    place, as MimicGen's task_spec: lengths are the task's unit (PushT's and ALOHA's m, gym-pusht's px),
    angles rad, times s. A task sets replay = ReplaySpec(...), or None where it cannot replay."""

    arms: dict[str, slice]  # {arm: the columns of its controlled point's position in an observation}
    action: ActionKind  # how an action becomes each arm's world-frame target and back
    # in order, the last one running to the source's end; by default one, every arm relative to the object
    subtasks: tuple[Subtask, ...] = (Subtask("whole", ("object",)),)
    reach: dict[str, tuple] = field(default_factory=dict)  # {arm: ((low, high) per axis)}: a box (none: all)
    bridge_speed: float | None = None  # length unit / s: a bridge's top speed (None: the source's own)
    bridge_tol: float = 0.0  # length unit: arms this close to their first waypoints are not bridged
    bridge_moves: tuple[float, float] | None = None  # (length, rad): a bridge moving the object more hit it
    bridge_turn_speed: float | None = None  # rad/s: a bridge's top turning speed (None: turns don't count)
    hold_steps: int = 0  # steps the arms hold still after the plan, for a success that must be held
    # (length, rad): mode "replay_live" re-expresses the rest of a segment from the object frames' live poses
    # once one lies farther than this from where the re-expressed segment expects it (datagen.replay). The
    # default, 2 mm and 0.02 rad for a task in metres, is bridge_moves' "the object moved": contact jitter
    # stays below it, so a segment that tracks is left as it was
    follow_tol: tuple[float, float] = (0.002, 0.02)
    # Task.signals reads the env's physics: a source is re-simulated to cut it (False: an observation alone
    # shows the signals, and a source's recorded frames are read)
    resimulate: bool = True

    def __post_init__(self):
        object.__setattr__(self, "subtasks", tuple(self.subtasks))

    def in_reach(self, arm: str, points) -> np.ndarray:
        """(T,) bool: which of `points` ((T, d) positions) `arm` can reach: its `reach` box."""
        pts = np.asarray(points)
        inside = np.ones(len(pts), bool)
        for axis, (lo, hi) in enumerate(self.reach.get(arm, ())):
            inside &= (pts[:, axis] >= lo) & (pts[:, axis] <= hi)
        return inside


@dataclass(frozen=True)
class ExpertSpec:
    """A task's scripted expert (a task's `expert`; None: it only replays): the demo generators roll it out
    (gen_demos.py) and mode "resolve" re-solves a perturbed start with it, noise-free."""

    cls: type  # cls(noise=std, seed=int) with reset() and act(obs) -> (act_dim,) action
    noise: float = 0.0  # its action noise in the task's demo sets (std, in noise_unit)
    noise_unit: str = "m/s"  # the unit of that noise: its actions' (gen_demos.py --noise)
    # lockstep's copy over a batch: batch() has act_batch(obs (N, obs_dim)) -> (N, act_dim), each row bit for
    # bit cls(noise=0.0).act of that row; None: mode "resolve" runs one expert per lane
    batch: type | None = None
    generator: str | None = None  # the command that makes a source set (None: gen_demos.py --task NAME)


REQUIRED_ATTRIBUTES = ("name", "spec", "start_names", "replay")  # besides Task's abstract methods


class Task(abc.ABC):
    """The contract between the engine and a task, in MimicGen's division of work: the task describes,
    the engine runs (the modes, the one replay: datagen.replay, lockstep, shards, resume, report, merge).

    Required (REQUIRED_ATTRIBUTES and the abstract methods: eight names, checked when the task registers):
    name, spec, start_names, replay; make_env, start_of, perturb, object_pose. Everything else has a
    default. Units are the task's own (PushT's and ALOHA's metres, gym-pusht's pixels; angles in rad, times
    in s), each attribute saying which; an observation is the env's (obs_dim,) float32 vector, an action
    its (act_dim,) float32 vector."""

    # ---- what the task is ----
    name: str  # "pusht": its key in known_tasks(), recorded in a run's settings and its sets
    spec: EnvSpec  # its env and what its sets record (EnvSpec.of(pusht_env), or an EnvSpec(...) of its own)
    start_names: tuple[str, ...]  # a start's numbers, in place()'s order (stored as aug.start)
    replay: ReplaySpec | None  # how its sources are replayed (MimicGen's task_spec); None: it only re-solves
    expert: ExpertSpec | None = None  # its scripted expert; None: it only replays

    @property
    def title(self) -> str:
        """How messages name the task ("PushT"); by default its name."""
        return self.name

    @property
    def default_noise(self) -> float:
        """The expert's action noise in the task's demo sets (expert.noise; 0 without an expert)."""
        return 0.0 if self.expert is None else self.expert.noise

    @abc.abstractmethod
    def make_env(self, share=None):
        """A new simulator of this task: step(action) -> (obs, reward, done, info["success"]) and
        set_start(*start) -> obs (see place); GymnasiumEnv makes one of a Gymnasium env. share: an env of
        this task whose compiled model (and, where the env can, its MjData) the new one may share; every
        env keeps its own state (lockstep's lanes)."""

    @abc.abstractmethod
    def start_of(self, state) -> tuple:
        """The start (start_names' values) an observation shows: place(env, start_of(obs)) puts the env
        where obs was."""

    @abc.abstractmethod
    def perturb(self, first_state, rng, how: Perturbation):
        """A start near a source's first observation: start_names' values drawn from `rng` alone with
        how.pos_sigma and how.yaw_sigma (the task's length unit, rad); None when no valid draw was found
        ("no_valid_start")."""

    def place(self, env, start):
        """Put `env` at `start` with fresh counters, fully (nothing of an earlier attempt may survive);
        returns the first observation. By default the env's own set_start(*start)."""
        return env.set_start(*start)

    def success(self, env) -> bool:
        """Whether `env` reports the task done: by default its latched `success` (GymnasiumEnv latches the
        info key its success_key names, "is_success" by default)."""
        return bool(env.success)

    def state_problem(self, states) -> tuple[int, str] | None:
        """None if every observation of a source (N, obs_dim) is one the task's env can be in, else (the
        first row that is not, what is wrong with it). spec.state_ranges checks each number alone; a task
        whose observation holds numbers that belong together checks them here (gym-pusht: its 8 keypoints
        must be a rigid placement of the T), so that nothing is grown from a state no env was ever in."""
        return None

    # ---- what replay reads (datagen.replay), beside the ReplaySpec ----
    # Poses live in SE(3) (datagen.poses): a frame is a (4, 4) pose, an arm's target a position (3,), an
    # orientation (3, 3) and its gripper command. A planar task (a robot on a table) gives its frames as
    # (x, y, yaw) triples and its targets as (x, y) points without orientation: the special case.
    @abc.abstractmethod
    def object_pose(self, state):
        """The pose of the object the task is about, read from an observation: (x, y, yaw) for a planar
        task, a (4, 4) matrix in SE(3) (datagen.poses)."""

    def frame_pose(self, frame: str, state):
        """The pose of the object frame named `frame` (a name in replay.subtasks' frames) in an
        observation, as object_pose gives one; by default every frame is the object's."""
        return self.object_pose(state)

    def start_distance(self, a, b) -> float:
        """How far apart two starts lie (nearest source selection); by default the Euclidean distance of
        their numbers."""
        return math.dist(a, b)

    def signals(self, obs, env) -> dict[str, bool]:
        """{signal: on} for every name in replay.subtasks' ends (MimicGen's subtask termination signals),
        in the observation `obs` of `env`, read after every step of a replay. A task whose signals the
        observation alone shows sets replay.resimulate = False (env is then None when a source is cut: its
        recorded frames are read); otherwise a source is re-simulated to read them."""
        return {}

    def arm_pose(self, arm: str, obs, env) -> tuple[np.ndarray, np.ndarray | None]:
        """Where `arm` is in the observation `obs` of `env`: (position (d,), orientation (3, 3) or None).
        By default its replay.arms columns of obs, no orientation (a planar point); an arm whose
        orientation the observation does not show reads it from env (a bridge starts from it)."""
        return np.asarray(obs[self.replay.arms[arm]], np.float64), None

    def frame_columns(self, states, actions) -> dict[str, np.ndarray]:
        """spec.frame_features' columns ((T, d) float32 each) of an episode's frames (states (T, obs_dim),
        actions (T, act_dim)): written beside them in its demo sets and in the engine's; none by default."""
        return {}

    def step_batch(self, envs, actions):
        """lockstep's: envs[i] stepped with actions[i]: (obs (N, obs_dim), success (N,) bool, done (N,)
        bool), bit for bit env.step per env (what this default does)."""
        return step_each(envs, actions)


def failures_of(task: Task) -> dict[str, tuple[str, ...]]:
    """{mode: every reason an attempt of that mode can return}: a task without an expert only replays, one
    without a ReplaySpec only re-solves. Replay's, in the order datagen.replay checks them: a waypoint
    beyond reach, a bridge that moved the object (for a task with bridge_moves), each subtask's end signal
    that never came on, and the rest."""
    resolve = {"resolve": ("expert_failed", "no_valid_start")} if task.expert is not None else {}
    spec = task.replay
    if spec is None:
        return resolve
    blocked = ("approach_blocked",) if spec.bridge_moves is not None else ()
    missed = tuple(f"{s.ends}_missed" for s in spec.subtasks if s.ends)
    tail = ("out_of_time", "finished_off_target", "source_not_split", "no_valid_start")
    replay = ("path_out_of_reach",) + blocked + missed + tail
    return resolve | {"replay": replay, "replay_live": replay}


def modes_of(task: Task) -> tuple[str, ...]:
    """The modes a task can be grown in (failures_of's keys)."""
    return tuple(failures_of(task))


def owed(task: Task, member: str, value, *shapes: tuple[int, ...]):
    """`value`, what the task's `member` returned, when it has one of `shapes` and only finite numbers;
    else DataError, one line naming the member, the shape it gave and the one it owes: a user's task that
    returns a NaN or the wrong shape is refused before anything is simulated or written from it."""
    from ch37.errors import DataError

    who = f"task {task.name!r}: {type(task).__name__}.{member}"
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(f"{who} returned {type(value).__name__} {value!r:.80}, not numbers") from None
    if arr.shape not in shapes:
        owes = " or ".join(str(s) for s in shapes)
        raise DataError(f"{who} returned shape {arr.shape}; it owes {owes}")
    if not np.isfinite(arr).all():
        i = int(np.argmin(np.isfinite(arr).reshape(-1)))
        raise DataError(f"{who} returned a non-finite number ({arr.reshape(-1)[i]} at flat index {i})")
    return value


POSE_SHAPES = ((3,), (4, 4))  # a planar (x, y, yaw) or an SE(3) matrix (datagen.poses)


# ---- the tasks the engine knows: each registers itself when its module is imported ----
_REGISTERED: dict[str, Task] = {}


def _file_of(module: str) -> str:
    """How a message names a module: its path from the project's root (datagen/tasks/pusht.py) where it
    lies there, else its file's name."""
    f, root = Path(sys.modules[module].__file__).resolve(), Path(__file__).resolve().parent.parent
    return f.relative_to(root).as_posix() if f.is_relative_to(root) else f.name


def contract_problem(task: Task) -> str | None:
    """None if `task` holds the contract's required attributes, its groups are of their types and its
    subtasks fit its arms, else what is missing or wrong, in words."""
    missing = [a for a in REQUIRED_ATTRIBUTES if not hasattr(task, a)]
    if missing:
        plural = "s" * (len(missing) > 1)
        return f"misses the required attribute{plural} {', '.join(missing)} (datagen.task.Task)"
    for member, kind, none in (
        ("spec", EnvSpec, False),
        ("replay", ReplaySpec, True),
        ("expert", ExpertSpec, True),
    ):
        value = getattr(task, member)
        if not isinstance(value, kind) and not (none and value is None):
            give = ("an " if kind.__name__[0] in "AEIOU" else "a ") + kind.__name__ + " or None" * none
            return f"has a {member} of type {type(value).__name__}: give {give} (datagen.task)"
    if task.replay is None:
        return None
    arms = task.replay.arms
    if not isinstance(task.replay.action, ActionKind):
        kind = type(task.replay.action).__name__
        return f"has a replay.action of type {kind}: give an ActionKind (datagen.task)"
    for sub in task.replay.subtasks:
        if len(sub.frames) != len(arms):
            return (
                f"has subtask {sub.name!r} with {len(sub.frames)} frame(s) for {len(arms)} arm(s) "
                f"({', '.join(arms)}): give each arm its frame"
            )
    return None


def register(task: Task) -> Task:
    """Make `task` known to the engine under task.name; a task module calls it as it is imported
    (PUSHT = register(PushT())), as MimicGen's env interfaces register through their metaclass. A task
    that misses a required member (REQUIRED_ATTRIBUTES; an abstract method already stops its
    class from being made) or whose subtasks do not name one frame per arm is refused in one line."""
    if problem := contract_problem(task):
        raise TypeError(f"{_file_of(type(task).__module__)}: {type(task).__name__} {problem}")
    old = _REGISTERED.setdefault(task.name, task)
    if old is not task and type(old) is not type(task):
        first, second = (_file_of(type(t).__module__) for t in (old, task))
        raise ValueError(
            f"{second} names its task {task.name!r}, as {first} does; give one of them another name"
        )
    return old


@functools.cache  # once per process (a forked worker inherits it): a module that failed is not re-run
def _import_modules() -> dict[str, str]:
    """Import every module of datagen/tasks, so that each task module registers its task; {file: why} for
    each that fails to import, and one warning line for each on stderr. A module that raises as it is
    imported (one half written, or a copy of another task's module that still bears its name) makes its
    own tasks unavailable, not the others."""
    failed = {}
    folder = Path(__file__).parent / "tasks"  # datagen/tasks: one module per task, with its expert
    for m in pkgutil.iter_modules([str(folder)]):
        name = f"{__package__}.tasks.{m.name}"
        try:
            importlib.import_module(name)
        except Exception as e:  # whatever a module raises, the others' tasks stay known
            file = str(folder / f"{m.name}.py")
            lines = [f.lineno for f in traceback.extract_tb(e.__traceback__) if f.filename == file]
            line = getattr(e, "lineno", None) if isinstance(e, SyntaxError) else lines[-1] if lines else None
            where = f"{__package__}/tasks/{m.name}.py" + (f" (line {line})" if line else "")
            failed[where] = f"{type(e).__name__}: {' '.join(str(e).split())}"
            print(f"warning: {where} was not loaded, its tasks unavailable: {failed[where]}", file=sys.stderr)
    return failed


def known_tasks() -> dict[str, Task]:
    """{name: task} of every task the engine knows, by name. Every module of this package is imported
    first, so a task module found here registers itself: a new task is one module in datagen/tasks/, listed
    nowhere else. A module that fails to import is one warning line, its tasks left out."""
    _import_modules()
    return dict(sorted(_REGISTERED.items()))
