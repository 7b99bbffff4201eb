"""LeRobot v3 read and write for the chapter's demo sets: features, write_dataset, load_arrays.

Everything here is a pure function of its arguments: no clock, no global RNG. A set is written
whole into a sibling temp folder and renamed into place, with the stamp (ch37.stamps) beside it.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import shutil
from pathlib import Path

import numpy as np

from ch37.errors import DataError
from ch37.files import dump_json, partial_dir, sweep_leftovers, temp_path
from ch37.stamps import STAMP_NAME, digests, holds_data

# torchcodec needs system FFmpeg libraries and prints long tracebacks when they are missing;
# pyav ships its own FFmpeg, so every dataset here is read and written through pyav.
VIDEO_BACKEND = "pyav"
IMAGE_KEY = "observation.images.top"
IMAGE_SIZE = 96  # px, the optional top-down video is IMAGE_SIZE x IMAGE_SIZE RGB
# LeRobot's policies (diffusion, ACT) need an image or this key: the object and task state. The
# writer fills it from observation.state's columns of the same names (each env's ENV_STATE_NAMES);
# nothing in the chapter reads it, so a set without it is read as before.
ENV_STATE_KEY = "observation.environment_state"


def check_hf_cache() -> None:
    """DataError (one line) unless Hugging Face datasets can write its cache: every read of a set goes
    through it, and without this check a cache problem reads as a damaged data set."""
    import datasets

    _probe_cache(Path(datasets.config.HF_DATASETS_CACHE))


@functools.cache
def _probe_cache(cache: Path) -> None:  # once per folder and process: every read and write calls it
    try:
        cache.mkdir(parents=True, exist_ok=True)
        probe = temp_path(cache / "probe")
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise DataError(
            f"the Hugging Face cache {cache} cannot be written ({e.strerror}); set HF_HOME to a folder "
            "you can write to (your data sets are fine)"
        ) from None


def _lerobot_dataset_class():
    """LeRobotDataset, with Hugging Face datasets' per-episode "Map" bars silenced (our own bar is enough)."""
    import datasets
    from lerobot.datasets import dataset_writer
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    datasets.disable_progress_bars()
    check_hf_cache()
    if not getattr(dataset_writer.embed_images, "skips_imageless", False):
        dataset_writer.embed_images = _embed_images_if_any(dataset_writer.embed_images)
    return LeRobotDataset


def _embed_images_if_any(embed):
    """lerobot 0.6 runs embed_images on every saved episode, a row-by-row map that costs ~0.1 s per
    episode even when the table holds no image column, where it returns the table unchanged.
    Skip it exactly then; any table with an image column goes through lerobot's own code."""
    import datasets

    def embed_images(ds):
        if any(isinstance(f, datasets.Image) for f in ds.features.values()):
            return embed(ds)
        return ds

    embed_images.skips_imageless = True
    return embed_images


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
    from datasets import arrow_dataset, fingerprint

    saved = arrow_dataset.generate_fingerprint
    arrow_dataset.generate_fingerprint = lambda dataset: fingerprint.generate_random_fingerprint()
    try:
        yield
    finally:
        arrow_dataset.generate_fingerprint = saved


