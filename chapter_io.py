"""Plumbing for scale_data.py: the demo cache, atomic writes, the wall-clock banner.

None of this is the lesson; it keeps the chapter's regions short and keeps user data safe:
a directory is deleted only when a stamp written by this project says the project made it.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import sys
from pathlib import Path

import demo_data
import demo_gen

ROOT = Path(__file__).resolve().parent


def fail(msg: str, code: int = 2):
    """One clear line on stderr and a non-zero exit: the contract for bad input."""
    print(f"error: {msg}", file=sys.stderr)
    sys.exit(code)


def ensure_demos(emb, path: Path, *, user_given: bool, episodes: int, seed: int, noise: float,
                 quiet: bool) -> str:
    """Make sure `path` holds the demo set this run needs; return how it was obtained.

    user_given: a set named by --pusht_data/--aloha_data. It is never modified. A set stamped by
    this project must match the request; an unstamped set must have the right schema and is used
    as given. Otherwise (our private cache) a stale set we made is rebuilt, and a directory we did
    not make is refused.
    """
    m = emb.env_module
    want = demo_gen.stamp_for(emb, episodes=episodes, seed=seed, noise=noise, video=False)
    stamp = demo_data.read_stamp(path)
    ours = stamp is not None and stamp.get("made_by") == want["made_by"]
    if user_given:
        if not demo_data.holds_data(path):
            raise demo_data.DataError(f"{path} does not exist or is empty; generate it with gen_demos_{emb.name}.py first")
        if ours and stamp != want:
            diff = ", ".join(f"{k}={stamp.get(k)} (need {v})" for k, v in want.items() if stamp.get(k) != v)
            raise demo_data.DataError(f"{path} does not match this run: {diff}; pass matching flags or another set")
        problem = demo_data.schema_problem(path, len(m.STATE_NAMES), len(m.ACTION_NAMES))
        if problem:
            raise demo_data.DataError(problem)
        return "matches its stamp" if ours else "your own set, used as given"
    if ours and stamp == want:
        return "cached"
    if demo_data.holds_data(path) and not ours:
        raise demo_data.DataError(f"{path} holds data this program did not make; move it or pass another --out")
    if ours:
        shutil.rmtree(path)  # stale set that this project made itself: rebuild it
    s = demo_gen.generate(emb, path, episodes=episodes, seed=seed, noise=noise, quiet=quiet)
    return f"generated ({s['successes']}/{s['episodes']} expert successes)"


def replace_own_dir(path: Path) -> None:
    """Clear `path` for rewriting if this project made it; refuse if it holds anything else."""
    if not demo_data.holds_data(path):
        return
    stamp = demo_data.read_stamp(path)
    if stamp is None or stamp.get("made_by") != "ch3.7-scale-data":
        raise demo_data.DataError(f"{path} holds data this program did not make; move it or pass another --out")
    shutil.rmtree(path)


def write_atomic(path: Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def dump_json(obj) -> str:
    return json.dumps(obj, sort_keys=True, indent=1) + "\n"


def round_floats(obj, digits: int = 4):
    """Round every float in a nested structure so metrics.json is stable and readable."""
    if isinstance(obj, float):
        return round(obj, digits)
    if isinstance(obj, dict):
        return {k: round_floats(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [round_floats(v, digits) for v in obj]
    return obj


def device_tier(device: str) -> str:
    """wallclock.csv tier name for the device in use."""
    if device == "cuda":
        import torch

        name = torch.cuda.get_device_name(0).lower()
        for tier in ("t4", "4090", "a100", "h100", "h200", "l4"):
            if tier in name:
                return tier
        return "cuda-other"
    return {"mps": "mps"}.get(device, "cpu-2core")


def expected_wallclock(tier: str, csv_path: Path = ROOT / "wallclock.csv") -> str:
    try:
        rows = list(csv.DictReader(csv_path.open()))
    except OSError:
        rows = []
    for r in rows:
        if r.get("tier") == tier and r.get("status") == "measured":
            return f"about {float(r['minutes']):.1f} min for the default run (wallclock.csv, measured {r['date']})"
    return "default-run wall-clock not yet measured for this tier"
