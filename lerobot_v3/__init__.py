"""The LeRobot v3 format, as this project writes, reads, checks and merges it. Imports nothing of the
project but its error type (ch37.errors.DataError): no ownership, no flags, no task.

dataset      features, write_set (a set in one pass, or LeRobot's own path for video), load_arrays
             and open_dataset (read back through LeRobotDataset), the schema/fps/frame checks
hub          hub_offline: no LeRobot or Hugging Face call reaches the Hub (set when first needed, not at
             import); OFFLINE_ENV: what a LeRobot program started as a subprocess is given
chunks       ChunkRoller: the one rule that starts a new data or episodes file at the size limit
frame_stats  FrameStats: exact stats.json over all frames of a merge (numpy's quantiles bit for bit)
merge        merge_sets: several sets of one task into one, in one pass

Low-level writers (_write_direct and its helpers) are intentionally not re-exported.
"""

from lerobot_v3.dataset import (
    ENV_STATE_KEY,
    IMAGE_KEY,
    IMAGE_SIZE,
    check_hf_cache,
    columns,
    features,
    fps_problem,
    frames_problem,
    info_problem,
    load_arrays,
    observation,
    open_dataset,
    schema_problem,
    write_set,
)
from lerobot_v3.hub import OFFLINE_ENV, hub_offline
from lerobot_v3.merge import merge_sets

__all__ = [
    "ENV_STATE_KEY",
    "IMAGE_KEY",
    "IMAGE_SIZE",
    "OFFLINE_ENV",
    "check_hf_cache",
    "columns",
    "features",
    "fps_problem",
    "frames_problem",
    "hub_offline",
    "info_problem",
    "load_arrays",
    "merge_sets",
    "observation",
    "open_dataset",
    "schema_problem",
    "write_set",
]
