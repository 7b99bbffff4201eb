"""LeRobot v3 read and write for the chapter's demo sets: features, write_dataset, load_arrays.

Everything here is a pure function of its arguments: no clock, no global RNG. The format only:
where a set is published and who owns it is the caller's (datagen.write_dataset, ch37.ownership).
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from ch37.errors import DataError
from lerobot_v3.chunks import ChunkRoller, rows_below, rows_within
from lerobot_v3.hub import hub_offline

# torchcodec needs system FFmpeg libraries and prints long tracebacks when they are missing;
# pyav ships its own FFmpeg, so every dataset here is read and written through pyav.
VIDEO_BACKEND = "pyav"
IMAGE_KEY = "observation.images.top"
IMAGE_SIZE = 96  # px, the optional top-down video is IMAGE_SIZE x IMAGE_SIZE RGB
# LeRobot's policies (diffusion, ACT) need an image or this key: the object and task state. The
# writer fills it from observation.state's columns of the same names (each env's ENV_STATE_NAMES);
# nothing in the chapter reads it, so a set without it is read as before.
ENV_STATE_KEY = "observation.environment_state"
# Parquet settings of every file we write. LeRobot writes snappy with dictionary encoding; on this
# chapter's float columns a dictionary never pays (measured: docs/engine.md, "Figures behind constants").
PARQUET = dict(compression="snappy", use_dictionary=False)


def check_hf_cache() -> None:
    """DataError (one line) unless Hugging Face datasets can write its cache: every read of a set goes
    through it, and without this check a cache problem reads as a damaged data set. Offline first
    (hub_offline): this is the first LeRobot step of every read and write."""
    hub_offline()
    import datasets

    _probe_cache(Path(datasets.config.HF_DATASETS_CACHE))


@functools.cache
def _probe_cache(cache: Path) -> None:  # once per folder and process: every read and write calls it
    try:
        cache.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=cache, prefix=".probe-"):
            pass
    except OSError as e:
        raise DataError(
            f"the Hugging Face cache {cache} cannot be written ({e.strerror}); set HF_HOME to a folder "
            "you can write to (your data sets are fine)"
        ) from None


def _lerobot_dataset_class():
    """LeRobotDataset, with Hugging Face datasets' per-episode "Map" bars silenced (our own bar is enough)."""
    check_hf_cache()  # offline before LeRobot is imported (hub_offline)
    import datasets
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    datasets.disable_progress_bars()
    return LeRobotDataset


@contextlib.contextmanager
def _embed_only_images():
    """lerobot 0.6 runs embed_images on every saved episode, a row-by-row map that costs ~0.1 s per
    episode even when the table holds no image column, where it returns the table unchanged. Inside
    this block (our writes through LeRobot's per-frame path) it is skipped exactly then; any table with
    an image column goes through lerobot's own code. Put back on leaving: nothing else in the process
    sees the change."""
    hub_offline()
    import datasets
    from lerobot.datasets import dataset_writer

    embed = dataset_writer.embed_images

    def embed_images(ds):
        if any(isinstance(f, datasets.Image) for f in ds.features.values()):
            return embed(ds)
        return ds

    dataset_writer.embed_images = embed_images
    try:
        yield
    finally:
        dataset_writer.embed_images = embed


def features(
    state_names, action_names, extra: dict | None = None, video: bool = False, env_state_names=()
) -> dict:
    """LeRobot features of a demo set; env_state_names (a subset of state_names) adds ENV_STATE_KEY."""
    feats = {
        "observation.state": {"dtype": "float32", "shape": (len(state_names),), "names": list(state_names)}
    }
    if env_state_names:
        env_names = list(env_state_names)
        feats[ENV_STATE_KEY] = {"dtype": "float32", "shape": (len(env_names),), "names": env_names}
    feats |= {
        "action": {"dtype": "float32", "shape": (len(action_names),), "names": list(action_names)},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    }
    if video:
        feats[IMAGE_KEY] = {
            "dtype": "video",
            "shape": (IMAGE_SIZE, IMAGE_SIZE, 3),
            "names": ["height", "width", "channels"],
        }
    feats.update(extra or {})
    return feats


def columns(names, wanted) -> list[int]:
    """Indices of `wanted` in `names`: where each environment-state number sits in the state."""
    names = list(names)
    missing = [n for n in wanted if n not in names]
    if missing:
        raise ValueError(f"{missing} are not state names ({names})")
    return [names.index(n) for n in wanted]


@contextlib.contextmanager
def _fast_fingerprints():
    """lerobot 0.6 builds a datasets.Dataset per saved episode only to get its Arrow table, and
    datasets fingerprints every new Dataset by dill-hashing all its rows (~10 ms per episode, a
    third of the write). Nothing reads that fingerprint, so while we write, new in-memory Datasets
    get a random one, which is what datasets itself falls back to when hashing fails."""
    hub_offline()
    from datasets import arrow_dataset, fingerprint

    saved = arrow_dataset.generate_fingerprint
    arrow_dataset.generate_fingerprint = lambda dataset: fingerprint.generate_random_fingerprint()
    try:
        yield
    finally:
        arrow_dataset.generate_fingerprint = saved


