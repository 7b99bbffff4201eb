"""How fast the chapter's parts run, and where the time goes: one entry point, a subcommand per part.

    python -m tools.bench lesson [--smoke]  where the time of one scale_data.py run goes
    python -m tools.bench engine            the data engine: validated demos/s local vs Ray, peak memory,
                                            against its own physics (writes OUT/bench_engine.json)
    python -m tools.bench envs              speed and competence of the two embodiments and their experts
    python -m tools.bench gym_pusht         the scripted expert on LeRobot's own PushT, by its success rule
    python -m tools.bench kernels           what the kernel path costs the training, and its bits
    python -m tools.bench reference         the lesson beside the reference chapter, cold, in one sitting
    python -m tools.bench host              issue 59's check of a host, one command: reference, lesson and
                                            kernels in turn, their outputs and a summary in OUT
    python -m tools.bench writer            the one-pass LeRobot v3 writer vs LeRobot's per-frame path

`SUBCOMMAND --help` says what each measures. One timing path: alternate() (every variant once a round,
the order reversed every other round, medians), in_fresh_process() where a setting is read once per
process. Run them alone: another busy process moves the figures. Exit codes: 0 ok, 2 bad input.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import importlib
import json
import math
import os
import re
import resource
import runpy
import secrets
import shlex
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

# numpy and torch are imported where used: `lesson` times torch's import (numpy's included) itself
from ch37 import ROOT, cli, config, errors
from ch37.config import DEFAULTS, check
from ch37.errors import DataError
from ch37.ownership import is_ours, read_stamp, write_atomic
from exercises.rules import ARMS
from tools.common import (
    META,
    check_results,
    in_fresh_process,
    parse_regions,
    parser,
    provenance,
    subcommands,
    write_result,
)


# --- The one timing path --------------------------------------------------------------------------------
def clock(fn: Callable, *args, **kwargs) -> tuple[float, object]:
    """(wall seconds, result) of one call."""
    t0 = time.perf_counter()
    result = fn(*args, **kwargs)
    return time.perf_counter() - t0, result


def alternate(measure: dict[str, Callable[[int], object]], rounds: int, after_round=None) -> dict[str, list]:
    """{name: [what measure[name](round) returned, one per round]}: every variant once per round, in the
    order given on even rounds and reversed on odd ones (a machine that speeds up or slows down over the
    run charges every variant alike); after_round(round, so_far) runs after each round (a progress line,
    a check across the variants)."""
    got: dict[str, list] = {name: [] for name in measure}
    for r in range(rounds):
        for name in list(measure) if r % 2 == 0 else reversed(list(measure)):
            got[name].append(measure[name](r))
        if after_round:
            after_round(r, got)
    return got


def medians(got: dict[str, list[float]]) -> dict[str, float]:
    return {name: float(statistics.median(v)) for name, v in got.items()}


# --- lesson: where the time of one scale_data.py run goes -----------------------------------------------
MON = sys.monitoring


def matmul_gflops(batch: int, hidden: int, seconds: float = 1.5) -> float:
    """fp32 (batch x hidden) @ (hidden x hidden) rate, the shape that dominates training."""
    import torch

    a, w = torch.randn(batch, hidden), torch.randn(hidden, hidden)
    for _ in range(20):
        a @ w
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for _ in range(50):
            a @ w
        n += 50
    return 2 * batch * hidden * hidden * n / (time.perf_counter() - t0) / 1e9


def step_flops(batch: int, hidden: int, obs: int, act: int) -> int:
    """Multiply-adds x2 of one training step on `batch` rows: forward, plus backward for all
    weights and the hidden activations (the input needs no gradient). Linear in `batch`."""
    fwd = 2 * batch * (obs * hidden + hidden * hidden + hidden * act)
    bwd = 2 * batch * obs * hidden + 4 * batch * hidden * hidden + 4 * batch * hidden * act
    return fwd + bwd


class RegionClock:
    """Wall time per phase of `script`: each top-level line's region, or "import" for an import line."""

    def __init__(self, script: Path):
        lines = script.read_text(encoding="utf-8").splitlines()
        self.phase = {}  # line number -> phase
        for r in parse_regions(script):
            for n in range(r.start, r.end + 1):
                self.phase[n] = "import" if lines[n - 1].startswith(("import ", "from ")) else r.name
        self.path, self.times, self.last = str(script.resolve()), {}, ("docstring", time.perf_counter())

    def _start(self, code, offset):
        if code.co_filename == self.path and code.co_name == "<module>":
            MON.set_local_events(MON.PROFILER_ID, code, MON.events.LINE)
        return MON.DISABLE  # every other function: never asked about again

    def _line(self, code, n):
        phase, t = self.last
        now = time.perf_counter()
        self.times[phase] = self.times.get(phase, 0.0) + now - t
        self.last = (self.phase.get(n, phase), now)

    def __enter__(self):
        MON.use_tool_id(MON.PROFILER_ID, "tools.bench")
        MON.register_callback(MON.PROFILER_ID, MON.events.PY_START, self._start)
        MON.register_callback(MON.PROFILER_ID, MON.events.LINE, self._line)
        MON.set_events(MON.PROFILER_ID, MON.events.PY_START)
        return self

    def __exit__(self, *exc):
        self._line(None, None)  # the last line's time
        MON.set_events(MON.PROFILER_ID, 0)
        MON.free_tool_id(MON.PROFILER_ID)
        MON.restart_events()


def run_once(script: Path, argv: list[str]) -> dict:
    """Run `script` with `argv` in this process; {phase: seconds}, the calls inside them, and facts."""
    import bc_recipe
    import datagen
    import lerobot_v3
    from datagen import demos, engine

    inner: dict[str, float] = {}  # calls inside the regions: "of which" lines
    facts: dict = {"train_steps": {}, "train_rows": {}}
    busy = []  # a wrapped call is running: the calls it makes are its own time

    def timed(phase, fn, note=None):
        def wrapper(*a, **k):
            if busy:
                return fn(*a, **k)
            busy.append(phase)
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                busy.pop()
                name = phase if note is None else note(*a, **k)
                inner[name] = inner.get(name, 0.0) + time.perf_counter() - t0

        return wrapper

    def train_note(datasets, steps, init, *, batch_size, **_):
        arm = f"train budget {len(facts['train_steps']) + 1} ({len(datasets)} arms side by side)"
        facts["train_steps"][arm] = steps * len(datasets)  # arm-steps
        facts["train_rows"][arm] = steps * len(datasets) * batch_size  # full batches
        return arm

    patches = [  # (module, name, phase): the script looks these up on their module when it calls them
        (datagen, "ensure_demos", "demo generation (or cache check)"),  # the faces the lesson imports
        (lerobot_v3, "load_arrays", "load LeRobot sets (all three)"),
        (demos, "write_dataset", "write augmented LeRobot set"),  # datagen.save looks it up there
        (engine, "run_attempts", "augmentation attempts"),
        (bc_recipe, "evaluate", "rollouts (all arms)"),
        (bc_recipe, "train", "train"),
    ]
    orig = [getattr(m, name) for m, name, _ in patches]
    for (m, name, phase), fn in zip(patches, orig):
        setattr(m, name, timed(phase, fn, train_note if name == "train" else None))
    sys.argv = [str(script), *argv]
    try:
        with RegionClock(script) as clock:
            ns = runpy.run_path(str(script), run_name="__main__")
    finally:
        for (m, name, _), fn in zip(patches, orig):
            setattr(m, name, fn)
    args = ns["args"]
    facts.update(batch=args.batch_size, hidden=args.hidden_dim, device=args.device)
    return {"times": clock.times, "inner": inner, "facts": facts}


OWNER = {"wrangle": ("demo generation", "load"), "augment": ("augmentation", "write")}
OWNER["measure"] = ("train", "rollouts")  # the regions whose calls are broken down


def report(runs: list[dict], walls: list[float], import_s: float, title: str) -> float:
    """Prints where the runs' time went; returns their training rate, GFLOP/s."""
    import torch

    import pusht_env

    f = runs[0]["facts"]
    gflops = matmul_gflops(f["batch"], f["hidden"]) if f["device"] == "cpu" else float("nan")
    per_row = step_flops(1, f["hidden"], pusht_env.OBS_DIM, pusht_env.ACT_DIM)  # FLOPs per row trained
    threads = torch.get_num_threads()
    print(f"\n{title}, median of {len(runs)} run(s), device {f['device']}, torch threads {threads}")
    print(f"{'phase':44s} {'seconds':>8s}")
    print(f"{'import torch (before the first run)':44s} {import_s:8.2f}")

    def med(part, key):
        return statistics.median(r[part].get(key, 0.0) for r in runs)

    for ph in dict.fromkeys(k for r in runs for k in r["times"]):
        print(f"{ph:44s} {med('times', ph):8.2f}")
        for sub in dict.fromkeys(k for r in runs for k in r["inner"]):
            if not sub.startswith(OWNER.get(ph, ())):
                continue
            extra = ""
            if sub in f["train_steps"]:
                steps, sec = f["train_steps"][sub], med("inner", sub)
                rate = f["train_rows"][sub] * per_row / sec / 1e9
                extra = f"  {steps} steps, {sec / steps * 1e3:.2f} ms/step, {rate:.0f} GFLOP/s"
                extra += f" = {rate / gflops:.0%} of matmul"
            print(f"  of which {sub:44s} {med('inner', sub):8.2f}{extra}")
    total_steps, rows = sum(f["train_steps"].values()), sum(f["train_rows"].values())
    train_s = statistics.median(
        sum(v for k, v in r["inner"].items() if k.startswith("train budget")) for r in runs
    )
    flops = rows * per_row
    rate, b, h = flops / train_s / 1e9, f["batch"], f["hidden"]
    print(f"{'wall (one run, in process)':40s} {statistics.median(walls):8.2f}")
    print(
        f"training: {total_steps} steps, {rows} rows x {per_row / 1e6:.2f} MFLOP = {flops / 1e12:.2f} TFLOP "
        f"in {train_s:.1f} s -> {rate:.0f} GFLOP/s; dense matmul ({b}x{h} @ {h}x{h}) in this process: "
        f"{gflops:.0f} GFLOP/s; training at {rate / gflops:.0%} of it; "
        f"floor at matmul rate {flops / gflops / 1e9:.1f} s"
    )
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    return rate


