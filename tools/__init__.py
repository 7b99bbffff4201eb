"""Instructor and engineer tooling for chapter 3.7, one job per module, each run from the repository root:

    python -m tools.regions [--check | --write]  the regions of scale_data.py, their hashes vs meta.yaml
    python -m tools.sweep --seeds 3 [FLAGS]      scale_data.py over seeds 0..2 -> sweep_seeds.json
    python -m tools.sweep --aug 0 4 8 [FLAGS]    seed 0 over aug_per_demo 0, 4, 8 -> sweep_aug.json
    python -m tools.meta                         meta.yaml: environment, reference_run, exercise_checks, ...
    python -m tools.replay --seeds 5 [--sigma M] replay vs re-solve on the chapter's recipe -> replay_*.json
    python -m tools.replay_yield --seeds 3       yield by task (PushT, ALOHA) and mode -> replay_yield.json
    python -m tools.value --task T --seeds 3     what grown demos buy BC (aloha, gym_pusht) -> T_value.json
    python -m tools.wallclock [--dry-run]        time the default run here, write its wallclock.csv row
    python -m tools.notebook [--check]           scale_data.ipynb from the regions
    python -m tools.bench [--smoke]              where the time of one run goes
    python -m tools.bench_envs                   speed and competence of the envs and their experts
    python -m tools.bench_engine                 the data engine: demos/s local vs Ray, peak memory
    python -m tools.bench_writer                 the one-pass LeRobot v3 writer vs LeRobot's per-frame path
    python -m tools.lerobot_eval --policy P      a LeRobot checkpoint on the lesson's held-out PushT starts
    python -m tools.lerobot_lab [FLAGS]          LeRobot's own policies trained on the lab's data points
    python -m tools.lock                         .venv against requirements.lock (bash tools/lock.sh makes it)
    (tools.common holds what they share: the parser, regions, provenance)
    (tools.install: the notebook's first cell installs the course's packages with it, standard library only)

Exit codes: 0 ok, 1 a check failed (drift, a stale notebook), 2 bad input (one `error:` line).
"""
