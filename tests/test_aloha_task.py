"""MimicGen's whole move on both robots (issue 29): ALOHA's set_start, perturbation, grasp-signal subtasks,
segment re-expression, bridged replay and nearest selection; PushT's subtask split and nearest selection."""

import json
import math

import numpy as np
import pytest

import aloha_env
import pusht_env
from ch37.seeds import env_seed
from datagen import ALOHA, PUSHT, Perturbation, engine, rollout
from datagen import replay as rp
from datagen import task as dt
from datagen.lockstep import replay_from
from datagen.poses import rotation
from datagen.tasks import aloha as at
from datagen.tasks import pusht as pt
from scripted_expert import AlohaExpert, PushTExpert


@pytest.fixture(scope="module")
def env():
    return aloha_env.AlohaCubeEnv()


def drawn_start(env, seed):
    """reset(seed), and the start it drew in float64, read back through the env's accessors."""
    obs = env.reset(seed)
    return obs, (*env.cube_pos, *env.target_pos, *env.right_ee, *env.left_ee)


def aloha_source(env, i, *, placed=True):
    """Expert demo i of seed 0. placed: rolled out from set_start at the start its first (float32)
    frame describes, as a source read back from a LeRobot set is replayed; else from reset(seed)."""
    obs = env.reset(env_seed(0, "demo", i))
    if placed:
        obs = env.set_start(*at.start_of(obs))
    ep = rollout(ALOHA, env, AlohaExpert(noise=0.0), obs)
    assert ep["success"]
    return dt.Source(i, ep["observation.state"], ep["action"])


# ------------------------------------------------------------------------------- set_start
def test_set_start_gives_reset_bytes_and_fresh_counters(env):
    seed = env_seed(0, "demo", 3)
    obs, start = drawn_start(env, seed)
    first = rollout(ALOHA, env, AlohaExpert(noise=0.0), obs)
    assert first["success"] and env.steps > 0 and env.success and env.holding[1]  # used, cube held
    again = env.set_start(*start)
    assert env.steps == 0 and not env.success and env.holding == (False, False)
    assert env.grip == (0.0, 0.0)
    assert again.tobytes() == obs.tobytes()
    second = rollout(ALOHA, env, AlohaExpert(noise=0.0), again)
    for k in ("observation.state", "action", "next.success"):
        assert second[k].tobytes() == first[k].tobytes(), k


def test_set_start_places_every_named_value(env):
    start = (0.2, -0.1, -0.25, 0.12, 0.3, 0.15, -0.2, -0.05)
    obs = env.set_start(*start)
    got = dict(zip(aloha_env.STATE_NAMES, obs.tolist()))
    for name, want in zip(aloha_env.START_NAMES, start):
        assert got[name] == pytest.approx(want, abs=1e-7), name
    assert at.start_of(obs) == pytest.approx(start, abs=1e-7)


# ------------------------------------------------------------------------------- perturbation
def test_perturbation_stays_in_its_regions_and_is_a_pure_function(env):
    first = aloha_source(env, 0).states[0]
    boxes = list(at.REGIONS.values())
    for k in range(200):
        start = at.perturbed_start(first, np.random.default_rng([7, k]), 0.3)  # a large sigma
        assert start is not None
        for i, (xr, yr) in enumerate(boxes):
            assert xr[0] <= start[2 * i] <= xr[1] and yr[0] <= start[2 * i + 1] <= yr[1]
    a = at.perturbed_start(first, np.random.default_rng(5), 0.08)
    assert a == at.perturbed_start(first, np.random.default_rng(5), 0.08)
    assert a != at.perturbed_start(first, np.random.default_rng(6), 0.08)
    assert at.perturbed_start(first, np.random.default_rng(5), 0.0) == at.start_of(first)
    assert at.perturbed_start(first, np.random.default_rng(5), 50.0, tries=3) is None  # no valid draw


