"""PushT as a data-engine task (datagen.task.Task): a description, no generation code. The only engine
module that imports pusht_env and its expert.

    arm        the pusher: its (x, y) are observation columns 0, 1; it reaches REACH m from the centre
    start      block x, y, yaw, pusher x, y (START_NAMES, what env.set_start takes)
    perturb    block x, y and pusher x, y get Gaussian noise of pos_sigma (m), block yaw of yaw_sigma
               (rad); the block must stay on the band R_LO..R_HI m from the target and the pusher inside
               its square and clear of the T (up to TRIES draws, else no_valid_start)
    expert     the noise-free PushTExpert, which re-solves the start in the real physics
    frames     block (its pose in the observation), target (fixed)
    subtasks   one: the whole push, relative to the block's pose at its start (the push is about the
               block), entered by a bridge from the pusher's start
    actions    velocities (m/s): a replayed step commands the segment's velocity plus TRACK_GAIN times
               the waypoint error, clipped to the env's range
    nearest    the source whose block start is nearest, position plus YAW_WEIGHT x yaw (pose_distance)

PushT(subtasks=BY_CONTACT) cuts a source at the first frame the pusher touches the T (the "contact"
signal: pusht_env.t_signed_distance within PUSHER_RADIUS + CONTACT_TOL) into an approach relative to the
block and a push whose frame slides from the block onto the target (our reading of "relative to the block
and the target": MimicGen gives every subtask one object, PushT's push has two, the block it moves and the
target it must end on); PushT(subtasks=BY_CONTACT_BLOCK) keeps the push relative to the block alone.
tools/replay.py (yield) studies both; the engine's --aug_mode replay uses the one segment (PUSHT).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

import pusht_env
from datagen.task import (
    EnvSpec,
    ExpertSpec,
    Perturbation,
    ReplaySpec,
    Subtask,
    Task,
    VelocityCommand,
    register,
)
from datagen.tasks.fast_pusht import SharedPushTEnv, step_many
from scripted_expert import PushTExpert

__all__ = [
    "BY_CONTACT",
    "BY_CONTACT_BLOCK",
    "ONE_SEGMENT",
    "PUSHT",
    "PushT",
    "START_NAMES",
    "block_pose",
    "perturbed_start",
    "pose_distance",
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
_LIMIT = pusht_env.ACTION_LIMIT  # m/s: the env clips the pusher's velocity to +-1
ACTION_RANGES = {name: (-_LIMIT, _LIMIT) for name in pusht_env.ACTION_NAMES}
REACH = pusht_env.WALL_INNER - pusht_env.PUSHER_RADIUS  # m: the pusher centre's reach from the centre
TRACK_GAIN = 5.0  # 1/s: velocity added per m of waypoint error (halves an error every 0.1 s step)
CONTACT_TOL = 0.002  # m: the pusher's edge this close to the T counts as touching it
# Nearest selection weighs a yaw difference against a position difference as the success
# tolerances do (0.03 m against 0.20 rad), so "nearest" means nearest in units of the goal's slack.
YAW_WEIGHT = pusht_env.SUCCESS_POS_TOL / pusht_env.SUCCESS_YAW_TOL  # m per rad

ONE_SEGMENT = (Subtask("push", ("block",)),)  # the engine's replay
BY_CONTACT = (  # the study's: approach, then a push sliding from the block onto the target
    Subtask("approach", ("block",), ends="contact"),
    Subtask("push", ("block",), bridge=False, onto=("target",)),  # it starts where the approach ended
)
BY_CONTACT_BLOCK = (BY_CONTACT[0], Subtask("push", ("block",), bridge=False))


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


def pose_distance(a, b) -> float:
    """Distance between two block poses (x m, y m, yaw rad): position plus YAW_WEIGHT x |yaw difference|."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) + YAW_WEIGHT * abs(pusht_env.wrap_angle(a[2] - b[2]))


class PushT(Task):
    """PushT's description for the engine (see the module docstring); subtasks: ONE_SEGMENT (the
    engine's), or a study's BY_CONTACT / BY_CONTACT_BLOCK."""

    name, title = "pusht", "PushT"
    spec = EnvSpec.of(pusht_env, state_ranges=STATE_RANGES, action_ranges=ACTION_RANGES)
    start_names = START_NAMES
    expert = ExpertSpec(PushTExpert, batch=PushTExpert, generator="gen_demos_pusht.py")
    replay = ReplaySpec(
        arms={"pusher": slice(0, 2)},
        action=VelocityCommand({"pusher": slice(0, 2)}, gain=TRACK_GAIN, limit=_LIMIT),
        subtasks=ONE_SEGMENT,
        reach={"pusher": ((-REACH, REACH), (-REACH, REACH))},
        bridge_speed=0.8,  # m/s, the expert's own top speed
        bridge_tol=0.002,  # m: closer, the tracking absorbs the gap
        bridge_moves=(0.002, 0.02),  # m, rad: a bridge that moves the block more has hit it
        resimulate=False,  # contact shows in an observation: a source's recorded frames are read
    )

    def __init__(self, subtasks: tuple[Subtask, ...] | None = None):  # None: ONE_SEGMENT
        if subtasks is not None:
            self.replay = replace(self.replay, subtasks=subtasks)

    def make_env(self, share=None):
        return SharedPushTEnv(share)

    def start_of(self, state) -> tuple:
        s = [float(v) for v in state]
        return (s[2], s[3], math.atan2(s[4], s[5]), s[0], s[1])

    def perturb(self, first_state, rng, how: Perturbation):
        return perturbed_start(first_state, rng, how.pos_sigma, how.yaw_sigma)

    def step_batch(self, envs, actions):
        return step_many(envs, actions)

    def object_pose(self, state) -> np.ndarray:
        return block_pose(state)

    def frame_pose(self, frame: str, state) -> tuple[float, float, float]:
        pose = block_pose(state) if frame == "block" else (state[6], state[7], math.atan2(state[8], state[9]))
        return tuple(float(v) for v in pose)

    def start_distance(self, a, b) -> float:
        return pose_distance(a[:3], b[:3])

    def signals(self, obs, env) -> dict[str, bool]:
        gap = pusht_env.t_signed_distance(obs[0], obs[1], obs[2], obs[3], math.atan2(obs[4], obs[5]))
        return {"contact": gap <= pusht_env.PUSHER_RADIUS + CONTACT_TOL}


PUSHT = register(PushT())
