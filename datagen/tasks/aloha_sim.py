"""LeRobot's bimanual ALOHA sim (gym-aloha 0.1.5, ACT's sim) on our mujoco: its model files, its rules.

gym-aloha's env code runs through dm_control, which fails on mujoco 4 (requirements.lock installs the wheel
without it: tools/lock-excludes.txt), so this module loads the wheel's model files (gym_aloha/assets: two
ViperX 300s arms, 6 joints and a two-finger gripper each, a table, a 4 cm cube) with mujoco directly and
re-states the rules of gym_aloha's code that a demo depends on, each where the wheel has it:

    constants.py    DT 0.02 s (50 fps; 10 MuJoCo steps of the models' 0.002 s), START_ARM_POSE, the
                    puppet gripper's finger range and its normalisation (0 closed, 1 open)
    utils.py        sample_box_pose: the cube's start, uniform over x [0, 0.2], y [0.4, 0.6] m, z 0.05 m,
                    upright, from np.random.RandomState(seed)
    tasks/sim.py    the joint-controlled task (bimanual_viperx_transfer_cube.xml): action = 6 joint targets
                    (rad) and a normalized gripper per arm, left first; observation = the same 14 from qpos;
                    env_state = the cube's qpos (position, quaternion w first); get_reward's four stages
                    from contacts (reward_stage below); success is the top stage (gym_aloha/env.py ends
                    the episode there)
    tasks/sim_end_effector.py  the mocap-controlled twin (bimanual_viperx_end_effector_transfer_cube.xml,
                    each gripper welded to a mocap body), where ACT drove its scripted demos (below)

A step is dm_control's (control.Environment with its legacy step): the controls set, then 10 times
mj_step2 then mj_step1, so that the contacts a reward reads are those of the state after the step.

    assets()                 the wheel's assets folder, found without importing gym_aloha
    TransferCubeEnv          the joint-controlled Gymnasium env (datagen/tasks/aloha_transfer_cube.py's)
    reward_stage(m, d)       get_reward of TransferCubeTask, 0..4
    gripper_pose, ik         a gripper's grasp point and orientation from the joints, and back (the
                             expert's way from end-effector waypoints to joint targets)

The end-effector model is not driven: its welds (solimp 0.25) hold a gripper 1 to 4 cm off its mocap
under load on mujoco 4 (measured: ACT's waypoints, run in it, left the fingers on top of the cube and
lifted it in about half of the starts), so the expert turns its end-effector waypoints into joint
targets by inverse kinematics on the joint model, whose position servos track them.
"""

from __future__ import annotations

import functools
import importlib.util
import sys
from pathlib import Path

import mujoco
import numpy as np

from ch37.errors import DataError
from datagen.poses import solve

__all__ = [
    "CUBE_RANGE",
    "DT",
    "FPS",
    "START_ARM_POSE",
    "InsertionEnv",
    "JOINT_IDS",
    "PEG_RANGE",
    "SOCKET_RANGE",
    "TransferCubeEnv",
    "assets",
    "box_pose",
    "normalize_gripper",
    "gripper_pose",
    "insertion_pose",
    "insertion_stage",
    "ik",
    "reward_stage",
    "unnormalize_gripper",
]

