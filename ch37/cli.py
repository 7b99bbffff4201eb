"""scale_data.py's flags checked in one call, the device picked, and the two-line banner."""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import platform
from pathlib import Path

from ch37 import ROOT, config
from ch37.errors import DataError
from ch37.process import available_memory, has_avx2_fma, max_workers

# wallclock.csv's tiers: a CPU's is named from the machine (cpu_tier: cpu-<cores>core-<vendor>, one row per
# kind of machine measured); the fixed ones are Apple's GPU, then GPUs matched by a substring of the
# device name (a pending row each until measured).
GPU_TIERS = ("t4", "l4", "4090", "a100", "h100", "h200")
TIERS = ("mps", *GPU_TIERS)
# /proc/cpuinfo's vendor_id (x86) and "CPU implementer" (ARM, hex) -> the vendor in a CPU tier's name
CPU_VENDORS = {
    "GenuineIntel": "intel",
    "AuthenticAMD": "amd",
    "HygonGenuine": "hygon",
    "0x41": "arm",
    "0x4e": "nvidia",
    "0x51": "qualcomm",
    "0x61": "apple",
    "0xc0": "ampere",
}
# not in config_hash: the tier names the device; workers, cache and the .rrd change speed only
HASH_EXCLUDE = ("device", "workers", "cache", "rerun")
# Every flag's bound is declared with the flag (ch37.config.flag): the experiment's in config.Chapter,
# the run's in scale_data.py's Args. --epochs and --full_steps cost time, not memory: a huge value runs
# long (Ctrl-C stops it cleanly). The step limits bound a run's frames for the memory estimate.
PUSHT_MAX_STEPS, ALOHA_MAX_STEPS = 300, 400  # pusht_env.MAX_STEPS, aloha_env.MAX_STEPS (not imported: slow)
PUSHT_OBS_DIM, PUSHT_ACT_DIM = 10, 2  # pusht_env.OBS_DIM, ACT_DIM: the step probe's network
ENV_BYTES = 1 << 20  # one evaluation env (a MuJoCo model and data), rounded up (docs/engine.md, figures)


def memory_estimate(args: argparse.Namespace) -> dict[str, int]:
    """Bytes a run needs at most, per flag that drives it (every episode at its step limit)."""
    frames = args.source_episodes * ((1 + args.aug_per_demo) * PUSHT_MAX_STEPS + ALOHA_MAX_STEPS)
    return training_memory(args, frames, "--source_episodes/--aug_per_demo", arms=2)  # measure's two arms


def training_memory(args: argparse.Namespace, frames: int, data_flags: str, arms: int) -> dict[str, int]:
    """Bytes the BC recipe needs at most to train `arms` side by side on `frames` frames (the flags
    `data_flags` set them) and evaluate on args.eval_episodes starts, per flag that drives it."""
    h = args.hidden_dim
    params = h * h + 14 * h + 2  # 10 -> h -> h -> 2
    act_row = (2 * h + 12) * 4 * 3  # one row through the net: activations and their gradients, float32
    return {
        # ~10 copies of a frame's ~100 bytes, and each frame once through the net (the final fit)
        data_flags: frames * (1024 + act_row),
        # per arm: weights, gradient, Adam's two moments, its policy's copy; plus the initial weights
        "--hidden_dim": params * 4 * (5 * arms + 2) + args.eval_episodes * act_row,
        "--batch_size": args.batch_size * arms * (act_row + 8 + 48),  # a batch: rows, indices, activations
        "--eval_episodes": args.eval_episodes * ENV_BYTES,
    }


def check_memory(need: dict[str, int]) -> None:
    """DataError (one line) when `need` ({flag: bytes}) is more than the memory available here, naming
    the flag that drives most of it."""
    free, total = available_memory(), sum(need.values())
    if free is not None and total > free:
        worst = max(need, key=need.get)
        raise DataError(
            f"this configuration needs up to {_gb(total)} of memory, more than the "
            f"{_gb(free)} available here (most of it from {worst}); lower {worst}"
        )


def _gb(n: float) -> str:
    return f"{n / 2**30:,.1f} GB" if n >= 2**30 else f"{n / 2**20:,.0f} MB"


