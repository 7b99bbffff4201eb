#!/usr/bin/env bash
# What the engine's demos buy a LeRobot policy, trained by lerobot-train, with only the commands a user
# types (issue 49's row in docs/gym_pusht.md, issue 50's in docs/engine.md). Per seed S (0..SEEDS-1),
# three training sets, as tools.replay value makes them for the chapter's MLP:
#   sources   gen_demos.py --task TASK --episodes SRC --seed S
#   GROWN     the SRC sources + augment_demos.py's PER attempts per source, kept on success (LeRobot's
#             lerobot-edit-dataset drops the engine's two aug.* columns, then merges the two sets: its
#             merge wants one schema)
#   fresh     gen_demos.py --task TASK --episodes FRESH --seed S (the sources are its first SRC)
# Each set: lerobot-train at STEPS steps (equal for all three), seed S, then scored on EPISODES held-out
# starts, env_seed(S, "eval", j) = (3S + 2) * 1e6 + j (ch37.seeds: never a demo start):
#   gym_pusht            SRC 12, re-solved (GROWN resolved, PER 8), FRESH 108; diffusion; scored by
#                        lerobot-eval on LeRobot's gym-pusht (its own success: 95% of the goal covered)
#   aloha_transfer_cube  SRC 10, replayed by subtasks (GROWN replayed, PER 20), FRESH 210; ACT; scored by
#                        python -m tools.lerobot eval --task aloha_transfer_cube in our env on gym-aloha's
#                        model (its success: the top reward stage; gym-aloha's env cannot run on mujoco 4)
#
#   bash tools/lerobot_row.sh TASK OUT [SEEDS=3] [STEPS=1000] [EPISODES=50] [LANES=2]
#   DEVICE=cuda PYTHON=python3 WORKERS=8 bash tools/lerobot_row.sh ...   on a GPU machine (tools/gpu_check.sh's
#                        step 5): train and evaluate on DEVICE (default cpu), run every Python step with
#                        PYTHON (default the checkout's .venv), augment with WORKERS processes (default 1;
#                        the same bytes for any count)
#   python -m tools.lerobot table OUT      the table, with Wilson intervals, from each run's evaluation
#
# Both policies are shrunk for a CPU (say so where their numbers go). Diffusion: the Diffusion Policy
# paper's PushT horizons (2 observations, 16 actions, 8 executed), a 2-level U-Net down_dims [64, 128]
# (1.3 M parameters; LeRobot's default has 249 M), 10 denoising steps, batch 64, peak lr 1e-3 (LeRobot's
# cosine schedule, warmed up over the first tenth of the steps: its preset's 500 are for 200k steps).
# ACT: no images (observation.state + observation.environment_state), dim_model 256, 4 heads, feed-forward
# 1024, 2 encoder and 2 VAE-encoder layers (4.3 M parameters; LeRobot's default has 40 M without a
# backbone), chunks of 50 actions (1 s at 50 fps), all executed, batch 8, lr 1e-4 (LeRobot's 1e-5 is for
# 100k steps). A finished step (its evaluation) is never redone: run the same command again to finish a
# stopped run. A training saves a checkpoint every CHECKPOINT steps and a stopped one resumes from its
# last (lerobot-train --resume: the same data order, optimizer and RNG state), so a row of hours runs in
# parts. A resumed training is not the same bits as an uninterrupted one: torch's DataLoader draws its
# seed from torch's RNG after LeRobot restores it, which moves ACT's latent noise by one draw (20 steps,
# resumed at 10: other weights; the same weights on every resume at 10). Its log says where it resumed
# ("Resuming data order"); the row's numbers are draws of the same recipe.
set -euo pipefail
usage="usage: bash tools/lerobot_row.sh gym_pusht|aloha_transfer_cube OUT [SEEDS] [STEPS] [EPISODES] [LANES]"
task=${1:-} out=${2:-}
case "$task" in
gym_pusht) src=12 fresh=108 per=8 mode=resolve grown=resolved ;;
aloha_transfer_cube) src=10 fresh=210 per=20 mode=replay grown=replayed ;;
*) echo "error: TASK must be gym_pusht or aloha_transfer_cube, not '${task}'; $usage" >&2 && exit 2 ;;
esac
[ -n "$out" ] || { echo "error: no OUT folder; $usage" >&2 && exit 2; }
[ ! -e "$out" ] || [ -d "$out" ] || { echo "error: OUT $out is not a folder; $usage" >&2 && exit 2; }
[ $# -le 6 ] || { echo "error: too many arguments (from '${7}' on); $usage" >&2 && exit 2; }
seeds=${3:-3} steps=${4:-1000} episodes=${5:-50} lanes=${6:-2}
checkpoint=1000  # steps between a training's checkpoints (ACT: ~5 min of one core), where a stopped one resumes
# every number checked before any work: a bad one once ran no seed (SEEDS=0) or generated sets first and
# failed in lerobot-train (STEPS=abc); nine digits keep bash's arithmetic far from overflow
for arg in "SEEDS=$seeds" "STEPS=$steps" "EPISODES=$episodes" "LANES=$lanes"; do
    [[ ${arg#*=} =~ ^[1-9][0-9]{0,8}$ ]] ||
        { echo "error: ${arg%%=*} must be a whole number from 1 up, not '${arg#*=}'; $usage" >&2 && exit 2; }
done
# each seed's evaluation starts are one block of ch37.seeds (tools.lerobot eval's own --eval_episodes bound)
[ "$episodes" -le 1000000 ] || { echo "error: EPISODES must be at most 1000000, not $episodes; $usage" >&2 && exit 2; }
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
py=${PYTHON:-$root/.venv/bin/python}  # LeRobot's commands run as modules of this Python (no console scripts needed)
device=${DEVICE:-cpu} workers=${WORKERS:-1}
case "$device" in cpu | cuda) ;; *) echo "error: DEVICE must be cpu or cuda, not '$device'; $usage" >&2 && exit 2 ;; esac
[[ $workers =~ ^[1-9][0-9]{0,2}$ ]] || { echo "error: WORKERS must be a whole number from 1 up, not '$workers'; $usage" >&2 && exit 2; }
export HF_HUB_OFFLINE=1 HF_DATASETS_OFFLINE=1  # a file missing from a set is an error, never a download
# one thread per lane: torch's OpenMP threads spin while they wait, and two lanes of two threads each on
# two cores ran 15x slower a step than one thread each (4.5 against 0.3 s)
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
mkdir -p "$out"
out=$(cd "$out" && pwd)

sets() {  # the three training sets of seed $1
    local s=$1 d="$out/seed$1"
    mkdir -p "$d"
    # the fresh set (the longest) is rolled out beside the sources and their growth: each is a pure function of
    # its flags, so the order changes no byte
    [ -f "$d/fresh/meta/info.json" ] || "$py" "$root/gen_demos.py" --task "$task" --episodes "$fresh" --seed "$s" --out "$d/fresh" --quiet &
    local fresh_pid=$!
    [ -f "$d/sources/meta/info.json" ] || "$py" "$root/gen_demos.py" --task "$task" --episodes "$src" --seed "$s" --out "$d/sources" --quiet
    [ -f "$d/grown/meta/info.json" ] || "$py" "$root/augment_demos.py" --src "$d/sources" --aug_mode "$mode" --attempts_per_demo "$per" --seed "$s" --out "$d/grown" --workers "$workers" --quiet
    if [ ! -f "$d/$grown/meta/info.json" ]; then
        rm -rf "$d/grown_plain" "$d/$grown.part"
        "$py" -m lerobot.scripts.lerobot_edit_dataset --repo_id local/grown --root "$d/grown" --new_repo_id local/grown_plain \
            --new_root "$d/grown_plain" --operation.type remove_feature \
            --operation.feature_names '[aug.source_episode, aug.start]'
        "$py" -m lerobot.scripts.lerobot_edit_dataset --new_repo_id "local/$grown" --new_root "$d/$grown.part" \
            --operation.type merge --operation.repo_ids '[local/sources, local/grown_plain]' \
            --operation.roots "[$d/sources, $d/grown_plain]"
        mv "$d/$grown.part" "$d/$grown"
    fi
    wait "$fresh_pid"
}

run() {  # train and evaluate one set: $1 seed, $2 set
    local s=$1 set=$2 d="$out/seed$1"
    local train="$d/train_$set" eval="$d/eval_$set" model final result=eval_info.json  # lerobot-eval's own file
    local -a policy
    # LeRobot names a checkpoint by its step, zero-padded to at least 6 digits; the last step's is the model
    final=$(printf "%0$((${#steps} > 6 ? ${#steps} : 6))d" "$steps")
    model="$train/checkpoints/$final/pretrained_model"
    [ "$task" = gym_pusht ] || result=lerobot_eval.json  # tools.lerobot eval's
    [ -f "$eval/$result" ] && return 0
    if [ -f "$train/checkpoints/last/pretrained_model/train_config.json" ] && [ ! -f "$model/config.json" ]; then
        "$py" -m lerobot.scripts.lerobot_train --config_path="$train/checkpoints/last/pretrained_model/train_config.json" \
            --resume=true >> "$d/train_$set.log" 2>&1 ||
            { echo "seed $s $set: lerobot-train failed to resume, see $d/train_$set.log"; return 1; }
    elif [ ! -f "$model/config.json" ]; then
        rm -rf "$train"
        if [ "$task" = gym_pusht ]; then
            policy=(--policy.type=diffusion --policy.horizon=16 --policy.n_action_steps=8 --policy.n_obs_steps=2
                --policy.down_dims='[64,128]' --policy.num_inference_steps=10 --policy.optimizer_lr=1e-3
                --policy.scheduler_warmup_steps=$((steps / 10)) --batch_size=64)
        else
            policy=(--policy.type=act --policy.dim_model=256 --policy.n_heads=4 --policy.dim_feedforward=1024
                --policy.n_encoder_layers=2 --policy.n_vae_encoder_layers=2 --policy.chunk_size=50
                --policy.n_action_steps=50 --policy.optimizer_lr=1e-4 --batch_size=8)
        fi
        "$py" -m lerobot.scripts.lerobot_train --dataset.repo_id="local/$set" --dataset.root="$d/$set" --dataset.video_backend=pyav \
            "${policy[@]}" --policy.device="$device" --policy.push_to_hub=false --num_workers=0 \
            --steps="$steps" --save_freq=$((steps < checkpoint ? steps : checkpoint)) --log_freq=100 --seed="$s" \
            --output_dir="$train" > "$d/train_$set.log" 2>&1 ||
            { echo "seed $s $set: lerobot-train failed, see $d/train_$set.log"; return 1; }
    fi
    # the model is the last checkpoint; the others (~50 MB each for ACT) only served a resume
    find "$train/checkpoints" -mindepth 1 -maxdepth 1 ! -name "$final" ! -name last -exec rm -rf {} +
    rm -rf "$eval" "$eval.part"
    mkdir -p "$eval.part"
    if [ "$task" = gym_pusht ]; then
        "$py" -m lerobot.scripts.lerobot_eval --policy.path="$model" --env.type=pusht \
            --env.obs_type=environment_state_agent_pos --eval.n_episodes="$episodes" --eval.batch_size=10 \
            --eval.use_async_envs=false --policy.device="$device" --seed=$(((3 * s + 2) * 1000000)) \
            --output_dir="$eval.part" > "$d/eval_$set.log" 2>&1
    else
        (cd "$root" && "$py" -m tools.lerobot eval --task "$task" --policy "$model" \
            --eval_episodes "$episodes" --seed "$s" --device "$device" --out "$eval.part/$result") > "$d/eval_$set.log" 2>&1
    fi || { echo "seed $s $set: the evaluation failed, see $d/eval_$set.log"; return 1; }
    mv "$eval.part" "$eval"
    echo "seed $s $set: $(grep -oE "'pc_success': [0-9.]*|success [0-9.]* \[[^]]*\]" "$d/eval_$set.log" | tail -n 1)"
}

for s in $(seq 0 $((seeds - 1))); do sets "$s" > "$out/sets_seed$s.log" 2>&1; done
export -f run
export out steps episodes py device task root checkpoint
for s in $(seq 0 $((seeds - 1))); do for set in sources "$grown" fresh; do echo "$s $set"; done; done |
    xargs -P "$lanes" -L 1 bash -c 'run "$0" "$1"'
