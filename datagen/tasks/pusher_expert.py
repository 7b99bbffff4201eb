"""Pusher-v5's robot controller, its pose-controlled env and its scripted expert (datagen/tasks/pusher.py's).

Pusher-v5 (gymnasium 1.4.0, assets/pusher_v5.xml): a 7-DoF arm whose hand (body tips_arm, the wrist
centre) is a U of capsules (radius 0.02 m) in its frame: a cross bar along y in [-0.1, 0.1] and two
prongs along +x (x in [0, 0.1]) at y = +-0.1; only these touch the object (every other arm geom has
contype 0). The object is a cylinder (radius 0.05 m, 0.1 m tall) on two slide joints, so a U around it
drags it anywhere but out of the opening (-x). Actions are joint torques (N.m, gear 1, [-2, 2]); no
gravity; dt 0.05 s (5 Euler steps of 0.01 s).

    controller(model, data, obs, pos, quat)   torques that drive the hand toward a pose target
    PoseControl(env)                          Pusher-v5 taking pose targets as its action
    PusherExpert(noise=, seed=)               act(obs) -> the next pose target (7,)
    held(obs, data), hand_rotation(obs, data) what the engine reads of the hand (data: a scratch MjData)
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import mujoco
import numpy as np

from datagen.poses import solve

__all__ = ["PoseControl", "PusherExpert", "controller", "hand_rotation", "held", "model"]

QPOS, QVEL, TIPS, OBJ, GOAL = slice(0, 7), slice(7, 14), slice(14, 17), slice(17, 20), slice(20, 23)
# the controller's gains (why these values: controller's docstring)
MAX_POS_ERR = 0.15  # m: the Cartesian error fed to the IK is clipped to this (it sets the hand's speed)
MAX_ROT_ERR = 0.5  # rad
ROT_WEIGHT = 0.3  # m per rad: an orientation error counts this much against a position error
DAMPING = 0.05  # m: the damped least squares' lambda
KP, KD = 250.0, 30.0  # 1/s^2, 1/s: joint-space PD, scaled by the joint inertia matrix
K_NULL = 0.2  # null-space pull toward Q_REST (fraction of the gap per step)
Q_REST = np.array([0.0, 0.8, 0.0, -1.5, 0.0, -0.4, 0.0])  # rad; [0] is replaced by the target's bearing
DAMPED = {n: DAMPING**2 * np.eye(n) for n in (3, 6)}  # lambda^2 I of a position (3) or a pose (6) error


@functools.cache  # one compiled model per process: read-only, shared by the expert and the signals
def model() -> mujoco.MjModel:
    """Pusher-v5's own model, from gymnasium's assets (without importing its env module)."""
    root = Path(importlib.util.find_spec("gymnasium").origin).parent
    return mujoco.MjModel.from_xml_path(str(root / "envs" / "mujoco" / "assets" / "pusher_v5.xml"))


def load_obs(m: mujoco.MjModel, data: mujoco.MjData, obs) -> None:
    """Put a scratch MjData's arm into the observed joint state and run mj_forward. The object's and the
    goal's slides are separate trees: they do not enter the arm's Jacobian, inertia or bias forces."""
    data.qpos[:7], data.qvel[:7] = obs[QPOS], obs[QVEL]
    mujoco.mj_forward(m, data)


def hand_rotation(obs, data: mujoco.MjData) -> np.ndarray:
    """The hand's orientation (3, 3) in the world, from the observed joint angles: the arm's kinematics in
    `data`, a scratch MjData of Pusher's model (making one costs ~0.3 ms, so its caller keeps one)."""
    data.qpos[:7] = obs[QPOS]
    mujoco.mj_kinematics(data.model, data)
    return data.xmat[data.model.body("tips_arm").id].reshape(3, 3).copy()


