#!/usr/bin/env bash
# Issue 49's LeRobot row (docs/gym_pusht.md): what the engine's demos buy LeRobot's diffusion policy on
# LeRobot's own PushT, trained by lerobot-train and scored by lerobot-eval, with only the commands a user
# types. Per seed S (0..SEEDS-1), three training sets, as tools.replay value makes them for the MLP:
#   sources   gen_demos.py --task gym_pusht --episodes 12 --seed S
#   resolved  the 12 sources + augment_demos.py's 8 re-solved per source (LeRobot's lerobot-edit-dataset
#             drops the engine's two aug.* columns, then merges the two sets: its merge wants one schema)
#   fresh     gen_demos.py --task gym_pusht --episodes 108 --seed S (the 12 sources are its first 12)
# Each set: lerobot-train diffusion at STEPS steps (equal for all three), seed S; then lerobot-eval on
# gym-pusht with its own success (95% of the goal covered), EPISODES starts from reset seed
# env_seed(S, "eval", 0) = (3S + 2) * 1e6 on (ch37.seeds: never a demo start).
#
#   bash tools/lerobot_pusht.sh OUT [SEEDS=3] [STEPS=1000] [EPISODES=50] [LANES=2]
#   python -m tools.lerobot table OUT      the table, with Wilson intervals, from each eval_info.json
#
# The policy is shrunk for a CPU (say so where its numbers go): the Diffusion Policy paper's PushT
# horizons (2 observations, 16 actions, 8 executed), a 2-level U-Net down_dims [64, 128] (1.3 M
# parameters; LeRobot's default has 249 M), 10 denoising steps, batch 64, peak lr 1e-3 (LeRobot's
# cosine schedule, warmed up over the first tenth of the steps: its preset's 500 are for 200k steps). A finished step (its eval_info.json) is never redone:
# run the same command again to finish a stopped run.
set -euo pipefail
out=${1:?usage: bash tools/lerobot_pusht.sh OUT [SEEDS] [STEPS] [EPISODES] [LANES]}
seeds=${2:-3} steps=${3:-1000} episodes=${4:-50} lanes=${5:-2}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin="$root/.venv/bin"
export HF_HUB_OFFLINE=1 HF_DATASETS_OFFLINE=1  # a file missing from a set is an error, never a download
# one thread per lane: torch's OpenMP threads spin while they wait, and two lanes of two threads each on
# two cores ran 15x slower a step than one thread each (4.5 against 0.3 s)
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$out"
out=$(cd "$out" && pwd)

sets() {  # the three training sets of seed $1
    local s=$1 d="$out/seed$1"
    mkdir -p "$d"
    [ -f "$d/sources/meta/info.json" ] || "$bin/python" "$root/gen_demos.py" --task gym_pusht --episodes 12 --seed "$s" --out "$d/sources"
    [ -f "$d/fresh/meta/info.json" ] || "$bin/python" "$root/gen_demos.py" --task gym_pusht --episodes 108 --seed "$s" --out "$d/fresh"
    [ -f "$d/grown/meta/info.json" ] || "$bin/python" "$root/augment_demos.py" --src "$d/sources" --attempts_per_demo 8 --seed "$s" --out "$d/grown" --workers 1 --quiet
    if [ ! -f "$d/resolved/meta/info.json" ]; then
        rm -rf "$d/grown_plain" "$d/resolved.part"
        "$bin/lerobot-edit-dataset" --repo_id local/grown --root "$d/grown" --new_repo_id local/grown_plain \
            --new_root "$d/grown_plain" --operation.type remove_feature \
            --operation.feature_names '[aug.source_episode, aug.start]'
        "$bin/lerobot-edit-dataset" --new_repo_id local/resolved --new_root "$d/resolved.part" \
            --operation.type merge --operation.repo_ids '[local/sources, local/grown_plain]' \
            --operation.roots "[$d/sources, $d/grown_plain]"
        mv "$d/resolved.part" "$d/resolved"
    fi
}

run() {  # train and evaluate one set: $1 seed, $2 set
    local s=$1 set=$2 d="$out/seed$1"
    local train="$d/train_$set" eval="$d/eval_$set"
    [ -f "$eval/eval_info.json" ] && return 0
    if [ ! -f "$train/checkpoints/last/pretrained_model/config.json" ]; then
        rm -rf "$train"
        "$bin/lerobot-train" --dataset.repo_id="local/$set" --dataset.root="$d/$set" --dataset.video_backend=pyav \
            --policy.type=diffusion --policy.horizon=16 --policy.n_action_steps=8 --policy.n_obs_steps=2 \
            --policy.down_dims='[64,128]' --policy.num_inference_steps=10 --policy.optimizer_lr=1e-3 \
            --policy.scheduler_warmup_steps=$((steps / 10)) \
            --policy.device=cpu --policy.push_to_hub=false --batch_size=64 --num_workers=0 \
            --steps="$steps" --save_freq="$steps" --log_freq=100 --seed="$s" --output_dir="$train" \
            > "$d/train_$set.log" 2>&1 || { echo "seed $s $set: lerobot-train failed, see $d/train_$set.log"; return 1; }
    fi
    rm -rf "$eval"
    "$bin/lerobot-eval" --policy.path="$train/checkpoints/last/pretrained_model" --env.type=pusht \
        --env.obs_type=environment_state_agent_pos --eval.n_episodes="$episodes" --eval.batch_size=10 \
        --eval.use_async_envs=false --policy.device=cpu --seed=$(((3 * s + 2) * 1000000)) \
        --output_dir="$eval" > "$d/eval_$set.log" 2>&1 || { echo "seed $s $set: lerobot-eval failed, see $d/eval_$set.log"; return 1; }
    echo "seed $s $set: $(grep -o "'pc_success': [0-9.]*" "$d/eval_$set.log" | tail -n 1)"
}

for s in $(seq 0 $((seeds - 1))); do sets "$s" > "$out/sets_seed$s.log" 2>&1; done
export -f run
export out steps episodes bin
for s in $(seq 0 $((seeds - 1))); do for set in sources resolved fresh; do echo "$s $set"; done; done |
    xargs -P "$lanes" -L 1 bash -c 'run "$0" "$1"'
