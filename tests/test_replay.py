"""Replay mode (MimicGen's move): the SE(2) transform, replay of a source demo in the real physics,
the success filter's reasons, and keep_first's rule (the first successes in k order)."""

import json
import math
from dataclasses import replace

import numpy as np
import pytest

import pusht_env
from ch37.seeds import env_seed
from datagen import PUSHT, Outcome, Perturbation, Source, engine, rollout
from datagen.lockstep import replay_from
from datagen.poses import (
    interpolate,
    interpolate_path,
    planar_pose,
    quat_of,
    rigid_inverse,
    rotation,
    rotation_of,
    rotations_of,
    slerp_path,
    transform_segment,
    transform_sliding,
)
from datagen.task import DeltaCommand, failures_of
from datagen.tasks import pusht
from scripted_expert import PushTExpert


def test_transform_identity_returns_the_path():
    rng = np.random.default_rng(0)
    pts, vel = rng.normal(size=(20, 2)), rng.normal(size=(20, 2))
    pose = (0.13, -0.07, 2.1)
    moved, turned = transform_segment(pts, vel, pose, pose)
    np.testing.assert_allclose(moved, pts, atol=1e-12)
    np.testing.assert_allclose(turned, vel, atol=1e-12)


def test_transform_rotation_about_the_object():
    # object at the origin turned by +90 degrees: a point 1 m ahead of it goes to 1 m to its left
    moved, turned = transform_segment([[1.0, 0.0], [0.0, 2.0]], [[0.5, 0.0]], (0, 0, 0), (0, 0, math.pi / 2))
    np.testing.assert_allclose(moved, [[0.0, 1.0], [-2.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(turned, [[0.0, 0.5]], atol=1e-12)


def test_transform_translation_moves_points_not_velocities():
    moved, turned = transform_segment([[1.5, 2.0]], [[0.3, -0.4]], (1.0, 2.0, 0.0), (3.0, -1.0, 0.0))
    np.testing.assert_allclose(moved, [[3.5, -1.0]], atol=1e-12)
    np.testing.assert_allclose(turned, [[0.3, -0.4]], atol=1e-12)


def test_transform_keeps_the_path_rigid_relative_to_the_object():
    """A general pose change: every point keeps its offset from the object in the object's own frame."""
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(30, 2))
    src, new = (0.2, -0.1, 0.7), (-0.3, 0.25, -2.4)
    moved, _ = transform_segment(pts, np.zeros_like(pts), src, new)
    off_src = (pts - src[:2]) @ rotation(-src[2]).T
    off_new = (moved - new[:2]) @ rotation(-new[2]).T
    np.testing.assert_allclose(off_new, off_src, atol=1e-12)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(moved[:, None] - moved[None], axis=-1), d, atol=1e-12)


def _random_pose(rng) -> np.ndarray:
    """A (4, 4) pose with a uniformly drawn orientation (a random unit quaternion) and position."""
    out = np.eye(4)
    out[:3, :3] = rotation_of(rng.normal(size=4))
    out[:3, 3] = rng.normal(size=3)
    return out


def test_se3_transform_is_the_planar_one_for_planar_frames():
    """Issue 46: a planar task is SE(3)'s special case. Frames given as (x, y, yaw) take the SE(2) path
    (their bytes); the same frames as (4, 4) poses and points at z = 0 take the SE(3) path: the two agree."""
    rng = np.random.default_rng(2)
    pts, vel = rng.normal(size=(25, 2)), rng.normal(size=(25, 2))
    src, new = (0.2, -0.1, 0.7), (-0.3, 0.25, -2.4)
    flat_pts, flat_vel = transform_segment(pts, vel, src, new)
    lift = np.c_[pts, np.zeros(25)], np.c_[vel, np.zeros(25)]
    moved, turned, turns = transform_segment(*lift, planar_pose(*src), planar_pose(*new), np.eye(3)[None])
    np.testing.assert_allclose(moved, np.c_[flat_pts, np.zeros(25)], atol=1e-12)
    np.testing.assert_allclose(turned, np.c_[flat_vel, np.zeros(25)], atol=1e-12)
    np.testing.assert_allclose(turns[0], planar_pose(0, 0, new[2] - src[2])[:3, :3], atol=1e-12)


def test_se3_transform_keeps_position_and_orientation_rigid_relative_to_the_object():
    """A pose of the arm written in the object's frame is the same before and after the object moves:
    inv(src) T = inv(new) T' for every waypoint T (position and orientation), and velocities turn."""
    rng = np.random.default_rng(3)
    src, new = _random_pose(rng), _random_pose(rng)
    pts, vel = rng.normal(size=(10, 3)), rng.normal(size=(10, 3))
    rots = np.stack([rotation_of(q) for q in rng.normal(size=(10, 4))])
    moved, turned, turns = transform_segment(pts, vel, src, new, rots)
    for t in range(10):
        before, after = np.eye(4), np.eye(4)
        before[:3, :3], before[:3, 3] = rots[t], pts[t]
        after[:3, :3], after[:3, 3] = turns[t], moved[t]
        np.testing.assert_allclose(np.linalg.inv(new) @ after, np.linalg.inv(src) @ before, atol=1e-10)
    np.testing.assert_allclose(
        turned @ np.linalg.inv(new[:3, :3]).T, vel @ np.linalg.inv(src[:3, :3]).T, atol=1e-10
    )
    same = transform_segment(pts, None, src, src, rots)
    np.testing.assert_allclose(same[0], pts, atol=1e-12)
    assert same[1] is None and np.allclose(same[2], rots, atol=1e-12)


def test_interpolate_moves_linearly_and_turns_by_slerp():
    """A bridge's pose: position linear, orientation along the shorter arc at a constant rate; the ends
    are the poses themselves; quat_of and rotation_of are each other's inverse."""
    rng = np.random.default_rng(4)
    a, b = _random_pose(rng), _random_pose(rng)
    np.testing.assert_allclose(interpolate(a, b, 0.0), a, atol=1e-12)
    np.testing.assert_allclose(interpolate(a, b, 1.0), b, atol=1e-12)
    whole = np.arccos((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2)
    for s in (0.25, 0.5, 0.8):
        mid = interpolate(a, b, s)
        np.testing.assert_allclose(mid[:3, 3], a[:3, 3] + s * (b[:3, 3] - a[:3, 3]), atol=1e-12)
        part = np.arccos(np.clip((np.trace(a[:3, :3].T @ mid[:3, :3]) - 1) / 2, -1, 1))
        assert part == pytest.approx(s * whole, abs=1e-9)
        np.testing.assert_allclose(mid[:3, :3] @ mid[:3, :3].T, np.eye(3), atol=1e-12)
    for q in rng.normal(size=(20, 4)):
        r = rotation_of(q)
        np.testing.assert_allclose(rotation_of(quat_of(r)), r, atol=1e-12)
    assert interpolate((0, 0, 3.0), (1, 2, -3.0), 0.5) == pytest.approx(
        (0.5, 1.0, 3.0 + 0.5 * (math.tau - 6))
    )


def plain_rotation_of(q) -> np.ndarray:
    """A quaternion's rotation matrix as one writes it for one quaternion (the oracle of rotations_of)."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def plain_transform(points, vectors, rotations, src, new):
    """transform_segment in SE(3) as one writes it for one pair of (4, 4) poses, its inverse [R^T, -R^T p]
    with p a vector (the oracle of rigid_inverse and transform_sliding)."""
    inv = np.eye(4)
    inv[:3, :3], inv[:3, 3] = src[:3, :3].T, -(src[:3, :3].T @ src[:3, 3])
    rel = new @ inv
    turn = rel[:3, :3]
    return points.reshape(-1, 3) @ turn.T + rel[:3, 3], vectors.reshape(-1, 3) @ turn.T, turn @ rotations


def test_rotations_of_stacks_each_quaternions_plain_rotation_bit_for_bit():
    """Issue 58 #6: rotations_of turns a stack of quaternions at once (a replayed path's orientations);
    each is the one-quaternion formula's, bit for bit, unit or not, float64 or float32, and rotation_of is
    its one row."""
    qs = np.random.default_rng(3).normal(size=(500, 4)) * np.repeat([1.0, 1e-3, 7.0, 1e3], 125)[:, None]
    for qs in (qs, qs.astype(np.float32)):  # float32: an observation's quaternion, its norm in float32
        stacked = rotations_of(qs)
        assert stacked.shape == (500, 3, 3) and stacked.dtype == np.float64 and stacked.flags.c_contiguous
        assert rotation_of(qs[0]).flags.c_contiguous  # laid out as one alone: later products take its path
        for q, got in zip(qs, stacked):
            want = plain_rotation_of(q)
            assert got.tobytes() == want.tobytes() and rotation_of(q).tobytes() == want.tobytes()


def test_a_sliding_frame_moves_each_step_as_transform_segment_of_that_step_alone_bit_for_bit():
    """Issue 58 #6: transform_sliding re-expresses every step of a path whose frame slides (its own source
    and new pose per step) in one stack of products; each step is the plain one-pose transform's, bit for
    bit, and rigid_inverse of a stack is each pose's."""
    rng = np.random.default_rng(11)
    for _ in range(20):
        n = int(rng.integers(1, 40))
        src = np.stack([_random_pose(rng) for _ in range(n)])
        new = np.stack([_random_pose(rng) for _ in range(n)])
        pts, vel = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
        rots = rotations_of(rng.normal(size=(n, 4)))
        moved, turned, spun = transform_sliding(pts, vel, src, new, rots)
        inverses = rigid_inverse(src)
        for t in range(n):
            want = plain_transform(pts[t], vel[t], rots[t : t + 1], src[t], new[t])
            assert moved[t].tobytes() == want[0][0].tobytes() and turned[t].tobytes() == want[1][0].tobytes()
            assert spun[t].tobytes() == want[2][0].tobytes()
            one = transform_segment(pts[t : t + 1], vel[t : t + 1], src[t], new[t], rots[t : t + 1])
            assert all(a.tobytes() == b.tobytes() for a, b in zip(one, want))
            assert inverses[t].tobytes() == rigid_inverse(src[t]).tobytes()
    # planar frames: frame by frame through transform_segment's SE(2) arithmetic
    src, new = [(0.1 * t, 0.2, 0.3 * t) for t in range(5)], [(1.0, -0.5 * t, -0.2 * t) for t in range(5)]
    pts, vel = rng.normal(size=(5, 2)), rng.normal(size=(5, 2))
    moved, turned = transform_sliding(pts, vel, src, new)
    for t in range(5):
        one = transform_segment(pts[t : t + 1], vel[t : t + 1], src[t], new[t])
        assert moved[t].tobytes() == one[0][0].tobytes() and turned[t].tobytes() == one[1][0].tobytes()


def test_a_path_is_each_of_its_poses_as_one_interpolation_makes_it_bit_for_bit():
    """Issue 58 #6: interpolate_path and slerp_path find their ends' quaternions once for a whole path (a
    bridge's turn, a frame sliding onto another); each pose is the one the plain per-fraction slerp
    (written out here) gives, bit for bit: on the long arc, the short one (q1 flipped) and nearly equal
    ends (the linear branch)."""

    def plain_slerp(r0, r1, s):
        q0, q1 = quat_of(r0), quat_of(r1)
        dot = float(q0 @ q1)
        if dot < 0:
            q1, dot = -q1, -dot
        if dot > 1 - 1e-12:
            return plain_rotation_of(q0 + s * (q1 - q0))
        theta = math.acos(min(dot, 1.0))
        return plain_rotation_of(
            (math.sin((1 - s) * theta) * q0 + math.sin(s * theta) * q1) / math.sin(theta)
        )

    rng = np.random.default_rng(7)
    way = [t / 37 for t in range(38)]
    flipped = 0
    for i in range(60):
        a, b = _random_pose(rng), _random_pose(rng)
        if i % 3 == 0:  # nearly the same orientation
            b[:3, :3] = rotation_of(quat_of(a[:3, :3]) + rng.normal(scale=1e-9, size=4))
        flipped += float(quat_of(a[:3, :3]) @ quat_of(b[:3, :3])) < 0
        rots = slerp_path(a[:3, :3], b[:3, :3], way)
        poses = interpolate_path(a, b, way)
        for s, rot, pose in zip(way, rots, poses):
            want = plain_slerp(a[:3, :3], b[:3, :3], s)
            assert rot.tobytes() == want.tobytes() and pose[:3, :3].tobytes() == want.tobytes()
            assert pose[:3, 3].tobytes() == (a[:3, 3] + s * (b[:3, 3] - a[:3, 3])).tobytes()
    assert flipped
    a, b = (0.1, -0.2, 3.0), (1.0, 2.0, -3.0)
    dyaw = math.remainder(b[2] - a[2], math.tau)
    want = [(a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), a[2] + s * dyaw) for s in way]
    assert interpolate_path(a, b, way) == want


