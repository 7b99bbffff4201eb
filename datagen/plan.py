"""A run's plan: its settings (as the engine names them and as its stamps store them), their key, the
packages whose versions can change its bytes, the attempts cut into shards, and the memory that cut needs.

    SETTINGS, stored(settings), attempts_per_demo(config)   the settings and their stored names
    run_key(config), versions(task)                         what every shard's stamp carries
    plan(episodes, attempts_per_demo, shard_size)           the attempts (e, k), cut into shards
    plan_memory_problem(n_sources, attempts_per_demo, free) whether that cut fits in memory

The attempts (source episode e, k) are listed e-major and cut into shards of `shard_size` attempts, so a
shard's contents depend on the run's settings alone, never on the worker count or the executor.
"""

from __future__ import annotations

import functools
import hashlib
import json
from importlib.metadata import version

# A run's settings in the engine's names (augment_demos.py maps its flags onto them): attempts_per_demo is
# the attempts per source episode, every one made (datagen.engine.grow's per_source counts kept demos).
SETTINGS = ("mode", "select", "attempts_per_demo", "seed", "pos_sigma", "yaw_sigma", "shard_size")
# How a run's stamps and its report store them (OUT's stamp, every shard's, generation_report.json; a
# resume compares them): attempts_per_demo under its first name "per_demo", kept so that what a run
# writes stays the same bytes, for readers of earlier runs. Nothing but this mapping reads "per_demo".
STORED = {"attempts_per_demo": "per_demo"}
STORED_SETTINGS = tuple(STORED.get(k, k) for k in SETTINGS)


def stored(settings: dict) -> dict:
    """`settings` (SETTINGS' names) as a run's stamps store them (STORED_SETTINGS' names)."""
    return {STORED.get(k, k): v for k, v in settings.items()}


def attempts_per_demo(config: dict) -> int:
    """The attempts per source episode of a run's stored config."""
    return config[STORED["attempts_per_demo"]]


def run_key(config: dict) -> str:
    """A short digest of a run's settings; every shard stamp carries it."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:16]


def versions(task=None) -> dict:
    """The packages whose versions can change a shard's bytes: LeRobot's writer, MuJoCo, numpy, pyarrow,
    and the task's own simulator packages (task.spec.packages: gym-pusht's pymunk). Read once per process:
    every shard's stamp names them, and each lookup parses the package's metadata, ~5 ms."""
    return dict(_versions(tuple(task.spec.packages) if task is not None else ()))


@functools.cache
def _versions(extra: tuple) -> tuple:
    names = ("lerobot", "mujoco", "numpy", "pyarrow") + tuple(n for n in extra if n != "mujoco")
    return tuple((name, version(name)) for name in names)


def plan(episodes, attempts_per_demo: int, shard_size: int) -> list[list[tuple[int, int]]]:
    """The attempts (e, k), e-major, cut into shards of shard_size (the last may be shorter)."""
    jobs = [(int(e), k) for e in episodes for k in range(attempts_per_demo)]
    return [jobs[i : i + shard_size] for i in range(0, len(jobs), shard_size)]


# Memory the plan holds per attempt (bytes): its (e, k) tuple and slot, about 100 B measured (docs/engine.md,
# "Figures behind constants"), doubled for the shard tasks and results that follow it.
ATTEMPT_BYTES = 200


def plan_memory_problem(
    n_sources: int, attempts_per_demo: int, free: int | None, flag: str = "--attempts_per_demo"
) -> str | None:
    """None if a plan of n_sources x attempts_per_demo attempts fits in `free` bytes (None: unknown), else
    why, naming the command's `flag` for attempts_per_demo."""
    attempts = n_sources * attempts_per_demo
    if free is None or attempts * ATTEMPT_BYTES <= free:
        return None
    return (
        f"{flag} {attempts_per_demo:,} x {n_sources} source episodes = {attempts:,} attempts need about "
        f"{attempts * ATTEMPT_BYTES / 2**30:,.1f} GB of memory to plan, more than the "
        f"{free / 2**30:,.1f} GB available here; lower {flag} (or run it in parts with --seed)"
    )
