"""The scripted transfer-cube expert (datagen/tasks/aloha_transfer_cube.py's), in end-effector space as ACT's
PickAndTransferPolicy is: per arm, waypoints (time step, grasp-point position, gripper orientation,
gripper command 0 closed .. 1 open) relative to the cube and to a meeting point in the air, interpolated
(position linearly, orientation by slerp); the right arm grasps the cube from above, tilted, and carries
it to the meeting point; the left arm comes in from the side, closes across it, and the right lets go.

Each step's waypoint becomes the joint action the lerobot/aloha_sim_* sets record (6 joint targets and a
normalized gripper per arm) by inverse kinematics on the joint-controlled model (datagen.tasks.aloha_sim.ik,
from the last step's solution): ACT drove the same waypoints through the end-effector model's mocap welds
and replayed the joints they gave, which on mujoco 4 track too loosely to grasp (datagen/tasks/aloha_sim.py).
The plan is made from the first observation (the cube's pose); the left arm's approach is planned again
when the right arm reaches the meeting point, relative to the cube as it then lies in the right hand.
"""

from __future__ import annotations

import mujoco
import numpy as np

from datagen.poses import slerp
from datagen.tasks.aloha_sim import START_ARM_POSE, gripper_pose, ik, model

__all__ = ["InsertionExpert", "TransferCubeExpert", "align", "handover", "insertion_plan", "plan"]

CUBE = slice(14, 17)  # the cube's position in an observation
MEET = np.array([0.0, 0.5, 0.25])  # m: where the hand-over happens (ACT's meet_xyz)
GRASP = np.array([0.0, 0.0, 0.0])  # m: the right grasp point from the cube's centre on the table
ABOVE = 0.08  # m: the right gripper comes down from this far above the cube
PICK_TILT = 60.0  # deg: the right gripper points down this far below horizontal (ACT's)
LEFT_IN = np.array([-0.01, 0.0, 0.0])  # m: the left grasp point from the held cube's centre
MET = 220  # the step the right arm reaches MEET with the cube: the left arm's approach is planned then
STEPS = 400  # the plan's length (ACT's episode_len for transfer-cube and insertion)
# insertion (ACT's InsertionPolicy, its parts' starts relative to the grasp points)
PEG, SOCKET = slice(14, 21), slice(21, 28)  # the peg's and the socket's poses in an observation
INSERT_GRASP = -0.01  # m: the grasp point's height from a part's centre at its start
INSERT_MEET = np.array([0.0, 0.5, 0.15])  # m: ACT's meet_xyz for insertion
ALIGN = 285  # the step both parts are lifted beside the meeting point: the insertion is planned then
SOCKET_AT = INSERT_MEET + [-0.05, 0, 0]  # m: where the socket's centre is brought
PEG_LENGTH = 0.12  # m: the peg's and the socket's length (gym-aloha's insertion model)
INSERT_DEPTH = 0.025  # m: how far the peg overlaps the socket at the end (the pin begins 0.02 m in)


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

    scene = "transfer_cube"
    replan_at = MET  # the step the plan is made again from what the observation shows

    def __init__(self, noise: float = 0.0, seed: int | None = None):
        self.noise, self.seed = float(noise), seed
        self.model = model(self.scene)
        self.scratch = mujoco.MjData(self.model)  # the IK's kinematics
        self.reset()

    def reset(self) -> None:
        self.t = 0
        self.waypoints = None
        self.q = [START_ARM_POSE[0:6].copy(), START_ARM_POSE[8:14].copy()]
        self.rng = np.random.default_rng(self.seed)

    def plan(self, obs, start_left, start_right) -> tuple[list, list]:
        return plan(obs[CUBE], start_left, start_right)

    def replan(self, obs, waypoints) -> tuple[list, list]:
        """The cube is in the right hand: the left arm's approach is planned to where it is."""
        return handover(waypoints[0], obs[CUBE]), waypoints[1]

    def act(self, obs) -> np.ndarray:
        m, d = self.model, self.scratch
        if self.waypoints is None:  # the first observation: the plan from the arms' start poses
            d.qpos[:16] = START_ARM_POSE
            mujoco.mj_kinematics(m, d)
            self.waypoints = self.plan(obs, gripper_pose(m, d, 0), gripper_pose(m, d, 1))
        if self.t == self.replan_at:
            self.waypoints = self.replan(obs, self.waypoints)
        action = np.zeros(14)
        for arm in (0, 1):
            position, rotation, grip = _at(self.waypoints[arm], min(self.t, STEPS))
            if self.noise:
                position = position + self.rng.normal(0, self.noise, 3)
            self.q[arm] = ik(m, d, arm, self.q[arm], position, rotation)
            action[7 * arm : 7 * arm + 6], action[7 * arm + 6] = self.q[arm], grip
        self.t += 1
        return action.astype(np.float32)


