"""Process hygiene, in one place: how a worker is born and dies, and what this machine allows.

Workers die with the run: each asks the kernel for SIGKILL when its parent dies (Linux prctl
PR_SET_PDEATHSIG; elsewhere a thread watching the parent pid), and Ctrl-C is the parent's alone
(workers ignore SIGINT; the parent stops them). forking() blocks the stop signals around a fork.
max_workers and available_memory bound the flags that spend cores and memory; environment() scopes an
environment variable to the call that needs it; headless_gl() picks a rendering program's GL backend;
has_avx2_fma() says whether this CPU runs the published kernel path's OpenBLAS kernels (ch37.cli).
(The main process's exit codes and its SIGTERM handler are ch37.errors'; a forked worker's copy of a
run's lock is closed by ch37.ownership's at-fork hook.)
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from pathlib import Path

_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


@contextlib.contextmanager
def forking():
    """Block SIGINT/SIGTERM while forking: a child is born with them blocked and unblocks them only
    after its own handlers are set (worker_setup), so a Ctrl-C at that moment never reaches the
    parent's Python handler in the child. Pending signals reach the parent when the block ends."""
    can_mask = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS) if can_mask else None
    try:
        yield
    finally:
        if can_mask:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def environment(**values: str):
    """These environment variables set for the block only, then put back as they were (unset where they
    were unset): a setting a library reads from the environment, scoped to the call that needs it."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def headless_gl() -> None:
    """MuJoCo's EGL backend for a program that renders (the demo generators' --video), unless you chose one
    (MUJOCO_GL): on Linux a machine may have no display for GLFW, MuJoCo's default. MuJoCo reads MUJOCO_GL
    once, when first imported, so the program calls this under `if __name__ == "__main__"` before its
    imports load mujoco; never an import of ours (a library's user chooses their own backend)."""
    if sys.platform.startswith("linux"):
        os.environ.setdefault("MUJOCO_GL", "egl")


def _die_with(parent: int) -> None:
    if sys.platform.startswith("linux"):
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    else:  # no parent-death signal: a thread polls the parent's pid

        def watch():
            while os.getppid() == parent:
                threading.Event().wait(1.0)
            os._exit(1)

        threading.Thread(target=watch, daemon=True).start()
    if os.getppid() != parent:  # the parent died before the request above took effect
        os._exit(1)


def worker_setup(parent: int) -> None:
    """First call in a forked worker: die with `parent`, leave Ctrl-C to it, end quietly on SIGTERM."""
    _die_with(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def has_avx2_fma() -> bool:
    """Whether this CPU has AVX2 and FMA (Linux's /proc/cpuinfo; False elsewhere): OpenBLAS's Haswell
    kernels, the published numbers' training kernels, need both; told to use them without, they fault."""
    info = Path("/proc/cpuinfo")
    flags = (
        next((ln for ln in info.read_text().splitlines() if ln.startswith("flags")), "")
        if info.exists()
        else ""
    )
    return {"avx2", "fma"} <= set(flags.split())


def max_workers() -> int:
    return max(8, 4 * (os.cpu_count() or 1))


def available_memory() -> int | None:
    """Bytes of RAM available now (Linux MemAvailable, else total physical memory), None if unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None
