"""Gymnasium's MuJoCo Pusher-v5 as a data-engine task (datagen.task.Task): a 7-DoF arm in 3-D, an env
nobody here wrote, described on the engine's SE(3) contract. The only engine module that imports it
(gymnasium's MuJoCo envs, at the first env made, not at import).

    env        gymnasium.make("Pusher-v5", max_episode_steps=MAX_STEPS) under PoseControl (below),
               through datagen.task.GymnasiumEnv; its observation is Pusher-v5's own 23 numbers
               (float32): qpos[:7] rad, qvel[:7] rad/s, then the world positions (m) of tips_arm (the
               wrist centre, the frame of the hand's U), the object and the goal
    action     the hand's pose target (ACTION_NAMES): position (m) and orientation quaternion (w, x, y,
               z), world frame. PoseControl turns it into Pusher-v5's own action, 7 joint torques (N.m),
               with the robot's controller (datagen.tasks.pusher_expert.controller: damped least squares on
               the model's Jacobian, computed-torque joint PD), as MimicGen's robots take pose targets
               through their operational-space controller
    success    Pusher-v5 has none: the object's centre within GOAL_TOL m of the goal's in xy; the
               episode ends there (or after MAX_STEPS control steps, 20 Hz)
    start      the arm's joint angles and speeds, the object's and the goal's (x, y) (START_NAMES),
               set through MuJoCo's state (env.unwrapped.set_state), all of it, so a start replays
    perturb    the object's (x, y) gets Gaussian noise of pos_sigma m, re-drawn (up to TRIES) until it
               lies where Pusher-v5's reset puts it (OBJECT_BOX from the goal, more than MIN_GAP m off
               it); the arm's state and the goal are kept
    expert     datagen.tasks.pusher_expert.PusherExpert (hover, descend, push with the hand's U), noise in m
               on the target position
    frames     object (its position; a cylinder on two slides: it never turns) and goal, in SE(3)
    subtasks   approach (relative to the object, ends when the object sits in the hand's U: "held")
               and push (relative to the object, its frame sliding onto the goal over the push, as
               PushT's by-contact study has it): one arm, the hand, whose targets carry an orientation
    actions    a replayed step commands the segment's re-expressed target pose, as it is (the robot's
               controller tracks it)
"""

from __future__ import annotations

import math
from dataclasses import replace

import mujoco
import numpy as np

from datagen.task import (
    EnvSpec,
    ExpertSpec,
    GymnasiumEnv,
    Perturbation,
    PoseTarget,
    ReplaySpec,
    Subtask,
    Task,
    register,
)
from datagen.tasks.pusher_expert import PoseControl, PusherExpert, hand_rotation, held, model

__all__ = ["PUSHER", "Pusher", "START_NAMES", "SUBTASKS", "SPEC", "WHOLE"]

MAX_STEPS = 200  # control steps (10 s at 20 Hz): Pusher-v5's registered 100 cut off 16% of the expert's
# held-out pushes (its slowest took 123 steps, 190 under 1 N.m of torque noise)
GOAL_TOL = 0.05  # m: the object's centre this close to the goal's, in xy, is success
TRIES = 100  # perturbation draws before "no_valid_start"
OBJECT_BOX = ((-0.2, 0.2), (-0.3, 0.0))  # m: the object's (x, y) offset from the goal that reset draws
MIN_GAP = 0.17  # m: reset keeps the object at least this far from the goal
JOINTS = (
    "shoulder_pan",
    "shoulder_lift",
    "upper_arm_roll",
    "elbow_flex",
    "forearm_roll",
    "wrist_flex",
    "wrist_roll",
)
ARM = tuple(f"q_{j}" for j in JOINTS) + tuple(f"qd_{j}" for j in JOINTS)  # rad, rad/s
START_NAMES = ARM + ("object_x", "object_y", "goal_x", "goal_y")


