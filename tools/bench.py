"""Where the time of one scale_data.py run goes. Prints figures; asserts nothing.

    python -m tools.bench                 # the default run (seed 0), --no-rerun --no-cache
    python -m tools.bench --smoke         # the smoke run
    python -m tools.bench --repeat 3      # median of 3 runs per phase
    python -m tools.bench --epochs 100    # other flags go to scale_data.py

It runs scale_data.py in this process as `python scale_data.py` would (runpy), charges the time
between two lines of the script's own top level to the region of the first (sys.monitoring line events
on that code only, so nothing else slows down), and wraps the shared functions the script calls (demo
generation, dataset loading and writing, the engine's attempts, bc_recipe's training and rollouts) to
attribute their time. For training it reports achieved GFLOP/s next to a dense fp32 matmul measured in
the same process, i.e. how close training runs to the machine's limit.
"""

from __future__ import annotations

import importlib
import resource
import runpy
import statistics
import sys
import tempfile
import time
from pathlib import Path

from ch37 import errors
from tools.common import parse_regions, parser

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
    from datagen import engine, task

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
        (task, "write_dataset", "write augmented LeRobot set"),  # datagen.save looks it up there
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


def report(runs: list[dict], walls: list[float], import_s: float, title: str) -> None:
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


def main(argv: list[str]) -> int:
    p = parser("bench", __doc__)
    p.add_argument("--smoke", action="store_true", help="benchmark the smoke run")
    p.add_argument("--repeat", type=int, default=1, help="runs per phase; the median is printed")
    p.add_argument("--seed", type=int, default=0)
    a, extra = p.parse_known_args(argv)  # anything else goes to scale_data.py, e.g. --epochs 100
    t0 = time.perf_counter()
    importlib.import_module("torch")  # here, after the flags: its import time is a phase of the report
    import_s = time.perf_counter() - t0
    runs, walls = [], []
    with tempfile.TemporaryDirectory(prefix="ch37-bench-") as tmp:
        for i in range(a.repeat):
            args = ["--seed", str(a.seed), "--no-rerun", "--no-cache", "--out", f"{tmp}/run{i}"]
            t0 = time.perf_counter()
            runs.append(run_once(a.script, args + ["--smoke"] * a.smoke + extra))
            walls.append(time.perf_counter() - t0)
    report(runs, walls, import_s, f"{a.script.name} {'--smoke' if a.smoke else '(default)'} seed {a.seed}")
    return 0


if __name__ == "__main__":
    errors.main(main)