def held(obs, data: mujoco.MjData) -> bool:
    """Whether the object sits in the hand's U: the hand at the object's height (within 3 cm) and the
    object's centre between the U's walls in the hand's own frame (2 cm margins). data: as hand_rotation's."""
    xa = hand_rotation(obs, data)[:2, 0]
    xa = xa / np.linalg.norm(xa)
    rel = np.asarray(obs[OBJ][:2], np.float64) - obs[TIPS][:2]
    rx, ry = rel @ xa, rel @ np.array([-xa[1], xa[0]])
    return bool(obs[TIPS][2] < obs[OBJ][2] + 0.03 and -0.02 < rx < 0.14 and abs(ry) < 0.1)


def yaw_quat(yaw: float) -> np.ndarray:
    """The quaternion (w, x, y, z), w >= 0, of a level hand turned by yaw (rad): its U opening along yaw."""
    q = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    return -q if q[0] < 0 else q


def ik_step(m, data, target_pos, target_quat=None) -> np.ndarray:
    """One damped-least-squares step (rad, (7,)) moving the hand toward the target pose from the joint
    angles in `data` (its kinematics current). The pose error is clipped (MAX_POS_ERR m, MAX_ROT_ERR rad)
    so that a far target gives a bounded step; orientation counts ROT_WEIGHT m/rad. The 7th degree of
    freedom (the 6-D task's null space) pulls toward a rest posture: the shoulder turned toward the
    target, rolls at zero, elbow and wrist bent, the arm's own tabletop pose."""
    bid = m.body("tips_arm").id
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacBody(m, data, jp, jr, bid)
    e = np.asarray(target_pos, float) - data.xpos[bid]
    e *= min(1.0, MAX_POS_ERR / (np.linalg.norm(e) + 1e-12))
    jac = jp[:, :7]
    if target_quat is not None:
        qinv, dqt, er = np.zeros(4), np.zeros(4), np.zeros(3)
        mujoco.mju_negQuat(qinv, data.xquat[bid])
        mujoco.mju_mulQuat(dqt, np.asarray(target_quat, float), qinv)
        mujoco.mju_quat2Vel(er, dqt, 1.0)  # world-frame rotation vector, rad
        er *= min(1.0, MAX_ROT_ERR / (np.linalg.norm(er) + 1e-12))
        e, jac = np.concatenate([e, ROT_WEIGHT * er]), np.concatenate([jac, ROT_WEIGHT * jr[:, :7]])
    jjt = jac @ jac.T + DAMPED[len(e)]
    base = m.body("r_shoulder_pan_link").pos
    rest = Q_REST.copy()
    rest[0] = np.arctan2(target_pos[1] - base[1], target_pos[0] - base[0])
    # np.linalg.solve's bits without its checks (jjt is positive definite): ~10 us less a call, and the
    # grasp choice's dry runs make ~700 of these steps an episode
    null = np.eye(7) - jac.T @ solve(jjt, jac)
    return jac.T @ solve(jjt, e) + null @ (K_NULL * (rest - data.qpos[:7]))


def controller(m, data, obs, target_pos, target_quat=None) -> np.ndarray:
    """Torques (N.m, (7,) float32) driving the hand toward target_pos (m, world) and, if given,
    target_quat (w, x, y, z, world). Reads only obs and the model (obs is loaded into the scratch
    `data`); deterministic. ik_step gives a joint correction dq; torque = M(q) (KP dq - KD qdot) +
    qfrc_bias, a computed-torque joint PD on a setpoint re-solved every step: M-scaling gives every joint
    the same bandwidth (the wrist is 20x lighter than the shoulder); KP, KD: ~16 rad/s, near critical
    damping, KD x dt = 1.5 < 2 keeps the 20 Hz loop stable. Orientation matters: the capsules are 0.02 m
    thick against a 0.1 m tall object, so a rolled hand tilts the cross bar off it and a pitched one
    drives the prongs into the table."""
    load_obs(m, data, obs)
    dq = ik_step(m, data, target_pos, target_quat)
    inertia = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, data, inertia)
    tau = inertia[:7, :7] @ (KP * dq - KD * data.qvel[:7]) + data.qfrc_bias[:7]
    return np.clip(tau, *m.actuator_ctrlrange.T).astype(np.float32)


