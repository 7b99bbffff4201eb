"""What the lesson's kernel path costs its training: milliseconds per step of bc_recipe.train (both data
arms side by side, the default recipe's shapes) on each path, and the trained weights' hash on each,
each measurement in a fresh process (numpy's OpenBLAS and torch's MKL choose their kernels once, as
they load), the paths alternated, medians printed.

    python -m tools.bench_kernels                        # the three paths below, 5 rounds of 1,000 steps
    python -m tools.bench_kernels --paths held native --rounds 7 --steps 2000 --threads 1 2

Paths: "held" is the published one (the stack's products on numpy's OpenBLAS held to its Haswell
kernels, MKL_CBWR=COMPATIBLE: scale_data.py's setup region); "compatible" the products on torch's MKL
held to COMPATIBLE (the published path before issue 47); "native" on MKL's own kernels for this CPU.
Run it alone: another busy process moves the figures far more than the path does. Exit codes: 0 ok,
2 bad input.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys

import yaml

from ch37 import ROOT, config, errors
from tools.common import META, parser

# The environment and the stack's products of each path ("torch": MLPStack's products on torch's MKL)
PATHS = {
    "held": ({"OPENBLAS_CORETYPE": "Haswell", "MKL_CBWR": "COMPATIBLE"}, "numpy"),
    "compatible": ({"MKL_CBWR": "COMPATIBLE"}, "torch"),
    "native": ({}, "torch"),
}

# One measurement: the default recipe's shapes (hidden 512, batch 128, two arms of 420 and 3,490 frames:
# the seed-0 source and source + augmented sizes, from its budgets; a step's time does not depend on
# them), `steps` timed after a warm-up of 50; the weights' sha256 after the timed steps.
CHILD = """
import hashlib, json, sys, time
import numpy as np, torch
import bc_recipe as bc
from ch37 import ensemble
steps, hidden, batch, threads = map(int, sys.argv[1:5])
if sys.argv[5] == "torch":  # the products on torch (MKL), as MLPStack runs them without numpy's OpenBLAS
    ensemble.one_blas_thread = lambda: False
torch.set_num_threads(threads)
rng = np.random.default_rng(0)
data = [(rng.normal(size=(n, 10)).astype(np.float32), rng.normal(size=(n, 2)).astype(np.float32))
        for n in (420, 3490)]
init = bc.init_weights(hidden, 0)
bc.train(data, 50, init, batch_size=batch, lr=1e-3, seed=0)
t0 = time.perf_counter()
pols, _ = bc.train(data, steps, init, batch_size=batch, lr=1e-3, seed=0)
dt = time.perf_counter() - t0
weights = b"".join(t.numpy().tobytes() for p in pols for t in p.net.state_dict().values())
print(json.dumps({"s_per_step": dt / steps, "sha256": hashlib.sha256(weights).hexdigest()[:8],
                  "blas": ensemble.blas_core()}))
"""


def measure(path: str, steps: int, hidden: int, batch: int, threads: int) -> dict:
    env, products = PATHS[path]
    base = {k: v for k, v in os.environ.items() if k not in ("MKL_CBWR", "OPENBLAS_CORETYPE")}
    cmd = [sys.executable, "-c", CHILD, str(steps), str(hidden), str(batch), str(threads), products]
    p = subprocess.run(cmd, cwd=ROOT, env=base | env, capture_output=True, text=True)
    if p.returncode != 0:
        raise errors.DataError(f"the timing process for {path} failed: {p.stderr.strip().splitlines()[-1]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    p = parser("bench_kernels", __doc__)
    p.add_argument("--paths", nargs="+", default=list(PATHS), choices=list(PATHS), help="kernel paths")
    p.add_argument("--threads", nargs="+", type=int, default=[2], help="torch threads of each measurement")
    p.add_argument("--rounds", type=int, default=5, help="measurements per path, alternated")
    p.add_argument("--steps", type=int, default=1000, help="timed training steps per measurement")
    a = p.parse_args(argv)
    config.check(a, positive=("rounds", "steps"))
    if min(a.threads) < 1:
        raise errors.DataError(f"--threads must be at least 1, got {min(a.threads)}")
    recipe = config.CHAPTER
    runs = [(path, t) for path in a.paths for t in a.threads]
    got = {r: [] for r in runs}
    for r in range(a.rounds):
        for path, t in runs if r % 2 == 0 else reversed(runs):  # alternate the order each round
            got[path, t].append(measure(path, a.steps, recipe.hidden_dim, recipe.batch_size, t))
    seed0 = yaml.safe_load(META.read_text())["reference_run"]["seeds"]["rows"][0]["steps"]
    full = seed0["full"] + seed0["short"]  # the default run's steps at seed 0, both budgets
    base = statistics.median(m["s_per_step"] for m in got[runs[0]])
    print(f"training steps, {a.steps} per measurement, {a.rounds} rounds alternated, medians:")
    for (path, t), ms in got.items():
        med = statistics.median(m["s_per_step"] for m in ms)
        hashes = sorted({m["sha256"] for m in ms})
        each = ", ".join(f"{m['s_per_step'] * 1e3:.3f}" for m in ms)
        print(
            f"  {path:10s} {t} threads {med * 1e3:7.3f} ms/step (runs {each})  x{med / base:.2f} of "
            f"{runs[0][0]}; "
            f"a default run's {full} steps: {med * full:.1f} s; weights {', '.join(hashes)} "
            f"(OpenBLAS {ms[0]['blas'] or 'absent'})"
        )
    return 0


if __name__ == "__main__":
    errors.main(main)
