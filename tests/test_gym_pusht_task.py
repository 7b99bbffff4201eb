"""LeRobot's own PushT (gym-pusht) through the engine, as a task nobody here wrote (issue 40): demo sets in
the schema of lerobot/pusht_keypoints, both modes of augment_demos.py, every kept episode re-executed
open-loop in a fresh gym-pusht from its recorded start, and a set written by LeRobot's own writer."""

import json

import numpy as np
import pytest
from conftest import ROOT, run_script

from datagen import known_tasks
from datagen.task import failures_of
from lerobot_v3 import ENV_STATE_KEY, load_arrays

TASK = known_tasks()["gym_pusht"]


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    out = tmp_path_factory.mktemp("gp") / "src"
    r = run_script(
        ROOT / "gen_demos.py", "--task", "gym_pusht", "--episodes", "3", "--seed", "0", "--out", out
    )
    assert "expert successes 3/3" in r.stdout, r.stdout + r.stderr
    return out


def test_the_demo_set_has_the_hub_schema(source):
    info = json.loads((source / "meta" / "info.json").read_text())
    shapes = {k: info["features"][k]["shape"] for k in ("observation.state", ENV_STATE_KEY, "action")}
    assert shapes == {"observation.state": [2], ENV_STATE_KEY: [16], "action": [2]} and info["fps"] == 10
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("local/gp", root=source, video_backend="pyav")
    assert ds.num_episodes == 3 and tuple(ds[0][ENV_STATE_KEY].shape) == (16,)
    # issue 49 #2: next.reward, next.done and next.success as lerobot/pusht_keypoints records them
    hub = {"next.reward": ("float32", [1]), "next.done": ("bool", [1]), "next.success": ("bool", [1])}
    assert {k: (info["features"][k]["dtype"], info["features"][k]["shape"]) for k in hub} == hub
    d = load_arrays(source, keys=("next.reward", "next.done", "next.success", "episode_index"))
    last = np.r_[np.diff(d["episode_index"]) != 0, True]  # each episode's last frame
    done, success, r = (np.ravel(d[k]) for k in ("next.done", "next.success", "next.reward"))
    assert np.array_equal(done, last) and np.array_equal(success, last)
    assert np.all(r[last] == 1.0) and np.all(((0 <= r) & (r < 1))[~last])


def replays_exactly(kept_set) -> int:
    """Re-execute every kept episode open-loop in a fresh gym-pusht from its aug.start: its recorded
    agent positions and keypoints, gym-pusht's reward and termination (next.reward, next.done) at every
    frame, and its own success at its end. Returns the episodes checked."""
    keys = (
        "observation.state",
        ENV_STATE_KEY,
        "action",
        "episode_index",
        "aug.start",
        "next.reward",
        "next.done",
    )
    d = load_arrays(kept_set, keys=keys)
    episodes = np.unique(d["episode_index"])
    for e in episodes:
        rows = np.flatnonzero(d["episode_index"] == e)
        env = TASK.make_env()
        obs = TASK.place(env, tuple(float(v) for v in d["aug.start"][rows[0]]))
        for r in rows:
            assert np.array_equal(obs[:2], d["observation.state"][r]) and np.array_equal(
                obs[2:], d[ENV_STATE_KEY][r]
            )
            obs, reward, done, info = env.step(d["action"][r])
            assert np.ravel(d["next.reward"])[r] == np.float32(reward) and np.ravel(d["next.done"])[r] == done
        assert info["is_success"] and done
    return len(episodes)


# replay at 1 mm and 0.005 rad: open-loop pushes in pymunk keep some there, none at the chapter's
@pytest.mark.parametrize("mode, sigmas", [("resolve", ("0.08", "0.5")), ("replay", ("0.001", "0.005"))])
def test_augment_demos_grows_it_and_every_kept_episode_re_executes(source, tmp_path, mode, sigmas):
    out = tmp_path / mode
    args = ["--src", source, "--out", out, "--per_demo", "3", "--seed", "1", "--aug_mode", mode, "--quiet"]
    args += ["--aug_pos_sigma", sigmas[0], "--aug_yaw_sigma", sigmas[1], "--workers", "1"]
    r = run_script(ROOT / "augment_demos.py", *args)
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "generation_report.json").read_text())
    assert report["attempts"] == 9 and set(report["failures"]) <= set(failures_of(TASK)[mode])
    assert report["kept"] >= (8 if mode == "resolve" else 1)  # the expert re-solves nearly every start
    assert replays_exactly(out) == report["kept"]


