"""Where the time of one scale_data.py run goes. Prints figures; asserts nothing.

    python -m tools.bench                 # the default run (seed 0), --no-rerun --no-cache
    python -m tools.bench --smoke         # the smoke run
    python -m tools.bench --repeat 3      # median of 3 runs per phase
    python -m tools.bench --epochs 100    # other flags go to scale_data.py

It executes scale_data.py statement by statement in one process (the same code, not a copy),
times each phase, and wraps the chapter's own functions (demo generation, dataset loading,
training, rollouts) to attribute their time. For training it reports achieved GFLOP/s next to a
dense fp32 matmul measured in the same process, i.e. how close training runs to the machine's limit.
"""

from __future__ import annotations

import argparse
import ast
import resource
import statistics
import sys
import tempfile
import time

from ch37 import ROOT


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


def run_once(argv: list[str]) -> dict:
    """Execute scale_data.py with `argv` in this process; return {phase: seconds} and facts."""
    from ch37 import demos, lerobot_io, parallel

    src = (ROOT / "scale_data.py").read_text()
    tree = ast.parse(src)
    times: dict[str, float] = {}  # regions (and imports)
    inner: dict[str, float] = {}  # calls inside them: "of which" lines
    facts: dict = {"train_steps": {}, "train_rows": {}}

    def add(phase, dt, into=None):
        into = inner if into is None else into
        into[phase] = into.get(phase, 0.0) + dt

    def timed(phase, fn):
        def wrapper(*a, **k):
            if facts.get("generating") and phase.startswith("write"):
                return fn(*a, **k)  # already inside "demo generation"
            facts["generating"] = phase.startswith("demo generation")
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                facts["generating"] = False
                add(phase, time.perf_counter() - t0)

        return wrapper

    # Patched before scale_data.py's own `from ch37... import` lines run, so the script calls the wrappers.
    orig = {
        "ensure": demos.ensure_demos,
        "load": lerobot_io.load_arrays,
        "write": lerobot_io.write_dataset,
        "pmap": parallel.parallel_map,
    }
    demos.ensure_demos = timed("demo generation (or cache check)", orig["ensure"])
    lerobot_io.load_arrays = timed("load LeRobot sets (all three)", orig["load"])
    lerobot_io.write_dataset = timed("write augmented LeRobot set", orig["write"])
    parallel.parallel_map = timed("augmentation re-solves", orig["pmap"])
    sys.argv = ["scale_data.py", *argv]
    ns = {"__name__": "__main__", "__file__": str(ROOT / "scale_data.py")}
    region = "docstring"
    lines = src.splitlines()
    try:
        for node in tree.body:
            for ln in range(node.lineno - 1, 0, -1):  # the region marker above this statement
                if lines[ln - 1].startswith("# --- region:"):
                    region = lines[ln - 1].split(":", 1)[1].strip(" -")
                    break
            code = compile(ast.Module([node], []), "scale_data.py", "exec")
            phase = "import" if isinstance(node, (ast.Import, ast.ImportFrom)) else region
            t0 = time.perf_counter()
            exec(code, ns)
            add(phase, time.perf_counter() - t0, times)
            if isinstance(node, ast.FunctionDef) and node.name == "train":

                def train(datasets, steps, _f=ns["train"]):
                    t0 = time.perf_counter()
                    out = _f(datasets, steps)
                    arm = f"train budget {len(facts['train_steps']) + 1} ({len(datasets)} arms side by side)"
                    add(arm, time.perf_counter() - t0)
                    facts["train_steps"][arm] = steps * len(datasets)  # arm-steps
                    facts["train_rows"][arm] = steps * len(datasets) * ns["args"].batch_size  # full batches
                    return out

                ns["train"] = train
            if isinstance(node, ast.FunctionDef) and node.name == "evaluate":
                ns["evaluate"] = timed("rollouts (all arms)", ns["evaluate"])
    finally:
        demos.ensure_demos, lerobot_io.load_arrays = orig["ensure"], orig["load"]
        lerobot_io.write_dataset, parallel.parallel_map = orig["write"], orig["pmap"]
    args = ns["args"]
    facts.update(batch=args.batch_size, hidden=args.hidden_dim, device=args.device)
    return {"times": times, "inner": inner, "facts": facts}