def write_set(
    root: Path,
    *,
    repo_id: str,
    fps: int,
    robot_type: str,
    task: str,
    feats: dict,
    episodes,
    per_frame=False,
    obs_names=None,
) -> None:
    """Write `episodes` (an iterable of dicts of per-frame arrays keyed like `feats`) as a LeRobot v3
    set in the new folder `root` (it must not exist). Whole-or-absent publication, stamps and the
    folder's ownership are the caller's (datagen.write_dataset builds it beside its target).

    ENV_STATE_KEY, when `feats` has it and an episode does not, is taken from the episode's
    observation.state columns of the same names (see features). obs_names: the names of an episode's
    observation.state columns when they are a task's whole observation (state and environment state,
    datagen.task.EnvSpec.observation_names); the set's observation.state then holds feats' state names of
    them.

    A set of numeric features of shape (d,) (every set the chapter writes) is written in one pass
    from the arrays (_write_direct): the same files, columns, Arrow types and metadata LeRobot's
    per-frame path (LeRobotDataset.create / add_frame / save_episode / finalize) writes, read back
    equal frame by frame (tests/test_writer.py), without its per-frame and per-episode costs.
    A set with a video (or any other) feature goes through LeRobot's own path (_write_lerobot):
    encoding mp4 is LeRobot's job. per_frame: every set through LeRobot's path (a benchmark's baseline).
    """
    root = Path(root)
    episodes = _with_env_state(episodes, feats, obs_names)
    if not per_frame and all(f["dtype"] in _DIRECT_DTYPES and len(f["shape"]) == 1 for f in feats.values()):
        _write_direct(root, fps=fps, robot_type=robot_type, task=task, feats=feats, episodes=episodes)
        return  # its stats.json is written sorted
    _write_lerobot(
        root, repo_id=repo_id, fps=fps, robot_type=robot_type, task=task, feats=feats, episodes=episodes
    )
    stats = root / "meta" / "stats.json"
    if stats.exists():
        write_sorted_stats(json.loads(stats.read_text()), root)


def write_sorted_stats(stats: dict, root: Path) -> None:
    """LeRobot's write_stats with sorted keys: LeRobot orders them by string hash; sorted, equal sets
    are equal bytes."""
    hub_offline()
    from lerobot.datasets.utils import serialize_dict

    text = json.dumps(serialize_dict(stats), indent=4, sort_keys=True, ensure_ascii=False)
    (root / "meta" / "stats.json").write_text(text)


# Feature dtypes _write_direct writes as plain Arrow columns (a scalar for shape (1,), else a
# fixed-size list); images and videos go through LeRobot's own path.
_DIRECT_DTYPES = {"bool", "float32", "float64", "int8", "int16", "int32", "int64", "uint8"}


def _with_env_state(episodes, feats: dict, obs_names=None):
    """`episodes`, each with ENV_STATE_KEY filled from its observation.state columns when missing, and,
    given obs_names (those columns' names), its observation.state cut to feats' state names."""
    state_names = feats["observation.state"]["names"]
    obs_names = state_names if obs_names is None else list(obs_names)
    keep = None if list(obs_names) == list(state_names) else columns(obs_names, state_names)
    cols = columns(obs_names, feats[ENV_STATE_KEY]["names"]) if ENV_STATE_KEY in feats else None
    for ep in episodes:
        obs = ep["observation.state"]
        if cols is not None and ENV_STATE_KEY not in ep:  # (T, 10) -> (T, len(cols))
            ep = ep | {ENV_STATE_KEY: np.ascontiguousarray(obs[:, cols])}
        if keep is not None:
            ep = ep | {"observation.state": np.ascontiguousarray(obs[:, keep])}
        yield ep


def observation(arrays: dict, obs_names, state_names, env_state_names=()) -> np.ndarray:
    """(N, len(obs_names)) float32: a set's observation.state and ENV_STATE_KEY columns (load_arrays'
    arrays) put together in the order of a task's observation names (the inverse of write_set's cut)."""
    if list(obs_names) == list(state_names):
        return arrays["observation.state"]
    names = list(state_names) + list(env_state_names)
    both = np.concatenate([arrays["observation.state"], arrays[ENV_STATE_KEY]], axis=1)
    return np.ascontiguousarray(both[:, columns(names, obs_names)], np.float32)


def _write_lerobot(tmp: Path, *, repo_id, fps, robot_type, task, feats, episodes) -> None:
    """LeRobot's per-frame path: kept for sets with a video feature (LeRobot encodes the mp4)."""
    ds = _lerobot_dataset_class().create(
        repo_id,
        fps=fps,
        features=feats,
        root=tmp,
        robot_type=robot_type,
        use_videos=any(f["dtype"] == "video" for f in feats.values()),
        video_backend=VIDEO_BACKEND,
    )
    with _fast_fingerprints(), _embed_only_images():
        for ep in episodes:
            for t in range(len(ep["action"])):
                ds.add_frame({k: ep[k][t] for k in feats} | {"task": task})
            ds.save_episode()
    ds.finalize()


