"""The source set a run grows, only read: which task it is (task_of), whether the engine can grow it
(read_source: its schema, names, fps, files, frames, value ranges and the task's own check of its states,
Task.state_problem; each failure one line) and what it is, wherever it lives (source_identity: a digest of
the frames read, in the run's stamp)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ch37.errors import DataError
from ch37.ownership import read_json
from ch37.seeds import SEED_BLOCK
from datagen.demos import TASK_FILE
from datagen.task import Task, known_tasks
from lerobot_v3.dataset import (
    ENV_STATE_KEY,
    check_hf_cache,
    fps_problem,
    frames_problem,
    info_problem,
    load_arrays,
    observation,
    schema_problem,
)
from lerobot_v3.hub import hub_offline

# The episodes table's columns that say where each episode's frames are (LeRobot v3)
EPISODE_COLUMNS = ("episode_index", "length", "dataset_from_index", "dataset_to_index")
EPISODE_COLUMNS += ("data/chunk_index", "data/file_index")


def state_range_problem(
    task: Task, src: Path, states: np.ndarray, actions: np.ndarray | None = None
) -> str | None:
    """None if every state (N, obs_dim) and action (N, act_dim) lies in the task's documented ranges
    (task.spec.state_ranges, task.spec.action_ranges; 1e-6 of slack: float32 rounding), else the first
    dimension outside, how many frames and the first row. A value outside is no state or action of the task:
    its attempts could only fail."""
    for key, values, ranges in (
        ("observation.state", states, task.spec.state_ranges),
        ("action", actions, task.spec.action_ranges),
    ):
        for i, (name, (lo, hi)) in enumerate(ranges.items() if values is not None else ()):
            bad = (values[:, i] < lo - 1e-6) | (values[:, i] > hi + 1e-6)
            if bad.any():
                row, what = int(np.argmax(bad)), key.split(".")[-1]
                return (
                    f"--src {src}: {key} {name} (index {i}) is {float(values[row, i]):g} in "
                    f"{int(bad.sum())} frames, the first at row {row}; the {task.title} env's range for it "
                    f"is [{lo:g}, {hi:g}]: this is not a {task.title} {what}"
                )
    return None


def _widths(task: Task) -> tuple[list, list]:
    """The shapes of a set's observation.state and action for `task`."""
    return [len(task.spec.state_names)], [task.spec.act_dim]


