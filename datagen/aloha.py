"""The ALOHA cube handoff as a data-engine task (datagen.task.Task; ALOHA below): perturb a source
start, re-solve it, or replay it the MimicGen way, subtask by subtask. The only engine module that
imports aloha_env and its expert.

    start = perturbed_start(source.states[0], rng, pos_sigma)   # START_NAMES, or None
    ep = resolve(env, start)                                    # the noise-free AlohaExpert
    steps = plan(env, source)                                   # the source's subtasks, by grasp signals
                                                                # (whole(source): one segment, for contrast)
    got = replay(env, start, source, steps)                     # an Outcome: reason None (kept) or why not
    e = nearest(sources, start)                                 # MimicGen's nearest source selection

Every function is a pure function of its arguments (the env is fully placed by set_start first).

Subtasks. A source demo is split by the env's own grasp signals (``env.holding`` after each step,
re-simulated from the source's first frame and recorded actions, as MimicGen's prepare_src_dataset
annotates a source through its env):

    subtask      frames                                  right arm frame   left arm frame
    reach_grasp  0 .. right engages the cube             cube              handoff
    handoff      right engages .. right releases         handoff           handoff     (coordination)
    carry_place  right releases .. end                   handoff           target

The cube frame sits at the cube's position when the subtask starts (read live in the new episode,
as MimicGen reads the object pose at each subtask's start); the handoff frame at the handoff point
(AlohaExpert.HANDOFF_X, target y), the frame the expert defines it in; the target frame at the
target. No frame has a yaw (the cube is a point on a planar table), so each re-expression is a
translation, done by datagen.task.transform_segment (the planar analog of MimicGen's
transform_source_data_segment_using_object_pose, which also turns a yaw where one exists).
Every subtask boundary is shared by both arms, so both arms enter each subtask together and run
it in step: the handoff is a coordination subtask (both arms in one frame, in step).

Execution. At each subtask start both arms are bridged from their current positions to their
segment's first waypoint by linear interpolation at up to BRIDGE_SPEED (the bridge's length is the
longer arm's; each gripper keeps its last command). Then every step commands, per arm, the
segment's (translated) velocity plus TRACK_GAIN times the waypoint error (a velocity-controlled
arm tracking the transformed end-effector waypoints; the env moves an arm at its commanded
velocity to within about 1 mm per step), and the source's gripper command of that frame. The
object is looked at only when a subtask starts (open loop in between), there is no expert, and
the attempt is kept only if the env reports success; after the last subtask the arms hold still
for up to SUCCESS_HOLD steps so the success hold can complete.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

import aloha_env
from datagen.fast_experts import AlohaBatch
from datagen.task import (
    Outcome,
    Perturbation,
    Source,
    Task,
    ended,
    recorded,
    register,
    rollout,
    transform_segment,
)
from scripted_expert import AlohaExpert

__all__ = [
    "ALOHA",
    "Aloha",
    "FAILURES",
    "START_NAMES",
    "STATE_RANGES",
    "Subtask",
    "attempt",
    "nearest",
    "perturbed_start",
    "plan",
    "replay",
    "resolve",
    "split",
    "start_of",
    "whole",
]

START_NAMES = aloha_env.START_NAMES
TRIES = 100  # draws per perturbed point before giving up with "no_valid_start"
# Where each point of a perturbed start must land (m): the env's own spawn regions, so a perturbed
# start is one reset() could have drawn, every point inside its arm's reach.
REGIONS = {
    "cube": (aloha_env.CUBE_X_RANGE, aloha_env.CUBE_Y_RANGE),
    "target": (aloha_env.TARGET_X_RANGE, aloha_env.TARGET_Y_RANGE),
    "right": (aloha_env.RIGHT_START_X_RANGE, aloha_env.START_Y_RANGE),
    "left": (aloha_env.LEFT_START_X_RANGE, aloha_env.START_Y_RANGE),
}
REACH = {  # (x range, y range) of each end-effector's slide joints (m)
    "right": (aloha_env.RIGHT_X_RANGE, aloha_env.Y_RANGE),
    "left": (aloha_env.LEFT_X_RANGE, aloha_env.Y_RANGE),
}
# Columns of each arm in the observation (x, y, closedness) and in the action (vx, vy, grip command).
XY = {"right": slice(0, 2), "left": slice(3, 5)}
GRIP = {"right": 2, "left": 5}
ARMS = ("right", "left")
SUBTASKS = (  # (name, frame of the right arm, frame of the left arm), in order
    ("reach_grasp", "cube", "handoff"),
    ("handoff", "handoff", "handoff"),
    ("carry_place", "handoff", "target"),
)
BRIDGE_SPEED = AlohaExpert.MAX_SPEED  # m/s, the expert's own top speed, so a bridge looks like it
BRIDGE_TOL = 1e-6  # m: an arm this close to its first waypoint needs no bridge
TRACK_GAIN = 5.0  # 1/s: velocity added per m of waypoint error (halves an error every 0.1 s step)
REPLAY_FAILURES = (
    "path_out_of_reach",  # a transformed waypoint lies beyond its arm's joint range
    "grasp_missed",  # the right gripper never engaged the cube
    "handoff_missed",  # the left gripper never engaged the cube
    "out_of_time",  # MAX_STEPS ran out before the plan did
    "finished_off_target",  # the plan ran to its end with the cube off the target
)
# A source the replay cannot split (no grasp and handoff, or one that does not re-simulate in this env):
# every replay of it fails with this reason (plan raises ValueError, the engine counts it).
SOURCE_UNSPLIT = "source_not_split"
FAILURES = {
    "resolve": ("expert_failed", "no_valid_start"),
    "replay": REPLAY_FAILURES + (SOURCE_UNSPLIT, "no_valid_start"),
}
# The ranges aloha_env.py documents for its state (STATE_NAMES order, m; closedness 0..1): each
# end-effector inside its slide joints' reach (plus MuJoCo's soft-limit overshoot: ~2 mm under steady
# pushing, up to 13.6 mm under full-speed random actions: aloha_env.LIMIT_SLACK, 30 mm), the cube
# and the target where the arms reach, a held cube up to GRASP_RADIUS beyond its gripper. A value
# outside is no ALOHA state: its attempts could only fail.
REACH_SLACK = aloha_env.LIMIT_SLACK  # m
_RX, _LX = aloha_env.RIGHT_X_RANGE, aloha_env.LEFT_X_RANGE
_OBJ = REACH_SLACK + aloha_env.GRASP_RADIUS
_X = (_LX[0] - _OBJ, _RX[1] + _OBJ)
_Y = (aloha_env.Y_RANGE[0] - REACH_SLACK, aloha_env.Y_RANGE[1] + REACH_SLACK)
_OY = (aloha_env.Y_RANGE[0] - _OBJ, aloha_env.Y_RANGE[1] + _OBJ)
STATE_RANGES = dict(
    zip(
        aloha_env.STATE_NAMES,
        [(_RX[0] - REACH_SLACK, _RX[1] + REACH_SLACK), _Y, (0.0, 1.0)]
        + [(_LX[0] - REACH_SLACK, _LX[1] + REACH_SLACK), _Y, (0.0, 1.0)]
        + [_X, _OY, _X, _OY],
    )
)

# Every action entry is clipped to [-1, 1] by the env (aloha_env.py): the expert's and replay's are inside.
ACTION_RANGES = {name: (-1.0, 1.0) for name in aloha_env.ACTION_NAMES}


def start_of(state) -> tuple[float, ...]:
    """The START_NAMES values (m) an observation describes: cube, target, right and left end-effector."""
    s = [float(v) for v in state]
    return (s[6], s[7], s[8], s[9], s[0], s[1], s[3], s[4])


def perturbed_start(first_state, rng, pos_sigma: float, tries: int = TRIES):
    """START_NAMES near the start `first_state` (an obs), or None if a point found no valid draw.

    Each of cube, target, right and left end-effector gets Gaussian noise of pos_sigma (m) on x and
    y, re-drawn (up to `tries` times) until it lies in its REGIONS box: a pure function of
    (first_state, rng state, pos_sigma)."""
    s = start_of(first_state)
    out = []
    for i, (xr, yr) in enumerate(REGIONS.values()):
        x0, y0 = s[2 * i], s[2 * i + 1]
        for _ in range(tries):
            x, y = x0 + rng.normal(0, pos_sigma), y0 + rng.normal(0, pos_sigma)
            if xr[0] <= x <= xr[1] and yr[0] <= y <= yr[1]:
                out += [x, y]
                break
        else:
            return None
    return tuple(out)


def resolve(env, start) -> dict:
    """The noise-free expert's episode from `start` (START_NAMES), in the real physics."""
    return rollout(env, AlohaExpert(noise=0.0), env.set_start(*start))


