"""Expert success counts: a fast subset by default, the full 50-start counts with -m slow."""

import numpy as np
import pytest

import aloha_env
import pusht_env
from scripted_expert import AlohaExpert, PushTExpert


def solved(Env, Expert, seeds, noise):
    env, wins = Env(), 0
    for s in seeds:
        obs, done, ex = env.reset(s), False, Expert(noise=noise, seed=s)
        while not done:
            obs, _, done, info = env.step(ex.act(obs))
        wins += bool(info["success"])
    return wins


CASES = [
    pytest.param(pusht_env.PushTEnv, PushTExpert, 0.08, id="pusht"),
    pytest.param(aloha_env.AlohaCubeEnv, AlohaExpert, 0.05, id="aloha"),
]


@pytest.mark.parametrize("Env,Expert,noise", CASES)
def test_expert_fast_subset(Env, Expert, noise):
    assert solved(Env, Expert, range(10), 0.0) >= 9
    assert solved(Env, Expert, range(10), noise) >= 8


@pytest.mark.slow
@pytest.mark.parametrize("Env,Expert,noise", CASES)
def test_expert_50_starts(Env, Expert, noise):
    assert solved(Env, Expert, range(50), 0.0) >= 49
    assert solved(Env, Expert, range(50), noise) >= 45


@pytest.mark.parametrize(
    "Env,Expert,act_dim", [(pusht_env.PushTEnv, PushTExpert, 2), (aloha_env.AlohaCubeEnv, AlohaExpert, 6)]
)
def test_noisy_expert_is_reproducible_per_seed(Env, Expert, act_dim):
    def actions(seed):
        env, ex = Env(), Expert(noise=0.1, seed=seed)
        obs, out = env.reset(0), []
        for _ in range(20):
            a = ex.act(obs)
            assert a.dtype == np.float32 and a.shape == (act_dim,) and np.all(np.abs(a) <= 1)
            out.append(a)
            obs, _, done, _ = env.step(a)
            if done:
                break
        return np.stack(out).tobytes()

    assert actions(3) == actions(3)
    assert actions(3) != actions(4)


def test_pusht_expert_solves_set_start_starts():
    # the augmentation's starts: block 0.08..0.26 m from the target, any yaw, pusher clear
    rng, env, wins, n = np.random.default_rng(123), pusht_env.PushTEnv(), 0, 0
    while n < 10:
        r, th, yaw = rng.uniform(0.08, 0.26), rng.uniform(-np.pi, np.pi), rng.uniform(-np.pi, np.pi)
        px, py = rng.uniform(-0.3, 0.3, 2)
        bx, by = r * np.cos(th), r * np.sin(th)
        if not pusht_env.pusher_clear(bx, by, yaw, px, py):
            continue
        n += 1
        obs, done, ex = env.set_start(bx, by, yaw, px, py), False, PushTExpert()
        while not done:
            obs, _, done, info = env.step(ex.act(obs))
        wins += bool(info["success"])
    assert wins >= 9
