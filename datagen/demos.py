"""Demo sets: roll out an expert (rollout: the engine's one attempt runner, mode Rollout), write LeRobot
v3 (write_dataset: a stamped set, whole or not at all), and keep a private cache of generated sets.

A demo set is a pure function of (embodiment, episodes, seed, noise, video): episode i of seed s
is rolled out from env seed seeds.env_seed(s, "demo", i), and the expert's action noise is
drawn from a generator seeded with that same number. gen_demos_pusht.py and gen_demos_aloha.py
are gen_demos.main with their embodiment; scale_data.py calls `ensure_demos`.
"""

from __future__ import annotations

import functools
import os
import sys
from importlib.metadata import version
from pathlib import Path

from ch37 import code_digest
from ch37.errors import DataError
from ch37.ownership import (
    MADE_BY,
    changed_files,
    dump_json,
    holds_data,
    is_ours,
    publish_dir,
    read_stamp,
    replace_own_dir,
)
from ch37.parallel import progress
from ch37.process import environment
from ch37.seeds import env_seed
from datagen.lockstep import Rollout, one_lane
from lerobot_v3 import (
    IMAGE_SIZE,
    features,
    fps_problem,
    frames_problem,
    load_arrays,
    schema_problem,
    write_set,
)

# The engine task that made a set, in the set's own meta/ folder: LeRobot's readers never open it and its
# writers never rewrite it (info.json keeps only the keys LeRobot knows), so a set copied, moved or
# pushed to the hub still says which task it is a set of (datagen.source_check.task_of reads it): two tasks
# of one robot with the same widths, or a user's variant of ours, each grow their own sets.
TASK_FILE = "meta/engine_task.json"


def name_task(root: Path, name: str) -> None:
    """Record in the set at `root` that the engine task `name` made it (TASK_FILE)."""
    (Path(root) / TASK_FILE).write_text(dump_json({"task": name}))


def write_dataset(
    out: Path,
    *,
    task_name: str | None = None,
    repo_id: str,
    fps: int,
    robot_type: str,
    task: str,
    feats: dict,
    episodes,
    stamp: dict,
    **how,
) -> None:
    """Write `episodes` as a LeRobot v3 set (lerobot_v3.write_set) of the engine task `task_name` (named in
    the set: TASK_FILE; every set the project makes names one) to the new folder `out`, whole or not at
    all, under our stamp listing every file with its sha256 (ch37.ownership.publish_dir). `how`:
    write_set's other options (per_frame)."""
    how |= dict(repo_id=repo_id, fps=fps, robot_type=robot_type, task=task, feats=feats, episodes=episodes)
    with publish_dir(out, stamp) as tmp:
        write_set(tmp, **how)
        if task_name is not None:  # None: a set as another program writes one (the tests' stand-ins)
            name_task(tmp, task_name)


REWARD_FEATURES = {  # what a task with spec.records_reward adds, as lerobot/pusht_keypoints has them
    "next.reward": {"dtype": "float32", "shape": (1,), "names": None},
    "next.done": {"dtype": "bool", "shape": (1,), "names": None},
}


def rollout(task, env, policy, obs, *, render: bool = False) -> dict:
    """Run `policy` in `env` of `task` from `obs` (what reset or set_start returned) to the end of the
    episode: the engine's one attempt runner in one lane (datagen.lockstep.one_lane, mode Rollout).

    Frame t pairs the obs before action t with action t.
    Returns arrays: observation.state (T, obs_dim) float32, action (T, act_dim) float32,
    next.success (T, 1) bool, "success" (the last next.success), for a task with spec.records_reward
    next.reward (T, 1) float32 and next.done (T, 1) bool (the step's reward and whether it ended the
    episode: REWARD_FEATURES), and IMAGE_KEY (T, IMAGE_SIZE, IMAGE_SIZE, 3) uint8 when render is set, and
    with an env whose step says whether the sim blew up (info["unstable"]: the ALOHA sims,
    datagen.tasks.aloha_sim) unstable: whether it did (the episode ended there).
    """
    return one_lane(task, env, [0], Rollout(lambda job, env: (policy, obs), render=render))[0]


# Any edit to the code that shapes a set's frames (this module, the task's module and the env it imports,
# its expert, and every project module they import: ch37.code_files reads them from what was imported), or
# another lerobot (the writer of its files), changes the version, so a cached set can never outlive the
# code that made it.
@functools.cache
def generator_version(task) -> str:  # at the first set made or checked, not at import
    classes = (task.expert.cls, type(task))
    roots = (sys.modules[__name__],) + tuple(sys.modules[c.__module__] for c in classes)  # and their imports
    packages = "".join(
        f"+{p}{version(p)}" for p in ("lerobot", *task.spec.packages)
    )  # the writer, the simulator
    return f"3+{code_digest(roots)}{packages}"


