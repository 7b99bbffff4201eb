"""PushT replay the MimicGen way, subtask by subtask, with its nearest source selection (issue 29;
it joins datagen/pusht.py behind the engine's task interface).

    steps = split(source)                                   # approach, push
    ep, why = replay(env, start, source, steps)             # why: None (kept) or engine.FAILURES["replay"]
    e = nearest(sources, start)                             # the source whose block start is nearest

A source demo is split at the first frame the pusher touches the T (the env's own geometry:
pusht_env.t_signed_distance within PUSHER_RADIUS + CONTACT_TOL):

    approach  0 .. first contact   relative to the block (its pose when the subtask starts)
    push      first contact .. end relative to the block and the target: the frame starts on the
              block's pose when the push starts and moves linearly (x, y, yaw) onto the target's
              frame by the push's last frame

MimicGen gives every subtask one reference object; PushT's push has two (the block it moves and
the target it must end on, which does not move with the block), and the frame that slides from
one to the other over the push is our reading of "relative to the block and the target" (with
push_frame="block" the push stays relative to the block alone, MimicGen's single-object form).
The first subtask is entered from the pusher's start by linear interpolation at up to
engine.APPROACH_SPEED (the push follows the approach in the same frame, see replay); then the
pusher tracks the segment's transformed waypoints: the source's velocity turned into the frame
plus TRACK_GAIN times the waypoint error. The object is read only at each subtask's start; the
attempt is kept only on the env's success.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import pusht_env
from ch37.engine import APPROACH_SPEED, APPROACH_TOL, MOVED_TOL, REACH, Source, block_pose, transform_segment

CONTACT_TOL = 0.002  # m: the pusher's edge this close to the T counts as touching it
TRACK_GAIN = 5.0  # 1/s: velocity added per m of waypoint error (halves an error every 0.1 s step)
BRIDGE_TOL = APPROACH_TOL  # m: closer, the tracking absorbs the gap (a 1-step bridge stalls on the block)
# Nearest selection weighs a yaw difference against a position difference as the success
# tolerances do (0.03 m against 0.20 rad), so "nearest" means nearest in units of the goal's slack.
YAW_WEIGHT = pusht_env.SUCCESS_POS_TOL / pusht_env.SUCCESS_YAW_TOL  # m per rad
FAILURES = ("approach_blocked", "path_off_table", "out_of_time", "finished_off_target")


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


def segment(source: Source, sub: Subtask, now, push_frame: str = "block+target") -> tuple:
    """The pusher's segment of `sub`, re-expressed for the block pose in the observation `now`.

    approach, and push with push_frame="block": from the source's block pose at the subtask's first frame
    to the block pose now (engine.transform_segment). push with "block+target": frame t of a T-frame push
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


def replay(
    env, start, source: Source, steps=None, push_frame: str = "block+target"
) -> tuple[dict, str | None]:
    """Replay `source` from `start` (engine.START_NAMES) subtask by subtask in the real physics.

    Returns the episode (frames and actions executed, as ch37.demos.rollout returns them) and None on the
    env's success, else the first FAILURES reason that applies: approach_blocked (a bridge into a subtask
    moved the block), path_off_table (a waypoint beyond the walls), out_of_time, finished_off_target."""
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
        pts, vel = segment(source, sub, obs, push_frame)
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
    if off_table:
        return ep, "path_off_table"
    if not planned:
        return ep, "out_of_time"
    return ep, "finished_off_target"


def pose_distance(a, b) -> float:
    """Distance between two block poses (x m, y m, yaw rad): position plus YAW_WEIGHT x |yaw difference|."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) + YAW_WEIGHT * abs(pusht_env.wrap_angle(a[2] - b[2]))


def nearest(sources: dict, start) -> int:
    """MimicGen's nearest selection: the episode of the source whose start block pose lies nearest
    `start`'s (pose_distance); ties go to the lowest episode index."""
    return min(sources, key=lambda e: (pose_distance(block_pose(sources[e].states[0]), start[:3]), e))
