"""Lockstep attempts and batched experts give today's one-at-a-time bytes: the PushT expert, written over a
batch, decides every row as the plain one-state reading of its steps (written out below) and as that row
alone, bit for bit; datagen.tasks.fast_experts' AlohaBatch equals AlohaExpert's act along real episodes;
and datagen.lockstep.attempts_lockstep returns exactly what datagen.engine.attempt returns, for both modes on
PushT and for ALOHA's re-solve."""

import math
import time
from dataclasses import replace

import numpy as np
import pytest

import aloha_env
import gen_demos_aloha
import gen_demos_pusht
import pusht_env
from datagen import ALOHA, PUSHT, Outcome, Perturbation, engine, lockstep, rollout
from datagen.task import Task
from datagen.tasks.fast_experts import AlohaBatch
from lerobot_v3.dataset import load_arrays
from scripted_expert import (
    PT_CLEAR,
    PT_GOAL_POS,
    PT_GOAL_YAW,
    PT_MOVE_GAIN,
    PT_ORBIT_CENTER,
    PT_PUSH_GAIN,
    PT_R,
    PT_STANDOFF,
    PT_TRAVEL_COST,
    PT_V_MOVE,
    PT_V_PUSH,
    PT_YAW_LEN,
    AlohaExpert,
    PushTExpert,
)


def states_along(task, env, expert_class, seeds, noise: float) -> np.ndarray:
    """Every observation of the expert's episodes from env.reset(seed); every other one noisy, so the
    states also come from off the clean expert's path (recoveries, orbits, failed grasps)."""
    obs = []
    for i, s in enumerate(seeds):
        ep = rollout(task, env, expert_class(noise=noise if i % 2 else 0.0, seed=s), env.reset(s))
        obs.append(ep["observation.state"])
    return np.concatenate(obs)


def assert_same_decisions(expert, batch, states: np.ndarray, chunk: int) -> None:
    scalar = np.stack([expert.act(o) for o in states])
    batched = np.concatenate([batch.act_batch(states[i : i + chunk]) for i in range(0, len(states), chunk)])
    assert batched.dtype == scalar.dtype == np.float32 and batched.shape == scalar.shape
    differ = np.flatnonzero((batched.view(np.uint32) != scalar.view(np.uint32)).any(axis=1))
    assert differ.size == 0, f"{differ.size} of {len(states)} decisions differ, first at row {differ[:1]}"


def plain_pusht_action(x: PushTExpert, o: np.ndarray) -> tuple[np.ndarray, str]:
    """The PushT expert's steps 1-4 for one state as a reader writes them for one env (Python floats, one
    numpy vector at a time: the expert's own code before it was written over a batch), the oracle a batch
    must equal row by row, bit for bit. -> (the action before its clip, the step that decided it)."""
    pw, bw = o[0:2], o[2:4]
    yaw = math.atan2(o[4], o[5])
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s], [s, c]])  # block frame -> world
    e = rot.T @ (o[6:8] - bw)
    eyaw = pusht_env.wrap_angle(math.atan2(o[8], o[9]) - yaw)
    p = rot.T @ (pw - bw)
    err = math.hypot(e[0], e[1])

    def grad_at(p):
        h = 1e-5
        d = pusht_env.t_sdf(np.array([p + (h, 0.0), p - (h, 0.0), p + (0.0, h), p - (0.0, h)]))
        g = np.array([d[0] - d[1], d[2] - d[3]])
        nrm = np.linalg.norm(g)
        return g / nrm if nrm > 1e-12 else np.array([0.0, 1.0])

    if err < PT_GOAL_POS and abs(eyaw) < PT_GOAL_YAW:
        if float(pusht_env.t_sdf(p)) > PT_R + 0.03:
            return np.zeros(2), "goal still"
        return rot @ (0.1 * grad_at(p)), "goal back off"
    want = np.array([e[0], e[1], PT_YAW_LEN * eyaw])
    want /= np.linalg.norm(want)
    align = x._u @ want
    pre_w = bw + x._pre @ rot.T
    reach = np.all(np.abs(pre_w) < pusht_env.WALL_INNER - PT_R - 0.005, axis=1)
    rel = p - x._contact
    along = np.clip(np.einsum("kj,kj->k", rel, x._n), -PT_STANDOFF, 0.0)
    travel = np.linalg.norm(rel - along[:, None] * x._n, axis=1)
    k = int(np.argmax(np.where(reach, align - PT_TRAVEL_COST * travel, -np.inf)))
    n, t, c0, g = x._n[k], x._t[k], x._contact[k], x._pre[k]
    rel = p - c0
    along, lat = float(rel @ n), float(rel @ t)
    if abs(lat) < 0.006 and -(PT_STANDOFF + 0.008) < along < 0.01:
        speed = min(max(PT_PUSH_GAIN * math.hypot(err, PT_YAW_LEN * eyaw), PT_V_PUSH[0]), PT_V_PUSH[1])
        return rot @ (speed * n - 5.0 * lat * t), "push"
    dg = g - p
    dist = float(np.linalg.norm(dg))
    speed = min(max(PT_MOVE_GAIN * dist, PT_V_MOVE[0]), PT_V_MOVE[1])
    floor = min(PT_R + 0.002, float(pusht_env.t_sdf(p)) - 0.001)
    if np.all(pusht_env.t_sdf(p + x._seg[:, None] * dg) > floor):
        return rot @ (speed * dg / max(dist, 1e-9)), "straight"
    grad = grad_at(p)
    tang = np.array([-grad[1], grad[0]])
    a_p = math.atan2(*(p - PT_ORBIT_CENTER)[::-1])
    a_g = math.atan2(*(g - PT_ORBIT_CENTER)[::-1])
    clockwise = pusht_env.wrap_angle(a_g - a_p) < 0.0
    if clockwise:
        tang = -tang
    radial = min(max(20.0 * (PT_CLEAR - (float(pusht_env.t_sdf(p)) - PT_R)), -1.0), 1.0)
    v = tang + radial * grad
    return rot @ (PT_V_MOVE[1] * v / max(np.linalg.norm(v), 1e-9)), "orbit " + ("cw" if clockwise else "ccw")


