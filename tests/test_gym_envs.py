"""PushT and the ALOHA handoff through Gymnasium (gym_envs.py): Gymnasium's own checker, the same episode as
the lesson's simulators for the same seed, terminated/truncated, chosen starts and rendering."""

import importlib.util
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from conftest import ROOT
from gymnasium.utils.env_checker import check_env

import aloha_env
import gym_envs
import pusht_env
from scripted_expert import AlohaExpert, PushTExpert

SPECS = [
    pytest.param(gym_envs.PUSHT_ID, pusht_env, pusht_env.PushTEnv, PushTExpert, id="pusht"),
    pytest.param(gym_envs.ALOHA_ID, aloha_env, aloha_env.AlohaCubeEnv, AlohaExpert, id="aloha"),
]


def gl_works() -> bool:
    from datagen import check_gl

    return check_gl() is None


@pytest.mark.parametrize("env_id,mod,Sim,Expert", SPECS)
def test_gymnasium_check_env_passes(env_id, mod, Sim, Expert):
    """gymnasium.make on the id, then Gymnasium's env_checker with every warning an error; with a renderer
    where this machine has an OpenGL backend, and its one-line error where it has none."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id)
        check_env(env.unwrapped)
        assert env.spec.max_episode_steps == mod.MAX_STEPS
        assert env.observation_space.shape == (mod.OBS_DIM,) and env.action_space.shape == (mod.ACT_DIM,)
        env = gym.make(env_id, render_mode="rgb_array")
        env.reset(seed=0)
        if gl_works():
            check_env(env.unwrapped)
            env.reset(seed=0)
            frame = env.render()
            assert frame.dtype == np.uint8 and frame.shape == (96, 96, 3) and frame.std() > 0
        else:
            with pytest.raises(gym.error.DependencyNotInstalled, match="OpenGL backend"):
                env.render()


@pytest.mark.parametrize("env_id,mod,Sim,Expert", SPECS)
def test_same_seed_same_episode_through_either_interface(env_id, mod, Sim, Expert):
    """The expert's episode from seed s: the lesson's 4-tuple env and gymnasium.make give the same obs
    bytes, rewards and end at every step; it ends terminated (success), not truncated."""
    seed = 11
    sim, expert = Sim(), Expert(noise=0.0)
    obs, done, ref = sim.reset(seed), False, []
    expert.reset()
    while not done:
        act = expert.act(obs)
        obs, r, done, info = sim.step(act)
        ref.append((act, obs, r, done, info["success"]))
    assert ref[-1][4], "the expert should solve this start"

    env = gym.make(env_id)
    obs, info = env.reset(seed=seed)
    assert obs.tobytes() == Sim().reset(seed).tobytes() and info["sim_seed"] == seed
    for act, o, r, done, success in ref:
        obs, reward, terminated, truncated, info = env.step(act)
        assert obs.tobytes() == o.tobytes() and reward == r
        assert (terminated, truncated) == (success and done, False)
    assert terminated and info["steps"] == len(ref)


@pytest.mark.parametrize("env_id,mod,Sim,Expert", SPECS)
def test_truncated_at_the_step_limit_without_success(env_id, mod, Sim, Expert):
    env = gym.make(env_id)
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, np.float32)  # nothing moves: no success
    for t in range(1, mod.MAX_STEPS + 1):
        obs, reward, terminated, truncated, info = env.step(zero)
        assert obs in env.observation_space and not terminated and truncated == (t == mod.MAX_STEPS)
    assert info["steps"] == mod.MAX_STEPS and not info["success"]
    # the unwrapped env truncates by itself, not only through gymnasium.make's TimeLimit wrapper
    raw = env.unwrapped
    raw.reset(seed=0)
    ends = [raw.step(zero)[3] for _ in range(mod.MAX_STEPS)]
    assert ends[-1] and not any(ends[:-1])


@pytest.mark.parametrize("env_id,mod,Sim,Expert", SPECS)
def test_observations_stay_in_the_space_under_full_speed_random_actions(env_id, mod, Sim, Expert):
    """Bang-bang actions push into the reach limits and reverse (ALOHA overshoots its soft limits)."""
    env = gym.make(env_id)
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        env.action_space.seed(seed)
        done = False
        while not done:
            obs, _, terminated, truncated, _ = env.step(np.sign(env.action_space.sample()))
            assert obs in env.observation_space, obs
            done = terminated or truncated


def test_pusht_start_option_places_set_starts_start():
    start = (0.15, -0.05, 0.4, -0.2, 0.25)  # block x m, y m, yaw rad, pusher x m, y m
    want = pusht_env.PushTEnv().set_start(*start)
    env = gym.make(gym_envs.PUSHT_ID)
    for given in (start, dict(zip(("block_x", "block_y", "block_yaw", "pusher_x", "pusher_y"), start))):
        obs, info = env.reset(seed=5, options={"start": given})
        assert obs.tobytes() == want.tobytes() and info["sim_seed"] is None
    with pytest.raises(ValueError, match="outside the observation space"):
        env.reset(options={"start": (0.9, 0.0, 0.0, 0.0, 0.3)})  # beyond the wall at 0.42 m
    with pytest.raises(ValueError, match="takes block_x"):
        env.reset(options={"start": (0.1, 0.0)})


def test_aloha_start_option_places_set_starts_start():
    values = (0.2, 0.1, -0.2, -0.1, 0.25, 0.0, -0.25, 0.05)  # cube, target, right, left: (x, y) m each
    start = dict(zip(aloha_env.START_NAMES, values))
    sim = aloha_env.AlohaCubeEnv()
    want = sim.set_start(**start)
    assert np.allclose(sim.cube_pos, values[0:2]) and np.allclose(sim.target_pos, values[2:4])
    assert np.allclose(sim.right_ee, values[4:6]) and np.allclose(sim.left_ee, values[6:8])
    env = gym.make(gym_envs.ALOHA_ID)
    obs, _ = env.reset(options={"start": start})
    assert obs.tobytes() == want.tobytes()
    obs, _ = env.reset(options={"start": values})
    assert obs.tobytes() == want.tobytes()
    # set_start is what reset(seed) does with the start it draws
    a, b = aloha_env.AlohaCubeEnv(), aloha_env.AlohaCubeEnv()
    o = a.reset(4)
    assert b.set_start(*a.cube_pos, *a.target_pos, *a.right_ee, *a.left_ee).tobytes() == o.tobytes()


@pytest.mark.parametrize("backend", ["disable", "osmesa", "glfw"])
def test_render_without_a_gl_backend_is_one_clear_line(backend):
    """MUJOCO_GL=disable stands for a machine without EGL or OSMesa: render() says what to install. Issue
    42 #11: MUJOCO_GL=osmesa without libOSMesa failed inside PyOpenGL as gym_envs was imported (a
    traceback, for the very backend the line recommends); it gives the same one line as glfw without a
    display. Where the backend's library is there and works, the frame is rendered instead."""
    code = (
        "import gymnasium as gym\n"
        "try:\n"
        "    import gym_envs\n"
        "    e = gym.make(gym_envs.PUSHT_ID, render_mode='rgb_array'); e.reset(seed=0)\n"
        "    print('rendered', e.render().shape)\n"
        "except gym.error.DependencyNotInstalled as x:\n    print(x)\n"
    )
    env = {"MUJOCO_GL": backend, "PATH": "/usr/bin:/bin"}  # no DISPLAY: glfw has no window system
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    line = p.stdout.strip()
    if backend == "osmesa" and line.startswith("rendered"):  # libOSMesa installed: it works
        return
    assert len(line.splitlines()) == 1 and f"MUJOCO_GL={backend} failed" in line, line
    assert "MUJOCO_GL=egl" in line and "apt-get install" in line, line


