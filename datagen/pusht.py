"""PushT as a data-engine task (datagen.task.Task): the only engine module that imports pusht_env
and its expert.

    perturb   block x, y and pusher x, y get Gaussian noise of pos_sigma (m), block yaw of yaw_sigma
              (rad); the block must stay on the band R_LO..R_HI m from the target and the pusher
              inside its square and clear of the T (up to TRIES draws, else no_valid_start)
    place     env.set_start at that start: block x, y, yaw, pusher x, y (START_NAMES)
    expert    the noise-free PushTExpert, which re-solves the start in the real physics
    segments  one: the whole source path, relative to the block's start pose (the push is about the
              block; the target stays put)
    replay    MimicGen's move: the segment's pusher path and commands re-expressed in the perturbed
              block's pose (transform_segment: the planar SE(2) analog of MimicGen's
              transform_source_data_segment_using_object_pose), an approach from the pusher's own start
              to the first transformed waypoint (as MimicGen interpolates into a segment), then the
              transformed commands open-loop; kept only on the env's success, else the reason
    nearest   MimicGen's nearest source selection: the source whose block start is nearest the new
              start, position plus YAW_WEIGHT x yaw (pose_distance)

MimicGen by subtasks (issue 29; tools/replay_yield.py's study, not the engine's --aug_mode replay, whose
bytes stay the one-segment replay above): split(source) cuts a source demo at the first frame the
pusher touches the T (pusht_env.t_signed_distance within PUSHER_RADIUS + CONTACT_TOL):

    approach  0 .. first contact   relative to the block (its pose when the subtask starts)
    push      first contact .. end relative to the block and the target: the frame starts on the
              block's pose when the push starts and moves linearly (x, y, yaw) onto the target's
              frame by the push's last frame

MimicGen gives every subtask one reference object; PushT's push has two (the block it moves and
the target it must end on, which does not move with the block), and the frame that slides from
one to the other over the push is our reading of "relative to the block and the target" (with
push_frame="block" the push stays relative to the block alone, MimicGen's single-object form).
replay_subtasks enters the first subtask from the pusher's start by linear interpolation at up to
APPROACH_SPEED; then the pusher tracks the segment's transformed waypoints: the source's velocity
turned into the frame plus TRACK_GAIN times the waypoint error. The object is read only at each
subtask's start; the attempt is kept only on the env's success.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import pusht_env
from datagen.fast_experts import PushTBatch
from datagen.fast_pusht import SharedPushTEnv, step_many
from datagen.task import (
    Outcome,
    Perturbation,
    Segment,
    Source,
    Task,
    ended,
    recorded,
    register,
    rotation,
    transform_segment,
)
from scripted_expert import PushTExpert

__all__ = [
    "PUSHT",
    "PushT",
    "START_NAMES",
    "Subtask",
    "block_pose",
    "first_contact",
    "nearest",
    "perturbed_start",
    "pose_distance",
    "replay_lanes",
    "replay_subtasks",
    "rotation",
    "split",
    "subtask_segment",
    "transform_segment",
]

R_LO, R_HI = 0.08, 0.26  # m; the block is kept on a band slightly wider than the spawn annulus
TRIES = 100  # perturbation draws per attempt before giving up with "no_valid_start"
START_NAMES = ("block_x", "block_y", "block_yaw", "pusher_x", "pusher_y")  # what env.set_start takes
# The ranges pusht_env.py documents for its state (STATE_NAMES order): positions inside the walls (m),
# sines and cosines in [-1, 1], the fixed target (0, 0, sin 0, cos 1). A value outside is no PushT
# state: its attempts could only fail (a block at 1e30 m is no valid start).
_W = pusht_env.WALL_INNER
STATE_RANGES = dict(
    zip(pusht_env.STATE_NAMES, [(-_W, _W)] * 4 + [(-1.0, 1.0)] * 2 + [(0.0, 0.0)] * 3 + [(1.0, 1.0)])
)
# The pusher velocity the env clips to (m/s): the expert's and replay's actions are inside.
ACTION_RANGES = {name: (-pusht_env.ACTION_LIMIT, pusht_env.ACTION_LIMIT) for name in pusht_env.ACTION_NAMES}


def perturbed_start(first_state, rng, pos_sigma: float, yaw_sigma: float, tries: int = TRIES):
    """(block x, y, yaw, pusher x, y) near the start `first_state` (an obs), or None if no draw was valid."""
    px, py, bx, by, s, c = (float(v) for v in first_state[:6])
    h = pusht_env.PUSHER_HALF  # the pusher is clipped with min/max: np.clip's values, without its cost
    for _ in range(tries):
        nbx, nby = bx + rng.normal(0, pos_sigma), by + rng.normal(0, pos_sigma)
        yaw = math.atan2(s, c) + rng.normal(0, yaw_sigma)
        npx, npy = (
            min(max(v, -h), h) for v in (px + rng.normal(0, pos_sigma), py + rng.normal(0, pos_sigma))
        )
        if R_LO <= math.hypot(nbx, nby) <= R_HI and pusht_env.pusher_clear(nbx, nby, yaw, npx, npy):
            return (nbx, nby, math.atan2(math.sin(yaw), math.cos(yaw)), float(npx), float(npy))
    return None


def block_pose(state) -> np.ndarray:
    """(x m, y m, yaw rad) of the block in a PushT observation."""
    return np.array([state[2], state[3], math.atan2(state[4], state[5])])


APPROACH_GAIN = 10.0  # 1/s: approach speed per m of distance to the first waypoint
APPROACH_SPEED = 0.8  # m/s, the expert's own top speed
APPROACH_TOL = 0.002  # m: close enough to the first waypoint to start the segment
APPROACH_STEPS = 60  # control steps (6 s) before the segment starts regardless
MOVED_TOL = (0.002, 0.02)  # m, rad: the approach "hit the block" if it moved it more than this
REACH = pusht_env.WALL_INNER - pusht_env.PUSHER_RADIUS  # m: the pusher centre's reach from the centre


def replay(env, start, source: Source, segment: Segment | None = None) -> Outcome:
    """Replay `source` from `start` (see START_NAMES): approach, then its transformed commands open-loop.

    Returns the Outcome, its episode the frames and actions actually executed (as datagen.task.rollout
    returns them) and, when the env did not report success, its reason: approach_blocked (the approach
    moved the block), path_off_table (a transformed waypoint lies beyond the walls), out_of_time (the
    episode ended before the segment did), or finished_off_target (the segment ran to its end off target).
    """
    seg = segment or Segment(0, len(source.actions), tuple(block_pose(source.states[0])))
    path, commands = transform_segment(
        source.states[seg.start : seg.stop, :2], source.actions[seg.start : seg.stop], seg.pose, start[:3]
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
    ep = recorded(pusht_env, states, actions, succ, env.success)
    if env.success:
        why = None
    elif blocked:
        why = "approach_blocked"
    elif np.any(np.abs(path) > REACH):
        why = "path_off_table"
    elif executed < len(commands):
        why = "out_of_time"
    else:
        why = "finished_off_target"
    return ended(ep, why, start, source.episode)


# ---------------------------------------------------------------- MimicGen by subtasks, nearest selection
CONTACT_TOL = 0.002  # m: the pusher's edge this close to the T counts as touching it
TRACK_GAIN = 5.0  # 1/s: velocity added per m of waypoint error (halves an error every 0.1 s step)
BRIDGE_TOL = APPROACH_TOL  # m: closer, the tracking absorbs the gap (a 1-step bridge stalls on the block)
# Nearest selection weighs a yaw difference against a position difference as the success
# tolerances do (0.03 m against 0.20 rad), so "nearest" means nearest in units of the goal's slack.
YAW_WEIGHT = pusht_env.SUCCESS_POS_TOL / pusht_env.SUCCESS_YAW_TOL  # m per rad


@dataclass(frozen=True)
class Subtask:
    name: str
    start: int  # first frame of the source in this subtask
    stop: int  # one past its last frame


def first_contact(states) -> int:
    """The first frame (obs (T, 10)) at which the pusher touches the T; len(states) if it never does."""
    for t, s in enumerate(states):
        d = pusht_env.t_signed_distance(s[0], s[1], s[2], s[3], math.atan2(s[4], s[5]))
        if d <= pusht_env.PUSHER_RADIUS + CONTACT_TOL:
            return t
    return len(states)


def split(source: Source) -> list[Subtask]:
    """approach (frames before the first contact) and push (the rest); an empty approach is dropped."""
    c, n = first_contact(source.states), len(source.states)
    return [s for s in (Subtask("approach", 0, c), Subtask("push", c, n)) if s.stop > s.start]


def interp_pose(a, b, s: float) -> tuple[float, float, float]:
    """The planar pose a fraction s (0..1) of the way from a to b (x, y linear; yaw the short way)."""
    dyaw = pusht_env.wrap_angle(float(b[2]) - float(a[2]))
    return (a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), float(a[2]) + s * dyaw)


def subtask_segment(source: Source, sub: Subtask, now, push_frame: str = "block+target") -> tuple:
    """The pusher's segment of `sub`, re-expressed for the block pose in the observation `now`.

    approach, and push with push_frame="block": from the source's block pose at the subtask's first frame
    to the block pose now (transform_segment). push with "block+target": frame t of a T-frame push
    goes into the pose a fraction t/(T-1) of the way from the block now to the source's block pose, so the
    push starts on the block and ends where the source's push ended (the target frame: the target is
    fixed). Returns waypoints (T, 2) m and velocities (T, 2) m/s."""
    rows = slice(sub.start, sub.stop)
    pts, vel = source.states[rows, :2], source.actions[rows]
    src, new = block_pose(source.states[sub.start]), block_pose(now)
    if sub.name == "approach" or push_frame == "block":
        return transform_segment(pts, vel, src, new)
    n = len(pts)
    out_p, out_v = np.zeros((n, 2)), np.zeros((n, 2))
    for t in range(n):
        pose = interp_pose(new, src, t / max(n - 1, 1))
        out_p[t], out_v[t] = (m[0] for m in transform_segment(pts[t : t + 1], vel[t : t + 1], src, pose))
    return out_p, out_v


def replay_subtasks(env, start, source: Source, steps=None, push_frame: str = "block+target") -> Outcome:
    """Replay `source` from `start` (START_NAMES) subtask by subtask in the real physics.

    Returns the Outcome (its episode: frames and actions executed, as datagen.task.rollout returns them),
    its reason None on the env's success, else the first replay failure that applies: approach_blocked (a
    bridge into a subtask moved the block), path_off_table (a waypoint beyond the walls), out_of_time,
    finished_off_target."""
    steps = split(source) if steps is None else steps
    obs = env.set_start(*start)
    states, actions, succ = [], [], []
    done, off_table, blocked = False, False, False

    def act(wp, vel) -> None:
        nonlocal obs, done
        a = np.clip(vel + TRACK_GAIN * (wp - np.asarray(obs[:2], np.float64)), -1.0, 1.0).astype(np.float32)
        states.append(obs)
        actions.append(a)
        obs, _, done, info = env.step(a)
        succ.append(bool(info["success"]))

    for sub in steps:
        if done:
            break
        pts, vel = subtask_segment(source, sub, obs, push_frame)
        off_table |= bool(np.any(np.abs(pts) > REACH))
        here = np.asarray(obs[:2], np.float64)
        dist = float(np.hypot(*(pts[0] - here)))
        # Only the plan's first subtask is bridged: the push starts one frame after the approach ended,
        # in the same block frame, so its gap is tracking error (mm) that the tracking law closes; a
        # bridge there would stall the pusher against the block it already touches.
        first = sub is steps[0]
        n = math.ceil(dist / (APPROACH_SPEED / pusht_env.FPS) - 1e-9) if first and dist > BRIDGE_TOL else 0
        before = env.block_pose
        for i in range(n):  # bridge: linear interpolation to the first waypoint
            if done:
                break
            act(here + i / n * (pts[0] - here), (pts[0] - here) * pusht_env.FPS / n)
        shift = env.block_pose - before  # a bridge that moves the block has hit it
        blocked |= math.hypot(*shift[:2]) > MOVED_TOL[0] or abs(pusht_env.wrap_angle(shift[2])) > MOVED_TOL[1]
        for wp, v in zip(pts, vel):
            if done:
                break
            act(wp, v)
    planned = not done or env.success
    ep = recorded(pusht_env, states, actions, succ, env.success)
    if env.success:
        why = None
    elif blocked:
        why = "approach_blocked"
    elif off_table:
        why = "path_off_table"
    elif not planned:
        why = "out_of_time"
    else:
        why = "finished_off_target"
    return ended(ep, why, start, source.episode)


def pose_distance(a, b) -> float:
    """Distance between two block poses (x m, y m, yaw rad): position plus YAW_WEIGHT x |yaw difference|."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) + YAW_WEIGHT * abs(pusht_env.wrap_angle(a[2] - b[2]))