@pytest.fixture(scope="module")
def env():
    return pusht_env.PushTEnv()


def expert_source(env, i):
    """Source demo i of seed 0, rolled out from the start its first (float32) frame describes."""
    obs = env.reset(env_seed(0, "demo", i))
    start = tuple(float(v) for v in pusht.block_pose(obs)) + (float(obs[0]), float(obs[1]))
    ep = rollout(PUSHT, env, PushTExpert(noise=0.0), env.set_start(*start))
    assert ep["success"]
    return Source(i, ep["observation.state"], ep["action"]), start


def test_identity_replay_reproduces_the_source(env):
    source, start = expert_source(env, 0)
    got = replay_from(PUSHT, env, start, source)
    ep = got.episode
    assert got.kept and got.reason is None and ep["success"] and got.steps == len(source.actions)
    assert len(ep["action"]) == len(source.actions)  # no bridge: the pusher is on the first waypoint
    np.testing.assert_allclose(ep["observation.state"], source.states, atol=1e-6)
    np.testing.assert_allclose(ep["action"], source.actions, atol=1e-6)


class DeltaPushT(pusht.PushT):
    """PushT read as a delta-command arm (issue 58 #4): its 1 m/s velocity command held for one 0.1 s
    control step moves the pusher's position target 0.1 m, so an action is a step of the target in units
    of 0.1 m. The task writes no encoding of its own: the action kind DeltaCommand (a source's targets:
    each frame's point plus its step; an action: the step from the point now to the waypoint) replaces
    PushT's VelocityCommand."""

    name = "delta_pusht"
    step = DeltaCommand({"pusher": slice(0, 2)}, scale=1 / pusht_env.FPS)  # m of target step per action unit
    replay = replace(pusht.PushT.replay, action=step)