@pytest.mark.parametrize("env_id,mod,Sim,Expert", SPECS)
def test_a_copy_or_a_pickle_mid_episode_steps_as_the_env_bit_for_bit(env_id, mod, Sim, Expert):
    """Issue 42 #2: a deep copy or a pickle round trip of an env was dead (PushT: its named views copied as
    plain arrays, the pusher never moving) or refused with a MuJoCo traceback (ALOHA). Taken mid-episode,
    each copy steps on as the original does, bit for bit, and apart from it."""
    import copy
    import pickle

    env = gym.make(env_id).unwrapped
    env.reset(seed=3)
    actions = np.random.default_rng(0).uniform(-1, 1, (40, mod.ACT_DIM)).astype(np.float32)
    for a in actions[:15]:
        env.step(a)
    copies = [copy.deepcopy(env), pickle.loads(pickle.dumps(env))]
    assert all(c.sim.data is not env.sim.data for c in copies)
    start = env.sim.steps
    for a in actions[15:]:
        want = env.step(a)
        for c in copies:
            got = c.step(a)
            assert got[0].tobytes() == want[0].tobytes() and got[1:4] == want[1:4]
    assert all(c.sim.steps == env.sim.steps == start + 25 for c in copies)
    ones = np.ones(mod.ACT_DIM, np.float32)  # apart: the original and a copy step differently
    assert env.step(ones)[0].tobytes() != copies[0].step(-ones)[0].tobytes()


