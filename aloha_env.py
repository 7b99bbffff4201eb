"""A simplified bimanual ALOHA cube handoff: two planar arms with grippers, seen from above.

The model lives in ``aloha.xml`` beside this file (MuJoCo MJCF). Everything is read and written
through MuJoCo's named accessors (``data.joint("right_x")``, ``data.actuator("left_grip")``,
``model.site("target")``), never through hard-coded array indices.

Task: a cube spawns where only the right arm can reach it; the target lies where only the left
arm can reach. The two reach ranges overlap only in the handoff zone |x| < 0.05 m, so the right
arm must pick the cube, carry it to the middle, hand it to the left arm, and the left arm must
carry it to the target.

Observation, float32[10] (``STATE_NAMES``)

    idx  name         unit  meaning
    0    right_x      m     right end-effector x, in [-0.05, 0.35]
    1    right_y      m     right end-effector y, in [-0.25, 0.25]
    2    right_grip   -     right gripper closedness, 0 open .. 1 closed
    3    left_x       m     left end-effector x, in [-0.35, 0.05]
    4    left_y       m     left end-effector y, in [-0.25, 0.25]
    5    left_grip    -     left gripper closedness, 0 open .. 1 closed
    6    cube_x       m     cube centre x
    7    cube_y       m     cube centre y
    8    target_x     m     delivery target x (constant within an episode)
    9    target_y     m     delivery target y (constant within an episode)

The demo sets also store indices 6..9 (cube and target) as LeRobot's
``observation.environment_state`` (``ENV_STATE_NAMES``), the object and task state its policies read.

Action, float32[6] (``ACTION_NAMES``), every entry clipped to [-1, 1]

    idx  name             unit  meaning
    0    right_vx         m/s   right end-effector velocity command, x
    1    right_vy         m/s   right end-effector velocity command, y
    2    right_grip_cmd   -     +1 close, -1 open (finger speed = cmd * GRIP_SPEED)
    3    left_vx          m/s   left end-effector velocity command, x
    4    left_vy          m/s   left end-effector velocity command, y
    5    left_grip_cmd    -     +1 close, -1 open

Constants: FPS = 10 control steps per second; PHYSICS_DT = 0.01 s (SUBSTEPS = 10 physics
steps per control step); MAX_STEPS = 400 control steps; SUCCESS_TOL = 0.04 m;
SUCCESS_HOLD = 5 control steps; GRIP_SPEED = 0.08 m/s of finger travel (FINGER_TRAVEL = 0.02 m,
so a full close or open takes 0.25 s, i.e. 2.5 control steps).

Physics: each end-effector is a body on slide joints (x, y) whose joint ranges are the reach
limits, driven by velocity actuators (ctrl = commanded m/s, kv = 60). Joint limits are MuJoCo's
soft constraints: pushing into a limit at full speed overshoots it by about 2 mm. Each gripper is a finger
slide joint (0 .. FINGER_TRAVEL m) driven by a velocity actuator; closedness = finger position /
FINGER_TRAVEL, clipped to [0, 1]. Gravity is off and contacts are off (a planar, top-down
abstraction): the arms pass over each other and over the cube.

Grasp rule (deterministic, evaluated after every physics step, right arm first):
* a gripper ENGAGES the cube when its closedness > GRASP_ENGAGE (0.8) and its end-effector is
  within GRASP_RADIUS (0.03 m) of the cube centre (planar distance); the cube-minus-gripper
  offset at that instant is remembered.
* a gripper RELEASES the cube when its closedness drops below GRASP_RELEASE (0.5).
* while held, the cube is a kinematic attachment: its joint positions are set to the holder's
  end-effector position plus the remembered offset (the mean over both holders during a
  handoff, when both grippers hold it), and its joint velocities to the holders' mean velocity.
* when nobody holds it the cube rests on the table: at the moment of release its velocity is set
  to zero, and nothing moves it afterwards.

Reward and success: reward is 1.0 once the episode has succeeded, else 0.0. Success means the
cube centre is within SUCCESS_TOL of the target for SUCCESS_HOLD consecutive control steps,
whether or not a gripper still holds it. Success latches. ``done`` is True at success or after
MAX_STEPS control steps.

Spawn distribution (``reset(seed)``, all from ``np.random.default_rng(seed)`` built there):
* cube uniform in CUBE_X_RANGE x CUBE_Y_RANGE = [0.15, 0.30] x [-0.15, 0.15] m (right-only);
* target uniform in TARGET_X_RANGE x TARGET_Y_RANGE = [-0.30, -0.15] x [-0.15, 0.15] m
  (left-only);
* right end-effector uniform in [0.10, 0.30] x [-0.20, 0.20] m, left end-effector in
  [-0.30, -0.10] x [-0.20, 0.20] m; both grippers open, everything at rest.

Start, float[8] (``START_NAMES``): what ``set_start(...)`` takes, and ``reset(seed)`` draws

    idx  name      unit  meaning
    0    cube_x    m     cube centre x
    1    cube_y    m     cube centre y
    2    target_x  m     delivery target x
    3    target_y  m     delivery target y
    4    right_x   m     right end-effector x
    5    right_y   m     right end-effector y
    6    left_x    m     left end-effector x
    7    left_y    m     left end-effector y

``set_start(*start)`` places any start with both grippers open, nothing held, everything at rest
and fresh step and success counters; ``reset(seed)`` is its draw followed by ``set_start``, so
the same start gives the same bytes either way. The grasp signals (engaged, released) are read
through the ``holding`` accessor after each step.
"""