# ---------------------------------------------------------------------------------------- subtasks
def grasp_signals(env, source: Source) -> np.ndarray:
    """(T+1, 2) bool: (right holds, left holds) at each frame of `source` and after its last action.

    Re-simulated from the source's first frame through its recorded actions (the env's grasp rule runs
    inside the physics steps, so the 10 Hz frames alone do not show it). Raises ValueError when the
    re-simulation leaves the recorded frames by more than 1 mm (a set from another env)."""
    env.set_start(*start_of(source.states[0]))
    held = [env.holding]
    drift = 0.0
    for t, a in enumerate(source.actions):
        obs, *_ = env.step(a)
        held.append(env.holding)
        if t + 1 < len(source.states):
            drift = max(drift, float(np.max(np.abs(obs - source.states[t + 1]))))
    if drift > 1e-3:
        raise ValueError(f"source episode {source.episode} does not re-simulate (max drift {drift:.4f})")
    return np.array(held, bool)


@dataclass(frozen=True)
class Subtask:
    name: str
    start: int  # first frame of the source in this subtask
    stop: int  # one past its last frame
    frames: tuple[str, str]  # reference frame of the right and the left arm: cube | handoff | target


def split(held: np.ndarray) -> list[Subtask]:
    """The source's SUBTASKS from its grasp signals (grasp_signals' (T+1, 2) array).

    Boundaries: the first frame the right gripper holds the cube (it engaged during the step before),
    and the first frame after the left gripper engaged at which the right one no longer holds it (it
    released). Raises ValueError for a source without a grasp and a handoff."""
    n = len(held) - 1  # frames
    right, left = held[:n, 0], held[:n, 1]
    if not right.any() or not left.any():
        raise ValueError("the source has no grasp and handoff (both grippers must hold the cube)")
    engage = int(np.argmax(right))
    after = int(np.argmax(left))
    free = np.flatnonzero(~right[after:])
    if engage == 0 or not len(free):
        raise ValueError("the source's right gripper holds from its first frame or never lets go")
    release = after + int(free[0])
    bounds = (0, engage, release, n)
    return [Subtask(name, a, b, (fr, fl)) for (name, fr, fl), a, b in zip(SUBTASKS, bounds, bounds[1:])]