def insertion_plan(peg, socket, start_left, start_right) -> tuple[list, list]:
    """ACT's InsertionPolicy's waypoints (t, position, orientation, gripper) of the left and the right
    grasp point: each arm grasps its part from above, tilted toward it (the socket with the left, the peg
    with the right), and lifts it beside the meeting point, until align() plans the insertion."""
    tilt = np.radians(PICK_TILT)
    right = _frame([-np.cos(tilt), 0, -np.sin(tilt)], [0, -1, 0])
    left = _frame([np.cos(tilt), 0, -np.sin(tilt)], [0, 1, 0])
    peg, socket = np.asarray(peg[:3], np.float64), np.asarray(socket[:3], np.float64)
    down = [0, 0, INSERT_GRASP]
    return (
        [
            (0, *start_left, 0),  # sleep
            (120, socket + [0, 0, ABOVE], left, 1),  # above the socket
            (170, socket + down, left, 1),  # down
            (220, socket + down, left, 0),  # close the gripper
            (ALIGN, INSERT_MEET + [-0.1, 0, 0], left, 0),  # lift it beside the meeting point
            (STEPS, INSERT_MEET + [-0.1, 0, 0], left, 0),  # wait (align replaces the rest)
        ],
        [
            (0, *start_right, 0),  # sleep
            (120, peg + [0, 0, ABOVE], right, 1),  # above the peg
            (170, peg + down, right, 1),  # down
            (220, peg + down, right, 0),  # close the gripper
            (ALIGN, INSERT_MEET + [0.1, 0, 0], right, 0),  # lift it beside the meeting point
            (STEPS, INSERT_MEET + [0.1, 0, 0], right, 0),  # wait (align replaces the rest)
        ],
    )


def align(waypoints, peg, socket, left_at, right_at) -> tuple[list, list]:
    """The insertion, planned from where the peg and the socket lie in the hands (their centres `peg`,
    `socket` and the grasp points `left_at`, `right_at`, (3,) each): the socket's centre to SOCKET_AT, the
    peg's centre in line with it, 4 cm out, then in until it overlaps the socket by INSERT_DEPTH (the pin
    sits 2 cm inside the socket's mouth)."""
    grip_socket = np.asarray(socket[:3], np.float64) - left_at  # each part's centre from its grasp point
    grip_peg = np.asarray(peg[:3], np.float64) - right_at
    peg_at = SOCKET_AT + [PEG_LENGTH - INSERT_DEPTH, 0, 0]
    (left, right), rl, rr = waypoints, waypoints[0][4][2], waypoints[1][4][2]
    return (
        left[:5] + [(340, SOCKET_AT - grip_socket, rl, 0), (STEPS, SOCKET_AT - grip_socket, rl, 0)],
        right[:5]
        + [
            (310, peg_at + [0.04, 0, 0] - grip_peg, rr, 0),  # in line, out of the socket
            (360, peg_at - grip_peg, rr, 0),  # in
            (STEPS, peg_at - grip_peg, rr, 0),
        ],
    )


class InsertionExpert(TransferCubeExpert):
    """The insertion expert (datagen/tasks/aloha_insertion.py's): act(obs) as TransferCubeExpert's, for the
    peg and the socket the observation shows (obs[14:21], obs[21:28]); at ALIGN the insertion is planned from
    where the two parts then lie in the hands."""

    scene = "insertion"
    replan_at = ALIGN

    def plan(self, obs, start_left, start_right) -> tuple[list, list]:
        return insertion_plan(obs[PEG], obs[SOCKET], start_left, start_right)

    def replan(self, obs, waypoints) -> tuple[list, list]:
        m, d = self.model, self.scratch
        o = np.asarray(obs, np.float64)
        d.qpos[0:6], d.qpos[8:14] = o[0:6], o[7:13]  # the observed joints: where the grasp points are
        mujoco.mj_kinematics(m, d)
        return align(waypoints, o[PEG], o[SOCKET], gripper_pose(m, d, 0)[0], gripper_pose(m, d, 1)[0])
