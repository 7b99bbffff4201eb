"""Gymnasium's Pusher-v5 through the engine's SE(3) contract (issue 46): a 7-DoF arm whose targets are 3-D
poses, an env nobody here wrote. Real MuJoCo, small sizes; the held-out measurements are in docs/replay.md."""

import json

import mujoco
import numpy as np
import pytest
from conftest import ROOT, run_script

from datagen import Perturbation, engine, known_tasks
from datagen.poses import quat_of
from datagen.source_check import read_source
from datagen.tasks import pusher_expert as pe
from datagen.tasks.pusher_expert import PusherExpert, controller, hand_rotation, model, yaw_quat

TASK = known_tasks()["pusher"]


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    """Four expert demos of Pusher-v5, made by the command a user runs."""
    out = tmp_path_factory.mktemp("pusher") / "src"
    r = run_script(ROOT / "gen_demos.py", "--task", "pusher", "--episodes", "4", "--seed", "3", "--out", out)
    assert "expert successes 4/4" in r.stdout, r.stdout + r.stderr
    return out


def test_a_start_round_trips_through_place():
    """place(start_of(obs)) puts the env where obs was: joint angles and speeds, object and goal to the
    bit (float32). The hand's position is its joint angles' own: Pusher-v5 reports body positions from
    before a step's last integration (MuJoCo's mj_step) and joint angles from after, so an observation
    of a moving arm shows its hand up to one substep (0.01 s) behind (under 1 mm here)."""
    env = TASK.make_env()
    obs = env.reset(seed=11)
    for _ in range(7):  # the arm moving: speeds and a pose that reset never shows
        obs, *_ = env.step(np.r_[obs[14:17] + (0.05, 0.0, 0.02), yaw_quat(0.4)].astype(np.float32))
    again = TASK.place(TASK.make_env(), TASK.start_of(obs))
    hand = slice(14, 17)
    np.testing.assert_array_equal(np.delete(again, np.r_[hand]), np.delete(obs, np.r_[hand]))
    assert 0 < np.abs(again[hand] - obs[hand]).max() < 1e-3


def test_the_controller_takes_the_hand_to_a_pose_target():
    """Position and orientation both: within 1 cm and 0.05 rad of a target 12 cm above the object, turned
    -0.6 rad, from the arm's pose at a reset."""
    env = TASK.make_env()
    obs = env.reset(seed=5)
    goal_pos = obs[17:20].astype(np.float64) + (0.0, 0.0, 0.12)
    goal_rot = yaw_quat(-0.6)  # a yaw this arm reaches there (it holds a level hand in some yaws only)
    for _ in range(60):
        obs, *_ = env.step(np.r_[goal_pos, goal_rot].astype(np.float32))
    assert np.linalg.norm(obs[14:17] - goal_pos) < 0.01
    turned = np.abs(quat_of(hand_rotation(obs, mujoco.MjData(model()))) @ goal_rot)
    assert 2 * np.arccos(min(1.0, turned)) < 0.05
    m = model()  # the torques it gives stay inside Pusher-v5's control range
    tau = controller(m, mujoco.MjData(m), obs.astype(np.float64), goal_pos + 1.0, goal_rot)
    assert np.all(np.abs(tau) <= 2.0)


def plain_ik_step(m, data, target_pos, target_quat=None) -> np.ndarray:
    """pusher_expert.ik_step as the textbook writes it: np.linalg.solve, np.r_, np.vstack, np.eye."""
    bid = m.body("tips_arm").id
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacBody(m, data, jp, jr, bid)
    e = np.asarray(target_pos, float) - data.xpos[bid]
    e *= min(1.0, pe.MAX_POS_ERR / (np.linalg.norm(e) + 1e-12))
    jac = jp[:, :7]
    if target_quat is not None:
        qinv, dqt, er = np.zeros(4), np.zeros(4), np.zeros(3)
        mujoco.mju_negQuat(qinv, data.xquat[bid])
        mujoco.mju_mulQuat(dqt, np.asarray(target_quat, float), qinv)
        mujoco.mju_quat2Vel(er, dqt, 1.0)
        er *= min(1.0, pe.MAX_ROT_ERR / (np.linalg.norm(er) + 1e-12))
        e, jac = np.r_[e, pe.ROT_WEIGHT * er], np.vstack([jac, pe.ROT_WEIGHT * jr[:, :7]])
    jjt = jac @ jac.T + pe.DAMPING**2 * np.eye(len(e))
    base = m.body("r_shoulder_pan_link").pos
    rest = pe.Q_REST.copy()
    rest[0] = np.arctan2(target_pos[1] - base[1], target_pos[0] - base[0])
    null = np.eye(7) - jac.T @ np.linalg.solve(jjt, jac)
    return jac.T @ np.linalg.solve(jjt, e) + null @ (pe.K_NULL * (rest - data.qpos[:7]))


