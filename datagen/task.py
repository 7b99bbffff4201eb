"""What a task gives the data engine: MimicGen's env interface, made small.

The engine (datagen.engine: one attempt in either mode; datagen.replay: the one replay; datagen.lockstep;
datagen.run: a run, its shards, resume, report and merge) knows no task. Everything about one task lives in
one module named for it (datagen/tasks/pusht.py, datagen/tasks/aloha.py), and only that module (and the
engine's bit-identical fast copies, datagen/tasks/fast_*.py) imports its env and its expert. A task is an
instance of a Task subclass that its module registers as it is imported (TASK = register(MyTask())):
known_tasks() finds it, no list names it, and the digests that guard resumed shards and cached demo sets read
its code from what the run imported.

In MimicGen's division of work, a task only describes (Task below, an abstract base: ten required
members, each attribute and method with its inputs, outputs and units; everything else a default):

    required             name, spec (an EnvSpec: its env, what its sets record), start_names, arms;
                         make_env (our envs, or a Gymnasium env through GymnasiumEnv), start_of (the start an
                         observation shows), perturb (a start near a source's first observation),
                         object_pose, action_to_target and target_to_action (how an action becomes a
                         world-frame target and back: a velocity command, a position target, a pose
                         target through the robot's controller)
    its env (defaults)   place (env.set_start), success (env.success), max_steps (the spec's), the
                         ranges of its states and actions, state_problem
    its robot            reach (in_reach), arm_pose (where an observation does not show the hand's
                         orientation), bridge_speed, bridge_tol, bridge_turn_speed, hold_steps
    its objects          frame_pose (the object frames its subtasks live in), start_distance, follow_tol
    its subtasks         subtasks (per arm, the frame each lives in; the signal that ends it; whether
                         it is entered by interpolation), signals (the env's subtask-end signals)
    its expert           expert_class (optional: a task without one only replays; the demo generators
                         roll it out with default_noise), batch_expert (optional)

Poses are SE(3) (datagen.poses); a planar task's (x, y, yaw) frames and (x, y) points are the special case.
python -m datagen.check TASK runs what a task must satisfy before a long run.

and the engine does the rest: the modes ("resolve": perturb, the expert re-solves, keep on success;
"replay": perturb, the source's subtasks re-expressed in the new object frames and executed, keep on
success: datagen.replay; "replay_live": the same, re-expressed again from the objects' live poses once
they drift beyond follow_tol), lockstep, shards, resume, report and merge.
"""

from __future__ import annotations

import abc
import functools
import importlib
import math
import pkgutil
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ch37.parallel import step_each

__all__ = [
    "DeltaCommand",
    "EnvSpec",
    "GymnasiumEnv",
    "Outcome",
    "Perturbation",
    "Source",
    "Subtask",
    "Task",
    "ended",
    "known_tasks",
    "contract_problem",
    "owed",
    "register",
]