def test_a_copy_of_a_pusht_env_that_shares_an_mjdata_is_a_standalone_env():
    """A lockstep lane (datagen.tasks.fast_pusht.SharedPushTEnv made with share=) borrows another's MjData;
    its copy carries its own state only, in an MjData of its own, and steps as it does while the env it
    shared with steps too."""
    import copy
    import pickle

    from datagen.tasks.fast_pusht import SharedPushTEnv

    owner = SharedPushTEnv()
    owner.reset(1)
    lane = SharedPushTEnv(share=owner)
    lane.reset(2)
    actions = np.random.default_rng(1).uniform(-1, 1, (30, 2))
    for a in actions[:10]:
        lane.step(a)
        owner.step(-a)  # the owner's state is loaded last: the lane's is parked when copied
    copies = [copy.deepcopy(lane), pickle.loads(pickle.dumps(lane))]
    assert all(c.data is not owner.data for c in copies)
    for a in actions[10:]:
        want = lane.step(a)[0].tobytes()
        owner.step(-a)
        assert all(c.step(a)[0].tobytes() == want for c in copies)


@pytest.mark.parametrize("env_id,mod,Sim,Expert", SPECS)
def test_a_nan_action_is_refused_and_nothing_is_written(env_id, mod, Sim, Expert, tmp_path, monkeypatch):
    """Issue 42 #3: ALOHA took step(NaN): MuJoCo warned, zeroed the controls, returned a normal
    observation and wrote MUJOCO_LOG.TXT into the current folder. Both envs, plain and through
    Gymnasium, refuse it as PushT did (ValueError), and the current folder stays empty."""
    monkeypatch.chdir(tmp_path)
    for env in (Sim(), gym.make(env_id)):
        env.reset(seed=0) if isinstance(env, gym.Env) else env.reset(0)
        for bad in (np.full(mod.ACT_DIM, np.nan), np.r_[np.inf, np.zeros(mod.ACT_DIM - 1)]):
            with pytest.raises(ValueError, match="non-finite action"):
                env.step(bad)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(importlib.util.find_spec("gym_aloha") is None, reason="gym-aloha (its model files)")