def write_dataset(
    out: Path, *, repo_id: str, fps: int, robot_type: str, task: str, feats: dict, episodes, stamp: dict
) -> None:
    """Write `episodes` (an iterable of dicts of per-frame arrays keyed like `feats`) to `out`.

    ENV_STATE_KEY, when `feats` has it and an episode does not, is taken from the episode's
    observation.state columns of the same names (see features).

    The set is built in a sibling temp directory (ch37.files.partial_dir) and renamed into place, so
    an interrupted run never leaves a half-written set at `out`; what a killed run left for `out` is
    removed here, and nothing else beside it. `out` must not
    hold data. The stamp lists every file of the set with its sha256 (ch37.stamps).
    """
    LeRobotDataset = _lerobot_dataset_class()
    out = Path(out)
    if holds_data(out):
        raise DataError(f"{out} already holds data; pick another --out or remove it yourself")
    out.parent.mkdir(parents=True, exist_ok=True)
    sweep_leftovers(out.parent, out.name)  # a killed run's partial `out` only: the parent is not ours
    use_videos = any(f["dtype"] == "video" for f in feats.values())
    env_cols = (
        columns(feats["observation.state"]["names"], feats[ENV_STATE_KEY]["names"])
        if ENV_STATE_KEY in feats
        else None
    )
    work = partial_dir(out)  # .NAME.ch37-partial-PID, our stamp inside; LeRobot writes the set in work/set
    tmp = work / "set"
    try:
        ds = LeRobotDataset.create(
            repo_id,
            fps=fps,
            features=feats,
            root=tmp,
            robot_type=robot_type,
            use_videos=use_videos,
            video_backend=VIDEO_BACKEND,
        )
        with _fast_fingerprints():
            for ep in episodes:
                if env_cols is not None and ENV_STATE_KEY not in ep:  # (T, 10) -> (T, len(env_cols))
                    ep = ep | {ENV_STATE_KEY: np.ascontiguousarray(ep["observation.state"][:, env_cols])}
                for t in range(len(ep["action"])):
                    ds.add_frame({k: ep[k][t] for k in feats} | {"task": task})
                ds.save_episode()
        ds.finalize()
        stats = (
            tmp / "meta" / "stats.json"
        )  # lerobot orders its keys by string hash; sorted, equal sets are equal bytes
        if stats.exists():
            stats.write_text(
                json.dumps(json.loads(stats.read_text()), indent=4, sort_keys=True, ensure_ascii=False)
            )
        (tmp / STAMP_NAME).write_text(dump_json(dict(stamp, files=digests(tmp))))
        try:
            if out.exists():
                out.rmdir()  # empty directory (holds_data checked above)
            tmp.rename(out)
        except OSError as e:  # ENOTEMPTY/EEXIST: another process wrote `out` meanwhile
            if not holds_data(out):
                raise
            raise DataError(
                f"{out} was written by another run at the same time; run the same command again"
            ) from e
    finally:
        shutil.rmtree(work, ignore_errors=True)


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


# A user's set must suit the env it feeds, checked where it is read (ch37.demos.ensure_demos for
# scale_data.py, ch37.shards.read_source for augment_demos.py): fps_problem before loading (LeRobot
# may refuse a set whose timestamps do not fit its fps), frames_problem on the loaded arrays.
def fps_problem(root: Path, fps: int) -> str | None:
    """None if the set at `root` is recorded at `fps` Hz, the env's control rate, else why not. An
    action is a command held for 1/fps s: a 50 fps set stepped at 10 fps runs each command 5x too long."""
    try:
        got = json.loads((Path(root) / "meta" / "info.json").read_text()).get("fps")
    except (OSError, ValueError, AttributeError):
        got = None
    if got != fps:
        return f"{root} is recorded at {got} fps, but the env steps at {fps} fps; resample it to {fps} fps"
    return None


def frames_problem(root: Path, arrays: dict) -> str | None:
    """None if every state and action in `arrays` (N, D) is finite, else where the first bad frame is."""
    for key in ("observation.state", "action"):
        bad = ~np.isfinite(arrays[key]).all(axis=tuple(range(1, arrays[key].ndim)))
        if bad.any():
            return (
                f"{root} holds non-finite values (NaN or inf) in {key} in {int(bad.sum())} frames, "
                f"the first at row {int(np.argmax(bad))}; fix or drop those frames"
            )
    return None


def schema_problem(root: Path, state_dim: int, action_dim: int) -> str | None:
    """None if `root` is a LeRobot dataset with the expected state/action widths, else why not."""
    info_path = Path(root) / "meta" / "info.json"
    try:
        feats = json.loads(info_path.read_text())["features"]
    except (OSError, json.JSONDecodeError, KeyError):
        return f"{root} is not a LeRobot v3 dataset (no readable meta/info.json)"
    for key, want in (("observation.state", state_dim), ("action", action_dim)):
        got = feats.get(key, {}).get("shape")
        if got is None or list(got) != [want]:
            return f"{root}: feature {key!r} has shape {got}, expected [{want}]"
    return None
