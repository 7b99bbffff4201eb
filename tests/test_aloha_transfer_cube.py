"""LeRobot's ALOHA transfer-cube (gym-aloha's ViperX sim, issue 50) through the engine: gym-aloha's model
files on our mujoco, its success rule, ACT's scripted expert, gen_demos.py's sets and their re-validation in
the joint-controlled model. Real MuJoCo, a few episodes each (the 100-start count is in docs/engine.md)."""

import importlib.util

import mujoco
import numpy as np
import pytest
from conftest import ROOT, run_script

from ch37.seeds import env_seed
from datagen import Perturbation, engine, known_tasks
from datagen.demos import expert_episodes
from datagen.source_check import read_source
from datagen.task import Source, failures_of
from datagen.tasks import aloha_sim as sim
from datagen.tasks.aloha_sim import CUBE_RANGE, box_pose
from datagen.tasks.aloha_sim_expert import TransferCubeExpert
from lerobot_v3 import load_arrays

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("gym_aloha") is None,
    reason="gym-aloha is not installed (its model files: requirements.lock pins gym-aloha==0.1.5; "
    "re-install .venv from the lock)",
)
TASK = known_tasks()["aloha_transfer_cube"]


@pytest.fixture(scope="module")
def demo_set(tmp_path_factory):
    """Two expert demos, made by the command a user runs."""
    out = tmp_path_factory.mktemp("aloha_transfer_cube") / "set"
    r = run_script(ROOT / "gen_demos.py", "--task", "aloha_transfer_cube", "--episodes", "2", "--out", out)
    assert "expert successes 2/2" in r.stdout, r.stdout + r.stderr
    return out


def contact_pairs(m: mujoco.MjModel, d: mujoco.MjData) -> list[tuple[str, str]]:
    """Every contact's (geom 1, geom 2) by name, in contact order, as gym_aloha/tasks/sim.py lists them."""
    name = lambda g: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g)  # noqa: E731
    return [(name(d.contact[i].geom1), name(d.contact[i].geom2)) for i in range(d.ncon)]


def gym_aloha_reward(m: mujoco.MjModel, d: mujoco.MjData) -> int:
    """gym_aloha/tasks/sim.py's TransferCubeTask.get_reward, line for line: contact pairs by geom name."""
    all_contact_pairs = contact_pairs(m, d)
    touch_left_gripper = ("red_box", "vx300s_left/10_left_gripper_finger") in all_contact_pairs
    touch_right_gripper = ("red_box", "vx300s_right/10_right_gripper_finger") in all_contact_pairs
    touch_table = ("red_box", "table") in all_contact_pairs
    reward = 0
    if touch_right_gripper:
        reward = 1
    if touch_right_gripper and not touch_table:
        reward = 2
    if touch_left_gripper:
        reward = 3
    if touch_left_gripper and not touch_table:
        reward = 4
    return reward


def run_expert(seed: int):
    """One expert episode from the start gym-aloha's reset(seed=seed) draws: (env, rewards, success)."""
    env = TASK.make_env()
    obs = env.reset(seed)
    expert = TransferCubeExpert(seed=seed)
    rewards, ours, done = [], [], False
    while not done:
        obs, reward, done, info = env.step(expert.act(obs))
        rewards.append(reward)
        ours.append(gym_aloha_reward(env.env.model, env.env.data))
    return rewards, ours, info["success"]


def test_success_is_gym_alohas_rule_on_the_contacts():
    """At every step of an expert episode the env's reward is the one gym-aloha's get_reward computes
    from the same contacts; the episode climbs through the stages and ends at the top one (success)."""
    rewards, theirs, success = run_expert(7)
    assert rewards == theirs
    assert success and rewards[-1] == 4 and {1, 2} <= set(rewards)
    assert 4 not in rewards[:-1]  # success ends the episode, as gym-aloha's env terminates there


