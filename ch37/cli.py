"""scale_data.py's flags checked in one call, the device picked, and the two-line banner."""

from __future__ import annotations

import argparse
import csv
import os
from pathlib import Path

from ch37 import ROOT, config
from ch37.errors import DataError
from ch37.seeds import MAX_SEED, SEED_BLOCK

# wallclock.csv's tiers: two CPU-side ones, then GPUs matched by a substring of the device name.
GPU_TIERS = ("t4", "l4", "4090", "a100", "h100", "h200")
TIERS = ("cpu-2core", "mps", *GPU_TIERS)
POSITIVE = ("source_episodes", "epochs", "batch_size", "hidden_dim", "eval_episodes", "workers", "aug_tries")
NON_NEGATIVE = ("aug_per_demo", "seed", "full_steps")
FINITE = ("aug_pos_sigma", "aug_yaw_sigma", "lr")
# Upper bounds that come from the code: episode indices live in one seed block (ch37.seeds), and
# every env seed must fit in 63 bits. The step limits bound a run's frames for the memory estimate.
# --epochs and --full_steps cost time, not memory: a huge value runs long (Ctrl-C stops it cleanly).
AT_MOST = {"seed": MAX_SEED, "source_episodes": SEED_BLOCK, "eval_episodes": SEED_BLOCK, "lr": 1.0}
AT_MOST.update(aug_pos_sigma=config.SIGMA_MAX, aug_yaw_sigma=config.SIGMA_MAX)
PUSHT_MAX_STEPS, ALOHA_MAX_STEPS = 300, 400  # pusht_env.MAX_STEPS, aloha_env.MAX_STEPS (not imported: slow)
ENV_BYTES = 1 << 20  # one evaluation env (a MuJoCo model and data): about 0.6 MB measured


def max_workers() -> int:
    return max(8, 4 * (os.cpu_count() or 1))


def available_memory() -> int | None:
    """Bytes of RAM available now (Linux MemAvailable, else total physical memory), None if unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def memory_estimate(args: argparse.Namespace) -> dict[str, int]:
    """Bytes a run needs at most, per flag that drives it (every episode at its step limit)."""
    frames = args.source_episodes * ((1 + args.aug_per_demo) * PUSHT_MAX_STEPS + ALOHA_MAX_STEPS)
    h, arms = args.hidden_dim, 2  # the two data arms of a budget train side by side (measure)
    params = h * h + 14 * h + 2  # 10 -> h -> h -> 2
    act_row = (2 * h + 12) * 4 * 3  # one row through the net: activations and their gradients, float32
    return {
        "--source_episodes/--aug_per_demo": frames * 1024,  # ~10 copies of a frame's ~100 bytes
        # per arm: weights, gradient, Adam's two moments, its policy's copy; plus the initial weights
        "--hidden_dim": params * 4 * (5 * arms + 2) + (frames + args.eval_episodes) * act_row,
        "--batch_size": args.batch_size * arms * (act_row + 8 + 48),  # a batch: rows, indices, activations
        "--eval_episodes": args.eval_episodes * ENV_BYTES,
    }


def _gb(n: float) -> str:
    return f"{n / 2**30:,.1f} GB" if n >= 2**30 else f"{n / 2**20:,.0f} MB"


def result_config(args: argparse.Namespace) -> dict:
    """The flags that shape the results, as metrics.json records them (paths as strings)."""
    items = sorted(vars(args).items())
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in items if k not in config.NOT_IN_KEY}


def parse(p: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse and check scale_data.py's flags (`p` from ch37.config.parser); a problem is a DataError.

    --smoke pins a tiny CPU configuration (the same on every machine); flags given explicitly win."""
    args = p.parse_args(argv)
    if args.smoke:
        p.set_defaults(**config.SMOKE)
        args = p.parse_args(argv)
    args.out = args.out or Path("outputs/ch3.7-scale-data" + ("-smoke" if args.smoke else ""))
    if args.workers is None:  # None, not 0: --workers 0 is an error below, not "the default"
        args.workers = min(8, os.cpu_count() or 1)
    config.check(args, positive=POSITIVE, non_negative=NON_NEGATIVE, finite=FINITE, at_most=AT_MOST)
    if args.workers > max_workers():
        raise DataError(f"--workers must be at most {max_workers()} (4 per CPU core), got {args.workers}")
    if args.device not in ("auto", "cpu", "cuda", "mps"):
        raise DataError(f"--device must be auto, cpu, cuda or mps, got {args.device!r}")
    need, free = memory_estimate(args), available_memory()
    if free is not None and sum(need.values()) > free:
        worst = max(need, key=need.get)
        raise DataError(
            f"this configuration needs up to {_gb(sum(need.values()))} of memory, more than the "
            f"{_gb(free)} available here (most of it from {worst}); lower {worst}"
        )
    return args


def aug_dir_name(seed, n_sources, per_demo, mode: str) -> str:
    """The augment region's folder under OUT/demos (re-solve's name has no mode suffix)."""
    return f"pusht_aug_seed{seed}_src{n_sources}_k{per_demo}" + ("" if mode == "resolve" else f"_{mode}")


def check_inputs(args: argparse.Namespace) -> None:
    """Your --pusht_data and --aloha_data checked as the wrangle region will read them (ch37.demos
    .check_given), before claim_out clears anything: a typo is one line, the last results intact."""
    from ch37.demos import check_given
    from gen_demos_aloha import ALOHA
    from gen_demos_pusht import PUSHT

    for emb, given in ((PUSHT, args.pusht_data), (ALOHA, args.aloha_data)):
        if given is not None:
            check_given(emb, given, episodes=args.source_episodes, seed=args.seed, noise=emb.default_noise)


def claim_out(args: argparse.Namespace):
    """--out taken for this run before any work (ch37.files.claim): every input checked first
    (check_inputs), then usable, locked against a second run, nothing of yours where this run
    writes, this program's earlier results there cleared."""
    from ch37.files import claim

    check_inputs(args)

    demos = Path(args.out) / "demos"
    reuses = [
        demos / f"{name}_seed{args.seed}_ep{args.source_episodes}"  # the names the wrangle region uses
        for name, given in (("pusht", args.pusht_data), ("aloha", args.aloha_data))
        if given is None
    ]
    replaces = sorted(demos.glob(aug_dir_name(args.seed, "*", args.aug_per_demo, args.aug_mode)))  # augment's
    inputs = {"--pusht_data": args.pusht_data, "--aloha_data": args.aloha_data}
    return claim(args.out, inputs=inputs, results=config.RESULT_FILES, reuses=reuses, replaces=replaces)


def pick_device(name: str) -> str:
    """auto -> cuda > mps > cpu; a named device that is not here is one line and exit 2."""
    import torch

    available = {"cpu": True, "cuda": torch.cuda.is_available(), "mps": torch.backends.mps.is_available()}
    if name == "auto":
        return next(d for d in ("cuda", "mps", "cpu") if available[d])
    if not available[name]:
        raise DataError(f"--device {name} is not available on this machine; use --device cpu or auto")
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
    head = f"ch3.7 Datasets at Scale | seed {args.seed} | device {args.device} ({tier})"
    print(f"{head} | torch {torch.__version__}")
    smoke = "smoke run: tiny configuration, seconds, numbers not meaningful"
    print(smoke if args.smoke else expected_wallclock(tier))