def expert_episodes(task, env, seed: int, n: int, *, noise: float = 0.0, render: bool = False):
    """Episodes 0..n-1 of the seed's demo set of `task`, one by one: episode i rolled out in `env` from
    env.reset(env_seed(seed, "demo", i)) by task.expert.cls seeded with that same number (its action
    noise `noise`), with next.reward and next.done for a task with records_reward."""

    def start(i: int, env):
        s = env_seed(seed, "demo", i)
        return task.expert.cls(noise=noise, seed=s), env.reset(s)

    mode = Rollout(start, render=render)
    for i in range(n):  # one at a time: the writer takes each as it comes
        yield one_lane(task, env, [i], mode)[0]


def generate(
    emb,
    out: Path,
    *,
    episodes: int,
    seed: int,
    noise: float,
    video: bool = False,
    quiet: bool = False,
) -> dict:
    """Write a demo set of the task `emb` (datagen.task.Task: its env, expert.cls, name) to `out` and
    return its summary (episodes, frames, successes: of those written; unstable: the episodes in which the
    simulation blew up, not written; DataError when that is every one)."""
    env = emb.make_env()
    m = emb.spec
    summary = {"episodes": 0, "frames": 0, "successes": 0, "unstable": 0}

    def episodes_iter():
        made = expert_episodes(emb, env, seed, episodes, noise=noise, render=video)
        for ep in progress(made, total=episodes, desc=f"{emb.name} demos", quiet=quiet):
            if ep.get("unstable"):  # MuJoCo reset the sim mid-episode: a failure, and no episode to write
                summary["unstable"] += 1
                continue
            summary["episodes"] += 1
            summary["frames"] += len(ep["action"])
            summary["successes"] += ep["success"]
            yield ep | emb.frame_columns(ep["observation.state"], ep["action"])
        if not summary["episodes"]:  # raised inside the writer: nothing is left of the set
            raise DataError(
                f"the simulation blew up (unstable) in all {episodes} {emb.name} episodes at noise "
                f"{noise:g}, so none was written; lower --noise"
            )

    extra = (REWARD_FEATURES if emb.spec.records_reward else {}) | emb.spec.frame_features
    feats = features(m.state_names, m.action_names, extra, video=video, env_state_names=m.env_state_names)
    stamp = stamp_for(emb, episodes=episodes, seed=seed, noise=noise, video=video)
    how = dict(repo_id=f"local/{emb.name}_demos", fps=m.fps, robot_type=m.robot_type, task=m.task)
    how["obs_names"] = (
        emb.spec.observation_names
    )  # the frames' observations: the set's state (and env state) columns
    # the AV1 encoder (video only) prints its banner unless SVT_LOG says errors only; a value of yours is kept
    with environment(SVT_LOG=os.environ.get("SVT_LOG", "1")):
        write_dataset(out, task_name=emb.name, feats=feats, episodes=episodes_iter(), stamp=stamp, **how)
    return summary


def stamp_for(emb, *, episodes: int, seed: int, noise: float, video: bool) -> dict:
    """Everything the frames of a generated set depend on; a cached set is reused only on equality."""
    return {
        "made_by": MADE_BY,
        "embodiment": emb.name,
        "episodes": int(episodes),
        "seed": int(seed),
        "noise": float(noise),
        "video": bool(video),
        "generator_version": generator_version(emb),
    }


def check_gl() -> str | None:
    """None if headless rendering works here, else a one-line reason."""
    import av

    av.logging.set_level(av.logging.ERROR)  # FFmpeg's muxer chatter
    try:
        import mujoco

        mujoco.Renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 8, 8).close()
        return None
    except Exception as e:  # no EGL/OSMesa/GLFW context: anything MuJoCo raises here means "no GL"
        return (
            f"no OpenGL backend for headless rendering ({type(e).__name__}); set MUJOCO_GL=egl or osmesa "
            "with its library installed, or use --no-video"
        )


