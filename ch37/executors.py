"""Where the data engine's shards run: local processes (the default) or Ray. Both yield each task's
result as soon as it is done, in any order; the caller saves it and drops it, so memory holds a
few shards, not the run. Which executor ran a shard never changes its bytes: a shard is a pure
function of its arguments (see ch37.shards)."""

from __future__ import annotations

import contextlib
import os
import sys

from ch37 import ROOT
from ch37.errors import DataError
from ch37.parallel import imap


def run(fn, tasks: list, *, workers: int, ray: str | None = None, timing: dict | None = None):
    """fn(*args) for each args in `tasks`, yielded in completion order: on `workers` local processes
    (ch37.parallel's pool) when `ray` is None, else on Ray ("local": a private local Ray with `workers`
    CPUs; an address: that cluster). `timing`, if given, receives "start_s": Ray's start or join."""
    if ray is None:
        return imap(lambda args: fn(*args), tasks, workers=workers, ordered=False, chunksize=1)
    return run_ray(fn, tasks, address=None if ray == "local" else ray, workers=workers, timing=timing)


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


def start_ray(address: str | None, workers: int):
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
            # would start a second pool of workers, seconds more on a small machine)
            saved = os.environ.get("PYTHONPATH")
            os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), saved]))
            try:
                ray.init(address="local", num_cpus=workers, **common)
            finally:
                if saved is None:
                    os.environ.pop("PYTHONPATH")
                else:
                    os.environ["PYTHONPATH"] = saved
        else:
            excludes = [".git", ".venv", "outputs", "*.ipynb", "tests"]
            with _stderr_silenced():
                ray.init(
                    address=address, runtime_env={"working_dir": str(ROOT), "excludes": excludes}, **common
                )
    except (ConnectionError, RuntimeError, ValueError) as e:
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        hint = (
            "" if address is None else " (is it running? a cluster with token auth needs RAY_AUTH_MODE=token)"
        )
        raise DataError(f"could not {'start' if address is None else 'join'} Ray{hint}: {why}") from None
    _quiet_raylet_messages()
    return ray


def _quiet_raylet_messages() -> None:
    """Keep Ray's cluster messages off our stdout. Whatever log_to_driver says, a Ray driver starts a
    thread that prints every raylet error message to stdout (ray._private.worker.listen_error_messages
    -> print_to_stdstream; a lost node is about 20 lines amid the run's own output). With log_to_driver
    off that thread is the function's only caller, so it is replaced by one that drops the messages; a
    failure they describe reaches the run as the failed task's exception (its one error line)."""
    with contextlib.suppress(ImportError, AttributeError):
        import ray._private.worker as ray_worker

        ray_worker.print_to_stdstream = lambda data, ignore_prefix=False: None


def run_ray(fn, tasks: list, *, address: str | None, workers: int, timing: dict | None = None):
    """fn(*args) for each args in `tasks` as Ray tasks of one CPU each, at most 2 per CPU in flight.
    `timing`, if given, receives "start_s": the seconds Ray took to start or join."""
    import time

    t0 = time.perf_counter()
    ray = start_ray(address, workers)
    if timing is not None:
        timing["start_s"] = time.perf_counter() - t0
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(fn)
        window = max(2, 2 * int(ray.cluster_resources().get("CPU", workers)))
        todo, pending = list(tasks), []
        while todo or pending:
            while todo and len(pending) < window:
                pending.append(remote.remote(*todo.pop(0)))
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        ray.shutdown()
