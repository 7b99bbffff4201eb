"""The generation report: attempts, kept, yield, failures by reason, episode lengths and yield per
source, summed from the shard stamps (report_of: a resumed run reports the whole run), beside what the
run was (describe) and its timing (datagen.run). It is OUT/generation_report.json, written last, with
the stamp that says the run is complete (datagen.resume.complete): a re-run of a complete run returns it."""

from __future__ import annotations

import platform
import shlex
import sys
from collections import Counter
from importlib.metadata import version
from pathlib import Path

import numpy as np

from datagen.plan import RunConfig

REPORT_NAME = "generation_report.json"


def length_stats(hist: dict) -> dict:
    """min, max, mean, median and p90 of episode lengths from {length: count}."""
    if not hist:
        return {}
    x = np.repeat([int(n) for n in hist], list(hist.values()))
    return {
        "min": int(x.min()),
        "max": int(x.max()),
        "mean": float(x.mean()),
        "median": float(np.median(x)),
        "p90": float(np.quantile(x, 0.9)),
    }


def report_of(stamps: list[dict], failures_known, base: dict) -> dict:
    """The generation report from the shard stamps (so a resumed run reports the whole run)."""
    failures, lengths = Counter(dict.fromkeys(failures_known, 0)), Counter()
    per_source = {}  # source episode -> [attempts, kept]
    for st in stamps:
        failures.update(st["failures"])
        lengths.update(st["lengths"])
        for e, (att, kept) in st["per_source"].items():
            t = per_source.setdefault(e, [0, 0])
            t[0], t[1] = t[0] + att, t[1] + kept
    attempts, kept = sum(st["attempts"] for st in stamps), sum(st["kept"] for st in stamps)
    return base | {
        "attempts": attempts,
        "kept": kept,
        "yield": kept / attempts if attempts else 0.0,
        "failures": dict(failures),
        "frames": sum(st["frames"] for st in stamps),
        "episode_length": length_stats(lengths),
        "per_source": {
            e: {"attempts": a, "kept": k, "yield": k / a}
            for e, (a, k) in sorted(per_source.items(), key=lambda kv: int(kv[0]))
        },
    }


def describe(src: Path, out: Path, config: RunConfig, *, ray: str | None, episodes: int) -> dict:
    """The report's fields that say what the run was: its source, settings, command and versions (Ray's
    too when it ran on Ray), and how to load the merged set of `episodes` episodes."""
    vers = {"python": platform.python_version(), **config.versions}
    if ray is not None:
        vers["ray"] = version("ray")
    return {
        "task": config.task,  # the engine task the source was grown as (datagen.source_check.task_of)
        "source": {"path": str(src.resolve()), **config.source},
        "settings": config.settings.stored(),
        "command": " ".join(shlex.quote(x) for x in [Path(sys.executable).name, *sys.argv]),
        "versions": vers,
        "dataset": {  # pyav: torchcodec without system FFmpeg logs a long traceback before falling back
            "episodes": episodes,
            "load": f"LeRobotDataset('local/{config.task}_aug', root='{out}', video_backend='pyav')",
        },
    }
