"""LeRobot v3 sets merged in one pass: merge_sets(roots, dest) -> episodes merged.

Each set's data and episodes parquet is read once, its episode and frame indices moved by those
before it, and every file of the merged set written once: data and meta/episodes files of up to
LeRobot's 100 MB (cut by row counts, never where an input set ends, so the data files' bytes do not
depend on how the episodes were cut into sets), tasks, info.json, and stats.json over all frames
(frame_stats, counted as the frames are written). LeRobotDataset reads what this writes as what
LeRobot's aggregate_datasets writes for the same sets (tests/test_merge.py).
"""

from __future__ import annotations

import io
import itertools
import json
from pathlib import Path

import numpy as np

from lerobot_v3.chunks import ChunkRoller, rows_within
from lerobot_v3.dataset import PARQUET, close_quietly, naming
from lerobot_v3.frame_stats import FrameStats, write_frame_stats
from lerobot_v3.hub import hub_offline

# Episode rows per row group of meta/episodes: a fixed count, so the row groups never depend on how
# the episodes were cut into shards (LeRobot's own writer buffers a few episodes per group).
EPISODE_ROWS = 1000
DATA_GROUP_ROWS = 2**16  # frames per row group of a data file
SHIFTED_STATS = ("min", "max", "mean", "q01", "q10", "q50", "q90", "q99")  # a column's stats but std, count


class _Files:
    """A series of parquet files `pattern` (chunk, file) under `root`, each written once, in order.

    A file holds at most `limit` rows, where limit = max_bytes / the Arrow size of a row (every row
    here has the same size: fixed-width columns and lists of fixed length), and a block placed with
    place() (an episode, or a block of episode rows) never straddles two files. After chunks_size
    files the next chunk begins (lerobot_v3.chunks.ChunkRoller, the writer's rule too). Rows go to
    disk in row groups of group_rows rows (the last of a file shorter); LeRobot writes one per
    episode, which at 10^4 episodes means 10^4 writes and as many metadata entries to parse on every
    read. Files and row groups are cut by row counts alone, so where they end never depends on the
    shards."""

    def __init__(self, root: Path, pattern: str, max_bytes: int, chunks_size: int, group_rows: int):
        self.root, self.pattern, self.max_bytes, self.chunks_size = root, pattern, max_bytes, chunks_size
        self.group_rows, self.buffer, self.buffered = group_rows, [], 0  # rows not yet written
        self.roller = self.writer = self.open_at = self.path = None

    def place(self, rows: int, row_bytes: int) -> tuple[int, int]:
        """Where the next block of `rows` rows goes: (chunk, file), starting a new file if needed."""
        if self.roller is None:  # every row here has the first row's size
            self.roller = ChunkRoller(rows_within(self.max_bytes, row_bytes), self.chunks_size)
        return self.roller.place(rows)

    def write(self, table, where: tuple[int, int]) -> None:
        """Append `table` (rows placed in order) to file `where`, the place() they were given."""
        import pyarrow.parquet as pq

        if where != self.open_at:
            self.close()
            self.path = self.root / self.pattern.format(chunk_index=where[0], file_index=where[1])
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with naming(self.path):
                self.writer = pq.ParquetWriter(self.path, table.schema, **PARQUET)
            self.open_at = where
        self.buffer.append(table)
        self.buffered += table.num_rows
        while self.buffered >= self.group_rows:
            self._flush(self.group_rows)

    def _flush(self, rows: int) -> None:
        import pyarrow as pa

        table = pa.concat_tables(self.buffer)
        with naming(self.path):
            self.writer.write_table(table.slice(0, rows))
        rest = table.slice(rows)
        self.buffer, self.buffered = ([rest] if rest.num_rows else []), rest.num_rows

    def close(self) -> None:
        """Write what is buffered and close the file; on any failure the file is closed all the same
        (abort), so no writer is left open to fail again when it is collected."""
        if self.writer is not None:
            try:
                if self.buffered:
                    self._flush(self.buffered)
                with naming(self.path):
                    self.writer.close()
            finally:
                self.abort()

    def abort(self) -> None:
        """Close the open file without writing what is buffered (after an error; a no-op when closed)."""
        writer, self.writer, self.open_at, self.buffer, self.buffered = self.writer, None, None, [], 0
        close_quietly(writer)