def whole(source: Source) -> list[Subtask]:
    """The whole demo as one segment with both arms relative to the cube: MimicGen's move without its
    subtasks (as datagen.pusht.replay makes it), for contrast: the target does not move with the cube."""
    return [Subtask("whole", 0, len(source.actions), ("cube", "cube"))]


def plan(env, source: Source) -> list[Subtask]:
    """The source's subtasks (grasp_signals, then split)."""
    return split(grasp_signals(env, source))


def frame_pose(frame: str, state) -> tuple[float, float, float]:
    """(x m, y m, yaw rad) of a reference frame in an observation; no ALOHA frame turns (yaw 0)."""
    if frame == "cube":
        return (float(state[6]), float(state[7]), 0.0)
    if frame == "target":
        return (float(state[8]), float(state[9]), 0.0)
    return (AlohaExpert.HANDOFF_X, float(state[9]), 0.0)  # handoff: the expert's (HANDOFF_X, target y)


def arm_segment(source: Source, sub: Subtask, arm: str, frame: str, now) -> tuple:
    """One arm's segment of subtask `sub`, re-expressed from the source's frame pose (at the subtask's
    first frame) into the same frame's pose in the observation `now`.
    Returns waypoints (T, 2) m, velocities (T, 2) m/s and gripper commands (T,)."""
    rows = slice(sub.start, sub.stop)
    pts, vel = transform_segment(
        source.states[rows, XY[arm]],
        source.actions[rows, XY[arm]],
        frame_pose(frame, source.states[sub.start]),
        frame_pose(frame, now),
    )
    return pts, vel, np.asarray(source.actions[rows, GRIP[arm]], np.float64)


