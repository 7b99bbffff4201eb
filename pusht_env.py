"""PushT: push a T-shaped block onto a fixed target pose with a round, velocity-controlled pusher.

Real MuJoCo physics (``pusht.xml`` beside this file), top-down and planar. The block has slide x,
slide y and hinge yaw joints with heavy damping, so it moves only while it is pushed
(quasi-static); the pusher is a puck of radius 0.015 m driven by two velocity servos. Walls stand
0.42 m from the centre. Physics runs at 100 Hz, control at 10 Hz (10 physics steps per action).
Everything is read and written through MuJoCo's named accessors, never by raw array layout.

Observation, float32[10] (``STATE_NAMES``):

    | index | name           | unit | meaning                                      |
    |-------|----------------|------|----------------------------------------------|
    | 0     | pusher_x       | m    | pusher centre x                              |
    | 1     | pusher_y       | m    | pusher centre y                              |
    | 2     | block_x        | m    | block origin x (origin = centre of the bar)  |
    | 3     | block_y        | m    | block origin y                               |
    | 4     | block_sin_yaw  | -    | sin(block yaw)                               |
    | 5     | block_cos_yaw  | -    | cos(block yaw)                               |
    | 6     | target_x       | m    | target x, always 0                           |
    | 7     | target_y       | m    | target y, always 0                           |
    | 8     | target_sin_yaw | -    | sin(target yaw), always 0                    |
    | 9     | target_cos_yaw | -    | cos(target yaw), always 1                    |

The demo sets also store indices 2..9 (block and target pose) as LeRobot's
``observation.environment_state`` (``ENV_STATE_NAMES``), the object and task state its policies read.

Action, float32[2] (``ACTION_NAMES``): the pusher's target velocity, clipped to [-1, 1] before
use (the clip is the env's, so any policy output is safe to pass in):

    | index | name      | unit | meaning                  |
    |-------|-----------|------|--------------------------|
    | 0     | pusher_vx | m/s  | commanded x velocity     |
    | 1     | pusher_vy | m/s  | commanded y velocity     |

Constants: ``FPS`` = 10 Hz control, ``PHYSICS_DT`` = 0.01 s, ``MAX_STEPS`` = 300 control steps
(30 s), ``SUCCESS_POS_TOL`` = 0.03 m, ``SUCCESS_YAW_TOL`` = 0.20 rad, ``SUCCESS_HOLD`` = 5 steps.

Success: the block origin within ``SUCCESS_POS_TOL`` of the target and the wrapped yaw error
below ``SUCCESS_YAW_TOL`` for ``SUCCESS_HOLD`` consecutive control steps. Success latches (it stays
True until the next reset or set_start). The episode is done at success or after ``MAX_STEPS``.

Reward: 1.0 on every step once success has latched; otherwise minus the pose error,
``-(pos_error_m + YAW_REWARD_SCALE * |yaw_error_rad|)`` with ``YAW_REWARD_SCALE`` = 0.05 m/rad.

Start distribution of ``reset(seed)`` (every draw from ``np.random.default_rng(seed)``):
    block distance from the target  uniform [SPAWN_R_MIN, SPAWN_R_MAX] = [0.10, 0.24] m
    block direction from the target uniform [-pi, pi) rad
    block yaw                       uniform [-pi, pi) rad
    pusher x, y                     uniform [-PUSHER_HALF, PUSHER_HALF] = [-0.32, 0.32] m each,
                                    re-drawn until its edge is at least SPAWN_CLEARANCE = 0.01 m
                                    from every part of the T
``set_start(...)`` places any other start with zero velocities and fresh counters.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

XML_PATH = Path(__file__).with_name("pusht.xml")

FPS = 10  # control steps per second (Hz)
PHYSICS_DT = 0.01  # physics step (s); must match pusht.xml's <option timestep>
SUBSTEPS = round(1.0 / (FPS * PHYSICS_DT))  # physics steps per control step (10)
MAX_STEPS = 300  # control steps per episode (30 s)
SUCCESS_POS_TOL = 0.03  # m
SUCCESS_YAW_TOL = 0.20  # rad
SUCCESS_HOLD = 5  # consecutive control steps inside both tolerances
SPAWN_R_MIN = 0.10  # m, block distance from target at reset
SPAWN_R_MAX = 0.24  # m
PUSHER_HALF = 0.32  # m, half-width of the square the pusher spawns in
SPAWN_CLEARANCE = 0.01  # m, gap between pusher edge and block at reset
YAW_REWARD_SCALE = 0.05  # m per rad, weighs yaw error against position error in the reward
ACT_DIM = 2
OBS_DIM = 10
ACTION_LIMIT = 1.0  # m/s, actions are clipped to [-1, 1]
STATE_NAMES = (
    "pusher_x",
    "pusher_y",
    "block_x",
    "block_y",
    "block_sin_yaw",
    "block_cos_yaw",
    "target_x",
    "target_y",
    "target_sin_yaw",
    "target_cos_yaw",
)
ACTION_NAMES = ("pusher_vx", "pusher_vy")
# LeRobot's convention puts the object and task state in observation.environment_state (its
# policies need it or an image): here the block and target poses, state indices 2..9, by name.
ENV_STATE_NAMES = STATE_NAMES[2:]  # block_x .. target_cos_yaw
ROBOT_TYPE = "pusht_pusher"
TASK = "Push the T-shaped block onto the target pose."

# T geometry in the block frame (m); must match pusht.xml. The origin is the centre of the bar.
BAR_HALF = (0.060, 0.015)  # bar half-sizes (x, y), centred at (0, 0)
STEM_HALF = (0.015, 0.045)  # stem half-sizes (x, y)
STEM_CENTER_Y = -0.060  # stem centre y: it spans y in [-0.105, -0.015]
PUSHER_RADIUS = 0.015  # m
WALL_INNER = 0.42  # m, distance from the centre to each wall's inner face
TARGET_POSE = (0.0, 0.0, 0.0)  # x (m), y (m), yaw (rad)
# Block "table friction" as joint damping (must match pusht.xml; checked at load). Their ratio
# sets how much a push rotates the block versus translating it; the scripted expert uses it.
BLOCK_SLIDE_DAMPING = 4.0  # N s/m on block_x and block_y
BLOCK_YAW_DAMPING = 0.02  # N m s/rad on block_yaw


def wrap_angle(a: float) -> float:
    """Wrap an angle (rad) to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def t_sdf(q: np.ndarray) -> np.ndarray:
    """Signed distance (m) from block-frame points q (..., 2) to the T; negative inside."""
    out = None
    for cy, (hx, hy) in ((0.0, BAR_HALF), (STEM_CENTER_Y, STEM_HALF)):
        ex = np.abs(q[..., 0]) - hx
        ey = np.abs(q[..., 1] - cy) - hy
        d = np.hypot(np.maximum(ex, 0.0), np.maximum(ey, 0.0)) + np.minimum(np.maximum(ex, ey), 0.0)
        out = d if out is None else np.minimum(out, d)
    return out


