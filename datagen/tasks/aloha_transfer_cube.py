"""LeRobot's ALOHA transfer-cube (gym-aloha's AlohaTransferCube-v0, ACT's sim_transfer_cube) as a
data-engine task: two ViperX 300s arms in 3-D, the model files of the gym-aloha wheel on our mujoco
(datagen/tasks/aloha_sim.py, which says what of gym-aloha's code it re-states).

    env        datagen.tasks.aloha_sim.TransferCubeEnv (joint-controlled, 50 fps) through
               datagen.task.GymnasiumEnv;
               its observation: the 14 numbers of observation.state, then the cube's pose (7)
    columns    what lerobot/aloha_sim_transfer_cube_* record: observation.state and action = per arm, left
               first, 6 joint angles (rad) and a normalized gripper (0 closed, 1 open: the fingers'
               position in the state, the command in the action); observation.environment_state = the
               cube's position (m) and quaternion (w first), so that state-based policies train on CPU
    start      the cube's pose (START_NAMES), the arms at gym-aloha's START_ARM_POSE; reset(seed) draws it
               as gym-aloha's reset(seed=seed) does (uniform on x [0, 0.2], y [0.4, 0.6] m, upright)
    perturb    the cube's (x, y) gets Gaussian noise of pos_sigma m, re-drawn (up to TRIES) until inside
               gym-aloha's range; it stays upright (gym-aloha never turns it)
    success    gym-aloha's: TransferCubeTask.get_reward's top stage (the left fingers touch the cube and
               the cube does not touch the table), which ends the episode
    expert     datagen.tasks.aloha_sim_expert.TransferCubeExpert (ACT's PickAndTransferPolicy's waypoints,
               through inverse kinematics), noise in m on the grasp points' targets
    frames     the cube, in SE(3), and the world (the meeting point in the air is fixed, as in ACT's script)
    subtasks   pick (the right arm relative to the cube, the left to the world; it ends when the cube is
               lifted 2 cm) and handover (both arms relative to the world)
    extra      action.end_effector: the end-effector targets each frame's joint action encodes (per arm, the
               grasp point (m) and the gripper's orientation quaternion), as ACT's scripted data drive them
    arms       left and right, each its grasp point (datagen.tasks.aloha_sim.gripper_pose) and orientation,
               read through the model's kinematics from the joints an observation (or an action) holds
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from datagen.poses import quat_of, rotation_of
from datagen.task import (
    ActionKind,
    EnvSpec,
    ExpertSpec,
    GymnasiumEnv,
    Perturbation,
    ReplaySpec,
    Subtask,
    Task,
    register,
)
from datagen.tasks.aloha_sim import CUBE_RANGE, FPS, gripper_pose, ik, model, scratch
from datagen.tasks.aloha_sim_expert import STEPS, TransferCubeExpert

__all__ = ["ALOHA_TRANSFER_CUBE", "AlohaTransferCube", "MOTORS", "SPEC", "START_NAMES"]

MAX_STEPS = STEPS  # control steps (8 s at 50 fps): ACT's episode_len, the hub sets' 400 frames
TRIES = 100  # perturbation draws before "no_valid_start"
# lerobot/aloha_sim_transfer_cube_*'s motor names, in its order
MOTORS = tuple(
    f"{side}_{j}"
    for side in ("left", "right")
    for j in ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate", "gripper")
)
START_NAMES = ("cube_x", "cube_y", "cube_z", "cube_qw", "cube_qx", "cube_qy", "cube_qz")  # m; quaternion
CUBE = slice(14, 21)  # the cube's pose in an observation
JOINTS = (slice(0, 6), slice(7, 13))  # each arm's joints in an observation or an action
GRIP = (6, 13)
ARMS = ("left", "right")
# m: the cube's centre at rest on the table (half its side); LIFT above it ends the pick. Not gym-aloha's
# stage 2 (the right fingers touch it, off the table): that names one finger of the two, and 3 of 100
# held-out expert episodes lift the cube without it ever showing
REST_Z, LIFT = 0.02, 0.02
# the end-effector targets' column: per arm, left first, the grasp point (m) and the gripper's orientation
EE_KEY = "action.end_effector"
EE_NAMES = tuple(f"{side}_{n}" for side in ARMS for n in ("x", "y", "z", "qw", "qx", "qy", "qz"))
SPEC = EnvSpec(
    state_names=MOTORS,
    action_names=MOTORS,
    fps=FPS,
    robot_type="aloha",  # the hub sets' own
    task="Pick up the cube with the right arm and transfer it to the left arm.",
    max_steps=MAX_STEPS,
    env_state_names=START_NAMES,
    obs_names=MOTORS + START_NAMES,
    packages=("gym-aloha", "mujoco"),  # its model files and the physics
    records_reward=True,  # gym-aloha's reward stages, as lerobot's sets of its env carry next.reward
    frame_features={  # the end-effector targets each frame's joint action encodes (JointIK.to_target)
        EE_KEY: {"dtype": "float32", "shape": (len(EE_NAMES),), "names": list(EE_NAMES)}
    },
)
# A recorded quaternion's norm may differ from 1 by float32 rounding (~1e-7: MuJoCo normalises its free
# joints' quaternions every step); one farther off (all zeros, a hand-edited pose) is no rotation at all
QUAT_TOL = 1e-3
TARGET_IK_ITERS = 20  # a replayed step's IK from the observed joints (the expert's runs from its last solve)
SUBTASKS = (  # the engine's: per arm (left, right), the frame its motion is relative to
    Subtask("pick", ("world", "object"), ends="lifted"),  # the right arm grasps and lifts the cube
    Subtask("handover", ("world", "world")),  # both meet at a fixed point in the air, as ACT's script does
)
WHOLE = (Subtask("whole", ("object", "object")),)  # MimicGen's move without subtasks, for contrast


def _observe(obs) -> np.ndarray:
    return np.asarray(obs, np.float32)


def _poses(d: mujoco.MjData, joints) -> list:
    """Each arm's grasp point and orientation for the joint angles in `joints` (an observation or action)."""
    j = np.asarray(joints, np.float64)
    d.qpos[0:6], d.qpos[8:14] = j[JOINTS[0]], j[JOINTS[1]]
    mujoco.mj_kinematics(d.model, d)
    return [gripper_pose(d.model, d, arm) for arm in (0, 1)]


