"""The scripted transfer-cube expert (datagen/aloha_transfer_cube.py's), in end-effector space as ACT's
PickAndTransferPolicy is: per arm, waypoints (time step, grasp-point position, gripper orientation,
gripper command 0 closed .. 1 open) relative to the cube and to a meeting point in the air, interpolated
(position linearly, orientation by slerp); the right arm grasps the cube from above, tilted, and carries
it to the meeting point; the left arm comes in from the side, closes across it, and the right lets go.

Each step's waypoint becomes the joint action the lerobot/aloha_sim_* sets record (6 joint targets and a
normalized gripper per arm) by inverse kinematics on the joint-controlled model (datagen.aloha_sim.ik,
from the last step's solution): ACT drove the same waypoints through the end-effector model's mocap welds
and replayed the joints they gave, which on mujoco 4 track too loosely to grasp (datagen/aloha_sim.py).
The plan is made from the first observation (the cube's pose); the left arm's approach is planned again
when the right arm reaches the meeting point, relative to the cube as it then lies in the right hand.
"""

from __future__ import annotations

import mujoco
import numpy as np

from datagen.aloha_sim import START_ARM_POSE, gripper_pose, ik, model
from datagen.poses import slerp

__all__ = ["TransferCubeExpert", "handover", "plan"]

CUBE = slice(14, 17)  # the cube's position in an observation
MEET = np.array([0.0, 0.5, 0.25])  # m: where the hand-over happens (ACT's meet_xyz)
GRASP = np.array([0.0, 0.0, 0.0])  # m: the right grasp point from the cube's centre on the table
ABOVE = 0.08  # m: the right gripper comes down from this far above the cube
PICK_TILT = 60.0  # deg: the right gripper points down this far below horizontal (ACT's)
LEFT_IN = np.array([-0.01, 0.0, 0.0])  # m: the left grasp point from the held cube's centre
MET = 220  # the step the right arm reaches MEET with the cube: the left arm's approach is planned then
STEPS = 400  # the plan's length (ACT's episode_len for transfer-cube)


def _frame(forward, closing) -> np.ndarray:
    """The gripper orientation (3, 3) whose x points `forward` and whose fingers close along `closing`."""
    x = np.asarray(forward, np.float64) / np.linalg.norm(forward)
    y = np.asarray(closing, np.float64)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=1)


def plan(cube, start_left, start_right) -> tuple[list, list]:
    """The waypoints (t, position (3,), orientation (3, 3), gripper 0..1) of the left and the right grasp
    point for a cube at `cube` (x, y, z), from the arms' start poses ((position, orientation) each): ACT's
    PickAndTransferPolicy's, the right arm's relative to the cube, the left arm's waiting beside MEET
    until handover() re-plans it relative to the cube in the right hand."""
    box = np.asarray(cube[:3], np.float64)
    tilt = np.radians(PICK_TILT)
    pick = _frame([-np.cos(tilt), 0, -np.sin(tilt)], [0, -1, 0])  # the right arm faces -x
    side = _frame([1, 0, 0], [0, 0, 1])  # the left gripper's fingers close vertically (ACT's 90 deg about x)
    left = [
        (0, *start_left, 0),  # sleep
        (100, MEET + [-0.12, 0, 0], side, 1),  # beside the meeting point
        (STEPS, MEET + [-0.12, 0, 0], side, 1),  # wait there (handover replaces the rest)
    ]
    grasp = box + GRASP
    right = [
        (0, *start_right, 0),  # sleep
        (90, grasp + [0, 0, ABOVE], pick, 1),  # above the cube
        (130, grasp, pick, 1),  # down
        (170, grasp, pick, 0),  # close the gripper
        (200, MEET + [0.05, 0, 0], pick, 0),  # approach the meeting point
        (MET, MEET, pick, 0),  # move to it
        (310, MEET, pick, 1),  # open the gripper
        (360, MEET + [0.1, 0, 0], pick, 1),  # move right
        (STEPS, MEET + [0.1, 0, 0], pick, 1),  # stay
    ]
    return left, right


def handover(left: list, held) -> list:
    """The left arm's waypoints from MET on, relative to the cube `held` (its position (3,) in the right
    hand at MET): level with it beside it, in around it, close, pull left."""
    at = np.asarray(held[:3], np.float64) + LEFT_IN
    _, p0, r0, _ = left[1]
    return left[:2] + [
        (MET, p0, r0, 1),  # where it waited
        (MET + 30, at + [-0.08, 0, 0], r0, 1),  # level with the cube, beside it
        (270, at, r0, 1),  # around it
        (310, at, r0, 0),  # close the gripper
        (360, at + [-0.1, 0, 0], r0, 0),  # pull left
        (STEPS, at + [-0.1, 0, 0], r0, 0),  # stay
    ]


def _at(waypoints, t: int):
    """(position, orientation, gripper) at step t between the waypoints around it."""
    i = max(k for k, w in enumerate(waypoints[:-1]) if w[0] <= t)
    (t0, p0, r0, g0), (t1, p1, r1, g1) = waypoints[i], waypoints[i + 1]
    s = min((t - t0) / (t1 - t0), 1.0)
    return p0 + (np.asarray(p1) - p0) * s, slerp(r0, r1, s), g0 + (g1 - g0) * s


class TransferCubeExpert:
    """act(obs) -> the joint action (14,) float32 of the plan for the cube the first observation shows;
    noise: std (m) of Gaussian noise on each grasp point's target position, drawn from `seed`."""

    def __init__(self, noise: float = 0.0, seed: int | None = None):
        self.noise, self.seed = float(noise), seed
        self.model = model()
        self.scratch = mujoco.MjData(self.model)  # the IK's kinematics
        self.reset()

    def reset(self) -> None:
        self.t = 0
        self.waypoints = None
        self.q = [START_ARM_POSE[0:6].copy(), START_ARM_POSE[8:14].copy()]
        self.rng = np.random.default_rng(self.seed)

    def act(self, obs) -> np.ndarray:
        m, d = self.model, self.scratch
        if self.waypoints is None:  # the first observation: the plan from the arms' start poses
            d.qpos[:16] = START_ARM_POSE
            mujoco.mj_kinematics(m, d)
            self.waypoints = plan(obs[CUBE], gripper_pose(m, d, 0), gripper_pose(m, d, 1))
        if self.t == MET:  # the cube is in the right hand: the left arm's approach is planned to where it is
            self.waypoints = (handover(self.waypoints[0], obs[CUBE]), self.waypoints[1])
        action = np.zeros(14)
        for arm in (0, 1):
            position, rotation, grip = _at(self.waypoints[arm], min(self.t, STEPS))
            if self.noise:
                position = position + self.rng.normal(0, self.noise, 3)
            self.q[arm] = ik(m, d, arm, self.q[arm], position, rotation)
            action[7 * arm : 7 * arm + 6], action[7 * arm + 6] = self.q[arm], grip
        self.t += 1
        return action.astype(np.float32)