def result_config(args: argparse.Namespace) -> dict:
    """The flags that shape the results, as metrics.json records them (paths as strings)."""
    items = sorted(vars(args).items())
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in items if k not in config.NOT_IN_KEY}


def parse(cls, argv=None) -> argparse.Namespace:
    """Parse and check scale_data.py's flags (`cls`: its Args dataclass); a problem is a DataError.

    --smoke pins a tiny CPU configuration (the same on every machine); flags given explicitly win."""
    args = config.parse(cls, argv, smoke=config.SMOKE)
    args.out = args.out or Path("outputs/ch3.7-scale-data" + ("-smoke" if args.smoke else ""))
    if args.workers is None:  # None, not 0: --workers 0 was an error above, not "the default"
        args.workers = config.default_workers()
    if args.workers > max_workers():
        raise DataError(f"--workers must be at most {max_workers()} (4 per CPU core), got {args.workers}")
    if args.device not in ("auto", "cpu", "cuda", "mps"):
        raise DataError(f"--device must be auto, cpu, cuda or mps, got {args.device!r}")
    check_memory(memory_estimate(args))
    return args


def aug_dir_name(seed, n_sources, per_demo, mode: str) -> str:
    """The augment region's folder under OUT/demos (re-solve's name has no mode suffix)."""
    return f"pusht_aug_seed{seed}_src{n_sources}_k{per_demo}" + ("" if mode == "resolve" else f"_{mode}")


def claim_out(args: argparse.Namespace):
    """--out taken for this run before any work (ch37.ownership.claim), once the lesson has checked your
    inputs: usable, locked against a second run, nothing of yours where this run writes, this
    program's earlier results there cleared."""
    from ch37.ownership import claim

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


def cpuinfo_fields(cpuinfo: str) -> dict:
    """/proc/cpuinfo's text as {field: value}, each field's first value (the first processor's)."""
    fields = {}
    for line in cpuinfo.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())
    return fields


def cpu_tier(cores: int, cpuinfo: str = "", system: str = "", machine: str = "") -> str:
    """cpu-<cores>core-<vendor>, e.g. cpu-2core-amd, cpu-8core-intel, cpu-10core-apple: the vendor from
    /proc/cpuinfo's text (x86's vendor_id, ARM's CPU implementer), else on macOS from the architecture
    (arm64: Apple silicon, else Intel), else the architecture itself (cpu-4core-aarch64) or "unknown"."""
    fields = cpuinfo_fields(cpuinfo)
    vendor = CPU_VENDORS.get(fields.get("vendor_id") or fields.get("CPU implementer", "").lower())
    if vendor is None and system == "Darwin":
        vendor = "apple" if machine == "arm64" else "intel"
    return f"cpu-{cores}core-{vendor or machine.lower() or 'unknown'}"


