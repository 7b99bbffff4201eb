"""PushT and the ALOHA handoff as Gymnasium environments; importing this module registers both, and
gym-aloha's transfer-cube and insertion on its ViperX model files (issue 50: AlohaSimGym, below).

    import gymnasium as gym
    import gym_envs  # noqa: F401  (registers the ids)

    env = gym.make("ch37/PushT-v0", render_mode="rgb_array")        # or "ch37/AlohaHandoff-v0"
    obs, info = env.reset(seed=0)                                   # the start PushTEnv().reset(0) draws
    obs, info = env.reset(options={"start": (0.15, 0.0, 0.0, 0.0, 0.30)})  # a chosen start
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    frame = env.render()                                            # uint8 (96, 96, 3), the top camera

Each class wraps the lesson's own simulator (pusht_env.PushTEnv, aloha_env.AlohaCubeEnv, kept as they are
with their 4-tuple step) and adds what Gymnasium asks for:

* Box spaces, float32, with the bounds and units of the env modules' index tables (below).
* ``reset(seed=s)`` starts the episode the simulator's ``reset(s)`` starts, so the same seed gives the same
  episode through either interface; ``reset()`` with no seed draws the simulator's seed from the env's
  np_random (seeded by the last seed given). ``options={"start": ...}`` places a chosen start instead
  (the data engine's move): PushT takes set_start's five numbers (block x m, y m, yaw rad, pusher x m,
  y m; a sequence or a mapping by those names), ALOHA the eight numbers of aloha_env.START_NAMES
  (cube, target, right and left end-effector (x, y), m).
  A start outside the observation space is a ValueError.
* ``step`` returns (obs, reward, terminated, truncated, info): terminated once success has latched,
  truncated at the simulator's step limit without success (PushT 300, ALOHA 400 control steps at 10 Hz).
  info is the simulator's ("success", "steps", ...).
* ``render()`` in "rgb_array" mode: the simulator's top-down renderer, uint8 (render_size, render_size, 3).
  It needs an OpenGL backend, which is yours to choose: MuJoCo reads MUJOCO_GL once, when it is first
  imported, so set it in the environment before that (headless Linux: MUJOCO_GL=egl, or osmesa; importing
  this module sets nothing); without one it raises gymnasium.error.DependencyNotInstalled with one line
  saying what to install (and so does
  ``import gym_envs`` where MUJOCO_GL names a backend whose library cannot even be loaded, such as
  osmesa without libOSMesa: MuJoCo then fails as it is imported).

Observation bounds: PushT positions within the walls (|x|, |y| <= WALL_INNER = 0.42 m), sin and cos in
[-1, 1] (the target's too, though it is fixed at (0, 0, 0, 1)). ALOHA end-effectors within their reach
(aloha_env's joint ranges) widened by LIMIT_SLACK = 0.03 m (MuJoCo's soft limits let full-speed
actions overshoot by up to 14 mm), grippers in [0, 1], cube and target within both reaches widened by
GRASP_RADIUS (a held cube sits up to that far from its gripper) plus LIMIT_SLACK.
Actions: Box(-1, 1), the range both simulators clip to.

gym-aloha's own ids (gym_aloha/AlohaTransferCube-v0) need dm_control, which fails on our mujoco; these run
its model files through mujoco directly (datagen.tasks.aloha_sim), the engine's env for
aloha_transfer_cube and aloha_insertion, with state observations instead of pixels; render_mode="rgb_array"
renders gym-aloha's render() frame (its "top" camera, 640 x 480 or visualization_width x
visualization_height, the same GL backend as above):

    env = gym.make("ch37/AlohaSimTransferCube-v0")    # or "ch37/AlohaSimInsertion-v0"
    obs, info = env.reset(seed=0)     # the objects where gym-aloha's reset(seed=0) puts them
    obs, info = env.reset(options={"reset_to_state": poses})   # the objects' poses (7 numbers each)

A scene, render_mode, reset_to_state (not 7 finite numbers per object, or an all-zero quaternion) or action
(not 14 finite numbers) it cannot take is a ValueError saying what it takes, as PushT's.

obs float32: the 14 numbers of lerobot/aloha_sim_*'s observation.state, then the objects' poses (the
cube's, or the peg's and the socket's); action float32[14] (per arm 6 joint targets, rad, and a
normalized gripper); terminated at gym-aloha's top reward stage (info["is_success"]), truncated after
ACT's 400 steps.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces


def _no_gl(what: str, e: BaseException) -> str:
    """The one line that says what to install when MUJOCO_GL's backend fails (at `what`)."""
    backend = os.environ.get("MUJOCO_GL", "glfw")
    return (
        f"{what} needs an OpenGL backend; MUJOCO_GL={backend} failed ({type(e).__name__}): "
        "use MUJOCO_GL=egl (apt-get install libegl1) or MUJOCO_GL=osmesa (apt-get install libosmesa6)"
    )


