#!/usr/bin/env bash
# The GPU check (../shared/GPU.md), one call on a bare GPU machine that has PyTorch and no registry:
# install the carried wheels, then time the lesson on cuda and write what it printed to $OUT.
#
#   here:   bash tools/gpu_check.sh --wheels [lesson|value]
#                      download the wheels the lesson (about 58 MiB) or tools.replay value on gym-pusht
#                      (about 28 MiB: no LeRobot) needs beyond the GPU image into .whl/ (git-ignored)
#   there:  bash tools/gpu_check.sh              # the check below; OUT=<folder> (default /tmp/gpu_check)
#   there:  bash tools/gpu_check.sh --run CMD... # install the carried wheels, then run CMD
#
# What it runs there, in this order (each step's output in $OUT/gpu_check.log):
#   1. the smoke run on cuda (seconds; stops the check early when the set-up is broken)
#   2. python -m tools.wallclock: the default run at seed 0, cold, its wallclock.csv row for this card
#   3. the default run at seed 0 on cuda, cold (fresh folder), then warm (same folder: demo sets
#      reused, result cache off), each timed, their metrics.json kept
#   4. one training step of bc_recipe.train at the default shapes (hidden 512, batch 128, both data
#      arms stacked), on cuda and on this machine's CPU, seconds per step, median of 5 rounds
#   5. with the minutes left (GPU_CHECK_SECONDS, default 560, counted from the start): LeRobot's ACT row
#      of transfer-cube on cuda, tools/lerobot_row.sh aloha_transfer_cube at ACT_SEEDS (default 1) seeds
#      and ACT_STEPS (default 5000) steps, cut off at the budget; its evaluations, training configs and
#      logs (not the checkpoints) in $OUT/act_row.tar.gz
# Wheels: the lesson's imports (mujoco, lerobot and what lerobot's dataset code imports) minus what the
# image holds, with termcolor and gym-aloha's model files for step 5 (lerobot-train and transfer-cube);
# mujoco-studio (the viewer, 13 MB) is left out: the lesson never draws through it.
set -uo pipefail
cd "$(dirname "$0")/.."
usage="usage: bash tools/gpu_check.sh [--wheels [lesson|value] | --run CMD [ARG...] | --help]"

# every argument is read before anything runs: a word it does not know once started the check (a pip
# install, a log in \$OUT) on a machine that may have no GPU
case "${1:-}" in
-h | --help)
    echo "$usage"
    sed -n '2,/^set -uo/p' "$0" | sed '$d; s/^# \{0,1\}//'  # the header above: what each form does
    exit 0
    ;;
--wheels)
    case "${2:-lesson}" in lesson | value) ;; *) echo "error: --wheels takes lesson or value, not '$2'; $usage" >&2 && exit 2 ;; esac
    [ $# -le 2 ] || { echo "error: --wheels takes one word (lesson or value), not '${*:2}'; $usage" >&2 && exit 2; }
    ;;
--run) [ $# -ge 2 ] || { echo "error: --run needs a command to run; $usage" >&2 && exit 2; } ;;
*) [ $# -eq 0 ] || { echo "error: unknown argument '$1'; $usage" >&2 && exit 2; } ;;
esac

if [ "${1:-}" = "--wheels" ]; then
    py=.venv/bin/python
    plat="--platform manylinux1_x86_64 --platform manylinux2014_x86_64"
    for n in 17 24 27 28; do plat+=" --platform manylinux_2_${n}_x86_64"; done
    mkdir -p .whl
    grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo /.whl/ >>.git/info/exclude
    common="dill glfw gymnasium mujoco mujoco-core farama-notifications cffi pycparser"
    case "${2:-lesson}" in
        lesson) names="$common av datasets diffusers draccus gym-aloha lerobot mergedeep multiprocess pytz termcolor tzdata" ;;
        value) names="$common gym-pusht pymunk pygame shapely" ;;
    esac
    for name in $names; do
        pin=$(grep -io "^$name==[^ ;]*" requirements.lock) || { echo "$name: not in requirements.lock"; exit 2; }
        # shellcheck disable=SC2086
        $py -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
            $plat -d .whl "$pin" || exit 2
    done
    du -sh .whl
    exit 0