def quota_cores(cpu_max: str) -> int | None:
    """The cores a cgroup v2 CPU quota allows (/sys/fs/cgroup/cpu.max: "QUOTA PERIOD", or "max PERIOD"
    for none), rounded up; None without a quota."""
    quota, _, period = cpu_max.strip().partition(" ")
    if not quota.isdigit() or not period.isdigit() or int(period) == 0:
        return None
    return max(1, -(-int(quota) // int(period)))


def usable_cores() -> int:
    """The cores this process may run on: its affinity (where the platform has one, else all of them),
    capped by a container's CPU quota (cgroup v2), as a container given 2 CPUs of a 64-core host has 2."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # macOS, Windows
        cores = os.cpu_count() or 1
    try:
        quota = quota_cores(Path("/sys/fs/cgroup/cpu.max").read_text())
    except OSError:  # no cgroup v2 here
        quota = None
    return min(cores, quota or cores)


def _cpuinfo() -> str:
    try:
        return Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:  # not Linux
        return ""


def device_tier(device: str) -> str:
    """wallclock.csv tier name for the device in use; a CPU's from this machine's cores and vendor."""
    if device == "cuda":
        import torch

        name = torch.cuda.get_device_name(0).lower()
        return next((t for t in GPU_TIERS if t in name), "cuda-other")
    if device == "mps":
        return "mps"
    return cpu_tier(usable_cores(), _cpuinfo(), platform.system(), platform.machine())


def cpu_model(cpuinfo: str) -> str:
    """A CPU's model from /proc/cpuinfo's text, as wallclock.csv's `cpu` column names it: its model name,
    family and model numbers ("AMD EPYC family 25 model 17": a cloud's EPYCs of two generations can share
    one name and differ twofold in speed); "" where the text names none (not Linux, not x86)."""
    fields = cpuinfo_fields(cpuinfo)
    name = fields.get("model name", "")
    numbers = " ".join(
        f"{k} {fields[f]}" for k, f in (("family", "cpu family"), ("model", "model")) if f in fields
    )
    return f"{name} {numbers}".strip() if name else ""


def this_cpu() -> str:
    """This machine's cpu_model (tools.wallclock records it in a CPU row; the banner compares)."""
    return cpu_model(_cpuinfo())


def config_hash(config: dict) -> str:
    """First 12 hex of sha256 over metrics.json's "config" less HASH_EXCLUDE, as sorted compact JSON:
    the configuration a wallclock.csv row was measured with (tools.wallclock writes it)."""
    c = {k: v for k, v in config.items() if k not in HASH_EXCLUDE}
    return hashlib.sha256(json.dumps(c, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:12]


# The sub-second probe behind the banner's estimate: PROBE_STEPS training steps at the run's shapes (the
# lesson's MLP stack, squared error, fused Adam, on random rows), taken as the run takes them
# (ch37.ensemble.arm_processes): each of two arms in a forked process of its own, set up as the run's are
# (arm_process_setup: its heap held, which moves a lone arm's step by a third), else both side by side in
# this one; each step timed, after PROBE_WARMUP untimed ones; the median step (a burst of other work slows
# only a few), of the slower process. Training is most of a default run on a CPU (tools.bench lesson), so
# a row's minutes scale from the machine that measured it to this one by their probes' ratio.
PROBE_STEPS, PROBE_WARMUP = 30, 3


def step_probe(hidden: int, batch: int, device: str = "cpu") -> float:
    """Milliseconds per training step of two arms (PushT's 10 -> hidden -> hidden -> 2 MLP, `batch` rows an
    arm) as the run trains them, on the kernel path in force here: about 0.2 s at the default shapes,
    after the warm-up (the first optimizer in a process pays torch's one-time set-up, as the run's first
    training would). Torch's random state is left as it was: the run after it draws what it would have."""
    from ch37.ensemble import arm_process_setup, arm_processes
    from ch37.parallel import map_jobs

    n = arm_processes(2, device)  # 2: one arm in each of two processes; 1: both arms here
    return max(
        map_jobs(
            _probe_steps, [(2 // n, hidden, batch, device)] * n, workers=n, star=True, setup=arm_process_setup
        )
    )


def _probe_steps(arms: int, hidden: int, batch: int, device: str) -> float:
    """step_probe's median ms a step of `arms` arms side by side in this process."""
    import statistics
    import time

    import torch

    from ch37.ensemble import stacked

    sizes = (PUSHT_OBS_DIM, hidden, hidden, PUSHT_ACT_DIM)
    times = []
    with torch.random.fork_rng(devices=[]):
        init = {}  # a Sequential's state dict: Linear layers 0, 2, 4 with ReLUs between
        for i, (n_in, n_out) in enumerate(zip(sizes, sizes[1:])):
            init[f"{2 * i}.weight"] = torch.randn(n_out, n_in) / n_in**0.5
            init[f"{2 * i}.bias"] = torch.zeros(n_out)
        # (arms, B, 10) states, (arms, B, 2) actions
        xb, yb = torch.randn(arms, batch, sizes[0]), torch.randn(arms, batch, sizes[-1])
        with stacked(init, arms, device) as model:
            opt = torch.optim.Adam(model.parameters(), lr=1e-3, fused=device in ("cpu", "cuda"))
            xb, yb = xb.to(device), yb.to(device)
            for _ in range(PROBE_WARMUP + PROBE_STEPS):
                t0 = time.perf_counter()
                loss = ((model(xb) - yb) ** 2).mean(dim=(1, 2)).sum()
                opt.zero_grad()
                loss.backward()
                opt.step()
                times.append(time.perf_counter() - t0)
    return statistics.median(times[PROBE_WARMUP:]) * 1e3


def expected_wallclock(
    tier: str,
    config: str,
    csv_path: Path = ROOT / "wallclock.csv",
    probe_ms: float | None = None,
    cpu: str = "",
) -> str:
    """The wall-clock a run of this configuration (config: its config_hash) should take here. A row of
    wallclock.csv measured on this configuration gives it; a CPU tier holds one row per CPU model measured
    (its `cpu`). A row of this tier measured on this very CPU model (cpu: this machine's cpu_model) is
    shown as it ran: a sub-second probe reads the moment it lands in, and on a shared VM that moves more
    than a whole run does (issue 59). Else, on a CPU with probe_ms (this machine's step_probe), the row
    whose probe is nearest this one's, of this tier or, where the tier is unmeasured, of any CPU tier,
    scaled by the two probes' ratio; else this tier's row as measured. Any other configuration may take
    much longer or shorter: no estimate."""
    try:
        rows = [r for r in csv.DictReader(csv_path.open()) if r.get("status") == "measured"]
    except OSError:
        rows = []
    mine = [r for r in rows if r.get("tier") == tier]  # one a CPU model measured in this tier
    if mine and not any(r.get("config_hash") == config for r in mine):
        return "wall-clock: measured for the default run only (wallclock.csv), not this configuration"
    mine = [r for r in mine if r.get("config_hash") == config]
    same = next((r for r in mine if cpu and r.get("cpu") == cpu), None)
    if same is not None:  # measured on this CPU model: as it ran
        minutes, date = float(same["minutes"]), same["date"]
        return (
            f"about {minutes:.1f} min here (wallclock.csv's {tier} row, measured {date} on this CPU: {cpu})"
        )
    # else the row nearest this probe in speed: of this tier, or on an unmeasured CPU of any CPU tier
    pool = mine or [r for r in rows if r["tier"].startswith("cpu-") and r.get("config_hash") == config]
    probed = [r for r in pool if _ms(r)] if probe_ms and tier.startswith("cpu-") else []
    nearest = min(probed, key=lambda r: abs(math.log(_ms(r) / probe_ms)), default=None)
    own = nearest or next(iter(mine), None)
    if own is None:
        return "default-run wall-clock not yet measured for this tier"
    minutes, date, row_ms = float(own["minutes"]), own["date"], _ms(own)
    if not (probe_ms and row_ms):  # nothing to scale by: the row as measured
        return f"about {minutes:.1f} min for this configuration (wallclock.csv, measured {date})"
    unmeasured = "this tier is unmeasured; " if own["tier"] != tier else ""
    return (
        f"about {minutes * probe_ms / row_ms:.1f} min here ({unmeasured}wallclock.csv's {own['tier']} row"
        f" took {minutes:.2f} min, measured {date} at {row_ms:.1f} ms a training step; a probe here:"
        f" {probe_ms:.1f} ms)"
    )


def _ms(row: dict) -> float | None:
    """A wallclock.csv row's probe (step_ms: step_probe on the machine that measured it), or None."""
    try:
        ms = float(row.get("step_ms") or "nan")
    except ValueError:
        return None
    return ms if math.isfinite(ms) and ms > 0 else None


READS = (ROOT / "meta.yaml",)  # the five-seed reference a run is placed beside: part of the result cache key


def five_seed_reference(run_config: dict, meta_path: Path = READS[0]) -> dict | None:
    """meta.yaml's reference_run over seeds (python -m tools.sweep --seeds 5): the data effect at the full
    budget, per seed and summarised, when this run's configuration is the swept one (any seed); else None.
    The sweep ran before --aug_mode and --aug_tries existed: it re-solved, and at yield 1.00 no cap bound."""
    import yaml

    try:
        ref = yaml.safe_load(meta_path.read_text())["reference_run"]["seeds"]
        swept = {"aug_mode": "resolve", "aug_tries": config.CHAPTER.aug_tries}
        swept |= ref["provenance"]["config"]
        rows, paired = ref["rows"], ref["paired"]["data_full"]
    except (OSError, KeyError, TypeError, yaml.YAMLError):
        return None
    if any(run_config.get(k) != v for k, v in swept.items() if k not in HASH_EXCLUDE):
        return None
    effects = {int(r["seed"]): float(r["data_full"]) for r in rows}
    return {
        "command": ref["provenance"]["command"],
        "effects": effects,
        "mean": float(paired["mean"]),
        "up": int(paired["wins"]),
        "n": int(paired["n"]),
    }


def reference_words(ref: dict | None, seed: int, effect: float) -> str:
    """One sentence placing this run's data effect (a success difference) among the five-seed reference's
    (five_seed_reference), or saying that the reference ran another configuration (ref None)."""
    if ref is None:
        return (
            "meta.yaml's five-seed reference ran the default configuration, not this one, so there is "
            "nothing to place this run beside (python -m tools.sweep --seeds 5 with these flags makes one)"
        )
    effects = ref["effects"]
    lo, hi = min(effects.values()), max(effects.values())
    seeds = ", ".join(map(str, sorted(effects)))
    text = (
        f"this run {effect * 100:+.0f} points beside the five-seed reference (meta.yaml, {ref['command']}): "
        f"mean {ref['mean'] * 100:+.1f} over seeds {seeds}, from {lo * 100:+.0f} to {hi * 100:+.0f}, "
        f"up on {ref['up']} of {ref['n']}"
    )
    # placed among the other seeds: the reference's own run of this seed is not another draw to beat
    others = {s: e for s, e in effects.items() if s != seed}
    counts = (
        (sum(e > effect + 1e-9 for e in others.values()), "below"),
        (sum(abs(e - effect) <= 1e-9 for e in others.values()), "tied with"),
        (sum(e < effect - 1e-9 for e in others.values()), "above"),
    )
    place = ", ".join(f"{word} {n}" for n, word in counts if n)
    text += f"; among the other seeds ({', '.join(map(str, sorted(others)))}) this run's effect is {place}"
    if effects.get(seed) is not None and abs(effects[seed] - effect) > 1e-9:
        text += f" (the reference's own seed {seed} gave {effects[seed] * 100:+.0f})"
    return text


# The kernel path the published numbers ran on, set by scale_data.py's setup region before numpy and torch
# load: an x86-64 CPU with AVX2 and FMA, the training's products on numpy's OpenBLAS held to these kernels
# (OPENBLAS_CORETYPE; ch37.ensemble), torch's others on MKL held to this branch (MKL_CBWR).
# docs/reproducibility.md says why and what it costs.
PUBLISHED_BLAS_CORE = "Haswell"
PUBLISHED_MKL_CBWR = "COMPATIBLE"
PUBLISHED_PATH = f"x86-64 CPU, OPENBLAS_CORETYPE={PUBLISHED_BLAS_CORE}, MKL_CBWR={PUBLISHED_MKL_CBWR}"


def kernel_path(environ=os.environ) -> dict[str, str]:
    """The variables that put this process on the published kernel path, less those already set (a
    value of yours is kept): scale_data.py's `os.environ.update(cli.kernel_path())`, before numpy and
    torch load (both read them once). Kernels round differently, and torch's MKL picks its own by the
    CPU's maker, so without them one seed would train another policy on another machine. OpenBLAS is
    held to its Haswell kernels only where the CPU has AVX2 and FMA (they fault without); elsewhere its
    own choice, another draw that the banner names (other_draw)."""
    want = {"MKL_CBWR": PUBLISHED_MKL_CBWR}
    if has_avx2_fma():
        want["OPENBLAS_CORETYPE"] = PUBLISHED_BLAS_CORE
    return {k: v for k, v in want.items() if k not in environ}


# MKL's branch codes (mkl_cbwr.h) as MKL_CBWR spells them; 1 (MKL_CBWR_BRANCH_OFF) is MKL_CBWR unset
MKL_BRANCHES = {1: "", 2: "AUTO", 3: "COMPATIBLE", 4: "SSE2", 6: "SSSE3", 7: "SSE4_1", 8: "SSE4_2", 9: "AVX"}
MKL_BRANCHES |= {10: "AVX2", 11: "AVX512_MIC", 12: "AVX512", 13: "AVX512_MIC_E1", 14: "AVX512_E1"}


def mkl_branch() -> str:
    """The MKL branch this process runs, as MKL_CBWR spells it ("" for MKL's own). MKL reads MKL_CBWR
    once, at its first use, and keeps that branch for the process: a value set later (a notebook's
    %env between two Run-alls) changes nothing, so MKL itself is asked (fixing its branch now, from
    MKL_CBWR as set, if it has not run yet). It falls back on its automatic choice for a branch this
    CPU lacks (AVX2 on AMD: AUTO). Without MKL (not x86-64, a torch built without it): MKL_CBWR as set."""
    import ctypes

    import torch

    try:  # torch's CPU library carries MKL and exports MKL's own service call
        get = ctypes.CDLL(str(Path(torch.__file__).parent / "lib" / "libtorch_cpu.so")).mkl_serv_cbwr_get
    except (OSError, AttributeError):
        return os.environ.get("MKL_CBWR", "")
    get.restype, get.argtypes = ctypes.c_int, [ctypes.c_int]
    got = get(-1)  # MKL_CBWR_ALL: the branch, and the STRICT bit (0x10000)
    name = MKL_BRANCHES.get(got & 0xFFFF, f"branch {got & 0xFFFF}")
    return f"{name},STRICT" if got & 0x10000 else name


def other_draw(device: str) -> str | None:
    """Why this run cannot reproduce the published numbers bit for bit (a CUDA or MPS device, a CPU that
    is not x86-64, numpy's OpenBLAS on other kernels or absent, another MKL branch in force: mkl_branch),
    or None when it runs on the published kernel path."""
    from ch37.ensemble import blas_core

    if device != "cpu":
        return f"device {device}"
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return f"a {platform.machine() or 'non-x86'} CPU (the published kernels are x86-64's)"
    if (core := blas_core()) != PUBLISHED_BLAS_CORE:
        return f"numpy's OpenBLAS on {f'its {core} kernels' if core else 'no OpenBLAS at all'}"
    branch, asked = mkl_branch(), os.environ.get("MKL_CBWR", "")
    if branch == asked != PUBLISHED_MKL_CBWR:
        return f"MKL_CBWR={asked} (published: {PUBLISHED_MKL_CBWR})"
    if branch != PUBLISHED_MKL_CBWR:
        return (
            f"MKL's {branch or 'own'} branch, taken at its first use in this process (MKL_CBWR={asked} now;"
            f" published: {PUBLISHED_MKL_CBWR})"
        )
    return None


def banner(args: argparse.Namespace, reminder=None) -> None:
    """Two lines: what runs where, and how long this configuration takes on this tier; a third when this
    run cannot take the published kernel path (other_draw); in the default configuration (exercise 1's
    experiment), a last: `reminder()`, when it has a line (the exercises' ex1_reminder: a learner who has
    not written a prediction yet)."""
    import torch

    tier = device_tier(args.device)
    # the tier: the machine class wallclock.csv times the default run on (cpu-<cores>core-<vendor>, a GPU)
    head = f"ch3.7 Datasets at Scale | seed {args.seed} | device {args.device} (wall-clock tier {tier})"
    print(f"{head} | torch {torch.__version__}")
    smoke = "smoke run: tiny configuration, seconds, numbers not meaningful"
    on_cpu = args.device == "cpu" and not args.smoke
    probe, cpu = (step_probe(args.hidden_dim, args.batch_size), this_cpu()) if on_cpu else (None, "")
    print(
        smoke
        if args.smoke
        else expected_wallclock(tier, config_hash(result_config(args)), probe_ms=probe, cpu=cpu)
    )
    default = not args.smoke and five_seed_reference(result_config(args)) is not None  # ex1's experiment
    if default and (why := other_draw(args.device)):
        print(
            f"another draw: {why} rounds differently from the published runs ({PUBLISHED_PATH}), so"
            " this seed's numbers differ; compare with the five-seed mean"
        )
    if default and reminder and (line := reminder()):
        print(line)
