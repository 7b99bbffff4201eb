"""The ALOHA cube handoff as a data-engine task (datagen.task.Task): a description, no generation code.
The only engine module that imports aloha_env and its expert.

    arms       right and left end-effector: (x, y) in observation columns 0, 1 and 3, 4; a gripper
               command in action columns 2 and 5; each reaches its slide joints' range (REACH)
    start      cube, target, right and left end-effector (x, y) each (START_NAMES: env.set_start's)
    perturb    each of the four points gets Gaussian noise of pos_sigma (m) on x and y, re-drawn (up to
               TRIES times) until it lies in its spawn region (REGIONS): a start reset() could have drawn
    expert     the noise-free AlohaExpert
    frames     cube (its position, read live), target, handoff (the expert's HANDOFF_X at the target's
               y); none turns (the cube is a point on a planar table)
    signals    grasp: the right gripper holds the cube; handoff: the left one holds it and the right one
               has let go (the env's grasp rule, env.holding)
    subtasks   the handoff's three, cut at the signals, both arms in step:

        subtask      ends at    right arm frame   left arm frame
        reach_grasp  grasp      cube              handoff
        handoff      handoff    handoff           handoff     (coordination)
        carry_place  (the end)  handoff           target

    actions    velocities (m/s) plus gripper commands: a replayed step commands, per arm, the segment's
               velocity plus TRACK_GAIN times the waypoint error, and the segment's gripper command; after
               the plan the arms hold still for SUCCESS_HOLD steps so the success hold can complete
    nearest    the source whose cube and target start nearest (object_distance)

Aloha(subtasks=WHOLE) replays the whole demo as one segment with both arms relative to the cube:
MimicGen's move without its subtasks, for contrast (tools.replay yield).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

import aloha_env
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
from datagen.tasks.fast_experts import AlohaBatch
from scripted_expert import AlohaExpert

__all__ = [
    "ALOHA",
    "Aloha",
    "START_NAMES",
    "STATE_RANGES",
    "SUBTASKS",
    "WHOLE",
    "perturbed_start",
    "start_of",
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
XY = {"right": slice(0, 2), "left": slice(3, 5)}  # an arm's (x, y) in the observation, (vx, vy) in the action
GRIP = {"right": 2, "left": 5}  # an arm's gripper command in the action
SUBTASKS = (
    Subtask("reach_grasp", ("cube", "handoff"), ends="grasp"),
    Subtask("handoff", ("handoff", "handoff"), ends="handoff"),
    Subtask("carry_place", ("handoff", "target")),
)
WHOLE = (Subtask("whole", ("cube", "cube")),)
TRACK_GAIN = 5.0  # 1/s: velocity added per m of waypoint error (halves an error every 0.1 s step)
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
    """START_NAMES near the start `first_state` (an obs), or None if a point found no valid draw: a pure
    function of (first_state, rng state, pos_sigma)."""
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


def object_distance(a, b) -> float:
    """Distance (m) between the object poses of two starts (START_NAMES): cube shift plus target shift."""
    return math.hypot(a[0] - b[0], a[1] - b[1]) + math.hypot(a[2] - b[2], a[3] - b[3])


class Aloha(Task):
    """The ALOHA handoff's description for the engine (see the module docstring). A perturbation moves
    cube, target and both end-effectors by pos_sigma (m) each (yaw_sigma is not read: nothing turns)."""

    name, title = "aloha", "ALOHA"
    spec = EnvSpec.of(aloha_env, state_ranges=STATE_RANGES, action_ranges=ACTION_RANGES)
    start_names = START_NAMES
    expert = ExpertSpec(
        AlohaExpert,
        noise_unit="m/s, grip commands alike (-1..1)",  # one std on all six action numbers
        batch=AlohaBatch,
        generator="gen_demos_aloha.py",
    )
    replay = ReplaySpec(
        arms=XY,
        action=VelocityCommand(XY, gain=TRACK_GAIN, limit=1.0, grips=GRIP),  # the env clips to [-1, 1]
        subtasks=SUBTASKS,
        reach=REACH,
        bridge_speed=AlohaExpert.MAX_SPEED,  # m/s, the expert's own top speed, so a bridge looks like it
        bridge_tol=1e-6,  # m: an arm this close to its first waypoint needs no bridge
        hold_steps=aloha_env.SUCCESS_HOLD,
    )

    def __init__(self, subtasks: tuple[Subtask, ...] | None = None):  # None: SUBTASKS
        if subtasks is not None:
            self.replay = replace(self.replay, subtasks=subtasks)

    def make_env(self, share=None):
        return aloha_env.AlohaCubeEnv(share.model if share is not None else None)

    def start_of(self, state) -> tuple:
        return start_of(state)

    def perturb(self, first_state, rng, how: Perturbation):
        return perturbed_start(first_state, rng, how.pos_sigma)

    def object_pose(self, state) -> np.ndarray:
        return np.array([float(state[6]), float(state[7]), 0.0])  # the cube (x, y m); it never turns

    def frame_pose(self, frame: str, state) -> tuple[float, float, float]:
        if frame == "cube":
            return (float(state[6]), float(state[7]), 0.0)
        if frame == "target":
            return (float(state[8]), float(state[9]), 0.0)
        return (AlohaExpert.HANDOFF_X, float(state[9]), 0.0)  # handoff: the expert's (HANDOFF_X, target y)

    def start_distance(self, a, b) -> float:
        return object_distance(a, b)

    def signals(self, obs, env) -> dict[str, bool]:  # the grasp rule lives in the physics: re-simulated
        right, left = env.holding
        return {"grasp": right, "handoff": left and not right}


ALOHA = register(Aloha())