def _shifted(table, name: str, by: int, *, fill: bool = False):
    """`table` with `by` added to its column `name` (int64, or a list<double> of per-episode stats,
    added in float64 as LeRobot's aggregate does), or every value set to `by` (fill); type kept."""
    import pyarrow as pa
    import pyarrow.compute as pc

    i = table.schema.get_field_index(name)
    col = table.column(i).combine_chunks()
    if pa.types.is_list(col.type):
        by = pa.scalar(float(by), col.type.value_type)
        values = pc.if_else(True, by, col.values) if fill else pc.add(col.values, by)
        new = pa.ListArray.from_arrays(col.offsets, values, type=col.type)
    else:
        new = pc.add(col, pa.scalar(by, col.type))
    return table.set_column(i, table.schema.field(i), new)


def _read_set(root: Path) -> tuple:
    """A shard's episodes table and data table (all its parquet files, in order), checked to be a fresh
    LeRobot v3 set of one task: episodes 0..n-1, frames 0..N-1 in episode order."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    # ParquetFile.read, not read_table: its dataset path costs far more on a file of many row groups
    # (docs/engine.md, "Figures behind constants")
    eps = pa.concat_tables(pq.ParquetFile(f).read() for f in sorted(root.glob("meta/episodes/*/*.parquet")))
    data = pa.concat_tables(pq.ParquetFile(f).read() for f in sorted(root.glob("data/*/*.parquet")))
    n = eps.num_rows
    ep = eps.column("episode_index").to_numpy()
    lo, hi = eps.column("dataset_from_index").to_numpy(), eps.column("dataset_to_index").to_numpy()
    length = eps.column("length").to_numpy()
    ok = (ep == np.arange(n)).all() and lo[0] == 0 and (lo[1:] == hi[:-1]).all() and (hi - lo == length).all()
    ok = ok and data.num_rows == hi[-1] and (data.column("index").to_numpy() == np.arange(hi[-1])).all()
    ok = ok and (data.column("task_index").to_numpy() == 0).all()
    if not ok:
        raise RuntimeError(f"{root} is not a LeRobot v3 set of one task with episodes in order")
    return eps, data


def _index_stats(eps, n_eps: int, n_frames: int) -> dict:
    """{stats/episode_index/STAT, stats/index/STAT: values, one per episode} of a shard's episodes as
    rows of the merged set, computed from their final indices (episode n_eps + j, frames n_frames +
    dataset_from_index ..) exactly as the shard's writer computes them (lerobot_v3.dataset._episode_stats,
    compute_episode_stats bit for bit). Shifting the shard's own stats instead (aggregate's way) left
    them depending on where the shards were cut: the quantiles are read off a histogram whose bins
    follow the values.

    _episode_stats' float operations, an episode per column: mean and std on all episodes of one
    length at once (the writer's _pairwise_mean_std), min, max and quantiles on all lengths at once
    (_quantiles works column by column, each with its own count); tests/test_engine.py checks them
    equal to _episode_stats."""
    from lerobot_v3.dataset import _episode_stats, _pairwise_mean_std, _quantiles

    lo = eps.column("dataset_from_index").to_numpy() + n_frames
    lengths = eps.column("dataset_to_index").to_numpy() + n_frames - lo
    cols: dict[str, np.ndarray] = {}  # column -> (episodes,) values

    def put(key: str, js, values) -> None:  # float64 as the episodes table stores them, counts int64
        kind = np.int64 if key.endswith("/count") else np.float64
        cols.setdefault(key, np.zeros(len(lengths), kind))[js] = values

    for n in np.unique(lengths):
        js = np.nonzero(lengths == n)[0]
        if n < 2:  # LeRobot's own code for an episode of one frame
            feats = {"episode_index": {"dtype": "int64"}, "index": {"dtype": "int64"}}
            for j in js:
                buf = {"episode_index": np.full(n, n_eps + j), "index": np.arange(lo[j], lo[j] + n)}
                for name, st in _episode_stats(buf, feats).items():
                    for k, v in st.items():
                        put(f"stats/{name}/{k}", [j], v)
            continue
        values = {  # (frames, episodes) in float64, as _episode_stats casts int64
            "episode_index": np.repeat((n_eps + js)[None, :], n, axis=0).astype(np.float64),
            "index": (lo[js][None, :] + np.arange(n)[:, None]).astype(np.float64),
        }
        for name, x in values.items():
            mean, std = _pairwise_mean_std(x)  # the writer's own, an episode per column: (E,) each
            put(f"stats/{name}/mean", js, mean)
            put(f"stats/{name}/std", js, std)
            put(f"stats/{name}/count", js, np.full(len(js), n))
    js = np.flatnonzero(lengths >= 2)  # min, max and quantiles of every length at once: one column each
    if len(js):
        rows = np.arange(lengths[js].max())[:, None]  # a column's rows past its length are not read
        values = {
            "episode_index": np.repeat((n_eps + js)[None, :], len(rows), axis=0).astype(np.float64),
            "index": (lo[js][None, :] + rows).astype(np.float64),
        }
        for name, x in values.items():
            low, high, qs = _quantiles(x, lengths[js])
            st = {"min": low, "max": high} | {key: np.where(p, e0, inside) for key, e0, inside, p in qs}
            for k, v in st.items():
                put(f"stats/{name}/{k}", js, v)
    return {k: v.reshape(-1, 1).tolist() for k, v in cols.items()}  # each a list of one, as LeRobot's


def _moved_episodes(eps, n_eps: int, n_frames: int, places: list[tuple[int, int]]):
    """A shard's episodes table as rows of the merged set: episode and frame indices shifted by the
    n_eps episodes and n_frames frames before it, their per-episode stats computed from the final
    indices (_index_stats), so no byte depends on --shard_size; data/chunk_index and data/file_index
    set to each episode's place."""
    import pyarrow as pa

    shifts = {"episode_index": n_eps, "dataset_from_index": n_frames, "dataset_to_index": n_frames}
    for name, values in _index_stats(eps, n_eps, n_frames).items():
        if name in eps.column_names:
            i = eps.schema.get_field_index(name)
            eps = eps.set_column(i, eps.schema.field(i), pa.array(values, eps.schema.field(i).type))
    for name, by in shifts.items():
        if name in eps.column_names:
            eps = _shifted(eps, name, by)
    for stat in ("std", *SHIFTED_STATS):
        # aggregate recomputes these from the episode's task ids (the one task: 0), where the
        # shard's writer estimated quantiles from a histogram (q01 = 4e-16, not 0)
        if f"stats/task_index/{stat}" in eps.column_names:
            eps = _shifted(eps, f"stats/task_index/{stat}", 0, fill=True)
    for j, name in enumerate(("data/chunk_index", "data/file_index")):
        i = eps.schema.get_field_index(name)
        eps = eps.set_column(i, eps.schema.field(i), pa.array([p[j] for p in places], pa.int64()))
    return eps


def merge_sets(roots: list[Path], dest: Path, *, max_bytes: int | None = None, chunks_size=None) -> int:
    """Merge the LeRobot v3 sets `roots` (each of one task, no videos) into the new set `dest`, in one
    pass: each set's data and episodes parquet is read once, its episode and frame indices (and the
    episodes table's per-episode index stats) moved by the episodes and frames before it, and written
    into data/chunk-XXX/file-YYY.parquet files of up to the first set's data_files_size_in_mb
    (`max_bytes` to override; row groups of DATA_GROUP_ROWS frames) and meta/episodes files the
    same way (row groups of EPISODE_ROWS episodes); tasks, info.json and stats.json (exact over all
    frames, write_frame_stats) once each. No file is written twice. Returns the episodes merged.

    What LeRobotDataset reads is what LeRobot's aggregate_datasets + write_frame_stats give for the
    same sets (tests/test_merge.py); only the file layout differs, and it depends on the frames alone."""
    hub_offline()  # before LeRobot's first import here
    import pandas as pd
    import pyarrow as pa
    from lerobot.datasets.io_utils import load_info, write_info
    from lerobot.datasets.utils import DEFAULT_DATA_PATH, DEFAULT_EPISODES_PATH, DEFAULT_TASKS_PATH

    dest = Path(dest)
    info = load_info(roots[0])
    if any(ft["dtype"] in ("video", "image") for ft in info.features.values()):
        raise RuntimeError("merge_sets merges sets without images or videos")
    max_bytes = max_bytes or info.data_files_size_in_mb * 2**20  # LeRobot's MB are MiB
    chunks_size = chunks_size or info.chunks_size
    template = _stats_template(roots)
    stats = FrameStats({k: sorted(st) for k, st in template.items() if k in info.features})
    data_out = _Files(dest, DEFAULT_DATA_PATH, max_bytes, chunks_size, group_rows=DATA_GROUP_ROWS)
    meta_out = _Files(dest, DEFAULT_EPISODES_PATH, max_bytes, chunks_size, group_rows=EPISODE_ROWS)
    n_eps = n_frames = 0
    task, pending = None, []  # episode rows not yet written (fewer than EPISODE_ROWS)

    def flush(rows: int) -> None:  # write the first `rows` pending episode rows as one row group
        nonlocal pending
        table = pa.concat_tables(pending)
        block, rest = table.slice(0, rows), table.slice(rows)
        chunk, file = meta_out.place(rows, block.slice(0, 1).nbytes)
        for name, value in (("meta/episodes/chunk_index", chunk), ("meta/episodes/file_index", file)):
            i = block.schema.get_field_index(name)
            block = block.set_column(i, block.schema.field(i), pa.array([value] * rows, pa.int64()))
        meta_out.write(block, (chunk, file))
        pending = [rest] if rest.num_rows else []

    try:
        for root in roots:
            eps, data = _read_set(root)
            tasks = eps.column("tasks").to_pylist()
            task = task if task is not None else tasks[0]
            if any(t != task for t in tasks):
                raise RuntimeError(f"{root}: tasks {tasks[0]} differ from {task}; merge_sets takes one task")
            data = _shifted(_shifted(data, "episode_index", n_eps), "index", n_frames)
            lengths = eps.column("dataset_to_index").to_numpy() - eps.column("dataset_from_index").to_numpy()
            row_bytes = data.slice(0, 1).nbytes
            places = [data_out.place(int(n), row_bytes) for n in lengths]  # (chunk, file) per episode
            start = 0
            for where, run in itertools.groupby(zip(places, lengths, strict=True), key=lambda p: p[0]):
                rows = int(sum(n for _, n in run))  # consecutive episodes bound for one file: one block
                data_out.write(data.slice(start, rows), where)
                start += rows
            stats.add(data)  # counted as it is written; the quantiles read back only a few bins
            pending.append(_moved_episodes(eps, n_eps, n_frames, places))
            n_eps, n_frames = n_eps + eps.num_rows, n_frames + data.num_rows
            while sum(t.num_rows for t in pending) >= EPISODE_ROWS:
                flush(EPISODE_ROWS)
        if pending:
            flush(sum(t.num_rows for t in pending))
        data_out.close()
        meta_out.close()
    finally:
        data_out.abort()  # after an error: the open files closed without their buffers (else no-ops)
        meta_out.abort()
    tasks = [task[0]] if task else []
    table = pd.DataFrame({"task_index": range(len(tasks))}, index=pd.Index(tasks, name="task"))
    buf = io.BytesIO()  # LeRobot's write_tasks (to_parquet) into memory: its writer cannot be left open
    table.to_parquet(buf)
    (dest / DEFAULT_TASKS_PATH).parent.mkdir(parents=True, exist_ok=True)
    (dest / DEFAULT_TASKS_PATH).write_bytes(buf.getvalue())
    info.total_episodes, info.total_frames, info.total_tasks = n_eps, n_frames, len(tasks)
    info.splits = {"train": f"0:{n_eps}"}
    write_info(info, dest)
    write_frame_stats(dest, template, stats)
    return n_eps


def _stats_template(roots: list[Path]) -> dict:
    """The stats.json entries write_frame_stats fills: the first set's keys and stat names; a key that
    is no data feature (none in the engine's sets) gets LeRobot's aggregate of every set's stats."""
    hub_offline()
    from lerobot.datasets.io_utils import load_info

    first = json.loads((roots[0] / "meta" / "stats.json").read_text())
    other = [k for k in first if k not in load_info(roots[0]).features]
    if not other:
        return first
    from lerobot.datasets.compute_stats import aggregate_stats
    from lerobot.datasets.io_utils import load_stats
    from lerobot.datasets.utils import serialize_dict

    agg = aggregate_stats([{k: v for k, v in load_stats(r).items() if k in other} for r in roots])
    return first | serialize_dict(agg)