@dataclass(frozen=True)
class EnvSpec:
    """What a task's env is and what its LeRobot sets record, in one typed place (a task's `spec`).
    EnvSpec.of(module) reads an env module's constants (pusht_env, aloha_env: STATE_NAMES, ACTION_NAMES,
    ENV_STATE_NAMES, FPS, ROBOT_TYPE, TASK, MAX_STEPS, and OBS_NAMES where it has them)."""

    state_names: tuple[str, ...]  # observation.state's entries, in order
    action_names: tuple[str, ...]  # action's entries, in order
    fps: int  # control steps per second: the set's fps
    robot_type: str  # the set's robot_type (meta/info.json)
    task: str  # the set's one task, in words
    max_steps: int  # the env's episode limit, in control steps
    env_state_names: tuple[str, ...] = ()  # observation.environment_state's entries: names of state_names
    # entries (our envs: the objects' share of the state), or, with obs_names, the entries the observation
    # vector holds beside state_names (lerobot/pusht_keypoints' keypoints)
    obs_names: tuple[str, ...] = ()  # the env's observation vector where it is more than observation.state

    def __post_init__(self):
        for name in ("state_names", "action_names", "env_state_names", "obs_names"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not self.state_names or not self.action_names:
            raise TypeError("an EnvSpec needs state_names and action_names")
        if int(self.fps) <= 0 or int(self.max_steps) <= 0:
            raise TypeError(
                f"an EnvSpec's fps and max_steps must be positive, not {self.fps}, {self.max_steps}"
            )

    @property
    def obs_dim(self) -> int:
        """Entries of the env's observation vector."""
        return len(self.obs_names or self.state_names)

    @property
    def act_dim(self) -> int:
        return len(self.action_names)

    @classmethod
    def of(cls, module) -> EnvSpec:
        """The spec an env module's constants say; a missing one is a TypeError naming it."""
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
    (the last step's: what a set's next.reward records, Task.records_reward), render(size) (--video's
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
    motion is relative to (task.arms order; names of task.frame_pose), the signal (task.signals) whose
    rise ends it (None: it runs to the source's end), whether it is entered by interpolation from where
    the arms are (bridge), and, per arm, a frame the arm's frame slides onto over the subtask (onto;
    None: it stays put). Every arm moves through every subtask in step (a coordination subtask is one
    whose frames all agree)."""

    name: str
    frames: tuple[str, ...]
    ends: str | None = None
    bridge: bool = True
    onto: tuple[str | None, ...] | None = None


class Task(abc.ABC):
    """The contract between the engine and a task, in MimicGen's division of work: the task describes,
    the engine runs (the modes, the one replay: datagen.replay, lockstep, shards, resume, report, merge).

    Required (REQUIRED_ATTRIBUTES and the abstract methods: ten names, checked when the task registers):
    name, spec, start_names, arms; make_env, start_of, perturb, object_pose, action_to_target,
    target_to_action. Everything else has a default. Units are the task's own (PushT's and ALOHA's
    metres, gym-pusht's pixels; angles in rad, times in s), each attribute saying which; an observation
    is the env's (obs_dim,) float32 vector, an action its (act_dim,) float32 vector."""

    REQUIRED_ATTRIBUTES = ("name", "spec", "start_names", "arms")

    # ---- what the task is ----
    name: str  # "pusht": its key in known_tasks(), recorded in a run's settings
    spec: EnvSpec  # its env and what its sets record (EnvSpec.of(pusht_env), or an EnvSpec(...) of its own)
    start_names: tuple[str, ...]  # a start's numbers, in place()'s order (stored as aug.start)
    state_ranges: dict[str, tuple[float, float]] = {}  # {state name: (low, high)}: a source outside: refused
    action_ranges: dict[str, tuple[float, float]] = {}  # {action name: (low, high)}: the clip range
    expert_class: type | None = None  # its scripted expert: expert_class(noise=std, seed=int); optional
    default_noise: float = 0.0  # the expert's action noise (std, in noise_unit) in the task's demo sets
    noise_unit: str = "m/s"  # the unit of the expert's noise: its actions' (gen_demos.py --noise)
    # the third-party packages whose versions can change its frames (its simulator), named in the digest
    # of its demo sets (datagen.demos) and in every shard's stamp (datagen.plan.versions)
    packages: tuple[str, ...] = ("mujoco",)
    # its sets carry next.reward (the env's reward, float32) and next.done (the env ended the episode there)
    # beside next.success, as the hub's sets of its env do (lerobot/pusht_keypoints); the env keeps its last
    # step's reward as env.reward (GymnasiumEnv does)
    records_reward: bool = False
    # LeRobot features of per-frame columns its sets carry beyond state, action and success (the ALOHA
    # transfer-cube's end-effector targets), each computed from an episode's frames by frame_columns
    frame_features: dict[str, dict] = {}

    @property
    def title(self) -> str:
        """How messages name the task ("PushT"); by default its name."""
        return self.name

    @property
    def generator(self) -> str:
        """The command that makes a source set of this task; by default gen_demos.py's."""
        return f"gen_demos.py --task {self.name}"

    @property
    def max_steps(self) -> int:
        """Control steps an episode may last: the env's limit (spec.max_steps by default)."""
        return int(self.spec.max_steps)

    # ---- what replay reads (datagen.replay) ----
    # Poses live in SE(3) (datagen.poses): a frame is a (4, 4) pose, an arm's target a position (3,), an
    # orientation (3, 3) and its gripper command. A planar task (a robot on a table) gives its frames as
    # (x, y, yaw) triples and its targets as (x, y) points without orientation: the special case.
    arms: dict[str, slice]  # {arm: the columns of its controlled point's position in an observation}
    reach: dict[str, tuple] = {}  # {arm: ((low, high) per axis of its point)}: a box it can reach (none: all)
    # in order, the last one running to the source's end; by default one, every arm relative to the object
    subtasks: tuple[Subtask, ...] = (Subtask("whole", ("object",)),)
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

    def expert(self):
        """The noise-free expert that re-solves a placed start (mode "resolve"): reset() and act(obs) ->
        action; None: the task has no expert, and only replays."""
        return None if self.expert_class is None else self.expert_class(noise=0.0)

    def success(self, env) -> bool:
        """Whether `env` reports the task done: by default its latched `success`."""
        return bool(env.success)

    def state_problem(self, states) -> tuple[int, str] | None:
        """None if every observation of a source (N, obs_dim) is one the task's env can be in, else (the
        first row that is not, what is wrong with it). state_ranges checks each number alone; a task whose
        observation holds numbers that belong together checks them here (gym-pusht: its 8 keypoints must
        be a rigid placement of the T), so that nothing is grown from a state no env was ever in."""
        return None

    @abc.abstractmethod
    def object_pose(self, state):
        """The pose of the object the task is about, read from an observation: (x, y, yaw) for a planar
        task, a (4, 4) matrix in SE(3) (datagen.poses)."""

    def frame_pose(self, frame: str, state):
        """The pose of the object frame named `frame` (a name in subtasks' frames) in an observation, as
        object_pose gives one; by default every frame is the object's."""
        return self.object_pose(state)

    def start_distance(self, a, b) -> float:
        """How far apart two starts lie (nearest source selection); by default the Euclidean distance of
        their numbers."""
        return math.dist(a, b)

    resimulate: bool = True  # signals() reads the env's physics: a source is re-simulated to read them

    def signals(self, obs, env) -> dict[str, bool]:
        """{signal: on} for every name in subtasks' ends (MimicGen's subtask termination signals), in the
        observation `obs` of `env`, read after every step of a replay. A task whose signals the
        observation alone shows sets resimulate = False (env is then None when a source is cut: its
        recorded frames are read); otherwise a source is re-simulated to read them."""
        return {}

    def arm_pose(self, arm: str, obs, env) -> tuple[np.ndarray, np.ndarray | None]:
        """Where `arm` is in the observation `obs` of `env`: (position (d,), orientation (3, 3) or None).
        By default its `arms` columns of obs, no orientation (a planar point); an arm whose orientation
        the observation does not show reads it from env (a bridge starts from it)."""
        return np.asarray(obs[self.arms[arm]], np.float64), None

    def in_reach(self, arm: str, points) -> np.ndarray:
        """(T,) bool: which of `points` ((T, d) positions) `arm` can reach; by default its `reach` box."""
        pts = np.asarray(points)
        inside = np.ones(len(pts), bool)
        for axis, (lo, hi) in enumerate(self.reach.get(arm, ())):
            inside &= (pts[:, axis] >= lo) & (pts[:, axis] <= hi)
        return inside

    @abc.abstractmethod
    def action_to_target(self, states, actions) -> dict:
        """A source's frames (states (T, obs_dim), actions (T, act_dim)) as world-frame targets, per arm:
        {arm: (waypoints (T, d), velocities (T, d) or None, gripper commands (T,) or None[, orientations
        (T, 3, 3)])}: planar, d = 2 and no orientation; in SE(3), d = 3 and the orientations of the arm's
        frame (a position-controlled arm gives velocities None). The engine re-expresses waypoints,
        velocities and orientations in a new object frame; the gripper rides along."""

    @abc.abstractmethod
    def target_to_action(
        self, obs, waypoints: dict, velocities: dict, grips: dict | None, orientations: dict | None = None
    ) -> np.ndarray:
        """The action ((act_dim,) float32) that takes each arm from where `obs` shows it towards its
        `waypoints[arm]` ((d,)) moving at `velocities[arm]` ((d,) or None), turned to `orientations[arm]`
        ((3, 3); None for a planar task), with `grips[arm]` its gripper command: a velocity command for
        our two robots, a position target for a robot that takes one, torques through the robot's own
        controller for one driven by torques (datagen/tasks/pusher.py)."""

    def frame_columns(self, states, actions) -> dict[str, np.ndarray]:
        """frame_features' columns ((T, d) float32 each) of an episode's frames (states (T, obs_dim),
        actions (T, act_dim)): written beside them in its demo sets and in the engine's; none by default."""
        return {}

    # ---- what lockstep needs; each default runs the same bytes one attempt (or one env) at a time ----
    def batch_expert(self):
        """expert() over a batch, obs (N, obs_dim) float32 -> actions (N, act_dim) float32, each row bit for
        bit expert().act of that row; None: mode "resolve" is run one attempt at a time."""
        return None

    def step_batch(self, envs, actions):
        """envs[i] stepped with actions[i]: (obs (N, obs_dim), success (N,) bool, done (N,) bool), bit for
        bit env.step per env (what this default does)."""
        return step_each(envs, actions)

    @property
    def obs_names(self) -> tuple[str, ...]:
        """The names of the observation vector's entries: spec.obs_names where the env's observation holds
        more than a set's observation.state (its env_state_names beside it, as lerobot/pusht_keypoints
        records them), else spec.state_names."""
        return self.spec.obs_names or self.spec.state_names

    @property
    def failures(self) -> dict[str, tuple[str, ...]]:
        """{mode: every reason an attempt of that mode can return}; a task without an expert only replays.
        Replay's, in the order datagen.replay checks them: a waypoint beyond reach, a bridge that moved the
        object (for a task with bridge_moves), each subtask's end signal that never came on, and the rest."""
        resolve = {"resolve": ("expert_failed", "no_valid_start")} if self.expert_class is not None else {}
        blocked = ("approach_blocked",) if self.bridge_moves is not None else ()
        missed = tuple(f"{s.ends}_missed" for s in self.subtasks if s.ends)
        tail = ("out_of_time", "finished_off_target", "source_not_split", "no_valid_start")
        replay = ("path_out_of_reach",) + blocked + missed + tail
        return resolve | {"replay": replay, "replay_live": replay}

    @property
    def modes(self) -> tuple[str, ...]:
        return tuple(self.failures)


class DeltaCommand:
    """An action kind, mixed into a Task (class MyTask(DeltaCommand, Task)): each arm's action is a step of
    its point's position target, taken from where the point is now, as MimicGen's OSC delta pose and a
    mocap move take it: target = point + scale * action[delta_columns[arm]] (`scale` length units per
    action unit). It gives action_to_target (a source's waypoints: where each arm's point was at each
    frame, and its velocity: the step the source commanded there, per second) and target_to_action (the
    step that takes the point from where it is now to its waypoint and on by that velocity, clipped to
    action_limit), so a delta-command arm writes no encoding of its own; at zero perturbation each step is
    the source's own. Gripper columns (grip_columns[arm], optional) ride along as commands. Orientation
    deltas are not covered: an arm that turns gives its own pair."""

    delta_columns: dict[str, slice]  # {arm: its step's columns of the action}
    grip_columns: dict[str, int] = {}  # {arm: its gripper command's column of the action}
    scale: float = 1.0  # length units per action unit
    action_limit: float = 1.0  # |action| at most this, per number (the env's clip)

    def action_to_target(self, states, actions) -> dict:
        states, actions = np.asarray(states, np.float64), np.asarray(actions, np.float64)
        per_second = self.scale * self.spec.fps
        out = {}
        for arm, cols in self.delta_columns.items():
            grip = actions[:, self.grip_columns[arm]] if arm in self.grip_columns else None
            out[arm] = (states[:, self.arms[arm]], per_second * actions[:, cols], grip)
        return out

    def target_to_action(self, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        action = np.zeros(self.spec.act_dim)
        here, fps = np.asarray(obs, np.float64), self.spec.fps
        for arm, cols in self.delta_columns.items():
            gap = np.asarray(waypoints[arm], np.float64) - here[self.arms[arm]]  # to where it should be
            action[cols] = (gap + np.asarray(velocities[arm], np.float64) / fps) / self.scale
            if arm in self.grip_columns and grips is not None:
                action[self.grip_columns[arm]] = grips[arm]
        return np.clip(action, -self.action_limit, self.action_limit).astype(np.float32)


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
    """None if `task` holds the contract's required attributes and its subtasks fit its arms, else what
    is missing or wrong, in words."""
    missing = [a for a in Task.REQUIRED_ATTRIBUTES if not hasattr(task, a)]
    if missing:
        plural = "s" * (len(missing) > 1)
        return f"misses the required attribute{plural} {', '.join(missing)} (datagen.task.Task)"
    if not isinstance(task.spec, EnvSpec):
        return f"has a spec of type {type(task.spec).__name__}: give an EnvSpec (datagen.task.EnvSpec)"
    for sub in task.subtasks:
        if len(sub.frames) != len(task.arms):
            return (
                f"has subtask {sub.name!r} with {len(sub.frames)} frame(s) for {len(task.arms)} arm(s) "
                f"({', '.join(task.arms)}): give each arm its frame"
            )
    return None


def register(task: Task) -> Task:
    """Make `task` known to the engine under task.name; a task module calls it as it is imported
    (PUSHT = register(PushT())), as MimicGen's env interfaces register through their metaclass. A task
    that misses a required member (Task.REQUIRED_ATTRIBUTES; an abstract method already stops its
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