def test_a_start_is_the_cube_gym_aloha_draws():
    """reset(seed) puts the cube where gym-aloha's sample_box_pose(seed) does (RandomState(seed), uniform
    on its ranges, upright); a seed past 32 bits (our env seeds reach 2**63) draws in the same ranges."""
    ranges = np.array(CUBE_RANGE)
    for seed in (0, 1, 2**32 - 1):
        want = np.random.RandomState(seed).uniform(ranges[:, 0], ranges[:, 1])
        np.testing.assert_array_equal(box_pose(seed), np.r_[want, 1, 0, 0, 0])
        obs = TASK.make_env().reset(seed)
        np.testing.assert_array_equal(obs[14:21], np.r_[want, 1, 0, 0, 0].astype(np.float32))
    big = box_pose(env_seed(10**9, "eval", 3))
    assert all(lo <= v <= hi for v, (lo, hi) in zip(big[:3], CUBE_RANGE))


def plain_ik(m, d, arm, q, position, rotation, iters):
    """aloha_sim.ik as the textbook writes it: each iteration's grasp point and orientation error, the
    Jacobian, q += J^T (J J^T + lambda^2 I)^-1 e, clipped to the joints' ranges."""
    q = np.array(q, np.float64)
    b = m.body(sim.GRIPPERS[arm]).id
    for _ in range(iters):
        d.qpos[sim.QPOS[arm]] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        p, rot = sim.gripper_pose(m, d, arm)
        quat, vel = np.zeros(4), np.zeros(3)
        mujoco.mju_mat2Quat(quat, (np.asarray(rotation) @ rot.T).ravel())
        mujoco.mju_quat2Vel(vel, quat, 1.0)
        err = np.concatenate([np.asarray(position, np.float64) - p, sim.ROT_WEIGHT * vel])
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jac(m, d, jacp, jacr, p, b)
        jac = np.vstack([jacp[:, sim.DOFS[arm]], sim.ROT_WEIGHT * jacr[:, sim.DOFS[arm]]])
        step = jac.T @ np.linalg.solve(jac @ jac.T + sim.IK_DAMPING**2 * np.eye(6), err)
        q = np.clip(q + step, *m.jnt_range[sim.JOINT_IDS[arm]].T)
    return q


def test_the_inverse_kinematics_is_the_plain_damped_least_squares_bit_for_bit():
    """aloha_sim.ik writes the arithmetic out on buffers it makes once, with np.linalg.solve's own LAPACK
    gufunc, for speed (issue 58 #6): the joints it returns, and the scratch MjData it leaves, are the
    plain reading's bit for bit, from starts near and far, both arms, 1 to 24 iterations."""
    m, d = sim.model("transfer_cube"), sim.scratch("transfer_cube")
    rng = np.random.default_rng(0)
    for i in range(200):
        arm, iters = i % 2, int(rng.integers(1, 25))
        d.qpos[:] = 0
        d.qpos[0:6] = d.qpos[8:14] = sim.START_ARM_POSE[:6]
        mujoco.mj_kinematics(m, d)
        position, rotation = sim.gripper_pose(m, d, arm)
        position = position + rng.normal(0, 0.05, 3)
        q0 = sim.START_ARM_POSE[:6] + rng.normal(0, 0.3, 6)
        before = d.qpos.copy()
        want = plain_ik(m, d, arm, q0, position, rotation, iters)
        left, d.qpos[:] = d.qpos.copy(), before
        got = sim.ik(m, d, arm, q0, position, rotation, iters)
        assert got.tobytes() == want.tobytes() and d.qpos.tobytes() == left.tobytes(), (i, got - want)


def test_the_expert_solves_held_out_starts():
    """ACT's waypoints through IK solve starts they were not tuned on (100 of 100 on seeds 1000-1099)."""
    for seed in (5000, 5001, 5002):
        rewards, _, success = run_expert(seed)
        assert success, (seed, max(rewards))


