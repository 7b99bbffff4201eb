"""LeRobot's own PushT (gym-pusht's gym_pusht/PushT-v0: pymunk physics, no MuJoCo) as a data-engine task:
a description, no generation code. Nobody here wrote this env; the engine grows its demos as it grows
ours. The only engine module that imports gym_pusht (at the first env made, not at import).

    env        gymnasium.make("gym_pusht/PushT-v0", obs_type="environment_state_agent_pos") through
               datagen.task.GymnasiumEnv; its observation vector: agent_pos (2,) then
               environment_state (16,) (the block's 8 keypoints), px, float32
    columns    what lerobot/pusht_keypoints records: observation.state = the agent's (x, y),
               observation.environment_state = the 16 keypoint numbers, action = a target (x, y); a
               source frame whose keypoints are no rigid placement of the T (KEYPOINT_TOL) is refused
    start      what reset(options={"reset_to_state": ...}) takes: agent x, y, block x, y, angle
               (START_NAMES). gym-pusht sets the block's position, then turns it about its centre of
               gravity (COG), so the block lands at start_to_pose(start), not at the numbers passed
    perturb    block x, y and agent x, y get Gaussian noise of pos_sigma x PX_PER_M px, the block's
               angle yaw_sigma rad, around a source's first frame; the block stays on the table
               (BLOCK_BOX), the agent inside its spawn box and clear of the T; up to TRIES draws.
               A start is rounded to float32 so that aug.start re-runs it exactly
    expert     datagen.tasks.gym_pusht_expert.GymPushTExpert (position targets through gym-pusht's PD)
    frames     block (its pose recovered from the keypoints: gym_pusht_expert.block_pose_from_keypoints, so
               a set that records only keypoints works), goal (fixed)
    subtasks   one: the whole push relative to the block, entered by a bridge from where the agent is
               (ONE_SEGMENT; GymPushT(ONTO_GOAL), a study's, slides the push's frame onto the goal)
    actions    position targets (px): a replayed step commands the segment's re-expressed target
    success    gym-pusht's own info["is_success"] (coverage of the goal above 0.95; it ends the episode)
    video      (--video) gym-pusht's own render(): the table drawn IMAGE_SIZE square (pygame, no OpenGL),
               with a cross at the last target
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np

from datagen.task import (
    EnvSpec,
    ExpertSpec,
    GymnasiumEnv,
    Perturbation,
    PositionTarget,
    ReplaySpec,
    Subtask,
    Task,
    register,
)
from datagen.tasks.gym_pusht_expert import GymPushTExpert, block_pose_from_keypoints, keypoint_residual
from lerobot_v3 import ENV_STATE_KEY, IMAGE_SIZE

__all__ = [
    "GYM_PUSHT",
    "KEYPOINT_TOL",
    "ONE_SEGMENT",
    "ONTO_GOAL",
    "GymPushT",
    "START_NAMES",
    "keypoint_residual",
    "pose_to_start",
    "start_to_pose",
]

PX_PER_M = 1000.0  # gym-pusht's T is the chapter's T at 1 px = 1 mm: --aug_pos_sigma (m) x this = px
TRIES = 100  # perturbation draws per attempt before "no_valid_start"
START_NAMES = ("agent_x", "agent_y", "block_x", "block_y", "block_angle")  # reset_to_state's order
COG = np.array([0.0, 45.0])  # px, block frame: gym-pusht's centre of gravity
BLOCK_BOX = (100.0, 412.0)  # px: where a perturbed block's pose may land on each axis (the table, less a T)
AGENT_BOX = (50.0, 450.0)  # px: gym-pusht's own spawn range for the agent
AGENT_R = 15.0  # px: the agent's radius
CLEAR = 5.0  # px: the agent's edge at least this far from the T at a start
GOAL = (256.0, 256.0, math.pi / 4)  # gym-pusht's goal pose (px, px, rad)
BOXES = ((-60.0, 60.0, 0.0, 30.0), (-15.0, 15.0, 30.0, 120.0))  # the T's bar and stem (block frame, px)
# px: how far a source frame's keypoints may be from a rigid placement of the T (keypoint_residual).
# Measured on 8,000 gym-pusht frames (random starts and pushes): its own float32 keypoints, as the hub's
# sets store them, are at most 3.6e-5 px off; rounded to whole px, 0.86 px. A T scaled by 1.05 is 3.8 px
# off; scaled x2 or collapsed onto a point, 76 px; mirrored (x -> 512 - x), 120 px.
KEYPOINT_TOL = 2.0


ONE_SEGMENT = (Subtask("push", ("block",)),)  # the engine's: the whole push relative to the block
ONTO_GOAL = (Subtask("push", ("block",), onto=("goal",)),)  # a study's: its frame sliding onto the goal

STATE_NAMES = ("agent_x", "agent_y")  # observation.state: the agent's position (px)
KEYPOINT_NAMES = tuple(f"keypoint_{i}_{a}" for i in range(8) for a in "xy")  # px
# What a LeRobot set of this task records (lerobot/pusht_keypoints' columns) and the engine steps
SPEC = EnvSpec(
    state_names=STATE_NAMES,
    action_names=("target_x", "target_y"),  # the agent's position target (px)
    fps=10,
    robot_type="gym_pusht",
    task="Push the T-shaped block onto the T-shaped target.",
    max_steps=300,  # gym-pusht's registered limit
    env_state_names=KEYPOINT_NAMES,  # observation.environment_state
    obs_names=STATE_NAMES + KEYPOINT_NAMES,  # the engine's observation vector
    state_ranges=dict.fromkeys(STATE_NAMES + KEYPOINT_NAMES, (-512.0, 1024.0)),  # px: keypoints may overhang
    action_ranges=dict.fromkeys(("target_x", "target_y"), (0.0, 512.0)),  # px: gym-pusht's action space
    packages=("gym-pusht", "pymunk", "shapely"),  # the env, its physics, its success (the goal's coverage)
    records_reward=True,  # next.reward (gym-pusht's: the goal's coverage over 95%, at most 1) and next.done
)


def _rot(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def start_to_pose(start) -> np.ndarray:
    """Where reset_to_state puts the block: (x, y, angle) of its centre of gravity."""
    xy = np.asarray(start[2:4], np.float64)
    return np.array([*(xy + COG - _rot(start[4]) @ COG), start[4]])


def pose_to_start(agent, pose) -> tuple[float, ...]:
    """The reset_to_state numbers that put the agent at `agent` and the block at `pose` (start_to_pose's
    inverse), rounded to float32 so that a stored aug.start is the start itself."""
    xy = np.asarray(pose[:2], np.float64) - COG + _rot(pose[2]) @ COG
    angle = math.remainder(float(pose[2]), math.tau)
    return tuple(float(np.float32(v)) for v in (agent[0], agent[1], xy[0], xy[1], angle))


def clear_of_t(agent, pose) -> bool:
    """Whether an agent at `agent` (px) keeps CLEAR px between its edge and the T at `pose`."""
    x, y = _rot(-pose[2]) @ (np.asarray(agent, np.float64) - pose[:2]) + COG  # the block's frame
    gap = min(math.hypot(max(x0 - x, 0, x - x1), max(y0 - y, 0, y - y1)) for x0, x1, y0, y1 in BOXES)
    return gap >= AGENT_R + CLEAR


def _observe(obs) -> np.ndarray:
    return np.concatenate([obs["agent_pos"], obs["environment_state"]]).astype(np.float32)


class GymPushT(Task):
    """gym-pusht's description for the engine (see the module docstring)."""

    name, title = "gym_pusht", "gym-pusht (LeRobot's PushT)"
    spec = SPEC
    start_names = START_NAMES
    expert = ExpertSpec(GymPushTExpert, noise_unit="px")  # the expert's noise is on its position targets
    replay = ReplaySpec(
        arms={"agent": slice(0, 2)},
        action=PositionTarget({"agent": slice(0, 2)}, low=0.0, high=512.0),
        subtasks=ONE_SEGMENT,
        reach={"agent": ((0.0, 512.0), (0.0, 512.0))},  # px: a target outside the action space is none
        bridge_speed=300.0,  # px/s: the expert's top pushing speed
        bridge_tol=120.0,  # px: how far ahead of the agent the expert's own targets lead (0.2 s x 600 px/s)
        bridge_moves=(2.0, 0.02),  # px, rad: a bridge that moves the block more has hit it
        follow_tol=(2.0, 0.02),  # px, rad: replay_live re-anchors beyond this (PushT's 2 mm at 1 px = 1 mm)
    )

    def __init__(self, subtasks: tuple[Subtask, ...] | None = None):  # None: ONE_SEGMENT
        if subtasks is not None:
            self.replay = replace(self.replay, subtasks=subtasks)

    def make_env(self, share=None):
        import gymnasium

        # pygame's "pkg_resources is deprecated" notice: gym-pusht's env module imports pygame (its own
        # filter there misses the notice's category), and gymnasium.make would import that module outside
        # this block, so it is imported here
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "pkg_resources is deprecated")
            import gym_pusht.envs  # noqa: F401  (registers gym_pusht/PushT-v0; the env module, pygame)

        # the checker warns when a keypoint of a block at the table's edge leaves [0, 512]: gym-pusht's own
        # frames (--video): gym-pusht's own drawing (pygame, no OpenGL), IMAGE_SIZE square, made at render()
        # alone; its cross marks the last target
        size = dict(visualization_width=IMAGE_SIZE, visualization_height=IMAGE_SIZE)
        env = gymnasium.make(
            "gym_pusht/PushT-v0",
            obs_type="environment_state_agent_pos",
            disable_env_checker=True,
            render_mode="rgb_array",
            **size,
        )
        return GymnasiumEnv(env, _observe)

    def start_of(self, state) -> tuple:
        return pose_to_start(state[:2], self.object_pose(state))

    def perturb(self, first_state, rng, how: Perturbation):
        pose, agent = self.object_pose(first_state), np.asarray(first_state[:2], np.float64)
        sigma = how.pos_sigma * PX_PER_M
        for _ in range(TRIES):
            new = pose + (rng.normal(0, sigma), rng.normal(0, sigma), rng.normal(0, how.yaw_sigma))
            at = agent + (rng.normal(0, sigma), rng.normal(0, sigma))
            on_table = all(BLOCK_BOX[0] <= v <= BLOCK_BOX[1] for v in new[:2])
            if on_table and all(AGENT_BOX[0] <= v <= AGENT_BOX[1] for v in at) and clear_of_t(at, new):
                return pose_to_start(at, new)
        return None

    def state_problem(self, states):
        off = keypoint_residual(np.asarray(states)[:, 2:18])
        bad = off > KEYPOINT_TOL
        if not bad.any():
            return None
        row = int(np.argmax(bad))
        return row, (
            f"its 8 keypoints ({ENV_STATE_KEY}) are not a rigid placement of the T: {off[row]:.3g} px off "
            f"the best fit, more than the {KEYPOINT_TOL:g} px allowed ({int(bad.sum())} of {len(off)} frames)"
        )

    def object_pose(self, state) -> np.ndarray:
        return np.array(block_pose_from_keypoints(np.asarray(state[2:18], np.float64)))

    def frame_pose(self, frame: str, state) -> tuple[float, float, float]:
        return GOAL if frame == "goal" else tuple(float(v) for v in self.object_pose(state))

    def start_distance(self, a, b) -> float:
        pa, pb = start_to_pose(a), start_to_pose(b)  # block poses; an angle weighs as the T's half-width
        return math.hypot(*(pa[:2] - pb[:2])) + 60.0 * abs(math.remainder(pa[2] - pb[2], math.tau))


GYM_PUSHT = register(GymPushT())