def test_gym_alohas_two_tasks_through_gymnasium_make():
    """Issue 50: gymnasium.make("ch37/AlohaSimTransferCube-v0") and "ch37/AlohaSimInsertion-v0" pass
    Gymnasium's checker (every warning an error but its advice on unbounded observations and unnormalized
    actions) with ACT's 400-step limit; an expert episode from seed s
    through make is the engine's env's (the same obs bytes and rewards at every step) and ends terminated
    at gym-aloha's success."""
    from datagen import known_tasks
    from datagen.tasks.aloha_sim_expert import TransferCubeExpert

    for env_id in gym_envs.ALOHA_SIM_IDS:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            # the actions are joint targets in their joints' ranges, as the hub sets record them (gym-aloha
            # declares Box(-1, 1), which they leave): not the normalized box the checker recommends for RL
            warnings.filterwarnings("ignore", "(?s).*symmetric and normalized space")
            # the observed objects are unbounded (a dropped part may fall anywhere), as TransferCubeEnv has it
            warnings.filterwarnings("ignore", "(?s).*Box observation space m.* value is -?infinity")
            env = gym.make(env_id)
            check_env(env.unwrapped)
        assert env.spec.max_episode_steps == 400
    env, ref = gym.make("ch37/AlohaSimTransferCube-v0"), known_tasks()["aloha_transfer_cube"].make_env()
    (obs, _), expert = env.reset(seed=5000), TransferCubeExpert(seed=5000)
    assert obs.tobytes() == ref.reset(5000).tobytes()
    terminated = truncated = False
    while not (terminated or truncated):
        action = expert.act(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        want, want_reward, *_ = ref.step(action)
        assert obs.tobytes() == want.tobytes() and reward == want_reward
    assert terminated and not truncated and info["is_success"]


@pytest.mark.skipif(importlib.util.find_spec("gym_aloha") is None, reason="gym-aloha (its model files)")
def test_gym_alohas_envs_refuse_what_they_cannot_take_as_pusht_does(tmp_path, monkeypatch):
    """Issue 62 #9: gymnasium.make("ch37/AlohaSimTransferCube-v0", ...) answered scene="bogus" with a bare
    KeyError, Gymnasium's render_mode="rgb_array" with a TypeError, reset_to_state with 3 of the cube's 7
    pose numbers (7 of insertion's 14) by placing what it got, a NaN pose with NaN observations, and a 3-wide
    action with a bare IndexError. Each is a ValueError saying what it takes, as ch37/PushT-v0's, and a NaN
    action is refused as there, nothing written in the current folder."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="scene must be one of .*'insertion'.*'transfer_cube'.*got 'bogus'"):
        gym.make("ch37/AlohaSimTransferCube-v0", scene="bogus")
    with pytest.raises(ValueError, match="render_mode must be None or 'rgb_array', got 'bogus'"):
        gym.make("ch37/AlohaSimTransferCube-v0", render_mode="bogus")
    for env_id, n in (("ch37/AlohaSimTransferCube-v0", 7), ("ch37/AlohaSimInsertion-v0", 14)):
        env = gym.make(env_id)
        obs, _ = env.reset(seed=0)
        good = obs[14:].astype(np.float64)
        for bad in (good[:3], good[:7] if n == 14 else np.r_[good, 0.0], [good], "cube", None):
            with pytest.raises(ValueError, match=f"reset_to_state'\\] takes {n} finite numbers"):
                env.reset(options={"reset_to_state": bad})
        for value in (np.nan, np.inf):
            bad = good.copy()
            bad[1] = value
            with pytest.raises(ValueError, match=f"takes {n} finite numbers"):
                env.reset(options={"reset_to_state": bad})
        bad = good.copy()
        bad[3:7] = 0.0  # a quaternion of no rotation at all: MuJoCo would quietly stand the object upright
        with pytest.raises(ValueError, match="quaternion"):
            env.reset(options={"reset_to_state": bad})
        placed, _ = env.reset(options={"reset_to_state": good})  # what it takes still places it
        assert np.all(np.isfinite(placed)) and np.allclose(placed[14:], good, atol=1e-6)
        for bad in (np.zeros(3), np.zeros((2, 14)), np.full(14, np.nan), np.r_[np.inf, np.zeros(13)]):
            with pytest.raises(ValueError, match="action takes 14 finite numbers|non-finite action"):
                env.step(bad)
        assert env.step(np.zeros(14))[0].shape == obs.shape  # and a good one still steps
        env.close()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not gl_works(), reason="no OpenGL backend (MUJOCO_GL=egl or osmesa)")
@pytest.mark.skipif(importlib.util.find_spec("gym_aloha") is None, reason="gym-aloha (its model files)")
def test_gym_alohas_envs_render_rgb_array_from_the_top_camera():
    """Issue 62 #9: render_mode="rgb_array", as Gymnasium's envs take it (and gym-aloha's, 640 x 480 from
    its "top" camera by default, visualization_width/_height to choose): render() is that frame, uint8;
    render_mode=None renders nothing; a size past the models' offscreen buffer is a ValueError up front."""
    env = gym.make(
        "ch37/AlohaSimTransferCube-v0",
        render_mode="rgb_array",
        visualization_width=160,
        visualization_height=120,
    )
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (120, 160, 3) and frame.dtype == np.uint8 and frame.std() > 0
    env.step(env.unwrapped.sim.observation()[:14])
    assert env.render().shape == (120, 160, 3)
    env.close()
    plain = gym.make("ch37/AlohaSimInsertion-v0")
    plain.reset(seed=0)
    assert plain.render() is None
    with pytest.raises(ValueError, match="at most 640 x 480"):
        gym.make("ch37/AlohaSimInsertion-v0", render_mode="rgb_array", visualization_width=1280)