def test_gen_demos_writes_a_set_whose_episodes_revalidate_in_the_joint_model(demo_set):
    """gen_demos.py --task aloha_transfer_cube writes a LeRobot v3 set as lerobot/aloha_sim_* record it
    (14 joint numbers in state and action, 50 fps) with the cube's pose as environment state and the
    end-effector targets as action.end_effector; every
    episode's recorded joint actions, replayed from its recorded start in a fresh joint-controlled env,
    reach gym-aloha's success again."""
    out = demo_set
    keys = ("observation.state", "observation.environment_state", "action", "episode_index", "next.reward")
    frames = load_arrays(out, keys=keys + ("action.end_effector",))
    assert frames["observation.state"].shape[1] == 14 and frames["action"].shape[1] == 14
    assert frames["observation.environment_state"].shape[1] == 7
    # the end-effector targets beside the joint actions: the grasp points the actions put the grippers at
    ee = TASK.frame_columns(None, frames["action"])["action.end_effector"]
    np.testing.assert_allclose(frames["action.end_effector"], ee, atol=1e-6)
    right = frames["action.end_effector"][:, 7:10]  # the right grasp point: down to the cube and up
    assert np.ptp(right[:, 2]) > 0.1 and right[:, 2].min() < 0.06
    for ep in (0, 1):
        rows = frames["episode_index"] == ep
        env = TASK.make_env()
        first = np.r_[frames["observation.state"][rows][0], frames["observation.environment_state"][rows][0]]
        TASK.place(env, TASK.start_of(first))
        for action in frames["action"][rows]:
            *_, done, info = env.step(action)
        assert done and info["success"], f"episode {ep} does not re-validate from its start"
        assert frames["next.reward"][rows][-1] == 4


def test_replay_hands_over_where_the_source_did(demo_set):
    """Issue 50 #4, MimicGen's move by subtasks: the pick is replayed relative to the moved cube, the
    hand-over relative to the world (ACT's meeting point is fixed), so a kept replay of a cube moved by
    centimetres grasps it where it now lies and still meets where the source met (one segment relative
    to the cube would carry the meeting point along with the cube)."""
    source = engine.sources(read_source(TASK, demo_set))[0]
    ee = lambda actions: TASK.frame_columns(None, actions)["action.end_effector"]  # noqa: E731
    src_ee = ee(source.actions)
    for k in range(4):
        out = engine.attempt(TASK, source, k, Perturbation(0, 0.05, 0.0), mode="replay")
        shift = np.linalg.norm(np.subtract(out.start[:2], TASK.start_of(source.states[0])[:2]))
        if out.kept and shift > 0.02:
            break
    else:
        pytest.fail("no kept replay of a cube moved by more than 2 cm in 4 attempts")
    new_ee = ee(out.episode["action"])
    lowest = lambda e: e[np.argmin(e[:, 9]), 7:9]  # noqa: E731  the right grasp point's (x, y) at the grasp
    np.testing.assert_allclose(
        lowest(new_ee) - lowest(src_ee), np.subtract(out.start[:2], source.states[0][14:16]), atol=0.01
    )
    np.testing.assert_allclose(new_ee[-1, 7:10], src_ee[-1, 7:10], atol=0.01)  # the right hand at the meeting


def gym_aloha_insertion_reward(m: mujoco.MjModel, d: mujoco.MjData) -> int:
    """gym_aloha/tasks/sim.py's InsertionTask.get_reward, line for line: contact pairs by geom name."""
    pairs = contact_pairs(m, d)
    sockets = ("socket-1", "socket-2", "socket-3", "socket-4")
    touch_right_gripper = ("red_peg", "vx300s_right/10_right_gripper_finger") in pairs
    touch_left_gripper = any((s, "vx300s_left/10_left_gripper_finger") in pairs for s in sockets)
    peg_touch_table = ("red_peg", "table") in pairs
    socket_touch_table = any((s, "table") in pairs for s in sockets)
    peg_touch_socket = any(("red_peg", s) in pairs for s in sockets)
    pin_touched = ("red_peg", "pin") in pairs
    reward = 0
    if touch_left_gripper and touch_right_gripper:
        reward = 1
    if touch_left_gripper and touch_right_gripper and (not peg_touch_table) and (not socket_touch_table):
        reward = 2
    if peg_touch_socket and (not peg_touch_table) and (not socket_touch_table):
        reward = 3
    if pin_touched:
        reward = 4
    return reward


