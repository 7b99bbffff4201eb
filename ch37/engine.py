"""The data engine's unit of work: one attempt = perturb a source start, re-solve it, keep it if it succeeds.

    attempt(source, k, seed=, pos_sigma=, yaw_sigma=, mode="resolve") -> a kept episode or a reason

is a pure function of its arguments: attempt k of source episode e draws from its own generator,
np.random.default_rng([env_seed(seed, "aug", e), k]), and the sim is fully reset at the perturbed
start, so the result never depends on which process runs it, in what order, or with what else.
scale_data.py's augment region and augment_demos.py (through ch37.shards) call the same function.

The three moves of mode "resolve":
  1. perturb   block x, y and pusher x, y get Gaussian noise of pos_sigma (m), block yaw of
               yaw_sigma (rad); the block must stay on the band R_LO..R_HI m from the target and
               the pusher inside its square and clear of the T (up to TRIES draws, else no_valid_start)
  2. re-solve  env.set_start at that start, then the noise-free PushTExpert to the end of the episode
  3. keep      only if the env reports success (else expert_failed); the kept episode carries its
               provenance on every frame: aug.source_episode and aug.start (the start it was solved from)

A second mode (MimicGen's replay of the source path in the perturbed block frame) is one more entry
in MODES with its own failure reasons; Source already carries the source demo's whole path for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import pusht_env
from ch37.demos import rollout
from ch37.seeds import env_seed
from scripted_expert import PushTExpert

R_LO, R_HI = 0.08, 0.26  # m; the block is kept on a band slightly wider than the spawn annulus
TRIES = 100  # perturbation draws per attempt before giving up with "no_valid_start"
START_NAMES = ("block_x", "block_y", "block_yaw", "pusher_x", "pusher_y")  # what env.set_start takes
PROVENANCE = {  # LeRobot features stored on every frame of a kept episode
    "aug.source_episode": {"dtype": "int64", "shape": (1,), "names": None},
    "aug.start": {"dtype": "float32", "shape": (len(START_NAMES),), "names": list(START_NAMES)},
}


@dataclass(frozen=True)
class Source:
    """One source demo: its episode index in the source set and its frames, in order."""

    episode: int
    states: np.ndarray  # (T, 10) observation.state; resolve reads only the first row
    actions: np.ndarray  # (T, 2) action; kept for modes that reuse the source path


def sources(arrays: dict) -> dict[int, Source]:
    """{episode index: Source} from load_arrays' columns (observation.state, action, episode_index)."""
    out = {}
    for e in np.unique(arrays["episode_index"]):
        rows = np.flatnonzero(arrays["episode_index"] == e)
        out[int(e)] = Source(int(e), arrays["observation.state"][rows], arrays["action"][rows])
    return out


def attempt_rng(seed: int, episode: int, k: int) -> np.random.Generator:
    """The generator of attempt k of source episode `episode`: its own stream, whatever else runs."""
    return np.random.default_rng([env_seed(seed, "aug", episode), k])


def perturbed_start(first_state, rng, pos_sigma: float, yaw_sigma: float, tries: int = TRIES):
    """(block x, y, yaw, pusher x, y) near the start `first_state` (an obs), or None if no draw was valid."""
    px, py, bx, by, s, c = (float(v) for v in first_state[:6])
    for _ in range(tries):
        nbx, nby = bx + rng.normal(0, pos_sigma), by + rng.normal(0, pos_sigma)
        yaw = math.atan2(s, c) + rng.normal(0, yaw_sigma)
        npx, npy = np.clip(
            [px + rng.normal(0, pos_sigma), py + rng.normal(0, pos_sigma)],
            -pusht_env.PUSHER_HALF,
            pusht_env.PUSHER_HALF,
        )
        if R_LO <= math.hypot(nbx, nby) <= R_HI and pusht_env.pusher_clear(nbx, nby, yaw, npx, npy):
            return (nbx, nby, math.atan2(math.sin(yaw), math.cos(yaw)), float(npx), float(npy))
    return None


def resolve(env, start) -> dict:
    """The noise-free expert's episode from `start` (see START_NAMES), in the real physics."""
    return rollout(env, PushTExpert(noise=0.0), env.set_start(*start))


def _resolve_mode(source: Source, rng, pos_sigma: float, yaw_sigma: float, env):
    start = perturbed_start(source.states[0], rng, pos_sigma, yaw_sigma)  # 1. perturb
    if start is None:
        return "no_valid_start"
    ep = resolve(env, start)  # 2. re-solve
    if not ep["success"]:  # 3. keep only on success
        return "expert_failed"
    return ep, start


MODES = {"resolve": _resolve_mode}  # mode -> (source, rng, pos_sigma, yaw_sigma, env) -> (ep, start) | reason
FAILURES = {"resolve": ("expert_failed", "no_valid_start")}  # every reason a mode can return

_ENV = None  # one simulator per process, fully reset by set_start before every attempt


def attempt(
    source: Source,
    k: int,
    *,
    seed: int,
    pos_sigma: float,
    yaw_sigma: float,
    mode: str = "resolve",
    env=None,
):
    """Attempt k from `source`: a kept episode (arrays per frame, with provenance) or a failure reason."""
    global _ENV
    if env is None:
        _ENV = _ENV or pusht_env.PushTEnv()
        env = _ENV
    got = MODES[mode](source, attempt_rng(seed, source.episode, k), pos_sigma, yaw_sigma, env)
    if isinstance(got, str):
        return got
    ep, start = got
    n = len(ep["action"])
    ep["aug.source_episode"] = np.full((n, 1), source.episode, np.int64)  # provenance, on every frame
    ep["aug.start"] = np.tile(np.float32(start), (n, 1))
    return ep


def write_kept(root, kept: list[dict], *, repo_id: str, stamp: dict) -> None:
    """Write kept episodes (with their provenance) to `root` as one LeRobot v3 PushT set."""
    from ch37.lerobot_io import features, write_dataset

    feats = features(pusht_env.STATE_NAMES, pusht_env.ACTION_NAMES, PROVENANCE)
    write_dataset(root, repo_id=repo_id, fps=pusht_env.FPS, robot_type=pusht_env.ROBOT_TYPE,
                  task=pusht_env.TASK, feats=feats, episodes=kept, stamp=stamp)  # fmt: skip