# ------------------------------------------------------------------------------- subtasks
@pytest.mark.parametrize("i", range(4))
def test_subtask_boundaries_sit_on_the_grasp_signals(env, i):
    src = aloha_source(env, i, placed=False)
    steps = rp.cut(ALOHA, src)
    assert [s.subtask.name for s in steps] == ["reach_grasp", "handoff", "carry_place"]
    assert steps[0].start == 0 and steps[-1].stop == len(src.actions)
    assert all(a.stop == b.start for a, b in zip(steps, steps[1:]))
    s = src.states
    engage, release = steps[1].start, steps[2].start
    near = np.hypot(*(s[:, 0:2] - s[:, 6:8]).T)  # right end-effector to cube (m)
    # before the grasp the cube rests where it spawned and the grasp condition was never met
    assert np.all(s[:engage, 6:8] == s[0, 6:8])
    assert not np.any((s[:engage, 2] > aloha_env.GRASP_ENGAGE) & (near[:engage] < aloha_env.GRASP_RADIUS))
    assert s[engage, 2] > aloha_env.GRASP_ENGAGE and np.any(s[engage + 1 :, 6:8] != s[0, 6:8])
    # the right gripper lets go only once the left one is closed on the cube
    assert s[release - 1, 2] >= aloha_env.GRASP_RELEASE > s[release, 2]
    assert s[release, 5] > aloha_env.GRASP_ENGAGE


def test_split_refuses_a_source_without_a_handoff(env):
    src = aloha_source(env, 0)
    steps = rp.cut(ALOHA, src)
    cut = dt.Source(0, src.states[: steps[1].start + 2], src.actions[: steps[1].start + 2])
    with pytest.raises(ValueError, match="handoff"):
        rp.cut(ALOHA, cut)


# ------------------------------------------------------------------------------- segment transforms
def test_arm_segment_identity_returns_the_source_columns(env):
    src = aloha_source(env, 1)
    plan = rp.cut(ALOHA, src)
    run = rp.Replay(ALOHA, src, plan, at.start_of(src.states[0]))
    for sub in plan:
        for arm, (pts, vel, grip, turns) in run.segment(sub, src.states[sub.start]).items():
            assert turns is None  # a planar arm: no orientation
            rows = slice(sub.start, sub.stop)
            assert np.array_equal(pts, src.states[rows, at.XY[arm]].astype(np.float64))
            assert np.array_equal(vel, src.actions[rows, at.XY[arm]].astype(np.float64))
            assert np.array_equal(grip, src.actions[rows, at.GRIP[arm]].astype(np.float64))


def test_arm_segment_translates_with_its_frame_and_stays_rigid(env):
    src = aloha_source(env, 1)
    plan = rp.cut(ALOHA, src)
    place = plan[2]  # carry_place: the right arm relative to the handoff, the left to the target
    now = src.states[place.start].copy()
    now[8:10] += (0.03, -0.05)  # the target moved; the cube did not
    segs = rp.Replay(ALOHA, src, plan, at.start_of(src.states[0])).segment(place, now)
    pts, vel, *_ = segs["left"]
    old = src.states[place.start : place.stop, 3:5].astype(np.float64)
    np.testing.assert_allclose(pts - old, np.tile((0.03, -0.05), (len(old), 1)), atol=1e-7)
    np.testing.assert_allclose(vel, src.actions[place.start : place.stop, 3:5], atol=1e-12)
    # rigid in the frame: every waypoint keeps its offset from the target
    np.testing.assert_allclose(
        pts - now[8:10].astype(np.float64), old - src.states[place.start, 8:10], atol=1e-7
    )
    # the handoff frame moves with the target's y only; the cube frame not at all here
    hand, *_ = segs["right"]
    np.testing.assert_allclose(
        hand - src.states[place.start : place.stop, 0:2], [[0.0, -0.05]] * len(old), atol=1e-7
    )


