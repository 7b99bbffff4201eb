"""Parallel execution, the project's one map over jobs and one pool: map_jobs for independent jobs
(forked local processes or Ray), LockstepEnvs for evaluation physics. Results never depend on the
worker count: every job carries its own seed and every env is its own simulator.

Workers die with the run (ch37.process: worker_setup, forking), an env worker also stops at the end
of its pipe, so an interrupted run prints one line, not a traceback from every process.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import sys

from ch37 import ROOT
from ch37.errors import DataError
from ch37.process import environment, forking, worker_setup


def progress(iterable, *, total: int, desc: str, quiet: bool = False):
    """A tqdm bar on a terminal; silent when quiet or when stderr is not a TTY."""
    from tqdm import tqdm

    quiet = quiet or not sys.stderr.isatty()
    return tqdm(iterable, total=total, desc=desc, unit="ep", leave=False, disable=quiet)


def can_fork() -> bool:
    """Whether this process may fork workers: the fork start method exists (Linux; not Windows, and not
    macOS's default) and this process is not itself a worker (multiprocessing's daemon workers may have
    no children)."""
    import multiprocessing as mp

    return "fork" in mp.get_all_start_methods() and not mp.current_process().daemon


def _imap(fn, jobs: list, *, workers: int, ordered=True, chunksize: int | None = None, setup=None):
    """fn(job) for each job, yielded as they finish (in job order when `ordered`), on `workers` forked
    processes; in this process without fork or with one worker. The results never depend on `workers`:
    every job carries its own seed. `fn` and `jobs` are each worker's arguments, inherited through fork,
    never pickled, so a function defined in a script or a notebook works; a worker takes the next
    `chunksize` job indices from a shared counter and sends back (index, result, exception); `setup()`, if
    given, runs first in each forked worker (never in this process)."""
    import multiprocessing as mp
    from multiprocessing.connection import wait

    jobs = list(jobs)
    if workers <= 1 or len(jobs) <= 1 or not can_fork():
        yield from map(fn, jobs)
        return
    ctx = mp.get_context("fork")
    size = chunksize or max(1, len(jobs) // (4 * workers))
    next_index = ctx.Value("q", 0)
    pipes = [ctx.Pipe(duplex=False) for _ in range(min(workers, len(jobs)))]  # (parent's end, worker's)
    procs = [
        ctx.Process(
            target=_job_worker, args=(os.getpid(), fn, jobs, size, next_index, end, setup), daemon=True
        )
        for _, end in pipes
    ]
    try:
        with forking():
            for proc in procs:
                proc.start()
        for _, end in pipes:
            end.close()
        open_ends, left = [conn for conn, _ in pipes], len(jobs)
        held, want = {}, 0  # results that came before their turn (ordered), the next index to yield
        while left:
            if not open_ends:  # every worker gone with jobs unanswered: one was killed (out of memory?)
                raise DataError(
                    f"a worker process died (exit code {_exit_codes(procs)}); try fewer --workers"
                )
            for conn in wait(open_ends):
                try:
                    i, got, error = conn.recv()
                except EOFError:  # its worker has ended
                    open_ends.remove(conn)
                    continue
                if error is not None:
                    raise error
                left -= 1
                if not ordered:
                    yield got
                    continue
                held[i] = got
                while want in held:
                    yield held.pop(want)
                    want += 1
    finally:  # done, failed or abandoned: no worker outlives the map
        for proc in procs:
            if proc.pid is None:  # never started: a stop signal (Terminated, Ctrl-C) came while forking
                continue
            if proc.is_alive():
                proc.kill()
            proc.join()
        for conn, _ in pipes:
            conn.close()


def _exit_codes(procs, wait_s: float = 10.0) -> str:
    """The exit codes of the workers that did not end cleanly, once they are reaped. A dying process
    closes its pipe before the kernel makes it reapable, so its end of the pipe can come first (often on
    a loaded machine) and its exitcode still read None: each is waited for, `wait_s` in all. A worker
    still running after that is named as such; with every worker ended cleanly (a job called exit(0)),
    their codes."""
    import time

    deadline = time.monotonic() + wait_s
    for proc in procs:
        proc.join(max(0.0, deadline - time.monotonic()))
    codes = [p.exitcode for p in procs if p.exitcode != 0] or [p.exitcode for p in procs]
    return ", ".join("none yet: still running" if c is None else str(c) for c in codes)


def _job_worker(parent: int, fn, jobs: list, size: int, next_index, conn, setup) -> None:
    worker_setup(parent)
    if setup is not None:
        setup()
    while True:
        with next_index.get_lock():
            start = next_index.value
            next_index.value = start + size
        if start >= len(jobs):
            break
        for i in range(start, min(start + size, len(jobs))):
            try:
                conn.send((i, fn(jobs[i]), None))  # pickled before anything is written
            except Exception as e:  # the caller re-raises it
                conn.send((i, None, e))
    conn.close()


def map_jobs(
    fn,
    jobs,
    *,
    workers: int,
    ray: str | None = None,
    ordered=True,
    star=False,
    bar=None,
    timing=None,
    setup=None,
):
    """The project's one map over jobs: fn(job) (fn(*job) when `star`) for each job, yielded as they
    finish, in job order when `ordered`. On `workers` forked local processes when `ray` is None (fn
    reaches them through fork, so a function of a script or a notebook works), else on Ray ("local": a
    private local Ray with `workers` CPUs; an address: that cluster; always completion order).
    `bar` (a tqdm bar, or None) advances once per job and is left open for the caller to close;
    `timing`, if given, receives "start_s": Ray's start or join; `setup()`, if given, runs first in each
    forked local worker. The results never depend on the executor or the worker count: every job carries
    its own seed."""
    call = (lambda job: fn(*job)) if star else fn
    if ray is None:
        got = _imap(
            call, jobs, workers=workers, ordered=ordered, chunksize=None if ordered else 1, setup=setup
        )
    else:
        tasks = list(jobs) if star else [(job,) for job in jobs]
        got = _run_ray(fn, tasks, address=None if ray == "local" else ray, workers=workers, timing=timing)
    for r in got:
        if bar is not None:
            bar.update()
        yield r


class LockstepEnvs:
    """`len(seeds)` environments from `make_env()`, reset to `seeds` and stepped together, their
    physics spread over `workers` forked processes (env i lives in worker i % workers) while the
    caller keeps the policy. The result never depends on `workers`: every env is its own simulator
    and receives the same actions. One process (no fork, or workers=1) runs them all in place.

        with LockstepEnvs(PushTEnv, seeds, workers=2) as envs:
            obs = envs.reset()                        # (N, obs_dim)
            obs[idx], done, success = envs.step(idx, actions)   # idx: envs still running
    """

    def __init__(self, make_env, seeds, *, workers: int):
        import multiprocessing as mp

        self.seeds = [int(s) for s in seeds]
        n = max(1, min(workers, len(self.seeds)))
        self.parts = [list(range(w, len(self.seeds), n)) for w in range(n)]  # env indices per worker
        self.conns, self.procs, self.local = [], [], None
        if n == 1 or not can_fork():
            self.parts, self.local = [list(range(len(self.seeds)))], [make_env() for _ in self.seeds]
            return
        ctx = mp.get_context("fork")
        for part in self.parts:
            parent, child = ctx.Pipe()
            # the child closes every parent end it inherits, so its recv() ends when the parent dies
            inherited = [*self.conns, parent]
            args = (child, make_env, [self.seeds[i] for i in part], len(self.procs), os.getpid(), inherited)
            proc = ctx.Process(target=_env_worker, args=args, daemon=True)
            with forking():
                proc.start()
            child.close()
            self.conns.append(parent)
            self.procs.append(proc)

    def _ask(self, msgs: dict) -> dict:
        """{worker: request} -> {worker: reply}; every request is sent before any reply is read."""
        if self.local is not None:
            return {w: _env_serve(self.local, self.seeds, *m) for w, m in msgs.items()}
        for w, m in msgs.items():
            self.conns[w].send(m)
        out = {w: self.conns[w].recv() for w in msgs}
        for r in out.values():
            if isinstance(r, BaseException):
                raise r
        return out

    def reset(self):
        import numpy as np

        replies = self._ask({w: ("reset", None) for w in range(len(self.parts))})
        self.obs_dim, self.obs_dtype = replies[0].shape[1], replies[0].dtype
        obs = np.zeros((len(self.seeds), self.obs_dim), self.obs_dtype)
        for w, part in enumerate(self.parts):
            obs[part] = replies[w]
        return obs

    def step(self, idx, actions):
        """Step envs `idx` with `actions` (len(idx), act_dim); returns their
        (obs (len(idx), obs_dim), done (len(idx),) bool, success (len(idx),) bool)."""
        import numpy as np

        row = {int(i): k for k, i in enumerate(idx)}  # env index -> row of `actions`
        mine = {w: [(j, row[i]) for j, i in enumerate(part) if i in row] for w, part in enumerate(self.parts)}
        asks = {w: m for w, m in mine.items() if m}  # worker -> [(its local env index, row)]
        replies = self._ask(
            {w: ("step", ([j for j, _ in m], actions[[k for _, k in m]])) for w, m in asks.items()}
        )
        obs = np.zeros((len(row), self.obs_dim), self.obs_dtype)
        done, success = np.zeros(len(row), bool), np.zeros(len(row), bool)
        for w, m in asks.items():
            rows = [k for _, k in m]
            obs[rows], done[rows], success[rows] = replies[w]
        return obs, done, success

    def close(self, stop: bool = False) -> None:
        """Ask each worker to end and wait for it; `stop`: kill them now (an exception is in flight)."""
        for conn in self.conns:
            with contextlib.suppress(OSError):  # the worker is already gone
                if not stop:
                    conn.send(None)
            conn.close()
        for proc in self.procs:
            if stop:
                proc.kill()
            proc.join()
        self.conns, self.procs = [], []

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        self.close(stop=kind is not None)


def _env_serve(envs, seeds, cmd, arg):
    """One request on a list of envs: ("reset", None) -> obs; ("step", (local idx, actions)) ->
    (obs, done, success), arrays in the order asked."""
    import numpy as np

    if cmd == "reset":
        return np.stack([e.reset(s) for e, s in zip(envs, seeds)])
    local, actions = arg
    obs, success, done = step_envs([envs[j] for j in local], actions)
    return obs, done, success


def step_envs(envs, actions):
    """envs[i] stepped with actions[i] for every i: (obs (N, obs_dim), success (N,) bool, done (N,)
    bool). In one call where the envs' class steps a batch (a step_many, the same bits: the engine's
    datagen.tasks.fast_pusht.SharedPushTEnv), else env.step per env (step_each). LockstepEnvs steps through
    it; the data engine's lanes step through their task's step_batch (datagen.task.Task)."""
    many = getattr(type(envs[0]), "step_many", None)
    if many is not None:
        return many(envs, actions)
    return step_each(envs, actions)


def step_each(envs, actions, infos: list | None = None):
    """envs[i] stepped with actions[i] by env.step, one env after the other: (obs (N, obs_dim), success
    (N,) bool, done (N,) bool). Any env with the Gym-like step(action) -> (obs, reward, done, info).
    infos: a list that gets each step's info, in env order."""
    import numpy as np

    obs, success, done = [], np.zeros(len(envs), bool), np.zeros(len(envs), bool)
    for k, (env, a) in enumerate(zip(envs, actions)):
        o, _, done[k], info = env.step(a)
        obs.append(o)
        success[k] = info["success"]
        if infos is not None:
            infos.append(info)
    return np.stack(obs), success, done