def _quantiles(x: np.ndarray, counts: np.ndarray | None = None):
    """Min, max and LeRobot's histogram quantiles of each column of x (T >= 2, D), bit for bit.

    LeRobot's RunningQuantileStats, fed one batch, bins each column into 5,000 bins between
    min - 1e-10 and max + 1e-10 (np.linspace) and reads a quantile q off the cumulated histogram:
    the first bin j whose cumulated count reaches q*T, interpolated inside it. The cumulated count
    of bin j is the number of values below edge j+1, so that bin is where the ceil(q*T)-th smallest
    value falls: the same bin and the same float operations from one sort, without the 5,000-bin
    histograms and cumsums per column and quantile. Returns lo, hi and per quantile (key, the bin's
    lower edge, the interpolated value, where LeRobot returns the edge itself), each (D,).
    counts (D,) >= 2: column d holds counts[d] values, its first rows (the rest is padding, never
    read), so episodes of different lengths share one call; None: every column holds T.
    """
    hub_offline()
    from lerobot.datasets.compute_stats import DEFAULT_QUANTILES

    rows, dims = x.shape
    if counts is None or (counts == rows).all():
        n = np.full(dims, rows)
        lo, hi = np.min(x, axis=0), np.max(x, axis=0)
        srt = np.sort(x, axis=0)
    else:  # padding as +inf sorts after every value and is below no edge; min and max skip it
        n, pad = counts, np.arange(rows)[:, None] >= counts[None, :]  # (T, D)
        padded = np.where(pad, np.inf, x)
        srt = np.sort(padded, axis=0)
        lo, hi = np.min(padded, axis=0), np.max(np.where(pad, -np.inf, x), axis=0)
    # Edge k of each dimension's np.linspace(lo - 1e-10, hi + 1e-10, 5001), as numpy computes it
    bins = 5000
    start, stop = lo - 1e-10, hi + 1e-10
    delta = np.subtract(stop, start, dtype=start.dtype)
    step = delta / bins
    flat = step == 0  # numpy's other formula for a zero step (a constant column in float32)

    def edge(k):  # k: (Q, D, W) bin numbers -> (Q, D, W) edges in the column's dtype
        kk = k.astype(start.dtype)
        s0, st, de = start[:, None], step[:, None], delta[:, None]
        return np.where(
            k == bins, stop[:, None], np.where(flat[:, None], (kk / bins) * de + s0, kk * st + s0)
        )

    targets = np.array(DEFAULT_QUANTILES)[:, None] * n  # (Q, D), LeRobot's q * count
    # (Q, D): the value where each count is reached
    v = np.take_along_axis(srt, np.ceil(targets).astype(np.int64) - 1, axis=0)
    # Its bin: how many of edges 1..4999 are <= v (edges rise with k). Counted in a window of 9
    # edges around a float64 guess; exact when the window's ends bracket v, else over the whole row.
    with np.errstate(all="ignore"):
        guess = np.nan_to_num((v - start.astype(np.float64)) / step.astype(np.float64))
    first = np.clip(np.floor(np.clip(guess, -16, bins + 16)).astype(np.int64) - 4, 1, bins - 1)
    win = first[..., None] + np.arange(9)  # (Q, D, 9)
    ew = edge(np.minimum(win, bins - 1))
    idx = first - 1 + ((ew <= v[..., None]) & (win <= bins - 1)).sum(axis=-1)
    ok = ((first == 1) | (ew[..., 0] <= v)) & ((first + 8 >= bins - 1) | (ew[..., 8] > v))
    if not ok.all():
        # Edges rise with k (a rounded k * step + start), so the count of edges 1..4999 <= v is the
        # first k whose edge is not <= v, less one: found by bisection for the pairs the window
        # missed (a near-constant column, whose bins are finer than its values' float spacing, so
        # many edges round to one value), ~13 edges a pair where the whole row took 4,999.
        qi, d = np.nonzero(~ok)
        vv, lo_k, hi_k = v[qi, d], np.ones(len(qi), np.int64), np.full(len(qi), bins, np.int64)
        while (lo_k < hi_k).any():
            mid = (lo_k + hi_k) // 2  # < bins: edge(mid) is one of edges 1..4999
            kk = mid.astype(start.dtype)
            e = np.where(flat[d], (kk / bins) * delta[d] + start[d], kk * step[d] + start[d])
            above = ~(e <= vv)  # not `e > vv`: a NaN counts no edge, as the row's sum did
            hi_k, lo_k = np.where(above, mid, hi_k), np.where(above, lo_k, mid + 1)
        idx[qi, d] = lo_k - 1
    e0, e1 = edge(idx[..., None])[..., 0], edge(idx[..., None] + 1)[..., 0]
    below = (srt[None] < e0[:, None]).sum(axis=1)  # (Q, D) values below the bin ...
    upto = np.where(idx < bins - 1, (srt[None] < e1[:, None]).sum(axis=1), n)  # ... and up to its top
    count_before = np.where(idx == 0, 0, below).astype(np.float64)
    in_bin = upto.astype(np.float64) - count_before
    plain = (idx == 0) | (in_bin == 0)  # LeRobot returns the edge itself (its dtype) there
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = e0 + ((targets - count_before) / in_bin) * (e1 - e0)
    keys = [f"q{int(q * 100):02d}" for q in DEFAULT_QUANTILES]
    return lo, hi, [(key, e0[i], inside[i], plain[i]) for i, key in enumerate(keys)]


