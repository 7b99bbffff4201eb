"""lerobot_v3.dataset.write_dataset's one-pass writer against LeRobot's own per-frame writer (issue 19).

The same episodes go through write_dataset and through LeRobotDataset.create / add_frame /
save_episode / finalize; both sets are read back with LeRobotDataset and compared feature by
feature, frame by frame, episode by episode. lerobot-edit-dataset must work on our output.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

import gen_demos_aloha
import gen_demos_pusht
from datagen import PUSHT, engine, write_dataset
from datagen.tasks.pusht import START_NAMES
from lerobot_v3 import dataset as lerobot_io

PROVENANCE = engine.provenance(PUSHT)

TASK = "push the T"
EDIT = Path(sys.executable).parent / "lerobot-edit-dataset"


def synthetic(names, action_dim, lengths, seed, extra=False):
    """Episodes of random float32 arrays, one per length; next.success on the last frame only."""
    rng = np.random.default_rng(seed)
    eps = []
    for e, n in enumerate(lengths):
        ep = {
            "observation.state": rng.standard_normal((n, len(names))).astype(np.float32),
            "action": rng.standard_normal((n, action_dim)).astype(np.float32),
            "next.success": (np.arange(n) == n - 1)[:, None],
        }
        if extra:
            start = rng.random((n, len(START_NAMES)), dtype=np.float32)
            ep |= {"aug.source_episode": np.full((n, 1), e % 2), "aug.start": start}
        eps.append(ep)
    return eps


def pusht_case():
    m = gen_demos_pusht.PUSHT.spec
    feats = lerobot_io.features(m.state_names, m.action_names, PROVENANCE, env_state_names=m.env_state_names)
    return feats, synthetic(m.state_names, len(m.action_names), [7, 2, 15, 4, 30, 3], 0, extra=True)


def aloha_case():
    m = gen_demos_aloha.ALOHA.spec
    feats = lerobot_io.features(m.state_names, m.action_names, env_state_names=m.env_state_names)
    return feats, synthetic(m.state_names, len(m.action_names), [12, 5, 9], 1)


def write_ours(root, feats, eps):
    write_dataset(
        root, repo_id="local/ours", fps=10, robot_type="r", task=TASK, feats=feats, episodes=eps, stamp={}
    )


def write_lerobots(root, feats, eps):
    """LeRobot's own recording path, frame by frame, with ENV_STATE_KEY filled as write_dataset does."""
    ds = lerobot_io._lerobot_dataset_class().create(
        "local/theirs", fps=10, features=feats, root=root, robot_type="r", use_videos=False
    )
    with lerobot_io._embed_only_images():  # as the project's own per-frame writes run it (same bytes)
        for ep in lerobot_io._with_env_state(eps, feats):
            for t in range(len(ep["action"])):
                ds.add_frame({k: ep[k][t] for k in feats} | {"task": TASK})
            ds.save_episode()
    ds.finalize()


def read(root):
    ds = lerobot_io.open_dataset(root)
    frames = ds.hf_dataset.with_format("numpy")[:]
    episodes = ds.meta.episodes  # without the stats columns (LeRobot's load_episodes)
    ep_table = pq.read_table(Path(root) / "meta/episodes/chunk-000/file-000.parquet").to_pydict()
    stats = json.loads((Path(root) / "meta/stats.json").read_text())
    return ds, frames, episodes, ep_table, stats


def assert_same_sets(ours: Path, theirs: Path):
    a, fa, ea, ta, sa = read(ours)
    b, fb, eb, tb, sb = read(theirs)
    assert a.meta.features == b.meta.features
    assert (a.meta.total_frames, a.meta.total_episodes) == (b.meta.total_frames, b.meta.total_episodes)
    assert a.meta.info.to_dict() == b.meta.info.to_dict()  # fps, robot_type, splits, paths, sizes
    assert list(a.meta.tasks.index) == list(b.meta.tasks.index) == [TASK]
    assert list(a.meta.tasks.task_index) == list(b.meta.tasks.task_index) == [0]
    # every column of every frame, and the same Arrow schema (types, order, "huggingface" metadata)
    data = "data/chunk-000/file-000.parquet"
    assert pq.read_schema(ours / data) == pq.read_schema(theirs / data)
    assert pq.read_schema(ours / data).metadata == pq.read_schema(theirs / data).metadata
    assert list(fa) == list(fb)
    for k in fb:
        assert fa[k].dtype == fb[k].dtype and fa[k].shape == fb[k].shape, k
        np.testing.assert_array_equal(fa[k], fb[k], err_msg=k)
    # episode boundaries and the rest of the episodes table, column for column, in LeRobot's order
    assert ea.column_names == eb.column_names
    for col in ("episode_index", "tasks", "length", "dataset_from_index", "dataset_to_index"):
        assert ea[col] == eb[col], col
    ep_file = "meta/episodes/chunk-000/file-000.parquet"
    assert pq.read_schema(ours / ep_file) == pq.read_schema(theirs / ep_file)
    assert list(ta) == list(tb)
    for col in tb:
        if col.startswith("stats/"):
            np.testing.assert_allclose(
                np.array(ta[col], float), np.array(tb[col], float), rtol=0, err_msg=col
            )
        else:
            assert ta[col] == tb[col], col
    # stats.json: same keys (sorted as written) and values
    assert list(sa) == sorted(sb)
    for key in sb:
        assert sorted(sa[key]) == sorted(sb[key])
        for st in sb[key]:
            np.testing.assert_allclose(sa[key][st], sb[key][st], rtol=1e-9, err_msg=f"{key}/{st}")