def video_problem(task) -> str | None:
    """None if `task`'s env draws the frames --video records (rollout(render=True)) here, else one line
    saying why: asked before anything is made, of a fresh env of the task, for every task alike."""
    env = task.make_env()
    try:
        env.reset(0)
        env.render(IMAGE_SIZE)
        return None
    except Exception as e:  # MuJoCo without a GL context raises its own kinds; an env may draw nothing at all
        return (
            check_gl()
            or f"--video: {task.title} draws no frames here ({type(e).__name__}: {e}); use --no-video"
        )


def ensure_demos(
    emb, path: Path, *, user_given: bool, episodes: int, seed: int, noise: float, quiet: bool
) -> str:
    """Make sure `path` holds the demo set this run needs; return how it was obtained.

    user_given: a set named by --pusht_data/--aloha_data. It is never modified. A demo set this
    project generated must match the request; any other set (a user's, or one of our other outputs
    such as an augment_demos.py run, stamp kind "engine") must have the right schema, the env's fps
    and finite frames, and is used as given. Otherwise (our private cache) a stale set we made is
    rebuilt, and a directory we did not make is refused.
    """
    if user_given:
        return check_given(emb, path, episodes=episodes, seed=seed, noise=noise)
    want = stamp_for(emb, episodes=episodes, seed=seed, noise=noise, video=False)
    stamp = read_stamp(path)
    matches = is_ours(stamp) and "kind" not in stamp and all(stamp.get(k) == v for k, v in want.items())
    changed = changed_files(path, stamp) if matches else []  # missing, truncated or edited since written
    if matches and not changed:
        return "cached"
    replace_own_dir(path)  # a stale or damaged set we made is rebuilt; anything else is refused
    s = generate(emb, path, episodes=episodes, seed=seed, noise=noise, quiet=quiet)
    why = f"; {', '.join(changed[:3])} had changed since written" if changed else ""
    return f"generated ({s['successes']}/{s['episodes']} expert successes{why})"


def check_given_sets(given: dict, *, episodes: int, seed: int) -> None:
    """Each set of {embodiment: path or None} that a user named (--pusht_data/--aloha_data; None: a set
    made under --out) checked with check_given, at the embodiment's default noise: scale_data.py calls
    this before it claims --out."""
    for emb, path in given.items():
        if path is not None:
            check_given(emb, path, episodes=episodes, seed=seed, noise=emb.default_noise)


_GIVEN: dict[tuple, str] = {}  # sets already checked in this process: the early check and the wrangle's


def check_given(emb, path: Path, *, episodes: int, seed: int, noise: float) -> str:
    """A set named by --pusht_data/--aloha_data, checked and never modified; a problem is a DataError.

    scale_data.py checks it before --out is claimed (so a typo leaves the last run's results intact)
    and again in the wrangle region, where the first check's answer is reused."""
    path = Path(path)
    key = (emb.name, str(path.resolve()), episodes, seed, noise)
    if key in _GIVEN:
        return _GIVEN[key]
    m = emb.spec
    want = stamp_for(emb, episodes=episodes, seed=seed, noise=noise, video=False)
    stamp = read_stamp(path)
    ours = is_ours(stamp) and "kind" not in stamp  # a set gen_demos made (stamp_for); others have a kind
    matches = ours and all(stamp.get(k) == v for k, v in want.items())
    changed = changed_files(path, stamp) if matches else []  # missing, truncated or edited since written
    if not holds_data(path):
        raise DataError(f"{path} does not exist or is empty; generate it with gen_demos_{emb.name}.py first")
    if not path.is_dir():
        raise DataError(f"{path} is a file, not a LeRobot dataset folder")
    if ours and not matches:
        diff = ", ".join(f"{k}={stamp.get(k)} (need {v})" for k, v in want.items() if stamp.get(k) != v)
        raise DataError(f"{path} does not match this run: {diff}; pass matching flags or another set")
    if changed:
        raise DataError(
            f"{path} is damaged: {', '.join(changed[:3])} changed since it was written; "
            f"regenerate it with gen_demos_{emb.name}.py (it was not modified)"
        )
    if is_ours(stamp) and stamp.get("kind") == "engine" and not stamp.get("complete"):
        raise DataError(f"{path} is an unfinished augment_demos.py run; finish it with the same command")
    problem = schema_problem(path, len(m.state_names), len(m.action_names))
    if not problem and not ours:  # a set we did not generate: its rate and frames are checked
        problem = fps_problem(path, m.fps) or frames_problem(
            path, load_arrays(path, keys=("observation.state", "action"))
        )
    if problem:
        raise DataError(problem)
    _GIVEN[key] = "matches its stamp" if ours else "your own set, used as given"
    return _GIVEN[key]