def test_a_delta_command_task_replays_its_sources_at_zero_perturbation(env):
    """Issue 58 #4: a task whose action is a step of a position target (MimicGen's OSC delta pose, a mocap
    move) fits the contract through DeltaCommand alone: replayed from its own start (nothing moved),
    every source is reproduced, action for action, and kept."""
    task = DeltaPushT()
    assert isinstance(task.replay.action, DeltaCommand)
    for i in range(3):
        source, start = expert_source(env, i)
        got = replay_from(task, env, start, source)
        assert got.kept and got.steps == len(source.actions), (i, got.reason, got.detail)
        np.testing.assert_allclose(got.episode["action"], source.actions, atol=1e-5)
        np.testing.assert_allclose(got.episode["observation.state"], source.states, atol=1e-5)


def test_a_moved_block_makes_the_replay_miss_and_names_why(env):
    """Shift the whole start 6 cm: the replayed push lands 6 cm off, where the transformed target
    would be; the filter rejects it and says it ran to its end off target."""
    source, start = expert_source(env, 0)
    shifted = (start[0] + 0.06, start[1], start[2], start[3] + 0.06, start[4])
    got = replay_from(PUSHT, env, shifted, source)
    assert not got.kept and got.episode is None and got.steps >= len(source.actions)
    assert got.reason == "finished_off_target"
    assert math.hypot(*env.block_pose[:2]) > pusht_env.SUCCESS_POS_TOL