class OnePushT:
    """act(obs): plain_pusht_action, clipped and cast as the expert's act."""

    def __init__(self):
        self.x = PushTExpert()

    def act(self, obs):
        v, _ = plain_pusht_action(self.x, np.asarray(obs, dtype=np.float64))
        return np.clip(v, -1.0, 1.0).astype(np.float32)


@pytest.fixture(scope="module")
def pusht_states():
    states = states_along(PUSHT, pusht_env.PushTEnv(), PushTExpert, range(240), noise=0.3)
    assert len(states) > 3000
    return states


def test_pusht_expert_over_a_batch_is_the_plain_reading_of_every_row_bit_for_bit(pusht_states):
    # every row, however the rows are grouped (37: batches mix every kind; 1: act is a batch of one)
    assert_same_decisions(OnePushT(), PushTExpert(), pusht_states, chunk=37)
    assert_same_decisions(OnePushT(), PushTExpert(), pusht_states[:400], chunk=1)
    assert_same_decisions(PushTExpert(), PushTExpert(), pusht_states, chunk=len(pusht_states))
    # and every kind of decision is in there: pushes, straight moves, orbits both ways, the goal's two
    x = PushTExpert()
    kinds = [plain_pusht_action(x, o.astype(np.float64))[1] for o in pusht_states]
    assert set(kinds) == {"push", "straight", "orbit ccw", "orbit cw", "goal back off", "goal still"}, set(
        kinds
    )


def test_the_pusht_experts_noise_over_a_batch_is_its_rows_in_order_and_aloha_batch_refuses_noise(
    pusht_states,
):
    # a noisy PushT expert draws a batch's rows in order from its one generator: act's actions, row by row
    states = pusht_states[:300]
    x = PushTExpert(noise=0.2, seed=7)
    rows = np.stack([x.act(o) for o in states])
    batched = PushTExpert(noise=0.2, seed=7)
    together = np.concatenate([batched.act_batch(states[i : i + 50]) for i in range(0, len(states), 50)])
    assert together.tobytes() == rows.tobytes()
    assert not np.array_equal(rows, PushTExpert().act_batch(states))  # the noise is there
    with pytest.raises(ValueError):
        AlohaBatch(AlohaExpert(noise=0.1))


def test_aloha_batched_expert_is_bit_identical():
    states = states_along(ALOHA, aloha_env.AlohaCubeEnv(), AlohaExpert, range(16), noise=0.3)
    assert len(states) > 2000
    assert_same_decisions(AlohaExpert(), AlohaBatch(), states, chunk=29)


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    out = tmp_path_factory.mktemp("src") / "pusht4"
    assert gen_demos_pusht.main(["--episodes", "4", "--seed", "0", "--out", str(out), "--quiet"]) == 0
    return engine.sources(load_arrays(out))


