"""A run's plan: its settings (one frozen object from the command line to the attempt loop, and as its
stamps store them), what else names the run, the packages whose versions can change its bytes, the
attempts cut into shards, and the memory that cut needs.

    Settings                                 augment_demos.py's flags in the engine's names
    RunConfig(settings, task, source, ...)   a run: its settings and what it grows; stored() for stamps
    run_key(config), versions(task)          what every shard's stamp carries
    plan(episodes, attempts_per_demo, shard_size)           the attempts (e, k), cut into shards
    plan_memory_problem(n_sources, attempts_per_demo, free) whether that cut fits in memory

The attempts (source episode e, k) are listed e-major and cut into shards of `shard_size` attempts, so a
shard's contents depend on the run's settings alone, never on the worker count or the executor.
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import asdict, dataclass
from importlib.metadata import version

from datagen.task import Perturbation


@dataclass(frozen=True)
class Settings:
    """A run's settings in the engine's names (augment_demos.py maps its flags onto them), passed as they
    are from the command line down to the attempt loop (datagen.shards.make_shard)."""

    mode: str  # resolve, replay or replay_live (datagen.lockstep.mode_parts)
    select: str  # the source a replay transforms: own or nearest
    attempts_per_demo: int  # attempts per source episode, every one made (engine.grow's per_source: kept)
    seed: int  # of the perturbations (ch37.seeds: disjoint per seed)
    pos_sigma: float  # m (the task's length unit): the perturbation's position spread
    yaw_sigma: float  # rad: its rotation spread
    shard_size: int  # attempts per shard

    @property
    def perturbation(self) -> Perturbation:
        return Perturbation(self.seed, self.pos_sigma, self.yaw_sigma)

    def stored(self) -> dict:
        """As a run's stamps and its report store them (attempts_per_demo under STORED's name)."""
        return {STORED.get(k, k): v for k, v in asdict(self).items()}


# How a run's stamps and its report store them (OUT's stamp, every shard's, generation_report.json; a
# resume compares them): attempts_per_demo under its first name "per_demo", kept so that what a run
# writes stays the same bytes, for readers of earlier runs. Nothing but this mapping reads "per_demo".
STORED = {"attempts_per_demo": "per_demo"}


@dataclass(frozen=True)
class RunConfig:
    """A run: its settings and what it grows (the task's name, the source's identity: datagen.source_check),
    with the engine's code digest and the package versions (versions) that could change its bytes. Its
    stored() form is what the run's stamp holds (a resume compares it) and run_key digests."""

    settings: Settings
    task: str
    source: dict
    engine: str
    versions: dict

    def stored(self) -> dict:
        return self.settings.stored() | {
            "task": self.task,
            "source": self.source,
            "engine": self.engine,
            "versions": self.versions,
        }


def run_key(config: RunConfig) -> str:
    """A short digest of a run's stored config; every shard stamp carries it."""
    return hashlib.sha256(json.dumps(config.stored(), sort_keys=True).encode()).hexdigest()[:16]


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
