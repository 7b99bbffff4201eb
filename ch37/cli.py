"""scale_data.py's flags checked in one call, the device picked, and the two-line banner."""

from __future__ import annotations

import argparse
import csv
import math
import os
from pathlib import Path

from ch37 import ROOT
from ch37.errors import fail

# wallclock.csv's tiers: two CPU-side ones, then GPUs matched by a substring of the device name.
GPU_TIERS = ("t4", "l4", "4090", "a100", "h100", "h200")
TIERS = ("cpu-2core", "mps", *GPU_TIERS)
SMOKE_DEFAULTS = dict(
    source_episodes=4, aug_per_demo=2, epochs=30, hidden_dim=64, eval_episodes=8, batch_size=64, device="cpu"
)
POSITIVE = ("source_episodes", "epochs", "batch_size", "hidden_dim", "eval_episodes", "workers")
NON_NEGATIVE = ("aug_per_demo", "seed", "full_steps")
FINITE = ("aug_pos_sigma", "aug_yaw_sigma", "lr")
NOT_IN_KEY = ("out", "cache", "workers")  # where results go and how fast they come never change them


def result_config(args: argparse.Namespace) -> dict:
    """The flags that shape the results, as metrics.json records them (paths as strings)."""
    return {
        k: (str(v) if isinstance(v, Path) else v)
        for k, v in sorted(vars(args).items())
        if k not in NOT_IN_KEY
    }


def parse(p: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse and check scale_data.py's flags; any problem is one line and exit 2.

    --smoke pins a tiny CPU configuration (the same on every machine); flags given explicitly win."""
    p.error = lambda msg: fail(f"{msg} (see --help)")
    args = p.parse_args(argv)
    if args.smoke:
        p.set_defaults(**SMOKE_DEFAULTS)
        args = p.parse_args(argv)
    args.out = args.out or Path("outputs/ch3.7-scale-data" + ("-smoke" if args.smoke else ""))
    args.workers = args.workers or min(8, os.cpu_count() or 1)
    for name in POSITIVE:
        if getattr(args, name) <= 0:
            fail(f"--{name} must be a positive integer, got {getattr(args, name)}")
    for name in NON_NEGATIVE:
        if getattr(args, name) < 0:
            fail(f"--{name} must be >= 0, got {getattr(args, name)}")
    for name in FINITE:
        v = getattr(args, name)
        if not math.isfinite(v) or v < 0 or (name == "lr" and v == 0):
            kind = "positive" if name == "lr" else "non-negative"
            fail(f"--{name} must be a finite {kind} number, got {v}")
    if args.device not in ("auto", "cpu", "cuda", "mps"):
        fail(f"--device must be auto, cpu, cuda or mps, got {args.device!r}")
    return args


def pick_device(name: str) -> str:
    """auto -> cuda > mps > cpu; a named device that is not here is one line and exit 2."""
    import torch

    available = {"cpu": True, "cuda": torch.cuda.is_available(), "mps": torch.backends.mps.is_available()}
    if name == "auto":
        return next(d for d in ("cuda", "mps", "cpu") if available[d])
    if not available[name]:
        fail(f"--device {name} is not available on this machine; use --device cpu or auto")
    return name


def device_tier(device: str) -> str:
    """wallclock.csv tier name for the device in use."""
    if device == "cuda":
        import torch

        name = torch.cuda.get_device_name(0).lower()
        return next((t for t in GPU_TIERS if t in name), "cuda-other")
    return {"mps": "mps"}.get(device, "cpu-2core")


def expected_wallclock(tier: str, csv_path: Path = ROOT / "wallclock.csv") -> str:
    try:
        rows = list(csv.DictReader(csv_path.open()))
    except OSError:
        rows = []
    for r in rows:
        if r.get("tier") == tier and r.get("status") == "measured":
            minutes, date = float(r["minutes"]), r["date"]
            return f"about {minutes:.1f} min for the default run (wallclock.csv, measured {date})"
    return "default-run wall-clock not yet measured for this tier"


def banner(args: argparse.Namespace) -> None:
    """Two lines: what runs where, and how long the default run takes on this tier."""
    import torch

    tier = device_tier(args.device)
    print(
        f"ch3.7 Datasets at Scale | seed {args.seed} | device {args.device} ({tier}) "
        f"| torch {torch.__version__}"
    )
    print(
        "smoke run: tiny configuration, seconds, numbers not meaningful"
        if args.smoke
        else expected_wallclock(tier)
    )