@pytest.mark.parametrize("case", [pusht_case, aloha_case])
def test_one_pass_writer_reads_back_as_lerobots_own(tmp_path, case):
    feats, eps = case()
    write_ours(tmp_path / "ours", feats, eps)
    write_lerobots(tmp_path / "theirs", feats, eps)
    assert_same_sets(tmp_path / "ours", tmp_path / "theirs")
    # the check can fail: one frame dropped from an episode is seen
    eps[1] = {k: v[:-1] for k, v in eps[1].items()}
    write_ours(tmp_path / "short", feats, eps)
    with pytest.raises(AssertionError):
        assert_same_sets(tmp_path / "short", tmp_path / "theirs")


def test_one_pass_writer_is_deterministic_and_empty_as_before(tmp_path):
    feats, eps = pusht_case()
    write_ours(tmp_path / "a", feats, eps)
    write_ours(tmp_path / "b", feats, iter(eps))  # a generator, as datagen.demos passes
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*") if p.is_file())
    for f in files:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    write_ours(tmp_path / "empty", feats, [])
    write_lerobots(tmp_path / "empty_theirs", feats, [])
    assert sorted(p.name for p in (tmp_path / "empty").rglob("*") if p.is_file()) == [
        "info.json",
        "scale_data_stamp.json",
    ]
    info = "meta/info.json"
    assert (tmp_path / "empty" / info).read_text() == (tmp_path / "empty_theirs" / info).read_text()