def test_kept_replays_hold_the_actions_actually_executed(env):
    """Small perturbations keep some replays; re-executing a kept demo's recorded actions from its
    recorded start reproduces its frames and its success (the bridge included)."""
    source, _ = expert_source(env, 1)
    results = [
        engine.attempt(PUSHT, source, k, Perturbation(0, 0.004, 0.02), mode="replay", env=env)
        for k in range(12)
    ]
    kept = [r for r in results if r.kept]
    assert kept, [r.reason for r in results]
    assert all(r.reason in failures_of(PUSHT)["replay"] and r.episode is None for r in results if not r.kept)
    k = next(k for k, r in enumerate(results) if r.kept)
    ep = results[k].episode
    assert results[k].steps == len(ep["action"]) and results[k].source_episode == source.episode
    start = pusht.perturbed_start(source.states[0], engine.attempt_rng(0, source.episode, k), 0.004, 0.02)
    np.testing.assert_allclose(ep["aug.start"][0], start, atol=1e-6)  # the provenance names this start
    obs = env.set_start(*start)
    assert len(ep["action"]) > 0
    for s, a in zip(ep["observation.state"], ep["action"]):
        np.testing.assert_allclose(obs, s, atol=1e-6)
        obs, _, done, info = env.step(a)
    assert info["success"] and done