def bridge(now, first: dict, grips: dict) -> list[tuple[dict, dict, dict]]:
    """Linear interpolation of both arms from `now` (an obs) to their `first` waypoints, in step.

    Returns one (waypoint, velocity, grip) per step (dicts by arm); the bridge lasts as many steps as the
    longer move needs at BRIDGE_SPEED (none when both arms are within BRIDGE_TOL)."""
    here = {arm: np.asarray(now[XY[arm]], np.float64) for arm in ARMS}
    dist = max(float(np.hypot(*(first[a] - here[a]))) for a in ARMS)
    if dist <= BRIDGE_TOL:
        return []
    n = math.ceil(dist / (BRIDGE_SPEED / aloha_env.FPS) - 1e-9)
    steps = []
    for i in range(n):
        wp = {a: here[a] + i / n * (first[a] - here[a]) for a in ARMS}
        vel = {a: (first[a] - here[a]) * aloha_env.FPS / n for a in ARMS}
        steps.append((wp, vel, dict(grips)))
    return steps


def replay(env, start, source: Source, steps: list[Subtask] | None = None) -> Outcome:
    """Replay `source` from `start` (START_NAMES) subtask by subtask, open-loop, in the real physics.

    steps: the source's plan (computed here when None). Returns the Outcome (its episode: the frames and
    actions actually executed, as datagen.task.rollout returns them), its reason None when the env
    reports success, else the first REPLAY_FAILURES reason that applies, in that order."""
    steps = plan(env, source) if steps is None else steps
    obs = env.set_start(*start)
    states, actions, succ = [], [], []
    grips = {a: float(source.actions[0, GRIP[a]]) for a in ARMS}  # what each gripper was last told
    held = np.zeros(2, bool)  # ever held: right, left
    out_of_reach = False
    done = False

    def act(wp: dict, vel: dict, grip: dict) -> None:
        nonlocal obs, done
        a = np.zeros(aloha_env.ACT_DIM)
        for arm in ARMS:
            here = np.asarray(obs[XY[arm]], np.float64)
            a[XY[arm]] = vel[arm] + TRACK_GAIN * (wp[arm] - here)  # track the transformed waypoint
            a[GRIP[arm]] = grip[arm]
        a = np.clip(a, -1.0, 1.0).astype(np.float32)
        states.append(obs)
        actions.append(a)
        obs, _, done, info = env.step(a)
        succ.append(bool(info["success"]))
        held[:] |= env.holding

    for sub in steps:
        if done:
            break
        segs = {arm: arm_segment(source, sub, arm, fr, obs) for arm, fr in zip(ARMS, sub.frames)}
        for arm, (pts, _, _) in segs.items():
            (xr, yr) = REACH[arm]
            inside = (pts[:, 0] >= xr[0]) & (pts[:, 0] <= xr[1]) & (pts[:, 1] >= yr[0]) & (pts[:, 1] <= yr[1])
            out_of_reach |= not inside.all()
        for wp, vel, grip in bridge(obs, {a: segs[a][0][0] for a in ARMS}, grips):
            if done:
                break
            act(wp, vel, grip)
        for t in range(sub.stop - sub.start):
            if done:
                break
            grips = {a: float(segs[a][2][t]) for a in ARMS}
            act({a: segs[a][0][t] for a in ARMS}, {a: segs[a][1][t] for a in ARMS}, grips)
    planned = not done or env.success
    for _ in range(aloha_env.SUCCESS_HOLD):  # hold still so the success hold can complete
        if done:
            break
        here = {a: np.asarray(obs[XY[a]], np.float64) for a in ARMS}
        act(here, {a: np.zeros(2) for a in ARMS}, grips)
    ep = recorded(aloha_env, states, actions, succ, env.success)
    if env.success:
        why = None
    elif out_of_reach:
        why = "path_out_of_reach"
    elif not held[0]:
        why = "grasp_missed"
    elif not held[1]:
        why = "handoff_missed"
    elif not planned:
        why = "out_of_time"
    else:
        why = "finished_off_target"
    return ended(ep, why, start, source.episode)


