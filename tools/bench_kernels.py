"""What holding MKL to one kernel branch costs the lesson's training: seconds per step of bc_recipe.train
(both data arms side by side, the default recipe's shapes), each measurement in a fresh process (MKL
reads MKL_CBWR once, as it loads), the branches alternated, medians printed.

    python -m tools.bench_kernels                          # native vs COMPATIBLE, 5 rounds of 1,000 steps
    python -m tools.bench_kernels --branches native COMPATIBLE AVX2 --rounds 7 --steps 2000

"native" leaves MKL_CBWR unset (MKL's own choice for this CPU). Run it alone: another busy process
moves the figures far more than the branch does. Exit codes: 0 ok, 2 bad input.
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

# One measurement: the default recipe's shapes (hidden 512, batch 128, two arms of 420 and 3,490 frames:
# the seed-0 source and source + augmented sizes, from its budgets; a step's time does not depend on
# them), `steps` timed after a warm-up of 50.
CHILD = """
import json, sys, time
import numpy as np, torch
import bc_recipe as bc
steps, hidden, batch = map(int, sys.argv[1:4])
rng = np.random.default_rng(0)
data = [(rng.normal(size=(n, 10)).astype(np.float32), rng.normal(size=(n, 2)).astype(np.float32))
        for n in (420, 3490)]
init = bc.init_weights(hidden, 0)
bc.train(data, 50, init, batch_size=batch, lr=1e-3, seed=0)
t0 = time.perf_counter()
bc.train(data, steps, init, batch_size=batch, lr=1e-3, seed=0)
print(json.dumps({"s_per_step": (time.perf_counter() - t0) / steps, "threads": torch.get_num_threads()}))
"""


def measure(branch: str, steps: int, hidden: int, batch: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "MKL_CBWR"}
    if branch != "native":
        env["MKL_CBWR"] = branch
    cmd = [sys.executable, "-c", CHILD, str(steps), str(hidden), str(batch)]
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        raise errors.DataError(f"the timing process for {branch} failed: {p.stderr.strip().splitlines()[-1]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def main(argv: list[str]) -> int:
    p = parser("bench_kernels", __doc__)
    p.add_argument("--branches", nargs="+", default=["native", "COMPATIBLE"], help="MKL_CBWR values")
    p.add_argument("--rounds", type=int, default=5, help="measurements per branch, alternated")
    p.add_argument("--steps", type=int, default=1000, help="timed training steps per measurement")
    a = p.parse_args(argv)
    config.check(a, positive=("rounds", "steps"))
    recipe = config.CHAPTER
    times = {b: [] for b in a.branches}
    for r in range(a.rounds):
        for b in a.branches if r % 2 == 0 else reversed(a.branches):  # alternate the order each round
            times[b].append(measure(b, a.steps, recipe.hidden_dim, recipe.batch_size)["s_per_step"])
    seed0 = yaml.safe_load(META.read_text())["reference_run"]["seeds"]["rows"][0]["steps"]
    full = seed0["full"] + seed0["short"]  # the default run's steps at seed 0, both budgets
    base = statistics.median(times[a.branches[0]])
    print(f"training steps, {a.steps} per measurement, {a.rounds} rounds alternated, medians:")
    for b, ts in times.items():
        med = statistics.median(ts)
        print(
            f"  {b:12s} {med * 1e3:7.3f} ms/step (runs {', '.join(f'{t * 1e3:.3f}' for t in ts)})  "
            f"x{med / base:.2f} of {a.branches[0]}; a default run's {full} steps: {med * full:.1f} s"
        )
    return 0


if __name__ == "__main__":
    errors.main(main)