def task_of(src: Path, name: str | None = None) -> Task:
    """The task whose set `src` is (of datagen.task.known_tasks()): `name` where the user chose one
    (--task), else the task the set names (datagen.demos.TASK_FILE: every set this project writes), else,
    for a set written elsewhere, the one task whose env's ROBOT_TYPE the set records (or, without one, whose
    state and action widths it has). DataError (one line) for an unknown name, a set that fits no task, or
    one that fits several (naming them: --task chooses). A folder without a readable info.json is left to
    read_source's checks (as PushT's, the engine's first task), which name what is wrong with it; one
    readable but not of LeRobot's form (a list where an object belongs) is named here, before any task's
    widths are blamed."""
    known = known_tasks()
    info = read_json(Path(src) / "meta" / "info.json")
    if info is not None and (problem := info_problem(src)):  # readable, but not LeRobot's form
        raise DataError(f"--src {problem}")
    if name is not None:
        if name not in known:
            raise DataError(f"--task {name!r} is no task of the engine; it knows {', '.join(known)}")
        return known[name]
    named = read_json(Path(src) / TASK_FILE)
    if named is not None:
        if not isinstance(named, dict) or not isinstance(named.get("task"), str):
            raise DataError(f'--src {src}: {TASK_FILE} holds no task name ({{"task": NAME}}); pass --task')
        if named["task"] not in known:
            raise DataError(
                f"--src {src} is a set of the task {named['task']!r} ({TASK_FILE}), which the engine does "
                f"not know here (it knows {', '.join(known)}): add its module to datagen/tasks/, or --task"
            )
        task = known[named["task"]]
        robot = (info or {}).get("robot_type")
        if robot and robot != task.spec.robot_type:  # an edited set: its two records disagree
            raise DataError(
                f"--src {src} names the task {task.name!r} ({TASK_FILE}) but records robot_type {robot!r}, "
                f"not {task.title}'s {task.spec.robot_type!r}: it is no set of that task"
            )
        return task
    if info is None:
        return known["pusht"]
    feats = info["features"]  # an object of objects (info_problem)
    shapes = tuple(feats.get(k, {}).get("shape") for k in ("observation.state", "action"))
    robot = info.get("robot_type")
    if robot:  # a set that names its robot is that robot's (an SO-100 set is no PushT set)
        fits = [t for t in known.values() if t.spec.robot_type == robot]
        if len(fits) > 1:  # one robot, several tasks (ALOHA's transfer-cube and insertion): by the objects
            env = feats.get(ENV_STATE_KEY, {}).get("shape")
            fits = [t for t in fits if env == [len(t.spec.env_state_names)]]
    else:  # a set someone else wrote without a robot_type (LeRobot's writer's default): by its widths
        fits = [t for t in known.values() if shapes == _widths(t)]
    if len(fits) == 1:
        return fits[0]
    if len(fits) > 1:
        raise DataError(
            f"--src {src} names no engine task ({TASK_FILE}) and fits {len(fits)} of them "
            f"(robot_type {robot!r}, observation.state {shapes[0]}, action {shapes[1]}): "
            f"{', '.join(t.name for t in fits)}; choose one with --task NAME"
        )
    described = "; ".join(
        f"{t.title}: robot_type '{t.spec.robot_type}', observation.state {_widths(t)[0]}, "
        f"action {_widths(t)[1]} (make one with {_made_with(t)})"
        for t in known.values()
    )
    raise DataError(
        f"--src {src} fits no task of the engine (robot_type {robot!r}, observation.state {shapes[0]}, "
        f"action {shapes[1]}); it grows {described}"
    )


def _made_with(task: Task) -> str:
    """The command that makes a source set of `task`: its expert's generator, by default gen_demos.py's."""
    return (task.expert and task.expert.generator) or f"gen_demos.py --task {task.name}"