def assert_same_results(one_at_a_time: list, together: list) -> None:
    """Outcomes (or episodes) equal field for field, every array byte for byte."""
    assert len(one_at_a_time) == len(together)
    for i, (a, b) in enumerate(zip(one_at_a_time, together)):
        if isinstance(a, Outcome) or isinstance(b, Outcome):
            fields = ("reason", "start", "source_episode", "steps")
            same = [getattr(a, f) for f in fields] == [getattr(b, f) for f in fields]
            assert same, f"attempt {i}: {a} / {b}"
            assert (a.episode is None) == (b.episode is None), f"attempt {i}"
            if a.episode is not None:
                assert_same_results([a.episode], [b.episode])
            continue
        assert list(a) == list(b), f"attempt {i}: keys differ"
        for key in a:
            if key in ("success", "unstable"):  # the episode's flags
                assert a[key] is b[key], f"attempt {i}: {key}"
            else:
                x, y = a[key], b[key]
                assert (x.dtype, x.shape) == (y.dtype, y.shape), f"attempt {i}: {key}"
                assert x.tobytes() == y.tobytes(), f"attempt {i}: {key} differs"


@pytest.mark.parametrize(
    "mode, sigmas, lanes",
    [("resolve", (0.08, 0.5), 37), ("replay", (0.02, 0.2), 7)],  # lanes refilled; replay: some keep
)
def test_lockstep_attempts_equal_one_at_a_time(sources, mode, sigmas, lanes):
    how = Perturbation(1, *sigmas)
    jobs = [(e, k) for e in sorted(sources) for k in range(50)]  # 200 attempts
    one = [engine.attempt(PUSHT, sources[e], k, how, mode=mode) for e, k in jobs]
    together = lockstep.attempts_lockstep(PUSHT, sources, jobs, how, mode=mode, lanes=lanes)
    kept = sum(r.kept for r in one)
    assert kept >= 10 and (mode == "resolve" or kept < len(jobs))  # both outcomes are compared
    assert_same_results(one, together)


def test_lockstep_reasons_without_a_start(sources):
    jobs = [(0, 0), (1, 3)]
    how = Perturbation(0, 10.0, 0.1)  # no draw lands on the band
    got = lockstep.attempts_lockstep(PUSHT, sources, jobs, how)
    want = [("no_valid_start", 0, 0), ("no_valid_start", 1, 0)]
    assert [(r.reason, r.source_episode, r.steps) for r in got] == want


def test_the_runner_is_task_agnostic_aloha_episodes_equal_rollout():
    """run_lanes with ALOHA's env and AlohaBatch.act_batch (the shape an ALOHA engine task plugs in):
    each episode from env.reset(seed) equals datagen.demos.rollout's, frame for frame and bit for bit."""
    expert = AlohaBatch()
    seeds = list(range(12))

    class FromReset(lockstep.Mode):  # episodes from env.reset(seed), the batch expert deciding
        def begin(self, seed, env):
            return lockstep.Lane(seed, env.reset(seed))

        def decide(self, lanes, envs, obs):
            return expert.act_batch(obs), None

        def finish(self, lane, env, episode, last):
            return episode | {"success": bool(episode["next.success"][-1, 0])}

    got = lockstep.run_lanes(
        seeds,
        FromReset(),
        envs=engine.Simulators().lanes(ALOHA, 5),
        max_frames=aloha_env.MAX_STEPS,
        obs_dim=aloha_env.OBS_DIM,
        act_dim=aloha_env.ACT_DIM,
        lanes=5,
    )
    env = aloha_env.AlohaCubeEnv()
    want = [rollout(ALOHA, env, AlohaExpert(), env.reset(s)) for s in seeds]
    assert sum(ep["success"] for ep in want) >= 6 and len({len(ep["action"]) for ep in want}) > 1
    assert_same_results(want, got)