def test_insertion_starts_success_and_expert_are_gym_alohas():
    """Insertion: reset(seed) draws the peg and the socket as gym-aloha's sample_insertion_pose(seed); at
    every step of expert episodes on held-out seeds the env's reward is InsertionTask.get_reward's from the
    same contacts, and the episode ends at the top stage (the peg touches the pin)."""
    task = known_tasks()["aloha_insertion"]
    rng = np.random.RandomState(3)
    peg = rng.uniform([0.1, 0.4, 0.05], [0.2, 0.6, 0.05])
    socket = rng.uniform([-0.2, 0.4, 0.05], [-0.1, 0.6, 0.05])
    want = np.r_[peg, 1, 0, 0, 0, socket, 1, 0, 0, 0].astype(np.float32)
    np.testing.assert_array_equal(task.make_env().reset(3)[14:28], want)
    for seed in (5000, 5001):
        env = task.make_env()
        obs, expert, done, rewards, theirs = env.reset(seed), task.expert.cls(seed=seed), False, [], []
        while not done:
            obs, reward, done, info = env.step(expert.act(obs))
            rewards.append(reward)
            theirs.append(gym_aloha_insertion_reward(env.env.model, env.env.data))
        assert rewards == theirs and info["success"] and rewards[-1] == 4, (seed, max(rewards))


def test_insertion_sets_revalidate_and_are_told_from_transfer_cube_sets(tmp_path):
    """gen_demos.py --task aloha_insertion writes a set whose episodes re-validate in the joint model from
    their recorded starts; both ALOHA tasks record robot_type "aloha", as the hub's sets do, and the
    engine tells them apart by their environment state (the cube's 7 numbers, the peg's and socket's 14)."""
    from datagen.source_check import task_of

    out = tmp_path / "ins"
    r = run_script(ROOT / "gen_demos.py", "--task", "aloha_insertion", "--episodes", "1", "--out", out)
    assert "expert successes 1/1" in r.stdout, r.stdout + r.stderr
    task = task_of(out)
    assert task.name == "aloha_insertion"
    frames = load_arrays(out, keys=("observation.state", "observation.environment_state", "action"))
    env = task.make_env()
    task.place(
        env, task.start_of(np.r_[frames["observation.state"][0], frames["observation.environment_state"][0]])
    )
    for action in frames["action"]:
        *_, done, info = env.step(action)
    assert done and info["success"]


def test_the_engines_guarantees_hold_on_transfer_cube_replay(demo_set, tmp_path):
    """Issue 50 #4: growing gym-aloha's transfer-cube by MimicGen's subtask replay (pick relative to the
    cube, hand-over relative to the world) gives the same bytes for --workers 1 and 2, on a private local
    Ray, and after a run killed (SIGKILL) once its first shard is on disk and finished by the same command
    (2 sources, 1 attempt each, a shard each: every attempt carries its own seed, and a resumed run reuses
    the shards it finds). Re-solve is left out: it would double the minute this takes, nearly all of it
    process and Ray start-up, and its path is the one every other task's tests cover."""
    import json

    from test_engine import same_bytes_everywhere

    mode = "replay"
    flags = ["--src", demo_set, "--aug_mode", mode, "--per_demo", "1", "--shard_size", "1", "--seed", "2"]
    flags += ["--aug_pos_sigma", "0.02", "--quiet"]
    report = json.loads((same_bytes_everywhere(flags, tmp_path) / "generation_report.json").read_text())
    assert report["attempts"] == 2 and report["shards"]["made_this_run"] == 2
    assert report["kept"] >= 1 and set(report["failures"]) <= set(failures_of(TASK)[mode])