def _episode_stats(buf: dict, feats: dict) -> dict:
    """compute_episode_stats(buf, feats) for numeric features, equal bit for bit and in dtype.

    Per feature, mean and std as RunningQuantileStats computes them (on the feature's own array:
    a sum's rounding depends on its layout); min, max and quantiles column by column (_quantiles)
    over all features of one dtype at once. An episode of one frame: LeRobot's own code.
    """
    return _episodes_stats([buf], feats)[0]


def _episodes_stats(bufs: list[dict], feats: dict) -> list[dict]:
    """[_episode_stats(buf, feats) for buf in bufs], the same bits and dtypes: rows of _stats_columns
    (each quantile back in the feature's dtype where LeRobot returns a bin's edge), LeRobot's own
    get_feature_stats for an episode of one frame."""
    hub_offline()
    from lerobot.datasets.compute_stats import get_feature_stats

    outs = [None] * len(bufs)
    long = [e for e, buf in enumerate(bufs) if _frames(buf, feats) >= 2]
    if long:
        cols, edges = _stats_columns([bufs[e] for e in long], feats)
        for j, e in enumerate(long):
            outs[e] = {
                k: {
                    name: v[j].astype(st["min"].dtype) if name in edges[k] and edges[k][name][j] else v[j]
                    for name, v in st.items()
                }
                for k, st in cols.items()
            }
    for e, buf in enumerate(bufs):
        if outs[e] is None:
            outs[e] = {
                k: get_feature_stats(x, axis=0, keepdims=x.ndim == 1)
                for k, x in buf.items()
                if feats[k]["dtype"] not in _TEXT
            }
    return outs


_TEXT = {"string", "language"}  # feature dtypes with no stats


def _frames(buf: dict, feats: dict) -> int:
    return len(next(x for k, x in buf.items() if feats[k]["dtype"] not in _TEXT))


def _stats_columns(bufs: list[dict], feats: dict) -> tuple[dict, dict]:
    """The stats of episodes of two frames or more, as columns: {feature: {stat: (E, D) array}}, row e
    equal in value to compute_episode_stats(bufs[e], feats)[feature][stat] (a quantile in float64, as
    LeRobot interpolates it), and {feature: {quantile: (E,) bool}}, where LeRobot returns the bin's
    edge itself, in the feature's dtype. Every episode has the same features.

    Each dtype's features (as RunningQuantileStats casts them: float32 at least) side by side, every
    episode's beside the others': one _quantiles call over all of them (it works column by column,
    each column with its own length), and mean and std in each feature's own summation order: row by
    row for (T, D > 1), one running sum down every episode at once (_row_by_row_mean_std), pairwise
    for (T, 1), once per episode length (_pairwise_mean_std) unless its sums are exact in any order
    (_sums_exactly). A few dozen numpy calls for a shard where there were dozens per episode, and the
    columns are what the episodes table and the set's aggregate read (_write_direct)."""
    keys = [k for k in bufs[0] if feats[k]["dtype"] not in _TEXT]
    lengths = np.array([_frames(buf, feats) for buf in bufs])  # (E,)
    same = {}  # episode length -> the episodes of that length
    for e, n in enumerate(lengths.tolist()):
        same.setdefault(n, []).append(e)
    groups = {}  # dtype -> [(feature, width)]
    for k in keys:
        x = bufs[0][k]
        groups.setdefault(np.result_type(x.dtype, np.float32), []).append(
            (k, 1 if x.ndim == 1 else x.shape[1])
        )
    cols, edges = {}, {}
    for dtype, layout in groups.items():
        width = sum(w for _, w in layout)
        firsts = np.cumsum([0] + [w for _, w in layout])  # each feature's first column in an episode's
        stacked = np.zeros((lengths.max(), len(bufs), width), dtype)  # (longest, E, width), padding unread
        for e, buf in enumerate(bufs):
            for (k, w), c in zip(layout, firsts):
                stacked[: lengths[e], e, c : c + w] = buf[k].reshape(lengths[e], w)  # cast as astype
        mean, std = np.empty((len(bufs), width), dtype), np.empty((len(bufs), width), dtype)
        wide = [c + i for (_, w), c in zip(layout, firsts) if w > 1 for i in range(w)]
        narrow = [c for (_, w), c in zip(layout, firsts) if w == 1]
        exact = [c for c in narrow if _sums_exactly(stacked[:, :, c], dtype)]
        narrow = [c for c in narrow if c not in exact]
        if wide or exact:  # summed row by row: a running sum down all episodes at once, read at each end
            x = stacked[:, :, wide + exact]  # (longest, E, W)
            mean[:, wide + exact], std[:, wide + exact] = _row_by_row_mean_std(x, lengths)
        for n, es in same.items() if narrow else ():  # summed pairwise: its blocks depend on the length
            x = stacked[:n][:, es][:, :, narrow].reshape(n, -1)  # (T, episodes * columns)
            m, s = _pairwise_mean_std(x)
            mean[np.ix_(es, narrow)], std[np.ix_(es, narrow)] = m.reshape(len(es), -1), s.reshape(len(es), -1)
        flat = stacked.reshape(len(stacked), -1)  # (longest, E * width)
        lo, hi, qs = _quantiles(flat, np.repeat(lengths, width))
        shaped = lambda v: v.reshape(len(bufs), width)  # noqa: E731
        lo, hi = shaped(lo), shaped(hi)
        qs = [(key, shaped(np.where(plain, e0, inside)), shaped(plain)) for key, e0, inside, plain in qs]
        for (k, w), c in zip(layout, firsts):
            part = lambda v: np.ascontiguousarray(v[:, c : c + w])  # noqa: E731
            st = {"min": part(lo), "max": part(hi), "mean": part(mean), "std": part(std)}
            cols[k] = st | {"count": lengths[:, None].copy()} | {key: part(v) for key, v, _ in qs}
            edges[k] = {key: plain[:, c : c + w].all(axis=1) for key, _, plain in qs}
    return {k: cols[k] for k in keys}, edges


