"""The data engine: one attempt as a pure function, augment_demos.py's shards, merge, stats, executors,
resume after SIGKILL, and its refusals. Real MuJoCo, real LeRobot, real Ray, real subprocesses."""

import hashlib
import json
import math
import os
import secrets
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, run_script, with_fps, with_nan, with_value

import gen_demos_aloha
import gen_demos_pusht
import pusht_env
from ch37.ownership import LOCK_NAME, MADE_BY, STAMP_NAME
from datagen import ALOHA, PUSHT, Perturbation, engine, plan, shards
from datagen.report import REPORT_NAME
from datagen.task import failures_of
from datagen.tasks import pusht
from lerobot_v3.dataset import load_arrays, open_dataset

PER_DEMO, SHARD = 4, 2  # 3 sources x 4 = 12 attempts in 6 shards: enough to kill one run mid-way
SETTINGS = ["--per_demo", str(PER_DEMO), "--shard_size", str(SHARD), "--quiet"]


def tree(root, skip=(REPORT_NAME,)):
    """{relative path: bytes} of every file under root (the report holds timings, so it is left out)."""
    return {
        p.relative_to(root).as_posix(): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name not in skip
    }


def augment(*args, check=True):
    return run_script(ROOT / "augment_demos.py", *args, check=check)


@pytest.fixture(scope="module")
def src(tmp_path_factory):
    out = tmp_path_factory.mktemp("src") / "pusht3"
    assert gen_demos_pusht.main(["--episodes", "3", "--seed", "0", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.fixture(scope="module")
def reference(src, tmp_path_factory):
    """The run every other run must equal byte for byte: --workers 1."""
    out = tmp_path_factory.mktemp("ref") / "aug"
    p = augment("--src", src, "--out", out, "--workers", "1", *SETTINGS)
    assert p.stdout.strip().splitlines()[-1].startswith("augment_demos: 12 attempts")
    return out


# ----------------------------------------------------------------------------------------------
# One attempt
# ----------------------------------------------------------------------------------------------
def test_attempt_is_a_pure_function_with_provenance(src):
    sources = engine.sources(load_arrays(src))
    how = Perturbation(seed=0, pos_sigma=0.08, yaw_sigma=0.5)
    got = engine.attempt(PUSHT, sources[1], 2, how, env=pusht_env.PushTEnv())
    shared = pusht_env.PushTEnv()
    engine.attempt(PUSHT, sources[0], 0, how, env=shared)  # another attempt first, on the same simulator
    b = engine.attempt(PUSHT, sources[1], 2, how, env=shared).episode
    a = got.episode
    assert got.kept and a["success"] and got.source_episode == 1 and got.steps == len(a["action"])
    assert all(a[k].tobytes() == b[k].tobytes() for k in ("observation.state", "action", "aug.start"))
    n = len(a["action"])
    assert a["aug.source_episode"].shape == (n, 1) and (a["aug.source_episode"] == 1).all()
    start = a["aug.start"][0]
    assert a["aug.start"].shape == (n, 5) and (a["aug.start"] == start).all()
    # the first frame is the simulator placed at the recorded start, and the start differs from the source's
    env = pusht_env.PushTEnv()
    first = env.set_start(
        *pusht.perturbed_start(sources[1].states[0], engine.attempt_rng(0, 1, 2), 0.08, 0.5)
    )
    assert a["observation.state"][0].tobytes() == first.tobytes()
    assert np.abs(start[:2] - sources[1].states[0][2:4]).max() > 1e-4
    other_k = engine.attempt(PUSHT, sources[1], 3, how).episode
    assert other_k["aug.start"][0].tobytes() != start.tobytes()


def test_perturbed_starts_stay_on_the_band_and_clear_of_the_block():
    rng = np.random.default_rng(0)
    state = np.array([0.3, 0.3, 0.15, 0.0, 0.0, 1.0, 0, 0, 0, 1], np.float32)
    for _ in range(200):
        bx, by, yaw, px, py = pusht.perturbed_start(state, rng, 0.08, 0.5)
        assert pusht.R_LO <= math.hypot(bx, by) <= pusht.R_HI and -math.pi <= yaw <= math.pi
        assert max(abs(px), abs(py)) <= pusht_env.PUSHER_HALF
        assert pusht_env.pusher_clear(bx, by, yaw, px, py)


def test_an_impossible_perturbation_is_a_reason_not_a_demo(src):
    sources = engine.sources(load_arrays(src))
    got = engine.attempt(PUSHT, sources[0], 0, Perturbation(0, 5.0, 0.5))
    assert not got.kept and got.reason == "no_valid_start" and got.episode is None and got.steps == 0
    assert "no_valid_start" in failures_of(PUSHT)["resolve"]


# ----------------------------------------------------------------------------------------------
# A run: what it writes
# ----------------------------------------------------------------------------------------------
def test_run_writes_the_attempts_in_order_loadable_with_provenance(src, reference):
    sources = engine.sources(load_arrays(src))
    want = [
        engine.attempt(PUSHT, sources[e], k, Perturbation(0, 0.08, 0.5)) for e in range(3) for k in range(4)
    ]
    want = [w.episode for w in want if w.kept]
    keys = ("observation.state", "action", "episode_index", "aug.start", "aug.source_episode")
    got = load_arrays(reference, keys=keys)
    for key in ("observation.state", "action", "aug.start", "aug.source_episode"):
        assert got[key].tobytes() == np.concatenate([w[key] for w in want]).reshape(got[key].shape).tobytes()
    ds = open_dataset(reference)
    assert ds.num_episodes == len(want) and ds.fps == pusht_env.FPS
    frame = ds[len(want[0]["action"])]  # first frame of the second kept episode
    assert int(frame["aug.source_episode"]) == int(want[1]["aug.source_episode"][0, 0])
    assert np.allclose(frame["aug.start"].numpy(), want[1]["aug.start"][0])
    assert not (reference / shards.SHARDS_DIR).exists()  # shards are removed once merged
    stamp = json.loads((reference / STAMP_NAME).read_text())
    assert stamp["made_by"] == MADE_BY and stamp["complete"] and stamp["config"]["source"]["episodes"] == 3
    rep = json.loads((reference / REPORT_NAME).read_text())
    assert rep["attempts"] == 12 and rep["kept"] == len(want) == rep["dataset"]["episodes"]
    assert rep["kept"] + sum(rep["failures"].values()) == rep["attempts"]
    assert rep["frames"] == len(got["action"]) and rep["yield"] == round(rep["kept"] / 12, 4)
    assert {e: v["attempts"] for e, v in rep["per_source"].items()} == {"0": 4, "1": 4, "2": 4}
    assert rep["source"]["sha256"] == stamp["config"]["source"]["sha256"]
    lengths = [len(w["action"]) for w in want]
    assert rep["episode_length"]["min"] == min(lengths) and rep["episode_length"]["max"] == max(lengths)
    assert rep["shards"] == {"total": 6, "made_this_run": 6, "reused": 0}
    assert rep["seconds"] > 0 and rep["demos_per_s"] > 0 and "augment_demos.py" in rep["command"]
    # the time split (issue 19 #5): the workers' write seconds lie inside the generate phase's
    assert rep["seconds_merge"] > 0 and 0 < rep["seconds_write"] < rep["seconds_generate"]
    assert {"lerobot", "mujoco", "numpy", "python"} <= set(rep["versions"])


def test_stats_are_over_all_frames(reference):
    """LeRobot 0.6.1's merge averages per-episode quantiles (lerobot issue 4156); ours are numpy's."""
    import pandas as pd

    df = pd.concat(pd.read_parquet(f) for f in sorted((reference / "data").rglob("*.parquet")))
    stats = json.loads((reference / "meta" / "stats.json").read_text())
    raw = (reference / "meta" / "stats.json").read_text()
    assert raw == json.dumps(json.loads(raw), indent=4, sort_keys=True, ensure_ascii=False)
    for key in ("observation.state", "action", "aug.start", "frame_index", "index", "next.success"):
        col = df[key].to_numpy()
        x = np.stack(col).astype(np.float64) if isinstance(col[0], np.ndarray) else col.astype(np.float64)
        x = x.reshape(len(df), -1)
        st = stats[key]
        assert st["count"] == [len(df)]
        for name, ref in (("min", x.min(0)), ("max", x.max(0)), ("mean", x.mean(0)), ("std", x.std(0))):
            np.testing.assert_allclose(st[name], ref, rtol=1e-12, atol=1e-12, err_msg=f"{key} {name}")
        for name, q in (("q01", 0.01), ("q10", 0.10), ("q50", 0.50), ("q90", 0.90), ("q99", 0.99)):
            np.testing.assert_allclose(st[name], np.quantile(x, q, axis=0), rtol=1e-12, atol=1e-12)
    ep = np.stack(df["episode_index"].to_numpy())
    assert sorted(set(ep.tolist())) == list(range(len(set(ep.tolist()))))  # merged episodes renumbered


# ----------------------------------------------------------------------------------------------
# Same bytes: any worker count, Ray, and a killed run finished by the same command
# ----------------------------------------------------------------------------------------------
def test_two_workers_same_bytes(src, reference, tmp_path):
    augment("--src", src, "--out", tmp_path / "w2", "--workers", "2", *SETTINGS)
    assert tree(tmp_path / "w2") == tree(reference)


def test_shard_size_changes_no_byte(src, reference, tmp_path):
    """Issue 31 #5: the merge cuts files by row counts, never where a shard ends, and computes each
    episode's index and episode_index stats from its final indices: shards of 7 attempts (2 shards,
    not 6) give the same data/ and meta/ files, byte for byte, meta/episodes included."""
    out = tmp_path / "s7"
    augment("--src", src, "--out", out, "--workers", "1", "--per_demo", str(PER_DEMO), "--shard_size", "7")
    assert json.loads((out / REPORT_NAME).read_text())["shards"]["total"] == 2
    got, want = (
        tree(out, skip=(REPORT_NAME, STAMP_NAME)),
        tree(reference, skip=(REPORT_NAME, STAMP_NAME)),
    )
    assert got.keys() == want.keys() and any(k.startswith("meta/episodes/") for k in got)
    assert [k for k in got if got[k] != want[k]] == []


def test_merged_index_stats_equal_the_writers_own():
    """Issue 31 #5: the merge's per-episode stats of index and episode_index, computed for all episodes
    of one length at once, equal _episode_stats (LeRobot's compute_episode_stats bit for bit) on each
    episode's final indices: lengths 1-300, indices up to 10^12."""
    import pyarrow as pa

    from lerobot_v3.dataset import _episode_stats
    from lerobot_v3.merge import _index_stats

    lengths = np.r_[1, 2, 300, np.random.default_rng(0).integers(1, 300, 60)]
    hi = np.cumsum(lengths)
    eps = pa.table({"dataset_from_index": hi - lengths, "dataset_to_index": hi})
    feats = {"episode_index": {"dtype": "int64"}, "index": {"dtype": "int64"}}
    for n_eps, n_frames in ((0, 0), (99_990, 3_200_000), (999_999_000, 10**12)):
        got = _index_stats(eps, n_eps, n_frames)
        for j, (lo, n) in enumerate(zip(hi - lengths + n_frames, lengths, strict=True)):
            buf = {"episode_index": np.full(n, n_eps + j), "index": np.arange(lo, lo + n)}
            for name, st in _episode_stats(buf, feats).items():
                for k, v in st.items():
                    want = np.asarray(v, np.int64 if k == "count" else np.float64).tolist()
                    assert got[f"stats/{name}/{k}"][j] == want, (n_eps, j, name, k)


def test_local_ray_same_bytes(src, reference, tmp_path):
    """A real Ray started by the command on this machine (2 CPUs) and shut down at its end."""
    p = augment("--src", src, "--out", tmp_path / "ray", "--ray", "--workers", "2", *SETTINGS)
    assert tree(tmp_path / "ray") == tree(reference)
    rep = json.loads((tmp_path / "ray" / REPORT_NAME).read_text())
    assert rep["executor"].startswith("ray local") and rep["versions"]["ray"]
    assert "Traceback" not in p.stderr


def test_forked_map_passes_its_work_and_names_a_killed_worker():
    """Issue 39 #4: the forked workers get fn and the jobs as their arguments (no module state), so a
    closure works, in job order or as finished; an exception in a job is raised here; a worker killed
    mid-job (out of memory) is one DataError, not a wait for an answer that never comes."""
    from ch37.errors import DataError
    from ch37.parallel import map_jobs

    k = 3
    want = [x * k for x in range(40)]
    assert list(map_jobs(lambda x: x * k, range(40), workers=2)) == want
    assert sorted(map_jobs(lambda x: x * k, range(40), workers=2, ordered=False)) == want

    def fails(x):
        if x == 7:
            raise ValueError("job 7")
        return x

    with pytest.raises(ValueError, match="job 7"):
        list(map_jobs(fails, range(20), workers=2))

    def killed(x):
        if x == 5:
            os.kill(os.getpid(), signal.SIGKILL)
        return x

    with pytest.raises(DataError, match=r"a worker process died \(exit code -9\)"):
        list(map_jobs(killed, range(20), workers=2))


def test_a_stop_signal_while_the_forked_map_starts_its_workers_is_raised_as_it_is(monkeypatch):
    """Issue 39 #4, found by test_hardening's SIGTERM case: a stop signal whose Python handler runs while
    the map starts its workers (Terminated, raised inside Process.start) reached the run as an
    AssertionError from joining a worker never started (exit 1 and a traceback, not one line and 143).
    It is raised as it is, and the worker started before it is gone."""
    import multiprocessing.process

    from ch37.errors import Terminated
    from ch37.parallel import map_jobs

    start, started = multiprocessing.process.BaseProcess.start, []

    def start_then_stop(self):
        if started:
            raise Terminated()
        start(self)
        started.append(self)

    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", start_then_stop)
    with pytest.raises(Terminated):
        list(map_jobs(abs, range(20), workers=3))
    assert len(started) == 1 and not started[0].is_alive()


RAY_CRASH = """
import os, sys, time
from ch37.parallel import map_jobs

def fn(i):
    if i == 1:
        os._exit(1)  # the worker dies, as on a lost node
    return i

try:
    for r in map_jobs(fn, [(0,), (1,), (2,)], workers=2, ray="local", ordered=False, star=True):
        print("result", r, flush=True)
except Exception as e:
    print("failed", type(e).__name__, flush=True)
time.sleep(2)  # Ray's message thread printed its lines in this time
"""


def test_ray_cluster_messages_stay_off_stdout():
    """Issue 31 #7: a Ray worker lost mid-run reaches the run as its task's exception; Ray's driver
    printed its raylet message ("(raylet) A worker died ...", 1 long line per loss, ~20 for a node)
    to our stdout as well, whatever log_to_driver said."""
    p = subprocess.run(
        [sys.executable, "-c", RAY_CRASH], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().splitlines()
    assert lines and lines[-1].startswith("failed "), p.stdout  # the task's exception reached the run
    assert all(x.startswith(("result ", "failed ")) for x in lines), p.stdout  # and nothing of Ray's


def killed_after_its_first_shard(cmd: list, out: Path) -> subprocess.Popen:
    """Run `cmd` (an augment_demos.py run into `out`) and SIGKILL it once its first shard is on disk."""
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 300
    while not list((out / shards.SHARDS_DIR).glob("shard-*")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate()
    return proc


def same_bytes_everywhere(flags: list, tmp_path: Path) -> Path:
    """The engine's guarantees for one augment_demos.py run (`flags`, everything but --out and
    --workers): the same bytes with --workers 1 and 2, on a private local Ray (--ray --workers 2), and
    after a --workers 1 run killed (SIGKILL) once its first shard is on disk and finished by the same
    command, which reuses what it finds. Returns the --workers 1 output, tmp_path/"w1"."""
    ref = tmp_path / "w1"
    augment(*flags, "--out", ref, "--workers", "1")
    want = tree(ref)
    augment(*flags, "--out", tmp_path / "w2", "--workers", "2")
    assert tree(tmp_path / "w2") == want
    augment(*flags, "--out", tmp_path / "ray", "--ray", "--workers", "2")
    assert tree(tmp_path / "ray") == want
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        str(ROOT / "augment_demos.py"),
        *map(str, flags),
        "--out",
        str(out),
        "--workers",
        "1",
    ]
    proc = killed_after_its_first_shard(cmd, out)
    assert proc.returncode == -signal.SIGKILL and not (out / "meta").exists()
    augment(*cmd[2:])
    assert tree(out) == want
    assert json.loads((out / REPORT_NAME).read_text())["shards"]["reused"] >= 1
    return ref


def test_killed_run_is_finished_by_the_same_command(src, reference, tmp_path):
    out = tmp_path / "killed"
    cmd = [sys.executable, str(ROOT / "augment_demos.py"), "--src", str(src), "--out", str(out)]
    cmd += ["--workers", "1", *SETTINGS]
    proc = killed_after_its_first_shard(cmd, out)
    assert proc.returncode == -signal.SIGKILL
    done = sorted(p.name for p in (out / shards.SHARDS_DIR).glob("shard-*"))
    assert 1 <= len(done) < 6 and not (out / "meta").exists()
    # what a kill can leave behind: a shard cut off mid-save, and a shard folder without a stamp
    (out / shards.SHARDS_DIR / ".shard-00005.partial" / "data").mkdir(parents=True)
    if "shard-00004" not in done:  # (one worker makes the shards in order; the kill came early)
        (out / shards.SHARDS_DIR / "shard-00004").mkdir()
        (out / shards.SHARDS_DIR / "shard-00004" / "junk.parquet").write_bytes(b"half a file")
    p = augment(*cmd[2:])
    assert tree(out) == tree(reference)
    rep = json.loads((out / REPORT_NAME).read_text())
    assert rep["shards"]["reused"] == len(done) and rep["shards"]["made_this_run"] == 6 - len(done)
    assert rep["attempts"] == 12  # the report covers the whole run, reused shards included
    # issue 31 #7: the summary says what this run made (its rate is over that) and what it resumed
    made = rep["kept_this_run"]
    resumed = rep["kept"] - made
    assert f"{made} made now in " in p.stdout and f"{resumed} resumed from {len(done)} shards" in p.stdout
    again = augment(*cmd[2:])  # a finished run: nothing to do, nothing changed
    assert "already complete" in again.stdout and tree(out) == tree(reference)


# ----------------------------------------------------------------------------------------------
# Bad input: one line, exit 2, nothing touched
# ----------------------------------------------------------------------------------------------
def _wrong_schema(tmp, src):
    bad = tmp / "wrong_schema"
    shutil.copytree(src, bad)
    info = json.loads((bad / "meta" / "info.json").read_text())
    info["features"]["observation.state"]["shape"] = [7]
    (bad / "meta" / "info.json").write_text(json.dumps(info))
    return bad


def _renamed_state(tmp, src):
    bad = tmp / "renamed"
    shutil.copytree(src, bad)
    info = json.loads((bad / "meta" / "info.json").read_text())
    info["features"]["observation.state"]["names"] = [f"x{i}" for i in range(10)]
    (bad / "meta" / "info.json").write_text(json.dumps(info))
    return bad


def _corrupt_parquet(tmp, src):
    bad = tmp / "corrupt"
    shutil.copytree(src, bad)
    for f in (bad / "data").rglob("*.parquet"):
        f.write_bytes(b"PAR1 this is not a parquet file")
    return bad


def _no_data_files(tmp, src):
    bad = tmp / "no_data"
    shutil.copytree(src, bad)
    shutil.rmtree(bad / "data")
    return bad


def _edited(edit):  # issue 22 item 11 and the fps question: a copy of the good source, edited
    def make(tmp, src):
        shutil.copytree(src, tmp / "edited")
        return edit(tmp / "edited")

    return make


def _without_index_columns(root):
    """The set's meta/episodes table without the columns that say where each episode's frames are."""
    import pyarrow.parquet as pq

    for f in (root / "meta" / "episodes").rglob("*.parquet"):
        t = pq.read_table(f)
        drop = ["dataset_from_index", "dataset_to_index", "data/chunk_index", "data/file_index"]
        pq.write_table(t.drop_columns(drop), f)
    return root


def _other_robot(tmp, src):  # issue 29: a set of no task the engine knows
    bad = tmp / "so100"
    shutil.copytree(src, bad)
    info = json.loads((bad / "meta" / "info.json").read_text())
    info["robot_type"] = "so100_follower"
    (bad / "meta" / "info.json").write_text(json.dumps(info))
    return bad


def _user_out(tmp):
    out = tmp / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    return out


def _other_settings_out(tmp):
    out = tmp / "other"
    out.mkdir()
    stamp = {"made_by": MADE_BY, "kind": "engine", "config": {"per_demo": 99}, "complete": True}
    (out / STAMP_NAME).write_text(json.dumps(stamp))
    return out


def _demo_set_out(tmp):  # a set this project made, but not an engine run: never overwritten
    out = tmp / "demo_set"
    assert gen_demos_pusht.main(["--episodes", "1", "--out", str(out), "--quiet"]) == 0
    return out


BAD = [  # (id, make src or None (the good one), make out or None (a new folder), extra flags, needle)
    ("missing_src", lambda t, s: t / "nope", None, [], "not a folder"),
    ("src_is_a_file", lambda t, s: s / "meta" / "info.json", None, [], "not a folder"),
    ("not_lerobot", lambda t, s: t, None, [], "not a LeRobot v3 dataset"),
    ("wrong_schema", _wrong_schema, None, [], "observation.state"),
    ("set_of_no_task", _other_robot, None, [], "robot_type 'so100_follower'"),
    ("renamed_state", _renamed_state, None, [], "names"),
    ("corrupt_parquet", _corrupt_parquet, None, [], "not a readable parquet file"),
    ("no_data_files", _no_data_files, None, [], "could not be read"),
    ("nan_action", _edited(with_nan), None, [], "non-finite values (NaN or inf) in action"),
    (
        "src_at_50fps",
        _edited(lambda p: with_fps(p, 50)),
        None,
        [],
        "recorded at 50 fps, but the env steps at 10",
    ),
    # issue 31 #6: values outside the env's documented ranges, an episodes table without its index columns
    (
        "block_x_beyond_the_walls",
        _edited(lambda p: with_value(p, "observation.state", 0, 2, 1e30)),
        None,
        [],
        "observation.state block_x (index 2) is 1e+30 in 1 frames, the first at row 0",
    ),
    ("episodes_without_index_columns", _edited(_without_index_columns), None, [], "dataset_from_index"),
    ("out_holds_user_data", None, _user_out, [], "did not make"),
    ("out_other_settings", None, _other_settings_out, [], "other settings"),
    ("out_is_a_demo_set", None, _demo_set_out, [], "did not make"),
    ("out_inside_src", None, lambda t: None, ["--out", "{src}/aug"], "overlaps"),
    ("out_not_utf8", None, lambda t: Path(os.fsdecode(os.fsencode(t) + b"/out\xff")), [], "UTF-8"),
    ("per_demo_0", None, None, ["--per_demo", "0"], "--per_demo"),
    ("per_demo_huge", None, None, ["--per_demo", "1000000000"], "--per_demo must be at most 1000000"),  # #10
    ("shard_size_0", None, None, ["--shard_size", "0"], "--shard_size"),
    ("workers_0", None, None, ["--workers", "0"], "--workers"),
    ("seed_negative", None, None, ["--seed", "-1"], "--seed"),
    ("seed_too_big", None, None, ["--seed", "3074457345618"], "--seed must be at most"),  # issue 22 #8
    ("out_name_too_long", None, None, ["--out", "/tmp/" + "a" * 300], "too long"),  # issue 22 #7
    ("pos_sigma_nan", None, None, ["--pos_sigma", "nan"], "--pos_sigma"),
    ("yaw_sigma_negative", None, None, ["--yaw_sigma", "-1"], "--yaw_sigma"),
    ("yaw_sigma_huge", None, None, ["--yaw_sigma", "1e308"], "--yaw_sigma must be at most 10"),  # issue 22 #9
    ("pos_sigma_huge", None, None, ["--pos_sigma", "11"], "--pos_sigma must be at most 10"),
    ("mode_unknown", None, None, ["--mode", "teleport"], "--mode"),
    ("select_nearest_resolve", None, None, ["--select", "nearest"], "--select nearest chooses the source"),
]


def test_a_shard_size_that_leaves_thousands_of_files_says_so():
    """Issue 31 #7: --shard_size 1 with 3,000 attempts kept ~18,000 files under shards/ without a word."""
    assert shards.many_files_note(30, 3000, 100, Path("big")) is None  # the default: 180 files
    note = shards.many_files_note(3000, 3000, 1, Path("big"))
    assert note.startswith("note: --shard_size 1 cuts 3,000 attempts into 3,000 shards: up to 18,000 files")
    assert "\n" not in note


def test_a_plan_beyond_memory_is_one_line():
    """Issue 22 item 10: the plan's memory (ATTEMPT_BYTES an attempt) is checked against what is free."""
    assert plan.plan_memory_problem(3, 10, 1 << 30) is None
    assert plan.plan_memory_problem(12, 10**6, None) is None  # unknown memory: not refused
    why = plan.plan_memory_problem(12, 10**6, 1 << 30, "--per_demo")  # 12e6 attempts x 200 B = 2.2 GB > 1 GB
    assert "12,000,000 attempts need about 2.2 GB" in why and "lower --per_demo" in why
    # the flag named as the command spells it: augment_demos' --attempts_per_demo unless told otherwise
    assert "lower --attempts_per_demo" in plan.plan_memory_problem(12, 10**6, 1 << 30)


@pytest.mark.parametrize("make_src,make_out,extra,needle", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_is_one_line_and_exit_2(src, tmp_path, make_src, make_out, extra, needle):
    work = tmp_path / "work"
    work.mkdir()
    the_src = make_src(work, src) if make_src else src
    out = (make_out(tmp_path) if make_out else None) or tmp_path / "out"
    before = {p: tree(p, skip=()) if p.is_dir() else None for p in (src, the_src, out) if p.exists()}
    args = ["--src", the_src, "--out", out, "--workers", "1", "--quiet"]
    args += [a.format(src=src) for a in extra]
    p = augment(*args, check=False)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2, (p.returncode, p.stdout, p.stderr)
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0], p.stderr
    assert "Traceback" not in p.stderr + p.stdout
    for path, files in before.items():
        assert (tree(path, skip=()) if path.is_dir() else None) == files, path
    if make_out is None:
        assert not out.exists() and not (src / "aug").exists()


def test_sigterm_is_one_line_and_143_and_the_run_finishes_later(src, reference, tmp_path):
    """Issue 22 #7: SIGTERM mid-run is one `terminated:` line and exit 143; the same command finishes."""
    out = tmp_path / "term"
    cmd = [sys.executable, str(ROOT / "augment_demos.py"), "--src", str(src), "--out", str(out)]
    cmd += ["--workers", "1", *SETTINGS]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not list((out / shards.SHARDS_DIR).glob("shard-*")) and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    lines = err.strip().splitlines()
    assert proc.returncode == 143 and len(lines) == 1 and lines[0].startswith("terminated:"), err
    augment(*cmd[2:])
    assert tree(out) == tree(reference)


@pytest.mark.slow
def test_joining_a_ray_cluster_same_bytes(src, reference, tmp_path):
    """--ray ADDRESS: a real single-node cluster started with `ray start --head`, stopped at the end."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    # Ray 2.60 clusters authenticate with a token: this one's own, given to the head and to the run
    # alike (no ~/.ray/auth_token: a fresh machine has none, and the engine's own clusters write none)
    env = dict(os.environ, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    ray_bin = Path(sys.executable).with_name("ray")
    head = subprocess.Popen(
        [str(ray_bin), "start", "--head", "--block", "--port", str(port), "--num-cpus", "2"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        cmd = [
            sys.executable,
            str(ROOT / "augment_demos.py"),
            "--src",
            str(src),
            "--out",
            str(tmp_path / "joined"),
        ]
        cmd += ["--ray", f"127.0.0.1:{port}", *SETTINGS]
        for _ in range(30):  # the head takes a few seconds to listen
            p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
            if p.returncode == 0 or "could not join" not in p.stderr:
                break
            time.sleep(2)
        assert p.returncode == 0, p.stderr
    finally:
        head.terminate()  # `ray start --block` stops the processes it started
        head.wait(timeout=60)
    assert tree(tmp_path / "joined") == tree(reference)
    rep = json.loads((tmp_path / "joined" / REPORT_NAME).read_text())
    assert rep["executor"] == f"ray 127.0.0.1:{port}"


# ----------------------------------------------------------------------------------------------
# Resume after a kill: the user's files refused, damaged shards remade (issue 22: #3, #4)
# ----------------------------------------------------------------------------------------------
def _killed_after(src, out, n_shards: int) -> list[str]:
    """Start the --workers 1 run on `out`, SIGKILL it once `n_shards` shards are finished; their names."""
    cmd = [sys.executable, str(ROOT / "augment_demos.py"), "--src", str(src), "--out", str(out)]
    proc = subprocess.Popen([*cmd, "--workers", "1", *SETTINGS], cwd=ROOT, stdout=subprocess.PIPE)
    deadline = time.monotonic() + 300
    while len(list((out / shards.SHARDS_DIR).glob("shard-*"))) < n_shards and proc.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate()
    assert proc.returncode == -signal.SIGKILL, "the run ended before it was killed"
    return sorted(p.name for p in (out / shards.SHARDS_DIR).glob("shard-*"))


def sha256_tree(root) -> dict:
    """{relative path: sha256} of every file under root but the lock file (which names its holder)."""
    return {rel: hashlib.sha256(data).hexdigest() for rel, data in tree(root, skip=(LOCK_NAME,)).items()}


def test_resume_refuses_user_files_in_shards_and_data(src, tmp_path):
    out = tmp_path / "o"
    _killed_after(src, out, 1)
    (out / shards.SHARDS_DIR / "notes.txt").write_text("mine\n")
    (out / "data").mkdir(exist_ok=True)
    (out / "data" / "README.md").write_text("my readme\n")
    before = sha256_tree(out)
    p = augment("--src", src, "--out", out, "--workers", "1", *SETTINGS, check=False)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and err[0].startswith("error: "), p.stdout + p.stderr
    assert "data/README.md" in err[0] and "shards/notes.txt" in err[0], err
    assert "Traceback" not in p.stdout + p.stderr
    assert sha256_tree(out) == before  # nothing changed, the user's files included


def test_resume_remakes_damaged_shards_byte_identical(src, reference, tmp_path):
    """A bit flipped in one finished shard's parquet, another's emptied (a crash before the data reached
    the disk): the resume says so, remakes both and ends byte-identical to an uninterrupted run."""
    out = tmp_path / "o"
    done = _killed_after(src, out, 2)
    flipped, emptied = [out / shards.SHARDS_DIR / d / "data/chunk-000/file-000.parquet" for d in done[:2]]
    data = bytearray(flipped.read_bytes())
    data[len(data) // 2] ^= 0x01  # one bit in the middle of the file
    flipped.write_bytes(bytes(data))
    emptied.write_bytes(b"")
    p = augment("--src", src, "--out", out, "--workers", "1", *SETTINGS, check=False)
    assert p.returncode == 0 and "Traceback" not in p.stdout + p.stderr, p.stdout + p.stderr
    lines = [x for x in p.stdout.splitlines() if "is damaged" in x]
    assert len(lines) == 2 and all("making it again" in x for x in lines), p.stdout
    assert tree(out) == tree(reference)  # every data/ and meta/ file, byte for byte
    rep = json.loads((out / REPORT_NAME).read_text())
    assert rep["shards"]["reused"] == len(done) - 2 and rep["attempts"] == 12


def test_a_stamp_whose_counts_disagree_with_its_files_is_a_damaged_shard(src, reference, tmp_path):
    """Issue 31 #2: one more "kept" in a finished shard's stamp (its files untouched, valid JSON) is
    caught against the shard's own files: the resume says the shard is damaged, remakes it and ends
    byte-identical to an uninterrupted run, where it stopped with an AssertionError (and kept doing so)."""
    out = tmp_path / "o"
    done = _killed_after(src, out, 2)
    path = out / shards.SHARDS_DIR / done[0] / STAMP_NAME
    stamp = json.loads(path.read_text())
    path.write_text(json.dumps(stamp | {"kept": stamp["kept"] + 1}))
    p = augment("--src", src, "--out", out, "--workers", "1", *SETTINGS, check=False)
    assert p.returncode == 0 and "Traceback" not in p.stdout + p.stderr, p.stdout + p.stderr
    lines = [x for x in p.stdout.splitlines() if "is damaged" in x]
    assert len(lines) == 1 and done[0][-5:] in lines[0] and "making it again" in lines[0], p.stdout
    assert tree(out) == tree(reference)
    rep = json.loads((out / REPORT_NAME).read_text())
    assert rep["kept"] == json.loads((reference / REPORT_NAME).read_text())["kept"]


# ----------------------------------------------------------------------------------------------
# The ALOHA handoff through the same engine (issue 29): its task read from the set
# ----------------------------------------------------------------------------------------------
ALOHA_SETTINGS = ["--per_demo", "2", "--shard_size", "1", "--quiet"]  # 3 sources x 2 = 6 shards of 1


@pytest.fixture(scope="module")
def aloha_src(tmp_path_factory):
    out = tmp_path_factory.mktemp("asrc") / "aloha3"
    assert gen_demos_aloha.main(["--episodes", "3", "--seed", "0", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize(
    "which,needle",
    [
        ("src", "action pusher_vx (index 0) is 1e+30 in 1 frames, the first at row 3"),
        ("aloha_src", "action right_vx (index 0) is 1e+30 in 1 frames, the first at row 3"),
    ],
)
def test_an_action_outside_the_envs_range_is_one_line(request, tmp_path, which, needle):
    """Issue 42 #10: a source action of 1e30 (finite) was accepted without a word (ALOHA's replays then
    failed as source_not_split): actions are checked against the env's range as states are."""
    bad = tmp_path / "bad"
    shutil.copytree(request.getfixturevalue(which), bad)
    with_value(bad, "action", 3, 0, 1e30)
    before = tree(bad, skip=())
    p = augment("--src", bad, "--out", tmp_path / "out", "--workers", "1", "--quiet", check=False)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and err[0].startswith("error: --src") and needle in err[0], err
    assert "[-1, 1]" in err[0] and tree(bad, skip=()) == before and not (tmp_path / "out").exists()


def test_aloha_replay_nearest_same_bytes_for_workers_ray_and_resume(aloha_src, tmp_path):
    """MimicGen's subtask replay from the nearest source, on an ALOHA set: the attempts as
    datagen.engine.attempt makes them, provenance naming the source replayed, and the same bytes for
    --workers 1 and 2, a local Ray and a run killed after its first shard and finished."""
    flags = ["--src", aloha_src, "--mode", "replay", "--select", "nearest", *ALOHA_SETTINGS]
    ref = same_bytes_everywhere(flags, tmp_path)
    sources = engine.sources(load_arrays(aloha_src))
    how = Perturbation(0, 0.08, 0.5)
    jobs = [(e, k) for e in range(3) for k in range(2)]
    want = [engine.attempt(ALOHA, sources[e], k, how, mode="replay", pool=sources) for e, k in jobs]
    kept = [w.episode for w in want if w.kept]
    keys = ("observation.state", "action", "aug.start", "aug.source_episode")
    got = load_arrays(ref, keys=keys)
    assert kept and got["action"].shape[1] == 6 and got["aug.start"].shape[1] == len(ALOHA.start_names)
    for key in keys:
        assert got[key].tobytes() == np.concatenate([w[key] for w in kept]).reshape(got[key].shape).tobytes()
    own = [e for e, _ in jobs]
    chosen = [w.source_episode for w in want]
    assert all(int(w.episode["aug.source_episode"][0, 0]) == w.source_episode for w in want if w.kept)
    assert chosen != own  # nearest chose another source for some attempt (else this test shows nothing)
    rep = json.loads((ref / REPORT_NAME).read_text())
    assert (
        set(rep["failures"]) == set(failures_of(ALOHA)["replay"]) and rep["settings"]["select"] == "nearest"
    )
    assert rep["kept"] + sum(rep["failures"].values()) == rep["attempts"] == 6


def test_aloha_resolve_is_a_lerobot_set_of_the_handoff(aloha_src, tmp_path):
    """--mode resolve on an ALOHA set: the noise-free AlohaExpert re-solves each perturbed start, and
    LeRobotDataset reads the result with its 6-D actions and provenance over ALOHA's start names."""
    out = tmp_path / "res"
    p = augment("--src", aloha_src, "--out", out, "--workers", "1", *ALOHA_SETTINGS)
    assert p.stdout.strip().splitlines()[-1].startswith("augment_demos: 6 attempts")
    ds = open_dataset(out)
    rep = json.loads((out / REPORT_NAME).read_text())
    assert ds.num_episodes == rep["kept"] > 0 and ds.meta.robot_type == ALOHA.spec.robot_type
    assert ds.meta.features["aug.start"]["names"] == list(ALOHA.start_names)
    frame = ds[0]
    assert tuple(frame["action"].shape) == (6,) and tuple(frame["aug.start"].shape) == (8,)
    assert set(rep["failures"]) == set(failures_of(ALOHA)["resolve"])


def test_a_killed_worker_is_named_with_its_exit_code_even_when_its_pipe_ends_first():
    """Issue 48 #3: a killed worker's pipe ends before the process is reaped (its files are closed
    first as it dies; on a loaded machine the gap is long enough to see), and the map read its exit
    code in that gap: "a worker process died (exit code ); ...". Here the gap is made wide on purpose:
    the job closes its pipe, waits, then kills its own process. The map waits for the dead worker (a
    bounded wait) and names its code."""
    from ch37.errors import DataError
    from ch37.parallel import map_jobs

    def dies_after_its_pipe(x):
        if x == 5:
            os.closerange(3, os.sysconf("SC_OPEN_MAX"))  # its end of the pipe: the parent sees it end
            time.sleep(1)
            os.kill(os.getpid(), signal.SIGKILL)
        return x

    with pytest.raises(DataError, match=r"a worker process died \(exit code -9\); try fewer --workers"):
        list(map_jobs(dies_after_its_pipe, range(20), workers=2))


RAY_TOKEN_PROBE = r"""
import json, os, subprocess
from ch37.parallel import map_jobs

LOOK = 'id -u; grep -rlsF -D skip -f - -- "$H" "$T" /proc/[0-9]*/cmdline /proc/[0-9]*/environ'


def probe(_):
    # in a worker of the run's own cluster, while it runs: the token it was started with (Ray's places:
    # the environment, else ~/.ray/auth_token), then every file where an unprivileged user finds it
    token = os.environ.get("RAY_AUTH_TOKEN")
    if token is None:
        with open(os.path.join(os.environ["HOME"], ".ray", "auth_token")) as f:
            token = f.read().strip()
    nobody = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", "sh", "-c", LOOK]
    env = {"PATH": "/usr/bin:/bin", "H": os.environ["HOME"], "T": os.environ["RAY_TMPDIR"]}
    p = subprocess.run(nobody, input=token, capture_output=True, text=True, env=env)  # on stdin: no trace
    return len(token), p.stdout.split()  # the user's id, then the files


for mode in (None, "token"):  # Ray's default, then RAY_AUTH_MODE=token; two runs in one process
    if mode:
        os.environ["RAY_AUTH_MODE"] = mode
    print(json.dumps([*map_jobs(probe, [0], workers=1, ray="local"), "RAY_AUTH_TOKEN" in os.environ]))
"""


def test_the_private_ray_clusters_token_is_the_runs_alone():
    """Issue 48 #2: the private cluster of --ray left its token in ~/.ray/auth_token, mode 0644 in a
    0755 folder (with RAY_AUTH_MODE=token too): any user of the machine could read it and join the
    cluster, which runs code as the run's user. As an unprivileged user, during each of two runs in one
    process (a notebook's second run), the token is in no file it can read (the run's home, Ray's
    session folders, every process's command line and environment), nothing is left in the home, and
    nothing of the cluster runs after."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to look as an unprivileged user")
    import tempfile

    home, tmp = Path(tempfile.mkdtemp(prefix="ch37-home-")), Path(tempfile.mkdtemp(prefix="ch37-ray-"))
    try:
        for d in (home, tmp):
            d.chmod(0o755)  # a home and a temp folder others may enter, as on many machines
        env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
        env.update(HOME=str(home), RAY_TMPDIR=str(tmp))
        p = subprocess.run(
            [sys.executable, "-c", RAY_TOKEN_PROBE],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert p.returncode == 0, p.stderr
        # each run: a token, looked for as uid 65534 and found nowhere; not left in the run's environment
        assert [json.loads(line) for line in p.stdout.splitlines()] == [[[64, ["65534"]], False]] * 2
        assert not list(home.iterdir())
        deadline = time.monotonic() + 30
        while left := [c for c in Path("/proc").glob("[0-9]*/cmdline") if str(tmp).encode() in _read(c)]:
            assert time.monotonic() < deadline, f"still running: {left}"
            time.sleep(0.5)
    finally:
        shutil.rmtree(home, ignore_errors=True)
        shutil.rmtree(tmp, ignore_errors=True)


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError:  # the process ended meanwhile
        return b""


def test_source_episodes_that_end_unsolved_are_skipped_in_one_line(src, tmp_path):
    """Issue 46: a source set holding failed episodes (an expert at 13 of 18) was grown from without a
    word, every failed demo a source. An episode whose last next.success is False is skipped, one line
    naming it; nothing is grown from it. A set in which no episode succeeds is refused in one line."""
    bad = shutil.copytree(src, tmp_path / "bad")
    ep = load_arrays(bad, keys=("episode_index",))["episode_index"]
    with_value(bad, "next.success", int(np.flatnonzero(ep == 1)[-1]), 0, False)
    p = augment("--src", bad, "--out", tmp_path / "o", "--workers", "1", *SETTINGS)
    note = "note: 1 of 3 source episodes end unsolved (next.success) and are skipped: episode 1;"
    assert note in p.stdout, p.stdout
    grown = load_arrays(tmp_path / "o", keys=("aug.source_episode",))["aug.source_episode"]
    assert set(np.unique(grown)) <= {0, 2} and len(grown)
    for e in (0, 2):
        with_value(bad, "next.success", int(np.flatnonzero(ep == e)[-1]), 0, False)
    p = augment("--src", bad, "--out", tmp_path / "o2", "--workers", "1", *SETTINGS, check=False)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "none of its 3 episodes ends in success" in err[0], (
        p.stderr
    )
    assert not (tmp_path / "o2").exists()
