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
"""

from __future__ import annotations

import math

import numpy as np

import pusht_env
from datagen.task import Perturbation, Segment, Source, Task
from scripted_expert import PushTExpert

__all__ = ["PUSHT", "PushT", "START_NAMES", "block_pose", "perturbed_start", "rotation", "transform_segment"]

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


def replay(env, start, source: Source, segment: Segment | None = None) -> tuple[dict, str | None]:
    """Replay `source` from `start` (see START_NAMES): approach, then its transformed commands open-loop.

    Returns the episode (the frames and actions actually executed, as datagen.task.rollout returns them)
    and, when the env did not report success, the reason: approach_blocked (the approach moved the
    block), path_off_table (a transformed waypoint lies beyond the walls), out_of_time (the episode
    ended before the segment did), or finished_off_target (the segment ran to its end off target).
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


class PushT(Task):
    """PushT's parts for the engine (see the module docstring)."""

    name, title, generator = "pusht", "PushT", "gen_demos_pusht.py"
    start_names = START_NAMES
    env_module = pusht_env
    state_ranges = STATE_RANGES
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

    def make_env(self):
        return pusht_env.PushTEnv()

    def perturb(self, first_state, rng, how: Perturbation):
        return perturbed_start(first_state, rng, how.pos_sigma, how.yaw_sigma)

    def place(self, env, start):
        return env.set_start(*start)

    def expert(self):
        return PushTExpert(noise=0.0)

    def object_pose(self, state) -> np.ndarray:
        return block_pose(state)

    def segments(self, source: Source) -> list[Segment]:
        return [Segment(0, len(source.actions), tuple(float(v) for v in block_pose(source.states[0])))]

    def replay(self, env, start, source: Source) -> tuple[dict, str | None]:
        (segment,) = self.segments(source)
        return replay(env, start, source, segment)

    def success(self, env) -> bool:
        return bool(env.success)


PUSHT = PushT()