def test_the_ik_step_is_the_plain_damped_least_squares_bit_for_bit():
    """ik_step calls np.linalg.solve's own LAPACK gufuncs and reuses its lambda^2 I, for speed (issue 58
    #6: the grasp choice's dry runs make ~700 steps an episode): its step is the plain reading's bit for
    bit, with and without an orientation target, from joint angles across their ranges."""
    m = model()
    data, rng = mujoco.MjData(m), np.random.default_rng(0)
    for i in range(300):
        data.qpos[:7] = rng.uniform(*m.jnt_range[:7].T)
        mujoco.mj_kinematics(m, data)
        mujoco.mj_comPos(m, data)
        target, quat = rng.uniform(-0.5, 0.8, 3), (yaw_quat(rng.uniform(-3, 3)) if i % 2 else None)
        got, want = pe.ik_step(m, data, target, quat), plain_ik_step(m, data, target, quat)
        assert got.tobytes() == want.tobytes(), (i, got - want)


def test_the_expert_pushes_the_object_onto_the_goal_from_starts_it_was_not_tuned_on():
    """A handful of reset seeds far from the ones it was tuned on (0..19): every one solved, and the
    episode ends at the success the task defines (the object within 5 cm of the goal in xy)."""
    for seed in (5001, 5002, 5003):
        env, expert = TASK.make_env(), PusherExpert()
        obs, done, steps = env.reset(seed=seed), False, 0
        while not done:
            obs, _, done, info = env.step(expert.act(obs))
            steps += 1
        assert info["success"] and steps < TASK.spec.max_steps, (seed, steps)
        assert np.hypot(*(obs[17:19] - obs[20:22])) < 0.05


def test_replay_at_zero_perturbation_reproduces_every_source(source):
    """MimicGen's move with nothing moved: each source's target poses, re-expressed in SE(3) for an object
    that did not move and executed through the robot's controller, succeed again."""
    sources = engine.sources(read_source(TASK, source))
    got = [engine.attempt(TASK, s, 0, Perturbation(0, 0.0, 0.0), mode="replay") for s in sources.values()]
    assert [g.reason for g in got] == [None] * len(sources)
    for g, s in zip(got, sources.values()):
        np.testing.assert_allclose(g.episode["action"], s.actions, atol=1e-6)


def test_both_modes_grow_a_pusher_set_with_the_same_bytes_for_any_worker_count(source, tmp_path):
    """augment_demos.py on a Pusher set: re-solve and replay, each kept demo succeeding; 1 and 2 workers
    write the same files."""
    outs = {}
    for mode in ("resolve", "replay"):
        for w in (1, 2):
            out = tmp_path / f"{mode}{w}"
            args = ["--src", source, "--out", out, "--per_demo", "2", "--aug_mode", mode, "--quiet"]
            r = run_script(ROOT / "augment_demos.py", *args, "--aug_pos_sigma", "0.02", "--workers", w)
            assert r.returncode == 0, r.stderr
            outs[mode, w] = {
                p.relative_to(out): p.read_bytes()
                for p in sorted(out.rglob("*"))
                if p.is_file() and p.name != "generation_report.json"
            }
        report = json.loads((tmp_path / f"{mode}1" / "generation_report.json").read_text())
        assert report["attempts"] == 8 and report["kept"] >= 4, report
        assert outs[mode, 1] == outs[mode, 2]
