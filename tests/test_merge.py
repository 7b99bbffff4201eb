"""lerobot_v3.merge.merge_sets, the engine's one-pass merge, against the merge it replaced: LeRobot's
aggregate_datasets (one data file per shard) followed by write_frame_stats. The same real shards
merged both ways must read back the same through LeRobotDataset: features, every column of every
frame, episode boundaries and per-episode metadata, stats.json. Real MuJoCo shards, real LeRobot."""

import shutil

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import torch

import gen_demos_pusht
from ch37.ownership import read_json
from datagen import engine, plan, shards
from lerobot_v3 import frame_stats, merge
from lerobot_v3.dataset import load_arrays, open_dataset

SETTINGS = plan.Settings("resolve", "own", 4, seed=0, pos_sigma=0.08, yaw_sigma=0.5, shard_size=5)
CONFIG = plan.RunConfig(SETTINGS, "pusht", source={}, engine="", versions={})
LAYOUT = ("data/chunk_index", "data/file_index", "meta/episodes/chunk_index", "meta/episodes/file_index")


@pytest.fixture(scope="module")
def roots(tmp_path_factory):
    """3 sources x 4 attempts in shards of 5, 5 and 2 attempts, made and saved as a run makes them."""
    tmp = tmp_path_factory.mktemp("merge")
    assert gen_demos_pusht.main(["--episodes", "3", "--seed", "0", "--out", str(tmp / "src"), "--quiet"]) == 0
    sources = engine.sources(load_arrays(tmp / "src"))
    cut = plan.plan(sources, SETTINGS.attempts_per_demo, SETTINGS.shard_size)
    for i, jobs in enumerate(cut):
        result = shards.make_shard(i, jobs, {e: sources[e] for e in sorted({e for e, _ in jobs})}, CONFIG)
        shards.save_shard(tmp / "run", i, result)
    return [shards.shard_dir(tmp / "run", i) for i in range(len(cut))]


@pytest.fixture(scope="module")
def lerobots(roots, tmp_path_factory):
    """The shards merged the old way: aggregate_datasets, then stats over all frames."""
    from lerobot.datasets.aggregate import aggregate_datasets

    out = tmp_path_factory.mktemp("lerobot") / "set"
    names = [f"local/shard-{i:05d}" for i in range(len(roots))]
    aggregate_datasets(names, "local/pusht_aug", roots=roots, aggr_root=out, concatenate_data=False)
    frame_stats.write_frame_stats(out)
    return out


def episodes_table(root) -> pd.DataFrame:
    """meta/episodes with its stats/ columns, which LeRobotDataset's meta.episodes leaves out."""
    return pd.concat(
        [pd.read_parquet(f) for f in sorted(root.glob("meta/episodes/*/*.parquet"))], ignore_index=True
    )


