"""The plumbing and presentation of chapter 3.7: what scale_data.py imports but does not teach, one
concern per module. The LeRobot v3 format is the package lerobot_v3; the data engine and the demo sets
are datagen. ch37 is the floor: none of its modules imports either.

plumbing (imported by the engine, the format's error type included, and the tools)
  errors        DataError, guard() / run_main() / main(): one line and an exit code (2, 130 on Ctrl-C)
  ownership     claim(): an output folder checked up front, locked, owned file by file (the Claim passed
                to every write); stamps; write_atomic, publish_dir, dump_json, read_json: whole or none
  process       process hygiene: workers die with the run, stop signals around a fork, core and memory limits
  parallel      map_jobs: the one map over jobs (forked processes or Ray); LockstepEnvs for evaluation;
                step_envs: a batch of envs stepped (theirs and the engine's lanes)
  seeds         env_seed: demos, augmentation and evaluation never share a start
  ensemble      several MLPs as one module: the arms of a training budget side by side
presentation and flags (the lesson's and the tools'; never imported by datagen or lerobot_v3)
  config        the chapter's defaults and smoke settings, the one flag parser and checker
  cli           scale_data.py's flag limits, claim_out, device choice, the tier banner, the five-seed
                reference a run is placed beside
  result_cache  reuse a finished run whose flags and code match; entries verified by checksum
  viz           the PNG figures and the Rerun recordings (the chapter's and the Scale Lab's)
  poster        the self-contained HTML posters (scale_data.html, scale_lab.html): inline SVG, no script

A command of its own (the data engine, a tool) gets the same guarantees from errors.run_main,
ownership.claim (or ownership.check_out_path), ownership.replace_own_dir and process.worker_setup.
"""

import hashlib
import os
import warnings
from pathlib import Path

# Offline by construction: everything the chapter reads it made itself, so no LeRobot or Hugging Face
# call may reach for the Hub (a missing local file must be an error here, never a download).
os.environ["HF_HUB_OFFLINE"] = os.environ["HF_DATASETS_OFFLINE"] = "1"
# In Jupyter without ipywidgets, tqdm.auto (which the datasets library imports) warns once and uses
# the text progress bar instead of a widget: the notebook loses nothing, so the warning is noise.
warnings.filterwarnings("ignore", message="IProgress not found")

ROOT = Path(__file__).resolve().parent.parent  # the repository root: scale_data.py, the envs, meta.yaml
CHAPTER_ID = "ch3.7-scale-data"
__all__ = [  # the face: the modules above, and the repository's root and code lists
    "cli",
    "config",
    "ensemble",
    "errors",
    "ownership",
    "parallel",
    "poster",
    "process",
    "result_cache",
    "seeds",
    "viz",
    "CHAPTER_ID",
    "DATA_CODE",
    "ROOT",
    "code_digest",
]

# The files that shape the frames of a demo set (paths from ROOT): a set's stamp carries their digest
# (datagen.demos.generator_version), so a cached set never outlives its code; the engine adds its own
# (datagen.shards.engine_version). The result cache needs no list: it records what a run imported.
DATA_CODE = tuple(
    "pusht_env.py pusht.xml aloha_env.py aloha.xml scripted_expert.py datagen/demos.py datagen/task.py "
    "lerobot_v3/dataset.py lerobot_v3/chunks.py ch37/seeds.py".split()
)


def code_digest(names=DATA_CODE) -> str:
    """First 12 hex of sha256 over the bytes of `names` (paths from the repository root)."""
    h = hashlib.sha256()
    for name in names:
        h.update((ROOT / name).read_bytes())
    return h.hexdigest()[:12]