def test_pusht_segment_rotates_about_the_block_and_slides_onto_the_target():
    env = pusht_env.PushTEnv()
    src = pusht_source(env, 0)
    by_contact = pt.PushT(pt.BY_CONTACT)
    plan = rp.cut(by_contact, src)
    approach, push = plan
    run = rp.Replay(by_contact, src, plan, by_contact.start_of(src.states[0]))
    first = src.states[0]
    same, *_ = run.segment(approach, first)["pusher"]
    np.testing.assert_allclose(same, src.states[: approach.stop, :2], atol=1e-12)  # identity
    turned = first.copy()  # the block turned by +90 degrees about its own origin
    yaw = math.atan2(first[4], first[5]) + math.pi / 2
    turned[4], turned[5] = math.sin(yaw), math.cos(yaw)
    pts, vel, *_ = run.segment(approach, turned)["pusher"]
    rel_old = src.states[: approach.stop, :2] - first[2:4]
    rel_new = pts - first[2:4]
    np.testing.assert_allclose(rel_new, rel_old @ rotation(math.pi / 2).T, atol=1e-6)  # rotated
    np.testing.assert_allclose(np.linalg.norm(rel_new, axis=1), np.linalg.norm(rel_old, axis=1), atol=1e-6)
    np.testing.assert_allclose(vel, src.actions[: approach.stop] @ rotation(math.pi / 2).T, atol=1e-6)
    # the push relative to the block and the target starts on the moved block, ends on the source's end
    moved = src.states[push.start].copy()
    moved[2:4] += (0.04, -0.02)
    pts, *_ = run.segment(push, moved)["pusher"]
    np.testing.assert_allclose(pts[0], src.states[push.start, :2] + (0.04, -0.02), atol=1e-6)
    np.testing.assert_allclose(pts[-1], src.states[-1, :2], atol=1e-6)
    block_only = pt.PushT(pt.BY_CONTACT_BLOCK)
    plan = rp.cut(block_only, src)
    blk, *_ = rp.Replay(block_only, src, plan, None).segment(plan[1], moved)["pusher"]
    np.testing.assert_allclose(blk - src.states[push.start :, :2], [[0.04, -0.02]] * len(blk), atol=1e-6)


# ------------------------------------------------------------------------------- replay
def test_identity_replay_reproduces_the_source_frames(env):
    """A source replayed from its own start, with no perturbation, is its own frames, byte for byte:
    every frame pose equals its source pose, no bridge is needed, and the tracking term is exactly 0."""
    src = aloha_source(env, 2)
    got = replay_from(ALOHA, env, at.start_of(src.states[0]), src)
    ep = got.episode
    assert got.reason is None and ep["success"]
    assert ep["observation.state"].tobytes() == src.states.tobytes()
    assert ep["action"].tobytes() == src.actions.tobytes()


def test_identity_replay_of_a_reset_source_is_its_frames_to_float32_rounding(env):
    """A source rolled out from reset(seed) started from float64 values its float32 first frame
    rounds; replayed from that frame, it differs from its source by rounding alone."""
    src = aloha_source(env, 2, placed=False)
    got = replay_from(ALOHA, env, at.start_of(src.states[0]), src)
    ep = got.episode
    assert got.reason is None and len(ep["action"]) == len(src.actions) == got.steps
    np.testing.assert_allclose(ep["observation.state"], src.states, atol=1e-6)
    np.testing.assert_allclose(ep["action"], src.actions, atol=1e-5)


def test_replay_keeps_what_re_executes_and_names_every_rejection(env):
    srcs = {i: aloha_source(env, i) for i in range(3)}
    sims = engine.Simulators()  # the sources' cuts, made once
    how = Perturbation(0, 0.08, 0.5)
    results = [
        engine.attempt(ALOHA, srcs[e], k, how, mode="replay", env=env, sims=sims)
        for e in srcs
        for k in range(4)
    ]
    kept = [r for r in results if r.kept]
    assert kept and all(r.reason in dt.failures_of(ALOHA)["replay"] for r in results if not r.kept)
    ep, start = kept[0].episode, kept[0].start
    obs = env.set_start(*start)  # the recorded actions from the recorded start give the same frames
    for s, a in zip(ep["observation.state"], ep["action"]):
        assert obs.tobytes() == s.tobytes()
        obs, _, done, info = env.step(a)
    assert info["success"] and done


def test_subtasks_carry_the_cube_where_one_cube_frame_cannot(env):
    """Move only the target: the cube-relative whole-demo replay delivers to the old target and is
    rejected; the subtask replay re-expresses the handoff and the place in the moved target's frames."""
    src = aloha_source(env, 0)
    start = list(at.start_of(src.states[0]))
    start[2] += 0.06  # target x: still inside its spawn region for this source
    start[3] = -start[3] * 0.5
    assert aloha_env.TARGET_X_RANGE[0] <= start[2] <= aloha_env.TARGET_X_RANGE[1]
    got = replay_from(at.Aloha(at.WHOLE), env, start, src)
    assert got.reason == "finished_off_target" and got.episode is None
    got = replay_from(ALOHA, env, start, src)
    assert got.reason is None and got.episode["success"]