def t_signed_distance(px: float, py: float, block_x: float, block_y: float, block_yaw: float) -> float:
    """Signed distance (m) from the world point (px, py) to the T at the given pose; negative inside."""
    c, s = math.cos(block_yaw), math.sin(block_yaw)
    dx, dy = px - block_x, py - block_y
    return float(t_sdf(np.array([c * dx + s * dy, -s * dx + c * dy])))  # the point in the block frame


def pusher_clear(
    block_x: float,
    block_y: float,
    block_yaw: float,
    pusher_x: float,
    pusher_y: float,
    clearance: float = SPAWN_CLEARANCE,
) -> bool:
    """True when the pusher's edge is at least ``clearance`` m from every part of the T."""
    return t_signed_distance(pusher_x, pusher_y, block_x, block_y, block_yaw) >= PUSHER_RADIUS + clearance


SIM_STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # everything mj_step reads: what a copy or a pickle carries


def _check(model: mujoco.MjModel) -> None:
    """Refuse a pusht.xml whose timestep, damping or geometry differs from this module's constants."""
    if abs(model.opt.timestep - PHYSICS_DT) > 1e-12:
        raise ValueError(f"pusht.xml timestep {model.opt.timestep} != PHYSICS_DT {PHYSICS_DT}")
    for name, value in (
        ("block_x", BLOCK_SLIDE_DAMPING),
        ("block_y", BLOCK_SLIDE_DAMPING),
        ("block_yaw", BLOCK_YAW_DAMPING),
    ):
        if abs(float(model.joint(name).damping[0]) - value) > 1e-12:
            raise ValueError(f"pusht.xml damping of {name} differs from pusht_env's {value}")
    geo = model.geom
    if (
        abs(float(geo("pusher").size[0]) - PUSHER_RADIUS) > 1e-12
        or not np.allclose(geo("block_bar").size[:2], BAR_HALF)
        or not np.allclose(geo("block_stem").size[:2], STEM_HALF)
        or not np.isclose(geo("block_stem").pos[1], STEM_CENTER_Y)
    ):
        raise ValueError("pusht.xml geometry differs from pusht_env's constants")