# ---------------------------------------------------------------------------------------- selection
def object_distance(a, b) -> float:
    """Distance (m) between the object poses of two starts (START_NAMES): cube shift plus target shift."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) + math.hypot(a[2] - b[2], a[3] - b[3])


def nearest(sources: dict, start) -> int:
    """MimicGen's nearest selection: the episode of the source whose start's objects (cube, target)
    lie nearest `start`'s (object_distance); ties go to the lowest episode index."""
    return min(sources, key=lambda e: (object_distance(start_of(sources[e].states[0]), start), e))


# ---------------------------------------------------------------------------------------- attempts
def attempt(
    source: Source,
    rng,
    env,
    *,
    pos_sigma: float,
    mode: str = "resolve",
    pool: dict | None = None,
    plans: dict | None = None,
) -> Outcome:
    """One attempt from `source` with the generator `rng`: its Outcome (reason None, or a FAILURES[mode]
    entry; source_episode: the source replayed).

    mode "resolve": the expert re-solves the perturbed start. Mode "replay": the perturbed start (the
    same draw) replayed from `source` itself, or, given `pool` ({episode: Source}), from the pool's
    source nearest the new start (MimicGen's selection). plans: {episode: [Subtask]} to reuse."""
    start = perturbed_start(source.states[0], rng, pos_sigma)
    if start is None:
        return Outcome("no_valid_start", source_episode=source.episode)
    if mode == "resolve":
        ep = resolve(env, start)
        return ended(ep, None if ep["success"] else "expert_failed", start, source.episode)
    chosen = pool[nearest(pool, start)] if pool else source
    steps = plans.get(chosen.episode) if plans else None
    return replay(env, start, chosen, steps)


# ---------------------------------------------------------------------------------------- the task
class Aloha(Task):
    """The ALOHA handoff's parts for the engine (see the module docstring). A perturbation moves cube,
    target and both end-effectors by pos_sigma (m) each, inside their spawn regions (yaw_sigma is not
    read: no ALOHA object turns); replay is the subtask replay above."""

    name, title, generator = "aloha", "ALOHA", "gen_demos_aloha.py"
    start_names = START_NAMES
    env_module = aloha_env
    state_ranges, action_ranges = STATE_RANGES, ACTION_RANGES
    failures = FAILURES
    max_steps = aloha_env.MAX_STEPS

    def make_env(self, share=None):
        return aloha_env.AlohaCubeEnv(share.model if share is not None else None)

    def perturb(self, first_state, rng, how: Perturbation):
        return perturbed_start(first_state, rng, how.pos_sigma)

    def place(self, env, start):
        return env.set_start(*start)

    def expert(self):
        return AlohaExpert(noise=0.0)

    def batch_expert(self):
        return AlohaBatch().act_batch

    def object_pose(self, state) -> np.ndarray:
        return np.array([float(state[6]), float(state[7]), 0.0])  # the cube (x, y m); it never turns

    def nearest(self, pool: dict, start) -> int:
        return nearest(pool, start)

    def segments(self, source: Source, plans: dict | None = None) -> list[Subtask]:
        """The source's subtasks (plan), re-simulated once per source in `plans` (the caller's cache,
        keyed by the task, the episode and the sha256 of its frames: a plan is a pure function of the
        source). Raises ValueError for a source without a grasp and a handoff, or one that does not
        re-simulate."""
        h = hashlib.sha256(np.ascontiguousarray(source.states).tobytes())
        h.update(np.ascontiguousarray(source.actions).tobytes())
        key = (self.name, source.episode, h.hexdigest())
        plans = {} if plans is None else plans
        if key not in plans:
            plans[key] = plan(self.make_env(), source)
        return plans[key]

    def replay(self, env, start, source: Source, plans: dict | None = None) -> Outcome:
        try:
            steps = self.segments(source, plans)
        except ValueError:
            return Outcome(SOURCE_UNSPLIT, None, start, source.episode)
        return replay(env, start, source, steps)

    def success(self, env) -> bool:
        return bool(env.success)


ALOHA = register(Aloha())