def test_replay_rejects_most_attempts_at_the_chapter_sigmas(env):
    """The honesty gate bites: at the chapter's perturbation, open-loop replay misses far more often
    than the re-solving expert (which keeps every one of these)."""
    source, _ = expert_source(env, 2)
    modes = {
        m: [engine.attempt(PUSHT, source, k, Perturbation(0, 0.08, 0.5), mode=m, env=env) for k in range(10)]
        for m in ("resolve", "replay")
    }
    assert all(r.kept for r in modes["resolve"])
    assert sum(r.kept for r in modes["replay"]) <= 3


def table_runner(table, log):
    """run_jobs over a fixed {(episode, k): result} table, recording each round it is asked for."""

    def run(jobs):
        log.append(list(jobs))
        return [table[j] for j in jobs]

    return run


def test_keep_first_takes_the_first_successes_in_k_order():
    ok = {"action": np.zeros((1, 2))}
    pattern = {0: "x.xx.x.x..", 1: "..........", 2: "xxxxxxxxxx"}  # x = kept, . = failed
    table = {
        (e, k): (Outcome("miss") if c == "." else Outcome(None, {**ok, "k": k, "e": e}))
        for e, p in pattern.items()
        for k, c in enumerate(p)
    }
    log = []
    kept, attempts, failures = engine.keep_first(
        [0, 1, 2], 3, table_runner(table, log), reasons=("miss",), cap=3
    )
    assert [(r["e"], r["k"]) for r in kept] == [(0, 0), (0, 2), (0, 3), (2, 0), (2, 1), (2, 2)]
    assert attempts == 4 + 9 + 3  # up to the third kept; episode 1 gives up at cap x per_demo = 9
    assert failures == {"miss": 1 + 9}
    assert log[0] == [(e, k) for e in (0, 1, 2) for k in range(3)]  # round one: k < per_demo for all