DT = 0.02  # s: gym_aloha.constants.DT, one control step
FPS = 50
SUBSTEPS = 10  # DT / the models' timestep (0.002 s, MuJoCo's default: the models set none)
START_ARM_POSE = np.array(  # gym_aloha.constants: 6 joints (rad) and the two finger slides (m) per arm
    [0, -0.96, 1.16, 0, -0.3, 0, 0.02239, -0.02239] * 2
)
GRIPPER_OPEN, GRIPPER_CLOSE = 0.05800, 0.01844  # m: PUPPET_GRIPPER_POSITION_OPEN / _CLOSE (left finger)
# gym_aloha.utils.sample_box_pose: (low, high) of the cube's x, y, z (m)
CUBE_RANGE = ((0.0, 0.2), (0.4, 0.6), (0.05, 0.05))
# gym_aloha.utils.sample_insertion_pose: the peg's and the socket's (low, high) of x, y, z (m)
PEG_RANGE = ((0.1, 0.2), (0.4, 0.6), (0.05, 0.05))
SOCKET_RANGE = ((-0.2, -0.1), (0.4, 0.6), (0.05, 0.05))
GRIPPERS = ("vx300s_left/gripper_link", "vx300s_right/gripper_link")
QPOS = (slice(0, 6), slice(8, 14))  # each arm's 6 joints in qpos (its two finger slides follow)
DOFS = (slice(0, 6), slice(8, 14))
JOINT_IDS = (slice(0, 6), slice(8, 14))
# m, in gripper_link's frame: the grasp point, between the finger pads (the fingers reach from 0.064 to
# 0.154 m ahead of gripper_link; the end-effector model's welds hold the point 0.135 m ahead on its mocap)
TCP_OFFSET = np.array([0.13, 0.0, 0.0])
IK_ITERS = 8  # damped least squares steps per solve, from the last solution (it moves < 1 cm a step)
IK_DAMPING = 0.02  # m: the damped least squares' lambda
ROT_WEIGHT = 0.2  # m per rad: an orientation error against a position error
MAX_REWARD = 4  # TransferCubeTask.max_reward: its success
# the geoms get_reward reads: the cube, the left arm's and the right arm's "10_..._gripper_finger" (one
# finger of each gripper: the rule names no other), the table
CONTACT_GEOMS = (
    "red_box",
    "vx300s_left/10_left_gripper_finger",
    "vx300s_right/10_right_gripper_finger",
    "table",
)


def assets() -> Path:
    """gym_aloha/assets of the installed gym-aloha wheel, located without importing it (its env code needs
    dm_control); a DataError (one line) when the wheel is not installed."""
    spec = importlib.util.find_spec("gym_aloha")
    if spec is None or spec.origin is None:
        raise DataError(
            "gym-aloha is not installed (its model files: requirements.lock pins gym-aloha==0.1.5; "
            "re-install the set-up: rm -r .venv, then bash run_tests.sh)"
        )
    return Path(spec.origin).parent / "assets"


@functools.cache  # one compiled model of each per process: read-only, shared by every env of it
def model(scene: str = "transfer_cube") -> mujoco.MjModel:
    """The joint-controlled model of `scene` ("transfer_cube", "insertion"): 16 position servos (6 joints
    and 2 fingers per arm), then the objects' free joints."""
    return mujoco.MjModel.from_xml_path(str(assets() / f"bimanual_viperx_{scene}.xml"))


@functools.cache  # making an MjData of these models costs ~0.8 ms, more than a control step's physics
def scratch(scene: str = "transfer_cube") -> mujoco.MjData:
    """One MjData of `scene` per process for kinematics alone (grasp points, inverse kinematics). Its users
    write only the arms' joints (qpos[0:6], qpos[8:14]) and read only what mj_kinematics and mj_comPos
    make of them, so a reused one gives the bits a new one gives."""
    return mujoco.MjData(model(scene))


def normalize_gripper(x):
    """A finger's position (m) as gym-aloha normalizes it: 0 closed, 1 open."""
    return (x - GRIPPER_CLOSE) / (GRIPPER_OPEN - GRIPPER_CLOSE)


def unnormalize_gripper(x):
    return x * (GRIPPER_OPEN - GRIPPER_CLOSE) + GRIPPER_CLOSE


def box_pose(seed) -> np.ndarray:
    """The cube's start (x, y, z, qw, qx, qy, qz) that gym-aloha's reset(seed=seed) draws (sample_box_pose):
    the same numbers for a seed below 2**32; a larger seed (our env seeds reach 2**63) seeds the same
    generator with its 32-bit words, the same uniform law."""
    if seed is not None and seed >= 2**32:
        seed = [(seed >> s) & 0xFFFFFFFF for s in range(0, seed.bit_length(), 32)]
    rng = np.random.RandomState(seed)
    ranges = np.array(CUBE_RANGE)
    return np.concatenate([rng.uniform(ranges[:, 0], ranges[:, 1]), [1.0, 0.0, 0.0, 0.0]])