def plain_rollout(env, policy, obs, *, rewards: bool) -> dict:
    """A plain Gym loop, as the demo generators ran their episodes before those went through the engine's
    runner (datagen.lockstep, mode Rollout): the reference datagen.demos.rollout keeps, bit for bit."""
    policy.reset()
    states, actions, succ, rews, dones, unstable = [], [], [], [], [], None
    done = False
    while not done:
        act = policy.act(obs)
        states.append(obs)
        actions.append(act)
        obs, reward, done, info = env.step(act)
        succ.append(bool(info["success"]))
        rews.append(reward)
        dones.append(bool(done))
        if "unstable" in info:
            unstable = unstable or bool(info["unstable"])
    ep = {
        "observation.state": np.asarray(states, np.float32),
        "action": np.asarray(actions, np.float32),
        "next.success": np.asarray(succ, bool)[:, None],
        "success": bool(succ[-1]),
    }
    if rewards:
        ep["next.reward"] = np.asarray(rews, np.float32)[:, None]
        ep["next.done"] = np.asarray(dones, bool)[:, None]
    if unstable is not None:
        ep["unstable"] = unstable
    return ep


@pytest.mark.parametrize(
    "name, noise",
    [
        ("pusht", 0.3),
        ("aloha", 0.3),
        ("gym_pusht", 5),  # px
        ("aloha_transfer_cube", 0),
        ("aloha_transfer_cube", 1e9),  # blows the simulation up
    ],
)
def test_the_demo_generators_rollout_is_a_plain_gym_loop(name, noise):
    """Issue 58 #2: gen_demos.py's episodes go through the engine's one runner (mode Rollout, one lane)
    and are what a plain Gym loop records, frame for frame and bit for bit: noisy experts (every other
    episode), gym-pusht's reward and termination, and a transfer-cube episode whose simulation blows up
    (noise 1e9: "unstable", the episode ends there) beside a solved one."""
    from ch37.seeds import env_seed
    from datagen.task import known_tasks

    task = known_tasks()[name]
    env = task.make_env()
    got, want = [], []
    for i in range(3 if name != "aloha_transfer_cube" else 1):
        s = env_seed(4, "demo", i)
        policy = lambda: task.expert.cls(noise=noise if i % 2 or noise > 1e6 else 0.0, seed=s)  # noqa: E731
        got.append(rollout(task, env, policy(), env.reset(s)))
        want.append(plain_rollout(env, policy(), env.reset(s), rewards=task.spec.records_reward))
    assert_same_results(want, got)
    blown = got[0].get("unstable", False)
    assert ("unstable" in got[0]) is name.startswith("aloha_") and blown is (noise > 1e6)


@pytest.mark.parametrize("mode, select", [("resolve", "own"), ("replay", "own"), ("replay", "nearest")])
def test_aloha_in_lockstep_equals_one_at_a_time(tmp_path, mode, select):
    """ALOHA's re-solve (the generic resolve lanes, AlohaBatch.act_batch deciding) and the engine's one
    replay (datagen.lockstep.Replaying, subtask by subtask, from the attempt's own or the nearest source)
    through lockstep return exactly datagen.engine.attempt's results."""
    out = tmp_path / "aloha3"
    assert gen_demos_aloha.main(["--episodes", "3", "--seed", "0", "--out", str(out), "--quiet"]) == 0
    srcs = engine.sources(load_arrays(out))
    how = Perturbation(0, 0.08, 0.5)
    jobs = [(e, k) for e in sorted(srcs) for k in range(10)]  # 30 attempts
    pool = srcs if select == "nearest" else None
    one = [engine.attempt(ALOHA, srcs[e], k, how, mode=mode, pool=pool) for e, k in jobs]
    if mode == "resolve":
        together = lockstep.attempts_lockstep(ALOHA, srcs, jobs, how, lanes=8)
    else:  # attempts_lockstep replays ALOHA one at a time (no batch step): its lanes, run directly
        sims, m = engine.Simulators(), aloha_env
        together = lockstep.run_lanes(
            jobs,
            lockstep.Replaying(ALOHA, srcs, how, pool, sims.plans),
            envs=sims.lanes(ALOHA, 8),
            max_frames=m.MAX_STEPS,
            obs_dim=m.OBS_DIM,
            act_dim=m.ACT_DIM,
            lanes=8,
            step=ALOHA.step_batch,
        )
    assert sum(r.kept for r in one) >= 10
    assert_same_results(one, together)


def test_pusht_replay_from_the_nearest_source_in_lockstep_equals_one_at_a_time(sources):
    how = Perturbation(2, 0.02, 0.2)
    jobs = [(e, k) for e in sorted(sources) for k in range(25)]  # 100 attempts
    one = [engine.attempt(PUSHT, sources[e], k, how, mode="replay", pool=sources) for e, k in jobs]
    together = lockstep.attempts_lockstep(PUSHT, sources, jobs, how, mode="replay", select="nearest", lanes=6)
    assert 0 < sum(r.kept for r in one) < len(jobs)
    assert_same_results(one, together)


