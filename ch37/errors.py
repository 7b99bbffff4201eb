"""The contract for bad input: one clear line on stderr and an exit code, never a traceback.

    DataError           a problem the user must fix (a flag, a path, a dataset): `error: ...`, exit 2
    KeyboardInterrupt   Ctrl-C: `interrupted: ...`, exit 130; the same command continues where it stopped
    Terminated          SIGTERM (raised by our handler): the same line, exit 143
    OSError of the environment (disk full, read-only, permission denied): `error: ...`, exit 2

Anything else is a genuine bug and keeps its traceback. CH37_DEBUG=1 shows the traceback for
everything. Two ways in, one behaviour (one formatter, _tell): `guard()` for a linear script
(scale_data.py), `run_main(fn, ...)` for a command with a main function (the generators, the tools,
the data engine), whose entry point is `main(fn)`.
"""

from __future__ import annotations

import _thread
import atexit
import contextlib
import errno
import os
import signal
import sys
import threading
import time

RESUME = "run the same command again to continue (nothing half-written was kept)"
# errno values that say something about the user's machine or paths, not about our code
_WRITABLE = "choose a folder you can write to"
ENVIRONMENT_ERRNOS = {
    errno.ENOSPC: "free some disk space",
    errno.EDQUOT: "free some space in your quota",
    errno.EROFS: _WRITABLE,
    errno.EACCES: _WRITABLE,
    errno.EPERM: _WRITABLE,
    errno.ENOTDIR: "a part of the path is a file, not a folder: fix the path",
    errno.EISDIR: "a folder is where a file should be: fix the path",
    errno.EEXIST: "a file is where a folder should be: fix the path",
    errno.ENAMETOOLONG: "use a shorter path",
    errno.EMFILE: "raise the open-file limit (ulimit -n)",
}


class DataError(Exception):
    """A problem with a demo folder or an output folder that the user must fix (printed as one line)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that cleanup (finally blocks, worker shutdown) runs."""


def env_flag(name: str) -> bool:
    """Whether the environment variable `name` is set to anything but empty, 0, false or no."""
    return os.environ.get(name, "").strip().lower() not in ("", "0", "false", "no")


def one_line(exc: BaseException) -> tuple[int, str] | None:
    """(exit code, the one line to print) for a problem the user can act on; None for a genuine bug."""
    if isinstance(exc, Terminated):
        return 143, f"terminated: {RESUME}"
    if isinstance(exc, KeyboardInterrupt):
        return 130, f"interrupted: {RESUME}"
    if isinstance(exc, DataError):
        return 2, "error: " + " ".join(str(exc).split())
    if isinstance(exc, OSError) and exc.errno in ENVIRONMENT_ERRNOS:
        where = f"{exc.filename}: " if exc.filename is not None else ""
        fix = ENVIRONMENT_ERRNOS[exc.errno]
        return 2, f"error: {where}{exc.strerror}; {fix}, then run the same command again"
    return None


def _tell(exc: BaseException) -> int | None:
    """Print `exc`'s one line on stderr and return its exit code; None for a genuine bug (or CH37_DEBUG)."""
    got = None if env_flag("CH37_DEBUG") else one_line(exc)  # CH37_DEBUG: every traceback shown
    if got is None:
        return None
    print(got[1], file=sys.stderr)
    return got[0]


def _raise_terminated(signum, frame):
    raise Terminated()


def _redeliver(unraisable) -> None:
    """sys.unraisablehook: Ctrl-C or SIGTERM that landed in a finalizer (a `__del__`, a weakref
    callback) is swallowed by Python ("Exception ignored in ..."), and the run went on to exit 0 as if
    nobody had pressed Ctrl-C. Deliver it again, from another thread: raised here or in the finalizer
    it would be lost again; the main thread takes it at its next step in the run's own code, where it
    stops the run as any Ctrl-C does."""
    if not isinstance(unraisable.exc_value, KeyboardInterrupt):
        sys.__unraisablehook__(unraisable)
        return
    signum = signal.SIGTERM if isinstance(unraisable.exc_value, Terminated) else signal.SIGINT
    # threading's start() waits for the thread, and the wait would take the signal here: _thread's does not
    _thread.start_new_thread(_signal_main_soon, (signum,))


def _signal_main_soon(signum: int) -> None:
    time.sleep(0.01)  # the finalizer has returned by then; if another one runs, _redeliver goes again
    signal.pthread_kill(threading.main_thread().ident, signum)  # a real signal: it ends a blocking wait


def _exit_now(code: int) -> None:
    """Exit with `code` from inside sys.excepthook: run atexit (worker shutdown), flush, leave."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not interrupt the shutdown
    try:
        atexit._run_exitfuncs()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        os._exit(code)


def guard() -> None:
    """For a linear script: every uncaught problem a user can act on becomes one line and its exit
    code (see the module docstring); SIGTERM is handled like Ctrl-C. A no-op inside a notebook."""
    in_notebook = "ipykernel" in sys.modules or hasattr(sys, "ps1")
    if in_notebook or threading.current_thread() is not threading.main_thread():
        return
    previous = sys.excepthook

    def hook(kind, exc, tb):
        code = _tell(exc)
        if code is None:
            previous(kind, exc, tb)
        else:
            _exit_now(code)

    sys.excepthook = hook
    sys.unraisablehook = _redeliver
    signal.signal(signal.SIGTERM, _raise_terminated)


def run_main(fn, *args, **kwargs) -> int:
    """fn(*args, **kwargs) -> its exit code; a problem a user can act on is one line and its exit code
    (see the module docstring). SIGTERM is handled like Ctrl-C while fn runs."""
    main_thread = threading.current_thread() is threading.main_thread()
    saved = signal.signal(signal.SIGTERM, _raise_terminated) if main_thread else None
    saved_hook = sys.unraisablehook
    if main_thread:
        sys.unraisablehook = _redeliver
    try:
        return fn(*args, **kwargs)
    except (KeyboardInterrupt, DataError, OSError) as e:
        code = _tell(e)
        if code is None:
            raise
        return code
    finally:
        sys.unraisablehook = saved_hook
        if main_thread:
            signal.signal(signal.SIGTERM, saved)


def main(fn) -> None:
    """A command's entry point: sys.exit(run_main(fn, argv)) with the process's own arguments."""
    sys.exit(run_main(fn, sys.argv[1:]))