from __future__ import annotations

import copy
from pathlib import Path

import mujoco
import numpy as np

XML_PATH = Path(__file__).with_name("aloha.xml")

FPS = 10  # control steps per second
PHYSICS_DT = 0.01  # s, MuJoCo timestep
SUBSTEPS = round(1.0 / (FPS * PHYSICS_DT))  # physics steps per control step (10)
MAX_STEPS = 400  # control steps per episode
SUCCESS_TOL = 0.04  # m, cube-to-target distance
SUCCESS_HOLD = 5  # consecutive control steps within SUCCESS_TOL
ACT_DIM = 6
OBS_DIM = 10

# Reach limits (m): these are the slide-joint ranges in aloha.xml (checked at load time).
RIGHT_X_RANGE = (-0.05, 0.35)
LEFT_X_RANGE = (-0.35, 0.05)
Y_RANGE = (-0.25, 0.25)
HANDOFF_HALF_WIDTH = 0.05  # m, the two reaches overlap for |x| < this

# Spawn regions (m).
CUBE_X_RANGE = (0.15, 0.30)
CUBE_Y_RANGE = (-0.15, 0.15)
TARGET_X_RANGE = (-0.30, -0.15)
TARGET_Y_RANGE = (-0.15, 0.15)
RIGHT_START_X_RANGE = (0.10, 0.30)
LEFT_START_X_RANGE = (-0.30, -0.10)
START_Y_RANGE = (-0.20, 0.20)

# Gripper and grasp rule.
FINGER_TRAVEL = 0.02  # m, finger slide range (closedness 1 = fully closed)
GRIP_SPEED = 0.08  # m/s of finger travel at |grip command| = 1
GRASP_ENGAGE = 0.8  # closedness above which a gripper near the cube grasps it
GRASP_RELEASE = 0.5  # closedness below which a holding gripper lets go
GRASP_RADIUS = 0.03  # m, end-effector-to-cube distance for a grasp to engage
# m an end-effector may pass its reach: MuJoCo's soft joint limits yield ~2 mm under steady full-speed
# pushing and up to 13.6 mm under full-speed random actions (12,000 steps, 30 seeds; 2026-11-25)
LIMIT_SLACK = 0.03

