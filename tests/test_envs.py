"""One contract for both embodiments: determinism, shapes, dtypes, clipping, success and episode end."""

import numpy as np
import pytest

import aloha_env
import pusht_env
from datagen.tasks.fast_pusht import SharedPushTEnv, step_many
from scripted_expert import AlohaExpert, PushTExpert

SPECS = [
    pytest.param(pusht_env, pusht_env.PushTEnv, PushTExpert, 2, id="pusht"),
    pytest.param(aloha_env, aloha_env.AlohaCubeEnv, AlohaExpert, 6, id="aloha"),
]


@pytest.mark.parametrize("mod,Env,Expert,act_dim", SPECS)
def test_contract(mod, Env, Expert, act_dim):
    # same seed -> byte-identical obs from two fresh envs; different seeds -> different obs
    a, b = Env().reset(3), Env().reset(3)
    assert a.dtype == np.float32 and a.shape == (10,)
    assert a.tobytes() == b.tobytes()
    assert Env().reset(4).tobytes() != a.tobytes()
    assert len(mod.STATE_NAMES) == 10 and len(mod.ACTION_NAMES) == act_dim == mod.ACT_DIM
    assert mod.FPS == 10

    # a rollout is a pure function of the seed, and actions outside [-1, 1] are clipped
    def run(scale):
        env, traj = Env(), []
        obs = env.reset(7)
        for t in range(15):
            act = np.full(act_dim, scale * (1 if t % 2 else -1), np.float32)
            obs, r, done, info = env.step(act)
            assert (
                obs.dtype == np.float32
                and obs.shape == (10,)
                and isinstance(info["success"], (bool, np.bool_))
            )
            traj.append(obs.copy())
        return np.stack(traj)

    assert run(1.0).tobytes() == run(1.0).tobytes()
    assert run(5.0).tobytes() == run(1.0).tobytes()  # clipped to 1
    assert run(0.5).tobytes() != run(1.0).tobytes()


@pytest.mark.parametrize("mod,Env,Expert,act_dim", SPECS)
def test_expert_episode_ends_on_latched_success(mod, Env, Expert, act_dim):
    env, expert = Env(), Expert()
    obs, done, t = env.reset(0), False, 0
    while not done:
        obs, r, done, info = env.step(expert.act(obs))
        t += 1
    assert info["success"] and env.success and t < mod.MAX_STEPS
    assert info["steps"] == t == env.steps


@pytest.mark.parametrize("mod,Env,Expert,act_dim", SPECS)
def test_episode_ends_at_max_steps_without_success(mod, Env, Expert, act_dim):
    env = Env()
    env.reset(1)
    done, t = False, 0
    while not done:  # standing still never succeeds
        _, _, done, info = env.step(np.zeros(act_dim, np.float32))
        t += 1
    assert t == mod.MAX_STEPS and not info["success"]


def test_pusht_set_start_places_state_with_fresh_counters():
    env = pusht_env.PushTEnv()
    env.reset(0)
    for _ in range(5):
        env.step(np.array([0.3, 0.0], np.float32))
    obs = env.set_start(0.15, -0.05, 0.7, -0.25, 0.2)
    assert env.steps == 0 and not env.success
    np.testing.assert_allclose(obs[:4], [-0.25, 0.2, 0.15, -0.05], atol=1e-6)
    np.testing.assert_allclose(obs[4:6], [np.sin(0.7), np.cos(0.7)], atol=1e-6)
    np.testing.assert_allclose(env.block_pose, [0.15, -0.05, 0.7], atol=1e-6)
    # a start placed this way is deterministic and independent of what ran before
    other = pusht_env.PushTEnv()
    assert other.set_start(0.15, -0.05, 0.7, -0.25, 0.2).tobytes() == obs.tobytes()
    assert (
        other.step(np.array([0.2, 0.1], np.float32))[0].tobytes()
        == env.step(np.array([0.2, 0.1], np.float32))[0].tobytes()
    )


def test_pusht_step_many_on_a_shared_mjdata_is_step_bit_for_bit():
    """datagen.tasks.fast_pusht's step_many (lockstep's batched step) over SharedPushTEnvs sharing one
    MjData =
    PushTEnv.step per env, each in
    its own: the same obs, success and done bits, clipped actions and the success latch included, and
    the same poses read between steps; a non-finite action is refused as step refuses it."""
    expert, rng = PushTExpert(), np.random.default_rng(0)
    one = [pusht_env.PushTEnv() for _ in range(6)]
    many = [SharedPushTEnv()]
    many += [SharedPushTEnv(share=many[0]) for _ in range(5)]
    assert all(e.data is many[0].data for e in many) and one[0].data is not one[1].data
    obs = np.stack([e.reset(s) for e, s in zip(one, range(6))])
    assert np.array_equal(obs, np.stack([e.reset(s) for e, s in zip(many, range(6))]))
    latched = set()
    for t in range(pusht_env.MAX_STEPS):
        act = expert.act_batch(obs)
        act[:2] = rng.uniform(-3, 3, (2, 2))  # two envs on random actions, beyond the clip
        got = step_many(many, act)
        want = [e.step(a) for e, a in zip(one, act)]
        assert got[0].tobytes() == np.stack([w[0] for w in want]).tobytes()
        assert got[1].tolist() == [w[3]["success"] for w in want]
        assert got[2].tolist() == [w[2] for w in want]
        latched |= {i for i, s in enumerate(got[1]) if s}
        obs = got[0]
        if t % 7 == 0:  # an env's state read while another's was loaded last
            assert [e.block_pose.tobytes() for e in many] == [e.block_pose.tobytes() for e in one]
    assert latched >= {2, 3, 4, 5}  # the expert's envs succeeded on the way (and kept stepping)
    with pytest.raises(ValueError, match="non-finite"):
        step_many(many[:1], np.array([[np.nan, 0.0]], np.float32))


def test_pusht_accessors_match_obs():
    env = pusht_env.PushTEnv()
    obs = env.reset(5)
    np.testing.assert_allclose(env.pusher_pos, obs[:2], atol=1e-6)
    x, y, yaw = env.block_pose
    np.testing.assert_allclose([x, y, np.sin(yaw), np.cos(yaw)], obs[2:6], atol=1e-6)
    np.testing.assert_allclose(env.target_pose, [0, 0, 0])
    r = np.hypot(x, y)
    assert pusht_env.SPAWN_R_MIN - 1e-6 <= r <= pusht_env.SPAWN_R_MAX + 1e-6


def test_aloha_accessors_match_obs():
    env = aloha_env.AlohaCubeEnv()
    obs = env.reset(5)
    np.testing.assert_allclose(env.right_ee, obs[0:2], atol=1e-6)
    np.testing.assert_allclose(env.left_ee, obs[3:5], atol=1e-6)
    np.testing.assert_allclose(env.grip, obs[[2, 5]], atol=1e-6)
    np.testing.assert_allclose(env.cube_pos, obs[6:8], atol=1e-6)
    np.testing.assert_allclose(env.target_pos, obs[8:10], atol=1e-6)
    assert tuple(env.holding) == (False, False)