def reward_stage(m: mujoco.MjModel, d: mujoco.MjData) -> int:
    """TransferCubeTask.get_reward (gym_aloha/tasks/sim.py): from the contacts' (geom1, geom2) pairs, in that
    order, 1 the right fingers touch the cube, 2 and it is off the table, 3 the left fingers touch it, 4 and
    it is off the table (success)."""
    pairs = {(int(a), int(b)) for a, b in zip(d.contact.geom1[: d.ncon], d.contact.geom2[: d.ncon])}
    box, left, right, table = (mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n) for n in CONTACT_GEOMS)
    touch_left, touch_right, touch_table = (
        ((box, left) in pairs),
        ((box, right) in pairs),
        ((box, table) in pairs),
    )
    reward = 0
    if touch_right:
        reward = 1
    if touch_right and not touch_table:  # lifted
        reward = 2
    if touch_left:  # attempted transfer
        reward = 3
    if touch_left and not touch_table:  # successful transfer
        reward = 4
    return reward


def insertion_pose(seed) -> np.ndarray:
    """The peg's and the socket's starts (7 each, the peg first) that gym-aloha's reset(seed=seed) draws for
    insertion (sample_insertion_pose: the peg uniform on x [0.1, 0.2], the socket on x [-0.2, -0.1], both on
    y [0.4, 0.6] m, z 0.05 m, upright, from one RandomState(seed)); a seed past 32 bits as box_pose."""
    if seed is not None and seed >= 2**32:
        seed = [(seed >> s) & 0xFFFFFFFF for s in range(0, seed.bit_length(), 32)]
    rng = np.random.RandomState(seed)
    up = [1.0, 0.0, 0.0, 0.0]
    peg = rng.uniform(*np.array(PEG_RANGE).T)
    socket = rng.uniform(*np.array(SOCKET_RANGE).T)
    return np.concatenate([peg, up, socket, up])


def insertion_stage(m: mujoco.MjModel, d: mujoco.MjData) -> int:
    """InsertionTask.get_reward (gym_aloha/tasks/sim.py), from the contacts' (geom1, geom2) pairs in that
    order: 1 the left fingers touch the socket and the right the peg, 2 and neither touches the table, 3
    the peg touches the socket off the table, 4 the peg touches the pin (success)."""
    name = functools.partial(mujoco.mj_id2name, m, mujoco.mjtObj.mjOBJ_GEOM)
    pairs = {
        (name(int(a)), name(int(b))) for a, b in zip(d.contact.geom1[: d.ncon], d.contact.geom2[: d.ncon])
    }
    sockets = [f"socket-{i}" for i in range(1, 5)]
    touch_right = ("red_peg", "vx300s_right/10_right_gripper_finger") in pairs
    touch_left = any((s, "vx300s_left/10_left_gripper_finger") in pairs for s in sockets)
    peg_table = ("red_peg", "table") in pairs
    socket_table = any((s, "table") in pairs for s in sockets)
    peg_socket = any(("red_peg", s) in pairs for s in sockets)
    reward = 0
    if touch_left and touch_right:  # touch both
        reward = 1
    if touch_left and touch_right and not peg_table and not socket_table:  # grasp both
        reward = 2
    if peg_socket and not peg_table and not socket_table:  # peg and socket touching
        reward = 3
    if ("red_peg", "pin") in pairs:  # successful insertion
        reward = 4
    return reward


def qpos14(d: mujoco.MjData) -> np.ndarray:
    """BimanualViperXTask.get_qpos: each arm's 6 joints (rad) and its normalized gripper, left first."""
    q = d.qpos
    return np.concatenate([q[:6], [normalize_gripper(q[6])], q[8:14], [normalize_gripper(q[14])]])


# MuJoCo's warnings that a sim blew up (a NaN, inf or huge position, velocity or acceleration): MuJoCo
# then resets the sim to the model's defaults and counts the warning in MjData.warning (until the next
# mj_resetData: an episode's reset)
UNSTABLE = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


def _warned(message: str) -> None:
    """MuJoCo's warnings, in place of its own handler, which appends each to MUJOCO_LOG.TXT in the current
    folder (a file outside any --out): an instability is the episode's end (step's "unstable", a failed
    episode, gen_demos.py's count of them), said by the command; any other warning is shown as MuJoCo
    shows it, on stderr."""
    if "The simulation is unstable" not in message:
        print(f"WARNING: {message}", file=sys.stderr)


def _step(m: mujoco.MjModel, d: mujoco.MjData) -> bool:
    """One control step as dm_control's legacy Physics.step takes it, SUBSTEPS times; whether the sim blew
    up since the episode's reset (MuJoCo then reset it, and what follows is no continuation)."""
    for _ in range(SUBSTEPS):
        mujoco.mj_step2(m, d)
        mujoco.mj_step1(m, d)
    return any(d.warning[w].number for w in UNSTABLE)