STATE_NAMES = (
    "right_x",
    "right_y",
    "right_grip",
    "left_x",
    "left_y",
    "left_grip",
    "cube_x",
    "cube_y",
    "target_x",
    "target_y",
)
ACTION_NAMES = ("right_vx", "right_vy", "right_grip_cmd", "left_vx", "left_vy", "left_grip_cmd")
# LeRobot's convention puts the object and task state in observation.environment_state (its
# policies need it or an image): here the cube and the target, state indices 6..9, by name.
ENV_STATE_NAMES = STATE_NAMES[6:]  # cube_x, cube_y, target_x, target_y
# set_start's arguments, in order (m): objects first, then the two end-effectors.
START_NAMES = ("cube_x", "cube_y", "target_x", "target_y", "right_x", "right_y", "left_x", "left_y")
ROBOT_TYPE = "aloha_planar_bimanual"
TASK = "Pick the cube with the right arm, hand it to the left arm, and place it on the target."

_ARMS = ("right", "left")
SIM_STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # everything mj_step reads: what a copy or a pickle carries


class AlohaCubeEnv:
    """Bimanual planar cube handoff. See the module docstring for the full contract."""

    max_steps = MAX_STEPS  # control steps an episode lasts at most (read by python -m datagen.check)

    def __init__(self, model: mujoco.MjModel | None = None) -> None:
        """model: another AlohaCubeEnv's compiled aloha.xml to share, else aloha.xml is loaded. MuJoCo
        only reads a model while stepping, so envs sharing one step independently, each in its own
        MjData (datagen.lockstep's lanes share one)."""
        self.model = model if model is not None else mujoco.MjModel.from_xml_path(str(XML_PATH))
        self.data = mujoco.MjData(self.model)
        m, d = self.model, self.data
        if abs(m.opt.timestep - PHYSICS_DT) > 1e-12:
            raise ValueError(f"aloha.xml timestep {m.opt.timestep} != PHYSICS_DT {PHYSICS_DT}")
        for arm, xr in (("right", RIGHT_X_RANGE), ("left", LEFT_X_RANGE)):
            for joint, want in (
                (f"{arm}_x", xr),
                (f"{arm}_y", Y_RANGE),
                (f"{arm}_finger", (0.0, FINGER_TRAVEL)),
            ):
                if not np.allclose(m.joint(joint).range, want):
                    raise ValueError(f"aloha.xml range of {joint} differs from aloha_env's {want}")
        # Named views into data (numpy views that stay valid across mj_resetData).
        self._jx = {a: d.joint(f"{a}_x") for a in _ARMS}
        self._jy = {a: d.joint(f"{a}_y") for a in _ARMS}
        self._jf = {a: d.joint(f"{a}_finger") for a in _ARMS}
        self._cube_x = d.joint("cube_x")
        self._cube_y = d.joint("cube_y")
        self._act_vx = {a: d.actuator(f"{a}_vx") for a in _ARMS}
        self._act_vy = {a: d.actuator(f"{a}_vy") for a in _ARMS}
        self._act_grip = {a: d.actuator(f"{a}_grip") for a in _ARMS}
        self._target_site = m.site("target")
        self._target = np.zeros(2)
        self._holding = {a: False for a in _ARMS}
        self._offset = {a: np.zeros(2) for a in _ARMS}
        self._steps = 0
        self._in_tol = 0
        self._success = False
        self._renderer = None

    # ------------------------------------------------------------------ episode API
    def reset(self, seed: int) -> np.ndarray:
        """Start a new episode; every random draw comes from ``np.random.default_rng(seed)``."""
        rng = np.random.default_rng(seed)
        cube = np.array([rng.uniform(*CUBE_X_RANGE), rng.uniform(*CUBE_Y_RANGE)])
        target = np.array([rng.uniform(*TARGET_X_RANGE), rng.uniform(*TARGET_Y_RANGE)])
        right = np.array([rng.uniform(*RIGHT_START_X_RANGE), rng.uniform(*START_Y_RANGE)])
        left = np.array([rng.uniform(*LEFT_START_X_RANGE), rng.uniform(*START_Y_RANGE)])
        return self.set_start(*cube, *target, *right, *left)

    def set_start(
        self,
        cube_x: float,
        cube_y: float,
        target_x: float,
        target_y: float,
        right_x: float,
        right_y: float,
        left_x: float,
        left_y: float,
    ) -> np.ndarray:
        """Place cube, target and both end-effectors (m, ``START_NAMES`` order) with both grippers
        open, nothing held and everything at rest; zero the step and success counters; return the obs.

        ``reset(seed)`` draws its start and calls this, so the same start gives the same obs and
        episode either way. The caller keeps the start inside the reach limits (see the module
        docstring); a position beyond a joint range is pulled back by the joint limit on the first step.
        """
        mujoco.mj_resetData(self.model, self.data)
        for a, p in (("right", (right_x, right_y)), ("left", (left_x, left_y))):
            self._jx[a].qpos[0] = p[0]
            self._jy[a].qpos[0] = p[1]
            self._jf[a].qpos[0] = 0.0
            self._holding[a] = False
            self._offset[a][:] = 0.0
        self._cube_x.qpos[0] = cube_x
        self._cube_y.qpos[0] = cube_y
        self._target[:] = (target_x, target_y)
        self._target_site.pos[:2] = self._target
        mujoco.mj_forward(self.model, self.data)
        self._steps = 0
        self._in_tol = 0
        self._success = False
        return self._obs()

    def step(self, action):
        """Apply one control step (SUBSTEPS physics steps). Returns (obs, reward, done, info)."""
        a = np.asarray(action, dtype=np.float64).reshape(ACT_DIM)
        if not np.all(np.isfinite(a)):  # MuJoCo would zero the controls and write MUJOCO_LOG.TXT here
            raise ValueError(f"non-finite action {a}")
        a = np.clip(a, -1.0, 1.0)
        for i, arm in enumerate(_ARMS):
            self._act_vx[arm].ctrl[0] = a[3 * i]
            self._act_vy[arm].ctrl[0] = a[3 * i + 1]
            self._act_grip[arm].ctrl[0] = a[3 * i + 2] * GRIP_SPEED
        m, d = self.model, self.data
        for _ in range(SUBSTEPS):
            mujoco.mj_step(m, d)
            self._apply_grasp()
        self._steps += 1
        cube = np.array([self._cube_x.qpos[0], self._cube_y.qpos[0]])
        if np.hypot(*(cube - self._target)) < SUCCESS_TOL:
            self._in_tol += 1
        else:
            self._in_tol = 0
        if self._in_tol >= SUCCESS_HOLD:
            self._success = True
        done = self._success or self._steps >= MAX_STEPS
        info = {"success": self._success, "steps": self._steps}
        return self._obs(), float(self._success), done, info

    def _apply_grasp(self) -> None:
        """Grasp rule of the module docstring, run after every physics step."""
        cube = np.array([self._cube_x.qpos[0], self._cube_y.qpos[0]])
        held_any_before = self._holding["right"] or self._holding["left"]
        pos_sum = np.zeros(2)
        vel_sum = np.zeros(2)
        n = 0
        for arm in _ARMS:
            ee = np.array([self._jx[arm].qpos[0], self._jy[arm].qpos[0]])
            closed = self._closedness(arm)
            if self._holding[arm]:
                if closed < GRASP_RELEASE:
                    self._holding[arm] = False
            elif closed > GRASP_ENGAGE and np.hypot(*(cube - ee)) < GRASP_RADIUS:
                self._holding[arm] = True
                self._offset[arm] = cube - ee
            if self._holding[arm]:
                pos_sum += ee + self._offset[arm]
                vel_sum += (self._jx[arm].qvel[0], self._jy[arm].qvel[0])
                n += 1
        if n:
            self._cube_x.qpos[0], self._cube_y.qpos[0] = pos_sum / n
            self._cube_x.qvel[0], self._cube_y.qvel[0] = vel_sum / n
        elif held_any_before:
            self._cube_x.qvel[0] = 0.0
            self._cube_y.qvel[0] = 0.0

    def _closedness(self, arm: str) -> float:
        return float(min(max(self._jf[arm].qpos[0] / FINGER_TRAVEL, 0.0), 1.0))

    def _obs(self) -> np.ndarray:
        return np.array(
            [
                self._jx["right"].qpos[0],
                self._jy["right"].qpos[0],
                self._closedness("right"),
                self._jx["left"].qpos[0],
                self._jy["left"].qpos[0],
                self._closedness("left"),
                self._cube_x.qpos[0],
                self._cube_y.qpos[0],
                self._target[0],
                self._target[1],
            ],
            dtype=np.float32,
        )

    # ------------------------------------------------------------------ read-only accessors
    @property
    def right_ee(self) -> np.ndarray:
        """Right end-effector (x, y) in m (a copy)."""
        return np.array([self._jx["right"].qpos[0], self._jy["right"].qpos[0]])

    @property
    def left_ee(self) -> np.ndarray:
        """Left end-effector (x, y) in m (a copy)."""
        return np.array([self._jx["left"].qpos[0], self._jy["left"].qpos[0]])

    @property
    def grip(self) -> tuple[float, float]:
        """(right, left) gripper closedness, 0 open .. 1 closed."""
        return (float(self._closedness("right")), float(self._closedness("left")))

    @property
    def cube_pos(self) -> np.ndarray:
        """Cube centre (x, y) in m (a copy)."""
        return np.array([self._cube_x.qpos[0], self._cube_y.qpos[0]])

    @property
    def target_pos(self) -> np.ndarray:
        """Delivery target (x, y) in m (a copy)."""
        return self._target.copy()

    @property
    def holding(self) -> tuple[bool, bool]:
        """(right holds the cube, left holds the cube)."""
        return (self._holding["right"], self._holding["left"])

    @property
    def steps(self) -> int:
        """Control steps taken in this episode."""
        return self._steps

    @property
    def success(self) -> bool:
        """True once the success rule has been met in this episode (latched)."""
        return self._success

    # ------------------------------------------------------------------ copy and pickle
    def __getstate__(self) -> dict:
        """What copy.deepcopy and pickle carry (Gymnasium's vector envs and RL libraries copy, pickle and
        checkpoint envs): the model, this env's simulator state (mjSTATE_INTEGRATION: everything mj_step
        reads) and its episode state. Not the MjData, its named views or the renderer: __setstate__
        makes them anew, so the copy steps as the env would, bit for bit."""
        state = np.empty(mujoco.mj_stateSize(self.model, SIM_STATE))
        mujoco.mj_getState(self.model, self.data, state, SIM_STATE)
        keep = ("_target", "_holding", "_offset", "_steps", "_in_tol", "_success")
        return {"model": self.model, "state": state, **{k: getattr(self, k) for k in keep}}

    def __setstate__(self, saved: dict) -> None:
        """A new env on the saved model, put in the saved state."""
        saved = dict(saved)
        self.__init__(saved.pop("model"))
        mujoco.mj_setState(self.model, self.data, saved.pop("state"), SIM_STATE)
        for k, v in copy.deepcopy(saved).items():
            setattr(self, k, v)
        self._target_site.pos[:2] = self._target
        mujoco.mj_forward(self.model, self.data)  # derived quantities (render) from the loaded state

    # ------------------------------------------------------------------ rendering
    def render(self, size: int = 96) -> np.ndarray:
        """Top-down uint8 image (size, size, 3) from the fixed "top" camera.

        Needs an OpenGL backend (for headless machines set MUJOCO_GL=egl or osmesa before
        importing mujoco); raises if none is available.
        """
        if self._renderer is None or self._renderer.height != size:
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = mujoco.Renderer(self.model, height=size, width=size)
        mujoco.mj_forward(self.model, self.data)
        self._renderer.update_scene(self.data, camera="top")
        return self._renderer.render().copy()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
