"""The data engine: grow a demo set of any task that implements datagen.task.Task, MimicGen-style.

task       Task (what a task describes, in MimicGen's division: an abstract base with eight required
           members: its name, EnvSpec, starts and their perturbation, object pose, ReplaySpec (arms,
           reach, subtasks, bridges, hold, the action kind); an optional ExpertSpec), EnvSpec, Subtask,
           Outcome (what one attempt came to), Perturbation, Source
poses      SE(3): transform_segment, interpolate (slerp), planar_pose; planar tasks are its SE(2) case
check      python -m datagen.check TASK: a task's contract, starts, expert, ranges and replay, in seconds
demos      expert demo sets of a task: rollout (the demo generators' loop), write_dataset (a
           stamped set), generate, ensure_demos (the chapter's private demo cache),
           check_given (a set you name, checked and never modified), video_problem (whether --video can)
tasks/     one module per task with its expert (datagen/tasks/__init__.py lists them): our PushT (PUSHT)
           and ALOHA handoff (ALOHA), LeRobot's gym-pusht, Gymnasium's Pusher-v5, gym-aloha's
           transfer-cube and insertion
engine     one attempt in either mode, keep_first, grow, run_attempts, save: task-agnostic
replay     the one replay for every task (MimicGen's generation loop): cut a source at its subtask
           signals, re-express each segment in the new object frames, bridge, execute, keep on success
lockstep   the one attempt runner (run_lanes): every attempt of either mode, one lane or many stepped
           together, the frames, starts and provenance recorded there; Simulators
run        a run on disk (augment_demos.py): run() says the order of its steps, each in its own module:
  source_check   which task a source set is (task_of), whether the engine can grow it (read_source)
  plan           the settings as stamped, the attempts cut into shards (plan), the memory that needs
  resume         --out checked and held under its lock, the run's stamp, an earlier run's shards judged
  shards         a shard made by a worker (local processes or Ray: ch37.parallel.map_jobs), saved, merged
                 (lerobot_v3.merge_sets)
  report         the generation report, summed from the shard stamps

A task registers itself when its module is imported (datagen.task.register); known_tasks() imports every
module of datagen/tasks and returns them by name, so a new task is one module there, listed nowhere else.
A module that fails to import (half written, or a copy still naming its original's task) is one warning
line naming it, its tasks unavailable and the others known.
"""

from datagen.demos import (
    check_given,
    check_given_sets,
    check_gl,
    ensure_demos,
    generate,
    rollout,
    video_problem,
    write_dataset,
)
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
from datagen.task import (
    EnvSpec,
    Outcome,
    Perturbation,
    Source,
    Subtask,
    Task,
    known_tasks,
    register,
)
from datagen.tasks.aloha import ALOHA
from datagen.tasks.pusht import PUSHT

__all__ = [
    "ALOHA",
    "ATTEMPTS_PER_KEPT",
    "KEPT_KEYS",
    "PUSHT",
    "EnvSpec",
    "Outcome",
    "Perturbation",
    "Subtask",
    "Source",
    "Task",
    "attempt",
    "attempt_rng",
    "check_gl",
    "empty_kept",
    "check_given",
    "check_given_sets",
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
    "video_problem",
    "write_dataset",
]