class PlainPushT(type(PUSHT)):
    """PushT with lockstep's hooks removed: the Task contract's defaults (no batch expert, no replay
    each env stepped by its own step)."""

    expert = replace(type(PUSHT).expert, batch=None)
    step_batch = Task.step_batch


class PerEnvPushT(type(PUSHT)):
    """PushT's batch expert, its envs stepped one by one (the default step_batch)."""

    step_batch = Task.step_batch


@pytest.mark.parametrize("mode, sigmas", [("resolve", (0.08, 0.5)), ("replay", (0.02, 0.2))])
def test_a_task_without_the_batch_hooks_gives_the_same_results(sources, mode, sigmas):
    """What lockstep needs is part of the Task contract with a default: a task that offers none runs one
    attempt at a time, and one that steps its envs one by one steps the same bits."""
    how = Perturbation(1, *sigmas)
    jobs = [(e, k) for e in sorted(sources) for k in range(12)]  # 48 attempts
    want = lockstep.attempts_lockstep(PUSHT, sources, jobs, how, mode=mode, lanes=9)
    assert sum(r.kept for r in want) >= 3
    for task in (PlainPushT(), PerEnvPushT()):
        assert_same_results(want, lockstep.attempts_lockstep(task, sources, jobs, how, mode=mode, lanes=9))
    assert PlainPushT().expert.batch is None


def test_the_simulators_a_worker_keeps_are_passed_not_hidden():
    """No module keeps simulators: a Simulators owns them, reuses its lanes between calls, and a copy
    sent to another process (pickled, as Ray sends a shard's arguments) arrives empty."""
    import pickle

    from datagen import lockstep as ls

    assert not hasattr(engine, "_ENVS") and not hasattr(ls, "_POOL")
    sims = engine.Simulators()
    lanes = sims.lanes(PUSHT, 3)
    assert sims.lanes(PUSHT, 2) == lanes[:2] and sims.env(PUSHT) is sims.env(PUSHT)
    copy = pickle.loads(pickle.dumps(sims))
    assert copy.lanes(PUSHT, 1)[0] is not lanes[0] and copy.plans == {}


def test_experts_without_a_batch_run_one_per_lane_and_equal_one_at_a_time(sources):
    """The one runner's resolve for a task without a batch expert: each lane runs its own expert
    (expert.cls(noise=0.0)), reset at its start. Several lanes at once (refilled) give exactly the
    one-lane results, and one lane gives exactly the demo generators' rollout of the expert from the same
    start."""
    task, how = PlainPushT(), Perturbation(1, 0.08, 0.5)
    jobs = [(e, k) for e in sorted(sources) for k in range(6)]  # 24 attempts
    one = [engine.attempt(task, sources[e], k, how) for e, k in jobs]
    assert sum(r.kept for r in one) >= 12
    kind, together = lockstep.mode_parts(task, sources, how, "resolve")
    assert not together  # attempts_lockstep runs such a task in one lane; the lanes still agree
    sims = engine.Simulators()
    lanes = lockstep.run_lanes(
        jobs, kind, envs=sims.lanes(task, 5), max_frames=task.spec.max_steps, obs_dim=10, act_dim=2, lanes=5
    )
    assert_same_results(one, lanes)
    env = task.make_env()
    for (e, k), got in zip(jobs[:4], one):
        start = lockstep.start_of_job(task, sources, (e, k), how)
        ep = rollout(task, env, task.expert.cls(noise=0.0), task.place(env, start))
        assert ep["success"] is got.kept and len(ep["action"]) == got.steps
        if got.kept:
            for key in ("observation.state", "action", "next.success"):
                assert ep[key].tobytes() == got.episode[key].tobytes(), key


def test_a_task_whose_max_steps_is_shorter_than_its_env_is_one_line(sources):
    """An env that runs on past the task's max_steps would overrun the runner's frames: one line, not an
    index error deep in the arrays."""

    class ShortPushT(type(PUSHT)):
        spec = replace(PUSHT.spec, max_steps=5)

    from ch37.errors import DataError

    with pytest.raises(DataError, match="ran past 5 steps without ending: the task's max_steps"):
        engine.attempt(ShortPushT(), sources[0], 0, Perturbation(1, 0.08, 0.5))