def test_nearest_picks_the_source_with_the_nearest_objects(env):
    srcs = {i: aloha_source(env, i) for i in range(4)}
    for e, s in srcs.items():
        assert rp.nearest(ALOHA, srcs, at.start_of(s.states[0])) == e
    near = np.array(at.start_of(srcs[2].states[0]))
    near[:4] += 0.004
    assert rp.nearest(ALOHA, srcs, tuple(near)) == 2


# ------------------------------------------------------------------------------- PushT
def pusht_source(env, i):
    obs = env.reset(env_seed(0, "demo", i))
    start = tuple(float(v) for v in pt.block_pose(obs)) + (float(obs[0]), float(obs[1]))
    ep = rollout(PUSHT, env, PushTExpert(noise=0.0), env.set_start(*start))
    assert ep["success"]
    return dt.Source(i, ep["observation.state"], ep["action"])


def test_pusht_split_and_identity_replay():
    env = pusht_env.PushTEnv()
    src = pusht_source(env, 0)
    by_contact = pt.PushT(pt.BY_CONTACT)
    approach, push = rp.cut(by_contact, src)
    s = src.states
    assert approach.start == 0 and approach.stop == push.start and push.stop == len(s)
    d = [pusht_env.t_signed_distance(r[0], r[1], r[2], r[3], math.atan2(r[4], r[5])) for r in s]
    assert min(d[: push.start]) > pusht_env.PUSHER_RADIUS + pt.CONTACT_TOL >= d[push.start]
    start = tuple(float(v) for v in pt.block_pose(s[0])) + (float(s[0][0]), float(s[0][1]))
    got = replay_from(by_contact, env, start, src)
    ep = got.episode
    assert got.reason is None
    assert (
        ep["observation.state"].tobytes() == s.tobytes() and ep["action"].tobytes() == src.actions.tobytes()
    )


def test_pusht_nearest_weighs_yaw_by_the_success_tolerances():
    env = pusht_env.PushTEnv()
    srcs = {i: pusht_source(env, i) for i in range(3)}
    for e, s in srcs.items():
        start = tuple(float(v) for v in pt.block_pose(s.states[0])) + (0.0, 0.0)
        assert rp.nearest(PUSHT, srcs, start) == e
    a, b = (0.1, 0.0, 0.0), (0.1, 0.0, 0.2)  # 0.2 rad apart = one success tolerance = 0.03 m
    assert pt.pose_distance(a, b) == pytest.approx(pusht_env.SUCCESS_POS_TOL)


def test_replay_yield_tool_counts_every_attempt_of_every_cell(tmp_path):
    from tools import replay as replay_yield

    argv = ["--seeds", "1", "--sources", "2", "--attempts", "1", "--aloha_sigma", "2", "--out", str(tmp_path)]
    assert replay_yield.yield_main(argv) == 0
    res = json.loads((tmp_path / "replay_yield.json").read_text())
    rows = {(r["task"], r["mode"], r["multiplier"]): r for r in res["rows"]}
    tasks = replay_yield.DEFAULT_TASKS  # pusher only on request (tests/test_pusher_task.py's own size)
    want = {(t, m, 1.0) for t in tasks for m in replay_yield.VARIANTS[t]}
    assert set(rows) == want | {("aloha", m, 2.0) for m in replay_yield.SIGMA_MODES}
    for r in rows.values():
        assert r["attempts"] == 2 and r["kept"] + sum(r["failures"].values()) == 2
    assert rows[("pusht", "resolve", 1.0)]["kept"] == rows[("aloha", "resolve", 1.0)]["kept"] == 2
    assert res["command"].endswith("--aloha_sigma 2")
    kept = [r for r in rows.values() if r["kept"]]
    assert kept and all(r["kept_frames_median"] > 0 for r in kept)
