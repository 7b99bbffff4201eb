"""python -m datagen.check TASK: what a newcomer needs while writing a task, in seconds, before a long run.

    the contract     the required members (datagen.task.contract_problem) and the episode limit: the
                     task's spec.max_steps against its env's own (a Gymnasium env's TimeLimit)
    the start        place(start_of(obs)) puts a fresh env where obs was, on reset and mid-episode
    perturb          the starts it draws have start_names' numbers, all finite, and place() takes them
    the expert       it solves the starts of --episodes resets (seeds --seed ..)
    the ranges       every state and action of those rollouts lies in spec.state_ranges / action_ranges
    the replay       every solved rollout, replayed at zero perturbation (MimicGen's move with nothing
                     moved), succeeds again; a failure names the subtask and the waypoint

One line per check, ok or what is wrong; exit 0 when all pass, 1 when one fails, 2 for an unknown task or a
flag out of its bounds (one `error:` line).
A task without an expert checks what it can (its start round-trip on resets).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ch37.errors import DataError, main
from ch37.seeds import MAX_SEED
from datagen.demos import rollout
from datagen.lockstep import replay_from
from datagen.source_check import state_range_problem
from datagen.task import Perturbation, Source, Task, contract_problem, known_tasks, owed

__all__ = ["checks"]


def env_limit(env) -> int | None:
    """The episode limit an env declares itself, None where it declares none: a Gymnasium env's spec, a
    TimeLimit wrapper anywhere in its chain, or a step-limit attribute of the env itself (an env that stops
    at its own limit outside Gymnasium's spec: max_episode_steps, max_steps, MAX_STEPS)."""
    inner = getattr(env, "env", env)  # GymnasiumEnv's Gymnasium env, or our own env
    limit = getattr(getattr(inner, "spec", None), "max_episode_steps", None)
    layer = inner
    while limit is None and layer is not None:
        limit = getattr(layer, "_max_episode_steps", None)  # a TimeLimit wrapper's
        layer = getattr(layer, "env", None)
    base = getattr(inner, "unwrapped", inner)
    for name in ("max_episode_steps", "max_steps", "MAX_STEPS"):
        limit = limit if limit is not None else getattr(base, name, None)
    return int(limit) if isinstance(limit, int | np.integer) and limit > 0 else None


def round_trip(task: Task, obs) -> tuple[float, str]:
    """How far (largest difference, the observation's name for it) a fresh env placed at start_of(obs) is
    from obs."""
    again = np.asarray(task.place(task.make_env(), task.start_of(obs)), np.float64)
    gap = np.abs(again - np.asarray(obs, np.float64))
    i = int(np.argmax(gap))
    return float(gap[i]), task.spec.observation_names[i]


def perturb_problem(task: Task, obs: list, seed: int) -> tuple[str | None, str]:
    """(problem or None, what was found) of perturb on the starts `obs` at the engine's default
    perturbation (0.08 m, 0.5 rad): each start it draws has start_names' numbers, all finite, and place()
    puts a fresh env there (an observation of obs_dim finite numbers)."""
    how, env, drawn = Perturbation(seed, 0.08, 0.5), task.make_env(), 0
    try:
        for i, o in enumerate(obs):
            start = task.perturb(o, np.random.default_rng([seed, i]), how)
            if start is None:  # no valid draw: a reason an attempt may give ("no_valid_start")
                continue
            owed(task, "perturb", start, (len(task.start_names),))
            owed(task, "place", task.place(env, start), (task.spec.obs_dim,))
            drawn += 1
    except DataError as e:
        return str(e), ""
    return None, f"{drawn} of {len(obs)} starts perturbed and placed"


def checks(task: Task, episodes: int, seed: int, tol: float):
    """(name, problem or None, what was found) for each check, in order."""
    yield "contract", contract_problem(task), "the required members are there"
    env = task.make_env()
    limit = env_limit(env)
    steps = task.spec.max_steps
    bad = limit is not None and limit != steps
    fine = f"max_steps {steps}" + (", as the env's own" if limit else " (the env declares none)")
    yield "episode limit", bad and f"max_steps {steps} but the env stops at {limit}", fine
    obs = [env.reset(seed=seed + i) for i in range(episodes)]  # a source's first frame is such a start
    worst = max((round_trip(task, o) for o in obs), key=lambda g: g[0])
    far = worst[0] > tol and f"place(start_of(obs)) is {worst[0]:.3g} off in {worst[1]} (over --tol {tol:g})"
    yield "start round-trip", far, f"within {worst[0]:.3g} on {len(obs)} starts"
    yield "perturb", *perturb_problem(task, obs, seed)
    eps = []
    try:
        for i, first in enumerate(obs if task.expert is not None else ()):
            env.reset(seed=seed + i)
            eps.append(rollout(task, env, task.expert.cls(noise=0.0), first))
    except DataError as e:  # an expert's episode longer than max_steps (an env that declares no limit)
        yield "expert", str(e), ""
        return
    if not eps:
        return
    solved = [ep for ep in eps if ep["success"]]
    short = f"the expert solved {len(solved)} of {len(eps)} starts" if len(solved) < len(eps) else None
    yield "expert", short, f"solved {len(eps)} of {len(eps)} starts"
    states = np.concatenate([ep["observation.state"] for ep in eps])
    actions = np.concatenate([ep["action"] for ep in eps])
    yield "ranges", state_range_problem(task, Path(f"the {task.name} rollouts"), states, actions), "inside"
    if task.replay is None:
        return
    failed = []
    for i, ep in enumerate(solved):
        source = Source(i, ep["observation.state"], ep["action"])
        got = replay_from(task, task.make_env(), task.start_of(source.states[0]), source)
        if not got.kept:
            failed.append(f"rollout {i}: {got.reason} ({got.detail})")
    lost = f"{len(failed)} of {len(solved)} not reproduced; the first: {failed[0]}" if failed else None
    yield "replay", lost, f"{len(solved)} of {len(solved)} rollouts reproduced at zero perturbation"


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line and exit 2, as every command's (ch37.errors.main)
        raise DataError(f"{message} (see --help)")


def _main(argv) -> int:
    tasks = known_tasks()
    p = _Parser(prog="python -m datagen.check", description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("task", help="the task to check: " + ", ".join(tasks))
    p.add_argument("--episodes", type=int, default=5, help="resets (and expert rollouts) to check")
    p.add_argument("--seed", type=int, default=0, help=f"the first reset seed, 0 to {MAX_SEED}")
    p.add_argument("--tol", type=float, default=1e-3, help="round-trip slack, in the task's own units")
    a = p.parse_args(argv)
    if a.task not in tasks:
        raise DataError(f"unknown task {a.task!r}: pick one of {', '.join(tasks)}")
    # the bounds every command's flags have (ch37.config.check's words; the engine imports no flag module):
    # a negative seed is no env's, and a --tol of nan passes every round trip and a negative one fails all
    if a.episodes < 1:
        raise DataError(f"--episodes must be a positive integer, got {a.episodes}")
    if a.seed < 0:
        raise DataError(f"--seed must be >= 0, got {a.seed}")
    if a.seed > MAX_SEED:
        raise DataError(f"--seed must be at most {MAX_SEED}, got {a.seed}")
    if not math.isfinite(a.tol) or math.copysign(1.0, a.tol) < 0:
        raise DataError(f"--tol must be a finite non-negative number, got {a.tol}")
    task = tasks[a.task]
    print(f"checking {task.name} ({task.title}), {a.episodes} starts from seed {a.seed}", flush=True)
    ok = True
    for name, problem, fine in checks(task, a.episodes, a.seed, a.tol):
        print(f"  {name:<17} {'FAIL: ' + problem if problem else 'ok: ' + fine}", flush=True)
        ok &= not problem
    return 0 if ok else 1


if __name__ == "__main__":
    main(_main)
