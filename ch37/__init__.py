"""The plumbing of chapter 3.7: what scale_data.py imports but does not teach, one concern per module.

errors        DataError, guard() / run_main() / main(): one line and an exit code (2, 130 on Ctrl-C)
files         claim(): an output folder checked up front, locked, owned file by file; write_atomic,
              dump_json: whole files or none, no leftovers
config        the chapter's defaults and smoke settings, the one flag parser and checker
cli           scale_data.py's flag limits, claim_out, device choice, the tier banner
lerobot_io    LeRobot v3 read/write: features, write_dataset, load_arrays, schema checks
seeds         env_seed: demos, augmentation and evaluation never share a start
stamps        ownership stamps: only files this project wrote are ever deleted or rewritten; read_json
demos         demo sets: rollout, generation, the private demo cache
parallel      parallel_map over forked workers, LockstepEnvs for evaluation physics; workers die with the run
engine        one augmentation attempt: perturb a source start, re-solve or replay it, keep it on success
pusht_task    PushT replay by subtasks (approach, push) and nearest source selection
aloha_task    the ALOHA handoff for the engine: perturbation, re-solve, replay by grasp-signal subtasks
shards        a data-engine run on disk: fixed shards (LeRobot sets with stamps), merge, stats over frames
executors     where the shards run: local processes or Ray
ensemble      several MLPs as one module: the arms of a training budget side by side
result_cache  reuse a finished run whose flags and code match; entries verified by checksum
viz           the PNG figures and the Rerun recordings (the chapter's and the Scale Lab's)
poster        the self-contained HTML posters (scale_data.html, scale_lab.html): inline SVG, no script

A command of its own (the data engine, a tool) gets the same guarantees from errors.run_main,
files.claim (or files.check_out_path), stamps.replace_own_dir and parallel.worker_setup.
"""

import os
from pathlib import Path

# Offline by construction: everything the chapter reads it made itself, so no LeRobot or Hugging Face
# call may reach for the Hub (a missing local file must be an error here, never a download).
os.environ["HF_HUB_OFFLINE"] = os.environ["HF_DATASETS_OFFLINE"] = "1"

ROOT = Path(__file__).resolve().parent.parent  # the repository root: scale_data.py, the envs, meta.yaml
CHAPTER_ID = "ch3.7-scale-data"

# Every file whose bytes can change a result, in one list (paths from ROOT). The first group
# shapes the frames of a demo set: a set's stamp carries their digest, so a cached set never
# outlives its code. The whole list keys the result cache.
DATA_CODE = tuple(
    "pusht_env.py pusht.xml aloha_env.py aloha.xml scripted_expert.py ch37/demos.py ch37/lerobot_io.py "
    "ch37/seeds.py".split()
)
CODE_FILES = DATA_CODE + tuple(
    "scale_data.py bc_recipe.py gen_demos_pusht.py gen_demos_aloha.py ch37/cli.py ch37/files.py "
    "ch37/parallel.py ch37/stamps.py ch37/viz.py ch37/poster.py ch37/ensemble.py ch37/engine.py "
    "ch37/shards.py ch37/frame_stats.py ch37/executors.py ch37/config.py".split()
)