STATE_NAMES = ARM + ("hand_x", "hand_y", "hand_z")  # the hand: tips_arm, the wrist centre (m)
ENV_STATE_NAMES = ("object_x", "object_y", "object_z", "goal_x", "goal_y", "goal_z")  # m
# What a LeRobot set of this task records: the arm in observation.state, the objects beside it
SPEC = EnvSpec(
    state_names=STATE_NAMES,
    action_names=("target_x", "target_y", "target_z", "target_qw", "target_qx", "target_qy", "target_qz"),
    fps=20,  # Pusher-v5's dt: 5 MuJoCo steps of 0.01 s
    robot_type="gymnasium_pusher",
    task="Push the cylinder onto the goal.",
    max_steps=MAX_STEPS,
    env_state_names=ENV_STATE_NAMES,
    obs_names=STATE_NAMES + ENV_STATE_NAMES,  # Pusher-v5's own observation, in order
    packages=("gymnasium", "mujoco"),  # Pusher-v5's env code and its physics
)


HAND, OBJECT, GOAL = slice(14, 17), slice(17, 20), slice(20, 23)  # observation columns
SUBTASKS = (  # the engine's: the approach relative to the object, then the push sliding onto the goal
    Subtask("approach", ("object",), ends="held"),
    Subtask("push", ("object",), bridge=False, onto=("goal",)),
)
WHOLE = (Subtask("push", ("object",)),)  # MimicGen's move without subtasks, for contrast (tools.replay yield)


def _pose(position) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = position
    return out


def _reached(obs, info) -> bool:
    return bool(np.hypot(*(obs[OBJECT][:2] - obs[GOAL][:2])) < GOAL_TOL)


def _scratch(env) -> mujoco.MjData:
    """A scratch MjData for the hand's kinematics: the env's controller's (PoseControl.scratch: it reloads
    its state every step), or a new one where there is no env (a source cut from its recorded frames)."""
    return mujoco.MjData(model()) if env is None else env.env.scratch


def _observe(obs) -> np.ndarray:
    return np.asarray(obs, np.float32)


class Pusher(Task):
    """Pusher-v5's description for the engine (see the module docstring)."""

    name, title = "pusher", "Pusher (Gymnasium's Pusher-v5)"
    spec = SPEC
    start_names = START_NAMES
    expert = ExpertSpec(PusherExpert, noise=0.005, noise_unit="m (on the hand's target position)")
    replay = ReplaySpec(
        arms={"hand": HAND},
        action=PoseTarget({"hand": slice(0, 7)}),  # the robot's controller tracks the pose target
        subtasks=SUBTASKS,
        # m: the robot's controller approaches any target itself (its error clipped to 0.15 m a step), so
        # the engine's bridge would only replace that approach with another: zero-perturbation replays of
        # 40 sources reproduced 34 with bridges beyond 1 cm, 40 without (docs/replay.md)
        bridge_tol=math.inf,
        resimulate=False,  # "held" shows in an observation
    )

    def __init__(self, subtasks: tuple[Subtask, ...] | None = None):  # None: SUBTASKS
        if subtasks is not None:
            self.replay = replace(self.replay, subtasks=subtasks)

    def make_env(self, share=None):
        import gymnasium  # its MuJoCo envs load here, when the task runs

        env = PoseControl(gymnasium.make("Pusher-v5", max_episode_steps=MAX_STEPS))
        return GymnasiumEnv(env, _observe, success=_reached, set_start=lambda e, start: e.place(start))

    def start_of(self, state) -> tuple:
        s = [float(v) for v in state]
        return tuple(s[:14] + s[17:19] + s[20:22])

    def perturb(self, first_state, rng, how: Perturbation):
        start = self.start_of(first_state)
        goal = np.array(start[16:18])
        for _ in range(TRIES):
            obj = np.array(start[14:16]) + rng.normal(0, how.pos_sigma, 2)
            off = obj - goal
            inside = all(lo <= v <= hi for v, (lo, hi) in zip(off, OBJECT_BOX))
            if inside and np.hypot(*off) > MIN_GAP:  # float32, so that aug.start re-runs it exactly
                return start[:14] + tuple(float(np.float32(v)) for v in obj) + start[16:]
        return None

    def object_pose(self, state) -> np.ndarray:
        return _pose(state[OBJECT])

    def frame_pose(self, frame: str, state) -> np.ndarray:
        return _pose(state[OBJECT] if frame == "object" else state[GOAL])

    def signals(self, obs, env) -> dict[str, bool]:
        return {"held": held(obs, _scratch(env))}

    def arm_pose(self, arm: str, obs, env):
        return np.asarray(obs[HAND], np.float64), hand_rotation(obs, _scratch(env))


PUSHER = register(Pusher())