def _sums_exactly(x: np.ndarray, dtype) -> bool:
    """Whether every sum of x's values and of their squares is exact in dtype (integers whose squares,
    added up over the longest episode, stay below 2 ** mantissa bits): such a column's sums do not
    depend on their order, so a (T, 1) feature's pairwise sum equals a running one. Indices, counts
    and flags are such columns (padding, zeros, included)."""
    top = float(np.max(np.abs(x)))
    return bool(top * top * len(x) < 2.0 ** np.finfo(dtype).nmant and np.all(x == np.round(x)))


def _pairwise_mean_std(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of each column of x (T, C), each as RunningQuantileStats computes them on a (T, 1)
    feature fed one batch, bit for bit: np.mean adds a (T, 1) feature pairwise (it is contiguous along
    T), as it adds each row of the contiguous (C, T) copy here."""
    x = np.ascontiguousarray(x.T)  # (C, T)
    return _running_update(np.mean(x, axis=1), np.mean(x**2, axis=1))


def _row_by_row_mean_std(x: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std (E, W) of the first lengths[e] rows of each x[:, e] (longest, E, W), each as
    RunningQuantileStats computes them on a (T, D > 1) feature, bit for bit: np.mean adds its rows one
    by one from the first (a running sum, np.cumsum's order), then divides by the count in float64 and
    rounds to the dtype (np.true_divide by an intp, as np.mean does)."""
    last, every = lengths - 1, np.arange(x.shape[1])
    count = lengths[:, None].astype(np.intp)

    def mean(v):  # (E, W)
        return np.true_divide(
            np.cumsum(v, axis=0)[last, every], count, out=np.empty(v.shape[1:], v.dtype), casting="unsafe"
        )

    return _running_update(mean(x), mean(x**2))


def _running_update(mean: np.ndarray, mean_sq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RunningQuantileStats' update with its first batch, mean + (batch mean - mean) * n / n, kept for
    equal bits (-0.0 becomes 0.0, inf becomes nan; the batch mean is `mean` itself), then std."""
    mean += mean - mean
    mean_sq += mean_sq - mean_sq
    return mean, np.sqrt(np.maximum(0, mean_sq - mean**2))


def _episode_columns(e: int, ep: dict, feats, all_feats, *, fps: int, first_frame: int) -> dict:
    """Episode e's columns as LeRobot's save_episode stacks them: each feature (T,) or (T, D), then
    timestamp (float64, float32 on disk), frame_index, episode_index, index (from first_frame), task_index."""
    n = len(ep["action"])
    buf = {}
    for k in feats:
        x = np.asarray(ep[k])
        if len(x) != n:
            raise ValueError(f"episode {e}: {k} has {len(x)} frames, action has {n}")
        buf[k] = x.reshape(n) if all_feats[k]["shape"] == (1,) else x.reshape(n, -1)
    buf["timestamp"] = np.arange(n) / fps
    buf["frame_index"] = np.arange(n)
    buf["episode_index"] = np.full(n, e)
    buf["index"] = np.arange(first_frame, first_frame + n)
    buf["task_index"] = np.zeros(n, dtype=np.int64)  # one task per set
    return buf


@contextlib.contextmanager
def naming(path: Path):
    """An OSError inside (pyarrow's carry no file name: "Error writing bytes to file") re-raised with
    `path` as its file name and the plain message of its errno, so the one error line says where."""
    try:
        yield
    except OSError as e:
        if e.errno is None or e.filename is not None:
            raise
        raise OSError(e.errno, os.strerror(e.errno), str(path)) from e


def close_quietly(writer) -> None:
    """Close a pyarrow ParquetWriter after an error, without a second one: its close fails again on a
    full disk, and a writer left open retries (and prints the failure) when it is collected."""
    if writer is not None and writer.is_open:
        with contextlib.suppress(Exception):  # the first error is the one reported
            writer.close()
        writer.is_open = False


def write_parquet(table, path: Path) -> None:
    """pq.write_table(table, path, **PARQUET) (the same bytes), its writer closed on every path and a
    failure's OSError naming `path` (naming)."""
    import pyarrow.parquet as pq

    writer = None
    try:
        with naming(path):
            writer = pq.ParquetWriter(path, table.schema, **PARQUET)
            writer.write_table(table)
            writer.close()
    finally:
        close_quietly(writer)


def _write_data_file(path: Path, schema, parts: dict) -> None:
    """One data parquet file from {column: [(T,) or (T, D) arrays, episode by episode]}."""
    import pyarrow as pa

    def column(field, arrays: list[np.ndarray]):
        listed = field.type.num_fields  # a (T, D) feature: a fixed-size list of D per frame
        flat = pa.array(
            np.concatenate(arrays).reshape(-1), type=field.type.value_type if listed else field.type
        )
        return pa.FixedSizeListArray.from_arrays(flat, type=field.type) if listed else flat

    path.parent.mkdir(parents=True, exist_ok=True)
    write_parquet(pa.Table.from_arrays([column(f, parts[f.name]) for f in schema], schema=schema), path)


def _write_episodes_table(root: Path, table, limit: float, chunks_size: int) -> None:
    """meta/episodes in files of at most `limit` bytes (Arrow size, as LeRobot splits it): one file up
    to ~50,000 episodes of this chapter's width (~2 KB a row)."""
    hub_offline()
    import pyarrow as pa
    from lerobot.datasets.utils import DEFAULT_EPISODES_PATH

    per_file = rows_within(limit, table.nbytes / table.num_rows)
    roller = ChunkRoller(per_file, chunks_size)
    for lo in range(0, table.num_rows, per_file):
        part = table.slice(lo, per_file)
        chunk, file = roller.place(part.num_rows)
        for name, value in (("meta/episodes/chunk_index", chunk), ("meta/episodes/file_index", file)):
            part = part.append_column(name, pa.array([value] * part.num_rows, pa.int64()))
        path = root / DEFAULT_EPISODES_PATH.format(chunk_index=chunk, file_index=file)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_parquet(part, path)


STATS_BATCH = 256  # episodes whose stats are computed together (_episodes_stats); bounds the memory held


def _stacked_batches(episodes, feats, all_feats, *, fps: int, task: str):
    """(first episode number, the batch's columns as save_episode stacks them, their stats, rows) for up
    to STATS_BATCH episodes at a time, in order. The stats: {feature: {stat: (E, D)}}, the arrays
    LeRobot's aggregate_stats stacks from the episodes' stats; rows: {episodes-table column: E values},
    each episode's stat as LeRobot's flatten_dict lists it (its .tolist())."""
    hub_offline()
    from lerobot.datasets.feature_utils import validate_frame

    it, e, frames = iter(episodes), 0, 0
    while batch := list(itertools.islice(it, STATS_BATCH)):
        bufs = []
        for ep in batch:
            n = len(ep["action"])
            if n == 0:
                raise ValueError(f"episode {e + len(bufs)} has no frames")
            validate_frame({k: ep[k][0] for k in feats} | {"task": task}, all_feats)  # LeRobot's messages
            bufs.append(_episode_columns(e + len(bufs), ep, feats, all_feats, fps=fps, first_frame=frames))
            frames += n
        if all(len(buf["action"]) >= 2 for buf in bufs):  # a column's rows are its episodes' values
            stats, _ = _stats_columns(bufs, all_feats)
            rows = {f"stats/{k}/{name}": v for k, st in stats.items() for name, v in st.items()}
        else:  # an episode of one frame: its stats are LeRobot's, dtypes and all; stacked as LeRobot does
            per_episode = _episodes_stats(bufs, all_feats)
            stats = {
                k: {name: np.stack([s[k][name] for s in per_episode]) for name in st}
                for k, st in per_episode[0].items()
            }
            rows = {
                f"stats/{k}/{name}": [s[k][name].tolist() for s in per_episode]
                for k, st in per_episode[0].items()
                for name in st
            }
        yield e, bufs, stats, rows
        e += len(bufs)


def _stats_column(parts: list):
    """One stats column of the episodes table from its batches (_stacked_batches' rows): (E, D) arrays
    become the Arrow list array pyarrow infers from their .tolist() (list<double>, list<int64> for a
    count), built from the numbers at once; lists (a batch with an episode of one frame) stay lists."""
    import pyarrow as pa

    if not all(isinstance(p, np.ndarray) for p in parts):
        return [x for p in parts for x in (p.tolist() if isinstance(p, np.ndarray) else p)]
    v = np.concatenate(parts)  # (E, D)
    values = v.astype(np.int64 if v.dtype.kind in "iu" else np.float64).ravel()
    return pa.ListArray.from_arrays(np.arange(0, v.size + 1, v.shape[1], dtype=np.int32), pa.array(values))


def _aggregate(stats: dict) -> dict:
    """LeRobot's aggregate_stats of a set's episodes from their stats as columns (_stacked_batches):
    aggregate_feature_stats' own operations on the arrays it stacks, so the same values, without a
    dict per episode and feature."""
    out = {}
    for k, st in stats.items():
        means, counts = st["mean"], st["count"]  # (E, D), (E, 1)
        total_count = counts.sum(axis=0)
        total_mean = (means * counts).sum(axis=0) / total_count
        delta_means = means - total_mean
        total_variance = ((st["std"] ** 2 + delta_means**2) * counts).sum(axis=0) / total_count
        out[k] = {
            "min": np.min(st["min"], axis=0),
            "max": np.max(st["max"], axis=0),
            "mean": total_mean,
            "std": np.sqrt(total_variance),
            "count": total_count,
        }
        out[k] |= {
            q: (v * counts).sum(axis=0) / total_count
            for q, v in st.items()
            if q[0] == "q" and q[1:].isdigit()
        }
    return out


def _write_direct(tmp: Path, *, fps, robot_type, task, feats, episodes, file_mb: int | None = None) -> None:
    """Write a LeRobot v3 set (no video) in one pass from the episodes' arrays.

    What LeRobot 0.6.1's save_episode does per episode, done once for the set: the data columns
    (each feature, timestamp, frame_index, episode_index, index, task_index; DEFAULT_FEATURES) in
    data/chunk-CCC/file-FFF.parquet with the Arrow schema of get_hf_features_from_features, a new
    file when the current one would pass info's data_files_size_in_mb (LeRobot's rule, on the
    uncompressed size); per-episode stats equal bit for bit to compute_episode_stats on the arrays
    save_episode stacks (_episode_stats, a faster equal of it), the episodes table with LeRobot's
    columns in its order, tasks.parquet, info.json, and stats.json as aggregate_stats of the
    episodes' stats (LeRobot folds them one episode at a time: the same values up to rounding).
    No clock, no randomness: equal episodes give equal bytes. No episodes: info.json only, as
    LeRobot leaves it. file_mb: the file size limit in MB (LeRobot's default when None; tests).
    """
    check_hf_cache()  # as on LeRobot's path: a cache problem is named here, not at the first read
    import pandas as pd
    import pyarrow as pa
    from lerobot.datasets.dataset_metadata import CODEBASE_VERSION
    from lerobot.datasets.feature_utils import create_empty_dataset_info, get_hf_features_from_features
    from lerobot.datasets.io_utils import write_info, write_tasks
    from lerobot.utils.constants import DEFAULT_FEATURES

    all_feats = {k: dict(f, shape=tuple(f["shape"])) for k, f in feats.items()} | DEFAULT_FEATURES
    info = create_empty_dataset_info(CODEBASE_VERSION, fps, all_feats, False, robot_type, None, file_mb)
    tmp.mkdir(parents=True)
    schema = get_hf_features_from_features(all_feats).arrow_schema  # with its "huggingface" metadata
    frame_bytes = sum(np.dtype(f["dtype"]).itemsize * f["shape"][0] for f in all_feats.values())
    limit = info.data_files_size_in_mb * 1024**2  # bytes, LeRobot's DEFAULT_DATA_FILE_SIZE_IN_MB

    rows: dict[str, list] = {}  # the episodes table, column by column
    batches = []  # each batch's stats, {feature: {stat: (E, D)}}
    stat_parts = {}  # the episodes table's stats columns, batch by batch
    parts = {k: [] for k in all_feats}  # the current data file's columns, episode by episode
    roller = ChunkRoller(rows_below(limit, frame_bytes), info.chunks_size)  # LeRobot's rule for data files
    chunk = file = frames = 0
    for first, bufs, stats, stat_rows in _stacked_batches(episodes, feats, all_feats, fps=fps, task=task):
        for e, buf in enumerate(bufs, first):
            n = len(buf["action"])
            if (where := roller.place(n)) != (chunk, file):  # this episode starts the next file
                _write_data_file(
                    tmp / info.data_path.format(chunk_index=chunk, file_index=file), schema, parts
                )
                parts = {k: [] for k in all_feats}
                chunk, file = where
            for k, x in buf.items():
                parts[k].append(x.astype(np.float32) if k == "timestamp" else x)
            row = {
                "episode_index": e,
                "tasks": [task],
                "length": n,
                "data/chunk_index": chunk,
                "data/file_index": file,
                "dataset_from_index": frames,
                "dataset_to_index": frames + n,
            }
            for k, v in row.items():
                rows.setdefault(k, []).append(v)
            frames += n
        # LeRobot's flatten_dict({"stats": stats}) per episode (its keys, in its order), a column at a time
        for k, v in stat_rows.items():
            stat_parts.setdefault(k, []).append(v)
        batches.append(stats)
    if not batches:
        write_info(info, tmp)
        return
    _write_data_file(tmp / info.data_path.format(chunk_index=chunk, file_index=file), schema, parts)
    n_eps = len(rows["episode_index"])
    rows |= {k: _stats_column(parts) for k, parts in stat_parts.items()}
    _write_episodes_table(tmp, pa.Table.from_pydict(rows), limit, info.chunks_size)
    write_tasks(pd.DataFrame({"task_index": range(1)}, index=pd.Index([task], name="task")), tmp)
    info.total_episodes, info.total_frames, info.total_tasks = n_eps, frames, 1
    info.splits = {"train": f"0:{n_eps}"}
    write_info(info, tmp)
    stats = {
        k: {name: np.concatenate([b[k][name] for b in batches]) for name in st}
        for k, st in batches[0].items()
    }
    write_sorted_stats(_aggregate(stats), tmp)


def open_dataset(root: Path, repo_id: str = "local/demos"):
    return _lerobot_dataset_class()(repo_id, root=Path(root), video_backend=VIDEO_BACKEND)


def load_arrays(root: Path, keys=("observation.state", "action", "episode_index", "frame_index")) -> dict:
    """Every frame of a local LeRobot dataset as numpy arrays, in dataset order. A set that cannot be
    read (a truncated parquet, a missing file, a wrong schema) is a DataError of one line."""
    _lerobot_dataset_class()  # imports datasets, which sets its log level on import
    datasets_log = logging.getLogger("datasets")  # it logs the same failure on stderr, twice
    level = datasets_log.level
    datasets_log.setLevel(logging.CRITICAL + 1)
    try:
        ds = open_dataset(root)
        batch = ds.hf_dataset.with_format("numpy", columns=list(keys))[:]  # one columnar read
        return {k: np.asarray(batch[k]) for k in keys}
    except (KeyboardInterrupt, MemoryError):
        raise
    except Exception as e:  # pyarrow, datasets and lerobot each raise their own kinds on a damaged set
        while (e.__cause__ or e.__context__) is not None:  # the root cause says what is wrong
            e = e.__cause__ or e.__context__
        why = " ".join(str(e).split())[:160]
        raise DataError(
            f"{root} cannot be read as a LeRobot v3 dataset ({type(e).__name__}: {why}); "
            "regenerate it (gen_demos_pusht.py / gen_demos_aloha.py) or pass another set"
        ) from e
    finally:
        datasets_log.setLevel(level)


# A user's set must suit the env it feeds, checked where it is read (datagen.demos.ensure_demos for
# scale_data.py, datagen.source_check.read_source for augment_demos.py): fps_problem before loading
# (LeRobot may refuse a set whose timestamps do not fit its fps), frames_problem on the loaded arrays.
def fps_problem(root: Path, fps: int) -> str | None:
    """None if the set at `root` is recorded at `fps` Hz, the env's control rate, else why not. An
    action is a command held for 1/fps s: a 50 fps set stepped at 10 fps runs each command 5x too long."""
    try:
        got = json.loads((Path(root) / "meta" / "info.json").read_text()).get("fps")
    except (OSError, ValueError, AttributeError):
        got = None
    if isinstance(got, str | bool) or (got is not None and not isinstance(got, int | float)):
        # "10" is no rate: said as it is, not as "recorded at 10 fps, but the env steps at 10 fps"
        return (
            f"{root}: meta/info.json's fps is {got!r} (a {json_kind(got)}), not a number of frames per second"
        )
    if got != fps:
        return f"{root} is recorded at {got} fps, but the env steps at {fps} fps; resample it to {fps} fps"
    return None


def frames_problem(root: Path, arrays: dict) -> str | None:
    """None if every state, environment state (where `arrays` holds one) and action (N, D) is finite,
    else where the first bad frame is, in the column that holds it."""
    for key in ("observation.state", ENV_STATE_KEY, "action"):
        if key not in arrays:
            continue
        bad = ~np.isfinite(arrays[key]).all(axis=tuple(range(1, arrays[key].ndim)))
        if bad.any():
            return (
                f"{root} holds non-finite values (NaN or inf) in {key} in {int(bad.sum())} frames, "
                f"the first at row {int(np.argmax(bad))}; fix or drop those frames"
            )
    return None


def json_kind(value) -> str:
    """What JSON calls the type of `value` (a parsed JSON value), for messages about a file's form."""
    kinds = {dict: "object", list: "list", str: "string", bool: "boolean", type(None): "null"}
    return kinds.get(type(value), "number")


def info_problem(root: Path) -> str | None:
    """None if `root`'s meta/info.json has the form LeRobot v3 writes (an object whose features is an
    object of objects), else one line saying what it is instead: a hand-edited or foreign file is named,
    not tripped over."""
    try:
        info = json.loads((Path(root) / "meta" / "info.json").read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return f"{root} is not a LeRobot v3 dataset (no readable meta/info.json)"
    if not isinstance(info, dict):
        return (
            f"{root}: meta/info.json holds a {json_kind(info)}, not an object; it is no LeRobot v3 info.json"
        )
    if "features" not in info:
        return f"{root} is not a LeRobot v3 dataset (its meta/info.json has no features)"
    feats = info["features"]
    if not isinstance(feats, dict):
        return f"{root}: meta/info.json's features is a {json_kind(feats)}, not an object of feature entries"
    for key, entry in feats.items():
        if not isinstance(entry, dict):
            return (
                f"{root}: meta/info.json's feature {key!r} is a {json_kind(entry)}, not an object with its "
                "dtype and shape"
            )
    return None


def schema_problem(root: Path, state_dim: int, action_dim: int) -> str | None:
    """None if `root` is a LeRobot dataset with the expected state/action widths, else why not."""
    problem = info_problem(root)
    if problem:
        return problem
    feats = json.loads((Path(root) / "meta" / "info.json").read_text())["features"]
    for key, want in (("observation.state", state_dim), ("action", action_dim)):
        got = feats.get(key, {}).get("shape")
        if not isinstance(got, list) or got != [want]:
            return f"{root}: feature {key!r} has shape {got}, expected [{want}]"
    return None