fi
if [ "${1:-}" = "--run" ]; then
    shift
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site \
        .whl/*.whl || exit 2
    PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1 exec "$@"
fi

OUT=${OUT:-/tmp/gpu_check}
mkdir -p "$OUT"
exec > >(tee "$OUT/gpu_check.log") 2>&1
export PYTHONUNBUFFERED=1
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site \
    .whl/*.whl || exit 2
export PYTHONPATH=/tmp/site
step() { echo; echo "=== $* ($(date -u +%H:%M:%S))"; }

step machine
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
grep -m1 "model name" /proc/cpuinfo
nproc
git log -1 --format='commit %H' 2>/dev/null || echo "commit: (no git here)"
python3 -c "import platform, numpy, torch, mujoco, lerobot; \
print('python', platform.python_version(), '| torch', torch.__version__, '| cuda', torch.version.cuda, \
'| numpy', numpy.__version__, '| mujoco', mujoco.__version__, '| lerobot', lerobot.__version__)" || exit 1
python3 -m pip list 2>/dev/null | grep -iE "^(pandas|pyarrow|huggingface|datasets|pillow|matplotlib) " >"$OUT/pip.txt"

step "1. smoke on cuda"
timed() { local t0=$SECONDS; "$@"; local rc=$?; echo "[$((SECONDS - t0)) s, rc $rc] $*"; return $rc; }
timed python3 scale_data.py --smoke --seed 0 --device cuda --no-rerun --no-cache --out /tmp/smoke || exit 1
cp /tmp/smoke/metrics.json "$OUT/metrics_smoke.json"

step "2. wallclock row (default run, seed 0, cold)"
timed python3 -m tools.wallclock && cp wallclock.csv "$OUT/wallclock.csv"

step "3a. default run, cold"
timed python3 scale_data.py --seed 0 --device cuda --no-rerun --no-cache --out /tmp/run &&
    cp /tmp/run/metrics.json "$OUT/metrics_cold.json"
step "3b. default run, warm (demo sets reused, result cache off)"
timed python3 scale_data.py --seed 0 --device cuda --no-rerun --no-cache --out /tmp/run &&
    cp /tmp/run/metrics.json "$OUT/metrics_warm.json"

step "4. one training step (hidden 512, batch 128, both arms stacked)"
python3 - <<'EOF' | tee "$OUT/step.json"
import json, statistics, time
import numpy as np, torch
import bc_recipe as bc

rng = np.random.default_rng(0)
data = [(rng.normal(size=(n, 10)).astype(np.float32), rng.normal(size=(n, 2)).astype(np.float32))
        for n in (420, 3490)]
init = bc.init_weights(512, 0)
out = {}
for device, steps in (("cuda", 2000), ("cpu", 300)):
    bc.train(data, 50, init, batch_size=128, lr=1e-3, seed=0, device=device)  # warm-up
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        bc.train(data, steps, init, batch_size=128, lr=1e-3, seed=0, device=device)  # ends on .item(): synchronised
        times.append((time.perf_counter() - t0) / steps)
    out[device] = {"s_per_step_median": statistics.median(times), "rounds": times, "steps": steps,
                   "threads": torch.get_num_threads()}
print(json.dumps(out, indent=1))
EOF
step "5. LeRobot's ACT row of transfer-cube on cuda, with the minutes left"
left=$((${GPU_CHECK_SECONDS:-560} - SECONDS))
if [ "$left" -ge 120 ]; then
    echo "budget: $left s; ACT_SEEDS=${ACT_SEEDS:-1} ACT_STEPS=${ACT_STEPS:-5000}"
    timed env DEVICE=cuda PYTHON=python3 WORKERS=$(($(nproc) > 3 ? $(nproc) - 3 : 1)) timeout "$left" \
        bash tools/lerobot_row.sh aloha_transfer_cube /tmp/act "${ACT_SEEDS:-1}" "${ACT_STEPS:-5000}" 50 3
    # what the row is counted from, and how far each part got: never the checkpoints (~50 MB each)
    (cd /tmp/act && find . \( -name lerobot_eval.json -o -name '*.log' -o -name generation_report.json \
        -o -path '*/pretrained_model/train_config.json' \) -print0 | tar czf "$OUT/act_row.tar.gz" --null -T -)
else
    echo "skipped: $left s left of GPU_CHECK_SECONDS=${GPU_CHECK_SECONDS:-560}"
fi
step done