try:  # MUJOCO_GL=osmesa without libOSMesa fails inside PyOpenGL as mujoco is imported, not at render()
    import mujoco
except (AttributeError, OSError) as e:
    raise gym.error.DependencyNotInstalled(_no_gl("importing mujoco", e)) from None

import aloha_env  # noqa: E402
import pusht_env  # noqa: E402
from datagen.tasks.aloha_insertion import SPEC as INSERTION_SPEC  # noqa: E402
from datagen.tasks.aloha_transfer_cube import SPEC as TRANSFER_CUBE_SPEC  # noqa: E402

__all__ = ["PUSHT_ID", "ALOHA_ID", "PushTGym", "AlohaHandoffGym", "LIMIT_SLACK"]
__all__ += ["ALOHA_SIM_IDS", "AlohaSimGym"]

PUSHT_ID = "ch37/PushT-v0"
ALOHA_ID = "ch37/AlohaHandoff-v0"
# gym-aloha's tasks (datagen.tasks.aloha_sim's scenes) by id, with their task specs (fps, ACT's step limit)
ALOHA_SIM_IDS = {
    "ch37/AlohaSimTransferCube-v0": ("transfer_cube", TRANSFER_CUBE_SPEC),
    "ch37/AlohaSimInsertion-v0": ("insertion", INSERTION_SPEC),
}
LIMIT_SLACK = aloha_env.LIMIT_SLACK  # m past a reach limit the observation space allows
SEED_RANGE = 2**63  # reset() without a seed draws the simulator's seed in [0, SEED_RANGE)


def _box(bounds: list[tuple[float, float]]) -> spaces.Box:
    lo, hi = np.array(bounds, dtype=np.float32).T
    return spaces.Box(lo, hi, dtype=np.float32)