def test_the_replay_yield_tool_takes_both_aloha_sim_tasks(tmp_path):
    """Issue 50 #4: `python -m tools.replay yield --tasks aloha_transfer_cube aloha_insertion` (the table
    in docs/replay.md) counts every attempt of every mode of both, at each --sim_sigma multiplier of
    0.08 m. Before, --tasks refused both."""
    import json

    from tools import replay

    tasks = ["aloha_transfer_cube", "aloha_insertion"]
    argv = ["--tasks", *tasks, "--seeds", "1", "--sources", "1", "--attempts", "1", "--sim_sigma", "0.25"]
    assert replay.yield_main([*argv, "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "replay_yield.json").read_text())
    rows = {(r["task"], r["mode"], r["multiplier"]): r for r in res["rows"]}
    assert set(rows) == {(t, m, 0.25) for t in tasks for m in replay.VARIANTS[t]}
    assert {"replay", "subtasks", "subtasks_nearest"} <= set(replay.VARIANTS["aloha_transfer_cube"])
    for r in rows.values():
        assert r["attempts"] == 1 and r["kept"] + sum(r["failures"].values()) == 1 and r["yaw_sigma"] is None
    assert rows[("aloha_transfer_cube", "resolve", 0.25)]["kept"] == 1
    assert res["command"].endswith("--sim_sigma 0.25 --tasks " + " ".join(tasks))


def test_an_insertion_replay_of_parts_moved_by_centimetres_fits_acts_400_steps():
    """Issue 50 #4: insertion replays mostly ran out of ACT's 400 steps. A source takes 361; the replay
    adds two bridges (into the moved parts' frames for the grasp, back to the fixed meeting point for the
    insert), each about as long as the farther part moved, and at the source's own top speed (0.10-0.12
    m/s) the two cost 10 steps per cm: 52 for this attempt, whose peg and socket moved 4.1 and 5.3 cm. At
    the task's bridge_speed the same attempt is kept, in the source's steps plus its bridges."""
    task = known_tasks()["aloha_insertion"]
    episode = next(expert_episodes(task, task.make_env(), 0, 1, noise=task.default_noise))
    source = Source(0, episode["observation.state"], episode["action"])
    out = engine.attempt(task, source, 0, Perturbation(0, 0.05, 0.0), mode="replay")
    moved = np.subtract(out.start, task.start_of(source.states[0]))
    assert min(np.linalg.norm(moved[0:2]), np.linalg.norm(moved[7:9])) > 0.04, moved
    assert out.kept and len(source.actions) < out.steps < task.spec.max_steps, (out.reason, out.steps)


def test_value_study_trains_the_mlp_on_joints_and_cube_at_the_issues_sizes():
    """Issue 50 #5: tools.replay value runs on transfer-cube: the issue's sizes (10 sources, 20 replayed per
    source, 210 fresh, 50 held-out starts, fixed steps), the MLP reading the 14 joints and the cube's pose,
    and one tiny seed of its arms (source, replayed, fresh) trained and rolled out."""
    from tools import replay

    c = replay.value_config("aloha_transfer_cube", smoke=False)
    sizes = (c["source_episodes"], c["per_demo"], c["eval_episodes"], c["steps"])
    assert sizes == (10, 20, 50, 5000), sizes
    arms = replay.VALUE_TASKS["aloha_transfer_cube"]
    assert arms == ("source", "replayed", "fresh") and TASK.spec.obs_dim == 14 + 7
    tiny = dict(c, source_episodes=1, per_demo=1, eval_episodes=1, steps=3, hidden_dim=8, batch_size=16)
    row = replay.value_seed(TASK, arms, 0, tiny, workers=1)
    assert row["steps"] == 3 and row["replay"]["attempts"] >= 1, row
    assert {a: row["arms"][a]["demos"] for a in arms} == {
        "source": 1,
        "replayed": 1 + row["replay"]["kept"],
        "fresh": 2,
    }


def _edited(src, dst, edit):
    """A copy of the set `src` at `dst` whose observation.environment_state is edit(array (N, 7)) in every
    data file, schema and metadata kept: a user's damaged source."""
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    from lerobot_v3.dataset import ENV_STATE_KEY

    shutil.copytree(src, dst)
    for f in sorted((dst / "data").rglob("*.parquet")):
        t = pq.read_table(f)
        field = t.schema.field(ENV_STATE_KEY)
        values = edit(np.array(t[ENV_STATE_KEY].to_pylist(), np.float32))
        i = t.schema.get_field_index(ENV_STATE_KEY)
        t = t.set_column(i, field, pa.array(values.tolist(), field.type))
        pq.write_table(t, f)
    return dst


@pytest.mark.parametrize("value", [float("nan"), float("inf")], ids=["nan", "inf"])
def test_a_non_finite_cube_pose_is_refused_naming_its_column(demo_set, tmp_path, value):
    """Issue 62 #4: a NaN or inf in a source's observation.environment_state (the cube's pose) was refused
    with a line naming observation.state, the column that holds the joints: the line names the column
    that holds the value, as the user finds it in the set."""
    from ch37.errors import DataError

    def damage(env):
        env[3, 1] = value
        return env

    with pytest.raises(DataError) as e:
        read_source(TASK, _edited(demo_set, tmp_path / "bad", damage))
    assert "in observation.environment_state in 1 frames, the first at row 3" in str(e.value), e.value


def test_a_source_whose_cube_quaternions_are_zero_is_refused(demo_set, tmp_path):
    """Issue 62 #11: a source whose cube quaternions are all zero (no rotation at all) was grown as if
    real; it is refused in one line naming the episode, the frame and the quaternion, as gym-pusht's
    keypoints that no T can take are (Task.state_problem)."""
    from ch37.errors import DataError

    def zero(env):
        env[:, 3:] = 0.0
        return env

    with pytest.raises(DataError) as e:
        read_source(TASK, _edited(demo_set, tmp_path / "bad", zero))
    said = str(e.value)
    assert "episode 0, frame 0 (row 0)" in said and "cube_qw, cube_qx, cube_qy, cube_qz" in said, said
    assert "norm 0" in said and "this is not a ALOHA" in said, said


def test_an_episode_the_simulation_blows_up_in_is_a_failure_and_nothing_lands_outside_out(tmp_path):
    """Issue 62 #11: at --noise 1e9 MuJoCo found the sim unstable, reset it mid-episode and went on: the
    frames were written as an episode, and MUJOCO_LOG.TXT was left in the caller's folder. Such an episode
    ends where the sim blew up and counts as a failure (rollout's "unstable"), it is not written (a set of
    none is one line, exit 2) and no file appears outside --out."""
    from datagen.demos import rollout

    env = TASK.make_env()
    s = env_seed(0, "demo", 0)
    ep = rollout(TASK, env, TransferCubeExpert(noise=1e9, seed=s), env.reset(s))
    assert ep["unstable"] and not ep["success"] and len(ep["action"]) < TASK.spec.max_steps, len(ep["action"])
    ep = rollout(TASK, env, TransferCubeExpert(noise=0.0, seed=s), env.reset(s))  # the same env, fresh again
    assert not ep["unstable"] and ep["success"]

    caller = tmp_path / "caller"
    caller.mkdir()
    argv = ["--task", "aloha_transfer_cube", "--episodes", "1", "--noise", "1e9", "--out", tmp_path / "o"]
    r = run_script(ROOT / "gen_demos.py", *argv, "--quiet", cwd=caller, check=False)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "unstable" in err[0], r.stdout + r.stderr
    assert "lower --noise" in err[0] and not (tmp_path / "o").exists(), err
    assert list(caller.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["caller"]