def _env_worker(conn, make_env, seeds, rank: int, parent: int, inherited) -> None:
    worker_setup(parent)
    for c in inherited:
        c.close()
    if hasattr(os, "sched_setaffinity"):  # one core each: woken together, they would otherwise
        cpus = sorted(os.sched_getaffinity(0))  # often queue on the core of the process that woke them
        os.sched_setaffinity(0, {cpus[rank % len(cpus)]})
    envs = [make_env() for _ in seeds]
    with contextlib.suppress(EOFError, OSError):  # the parent gone: nothing left to serve
        while (msg := conn.recv()) is not None:
            try:
                reply = _env_serve(envs, seeds, *msg)
            except Exception as e:  # the caller re-raises it
                reply = e
            conn.send(reply)
    conn.close()


@contextlib.contextmanager
def _stderr_silenced():
    """File descriptor 2 to /dev/null for a while: Ray's C++ client logs a warning per retry straight
    to it when a cluster cannot be joined; the one-line error after it says what happened."""
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    try:
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def _start_ray(address: str | None, workers: int):
    """Start a private local Ray (address None: `workers` CPUs, no dashboard) or join a cluster.

    Joining ships this repository to the cluster's workers as their working directory; they need
    the same Python packages (pip install the project with its `ray` extra on every node)."""
    try:
        import ray
    except ImportError:
        raise DataError("--ray needs Ray: pip install -e '.[ray]' (or pip install ray)") from None
    import logging

    common = dict(include_dashboard=False, logging_level=logging.ERROR, log_to_driver=False)
    try:
        if address is None:  # "local": always a new instance, never a cluster that happens to run here
            # its workers inherit this environment: the repository on their path (a runtime_env
            # would start a second pool of workers, seconds more on a small machine), and the cluster's
            # own token, made for this run and held in the environment of its processes alone (readable
            # by their user only), whatever RAY_AUTH_MODE says: anyone holding it can join and run code
            # as this user, and Ray's own place, ~/.ray/auth_token, it writes readable by every user
            path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
            token = secrets.token_hex(32)
            with environment(PYTHONPATH=path, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=token):
                _ray_auth_reread()
                ray.init(address="local", num_cpus=workers, **common)
        else:
            excludes = [".git", ".venv", "outputs", "*.ipynb", "tests"]
            with _stderr_silenced():
                ray.init(
                    address=address, runtime_env={"working_dir": str(ROOT), "excludes": excludes}, **common
                )
    except (ConnectionError, RuntimeError, ValueError, ray.exceptions.RayError) as e:  # a wrong token too
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        hint = (
            ""
            if address is None
            else " (is it running? a cluster with token auth needs RAY_AUTH_MODE=token and its token:"
            " ~/.ray/auth_token, RAY_AUTH_TOKEN_PATH or RAY_AUTH_TOKEN)"
        )
        raise DataError(f"could not {'start' if address is None else 'join'} Ray{hint}: {why}") from None
    return ray