def assert_same_set(new, old):
    a, b = open_dataset(new), open_dataset(old)
    assert a.meta.features == b.meta.features and a.fps == b.fps
    assert read_json(new / "meta" / "info.json") == read_json(old / "meta" / "info.json")
    assert a.num_episodes == b.num_episodes and a.num_frames == b.num_frames
    # every column of every frame, as Hugging Face datasets reads them (types from info.json)
    cols_a, cols_b = a.hf_dataset.with_format("numpy")[:], b.hf_dataset.with_format("numpy")[:]
    assert set(cols_a) == set(cols_b) == set(a.hf_dataset.column_names)
    for key in cols_a:
        x, y = np.asarray(cols_a[key]), np.asarray(cols_b[key])
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), key
    # and as a policy reads them: LeRobotDataset[i], the task string included
    for i in range(a.num_frames):
        fa, fb = a[i], b[i]
        assert fa.keys() == fb.keys()
        for key in fa:
            same = torch.equal(fa[key], fb[key]) if torch.is_tensor(fa[key]) else fa[key] == fb[key]
            assert same, (i, key)
    # the episodes: boundaries, lengths, tasks and every per-episode stats column, all but the layout
    ea, eb = episodes_table(new), episodes_table(old)
    assert list(ea.columns) == list(eb.columns)
    for key in (c for c in ea.columns if c not in LAYOUT):
        x, y = ea[key].to_numpy(), eb[key].to_numpy()
        if x.dtype == object:
            x, y = np.stack([np.asarray(v) for v in x]), np.stack([np.asarray(v) for v in y])
        if key.startswith(("stats/index/", "stats/episode_index/")):
            # aggregate shifts each set's own, which depend on where the sets were cut (issue 31);
            # ours are LeRobot's on the final indices (below): the same up to the histogram's bins
            assert x.dtype == y.dtype and np.allclose(x, y, rtol=0, atol=0.05), key
            continue
        assert x.dtype == y.dtype and np.array_equal(x, y), key
    # ... and equal, bit for bit, what LeRobot's compute_episode_stats gives on the final indices
    from lerobot.datasets.compute_stats import compute_episode_stats

    feats = {"index": {"dtype": "int64"}, "episode_index": {"dtype": "int64"}}
    for _, ep in ea.iterrows():
        lo, hi = ep["dataset_from_index"], ep["dataset_to_index"]
        buf = {"index": np.arange(lo, hi), "episode_index": np.full(hi - lo, ep["episode_index"])}
        for name, st in compute_episode_stats(buf, feats).items():
            for k, v in st.items():
                assert np.asarray(ep[f"stats/{name}/{k}"]).tolist() == np.asarray(v, float).tolist(), (
                    name,
                    k,
                )
    assert (ea["episode_index"] == range(len(ea))).all() and ea["dataset_to_index"].iloc[-1] == a.num_frames
    assert a.meta.tasks.equals(b.meta.tasks)
    assert (new / "meta" / "stats.json").read_bytes() == (old / "meta" / "stats.json").read_bytes()
    # each episode is where its layout columns say: the rows of its data file, in its meta file
    for _, ep in ea.iterrows():
        chunk, file = ep["data/chunk_index"], ep["data/file_index"]
        data = pq.read_table(new / f"data/chunk-{chunk:03d}/file-{file:03d}.parquet")
        rows = data.column("episode_index").to_numpy() == ep["episode_index"]
        assert rows.sum() == ep["length"]
        assert (
            data.column("index").to_numpy()[rows]
            == np.arange(*ep[["dataset_from_index", "dataset_to_index"]])
        ).all()
        chunk, file = ep["meta/episodes/chunk_index"], ep["meta/episodes/file_index"]
        meta = pq.read_table(new / f"meta/episodes/chunk-{chunk:03d}/file-{file:03d}.parquet")
        assert ep["episode_index"] in meta.column("episode_index").to_pylist()
    return a, b


def test_merge_reads_back_as_lerobots_merge(roots, lerobots, tmp_path):
    n = merge.merge_sets(roots, tmp_path / "set")
    assert n == sum(read_json(r / "meta" / "info.json")["total_episodes"] for r in roots) == 12
    assert_same_set(tmp_path / "set", lerobots)
    # one file each: the set is far below LeRobot's 100 MB per file
    files = sorted(p.relative_to(tmp_path / "set").as_posix() for p in (tmp_path / "set").rglob("*.parquet"))
    assert files == [
        "data/chunk-000/file-000.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "meta/tasks.parquet",
    ]
    # row groups of DATA_GROUP_ROWS frames: this small set is one
    assert pq.ParquetFile(tmp_path / "set" / files[0]).num_row_groups == 1