def main() -> None:
    ap = argparse.ArgumentParser(prog="python -m tools.bench", description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="benchmark the smoke run")
    ap.add_argument("--repeat", type=int, default=1, help="runs per phase; the median is printed")
    ap.add_argument("--seed", type=int, default=0)
    a, extra = ap.parse_known_args()  # anything else goes to scale_data.py, e.g. --epochs 100
    t_imp = time.perf_counter()
    import torch  # noqa: F401  (counted as the import phase of the first run below)

    import_s = time.perf_counter() - t_imp
    runs, walls = [], []
    with tempfile.TemporaryDirectory(prefix="ch37-bench-") as tmp:
        for i in range(a.repeat):
            argv = ["--seed", str(a.seed), "--no-rerun", "--no-cache", "--out", f"{tmp}/run{i}"]
            argv += (["--smoke"] if a.smoke else []) + extra
            t0 = time.perf_counter()
            runs.append(run_once(argv))
            walls.append(time.perf_counter() - t0)
    f = runs[0]["facts"]
    gflops = matmul_gflops(f["batch"], f["hidden"]) if f["device"] == "cpu" else float("nan")
    import pusht_env  # already loaded by the runs; the policy maps a PushT state to a PushT action

    per_row = step_flops(1, f["hidden"], pusht_env.OBS_DIM, pusht_env.ACT_DIM)  # FLOPs per row trained
    print(
        f"\nscale_data.py {'--smoke' if a.smoke else '(default)'} seed {a.seed}, "
        f"median of {a.repeat} run(s), device {f['device']}, torch threads {torch.get_num_threads()}"
    )
    print(f"{'phase':44s} {'seconds':>8s}")
    print(f"{'import torch (before the first run)':44s} {import_s:8.2f}")

    def med(part, key):
        return statistics.median(r[part].get(key, 0.0) for r in runs)

    for ph in dict.fromkeys(k for r in runs for k in r["times"]):
        print(f"{ph:44s} {med('times', ph):8.2f}")
        for sub in dict.fromkeys(k for r in runs for k in r["inner"]):
            owner = {
                "wrangle": ("demo generation", "load"),
                "augment": ("augmentation", "write"),
                "measure": ("train", "rollouts"),
            }.get(ph, ())
            if not sub.startswith(owner):
                continue
            extra = ""
            if sub in f["train_steps"]:
                steps, sec = f["train_steps"][sub], med("inner", sub)
                rate = f["train_rows"][sub] * per_row / sec / 1e9
                extra = (
                    f"  {steps} steps, {sec / steps * 1e3:.2f} ms/step, {rate:.0f} GFLOP/s "
                    f"= {rate / gflops:.0%} of matmul"
                )
            print(f"  of which {sub:44s} {med('inner', sub):8.2f}{extra}")
    total_steps, flops = sum(f["train_steps"].values()), sum(f["train_rows"].values()) * per_row
    train_s = statistics.median(
        sum(v for k, v in r["inner"].items() if k.startswith("train budget")) for r in runs
    )
    rate = flops / train_s / 1e9
    print(f"{'wall (one run, in process)':40s} {statistics.median(walls):8.2f}")
    rows, b, h = sum(f["train_rows"].values()), f["batch"], f["hidden"]
    print(
        f"training: {total_steps} steps, {rows} rows x {per_row / 1e6:.2f} MFLOP = {flops / 1e12:.2f} TFLOP "
        f"in {train_s:.1f} s -> {rate:.0f} GFLOP/s; dense matmul ({b}x{h} @ {h}x{h}) in this process: "
        f"{gflops:.0f} GFLOP/s; training at {rate / gflops:.0%} of it; "
        f"floor at matmul rate {flops / gflops / 1e9:.1f} s"
    )
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