@dataclass(frozen=True)
class JointIK(ActionKind):
    """The arms' action: per arm (left, right) 6 joint angles and a gripper command. A source's targets are
    the grasp points and orientations its joint actions put each gripper at (forward kinematics of
    gym-aloha's `scene`); a replayed step is the joints inverse kinematics finds for each re-expressed
    target, from the joints the observation holds (TARGET_IK_ITERS)."""

    scene: str  # gym-aloha's model (aloha_sim.model)

    def to_target(self, task, states, actions) -> dict:
        poses = [_poses(scratch(self.scene), a) for a in np.asarray(actions, np.float64)]
        a = np.asarray(actions, np.float64)
        return {
            name: (
                np.stack([p[i][0] for p in poses]),
                None,
                a[:, GRIP[i]],
                np.stack([p[i][1] for p in poses]),
            )
            for i, name in enumerate(ARMS)
        }

    def to_action(self, task, obs, waypoints, velocities, grips, orientations=None) -> np.ndarray:
        m, d = model(self.scene), scratch(self.scene)
        o = np.asarray(obs, np.float64)
        d.qpos[0:6], d.qpos[8:14] = o[JOINTS[0]], o[JOINTS[1]]
        action = np.zeros(14)
        for i, name in enumerate(ARMS):
            q = ik(m, d, i, o[JOINTS[i]], waypoints[name], orientations[name], TARGET_IK_ITERS)
            action[JOINTS[i]], action[GRIP[i]] = q, grips[name]
        return action.astype(np.float32)


class AlohaTransferCube(Task):
    """gym-aloha's transfer-cube for the engine (see the module docstring)."""

    name, title = "aloha_transfer_cube", "ALOHA transfer-cube (gym-aloha's ViperX sim)"
    spec = SPEC
    start_names = START_NAMES
    expert = ExpertSpec(TransferCubeExpert, noise_unit="m (on the grasp points' targets)")
    replay = ReplaySpec(
        arms={"left": JOINTS[0], "right": JOINTS[1]},  # the joints that place each grasp point (arm_pose)
        action=JointIK("transfer_cube"),
        subtasks=SUBTASKS,
        resimulate=False,  # "lifted" shows in an observation
    )
    scene, objects = "transfer_cube", CUBE  # gym-aloha's model (aloha_sim.model); the objects' obs columns

    def __init__(self, subtasks: tuple[Subtask, ...] | None = None):  # None: SUBTASKS
        if subtasks is not None:
            self.replay = replace(self.replay, subtasks=subtasks)

    def make_env(self, share=None):
        from datagen.tasks.aloha_sim import TransferCubeEnv

        env = TransferCubeEnv(MAX_STEPS, share=None if share is None else share.env)
        return GymnasiumEnv(env, _observe)

    def start_of(self, state) -> tuple:
        return tuple(float(v) for v in state[self.objects])

    def perturb(self, first_state, rng, how: Perturbation):
        start = self.start_of(first_state)
        for _ in range(TRIES):
            xy = np.array(start[:2]) + rng.normal(0, how.pos_sigma, 2)
            if all(lo <= v <= hi for v, (lo, hi) in zip(xy, CUBE_RANGE)):  # float32: aug.start re-runs it
                return tuple(float(np.float32(v)) for v in xy) + start[2:]
        return None

    def state_problem(self, states):
        # each object's pose is 7 numbers, its quaternion the last 4: one that is no unit quaternion is no
        # orientation (rotation_of would divide by its zero norm, or scale), and no env was ever in it
        s = np.asarray(states, np.float64)[:, self.objects]
        norms = np.linalg.norm(s.reshape(len(s), -1, 7)[:, :, 3:], axis=2)  # (frames, objects)
        off = np.abs(norms - 1.0) > QUAT_TOL
        bad = off.any(axis=1)
        if not bad.any():
            return None
        row = int(np.argmax(bad))
        k = int(np.argmax(off[row]))  # the object at fault
        names = ", ".join(self.start_names[7 * k + 3 : 7 * k + 7])
        return row, (
            f"its quaternion ({names}) has norm {norms[row, k]:.3g}, not 1: no orientation "
            f"({int(bad.sum())} of {len(bad)} frames)"
        )

    def object_pose(self, state) -> np.ndarray:
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = rotation_of(state[CUBE][3:]), state[CUBE][:3]
        return out

    def frame_pose(self, frame: str, state) -> np.ndarray:
        return self.object_pose(state) if frame == "object" else np.eye(4)

    def signals(self, obs, env) -> dict[str, bool]:
        return {"lifted": bool(obs[CUBE][2] > REST_Z + LIFT)}

    def arm_pose(self, arm: str, obs, env):
        return _poses(scratch(self.scene), obs)[ARMS.index(arm)]

    def frame_columns(self, states, actions) -> dict[str, np.ndarray]:
        targets = self.replay.action.to_target(self, states, actions)
        per_arm = [np.concatenate([t[0], [quat_of(r) for r in t[3]]], axis=1) for t in targets.values()]
        return {EE_KEY: np.concatenate(per_arm, axis=1).astype(np.float32)}


ALOHA_TRANSFER_CUBE = register(AlohaTransferCube())