def _reset(m: mujoco.MjModel, d: mujoco.MjData, objects) -> None:
    """physics.reset_context's part of initialize_episode: mj_resetData, the arms at START_ARM_POSE, the
    objects at `objects` (7 numbers each); the caller sets the controls, then mj_forward."""
    mujoco.mj_resetData(m, d)
    d.qpos[:16] = START_ARM_POSE
    d.qpos[16 : 16 + len(objects)] = objects


class TransferCubeEnv:
    """gym_aloha's AlohaTransferCube-v0 (tasks/sim.py's TransferCubeTask) on mujoco directly, with its
    state instead of its pixels, on Gymnasium's API (reset, step's five values, the spaces; gymnasium is
    imported when one is made, not when the engine's registry imports this module).
    observation float32: the 14 of qpos14, then the objects' poses (x, y, z m; qw, qx, qy, qz each)
    action (14,): per arm, left first, 6 joint targets (rad) and a normalized gripper target
    info["is_success"] at reward 4, which ends the episode (terminated); truncated after max_steps;
    info["unstable"] when MuJoCo found the sim blown up and reset it, which ends the episode unsolved.
    reset(seed) places the objects as gym-aloha's reset(seed=seed) does (draw);
    reset(options={"reset_to_state": the objects' poses}) places them there."""

    metadata = {"render_modes": [], "render_fps": FPS}
    render_mode = None  # it draws no frames (gen_demos.py --video is refused in one line)
    scene, objects = "transfer_cube", 7  # the model, and the numbers of its objects' poses
    draw, stage = staticmethod(box_pose), staticmethod(reward_stage)

    def __init__(self, max_steps: int, share: TransferCubeEnv | None = None):
        import gymnasium

        mujoco.set_mju_user_warning(_warned)  # when a sim is made, not at import: its warnings are ours
        self.model = model(self.scene) if share is None else share.model
        self.data = mujoco.MjData(self.model)
        self.max_steps = max_steps
        self.t = 0
        self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (14 + self.objects,), np.float32)
        self.action_space = gymnasium.spaces.Box(-np.inf, np.inf, (14,), np.float32)

    def observation(self) -> np.ndarray:
        return np.concatenate([qpos14(self.data), self.data.qpos[16 : 16 + self.objects]]).astype(np.float32)

    def poses(self, state) -> np.ndarray:
        """reset_to_state's numbers as the objects' poses, (objects,) float64; anything else is a ValueError
        saying what it takes (MuJoCo would place a short or NaN pose as it came, and stand an object with
        an all-zero quaternion upright)."""
        what = "the cube's" if self.objects == 7 else "the peg's, then the socket's"
        takes = f"options['reset_to_state'] takes {self.objects} finite numbers, {what} pose"
        takes += " (x, y, z m; qw, qx, qy, qz)"
        try:
            x = np.asarray(state, np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{takes}; got {state!r}") from None
        if x.shape != (self.objects,) or not np.all(np.isfinite(x)):
            raise ValueError(f"{takes}; got {x.tolist() if x.size <= 2 * self.objects else x.shape}")
        if np.any(np.linalg.norm(x.reshape(-1, 7)[:, 3:], axis=1) < 1e-6):
            raise ValueError(f"{takes}; a quaternion of {x.tolist()} is all zeros: it is no orientation")
        return x

    def reset(self, *, seed=None, options=None):
        placed = options and "reset_to_state" in options
        objects = self.poses(options["reset_to_state"]) if placed else self.draw(seed)
        m, d = self.model, self.data
        _reset(m, d, np.asarray(objects, np.float64))
        d.ctrl[:] = START_ARM_POSE
        mujoco.mj_forward(m, d)
        self.t = 0
        return self.observation(), {"is_success": False}

    def step(self, action):
        a = np.asarray(action, np.float64)
        if a.shape != (14,):  # a 3-wide one was an IndexError deep in here
            raise ValueError(
                f"action takes 14 finite numbers (per arm, left first, 6 joint targets rad and a gripper, "
                f"0 closed, 1 open); got shape {a.shape}"
            )
        if not np.all(np.isfinite(a)):  # MuJoCo would zero the controls, warn and write MUJOCO_LOG.TXT
            raise ValueError(f"non-finite action {a}")
        gl, gr = unnormalize_gripper(a[6]), unnormalize_gripper(a[13])  # BimanualViperXTask.before_step
        self.data.ctrl[:] = np.r_[a[:6], gl, -gl, a[7:13], gr, -gr]
        unstable = _step(self.model, self.data)
        self.t += 1
        # a sim MuJoCo reset mid-episode ends the episode there, unsolved: its frames are no episode
        reward = 0 if unstable else self.stage(self.model, self.data)
        success = reward == MAX_REWARD
        info = {"is_success": success, "unstable": unstable}
        return self.observation(), float(reward), success or unstable, self.t >= self.max_steps, info


class InsertionEnv(TransferCubeEnv):
    """gym_aloha's AlohaInsertion-v0 (InsertionTask) alike: the objects are the peg and the socket (7
    each, the peg first); success is the peg touching the socket's pin."""

    scene, objects = "insertion", 14
    draw, stage = staticmethod(insertion_pose), staticmethod(insertion_stage)


def gripper_pose(m: mujoco.MjModel, d: mujoco.MjData, arm: int) -> tuple[np.ndarray, np.ndarray]:
    """Arm `arm`'s (0 left, 1 right) grasp point, TCP_OFFSET ahead of its gripper_link between the finger
    pads, and the gripper's orientation (3, 3: x forward, y the fingers' closing axis), from d's
    kinematics."""
    b = m.body(GRIPPERS[arm]).id
    rot = d.xmat[b].reshape(3, 3)
    return d.xpos[b] + rot @ TCP_OFFSET, rot.copy()


def ik(
    m: mujoco.MjModel, d: mujoco.MjData, arm: int, q, position, rotation, iters: int = IK_ITERS
) -> np.ndarray:
    """Joint angles (6,) of arm `arm` that put its grasp point at `position` (m) turned to `rotation`
    (3, 3): damped least squares on the model's Jacobian from `q` (6,), in the scratch MjData `d` (its
    other joints as they are), clipped to the joints' ranges."""
    qadr, dofs = QPOS[arm], DOFS[arm]
    q = np.array(q, np.float64)
    b = m.body(GRIPPERS[arm]).id
    # gripper_pose, the concatenations, np.clip and np.linalg.solve written out on buffers made once: the
    # same arithmetic in the same order (the same bits: every product and sum is the same numpy loop,
    # written into a buffer instead of a new array), without ~60 us of per-call overhead an iteration (a
    # replayed ALOHA frame runs 2 x 20 of them). solve: np.linalg.solve's bits without its checks
    # (datagen.poses.solve); jac @ jac.T + damping is positive definite, never singular.
    position, rotation = np.asarray(position, np.float64), np.asarray(rotation)
    xpos, xmat = d.xpos[b], d.xmat[b].reshape(3, 3)  # views: mj_kinematics writes them in place
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    jacp_arm, jacr_arm = jacp[:, dofs], jacr[:, dofs]  # views: mj_jac writes jacp and jacr in place
    lo, hi = m.jnt_range[JOINT_IDS[arm]].T
    err_q, vel, err, jac = np.zeros(4), np.zeros(3), np.zeros(6), np.zeros((6, 6))
    p, turn, jjt, step = np.zeros(3), np.zeros((3, 3)), np.zeros((6, 6)), np.zeros(6)
    damping = IK_DAMPING**2 * np.eye(6)
    for _ in range(iters):
        d.qpos[qadr] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        np.add(xpos, np.matmul(xmat, TCP_OFFSET, out=p), out=p)  # gripper_pose's grasp point
        mujoco.mju_mat2Quat(err_q, np.matmul(rotation, xmat.T, out=turn).ravel())
        mujoco.mju_quat2Vel(vel, err_q, 1.0)
        np.subtract(position, p, out=err[:3])
        np.multiply(ROT_WEIGHT, vel, out=err[3:])
        mujoco.mj_jac(m, d, jacp, jacr, p, b)
        jac[:3] = jacp_arm
        np.multiply(ROT_WEIGHT, jacr_arm, out=jac[3:])
        np.add(np.matmul(jac, jac.T, out=jjt), damping, out=jjt)
        np.matmul(jac.T, solve(jjt, err), out=step)
        np.minimum(np.maximum(np.add(q, step, out=q), lo, out=q), hi, out=q)
    return q