def lesson_main(argv: list[str]) -> int:
    """Where the time of one scale_data.py run goes. Prints figures; asserts nothing.

        python -m tools.bench lesson                 # the default run (seed 0), --no-rerun --no-cache
        python -m tools.bench lesson --smoke         # the smoke run
        python -m tools.bench lesson --repeat 3      # median of 3 runs per phase
        python -m tools.bench lesson --epochs 100    # other flags go to scale_data.py

    It runs scale_data.py in this process as `python scale_data.py` would (runpy), charges the time
    between two lines of the script's own top level to the region of the first (sys.monitoring line events
    on that code only, so nothing else slows down), and wraps the shared functions the script calls (demo
    generation, dataset loading and writing, the engine's attempts, bc_recipe's training and rollouts) to
    attribute their time. For training it reports achieved GFLOP/s next to a dense fp32 matmul measured in
    the same process, and (its last lines) against this machine's best training-step rate over the kernel
    paths `tools.bench kernels` times, each in a fresh process. The run takes the learner's kernel path: the
    published one (ch37.cli.kernel_path) is set before numpy loads here, as the setup region sets it before
    numpy loads in `python scale_data.py`; the last line says whether seed 0 printed meta.yaml's row.
    """
    p = parser("bench lesson", lesson_main.__doc__)
    arg = p.add_argument
    arg("--smoke", action="store_true", help="benchmark the smoke run")
    arg("--repeat", type=int, default=1, help="runs per phase; the median is printed")
    arg("--seed", type=int, default=0)
    arg("--kernel_steps", type=int, default=300, help="training steps per kernel path for the best rate")
    a, extra = p.parse_known_args(argv)  # anything else goes to scale_data.py, e.g. --epochs 100
    config.check(a, positive=("repeat", "kernel_steps"))
    # the learner's path: numpy and torch load here, before the script's setup region could hold their
    # kernels, so they are held first, as that region holds them (a value of yours is kept)
    os.environ.update(cli.kernel_path())
    import_s, _ = clock(importlib.import_module, "torch")  # after the flags: a phase of the report
    with tempfile.TemporaryDirectory(prefix="ch37-bench-") as tmp:

        def run(i: int) -> dict:
            args = ["--seed", str(a.seed), "--no-rerun", "--no-cache", "--out", f"{tmp}/run{i}"]
            wall, got = clock(run_once, a.script, args + ["--smoke"] * a.smoke + extra)
            m = json.loads(Path(f"{tmp}/run{i}/metrics.json").read_text())
            n = m["config"]["eval_episodes"]
            wins = {arm: round(m["arms"][arm]["success"] * n) for arm in ARMS}  # meta.yaml's row's arms
            return got | {"wall": wall, "budgets": m["budgets"], "successes": wins}

        runs = alternate({"run": run}, a.repeat)["run"]
    title = f"{a.script.name} {'--smoke' if a.smoke else '(default)'} seed {a.seed}"
    rate = report(runs, [r["wall"] for r in runs], import_s, title)
    in_run_rate(runs, a, rate)
    return 0


def in_run_rate(runs: list[dict], a, rate: float) -> None:
    """The run's training rate (report's, GFLOP/s) against this machine's best: the fastest kernel path of
    `tools.bench kernels` (a training step of the run's shapes, each path in a fresh process), in GFLOP/s
    of the same count; and whether the run took the published kernel path and printed meta.yaml's seed-0
    row."""
    import yaml

    import pusht_env
    from ch37.ensemble import blas_core

    f = runs[0]["facts"]
    per_row = step_flops(1, f["hidden"], pusht_env.OBS_DIM, pusht_env.ACT_DIM)
    paths = {path: train_step(path, a.kernel_steps, f["hidden"], f["batch"], 2) for path in KERNEL_PATHS}
    step_rows = 2 * f["batch"]  # the kernel step trains two arms side by side, 2 threads as the run
    rates = {path: step_rows * per_row / m["s_per_step"] / 1e9 for path, m in paths.items()}
    best = max(rates, key=rates.get)
    each = ", ".join(f"{path} {r:.0f}" for path, r in rates.items())
    print(
        f"in-run training: {rate:.0f} GFLOP/s on OpenBLAS {blas_core() or 'absent'} kernels,"
        f" {rate / rates[best]:.0%} of this machine's best matrix rate ({best}: {rates[best]:.0f} GFLOP/s;"
        f" a training step of the run's shapes, {a.kernel_steps} steps per path in a fresh process: {each})"
    )
    row = yaml.safe_load(META.read_text())["reference_run"]["seeds"]["rows"][0]
    same = [
        r["budgets"] == row["steps"] and r["successes"] == row["successes"] for r in runs if "budgets" in r
    ]
    if a.seed == 0 and not a.smoke and same:
        print(
            f"the run printed meta.yaml's seed-0 row: {'yes' if all(same) else 'no'}"
            f" (published path: {cli.PUBLISHED_PATH})"
        )


# --- engine: validated demos per second of the data engine, against its own physics ---------------------
SOURCE_EPISODES = DEFAULTS["source_episodes"]
TABLE = {  # printed column: row key
    "wall s": "wall_s",
    "gen s": "generate_s",
    "write s": "write_s",
    "merge s": "merge_s",
    "merge %": "merge_pct",
    "demos/s": "demos_per_s",
    "/worker": "generate_demos_per_s_per_worker",
    "phys s": "physics_s",
    "x phys": "gen_over_physics",
}
KIND, COSTS = "bench_engine", "bench_engine_costs"  # each JSON's "kind" and name: a re-run replaces its own
EXECUTORS = ("local", "ray", "ray2")  # ray2: two Ray nodes on this machine, joined by address
FLOOR_REPEATS = 3  # a run's floor is the least of 3: bursts of load on this machine slow one by up to 1.7x


def tree_digest(root: Path) -> str:
    """sha256 over every file of a run but its report (which holds timings)."""
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.name != "generation_report.json":
            h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def run_sampled(cmd: list[str], env: dict | None = None) -> dict:
    """Run `cmd`; wall seconds and peak RSS (MB) of the driver, of the largest process, of the tree
    (the tree: the driver's descendants; a joined cluster's workers are not its children)."""
    import psutil

    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    root = psutil.Process(proc.pid)
    peak = {"driver": 0, "largest": 0, "tree": 0}
    while proc.poll() is None:
        try:
            procs = [root, *root.children(recursive=True)]
        except psutil.NoSuchProcess:
            break
        rss = {}
        for p in procs:
            try:
                rss[p.pid] = p.memory_info().rss
            except psutil.Error:
                pass
        peak["driver"] = max(peak["driver"], rss.get(proc.pid, 0))
        peak["largest"] = max(peak["largest"], max(rss.values(), default=0))
        peak["tree"] = max(peak["tree"], sum(rss.values()))
        time.sleep(0.2)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        last = (err.strip().splitlines() or [""])[-1]
        raise DataError(f"{' '.join(cmd[1:])} exited {proc.returncode}: {last}")
    return {"wall_s": wall, **{f"peak_rss_{k}_mb": v / 2**20 for k, v in peak.items()}, "stdout": out}