def edit(*args):
    proc = subprocess.run([str(EDIT), *args], capture_output=True, text=True, env=os.environ, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def test_lerobot_edit_dataset_works_on_our_output(tmp_path):
    feats, eps = pusht_case()
    root = tmp_path / "ours"
    write_ours(root, feats, eps)
    out = edit("--operation.type", "info", "--repo_id", "local/ours", "--root", str(root))
    assert "local/ours" in out
    edit(
        "--operation.type",
        "delete_episodes",
        "--operation.episode_indices",
        "[1, 3]",
        "--repo_id",
        "local/ours",
        "--root",
        str(root),
        "--new_repo_id",
        "local/fewer",
        "--new_root",
        str(tmp_path / "fewer"),
    )
    fewer = lerobot_io.open_dataset(tmp_path / "fewer")
    assert fewer.meta.total_episodes == 4 and fewer.meta.total_frames == 7 + 15 + 30 + 3
    kept = fewer.hf_dataset.with_format("numpy")[:]
    np.testing.assert_array_equal(kept["action"][:7], eps[0]["action"])
    edit(
        "--operation.type",
        "split",
        "--operation.splits",
        '{"train": [0, 1, 2, 3], "val": [4, 5]}',
        "--repo_id",
        "local/ours",
        "--root",
        str(root),
        "--new_root",
        str(tmp_path / "split"),
    )
    parts = sorted(p.parent.parent for p in (tmp_path / "split").rglob("meta/info.json"))
    sizes = sorted(lerobot_io.open_dataset(p).meta.total_frames for p in parts)
    assert sizes == sorted([7 + 2 + 15 + 4, 30 + 3])


def test_episode_stats_equal_lerobots_bit_for_bit():
    """_episode_stats against LeRobot's compute_episode_stats on episodes shaped like a set's, with
    the cases its histogram quantiles treat apart: constant columns, ties, 1-3 frames, bool, int,
    huge and tiny values; bit for bit, dtypes and shapes included. The writer's batched
    _episodes_stats over all of them at once (several of one length, stacked side by side) too."""
    from lerobot.datasets.compute_stats import compute_episode_stats

    feats, _ = pusht_case()
    feats = feats | {k: {"dtype": "int64"} for k in ("frame_index", "episode_index", "index", "task_index")}
    feats["timestamp"] = {"dtype": "float32"}
    feats["next.reward"] = {"dtype": "float32"}  # one column of floats: summed pairwise, not row by row
    rng = np.random.default_rng(7)
    bufs = []
    for e, n in enumerate((1, 2, 3, 7, 9, 30, 99, 100, 101, 400, 30, 100, 1, 30)):
        x = rng.standard_normal((n, 10)).astype(np.float32)
        x[:, 1] = 0.25  # constant: float32 keeps min - 1e-10 == min, numpy's zero-step linspace
        x[:, 2] = np.round(x[:, 2], 1)  # ties
        x[:, 3] *= 1e7
        x[:, 4] = 1e-30
        buf = {
            "observation.state": x,
            "observation.environment_state": x[:, 2:5].copy(),
            "action": rng.standard_normal((n, 2)).astype(np.float32),
            "next.success": np.arange(n) == n - 1,
            "next.reward": rng.standard_normal(n).astype(np.float32),
            "aug.source_episode": np.full(n, e % 3),
            "aug.start": rng.random((n, len(START_NAMES)), dtype=np.float32),
            "timestamp": np.arange(n) / 10,
            "frame_index": np.arange(n),
            # large indices, as deep in a 10^5-episode merge: a constant column whose bins are finer
            # than its float spacing (the edges found by bisection, issue 31)
            "episode_index": np.full(n, 99_990 + e),
            "index": np.arange(3_200_000 + 1000 * e, 3_200_000 + 1000 * e + n),
            "task_index": np.zeros(n, dtype=np.int64),
        }
        bufs.append(buf)
    batched = lerobot_io._episodes_stats(bufs, feats)
    for buf, together in zip(bufs, batched, strict=True):
        n, theirs = len(buf["action"]), compute_episode_stats(buf, feats)
        for ours in (lerobot_io._episode_stats(buf, feats), together):
            assert list(ours) == list(theirs)
            for key in theirs:
                assert list(ours[key]) == list(theirs[key])
                for st in theirs[key]:
                    a, b = ours[key][st], theirs[key][st]
                    assert a.dtype == b.dtype and a.shape == b.shape, (key, st, n)
                    np.testing.assert_array_equal(a, b, err_msg=f"{key} {st} {n} frames")


def test_one_pass_writer_splits_files_as_lerobot_names_them(tmp_path):
    """Past data_files_size_in_mb (1 MB here, ~10,800 frames) data and episodes tables go on in
    chunk-000/file-001, ..., and LeRobot reads the set as the same frames and episodes."""
    feats, _ = pusht_case()
    m = gen_demos_pusht.PUSHT.spec
    eps = synthetic(m.state_names, len(m.action_names), [20 + e % 5 for e in range(600)], 2, extra=True)
    eps = list(lerobot_io._with_env_state(eps, feats))
    split = tmp_path / "split"
    lerobot_io._write_direct(split, fps=10, robot_type="r", task=TASK, feats=feats, episodes=eps, file_mb=1)
    write_ours(tmp_path / "one", feats, eps)
    assert [p.name for p in sorted((split / "data/chunk-000").iterdir())] == [
        "file-000.parquet",
        "file-001.parquet",
    ]
    assert len(list((split / "meta/episodes/chunk-000").iterdir())) == 2
    a, b = lerobot_io.open_dataset(split), lerobot_io.open_dataset(tmp_path / "one")
    fa, fb = a.hf_dataset.with_format("numpy")[:], b.hf_dataset.with_format("numpy")[:]
    for k in fb:
        np.testing.assert_array_equal(fa[k], fb[k], err_msg=k)
    for col in ("episode_index", "length", "dataset_from_index", "dataset_to_index"):
        assert a.meta.episodes[col] == b.meta.episodes[col], col
    for e in (0, 299, 599):  # each episode's rows are in the file its episodes row names
        rows = pq.read_table(split / a.meta.get_data_file_path(e)).column("episode_index").to_numpy()
        assert (rows == e).sum() == a.meta.episodes[e]["length"]
    assert a[len(a) - 1]["index"] == len(b) - 1


def test_one_chunk_rule_for_every_file_of_the_layout():
    """lerobot_v3.chunks: a block never straddles files, a file takes rows up to its limit, the next
    chunk starts after chunks_size files; the writer's byte rule (a new file once rows x size >= the
    limit) and the merge's (rows within the limit) as row counts."""
    from lerobot_v3.chunks import ChunkRoller, rows_below, rows_within

    roll = ChunkRoller(3, chunks_size=2)
    got = [roll.place(n) for n in (2, 1, 1, 5, 1, 3)]
    assert got == [(0, 0), (0, 0), (0, 1), (1, 0), (1, 1), (2, 0)]
    assert rows_below(100, 10) == 9 and rows_below(101, 10) == 10 and rows_below(5, 10) == 0
    assert rows_within(100, 10) == 10 and rows_within(109, 10) == 10 and rows_within(5, 10) == 1


def test_lerobots_embed_images_is_changed_only_inside_our_write():
    """The skip of embed_images for image-less tables holds inside the project's per-frame writes only:
    nothing else in the process sees lerobot's function changed."""
    from lerobot.datasets import dataset_writer

    before = dataset_writer.embed_images
    lerobot_io._lerobot_dataset_class()  # once patched the whole process
    assert dataset_writer.embed_images is before
    with lerobot_io._embed_only_images():
        assert dataset_writer.embed_images is not before
    assert dataset_writer.embed_images is before