def nearest(sources: dict, start) -> int:
    """MimicGen's nearest selection: the episode of the source whose start block pose lies nearest
    `start`'s (pose_distance); ties go to the lowest episode index."""
    return min(sources, key=lambda e: (pose_distance(block_pose(sources[e].states[0]), start[:3]), e))


# ---------------------------------------------------------------- replay in lockstep (datagen.lockstep)
def replay_lanes(sources: dict, how: Perturbation) -> dict:
    """Mode "replay" as datagen.lockstep lanes: replay()'s approach and open-loop segment, decided for
    all lanes at once, bit for bit what replay() does one attempt at a time (tests/test_lockstep.py)."""
    from datagen.lockstep import Lane, kept_or_not, start_of_job

    def begin(job, env):
        start = start_of_job(PUSHT, sources, job, how)
        if start is None:
            return Outcome("no_valid_start", source_episode=job[0])
        src = sources[job[0]]
        path, commands = transform_segment(
            src.states[:, :2], src.actions, block_pose(src.states[0]), start[:3]
        )
        obs = env.set_start(*start)
        # approached: approach steps taken; blocked: None until the approach ends, then whether it
        # moved the block (from `before`, the block's pose at the start); executed: segment steps taken
        return Lane(
            job,
            obs,
            start=start,
            path=path,
            commands=commands,
            before=env.block_pose,
            approached=0,
            blocked=None,
            executed=0,
        )

    def end_approach(lane, env) -> None:
        shift = env.block_pose - lane.before
        lane.blocked = (
            math.hypot(shift[0], shift[1]) > MOVED_TOL[0]
            or abs(pusht_env.wrap_angle(shift[2])) > MOVED_TOL[1]
        )

    def decide(lanes, envs, obs):
        n = len(lanes)
        actions = np.zeros((n, pusht_env.ACT_DIM), np.float32)
        stop, took = np.zeros(n, bool), np.zeros(n, bool)  # took: an approach step this call
        approaching = [j for j, lane in enumerate(lanes) if lane.blocked is None]
        if approaching:  # approach the first waypoint on a straight line, in replay's float64 math
            gap = np.stack([lanes[j].path[0] - envs[j].pusher_pos for j in approaching])  # (M, 2) m
            dist = np.hypot(gap[:, 0], gap[:, 1])  # the ufunc replay calls on two scalars
            speed = np.minimum(APPROACH_GAIN * dist, APPROACH_SPEED)
            with np.errstate(invalid="ignore", divide="ignore"):  # a lane on its waypoint: not used
                step = gap / dist[:, None] * speed[:, None]
            for m, j in enumerate(approaching):
                lane = lanes[j]
                if lane.approached < APPROACH_STEPS and not dist[m] <= APPROACH_TOL:
                    actions[j] = step[m]  # cast to float32, as replay's act does
                    lane.approached += 1
                    took[j] = True
                else:
                    end_approach(lane, envs[j])
        for j, lane in enumerate(lanes):  # the transformed segment, open-loop; stop when it ran out
            if took[j]:
                continue
            if lane.executed < len(lane.commands):
                actions[j] = lane.commands[lane.executed]
                lane.executed += 1
            else:
                stop[j] = True
        return actions, stop

    def finish(lane, env, episode):
        if lane.blocked is None:  # the episode ended during the approach
            end_approach(lane, env)
        if env.success:
            why = None
        elif lane.blocked:
            why = "approach_blocked"
        elif np.any(np.abs(lane.path) > REACH):
            why = "path_off_table"
        elif lane.executed < len(lane.commands):
            why = "out_of_time"
        else:
            why = "finished_off_target"
        return kept_or_not(lane, episode, env.success, why)

    return {"begin": begin, "decide": decide, "finish": finish}