def test_a_set_written_by_lerobots_own_writer_in_the_hubs_form_goes_in_as_it_is(source, tmp_path):
    """What a practitioner has: a set LeRobot wrote (LeRobotDataset.create, add_frame, save_episode),
    names in the hub's {"motors": [...]} form, next.reward and next.done beside next.success, no
    robot_type of ours. augment_demos.py reads the task from its widths and grows it."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    d = load_arrays(
        source, keys=("observation.state", ENV_STATE_KEY, "action", "episode_index", "next.success")
    )
    feats = {
        "observation.state": {"dtype": "float32", "shape": (2,), "names": {"motors": ["motor_0", "motor_1"]}},
        ENV_STATE_KEY: {"dtype": "float32", "shape": (16,), "names": None},
        "action": {"dtype": "float32", "shape": (2,), "names": {"motors": ["motor_0", "motor_1"]}},
        "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
        "next.done": {"dtype": "bool", "shape": (1,), "names": None},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    }
    theirs = tmp_path / "theirs"
    ds = LeRobotDataset.create(
        "someone/pusht_keypoints", fps=10, features=feats, root=theirs, use_videos=False
    )
    for e in np.unique(d["episode_index"]):
        rows = np.flatnonzero(d["episode_index"] == e)
        for i, r in enumerate(rows):
            last = i == len(rows) - 1
            frame = {
                k: np.atleast_1d(d[k][r])
                for k in ("observation.state", ENV_STATE_KEY, "action", "next.success")
            }
            frame |= {"next.reward": np.float32([float(last)]), "next.done": np.array([last])}
            ds.add_frame(frame | {"task": "Push the T-shaped block onto the T-shaped target."})
        ds.save_episode()
    ds.finalize()
    out = tmp_path / "grown"
    args = ["--src", theirs, "--out", out, "--per_demo", "2", "--seed", "1", "--workers", "1", "--quiet"]
    r = run_script(ROOT / "augment_demos.py", *args)
    assert r.returncode == 0, r.stderr
    report = json.loads((out / "generation_report.json").read_text())
    assert report["attempts"] == 6 and report["kept"] >= 5
    assert replays_exactly(out) == report["kept"]


def test_making_the_env_prints_no_pygame_notice():
    """Issue 48 #11: gymnasium.make imports gym-pusht's env module, and with it pygame, whose
    "pkg_resources is deprecated" notice was printed on every run (once per worker): the env module is
    imported inside the import that silences it. A fresh process: this one may have imported pygame."""
    code = "from datagen.tasks.gym_pusht import GYM_PUSHT\nGYM_PUSHT.make_env().reset(0)\nprint('made')"
    r = run_script("-c", code)
    assert r.stdout.strip() == "made" and r.stderr.strip() == "", r.stderr


def test_gen_demos_records_a_gym_pusht_video(tmp_path):
    """Issue 48 #5: `gen_demos.py --task gym_pusht --video` stopped in its first rollout with
    AttributeError: 'GymnasiumEnv' object has no attribute 'render'. gym-pusht draws its frames itself
    (pygame, no OpenGL): the set holds its video, IMAGE_SIZE square, one frame per frame."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_v3 import IMAGE_KEY, IMAGE_SIZE

    out = tmp_path / "set"
    r = run_script(ROOT / "gen_demos.py", "--task", "gym_pusht", "--episodes", "1", "--video", "--out", out)
    assert "expert successes 1/1" in r.stdout and r.stderr.strip() == "", r.stderr
    ds = LeRobotDataset("local/gp", root=out, video_backend="pyav")
    first, last = ds[0][IMAGE_KEY], ds[len(ds) - 1][IMAGE_KEY]
    assert tuple(first.shape) == (3, IMAGE_SIZE, IMAGE_SIZE) and float(first.std()) > 0.05
    assert not np.allclose(first.numpy(), last.numpy())  # the block moved


def _one_frame_moved(src, dst, move, episode=1, frame=4):
    """A copy of `src` whose keypoints at `frame` of `episode` are move(keypoints (8, 2)), all else kept."""
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    shutil.copytree(src, dst)
    f = sorted((dst / "data").rglob("*.parquet"))[0]
    t = pq.read_table(f)
    row = np.flatnonzero(t["episode_index"].to_numpy() == episode)[frame]
    values = t[ENV_STATE_KEY].to_pylist()
    values[row] = [float(v) for v in move(np.asarray(values[row], np.float64).reshape(8, 2)).ravel()]
    i = t.schema.get_field_index(ENV_STATE_KEY)
    field = t.schema.field(ENV_STATE_KEY)
    pq.write_table(t.set_column(i, field, pa.array(values, field.type)), f)
    return dst


