"""The data engine: grow a demo set of any task that implements datagen.task.Task, MimicGen-style.

task       Task (what a task provides: env, start names, perturbation, place, expert, segments,
           replay, success), Outcome (what one attempt came to), Perturbation, Source, Segment,
           rollout, write_dataset (a stamped set)
demos      expert demo sets: Embodiment, generate, ensure_demos (the chapter's private demo cache),
           check_given (a set you name, checked and never modified)
pusht      PUSHT: PushT as a task (the only module here that imports pusht_env and its expert)
aloha      ALOHA: the ALOHA cube handoff as a task (perturbation in the spawn regions, re-solve,
           replay by grasp-signal subtasks; the only module here that imports aloha_env)
engine     one attempt, keep_first, grow, run_attempts, save: task-agnostic
shards     a run on disk: fixed shards on local processes or Ray (ch37.parallel.map_jobs), resume,
           the generation report, the merge (lerobot_v3.merge_sets)

A task registers itself when its module is imported (datagen.task.register); known_tasks() imports every
module of the package and returns them by name, so a new task is one module here, listed nowhere else.
"""

from datagen.aloha import ALOHA
from datagen.demos import Embodiment, check_given, check_gl, ensure_demos, generate
from datagen.engine import (
    ATTEMPTS_PER_KEPT,
    KEPT_KEYS,
    attempt,
    attempt_rng,
    empty_kept,
    first_per_source,
    grow,
    keep_first,
    run_attempts,
    save,
    sources,
)
from datagen.pusht import PUSHT
from datagen.task import (
    Outcome,
    Perturbation,
    Segment,
    Source,
    Task,
    known_tasks,
    register,
    rollout,
    write_dataset,
)

__all__ = [
    "ALOHA",
    "ATTEMPTS_PER_KEPT",
    "Embodiment",
    "KEPT_KEYS",
    "PUSHT",
    "Outcome",
    "Perturbation",
    "Segment",
    "Source",
    "Task",
    "attempt",
    "attempt_rng",
    "check_gl",
    "empty_kept",
    "check_given",
    "ensure_demos",
    "first_per_source",
    "generate",
    "grow",
    "keep_first",
    "known_tasks",
    "register",
    "rollout",
    "run_attempts",
    "save",
    "sources",
    "write_dataset",
]