class PushT(Task):
    """PushT's parts for the engine (see the module docstring)."""

    name, title, generator = "pusht", "PushT", "gen_demos_pusht.py"
    start_names = START_NAMES
    env_module = pusht_env
    state_ranges, action_ranges = STATE_RANGES, ACTION_RANGES
    max_steps = pusht_env.MAX_STEPS
    failures = {  # every reason a mode can return
        "resolve": ("expert_failed", "no_valid_start"),
        "replay": (
            "approach_blocked",
            "path_off_table",
            "out_of_time",
            "finished_off_target",
            "no_valid_start",
        ),
    }

    def make_env(self, share=None):
        return SharedPushTEnv(share)

    def perturb(self, first_state, rng, how: Perturbation):
        return perturbed_start(first_state, rng, how.pos_sigma, how.yaw_sigma)

    def place(self, env, start):
        return env.set_start(*start)

    def expert(self):
        return PushTExpert(noise=0.0)

    def object_pose(self, state) -> np.ndarray:
        return block_pose(state)

    def nearest(self, pool: dict, start) -> int:
        return nearest(pool, start)

    def segments(self, source: Source) -> list[Segment]:
        return [Segment(0, len(source.actions), tuple(float(v) for v in block_pose(source.states[0])))]

    def replay(self, env, start, source: Source, plans: dict | None = None) -> Outcome:
        (segment,) = self.segments(source)
        return replay(env, start, source, segment)

    def success(self, env) -> bool:
        return bool(env.success)

    def replay_lanes(self, sources: dict, how: Perturbation) -> dict:
        return replay_lanes(sources, how)

    def batch_expert(self):
        return PushTBatch().act_batch

    def step_batch(self, envs, actions):
        return step_many(envs, actions)


PUSHT = register(PushT())