class PoseControl:
    """Pusher-v5 (a Gymnasium env) driven by pose targets, with Gymnasium's reset and step: action (7,) =
    the hand's target position (m) and orientation quaternion (w, x, y, z), world frame; each step the
    controller turns it into Pusher-v5's torques from the last observation. place(start) sets the whole
    state (START_NAMES' order: joint angles and speeds, the object's and the goal's (x, y)) through
    MuJoCo's state, the env's own set_state. scratch: its MjData for the controller, which the task's
    signals may use between steps. (A plain wrapper: importing this module imports no Gymnasium.)"""

    def __init__(self, env):
        self.env, self.unwrapped, self.render_mode, self.spec = env, env.unwrapped, env.render_mode, env.spec
        self.scratch = mujoco.MjData(env.unwrapped.model)
        self.obs = None

    def render(self):
        return self.env.render()

    def reset(self, **kw):
        self.obs, info = self.env.reset(**kw)
        return self.obs, info

    def step(self, action):
        a = np.asarray(action, np.float64)
        tau = controller(self.env.unwrapped.model, self.scratch, self.obs, a[:3], a[3:7])
        self.obs, *rest = self.env.step(tau)
        return self.obs, *rest

    def place(self, start) -> np.ndarray:
        env = self.env.unwrapped
        m, data = env.model, env.data
        qpos, qvel = data.qpos.copy(), np.zeros(m.nv)
        qpos[:7], qvel[:7] = start[:7], start[7:14]
        for body, xy in (("object", start[14:16]), ("goal", start[16:18])):
            b = m.body(body)
            for j in range(b.jntadr[0], b.jntadr[0] + b.jntnum[0]):  # its slides: the offset along each
                qpos[m.jnt_qposadr[j]] = np.dot(
                    np.asarray(xy, float) - m.body_pos[b.id][:2], m.jnt_axis[j][:2]
                )
        env.set_state(qpos, qvel)
        names = ("tips_arm", "object", "goal")
        self.obs = np.concatenate([data.qpos[:7], data.qvel[:7], *(data.body(n).xpos for n in names)])
        return self.obs


