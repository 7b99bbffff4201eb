"""Instructor and engineer tooling for chapter 3.7, one entry point per job, run from the repository root
(`python -m tools.X --help`; a tool with subcommands lists them, `SUBCOMMAND --help` each one's flags):

    python -m tools.regions [--check | --write]  the regions of scale_data.py, their hashes vs meta.yaml
    python -m tools.sweep --seeds 3 | --aug 0 4 8  scale_data.py over seeds or aug_per_demo -> sweep_*.json
    python -m tools.meta                         meta.yaml: environment, reference_run, exercise_checks, ...
    python -m tools.wallclock [--dry-run]        time the default run here, write its wallclock.csv row
    python -m tools.notebook [--check]           scale_data.ipynb from the regions
    python -m tools.lock                         .venv against requirements.lock (bash tools/lock.sh makes it)
    python -m tools.replay compare|yield|value   replay vs re-solve: what each buys BC, yield by task and mode
    python -m tools.embodiment --seeds 3         objective 2: per-robot and shared policies on the padded pile
    python -m tools.bench lesson|engine|envs|gym_pusht|kernels|writer   how fast, and where the time goes
    python -m tools.lerobot eval|lab             LeRobot's own policies: a checkpoint on our starts, the lab
    (tools.common holds what they share: the parser and subcommands, regions, provenance, result files)
    (tools.install: the notebook's first cell installs the course's packages with it, standard library only)

Exit codes: 0 ok, 1 a check failed (drift, a stale notebook), 2 bad input (one `error:` line).
"""