class _SimGym(gym.Env):
    """What both share: the simulator's episode behind Gymnasium's reset, step, render and close."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": pusht_env.FPS}
    sim_class: type
    start_names: tuple[str, ...]

    def __init__(self, render_mode: str | None = None, render_size: int = 96) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode, self.render_size = render_mode, int(render_size)
        self.sim = self.sim_class()

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        start = (options or {}).get("start")
        if start is not None:
            args = [start[k] for k in self.start_names] if isinstance(start, Mapping) else list(start)
            if len(args) != len(self.start_names):
                raise ValueError(f"options['start'] takes {', '.join(self.start_names)}; got {start!r}")
            obs, sim_seed = self.sim.set_start(*args), None
            if not self.observation_space.contains(obs):
                raise ValueError(f"options['start'] {start!r} lies outside the observation space")
        else:
            sim_seed = seed if seed is not None else int(self.np_random.integers(SEED_RANGE))
            obs = self.sim.reset(sim_seed)
        return obs, {"sim_seed": sim_seed, "success": False, "steps": 0}

    def step(self, action):
        obs, reward, done, info = self.sim.step(action)
        terminated = bool(info["success"])
        return obs, float(reward), terminated, bool(done and not terminated), info

    def render(self):
        if self.render_mode != "rgb_array":
            return None  # Gymnasium's contract for render_mode=None
        try:
            return self.sim.render(self.render_size)
        except Exception as e:  # MuJoCo raises its own kinds (or AttributeError) when no GL context exists
            raise gym.error.DependencyNotInstalled(_no_gl("render()", e)) from e

    def close(self) -> None:
        self.sim.close()


class PushTGym(_SimGym):
    """pusht_env.PushTEnv as a gymnasium.Env: obs float32[10] (STATE_NAMES), action float32[2] m/s."""

    sim_class = pusht_env.PushTEnv
    start_names = ("block_x", "block_y", "block_yaw", "pusher_x", "pusher_y")  # set_start's arguments
    metadata = {"render_modes": ["rgb_array"], "render_fps": pusht_env.FPS}

    def __init__(self, render_mode: str | None = None, render_size: int = 96) -> None:
        super().__init__(render_mode, render_size)
        wall, unit = (-pusht_env.WALL_INNER, pusht_env.WALL_INNER), (-1.0, 1.0)
        # pusher x, y; block x, y, sin, cos; target x, y, sin, cos (the target's as wide as the block's:
        # Gymnasium's checker warns on a Box whose low equals its high, though the target is fixed today)
        self.observation_space = _box([wall, wall, wall, wall, unit, unit, wall, wall, unit, unit])
        lim = pusht_env.ACTION_LIMIT
        self.action_space = spaces.Box(-lim, lim, shape=(pusht_env.ACT_DIM,), dtype=np.float32)


class AlohaHandoffGym(_SimGym):
    """aloha_env.AlohaCubeEnv as a gymnasium.Env: obs float32[10] (STATE_NAMES), action float32[6]."""

    sim_class = aloha_env.AlohaCubeEnv
    start_names = aloha_env.START_NAMES  # set_start's arguments, m each
    metadata = {"render_modes": ["rgb_array"], "render_fps": aloha_env.FPS}

    def __init__(self, render_mode: str | None = None, render_size: int = 96) -> None:
        super().__init__(render_mode, render_size)
        a, s = aloha_env, LIMIT_SLACK

        def widen(r, by):
            return (r[0] - by, r[1] + by)

        rx, lx, y = (widen(r, s) for r in (a.RIGHT_X_RANGE, a.LEFT_X_RANGE, a.Y_RANGE))
        obj_x = widen((a.LEFT_X_RANGE[0], a.RIGHT_X_RANGE[1]), a.GRASP_RADIUS + s)
        obj_y = widen(a.Y_RANGE, a.GRASP_RADIUS + s)
        grip = (0.0, 1.0)
        self.observation_space = _box([rx, y, grip, lx, y, grip, obj_x, obj_y, obj_x, obj_y])
        self.action_space = spaces.Box(-1.0, 1.0, shape=(a.ACT_DIM,), dtype=np.float32)


class AlohaSimGym(gym.Env):
    """datagen.tasks.aloha_sim's TransferCubeEnv or InsertionEnv (`scene`) as a gymnasium.Env (see the module
    docstring); reset() with no seed draws gym-aloha's seed from the env's np_random. render_mode
    "rgb_array" renders as gym-aloha's render() does: its "top" camera, visualization_width x
    visualization_height (640 x 480, the models' offscreen buffer, at most), uint8."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": TRANSFER_CUBE_SPEC.fps}
    camera = "top"  # gym-aloha's render() camera

    def __init__(
        self,
        scene: str = "transfer_cube",
        render_mode: str | None = None,
        visualization_width: int = 640,
        visualization_height: int = 480,
    ) -> None:
        from datagen.tasks.aloha_sim import JOINT_IDS, InsertionEnv, TransferCubeEnv

        envs = {"transfer_cube": TransferCubeEnv, "insertion": InsertionEnv}
        if scene not in envs:  # a bare KeyError before
            raise ValueError(f"scene must be one of {sorted(envs)}, got {scene!r}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        spec = dict(ALOHA_SIM_IDS.values())[scene]
        self.sim = envs[scene](spec.max_steps)
        buf = self.sim.model.vis.global_
        size = (visualization_width, visualization_height)
        if (
            not all(isinstance(v, (int, np.integer)) and v > 0 for v in size)
            or size[0] > buf.offwidth
            or size[1] > buf.offheight
        ):
            # MuJoCo's renderer would refuse it only at the first render()
            raise ValueError(
                "visualization_width x visualization_height must be whole numbers from 1 up to at most "
                f"{buf.offwidth} x {buf.offheight} (the models' offscreen buffer), got {size[0]!r} x "
                f"{size[1]!r}"
            )
        self.render_mode, self.size, self.renderer = render_mode, size, None
        self.observation_space = self.sim.observation_space
        # the action's bounds: per arm, left first, its joints' ranges (rad) and the normalized grip [0, 1]
        r = self.sim.model.jnt_range
        lo, hi = (np.concatenate([np.r_[r[j, i], float(i)] for j in JOINT_IDS]) for i in (0, 1))
        self.action_space = spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(SEED_RANGE))
        return self.sim.reset(seed=seed, options=options)

    def step(self, action):
        return self.sim.step(action)

    def render(self):
        if self.render_mode != "rgb_array":
            return None  # Gymnasium's contract for render_mode=None
        try:
            if self.renderer is None:  # made at the first frame: a GL context only where one is drawn
                self.renderer = mujoco.Renderer(self.sim.model, height=self.size[1], width=self.size[0])
            self.renderer.update_scene(self.sim.data, camera=self.camera)
            return self.renderer.render().copy()
        except Exception as e:  # MuJoCo raises its own kinds (or AttributeError) when no GL context exists
            raise gym.error.DependencyNotInstalled(_no_gl("render()", e)) from e

    def close(self) -> None:
        if self.renderer is not None:
            self.renderer.close()
            self.renderer = None


def _register() -> None:
    for env_id, cls, sim in ((PUSHT_ID, PushTGym, pusht_env), (ALOHA_ID, AlohaHandoffGym, aloha_env)):
        if env_id not in gym.registry:  # importing twice (or reloading) registers once
            gym.register(env_id, entry_point=cls, max_episode_steps=sim.MAX_STEPS, nondeterministic=False)
    for env_id, (scene, spec) in ALOHA_SIM_IDS.items():
        if env_id not in gym.registry:
            kw = dict(max_episode_steps=spec.max_steps, nondeterministic=False, kwargs={"scene": scene})
            gym.register(env_id, entry_point=AlohaSimGym, **kw)


_register()