def test_keep_first_matches_one_attempt_at_a_time():
    """Against the plain rule (try k = 0, 1, ... one by one until per_demo kept or the cap), on random
    yields from 0 to 1: the rounds keep_first batches its attempts into never change the outcome."""
    rng = np.random.default_rng(0)
    for trial in range(50):
        per_demo, cap = int(rng.integers(1, 5)), int(rng.integers(1, 6))
        rates = rng.uniform(0, 1, size=4)
        table = {
            (e, k): (Outcome(None, {"k": k}) if rng.uniform() < rates[e] else Outcome("miss"))
            for e in range(4)
            for k in range(cap * per_demo)
        }
        want_kept, want_attempts, want_miss = [], 0, 0
        for e in range(4):
            n = 0
            for k in range(cap * per_demo):
                if n == per_demo:
                    break
                want_attempts += 1
                if not table[e, k].kept:
                    want_miss += 1
                else:
                    want_kept.append((e, k))
                    n += 1
        log = []
        kept, attempts, failures = engine.keep_first(
            range(4), per_demo, table_runner(table, log), reasons=("miss",), cap=cap
        )
        assert attempts == want_attempts and failures == {"miss": want_miss}, trial
        assert len(kept) == len(want_kept)
        assert [r["k"] for r in kept] == [k for _, k in want_kept], trial


def test_scale_data_replay_names_its_mode_and_what_the_filter_rejected(tmp_path):
    from conftest import ROOT, run_script

    p = run_script(ROOT / "scale_data.py", "--smoke", "--seed", "0", "--no-cache", "--no-rerun",
                   "--aug_mode", "replay", "--aug_tries", "20", "--out", tmp_path / "run")  # fmt: skip
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["aug_mode"] == "replay" and m["config"]["aug_mode"] == "replay"
    assert m["yield"] < 1 and m["attempts"] > m["kept"]
    assert sum(m["augment_failures"].values()) == m["attempts"] - m["kept"]
    assert set(m["augment_failures"]) == set(failures_of(PUSHT)["replay"])
    assert f"the success filter rejected {m['attempts'] - m['kept']} of {m['attempts']}" in p.stdout
    assert (tmp_path / "run" / "demos" / "pusht_aug_seed0_src4_k2_replay").is_dir() or m["kept"] == 0


def test_augment_demos_replay_reports_reasons(tmp_path):
    from conftest import ROOT, run_script

    src = tmp_path / "src"
    run_script(ROOT / "gen_demos_pusht.py", "--episodes", "2", "--seed", "0", "--out", src)
    run_script(ROOT / "augment_demos.py", "--src", src, "--per_demo", "3", "--mode", "replay",
               "--out", tmp_path / "aug", "--workers", "1", "--quiet")  # fmt: skip
    rep = json.loads((tmp_path / "aug" / "generation_report.json").read_text())
    assert rep["attempts"] == 6 and rep["settings"]["mode"] == "replay"
    assert sum(rep["failures"].values()) == rep["attempts"] - rep["kept"]