class PusherExpert:
    """Pushes the object onto the goal with the hand's U; its pose targets re-planned every step from the
    observation, in the object's frame. Pusher's contact is very soft (the object weighs 8e-9 kg, so
    MuJoCo's contact force ~ penetration): the object moves at ~0.8 m/s per metre of penetration against
    its 0.5 N.s/m slide damping. So the push holds the object DEPTH m *inside* the U's walls, and its
    speed follows that depth. The hand may pass down through the object's top (a vertical contact
    normal, which the object's slides ignore), so it descends on the push pose.
      hover   HOVER m above the push pose (the object's centre height read from the observation)
      descend to the push pose once within NEAR m of it in xy
      push    while the object is held (held()): it sits in the U's corner facing the goal (cross bar
              and one prong), pressed DEPTH m into both walls, less near the goal
    Hand yaw = push direction - beta, the grasp, chosen once per episode (first act()) among BETAS by
    dry-running the controller's IK to the push poses at the object's start and on the goal: this arm
    holds a level hand only in some yaws, and near its base a wrong one ends at a joint limit.
    act(obs) -> the target (7,) float32; noise: Gaussian std (m) on its position, from Generator(seed)."""

    CORNER = np.array([0.07, 0.03])  # m: object centre touching cross bar (x) and a prong (|y|), hand frame
    HOVER = 0.12  # m above the object centre: the capsules clear its top (0.05 + 0.02) by 0.05 m
    NEAR = 0.03  # m: xy distance to the push pose at which the hand descends
    DEPTH = 0.06  # m: penetration per wall while pushing; beyond ~0.065 the contact normal turns vertical
    SLOW = 3.0  # depth = SLOW x remaining distance near the goal (m/m), so the object stops on it
    BETAS = np.radians([-80, -60, -45, -20, 0, 20, 45, 60, 80])  # rad: push direction, hand frame
    REACHED = 0.005  # m: dry-run position error under which a grasp counts as reachable

    def __init__(self, noise: float = 0.0, seed: int = 0):
        self.model = model()
        self.data = mujoco.MjData(self.model)
        self.noise, self.seed = noise, seed
        self.reset()

    def reset(self) -> None:
        self.rng = np.random.default_rng(self.seed)
        self.beta = None

    def push_pose(self, obj, psi: float, dist: float, beta: float) -> tuple[np.ndarray, float]:
        """Wrist xy (m) and hand yaw (rad) that press the object (centre obj, m) into the U's corner
        facing the push direction psi (rad), dist (m) from the goal, with the grasp beta (rad)."""
        yaw = psi - beta
        rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])  # hand -> world (xy)
        u = np.array([np.cos(beta), np.sin(beta)])  # push direction, hand frame
        corner = self.CORNER * np.array([1.0, -np.clip(u[1] / 0.3, -1.0, 1.0)])
        depth = min(self.DEPTH / max(abs(u[0]), abs(u[1])), self.SLOW * dist)
        return obj[:2] - rot @ (corner - depth * u), yaw

    def dry_run(self, q, target_pos, target_quat, iters: int = 40) -> tuple[np.ndarray, float]:
        """Kinematic rehearsal of the controller: ik_step iterated from joint angles q (joint limits
        clamped); the final angles and the position error left (m). No dynamics, no env."""
        m, data = self.model, self.data
        bid, (lo, hi) = m.body("tips_arm").id, m.jnt_range[:7].T
        for _ in range(iters):
            data.qpos[:7] = q
            mujoco.mj_kinematics(m, data)
            mujoco.mj_comPos(m, data)
            q = np.clip(q + ik_step(m, data, target_pos, target_quat), lo, hi)
        data.qpos[:7] = q
        mujoco.mj_kinematics(m, data)
        return q, float(np.linalg.norm(np.asarray(target_pos) - data.xpos[bid]))

    def choose_beta(self, obs) -> float:
        """Among the grasps the arm reaches (IK error under REACHED at the push poses on the object's
        start and on the goal), the one nearest +-45 deg: it pushes with both walls at once (fastest);
        if none is reached, the least bad one."""
        obj, goal = np.asarray(obs[OBJ], np.float64), np.asarray(obs[GOAL], np.float64)
        push = goal[:2] - obj[:2]
        psi, dist = np.arctan2(push[1], push[0]), np.linalg.norm(push)
        errs = []
        for beta in self.BETAS:
            q, err = np.asarray(obs[QPOS], np.float64), 0.0
            for o, d in ((obj, dist), (goal, 0.0)):
                xy, yaw = self.push_pose(o, psi, d, beta)
                q, e = self.dry_run(q, np.r_[xy, obj[2]], yaw_quat(yaw))
                err = max(err, e)
            errs.append(err)
        errs = np.array(errs)
        pref = np.where(errs < self.REACHED, np.abs(np.abs(self.BETAS) - np.pi / 4), np.inf)
        return float(self.BETAS[int(np.argmin(pref) if np.isfinite(pref).any() else np.argmin(errs))])

    def act(self, obs) -> np.ndarray:
        obj, goal = np.asarray(obs[OBJ], np.float64), np.asarray(obs[GOAL], np.float64)
        if self.beta is None:
            self.beta = self.choose_beta(obs)
        push = goal[:2] - obj[:2]
        xy, yaw = self.push_pose(obj, np.arctan2(push[1], push[0]), np.linalg.norm(push), self.beta)
        near = np.linalg.norm(obs[TIPS][:2] - xy) < self.NEAR
        pos = np.r_[xy, obj[2] + (0.0 if held(obs, self.data) or near else self.HOVER)]
        if self.noise > 0:
            pos = pos + self.rng.normal(0.0, self.noise, 3)
        return np.r_[pos, yaw_quat(yaw)].astype(np.float32)