def test_small_files_roll_over_files_and_chunks(roots, lerobots, tmp_path, monkeypatch):
    """Files of at most 4,000 B of rows (25 frames; an episode is never split), 2 files a chunk, row
    groups of 5 episodes in meta/episodes: many files and chunks, read back the same, and LeRobot's
    own delete_episodes (which follows data/file_index) gives the same set from both."""
    from lerobot.datasets.dataset_tools import delete_episodes

    monkeypatch.setattr(merge, "EPISODE_ROWS", 5)
    new = tmp_path / "set"
    merge.merge_sets(roots, new, max_bytes=4000, chunks_size=2)
    data = sorted(p.relative_to(new).as_posix() for p in new.glob("data/*/*.parquet"))
    meta = sorted(p.relative_to(new).as_posix() for p in new.glob("meta/episodes/*/*.parquet"))
    assert len(data) >= 6 and "data/chunk-001/file-000.parquet" in data and len(meta) == 3, (data, meta)
    a, b = assert_same_set(new, lerobots)
    drop = [0, 5, 11]
    da = delete_episodes(a, drop, output_dir=tmp_path / "del_new", repo_id="local/del_new")
    db = delete_episodes(b, drop, output_dir=tmp_path / "del_old", repo_id="local/del_old")
    assert da.num_episodes == db.num_episodes == 9 and da.num_frames == db.num_frames
    for key in ("observation.state", "action", "aug.start", "episode_index", "index"):
        x = np.asarray(da.hf_dataset.with_format("numpy")[key])
        assert x.tobytes() == np.asarray(db.hf_dataset.with_format("numpy")[key]).tobytes(), key


def test_a_set_out_of_order_is_refused(roots, tmp_path):
    """merge_sets takes sets as LeRobot writes them; a set whose frames are not 0..N-1 is an error."""
    bad = tmp_path / "bad"
    shutil.copytree(roots[0], bad)
    f = sorted(bad.glob("data/*/*.parquet"))[0]
    t = pq.read_table(f)
    i = t.schema.get_field_index("index")
    pq.write_table(t.set_column(i, t.schema.field(i), pa.array(t.column(i).to_numpy()[::-1])), f)
    with pytest.raises(RuntimeError, match="episodes in order"):
        merge.merge_sets([roots[1], bad], tmp_path / "set")


@pytest.mark.parametrize("collect", [2**14, 16])
def test_frame_stats_are_numpys_whatever_the_tables(collect, monkeypatch):
    """FrameStats against numpy on the whole column: quantiles bit for bit, mean and std within
    1e-12, and the same bits however the frames are cut into tables. Ties, negatives, -0.0, a
    constant and a repeated-integer column; collect=16 forces the bins to be counted again (two
    more passes) before any is read out."""
    monkeypatch.setattr(frame_stats, "COLLECT", collect)
    rng = np.random.default_rng(0)
    n = 150_001
    x = np.concatenate([rng.normal(size=(n // 2, 3)), rng.integers(-3, 4, size=(n - n // 2, 3))])
    x[::7, 1] = -0.0
    x = rng.permutation(x).astype(np.float32)
    table = pa.table(
        {
            "a": pa.FixedSizeListArray.from_arrays(pa.array(x.reshape(-1)), 3),
            "frame": pa.array(np.arange(n) % 61),
            "task": pa.array(np.zeros(n, np.int64)),
        }
    )
    names = ["count", "max", "mean", "min", "q01", "q10", "q50", "q90", "q99", "std"]

    def stats_of(cuts):
        st = frame_stats.FrameStats({k: names for k in table.column_names})
        for lo, hi in zip([0, *cuts], [*cuts, n]):
            st.add(table.slice(lo, hi - lo))
        return st.result(lambda keys: (table.slice(i, 40_000).select(keys) for i in range(0, n, 40_000)))

    got = stats_of([5, 70_000, 70_001])
    assert got == stats_of([]) == stats_of(list(range(1000, n, 1000)))
    for key in table.column_names:
        ref = frame_stats.matrix(table.column(key))  # float64 (n, dims), -0.0 as 0.0
        for name, q in frame_stats.quantile_names(names).items():
            assert np.quantile(ref, q, axis=0).tolist() == got[key][name], (key, name)
        assert got[key]["min"] == ref.min(0).tolist() and got[key]["max"] == ref.max(0).tolist()
        np.testing.assert_allclose(got[key]["mean"], ref.mean(0), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(got[key]["std"], ref.std(0), rtol=1e-12, atol=1e-12)
        assert got[key]["count"] == [n]