def test_tools_replay_smoke_feeds_meta_yaml(tmp_path):
    """python -m tools.replay compare (smoke) writes both files; tools.meta turns them into meta.yaml's
    `replay` section, marked provisional, and leaves the section as found when they are absent."""
    import yaml
    from conftest import ROOT, run_script
    from test_packaging import sweep_files

    out = tmp_path / "replay"
    run_script("-m", "tools.replay", "compare", "--smoke", "--seeds", "1", "--sigma", "1", "--attempts", "2",
               "--sigma_seeds", "1", "--out", out)  # fmt: skip
    cmp_ = json.loads((out / "replay_compare.json").read_text())
    (row,) = cmp_["rows"]
    steps = row["steps"]
    assert {a: v["frames"] for a, v in row["arms"].items()}["source"] < row["arms"]["resolve_all"]["frames"]
    assert row["arms"]["replay"]["demos"] == row["arms"]["resolve_matched"]["demos"]  # matched counts
    assert steps == -(-30 * row["arms"]["resolve_all"]["frames"] // 64)  # the chapter's full budget
    a, b = sweep_files(tmp_path, [0.1, 0.2], [0.0, 0.1, 0.2])
    meta = tmp_path / "meta.yaml"
    lab = yaml.safe_load((ROOT / "meta.yaml").read_text())["scale_lab"]  # ex3's answer reads the lab's curves
    meta.write_text(yaml.safe_dump({"replay": {"kept": True}, "scale_lab": lab}))
    base = [
        "-m",
        "tools.meta",
        "--sweep",
        a,
        "--aug-sweep",
        b,
        "--meta",
        meta,
        "--scale-lab",
        tmp_path / "no",
    ]
    run_script(*base, "--replay", tmp_path / "absent")
    assert yaml.safe_load(meta.read_text())["replay"] == {"kept": True}
    run_script(*base, "--replay", out)
    sec = yaml.safe_load(meta.read_text())["replay"]
    assert sec["provisional"] is True
    assert sec["compare"]["per_seed"][0]["replay"] == row["arms"]["replay"]["success"]
    assert [r["mode"] for r in sec["sigma"]["rows"]] == ["resolve", "replay"]


def test_first_per_source_takes_each_source_demos_first_episodes():
    """Episodes 0..5 from sources 3, 3, 7, 3, 7, 7 (two frames each): the first ones per source."""
    ep = np.repeat(np.arange(6), 2)
    src = np.repeat([3, 3, 7, 3, 7, 7], 2)[:, None]
    assert np.unique(ep[engine.first_per_source(ep, src, 2)]).tolist() == [0, 1, 2, 4]
    assert np.unique(ep[engine.first_per_source(ep, src, {3: 3, 7: 1})]).tolist() == [0, 1, 2, 3]
    assert not engine.first_per_source(ep, src, 0).any()
    assert engine.first_per_source(ep, src, {7: 9}).tolist() == np.isin(ep, [2, 4, 5]).tolist()


def test_the_check_command_tells_a_newcomer_what_is_wrong_before_a_long_run():
    """Issue 46 #4: python -m datagen.check TASK runs the start round-trip, the episode limit, the expert,
    the ranges and the zero-perturbation replay, one line each. Each check can fail: a start_of that
    drops the block's yaw, a max_steps that is not the env's, a reach that excludes the path (the line
    names the subtask and the waypoint)."""
    from conftest import ROOT, run_script

    from datagen.check import checks
    from datagen.tasks.gym_pusht import GymPushT
    from datagen.tasks.pusht import PushT

    r = run_script("-m", "datagen.check", "aloha", "--episodes", "2", cwd=ROOT, check=False)
    lines = r.stdout.strip().splitlines()
    assert r.returncode == 0 and len(lines) == 8 and all(" ok: " in x for x in lines[1:]), r.stdout + r.stderr
    assert run_script("-m", "datagen.check", "nope", cwd=ROOT, check=False).returncode == 2

    class NoYaw(PushT):
        def start_of(self, state):
            return super().start_of(state)[:2] + (0.0,) + super().start_of(state)[3:]

    class Shorter(GymPushT):
        spec = replace(GymPushT.spec, max_steps=100)

    class Fenced(NoYaw):  # started at the wrong yaw, its replays fail; a reach that excludes their paths
        replay = replace(PushT.replay, reach={"pusher": ((-0.05, 0.05), (-0.05, 0.05))})

    found = {c: {n: p for n, p, _ in checks(c(), 2, 0, 1e-3)} for c in (NoYaw, Shorter, Fenced)}
    assert "off in block_cos_yaw" in found[NoYaw]["start round-trip"]
    assert found[Shorter]["episode limit"] == "max_steps 100 but the env stops at 300"
    out = found[Fenced]["replay"]
    assert out.startswith(
        "2 of 2 not reproduced; the first: rollout 0: path_out_of_reach (subtask 'push': "
    ), out
    assert "waypoint 0 of" in out and "beyond its reach" in out


def test_transform_pose_moves_a_pose_as_transform_segment_moves_a_path():
    """Issue 49 #4: a frame's pose re-expressed for its object moved (replay_live's expectation of where the
    object should be) is the pose whose position transform_segment gives and whose yaw turns by the
    object's turn; in SE(3) the same as the planar case; pose_gap reads back a known drift."""
    from datagen.poses import pose_gap, transform_pose

    src, new, pose = (0.2, -0.1, 0.7), (-0.3, 0.25, -2.4), (0.25, -0.05, 1.1)
    got = transform_pose(pose, src, new)
    (xy,), _ = transform_segment([pose[:2]], [[0.0, 0.0]], src, new)
    np.testing.assert_allclose(got, [*xy, 1.1 - 2.4 - 0.7], atol=1e-12)
    np.testing.assert_allclose(
        transform_pose(planar_pose(*pose), planar_pose(*src), planar_pose(*new)),
        planar_pose(*got),
        atol=1e-12,
    )
    assert transform_pose(src, src, new) == pytest.approx(new)  # the object itself lands on its new pose
    drift = (pose[0] + 0.003, pose[1] - 0.004, pose[2] + 0.05)
    for a, b in ((pose, drift), (planar_pose(*pose), planar_pose(*drift))):
        assert pose_gap(a, b) == pytest.approx((0.005, 0.05), abs=1e-12)


def test_live_replay_re_expresses_the_rest_of_the_segment_once_the_block_drifts(env):
    """Issue 49 #4, the decision: fed its source's own frames, a live replay commands the source's own
    targets; a block that lies 1 mm from where the segment expects it (below PushT's follow_tol, 2 mm)
    changes nothing; one 1 cm and 0.1 rad off makes the rest of the segment re-expressed from the pose now:
    the next action tracks the source's waypoint moved from the source's block pose at that frame onto
    the live one, with the source's velocity turned with it."""
    from datagen.replay import Replay, plan_of

    source, start = expert_source(env, 0)
    run = Replay(PUSHT, source, plan_of(PUSHT, source), start, follow=PUSHT.replay.follow_tol)
    r = 10
    for t in range(r):
        assert np.allclose(run.act(source.states[t], None), source.actions[t], atol=1e-6)
    near = source.states[r].copy()
    near[2] += 0.001
    assert np.allclose(
        run.act(near, None),
        PUSHT.replay.action.to_action(
            PUSHT, near, {"pusher": source.states[r, :2]}, {"pusher": source.actions[r]}, None
        ),
        atol=1e-6,
    )
    assert run.reanchored == 0
    was = pusht.block_pose(source.states[r + 1])
    now = was + (0.01, 0.0, 0.1)
    live = source.states[r + 1].copy()
    live[2:6] = now[0], now[1], math.sin(now[2]), math.cos(now[2])
    (wp,), (vel,) = transform_segment(
        source.states[r + 1 : r + 2, :2], source.actions[r + 1 : r + 2], was, pusht.block_pose(live)
    )
    want = PUSHT.replay.action.to_action(PUSHT, live, {"pusher": wp}, {"pusher": vel}, None)
    open_loop = PUSHT.replay.action.to_action(
        PUSHT, live, {"pusher": source.states[r + 1, :2]}, {"pusher": source.actions[r + 1]}, None
    )
    got = run.act(live, None)
    assert (
        run.reanchored == 1
        and np.allclose(got, want, atol=1e-6)
        and not np.allclose(got, open_loop, atol=1e-3)
    )


def test_live_replay_keeps_a_start_open_loop_replay_loses(env):
    """Issue 49 #4: from the same perturbed start (source 0, 2 cm and 0.12 rad, attempt 2), open-loop replay
    pushes the block off target; the replay that follows the block's live pose keeps it, and
    the kept demo re-executes from its recorded start to its recorded frames and success."""
    source, _ = expert_source(env, 0)
    how = Perturbation(0, 0.02, 0.12)
    lost = engine.attempt(PUSHT, source, 2, how, mode="replay", env=env)
    got = engine.attempt(PUSHT, source, 2, how, mode="replay_live", env=env)
    assert lost.reason == "finished_off_target" and got.kept, (lost.reason, got.reason)
    ep = got.episode
    np.testing.assert_allclose(ep["aug.start"][0], got.start, atol=1e-6)  # the provenance names its start
    obs = env.set_start(*got.start)
    for s, a in zip(ep["observation.state"], ep["action"]):
        np.testing.assert_allclose(obs, s, atol=1e-6)
        obs, _, done, info = env.step(a)
    assert info["success"] and done