@pytest.mark.parametrize(
    "move",
    [
        lambda kp: 2 * kp - kp.mean(axis=0),  # scaled x2 about its centre
        lambda kp: np.repeat(kp.mean(axis=0, keepdims=True), 8, axis=0),  # collapsed onto one point
        lambda kp: kp * (-1, 1) + (512, 0),  # mirrored, x -> 512 - x
    ],
    ids=["scaled", "collapsed", "mirrored"],
)
def test_keypoints_that_are_no_rigid_t_are_refused_naming_the_episode_and_frame(source, tmp_path, move):
    """Issue 48 #1: a frame whose 8 keypoints are no placement of the T (within the range check) is no
    gym-pusht state: refused in one line naming its episode and frame, nothing grown from it."""
    bad = _one_frame_moved(source, tmp_path / "bad", move)
    args = ["--src", bad, "--out", tmp_path / "o", "--per_demo", "1", "--workers", "1", "--quiet"]
    r = run_script(ROOT / "augment_demos.py", *args, check=False)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and "Traceback" not in r.stderr, r.stdout + r.stderr
    assert "episode 1, frame 4" in err[0] and "not a rigid placement of the T" in err[0], err[0]
    assert not (tmp_path / "o").exists()


def test_gym_pusht_s_own_keypoints_fit_the_t_well_inside_the_tolerance(source):
    """The tolerance is far above what gym-pusht's own float32 keypoints are off (their fit residual) and
    far below what the cases above are off."""
    from datagen.tasks.gym_pusht import KEYPOINT_TOL, keypoint_residual

    d = load_arrays(source, keys=(ENV_STATE_KEY,))
    assert keypoint_residual(d[ENV_STATE_KEY]).max() < KEYPOINT_TOL / 100
    assert TASK.state_problem(np.hstack([np.zeros((len(d[ENV_STATE_KEY]), 2)), d[ENV_STATE_KEY]])) is None


def test_the_engines_guarantees_hold_on_gym_pusht(source, tmp_path):
    """Issue 49 #3: growing LeRobot's own PushT gives the same bytes for --workers 1 and 2, on a private
    local Ray, and after a run killed (SIGKILL) once its first shard is on disk and finished by the same
    command: every attempt carries its own seed, and a resumed run reuses the shards it finds."""
    from test_engine import same_bytes_everywhere

    flags = ["--src", source, "--per_demo", "4", "--shard_size", "2", "--seed", "2", "--quiet"]
    report = json.loads((same_bytes_everywhere(flags, tmp_path) / "generation_report.json").read_text())
    assert report["attempts"] == 12 and report["kept"] >= 10 and report["shards"]["made_this_run"] == 6


def test_an_upgrade_of_gym_pusht_or_pymunk_remakes_cached_sets_and_refuses_old_shards(source, tmp_path):
    """Issue 49 #2: the digest a demo set is stamped with (datagen.demos.generator_version: a cached set
    with another digest is made again) and every grown run's settings (what a resumed shard must match)
    name the versions of gym-pusht, pymunk and shapely, the packages that make its frames and its success."""
    from importlib.metadata import version

    digest = json.loads((source / "scale_data_stamp.json").read_text())["generator_version"]
    out = tmp_path / "grown"
    r = run_script(ROOT / "augment_demos.py", "--src", source, "--out", out, "--per_demo", "1", "--quiet")
    assert r.returncode == 0, r.stderr
    ran = json.loads((out / "scale_data_stamp.json").read_text())["config"]["versions"]
    for p in TASK.spec.packages:
        assert f"+{p}{version(p)}" in digest and ran[p] == version(p)
    assert {"gym-pusht", "pymunk"} <= set(TASK.spec.packages)


def test_live_replay_gives_the_same_bytes_for_any_workers_and_every_kept_episode_re_executes(
    source, tmp_path
):
    """Issue 49 #4: --aug_mode replay_live (the replay that re-anchors on the block's live pose) grows
    LeRobot's own PushT through the engine's runner: the same bytes with --workers 1 and 2, its failures
    among the mode's reasons, and every kept episode re-executed open-loop in a fresh gym-pusht."""
    from test_engine import tree

    flags = ["--src", source, "--per_demo", "3", "--seed", "1", "--aug_mode", "replay_live", "--quiet"]
    flags += ["--aug_pos_sigma", "0.001", "--aug_yaw_sigma", "0.005", "--shard_size", "2"]
    for w in ("1", "2"):
        r = run_script(ROOT / "augment_demos.py", *flags, "--out", tmp_path / w, "--workers", w)
        assert r.returncode == 0, r.stderr
    assert tree(tmp_path / "1") == tree(tmp_path / "2")
    report = json.loads((tmp_path / "1" / "generation_report.json").read_text())
    assert report["attempts"] == 9 and set(report["failures"]) <= set(failures_of(TASK)["replay_live"])
    assert report["kept"] >= 1 and replays_exactly(tmp_path / "1") == report["kept"]