def _ray_auth_reread() -> None:
    """Make this process's Ray read RAY_AUTH_MODE and its token from the environment again. It reads
    them once and keeps them, so a second private cluster in one process (a notebook's second run)
    would be shown the first one's token, and a cluster joined after ours would be shown ours."""
    try:
        from ray._raylet import AuthenticationTokenLoader, Config
    except ImportError:  # a Ray without token authentication: nothing kept
        return
    Config.initialize("")  # what Ray's own ray.init does when it turns token authentication on
    AuthenticationTokenLoader.instance().reset_cache()


@contextlib.contextmanager
def _ray_auth_put_back():
    """On leaving (Ray shut down, or its start failed), this process's Ray forgets our cluster's token
    and mode and reads the environment's again (_ray_auth_reread)."""
    try:
        yield
    finally:
        _ray_auth_reread()


@contextlib.contextmanager
def _raylet_messages_dropped():
    """Keep Ray's cluster messages off our stdout while a run uses Ray. Whatever log_to_driver says, a
    Ray driver starts a thread that prints every raylet error message to stdout
    (ray._private.worker.listen_error_messages -> print_to_stdstream; a lost node is about 20 lines amid
    the run's own output). With log_to_driver off that thread is the function's only caller, so inside
    this block it is replaced by one that drops the messages; a failure they describe reaches the run as
    the failed task's exception (its one error line). Put back on leaving (after ray.shutdown, which
    ends that thread): nothing else in the process sees the change."""
    try:
        import ray._private.worker as ray_worker

        saved = ray_worker.print_to_stdstream
    except (ImportError, AttributeError):  # no Ray (_start_ray says so) or another Ray inside
        yield
        return
    ray_worker.print_to_stdstream = lambda data, ignore_prefix=False: None
    try:
        yield
    finally:
        ray_worker.print_to_stdstream = saved


def _apply(fn, *args):
    """fn(*args): the one function Ray runs, so `fn` may be any picklable callable (operator.call too)."""
    return fn(*args)


def _run_ray(fn, tasks: list, *, address: str | None, workers: int, timing: dict | None = None):
    """fn(*args) for each args in `tasks` as Ray tasks of one CPU each, at most 2 per CPU in flight.
    `timing`, if given, receives "start_s": the seconds Ray took to start or join."""
    import time

    t0 = time.perf_counter()
    with _raylet_messages_dropped(), _ray_auth_put_back():
        ray = _start_ray(address, workers)
        if timing is not None:
            timing["start_s"] = time.perf_counter() - t0
        try:
            remote = ray.remote(num_cpus=1, max_retries=0)(_apply)  # any picklable fn, a builtin too
            window = max(2, 2 * int(ray.cluster_resources().get("CPU", workers)))
            todo, pending = list(tasks), []
            while todo or pending:
                while todo and len(pending) < window:
                    pending.append(remote.remote(fn, *todo.pop(0)))
                done, pending = ray.wait(pending, num_returns=1)
                yield ray.get(done[0])
        finally:
            ray.shutdown()