def read_source(task: Task, src: Path) -> dict:
    """The source set's columns (a set of `task`), or DataError with one line saying what is wrong with it."""
    hub_offline()
    import datasets
    import pyarrow.parquet as pq

    m, title = task.spec, task.title
    if not src.is_dir():
        raise DataError(f"--src {src} is not a folder; make a {title} set with {_made_with(task)}")
    n_state = len(m.state_names)
    problem = schema_problem(src, n_state, m.act_dim)
    if problem:
        raise DataError(f"--src {problem} (a {title} set has state [{n_state}] and action [{m.act_dim}])")
    feats = read_json(src / "meta" / "info.json")["features"]
    for key, want in (("observation.state", m.state_names), ("action", m.action_names)):
        names = feats[key].get("names")
        # names as a list are checked; the hub's {"motors": [...]} form names the set's own axes
        if isinstance(names, list) and names != list(want):
            raise DataError(f"--src {src}: {key} names {names} are not {title}'s {list(want)}")
    whole = task.spec.observation_names != tuple(
        m.state_names
    )  # the observation holds the environment state too
    if whole and ENV_STATE_KEY not in feats:
        raise DataError(f"--src {src} has no {ENV_STATE_KEY} (a {title} observation needs it)")
    problem = fps_problem(src, m.fps)
    if problem:
        raise DataError(f"--src {problem}")
    for f in sorted(src.glob("data/*/*.parquet")) + sorted(src.glob("meta/episodes/*/*.parquet")):
        try:
            schema = pq.read_schema(f)
        except Exception as e:  # pyarrow's errors for a broken file vary by what is broken
            raise DataError(
                f"--src {src}: {f.relative_to(src)} is not a readable parquet file ({e})"
            ) from None
        missing = (
            [c for c in EPISODE_COLUMNS if c not in schema.names]
            if f.relative_to(src).parts[1] == "episodes"
            else []
        )
        if missing:
            raise DataError(
                f"--src {src}: {f.relative_to(src)} lacks the columns {', '.join(missing)} (a LeRobot v3 "
                "episodes table says where each episode's frames are); regenerate or repair the set"
            )
    datasets.logging.set_verbosity(datasets.logging.CRITICAL)  # a failure below is our one line, not a log
    check_hf_cache()  # a cache we cannot write is named as the cause, not the set
    try:
        keys = ("observation.state", "action", "episode_index") + ((ENV_STATE_KEY,) if whole else ())
        keys += (SUCCESS_KEY,) if SUCCESS_KEY in feats else ()
        arrays = load_arrays(src, keys=keys)
    except Exception as e:  # pyarrow, datasets and lerobot each raise their own kinds for a broken set
        first = (str(e).strip().splitlines() or [""])[0][:160]
        raise DataError(
            f"--src {src} could not be read as a LeRobot dataset ({type(e).__name__}: {first})"
        ) from None
    if len(arrays["action"]) == 0:
        raise DataError(f"--src {src} holds no frames")
    env_names = tuple(m.env_state_names)
    if whole and arrays[ENV_STATE_KEY].shape[1:] != (len(env_names),):
        raise DataError(f"--src {src}: {ENV_STATE_KEY} is not [{len(env_names)}] wide")
    problem = frames_problem(src, arrays)  # before the columns are joined: the line names the one at fault
    if problem:
        raise DataError(f"--src {problem}")
    if whole:  # the observation vector the task's env gives: state and environment state together
        arrays["observation.state"] = observation(
            arrays, task.spec.observation_names, m.state_names, env_names
        )
    problem = state_range_problem(task, src, arrays["observation.state"], arrays["action"])
    if problem:
        raise DataError(problem)
    found = task.state_problem(arrays["observation.state"])
    if found:  # named by episode and frame, as a user finds it in the set
        row, what = found
        ep = arrays["episode_index"]
        frame = int(np.count_nonzero(ep[:row] == ep[row]))
        raise DataError(
            f"--src {src}: episode {int(ep[row])}, frame {frame} (row {row}): {what}; this is not a "
            f"{task.title} state, and nothing is grown from it"
        )
    if arrays["episode_index"].max() >= SEED_BLOCK:
        raise DataError(f"--src {src}: episode indices must be below {SEED_BLOCK:,} (the seed block)")
    return arrays


SUCCESS_KEY = "next.success"  # what our sets (and the hub's) record after each frame's action


def successful_only(arrays: dict, src: Path) -> tuple[dict, str | None]:
    """The source's columns without its episodes that end unsolved (their last next.success False), and
    a line naming them (None when none is dropped or the set records no success). A failed demo shows no
    way to the goal: replaying it can only fail, and a demo grown from it would carry it as provenance.
    DataError when no episode is left."""
    if SUCCESS_KEY not in arrays:
        return arrays, None
    ep = arrays["episode_index"]
    done = np.asarray(arrays.pop(SUCCESS_KEY)).reshape(len(ep), -1)[:, 0]
    last = np.r_[ep[1:] != ep[:-1], True]  # each episode's last frame
    failed = ep[last][~done[last]]
    if not len(failed):
        return arrays, None
    if len(failed) == len(np.unique(ep)):
        raise DataError(f"--src {src}: none of its {len(failed)} episodes ends in success (next.success)")
    keep = ~np.isin(ep, failed)
    shown = ", ".join(map(str, failed[:10].tolist())) + (", ..." if len(failed) > 10 else "")
    note = (
        f"note: {len(failed)} of {len(np.unique(ep))} source episodes end unsolved (next.success) and are "
        f"skipped: episode {shown}; a failed demo shows no way to the goal"
    )
    return {k: v[keep] for k, v in arrays.items()}, note


def source_identity(arrays: dict) -> dict:
    """What a run was grown from, independent of where the set lives: a digest of the frames read."""
    h = hashlib.sha256()
    for key in ("episode_index", "observation.state", "action"):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return {
        "sha256": h.hexdigest(),
        "episodes": int(len(np.unique(arrays["episode_index"]))),
        "frames": int(len(arrays["action"])),
    }