def test_live_replay_in_lockstep_equals_one_at_a_time(sources):
    """Issue 49 #4: replay_live decides inside each lane (its re-anchoring reads only that lane's
    observations), so PushT's lanes stepped together give engine.attempt's bytes, kept and lost alike,
    from the attempts' own sources and from the nearest."""
    how = Perturbation(1, 0.02, 0.2)
    jobs = [(e, k) for e in sorted(sources) for k in range(25)]  # 100 attempts
    for select, pool in (("own", None), ("nearest", sources)):
        one = [engine.attempt(PUSHT, sources[e], k, how, mode="replay_live", pool=pool) for e, k in jobs]
        together = lockstep.attempts_lockstep(
            PUSHT, sources, jobs, how, mode="replay_live", select=select, lanes=7
        )
        assert 5 <= sum(r.kept for r in one) < len(jobs)  # both outcomes are compared
        assert_same_results(one, together)


def test_the_bench_notes_every_simulated_frame_kept_or_not(sources):
    """Issue 58 #6: tools.bench engine's floor of every simulated frame steps the env through the frames
    of the failed attempts too. Its notes are lockstep's own attempts: one per attempt that simulated,
    as many frames as each Outcome's steps, and a kept one's actions byte for byte its episode's."""
    from tools.bench import every_attempt

    how = Perturbation(1, 0.02, 0.2)
    jobs = [(e, k) for e in sorted(sources) for k in range(10)]
    together = lockstep.attempts_lockstep(PUSHT, sources, jobs, how, mode="replay")
    noted = every_attempt(PUSHT, sources, jobs, how, "replay", engine.Simulators())
    ran = [r for r in together if r.steps]
    assert 0 < sum(r.kept for r in ran) < len(ran)  # failed attempts are among them
    assert len(noted) == len(ran)
    for r, (start, actions) in zip(ran, noted):
        assert start == r.start and len(actions) == r.steps
        if r.kept:
            assert actions.tobytes() == r.episode["action"].tobytes()


def test_the_bench_clocks_the_tasks_code_and_the_physics_once_and_changes_nothing(sources):
    """Issue 58 #6: tools.bench engine splits lockstep's time into the task's own code (its expert, its
    replay's conversions, its poses), the physics (its envs' place and steps) and the engine's own, on the
    clocks of a copy of the task (TaskClock). The copy gives the same attempts bit for bit; its expert's
    every act is on the task's clock (one call per simulated frame, besides a perturb per attempt); a
    call inside a clocked call counts once."""
    from tools.bench import TaskClock

    how = Perturbation(1, 0.02, 0.2)
    jobs = [(e, k) for e in sorted(sources) for k in range(3)]
    for mode in ("resolve", "replay"):
        plain, _ = lockstep.mode_parts(PUSHT, sources, how, mode, lanes=False)
        want = lockstep.one_lane(PUSHT, PUSHT.make_env(), jobs, plain)
        clock = TaskClock(PUSHT)
        timed, _ = lockstep.mode_parts(clock.clocked, sources, how, mode, lanes=False)
        t0 = time.perf_counter()
        got = lockstep.one_lane(clock.clocked, clock.clocked.make_env(), jobs, timed)
        wall = time.perf_counter() - t0
        assert [r.steps for r in got] == [r.steps for r in want] and sum(r.kept for r in want)
        for a, b in zip(got, want):
            assert (a.episode is None) == (b.episode is None)
            if a.episode is not None:
                assert a.episode.keys() == b.episode.keys()
                assert all(
                    np.asarray(a.episode[k]).tobytes() == np.asarray(b.episode[k]).tobytes()
                    for k in b.episode
                )
        # a frame's act (resolve) or to_action (replay), and each attempt's perturb; a frame's step and
        # each attempt's place
        frames = sum(r.steps for r in want)
        assert clock.calls["task"] >= frames + len(jobs) and clock.calls["physics"] == frames + len(jobs)
        assert 0.0 < clock.seconds["task"] and 0.0 < clock.seconds["physics"]
        assert clock.seconds["task"] + clock.seconds["physics"] < wall

    clock = TaskClock(PUSHT)
    inner = clock._timed(lambda: None)
    outer = clock._timed(lambda: [inner() for _ in range(5)])
    outer()
    assert clock.calls == {"task": 1, "physics": 0}
    clock.start()
    clock._timed(lambda: inner(), "physics")()  # the task's code inside the physics: the physics' call
    assert (
        clock.calls == {"task": 0, "physics": 1} and clock.seconds["task"] == 0.0 < clock.seconds["physics"]
    )