@contextlib.contextmanager
def two_ray_nodes(workers: int):
    """A Ray cluster of two nodes on this machine, as an operator starts one: its address, then stopped.
    `ray start` enables token authentication, so the nodes and the run that joins get RAY_AUTH_MODE=token
    and this cluster's own token (none is in ~/.ray/auth_token on a fresh machine)."""
    ray = [str(Path(sys.executable).with_name("ray"))]
    env = os.environ | {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    with socket.socket() as s:  # a free port for the head's GCS
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cpus = [str(max(1, workers // 2)), str(max(1, workers - workers // 2))]
    quiet = dict(env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        head = ["--head", f"--port={port}", "--include-dashboard=false"]
        for where, n in ((head, cpus[0]), ([f"--address=127.0.0.1:{port}"], cpus[1])):
            subprocess.run([*ray, "start", *where, f"--num-cpus={n}", "--disable-usage-stats"], **quiet)
        yield f"127.0.0.1:{port}", env
    finally:
        subprocess.run(
            [*ray, "stop", "--force"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )


def remove_run(run_dir: Path) -> None:
    """Remove an engine run this tool made (resume.foreign finds nothing else in it); refuse otherwise."""
    from datagen import resume

    if not run_dir.exists():
        return
    stamp = read_stamp(run_dir)
    if not is_ours(stamp) or stamp.get("kind") != "engine" or resume.foreign(run_dir, stamp):
        raise DataError(f"{run_dir} holds files this tool did not write; move it elsewhere")
    shutil.rmtree(run_dir)


def point(src: Path, out: Path, n: int, executor: str, a) -> dict:
    """One real augment_demos.py run of n demos on `executor`, timed from outside: its table row."""
    from datagen import known_tasks

    workers, shard_size = a.workers, a.shard_size
    run_dir = out / "runs" / f"n{n}-{executor}"
    remove_run(run_dir)  # an earlier run of this tool; anything else is refused
    cmd = [sys.executable, str(a.checkout / "augment_demos.py"), "--src", str(src), "--out", str(run_dir)]
    # --per_demo: augment_demos' --attempts_per_demo under the spelling every --checkout understands
    cmd += ["--per_demo", str(math.ceil(n / SOURCE_EPISODES)), "--workers", str(workers), "--quiet"]
    cmd += ["--shard_size", str(shard_size)] if shard_size else []
    cmd += ["--seed", str(a.seed), "--mode", a.mode]
    if executor == "ray2":
        with two_ray_nodes(workers) as (address, env):
            m = run_sampled([*cmd, "--ray", address], env)
    else:
        m = run_sampled(cmd + (["--ray"] if executor == "ray" else []))
    rep = json.loads((run_dir / "generation_report.json").read_text())
    gen, start, merge = rep["seconds_generate"], rep["seconds_start_executor"], rep["seconds_merge"]
    shards, wall = rep["shards"]["total"], m.pop("wall_s")
    row = {"demos_requested": n, "executor": executor, "workers": workers, "shards": shards}
    row |= {k: rep[k] for k in ("attempts", "kept", "yield", "frames")} | {"wall_s": wall}
    row |= {"generate_s": gen, "start_executor_s": start, "merge_s": merge}  # start_executor_s: of generate_s
    row |= {"write_s": rep.get("seconds_write", math.nan)}  # worker seconds, inside generate_s
    row |= {
        "other_s": wall - gen - merge,
        "demos_per_s": rep["kept"] / wall,
        "merge_s_per_shard": merge / shards,
        "merge_s_per_demo": merge / max(rep["kept"], 1),
        "merge_pct": 100 * merge / wall,
    }
    row |= {"generate_demos_per_s_per_worker": rep["kept"] / (gen - start) / workers}
    row |= {"shard_size": rep["settings"]["shard_size"], "sha256": tree_digest(run_dir)}
    # the run's generation worker-seconds (its shard writes included) over its kept frames' physics
    kept = rep["kept"]
    row["physics_s"] = (
        physics_floor(known_tasks()[a.task], kept_runs(run_dir), FLOOR_REPEATS) if kept else math.nan
    )
    row["gen_over_physics"] = (gen - start) * workers / row["physics_s"]
    row |= {"summary": m.pop("stdout").strip().splitlines()[-1], **m}  # m: the peak RSS
    remove_run(run_dir)
    return row


def physics_floor(task, runs, repeats: int = 1) -> float:
    """Seconds the env alone takes over kept frames: for each (start, actions (T, act_dim)) in `runs`,
    task.place(env, start) then env.step per action; no expert, no recording, no writing. The least
    of `repeats` passes."""
    env = task.make_env()
    runs = [([float(v) for v in start], list(actions)) for start, actions in runs]

    def steps():
        for start, actions in runs:
            task.place(env, start)
            for act in actions:
                env.step(act)

    return min(clock(steps)[0] for _ in range(repeats))


def kept_runs(root: Path) -> list:
    """(recorded start, recorded actions) of every episode of an engine run's merged set."""
    import numpy as np

    from lerobot_v3.dataset import load_arrays

    arrays = load_arrays(root, keys=("episode_index", "action", "aug.start"))
    cuts = np.flatnonzero(np.diff(arrays["episode_index"])) + 1
    return [(s[0], a) for s, a in zip(np.split(arrays["aug.start"], cuts), np.split(arrays["action"], cuts))]


def every_attempt(task, sources: dict, jobs: list, how, mode: str, sims) -> list:
    """(start, actions (T, act_dim)) of every attempt of `jobs` that simulated a frame, kept or not: the
    engine's own Mode for `mode`, one attempt at a time (the same frames as lockstep, tests/test_lockstep.py),
    noting each attempt's actions before its finish drops a failed one's frames."""
    from datagen import lockstep

    kind, _ = lockstep.mode_parts(task, sources, how, mode, plans=sims.plans, lanes=False)
    runs = []

    class Noting(lockstep.Mode):
        def begin(self, job, env):
            return kind.begin(job, env)

        def decide(self, lanes, envs, obs):
            return kind.decide(lanes, envs, obs)

        def step(self, envs, actions):
            return kind.step(envs, actions)

        def finish(self, lane, env, episode, last_obs):
            actions = episode["action"].copy()  # the frames the env was stepped through, before they go
            got = kind.finish(lane, env, episode, last_obs)
            runs.append((got.start, actions))
            return got

    lockstep.one_lane(task, sims.env(task), jobs, Noting())
    return runs


# The task's own code, as the engine calls it: the Task's members but make_env, place and step_batch (they
# make, reset and step the env: what the physics floors time), its expert (made, reset, act, act_batch), and
# its replay's action kind (to_target, to_action: the gym-aloha tasks' inverse kinematics).
TASK_MEMBERS = (
    "start_of",
    "perturb",
    "success",
    "state_problem",
    "object_pose",
    "frame_pose",
    "start_distance",
    "signals",
    "arm_pose",
    "frame_columns",
)


class TaskClock:
    """Where a run's time goes, on two clocks, while the engine runs `clocked`, a shallow copy of the task:
    seconds["task"], the task's own code (TASK_MEMBERS, its expert, its replay's action kind), and
    seconds["physics"], its envs' (those its make_env makes) place, step and step_batch. What a run takes
    besides them is the engine's own. A call inside another clocked call (to_action reading arm_pose,
    step_batch asking success) counts once, on the outer one's clock; calls: each clock's."""

    def __init__(self, task):
        self.seconds, self.calls, self._depth = {"task": 0.0, "physics": 0.0}, {"task": 0, "physics": 0}, 0
        t = self.clocked = copy.copy(task)
        for name in TASK_MEMBERS:
            setattr(t, name, self._timed(getattr(task, name)))
        if task.expert is not None:
            batch = task.expert.batch and self._made(task.expert.batch, "act_batch")
            t.expert = replace(task.expert, cls=self._made(task.expert.cls, "reset", "act"), batch=batch)
        action = task.replay.action  # its two conversions on the clock
        clocked = SimpleNamespace(
            to_target=self._timed(action.to_target), to_action=self._timed(action.to_action)
        )
        t.replay = replace(task.replay, action=clocked)
        t.place, t.step_batch = self._timed(task.place, "physics"), self._timed(task.step_batch, "physics")

        def make_env(*args, **kwargs):
            env = task.make_env(*args, **kwargs)
            env.step = self._timed(env.step, "physics")
            return env

        t.make_env = make_env

    def start(self) -> None:
        """The clocks and the count to zero (the envs made and their steps' wrappers kept)."""
        self.seconds, self.calls = dict.fromkeys(self.seconds, 0.0), dict.fromkeys(self.calls, 0)

    def _timed(self, fn, clock: str = "task"):
        def run(*args, **kwargs):
            self._depth += 1
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self._depth -= 1
                if not self._depth:
                    self.seconds[clock] += time.perf_counter() - t0
                    self.calls[clock] += 1

        return run

    def _made(self, cls, *methods: str):
        made = self._timed(cls)  # the making is the task's too

        def make(*args, **kwargs):
            obj = made(*args, **kwargs)
            for m in methods:
                setattr(obj, m, self._timed(getattr(obj, m)))
            return obj

        return make


def per_demo_costs(
    task, src: Path, attempts_per_demo: int, seed: int, repeats: int, mode: str = "resolve", sigma=None
) -> dict:
    """Where one core's time goes, in this process, for augment_demos.py's first attempts_per_demo
    attempts of every source episode at `seed` in `mode`: one attempt at a time, in lockstep (where the
    task's mode has lanes; else the same one at a time), the physics floor of the kept frames, and the
    engine's write of the kept set; `repeats` rounds, alternated, medians. And the floor of every frame
    simulated, kept or not (physics_all_s): a mode that keeps few attempts pays for its failed ones' frames
    too, which the kept frames' floor does not count (lockstep_over_all_physics). And the seconds inside the
    task's own code and in the physics in one more lockstep run on their clocks (clocked_s, TaskClock): task_s
    (its expert, its replay's conversions, its poses and signals), physics_in_run_s (its envs' place and
    steps) and the rest, engine_s, the engine's own (recording, the replay's plan, the bookkeeping);
    engine_over_physics: (physics_in_run_s + engine_s) / physics_in_run_s, each round's own, whatever the
    machine's speed did between the variants."""
    from datagen import Perturbation, engine, lockstep
    from datagen.source_check import read_source, successful_only

    # the run's own read of a source (augment_demos.py): the task's whole observation, environment state too
    sources = engine.sources(successful_only(read_source(task, src), src)[0])
    jobs = [(e, k) for e in sorted(sources) for k in range(attempts_per_demo)]
    pos, yaw = sigma or (DEFAULTS["aug_pos_sigma"], DEFAULTS["aug_yaw_sigma"])  # m, rad
    how = Perturbation(seed=seed, pos_sigma=pos, yaw_sigma=yaw)
    sims = engine.Simulators()  # the envs (and plans) both sides reuse, made once
    engine.attempt(task, sources[jobs[0][0]], 10**6, how, mode=mode, sims=sims)  # warm up
    got = {}  # each variant's last results: lockstep's kept episodes feed the floor and the write

    def one_at_a_time(_):
        s, got["one"] = clock(
            lambda: [engine.attempt(task, sources[e], k, how, mode=mode, sims=sims) for e, k in jobs]
        )
        return s

    def together(_):
        s, results = clock(lockstep.attempts_lockstep, task, sources, jobs, how, mode=mode, sims=sims)
        got["kept"] = [r.episode for r in results if r.kept]
        got["steps"] = [r.steps for r in results]
        got["simulated"] = sum(got["steps"])  # control steps, kept or not
        return s

    # lockstep once more, on the task's and the physics' clocks, in envs of its own, made (and the engine
    # warmed up on them) before any round; the replay plans are the others'
    tc, clocked_sims = TaskClock(task), engine.Simulators()
    clocked_sims.plans = sims.plans
    lockstep.attempts_lockstep(tc.clocked, sources, jobs, how, mode=mode, sims=clocked_sims)
    split = {"task_s": [], "physics_in_run_s": [], "engine_s": [], "engine_over_physics": []}

    def clocked(_):
        tc.start()
        s, results = clock(
            lockstep.attempts_lockstep, tc.clocked, sources, jobs, how, mode=mode, sims=clocked_sims
        )
        if [r.steps for r in results] != got["steps"]:
            raise DataError("lockstep on the clocks simulated other frames")
        task_s, physics_s = tc.seconds["task"], tc.seconds["physics"]
        split["task_s"].append(task_s)
        split["physics_in_run_s"].append(physics_s)
        split["engine_s"].append(s - task_s - physics_s)
        split["engine_over_physics"].append((s - task_s) / physics_s)
        got["task_calls"] = tc.calls["task"]
        return s

    def write(_):
        with tempfile.TemporaryDirectory() as tmp:  # the engine's own writer, whatever columns it adds
            return clock(engine.save, task, Path(tmp) / "set", got["kept"], repo_id="local/x", stamp={})[0]

    def same_kept(_, __):
        if sum(r.kept for r in got["one"]) != len(got["kept"]):
            raise DataError("lockstep kept another set than one attempt at a time")

    every = every_attempt(task, sources, jobs, how, mode, sims)  # the same frames each round: noted once
    measure = {
        "one_at_a_time_s": one_at_a_time,
        "lockstep_s": together,
        "physics_s": lambda _: physics_floor(
            task, ((ep["aug.start"][0], ep["action"]) for ep in got["kept"])
        ),
        "physics_all_s": lambda _: physics_floor(task, every),
        "clocked_s": clocked,
        "write_s": write,
    }
    times = alternate(measure, repeats, after_round=same_kept) | split
    med, kept = medians(times), got["kept"]
    frames = sum(len(ep["action"]) for ep in kept)
    if sum(len(a) for _, a in every) != got["simulated"]:
        raise DataError("the attempts one at a time simulated other frames than lockstep's")
    if not frames:  # nothing kept, nothing to time the physics on
        raise DataError(
            f"{task.name} {mode}: none of the {len(jobs)} attempts was kept, so no kept frames to time the "
            "physics on; give more --cost_attempts_per_demo or a smaller --pos_sigma"
        )
    return {
        "task": task.name,
        "mode": mode,
        "attempts": len(jobs),
        "kept": len(kept),
        "frames": frames,
        "simulated_frames": got["simulated"],
        **med,
        "runs": times,
        "one_at_a_time_over_physics": med["one_at_a_time_s"] / med["physics_s"],
        "lockstep_over_physics": med["lockstep_s"] / med["physics_s"],
        "lockstep_and_write_over_physics": (med["lockstep_s"] + med["write_s"]) / med["physics_s"],
        "lockstep_over_all_physics": med["lockstep_s"] / med["physics_all_s"],
        "task_calls": got["task_calls"],
        "task_share": med["task_s"] / med["clocked_s"],
        "engine_share": med["engine_s"] / med["clocked_s"],
        "physics_us_per_frame": med["physics_s"] / frames * 1e6,
        "write_us_per_frame": med["write_s"] / frames * 1e6,
    }


def estimate(rows: list[dict], cores_list=(64, 1024)) -> dict:
    """10^5 and 10^6 demos on clusters of `cores_list` cores, from the largest measured local run."""
    big = max(r["demos_requested"] for r in rows)
    at = {r["executor"]: r for r in rows if r["demos_requested"] == big}
    base = at.get("local") or next(iter(at.values()))
    rate = base["generate_demos_per_s_per_worker"]  # validated demos per second per core, write included
    ray = at.get("ray2") or at.get("ray")
    busy = lambda r: r["generate_s"] - r["start_executor_s"]  # noqa: E731
    ray_factor = busy(ray) / busy(base) if ray and base is not ray else 1.0
    fixed = (ray or base)["other_s"] + (ray or base)["start_executor_s"]  # imports, source, Ray
    merge_per_demo = base["merge_s_per_demo"]
    out = {
        "measured_at_demos": big,
        "per_core_demos_per_s": rate,
        "ray_vs_local_generate_time": ray_factor,
        "fixed_s": fixed,
        "merge_s_per_demo": merge_per_demo,
        "assumptions": [
            f"every cluster core makes demos at this machine's measured rate per worker ({rate:.1f}/s, "
            "write included) and shards scale perfectly (they share nothing)",
            f"Ray's overhead on the generation is the measured ratio to the local pool ({ray_factor:.2f})",
            f"fixed cost (imports, reading the source, starting Ray) as measured here ({fixed:.0f} s)",
            f"the merge runs on the driver alone, linear in demos at {merge_per_demo * 1e3:.2f} ms a demo"
            " (it places each shard once, counts the stats as it writes, and reads the numbers back"
            " once or twice for the exact quantiles)",
            "shard bytes reach the driver as fast as they are made (~0.4 MB per 100 demos; 10^6: ~4 GB)",
            "yield as measured (about 1.0 for resolve)",
        ],
    }
    for cores in cores_list:
        for n in (10**5, 10**6):
            gen = n / (rate * cores) * ray_factor
            merge = n * merge_per_demo
            total = fixed + gen + merge
            out[f"{n}@{cores}"] = dict(generate_s=gen, merge_s=merge, total_s=total, demos_per_s=n / total)
    return out


def engine_args(argv: list[str]):
    """engine's flags, checked; its --out refused before anything is made under it."""
    p = parser("bench engine", engine_main.__doc__)
    arg = p.add_argument
    from datagen import known_tasks

    arg("--task", choices=list(known_tasks()), default="pusht", help="the task grown (its generator's set)")
    modes = ("resolve", "replay", "replay_live")
    arg("--mode", choices=modes, default="resolve", help="augment_demos.py's --mode")
    arg("--sizes", type=int, nargs="+", default=[1000, 10000, 100000], help="demos per run")
    arg("--executors", nargs="+", choices=EXECUTORS, default=list(EXECUTORS))
    arg("--workers", type=int, default=os.cpu_count() or 1, help="processes / Ray CPUs")
    arg("--shard_size", type=int, help="attempts per shard (default: augment_demos.py's)")
    arg("--seed", type=int, default=1, help="augment_demos.py's --seed for every run and the costs")
    arg("--cost_attempts_per_demo", type=int, default=50, help="attempts per source episode of the costs")
    arg("--cost_repeats", type=int, default=3, help="rounds of the in-process costs (0: none)")
    arg("--costs_only", action="store_true", help="only the in-process costs (no runs)")
    arg("--pos_sigma", type=float, default=DEFAULTS["aug_pos_sigma"], help="the costs' perturbation, m")
    arg("--yaw_sigma", type=float, default=DEFAULTS["aug_yaw_sigma"], help="the costs' perturbation, rad")
    arg("--src", type=Path, help="a set of --task (default: a 12-episode set made under --out)")
    arg("--out", type=Path, default=ROOT / "outputs" / "bench_engine")
    help = "the checkout whose augment_demos.py runs (default this one); another commit's for a before/after"
    arg("--checkout", type=Path, default=ROOT, help=help)
    a = p.parse_args(argv)
    positive, non_negative = ("workers", "cost_attempts_per_demo"), ("seed", "cost_repeats")
    check(a, positive=positive, non_negative=non_negative, finite=("pos_sigma", "yaw_sigma"))
    if not (a.checkout / "augment_demos.py").is_file():
        raise DataError(f"--checkout {a.checkout} has no augment_demos.py")
    if min(a.sizes) < 1:
        raise DataError("--sizes must be positive")
    check_results(a.out, COSTS if a.costs_only else KIND)  # before the source set and the runs are made
    return a


def engine_source(task, a) -> Path:
    """--src, or the 12-episode set of `task` this bench makes under --out (once; then reused)."""
    import gen_demos

    src = a.src or a.out / f"src_{task.name}_seed0_ep{SOURCE_EPISODES}"
    if a.src is None and not (src / "meta" / "info.json").exists():
        if gen_demos.main(task, ["--episodes", str(SOURCE_EPISODES), "--out", str(src), "--quiet"]) != 0:
            raise DataError(f"could not make the source set at {src}")
    return src


def engine_costs(task, src: Path, a) -> dict:
    """per_demo_costs at --cost_* and its line ({} with --cost_repeats 0)."""
    if not a.cost_repeats:
        return {}
    sigma = (a.pos_sigma, a.yaw_sigma)
    c = per_demo_costs(task, src, a.cost_attempts_per_demo, a.seed, a.cost_repeats, a.mode, sigma)
    print(
        f"this checkout, one core, {task.title} {a.mode}: {c['attempts']} attempts, {c['kept']} kept "
        f"({c['frames']} frames), "
        f"medians of {a.cost_repeats} in this process: one at a time {c['one_at_a_time_s']:.2f} s, "
        f"lockstep {c['lockstep_s']:.2f} s, physics floor {c['physics_s']:.2f} s, write "
        f"{c['write_s']:.2f} s; lockstep {c['lockstep_over_physics']:.2f}x the physics "
        f"({c['lockstep_and_write_over_physics']:.2f}x with the write), "
        f"one at a time {c['one_at_a_time_over_physics']:.2f}x; every simulated frame "
        f"({c['simulated_frames']}) {c['physics_all_s']:.2f} s, "
        f"lockstep {c['lockstep_over_all_physics']:.2f}x; on the clocks, lockstep {c['clocked_s']:.2f} s: "
        f"the task's own code {c['task_s']:.2f} s ({c['task_calls']} calls), the physics "
        f"{c['physics_in_run_s']:.2f} s, the engine's own {c['engine_s']:.2f} s "
        f"({100 * c['engine_share']:.0f}%): the physics and the engine {c['engine_over_physics']:.2f}x the "
        "physics"
    )
    return c


def engine_runs(src: Path, a) -> list[dict]:
    """point() for every size and executor, a table line each, and whether a size's bytes agreed."""
    rows = []
    head = " ".join(f"{h:>7s}" for h in TABLE)
    print(f"{'demos':>6s} {'executor':8s} {'kept':>6s} {head} {'RSS MB driver/largest/tree':>27s}")
    for n in a.sizes:
        for ex in a.executors:
            r = point(src, a.out, n, ex, a)
            rows.append(r)
            rss = f"{r['peak_rss_driver_mb']:.0f}/{r['peak_rss_largest_mb']:.0f}/{r['peak_rss_tree_mb']:.0f}"
            cells = " ".join(f"{r[k]:7.1f}" for k in TABLE.values())
            print(f"{n:6d} {ex:8s} {r['kept']:6d} {cells} {rss:>27s}", flush=True)
        same = {r["sha256"] for r in rows if r["demos_requested"] == n}
        if len(a.executors) > 1:
            print(f"{n:6d} outputs byte-identical across {', '.join(a.executors)}: {len(same) == 1}")
    return rows


def print_estimate(est: dict) -> None:
    for key, e in est.items():
        if "@" in key:
            n, cores = map(int, key.split("@"))
            print(
                f"estimate {n:>9,d} demos on {cores:>5,d} Ray cores: {e['total_s'] / 60:6.1f} min "
                f"({e['demos_per_s']:.0f} demos/s; generate {e['generate_s'] / 60:.1f} min, "
                f"merge {e['merge_s'] / 60:.1f} min)"
            )
    print("assumptions: " + "; ".join(est["assumptions"]))


def engine_main(argv: list[str]) -> int:
    """Validated demos per second of the data engine, end to end: local processes, Ray, two Ray nodes,
    each beside the cost of its own physics.

        python -m tools.bench engine                                 # 10^3, 10^4, 10^5; local, ray, ray2
        python -m tools.bench engine --sizes 1000 --executors local  # quicker
        python -m tools.bench engine --task aloha --costs_only       # where one core's time goes (ALOHA)

    Each point is one real `augment_demos.py` run (re-solve + shard write + merge + stats) from a
    12-episode gen_demos_pusht.py set, timed from outside, with the peak memory of its process tree
    sampled every 0.2 s (psutil): the driver alone, the largest single process, and the whole tree.
    `ray` is a private local Ray of --workers CPUs; `ray2` is a cluster of two Ray nodes on this
    machine (`ray start --head` and a second `ray start --address`, --workers / 2 CPUs each) that the
    run joins with `--ray ADDRESS`. Runs of one size must give the same bytes on every executor; the
    table says whether they did. Then an estimate for 10^5 and 10^6 demos on 64 and 1,024 cores from
    the measured per-core rate and the measured merge cost per demo (assumptions printed beside it).
    The physics floor: the env alone stepped through the very frames a run kept, from their recorded
    starts (aug.start, the task's place()) with their recorded actions; no expert, no recording, no
    writing (the least of FLOOR_REPEATS passes, right after the run). A row's "x phys" is the run's
    generation worker-seconds (the shard writes included) over that floor: 1.0 would be a generator that
    costs only its physics. First, in this process, the same split for the first --cost_attempts_per_demo
    attempts of every source episode: one attempt at a time (datagen.engine.attempt), in lockstep
    (datagen.lockstep.attempts_lockstep), the floor, and the write of the kept set (datagen.engine.save),
    each run --cost_repeats times alternated, medians. Any task of the engine (--task; its set made by
    gen_demos.py --task), in any mode.
    Writes OUT/bench_engine.json (default outputs/bench_engine; bench_engine_costs.json with
    --costs_only); the runs' own folders are removed. Asserts nothing: the figures are for
    docs/engine.md.
    """
    from datagen import known_tasks

    a = engine_args(argv)
    task = known_tasks()[a.task]
    src = engine_source(task, a)
    costs = engine_costs(task, src, a)
    if a.costs_only:
        result = {"kind": COSTS, "per_demo_costs": costs, "provenance": provenance(a.script)}
        path = write_result(a.out / f"{COSTS}.json", result)
        print(f"wrote {path}")
        return 0
    rows = engine_runs(src, a)
    est = estimate(rows)
    print_estimate(est)
    same = {str(n): len({r["sha256"] for r in rows if r["demos_requested"] == n}) == 1 for n in a.sizes}
    result = {
        "kind": KIND,
        "task": task.name,
        "per_demo_costs": costs,
        "runs": rows,
        "estimate": est,
        "checkout": str(a.checkout.resolve()),
    }
    result |= {"provenance": provenance(a.script), "identical_across_executors": same}
    path = write_result(a.out / f"{KIND}.json", result)
    print(f"wrote {path}")
    return 0


# --- envs: speed and competence of the two embodiments and their experts --------------------------------
NOISE = {"pusht": 0.08, "aloha": 0.05}  # the noisy-expert levels the success targets are stated at


def steps_per_second(emb, n: int = 3000) -> float:
    import numpy as np

    env, rng = emb.make_env(), np.random.default_rng(0)
    env.reset(0)
    acts = rng.uniform(-1, 1, (n, len(emb.spec.action_names))).astype(np.float32)
    t0 = time.perf_counter()
    for a in acts:
        if env.step(a)[2]:
            env.reset(int(rng.integers(1 << 30)))
    return n / (time.perf_counter() - t0)


def expert_record(emb, starts: int, noise: float) -> tuple[int, float]:
    from datagen import rollout

    env, wins, lengths = emb.make_env(), 0, []
    for s in range(starts):
        ep = rollout(emb, env, emb.expert.cls(noise=noise, seed=s), env.reset(s))
        wins += ep["success"]
        lengths.append(len(ep["action"]))
    return wins, statistics.median(lengths)


def generation_fps(emb, episodes: int = 12) -> float:
    from datagen import demos

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        s = demos.generate(
            emb, Path(tmp) / "set", episodes=episodes, seed=0, noise=emb.default_noise, quiet=True
        )
        return s["frames"] / (time.perf_counter() - t0)


def envs_main(argv: list[str]) -> int:
    """Speed and competence of the two embodiments and their experts. Prints figures; asserts nothing.

        python -m tools.bench envs              # 50 seeded starts per expert and noise level
        python -m tools.bench envs --starts 10  # quicker

    For each env: control steps per second under random actions, the expert's success count and
    median episode length with and without action noise, and demo generation frames per second
    (rollout + LeRobot v3 write, through the same code as gen_demos_*.py).
    """
    import gen_demos_aloha
    import gen_demos_pusht
    from datagen import demos

    p = parser("bench envs", envs_main.__doc__, script=False)
    arg = p.add_argument
    arg("--starts", type=int, default=50, help="seeded starts per expert and noise level")
    a = p.parse_args(argv)
    check(a, positive=["starts"])
    warm = Path(tempfile.mkdtemp()) / "warm"  # the first set pays for the imports and the encoder
    demos.generate(gen_demos_pusht.PUSHT, warm, episodes=1, seed=0, noise=0.0, quiet=True)
    head = f"{'expert (noise 0)':>22s} {'expert (noisy)':>26s} {'demo gen frames/s':>18s}"
    print(f"{'env':6s} {'steps/s':>9s} {head}")
    for emb in (gen_demos_pusht.PUSHT, gen_demos_aloha.ALOHA):
        sps = steps_per_second(emb)
        w0, m0 = expert_record(emb, a.starts, 0.0)
        wn, mn = expert_record(emb, a.starts, NOISE[emb.name])
        fps = generation_fps(emb)
        print(
            f"{emb.name:6s} {sps:9.0f} {f'{w0}/{a.starts}, median {m0:g} steps':>22s} "
            f"{f'{wn}/{a.starts} at {NOISE[emb.name]}, median {mn:g}':>26s} {fps:18.0f}"
        )
    return 0


# --- gym_pusht: the scripted expert on LeRobot's own PushT ----------------------------------------------
GYM_PUSHT_ID, GYM_PUSHT_OBS = "gym_pusht/PushT-v0", "environment_state_agent_pos"


def gym_pusht_episode(env, expert, seed: int) -> dict:
    """One episode from env.reset(seed=seed): success, control steps, final coverage, start pose.
    The expert reads gym-pusht's observation flattened: agent x, y then the 16 keypoint coordinates."""
    import numpy as np

    obs, info = env.reset(seed=seed)
    start = info["block_pose"]
    expert.reset()
    steps, done = 0, False
    while not done:
        flat = np.concatenate([obs["agent_pos"], obs["environment_state"]])
        obs, _, terminated, truncated, info = env.step(expert.act(flat))
        steps += 1
        done = terminated or truncated
    return {
        "seed": seed,
        "success": bool(info["is_success"]),
        "steps": steps,
        "coverage": float(info["coverage"]),
        "start": [round(float(v), 2) for v in start],
    }


def gym_pusht_main(argv: list[str]) -> int:
    """How good is the scripted expert on LeRobot's own PushT? GymPushTExpert
    (datagen/tasks/gym_pusht_expert.py) on gym-pusht (LeRobot's `pusht` extra), judged by gym-pusht's own
    success (info["is_success"]: more than 95% of the goal T covered). Prints figures; writes nothing.

        python -m tools.bench gym_pusht                          # 50 seeded starts, seeds 0..49
        python -m tools.bench gym_pusht --episodes 200 --seed 1000 --noise 5

    Episode i starts from env.reset(seed=SEED + i), gym-pusht's own random start (agent anywhere in
    [50, 450]^2, block in [100, 400]^2 at any angle), and runs until success ends it or gym-pusht's
    episode limit (300 control steps at 10 Hz, as lerobot-eval's) cuts it. The observation is
    "environment_state_agent_pos", flattened as the expert reads it: agent_pos then environment_state.
    """
    p = parser("bench gym_pusht", gym_pusht_main.__doc__, script=False)
    arg = p.add_argument
    arg("--episodes", type=int, default=50, help="seeded starts")
    arg("--seed", type=int, default=0, help="episode i resets with seed SEED + i")
    arg("--noise", type=float, default=0.0, help="std (px) of Gaussian noise on every target")
    a = p.parse_args(argv)
    check(a, positive=["episodes"], non_negative=["seed"], finite=["noise"])
    import gymnasium

    from datagen.tasks.gym_pusht_expert import GymPushTExpert

    with warnings.catch_warnings():  # pygame (gym-pusht draws with it): pkg_resources is deprecated
        warnings.simplefilter("ignore", UserWarning)
        import gym_pusht  # noqa: F401  (registers gym_pusht/PushT-v0)

        env = gymnasium.make(GYM_PUSHT_ID, obs_type=GYM_PUSHT_OBS)
    expert = GymPushTExpert(noise=a.noise, seed=a.seed)
    wall, runs = clock(lambda: [gym_pusht_episode(env, expert, a.seed + i) for i in range(a.episodes)])
    env.close()
    won = [r for r in runs if r["success"]]
    limit = env.spec.max_episode_steps
    print(f"gym-pusht {GYM_PUSHT_ID} ({GYM_PUSHT_OBS}), episode limit {limit} steps, noise {a.noise:g} px")
    seeds = f"seeds {a.seed}..{a.seed + a.episodes - 1}"
    print(f"success {len(won)}/{a.episodes} = {len(won) / a.episodes:.3f} ({seeds})")
    if won:
        steps = [r["steps"] for r in won]
        mean, median = statistics.mean(steps), statistics.median(steps)
        print(f"steps to success: mean {mean:.1f}, median {median:g}, max {max(steps)}")
    for r in runs:
        if not r["success"]:
            print(f"failed: seed {r['seed']}, start block {r['start']}, final coverage {r['coverage']:.3f}")
    print(f"{wall:.1f} s, {sum(r['steps'] for r in runs) / wall:.0f} steps/s")
    return 0


# --- kernels: what the lesson's kernel path costs its training, and the bits each path gives --------------
# The environment and the stack's products of each path ("torch": MLPStack's products on torch's MKL)
KERNEL_PATHS = {
    "held": ({"OPENBLAS_CORETYPE": "Haswell", "MKL_CBWR": "COMPATIBLE"}, "numpy"),
    "compatible": ({"MKL_CBWR": "COMPATIBLE"}, "torch"),
    "native": ({}, "torch"),
}
# One measurement: the default recipe's shapes (hidden 512, batch 128, two arms of 420 and 3,490 frames:
# the seed-0 source and source + augmented sizes, from its budgets; a step's time does not depend on
# them), `steps` timed after a warm-up of 50; the weights' sha256 after the timed steps. With --parts
# (PARTS passed after the path), the calls bc_recipe.train's loop makes are wrapped with clocks (PARTS: the
# stack's forward, the backward, Adam's step, zero_grad, the scheduler, each a mean over the arms'
# processes; the rest is the batch, the loss, the progress bar and the processes' start and hand-back),
# and the bare products are timed after it: one arm's three batch x hidden x hidden products on one thread
# (its forward z = h @ W, its backward's h^T @ g and g @ W^T), and two arms' at once on two threads.
PARTS = ("forward", "backward", "Adam", "zero_grad", "scheduler")
TRAIN_STEP = """
import hashlib, json, sys, threading, time
import numpy as np, torch
import bc_recipe as bc
from ch37 import ensemble
steps, hidden, batch, threads = map(int, sys.argv[1:5])
if sys.argv[5] == "torch":  # the products on torch (MKL), as MLPStack runs them without numpy's OpenBLAS
    ensemble.one_blas_thread = lambda: False
import multiprocessing as mp
names = sys.argv[6:]  # PARTS, with --parts; none without
spent = mp.Array("d", len(names))  # seconds of each part, summed over the arms' processes (shared with them)
def clocked(owner, name, part):  # owner.name's seconds added to spent[part] (cleared after the warm-up)
    call, i = getattr(owner, name), names.index(part)
    def timed(*a, **k):
        t0 = time.perf_counter()
        try:
            return call(*a, **k)
        finally:
            with spent.get_lock():
                spent[i] += time.perf_counter() - t0
    setattr(owner, name, timed)
if names:
    clocked(ensemble.MLPStack, "forward", "forward")
    clocked(torch.Tensor, "backward", "backward")
    clocked(torch.optim.Adam, "step", "Adam")
    clocked(torch.optim.Adam, "zero_grad", "zero_grad")
    clocked(torch.optim.lr_scheduler.CosineAnnealingLR, "step", "scheduler")
torch.set_num_threads(threads)
rng = np.random.default_rng(0)
data = [(rng.normal(size=(n, 10)).astype(np.float32), rng.normal(size=(n, 2)).astype(np.float32))
        for n in (420, 3490)]
init = bc.init_weights(hidden, 0)
bc.train(data, 50, init, batch_size=batch, lr=1e-3, seed=0)
spent[:] = [0.0] * len(names)
t0 = time.perf_counter()
pols, _ = bc.train(data, steps, init, batch_size=batch, lr=1e-3, seed=0)
dt = time.perf_counter() - t0
weights = b"".join(t.numpy().tobytes() for p in pols for t in p.net.state_dict().values())
out = {"s_per_step": dt / steps, "sha256": hashlib.sha256(weights).hexdigest()[:8]}
out["blas"] = ensemble.blas_core()
if names:  # each part's seconds a step of one process (the arms' processes run theirs side by side)
    out["parts"] = {k: v / steps / ensemble.arm_processes(len(data), "cpu") for k, v in zip(names, spent)}
    shapes = ((batch, hidden), (hidden, hidden), (batch, hidden))
    a, w, g = (rng.normal(size=s).astype(np.float32) for s in shapes)
    def arm(n=200):
        for _ in range(n):
            a @ w, a.T @ g, g @ w.T
    def two():
        t = threading.Thread(target=arm)
        t.start()
        arm()
        t.join()
    if sys.argv[5] == "numpy":  # the bare products on numpy's OpenBLAS, where the held path runs them
        ensemble.one_blas_thread()  # as in the arms' processes: one thread a product
        out["products"] = {}
        for name, f in (("one arm", arm), ("two arms", two)):
            times = []
            for _ in range(4):  # a warm-up, then the best of 3
                t0 = time.perf_counter()
                f()
                times.append((time.perf_counter() - t0) / 200)
            out["products"][name] = min(times[1:])
print(json.dumps(out))
"""


def train_step(path: str, steps: int, hidden: int, batch: int, threads: int, parts: bool = False) -> dict:
    """Seconds per training step and the weights' hash, in a fresh process on kernel path `path` (parts:
    and the seconds of each of its PARTS per step, and the bare products'; TRAIN_STEP)."""
    env, products = KERNEL_PATHS[path]
    base = {k: v for k, v in os.environ.items() if k not in ("MKL_CBWR", "OPENBLAS_CORETYPE")}
    args = [steps, hidden, batch, threads, products, *(PARTS if parts else ())]
    return in_fresh_process(TRAIN_STEP, args, base | env, f"the timing process for {path}")


def kernels_main(argv: list[str]) -> int:
    """What the lesson's kernel path costs its training: milliseconds per step of bc_recipe.train (both
    data arms side by side, the default recipe's shapes) on each path, and the trained weights' hash on
    each, each measurement in a fresh process (numpy's OpenBLAS and torch's MKL choose their kernels
    once, as they load), the paths alternated, medians printed.

        python -m tools.bench kernels                    # the three paths below, 5 rounds of 1,000 steps
        python -m tools.bench kernels --paths held native --rounds 7 --steps 2000 --threads 1 2
        python -m tools.bench kernels --parts            # and where a step's time goes, part by part

    "held" is the published path (the stack's products on numpy's OpenBLAS held to its Haswell kernels,
    MKL_CBWR=COMPATIBLE: scale_data.py's setup region); "compatible" the products on torch's MKL held to
    COMPATIBLE (the published path before issue 47); "native" MKL's own kernels for this CPU. Run it
    alone: another busy process moves the figures far more than the path does.
    """
    import yaml

    p = parser("bench kernels", kernels_main.__doc__)
    arg = p.add_argument
    arg("--paths", nargs="+", default=list(KERNEL_PATHS), choices=list(KERNEL_PATHS), help="kernel paths")
    arg("--threads", nargs="+", type=int, default=[2], help="torch threads of each measurement")
    arg("--rounds", type=int, default=5, help="measurements per path, alternated")
    arg("--steps", type=int, default=1000, help="timed training steps per measurement")
    arg("--parts", action="store_true", help="also time each part of a step (its calls wrapped with clocks)")
    a = p.parse_args(argv)
    config.check(a, positive=("rounds", "steps"))
    if min(a.threads) < 1:
        raise DataError(f"--threads must be at least 1, got {min(a.threads)}")
    shape = (a.steps, config.CHAPTER.hidden_dim, config.CHAPTER.batch_size)
    runs = {f"{path} {t}": (path, t) for path in a.paths for t in a.threads}
    timed = {k: lambda _, p=p, t=t: train_step(p, *shape, t, a.parts) for k, (p, t) in runs.items()}
    got = alternate(timed, a.rounds)
    seed0 = yaml.safe_load(META.read_text())["reference_run"]["seeds"]["rows"][0]["steps"]
    full = seed0["full"] + seed0["short"]  # the default run's steps at seed 0, both budgets
    med = medians({k: [m["s_per_step"] for m in ms] for k, ms in got.items()})
    first = next(iter(runs))
    print(f"training steps, {a.steps} per measurement, {a.rounds} rounds alternated, medians:")
    for k, ms in got.items():
        each = ", ".join(f"{m['s_per_step'] * 1e3:.3f}" for m in ms)
        hashes = ", ".join(sorted({m["sha256"] for m in ms}))
        print(
            f"  {k:12s} threads {med[k] * 1e3:7.3f} ms/step (runs {each})  x{med[k] / med[first]:.2f} of"
            f" {first}; a default run's {full} steps: {med[k] * full:.1f} s; weights {hashes}"
            f" (OpenBLAS {ms[0]['blas'] or 'absent'})"
        )
    for k, ms in got.items() if a.parts else ():
        part = {n: statistics.median(m["parts"].get(n, 0.0) for m in ms) * 1e3 for n in PARTS}
        rest = med[k] * 1e3 - sum(part.values())
        each = ", ".join(f"{n} {v:.3f}" for n, v in part.items())
        print(f"  {k:12s} a step's parts, ms (medians): {each}; the rest (batch, loss, bar) {rest:.3f}")
        if "products" in ms[0]:
            bare = {n: statistics.median(m["products"][n] for m in ms) * 1e3 for n in ms[0]["products"]}
            print(
                f"  {k:12s} the bare products, ms: one arm's three {shape[2]}x{shape[1]}x{shape[1]} products"
                f" on one thread {bare['one arm']:.3f}, two arms' at once on two threads"
                f" {bare['two arms']:.3f} ({bare['two arms'] / (med[k] * 1e3):.0%} of the step)"
            )
    return 0


# --- reference: the lesson beside the reference chapter, cold, in one sitting ----------------------------
REF_SCRIPT = "curriculum/phase3_advanced/ch3.7_scale_data/scale_data.py"  # in a zero2robot checkout
REF_EPOCHS, REF_BATCH = 500, 128  # its defaults: every arm takes ceil(frames / batch) steps per epoch
VERSUS = "bench_reference"  # OUT/VERSUS.json


def ref_arm_steps(metrics: dict) -> int:
    """The reference's training work in arm-steps, from its metrics.json: its two arms (source, source +
    augmented) each train REF_EPOCHS epochs of ceil(frames / REF_BATCH) minibatches."""
    src, aug = metrics["source_frames"], metrics["aug_frames"]
    return REF_EPOCHS * (math.ceil(src / REF_BATCH) + math.ceil((src + aug) / REF_BATCH))


def versus(runs: dict, work: dict) -> dict:
    """Both chapters' wall-clock from a sitting's runs ({"ours": [...], "reference": [...]}, each run's
    wall_s) and training work (arm-steps): {"median": ..., "fastest": ...}, each as (ours s, reference s,
    ours / reference per unit of training work). The median is the figure; the fastest run of each side
    says how much of a median is the VM: a busy neighbour only ever adds time, and on the Zen 4 hosts
    the reference's runs fall near 85 s or past 100 s where ours move by at most 14% in a sitting."""
    got = {}
    for name, pick in (("median", statistics.median), ("fastest", min)):
        ours, ref = (pick(r["wall_s"] for r in runs[k]) for k in ("ours", "reference"))
        got[name] = (ours, ref, ours / ref * work["reference"] / work["ours"])
    return got


def timed_run(cmd: list, cwd: Path, env: dict, out: Path) -> tuple[float, str, dict]:
    """(wall seconds, stdout, metrics.json) of one cold run writing into `out` (a new folder)."""
    wall, p = clock(subprocess.run, cmd, cwd=cwd, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        tail = (p.stdout + p.stderr).strip().splitlines()[-1:] or [""]
        raise DataError(f"{shlex.join(map(str, cmd))} exited {p.returncode}: {tail[0]}")
    return wall, p.stdout, json.loads((out / "metrics.json").read_text())


def reference_args(arg, rounds: int) -> None:
    """--ref, --ref_python and --rounds (default `rounds`) of `reference` and `host`: defined here once."""
    arg("--ref", type=Path, required=True, help="a zero2robot checkout (holds " + REF_SCRIPT + ")")
    arg("--ref_python", type=Path, required=True, help="the Python of the reference's own venv")
    arg("--rounds", type=int, default=rounds, help="runs of each chapter, alternated")


def check_reference(a) -> None:
    """--ref, --ref_python and --rounds of `reference` and `host`, before any work: one line each."""
    config.check(a, positive=("rounds",))
    if not (a.ref / REF_SCRIPT).is_file():
        raise DataError(f"--ref {a.ref}: no {REF_SCRIPT} in it (a zero2robot checkout)")
    if not os.access(a.ref_python, os.X_OK) or a.ref_python.is_dir():
        raise DataError(f"--ref_python {a.ref_python}: not an executable Python")


def reference_main(argv: list[str]) -> int:
    """The lesson beside the reference chapter (zero2robot's ch3.7: its own checkout and venv), both cold
    (new output folders, demos generated, our result cache off), alternated, in one sitting:

        python -m tools.bench reference --ref ~/zero2robot --ref_python ~/z2r-venv/bin/python --rounds 2

    Ours is `scale_data.py --seed 0 --no-rerun --no-cache` on the published kernel path (its setup region
    holds it); the reference is its `scale_data.py --seed 0 --no-rerun --device cpu` on its own kernels
    (MKL's own, none of our kernel variables passed on). Per run: the wall-clock and the training work in
    arm-steps (ours: both budgets' steps, two arms each, from metrics.json; the reference: its two arms'
    epochs x minibatches, from its metrics.json); medians, their ratio and the ratio per unit of work, the
    same of each side's fastest run (versus), and ours's banner estimate against its own run. Run it alone:
    another busy process moves the figures more than the paths do. Writes OUT/bench_reference.json (default
    outputs/bench_reference).
    """
    p = parser("bench reference", reference_main.__doc__)
    arg = p.add_argument
    reference_args(arg, rounds=2)
    arg("--out", type=Path, default=ROOT / "outputs" / VERSUS, help="where bench_reference.json goes")
    a = p.parse_args(argv)
    check_reference(a)
    check_results(a.out, VERSUS)
    ours_env = {k: v for k, v in os.environ.items() if k not in ("MKL_CBWR", "OPENBLAS_CORETYPE")}
    ref_env = ours_env | {"PYTHONPATH": str(a.ref.resolve())}
    with tempfile.TemporaryDirectory(prefix="ch37-versus-") as tmp:

        def ours(r: int) -> dict:
            out = Path(tmp) / f"ours{r}"
            cmd = [sys.executable, a.script, "--seed", "0", "--no-rerun", "--no-cache", "--out", out]
            wall, stdout, m = timed_run(cmd, ROOT, ours_env, out)
            said = re.search(r"^about ([0-9.]+) min", stdout, re.MULTILINE)
            steps = 2 * sum(m["budgets"].values())  # two arms per budget
            est = float(said.group(1)) * 60 if said else None
            print(f"ours      {wall:6.1f} s, {steps} arm-steps; the banner said {said and said.group(0)}")
            return {"wall_s": wall, "arm_steps": steps, "banner_estimate_s": est}

        def ref(r: int) -> dict:
            out = Path(tmp) / f"ref{r}"
            cmd = [
                a.ref_python,
                a.ref / REF_SCRIPT,
                "--seed",
                "0",
                "--no-rerun",
                "--device",
                "cpu",
                "--out",
                out,
            ]
            wall, _, m = timed_run(cmd, a.ref, ref_env, out)
            print(f"reference {wall:6.1f} s, {ref_arm_steps(m)} arm-steps")
            return {"wall_s": wall, "arm_steps": ref_arm_steps(m)}

        got = alternate({"ours": ours, "reference": ref}, a.rounds)
    work = {k: runs[0]["arm_steps"] for k, runs in got.items()}
    both = versus(got, work)
    (ours_s, ref_s, per_work), fast = both["median"], both["fastest"]
    med = {"ours": ours_s, "reference": ref_s}
    ratio = ours_s / ref_s
    errors_ = [r["banner_estimate_s"] / r["wall_s"] - 1 for r in got["ours"] if r["banner_estimate_s"]]
    print(
        f"medians of {a.rounds}: ours {med['ours']:.1f} s ({work['ours']} arm-steps), the reference"
        f" {med['reference']:.1f} s ({work['reference']} arm-steps): ratio {ratio:.3f},"
        f" {per_work:.3f} per unit of training work"
    )
    print(
        f"fastest of {a.rounds}: ours {fast[0]:.1f} s, the reference {fast[1]:.1f} s:"
        f" {fast[2]:.3f} per unit of work"
    )
    if errors_:
        print("the banner's estimate against each of our runs: " + ", ".join(f"{e:+.0%}" for e in errors_))
    result = {
        "kind": VERSUS,
        "runs": got,
        "median_wall_s": med,
        "arm_steps": work,
        "ratio": ratio,
        "ratio_per_unit_of_work": per_work,
        "fastest_ratio_per_unit_of_work": fast[2],
        "banner_estimate_errors": errors_,
        "reference": {"script": REF_SCRIPT, "python": str(a.ref_python), "commit": ref_commit(a.ref)},
        "provenance": provenance(a.script),
    }
    print(f"wrote {write_result(a.out / f'{VERSUS}.json', result)}")
    return 0


# --- host: issue 59's check of a host, one command -------------------------------------------------------
HOST_LOGS = ("bench_reference.txt", "bench_lesson.txt", "bench_kernels.txt")  # each step's printed output


def tee(cmd: list, log: Path) -> None:
    """Run `cmd` from the checkout, its output (stdout and stderr) shown as it comes and written to `log`
    when it ends (atomically); a DataError naming the log if it fails."""
    lines = []
    cmd = [str(c) for c in cmd]
    with subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
        for line in proc.stdout:
            print(line, end="", flush=True)
            lines.append(line)
    write_atomic(log, "".join(lines))
    if proc.returncode:
        raise DataError(f"{shlex.join(cmd)} exited {proc.returncode}; its output is in {log}")


def host_summary(out: Path, cpu: str) -> list[str]:
    """Issue 59's figures for a host, from what `host` wrote to `out`: the time of both chapters and the
    ratio per unit of work, the banner against each of our runs, the in-run training rate against the best
    matrix rate, and each kernel path's weights (the bits table's row for `cpu`, the host's cpu_model)."""
    v = json.loads((out / f"{VERSUS}.json").read_text())
    lesson, kernels = ((out / name).read_text() for name in HOST_LOGS[1:])
    n, both = len(v["runs"]["ours"]), versus(v["runs"], v["arm_steps"])

    def chapters(name: str, key: str) -> str:  # "both chapters, medians of 3: ours 66.9 s, ..."
        ours, ref, per = both[key]
        return (
            f"both chapters, {name} of {n}: ours {ours:.1f} s, the reference {ref:.1f} s: {per:.3f} per unit"
        )

    lines = [
        f"host: {cpu or v['provenance']['platform']['cpu_model']}, commit"
        f" {v['provenance']['git']['commit'][:7]}{' (dirty)' if v['provenance']['git']['dirty'] else ''}",
        chapters("medians", "median") + " of training work (issue 59: at most 0.60)",
        chapters("fastest", "fastest") + " of training work",
        "the banner against each of our runs: "
        + (", ".join(f"{e:+.0%}" for e in v["banner_estimate_errors"]) or "no estimate"),
    ]
    lines += [
        ln.strip() for ln in lesson.splitlines() if ln.startswith(("in-run training:", "the run printed"))
    ]
    lines += [  # "held 2 threads 3.913 ms/step (...) ...; weights ebffe19e (OpenBLAS Haswell)"
        f"{got[1]}: {got[2]} ms a step, weights {got[3]}"
        for got in re.finditer(r"^\s+(\w+) \d+ +threads +([0-9.]+) ms/step .* weights (\w+)", kernels, re.M)
    ]
    return lines


def host_main(argv: list[str]) -> int:
    """Issue 59's check of this host, one command, alone on the machine (about 15 minutes):

        python -m tools.bench host --ref ~/zero2robot --ref_python ~/z2r-venv/bin/python --out OUT

    In that order, each in a process of its own: [--wallclock: python -m tools.wallclock, this tier's and
    CPU model's row of wallclock.csv, so the banner below shows it as it ran]; python -m tools.bench
    reference (both chapters, cold, alternated, --rounds each); python -m tools.bench lesson (the in-run
    training rate against this machine's best); python -m tools.bench kernels --rounds 3 --steps 500
    --parts (each kernel path's step and weights). OUT keeps bench_reference.json and each step's output
    (bench_reference.txt, bench_lesson.txt, bench_kernels.txt, wallclock.txt), and the summary printed
    last: the figures issue 59's note gives for a host."""
    p = parser("bench host", host_main.__doc__)
    arg = p.add_argument
    reference_args(arg, rounds=3)
    arg("--wallclock", action="store_true", help="first write this host's wallclock.csv row")
    arg("--out", type=Path, required=True, help="where the results and outputs go")
    a = p.parse_args(argv)
    check_reference(a)
    logs = (*HOST_LOGS, "wallclock.txt", "host_summary.txt")
    check_results(a.out, VERSUS, beside={VERSUS: [a.out / name for name in logs]})
    a.out.mkdir(parents=True, exist_ok=True)
    me = [sys.executable, "-m", "tools.bench"]
    cmds = (
        [
            *me,
            "reference",
            "--ref",
            a.ref,
            "--ref_python",
            a.ref_python,
            "--rounds",
            a.rounds,
            "--out",
            a.out,
        ],
        [*me, "lesson"],
        [*me, "kernels", "--rounds", 3, "--steps", 500, "--parts"],
    )
    steps = list(zip(HOST_LOGS, cmds, strict=True))
    if a.wallclock:
        steps.insert(0, ("wallclock.txt", [sys.executable, "-m", "tools.wallclock"]))
    for name, cmd in steps:
        print(f"=== {shlex.join(map(str, cmd))}", flush=True)
        tee(cmd, a.out / name)
    summary = host_summary(a.out, cli.this_cpu())
    print("\n".join(["=== issue 59's figures for this host", *summary]))
    write_atomic(a.out / "host_summary.txt", "\n".join(summary) + "\n")
    return 0


def ref_commit(ref: Path) -> str | None:
    """The reference checkout's commit (git rev-parse HEAD), or None where it is no git work tree."""
    p = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ref, capture_output=True, text=True)
    return p.stdout.strip() if p.returncode == 0 else None


# --- writer: the one-pass LeRobot v3 writer vs LeRobot's per-frame path ---------------------------------
def synthetic_demos(n: int, frames: int, seed: int = 0) -> list[dict]:
    """n demos of `frames` frames: random float32 arrays of the PushT set's features."""
    import numpy as np

    import gen_demos_pusht

    m = gen_demos_pusht.PUSHT.spec
    rng = np.random.default_rng(seed)
    return [
        {
            "observation.state": rng.standard_normal((frames, len(m.state_names))).astype(np.float32),
            "action": rng.standard_normal((frames, len(m.action_names))).astype(np.float32),
            "next.success": (np.arange(frames) == frames - 1)[:, None],
        }
        for _ in range(n)
    ]


def write_seconds(eps: list[dict], root: Path, per_frame: bool = False) -> float:
    """Seconds to write `eps` with write_dataset (per_frame: every feature through LeRobot's path)."""
    import gen_demos_pusht
    from datagen import write_dataset
    from lerobot_v3 import features

    m = gen_demos_pusht.PUSHT.spec
    feats = features(m.state_names, m.action_names, env_state_names=m.env_state_names)
    kw = dict(repo_id="local/bench", fps=m.fps, robot_type=m.robot_type, task=m.task, feats=feats)
    seconds, _ = clock(write_dataset, root, **kw, episodes=eps, stamp={}, per_frame=per_frame)
    shutil.rmtree(root)
    return seconds


def writer_main(argv: list[str]) -> int:
    """Seconds to write N PushT demos with lerobot_v3.dataset.write_dataset: the one-pass writer vs
    LeRobot's per-frame path (what write_dataset did before issue 19), alternating. Asserts nothing.

        python -m tools.bench writer                 # 1,000 demos of 30 frames, 3 rounds, medians
        python -m tools.bench writer --demos 200 --rounds 1

    The demos are synthetic float32 arrays of the PushT set's features (gen_demos_pusht.py's, with
    observation.environment_state filled from the state), so the time is the writer's alone. The
    LeRobot path is taken through the same write_dataset (folder, stamp, rename) with per_frame=True.
    """
    p = parser("bench writer", writer_main.__doc__, script=False)
    arg = p.add_argument
    arg("--demos", type=int, default=1000)
    arg("--frames", type=int, default=30, help="frames per demo")
    arg("--rounds", type=int, default=3)
    a = p.parse_args(argv)
    if min(a.demos, a.frames, a.rounds) < 1:
        raise DataError("--demos, --frames and --rounds must be positive")
    eps = synthetic_demos(a.demos, a.frames)

    def said(r, times):
        print(
            f"round {r}: lerobot {times['lerobot'][-1]:.2f} s, direct {times['direct'][-1]:.2f} s", flush=True
        )

    with tempfile.TemporaryDirectory() as tmp:
        write_seconds(eps[:2], Path(tmp) / "warm")  # imports and caches, not timed
        measure = {
            "lerobot": lambda r: write_seconds(eps, Path(tmp) / f"lerobot{r}", per_frame=True),
            "direct": lambda r: write_seconds(eps, Path(tmp) / f"direct{r}"),
        }
        old, new = medians(alternate(measure, a.rounds, after_round=said)).values()
    n = a.demos
    print(f"{n} demos x {a.frames} frames, median of {a.rounds} rounds:")
    print(f"  LeRobot per-frame path {old:.2f} s ({1e3 * old / n:.1f} ms/demo)")
    print(f"  one-pass writer        {new:.2f} s ({1e3 * new / n:.2f} ms/demo), {old / new:.1f}x faster")
    return 0


SUBCOMMANDS = {
    "lesson": lesson_main,
    "engine": engine_main,
    "envs": envs_main,
    "gym_pusht": gym_pusht_main,
    "kernels": kernels_main,
    "reference": reference_main,
    "host": host_main,
    "writer": writer_main,
}


def main(argv: list[str]) -> int:
    return subcommands("bench", SUBCOMMANDS, argv, __doc__)


if __name__ == "__main__":
    errors.main(main)