class PushTEnv:
    """The PushT task. ``reset(seed)`` or ``set_start(...)``, then ``step(action)`` at 10 Hz."""

    max_steps = MAX_STEPS  # control steps an episode lasts at most (read by python -m datagen.check)

    def __init__(self, model: mujoco.MjModel | None = None) -> None:
        """model: another PushTEnv's compiled pusht.xml to share (MuJoCo only reads a model while it
        steps), else pusht.xml is loaded (~4 ms) and checked. Each env steps in its own MjData."""
        if model is None:
            model = mujoco.MjModel.from_xml_path(str(XML_PATH))
            _check(model)
        self.model = model
        self._attach(mujoco.MjData(model))

    def _attach(self, data: mujoco.MjData) -> None:
        """Use `data` as this env's simulator: named views into it, fresh counters, the default start."""
        self.data = d = data
        # Named views into MjData (numpy views of length 1): reading/writing them touches the
        # simulator state directly, with no assumption about where each joint sits in qpos.
        self._bx, self._by, self._byaw = (d.joint(n).qpos for n in ("block_x", "block_y", "block_yaw"))
        self._px, self._py = (d.joint(n).qpos for n in ("pusher_x", "pusher_y"))
        self._ctrl_x, self._ctrl_y = (d.actuator(n).ctrl for n in ACTION_NAMES)
        self._renderers: dict[int, mujoco.Renderer] = {}
        self._steps = 0
        self._hold = 0
        self._success = False
        self._obs = np.zeros(OBS_DIM, dtype=np.float32)
        self.set_start(0.15, 0.0, 0.0, 0.0, 0.30)

    # ----- public read-only state -----
    @property
    def pusher_pos(self) -> np.ndarray:
        """Pusher centre (x, y) in m, a copy."""
        return np.array([self._px[0], self._py[0]])

    @property
    def block_pose(self) -> np.ndarray:
        """Block (x m, y m, yaw rad wrapped to [-pi, pi)), a copy."""
        return np.array([self._bx[0], self._by[0], wrap_angle(float(self._byaw[0]))])

    @property
    def target_pose(self) -> np.ndarray:
        """Target (x m, y m, yaw rad), a copy; fixed at (0, 0, 0)."""
        return np.array(TARGET_POSE, dtype=np.float64)

    @property
    def steps(self) -> int:
        """Control steps taken since the last reset or set_start."""
        return self._steps

    @property
    def success(self) -> bool:
        """True once the block has held the target pose for SUCCESS_HOLD steps (latched)."""
        return self._success

    # ----- episode control -----
    def reset(self, seed: int) -> np.ndarray:
        """Draw a start from ``np.random.default_rng(seed)`` alone and return the first obs."""
        rng = np.random.default_rng(seed)
        r = rng.uniform(SPAWN_R_MIN, SPAWN_R_MAX)
        direction = rng.uniform(-math.pi, math.pi)
        yaw = rng.uniform(-math.pi, math.pi)
        bx = TARGET_POSE[0] + r * math.cos(direction)
        by = TARGET_POSE[1] + r * math.sin(direction)
        while True:  # rejection sampling: the clear part of the square is most of it
            px, py = rng.uniform(-PUSHER_HALF, PUSHER_HALF, size=2)
            if pusher_clear(bx, by, yaw, px, py):
                break
        return self.set_start(bx, by, yaw, float(px), float(py))

    def set_start(
        self, block_x: float, block_y: float, block_yaw: float, pusher_x: float, pusher_y: float
    ) -> np.ndarray:
        """Place block (m, m, rad) and pusher (m, m) at rest, zero the counters, return the obs.

        The caller keeps the pusher clear of the block (see ``pusher_clear``); an overlapping
        start is resolved by the contact solver pushing the two apart on the first step.
        """
        mujoco.mj_resetData(self.model, self.data)
        self._bx[0], self._by[0], self._byaw[0] = block_x, block_y, wrap_angle(float(block_yaw))
        self._px[0], self._py[0] = pusher_x, pusher_y
        mujoco.mj_forward(self.model, self.data)
        self._steps = 0
        self._hold = 0
        self._success = False
        return self._observe()

    def step(self, action) -> tuple[np.ndarray, float, bool, dict]:
        """Apply a pusher velocity (m/s, clipped to [-1, 1]) for one 0.1 s control step."""
        a = np.asarray(action, dtype=np.float64).reshape(ACT_DIM)
        if not np.all(np.isfinite(a)):
            raise ValueError(f"non-finite action {a}")
        pos_err, yaw_err = self._advance(
            min(max(a[0], -ACTION_LIMIT), ACTION_LIMIT), min(max(a[1], -ACTION_LIMIT), ACTION_LIMIT)
        )
        reward = 1.0 if self._success else -(pos_err + YAW_REWARD_SCALE * abs(yaw_err))
        done = self._success or self._steps >= MAX_STEPS
        info = {"success": self._success, "steps": self._steps, "pos_error": pos_err, "yaw_error": yaw_err}
        return self._observe(), reward, done, info

    def _advance(self, vx: float, vy: float) -> tuple[float, float]:
        """One control step at the clipped velocity (vx, vy) m/s: the physics, the step count and the
        success hold. Returns the pose error after it (pos m, wrapped yaw rad)."""
        self._ctrl_x[0], self._ctrl_y[0] = vx, vy
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        self._steps += 1
        pos_err = math.hypot(self._bx[0] - TARGET_POSE[0], self._by[0] - TARGET_POSE[1])
        yaw_err = wrap_angle(float(self._byaw[0]) - TARGET_POSE[2])
        if pos_err < SUCCESS_POS_TOL and abs(yaw_err) < SUCCESS_YAW_TOL:
            self._hold += 1
        else:
            self._hold = 0
        if self._hold >= SUCCESS_HOLD:
            self._success = True
        return pos_err, yaw_err

    def _observe(self) -> np.ndarray:
        self._fill(self._obs)
        return self._obs.copy()

    def _fill(self, o: np.ndarray) -> None:
        """Write the observation (STATE_NAMES) into o, a float32[OBS_DIM]."""
        yaw = float(self._byaw[0])
        o[0], o[1] = self._px[0], self._py[0]
        o[2], o[3] = self._bx[0], self._by[0]
        o[4], o[5] = math.sin(yaw), math.cos(yaw)
        o[6], o[7] = TARGET_POSE[0], TARGET_POSE[1]
        o[8], o[9] = math.sin(TARGET_POSE[2]), math.cos(TARGET_POSE[2])

    # ----- copy and pickle (Gymnasium's vector envs and RL libraries copy, pickle and checkpoint envs) -----
    def __getstate__(self) -> dict:
        """What copy.deepcopy and pickle carry: this env's simulator state (SIM_STATE) and its episode
        counters. Not the MjData, its named views or the renderers: __setstate__ makes them anew, so the
        copy steps as the env would, bit for bit."""
        state = np.empty(mujoco.mj_stateSize(self.model, SIM_STATE))
        mujoco.mj_getState(self.model, self.data, state, SIM_STATE)
        counters = {k: getattr(self, k) for k in ("_steps", "_hold", "_success", "_obs")}
        return {"state": state, **counters}

    def __setstate__(self, saved: dict) -> None:
        """A new env (pusht.xml loaded: the env never changes its model) put in the saved state."""
        saved = dict(saved)
        self.__init__()
        mujoco.mj_setState(self.model, self.data, saved.pop("state"), SIM_STATE)
        mujoco.mj_forward(self.model, self.data)  # derived quantities (render) from the loaded state
        for k, v in saved.items():
            setattr(self, k, v.copy() if isinstance(v, np.ndarray) else v)

    # ----- rendering (optional; needs an OpenGL backend such as EGL or OSMesa) -----
    def render(self, size: int = 96) -> np.ndarray:
        """Top-down RGB image, uint8 (size, size, 3), from the fixed camera "top" (MUJOCO_GL=egl)."""
        renderer = self._renderers.get(size)
        if renderer is None:
            renderer = mujoco.Renderer(self.model, height=size, width=size)
            self._renderers[size] = renderer
        renderer.update_scene(self.data, camera="top")
        return renderer.render().copy()

    def close(self) -> None:
        """Free any renderers (GL contexts)."""
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
