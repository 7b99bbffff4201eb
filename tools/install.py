"""The course's packages in a fresh notebook runtime (Colab): what scale_data.ipynb's first cell calls
once it has found or cloned the repository.

    from tools.install import ensure_packages; print(ensure_packages(repo))

When lerobot is importable already (a clone set up with run_chapter.sh, the notebook run again), nothing
is installed. Otherwise pip installs pyproject.toml's dependencies, no more, with its default strategy
(only-if-needed): a preinstalled package that already satisfies every pin is kept, torch and numpy
included; one that does not (a torch newer than lerobot 0.6's torch<2.12, a numpy newer than its
numpy<2.3) is replaced, since lerobot cannot run with it. The returned line says what the install added
and replaced, and whether the runtime must restart: it must when a replaced package is one this Python
had already imported (the old version stays loaded). Standard library only: it runs before anything
is installed.
"""

from __future__ import annotations

import importlib
import importlib.metadata as md
import importlib.util
import re
import subprocess
import sys
import tomllib
from pathlib import Path

SHOWN = 8  # replaced packages named in the line; the rest are counted


class InstallError(RuntimeError):
    """pip failed: one line in a notebook (IPython shows what _render_traceback_ returns), no traceback."""

    def _render_traceback_(self) -> list[str]:
        return [f"stopped: {self}"]


def dependencies(root: Path) -> list[str]:
    """pyproject.toml's [project] dependencies: what the chapter needs to run (no dev, ray or train)."""
    text = (Path(root) / "pyproject.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)["project"]["dependencies"]


def canonicalize_name(name: str) -> str:
    """A distribution's name as PEP 503 compares it (packaging.utils.canonicalize_name, without needing
    packaging: this module runs before anything is installed, tools.lock in a .venv whose set-up stopped)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def installed() -> dict[str, str]:
    """{distribution name (normalised): version} of every package this Python sees."""
    return {
        canonicalize_name(d.metadata["Name"]): d.version for d in md.distributions() if d.metadata["Name"]
    }


def changes(before: dict, after: dict) -> tuple[dict, dict]:
    """(added {name: version}, replaced {name: (old, new)}) between two installed() snapshots."""
    added = {n: v for n, v in after.items() if n not in before}
    replaced = {n: (before[n], v) for n, v in after.items() if n in before and before[n] != v}
    return added, replaced


def imported(names, modules=None) -> list[str]:
    """Those of the distributions `names` that have a module imported in this process (`modules`:
    default sys.modules)."""
    modules = sys.modules if modules is None else modules
    owners = md.packages_distributions()  # top-level module -> the distributions that provide it
    hit = {canonicalize_name(d) for top, dists in owners.items() if top in modules for d in dists}
    return sorted(set(names) & hit)


def summary(added: dict, replaced: dict, loaded: list[str]) -> str:
    """One line: what the install changed, and whether to restart the runtime."""
    if not added and not replaced:
        return "pip installed nothing: every package was here and satisfies the pins; no restart needed"
    what = [f"added {len(added)} package{'s' * (len(added) != 1)}"] if added else []
    if replaced:
        named = [f"{n} {old} -> {new}" for n, (old, new) in sorted(replaced.items())]
        more = f" and {len(named) - SHOWN} more" if len(named) > SHOWN else ""
        what.append("replaced " + ", ".join(named[:SHOWN]) + more)
    else:
        what.append("kept every preinstalled package")
    if loaded:
        restart = (
            f"restart the runtime now (Colab: Runtime > Restart session), then Run all: this Python had "
            f"already imported the replaced {', '.join(loaded)}"
        )
    else:
        restart = "no restart needed" + (" (no replaced package was imported yet)" if replaced else "")
    return f"the install {'; '.join(what)}; {restart}"


def ensure_packages(root: Path) -> str:
    """Install pyproject.toml's dependencies into this Python unless lerobot is importable; returns the
    line to print."""
    if importlib.util.find_spec("lerobot") is not None:
        return f"lerobot {md.version('lerobot')} is importable: nothing installed"
    deps = dependencies(root)
    print(
        "installing the course's packages with pip (a preinstalled package that satisfies the pins is "
        "kept; a few minutes)...",
        flush=True,
    )
    before = installed()
    # captured, then printed: a subprocess's own output does not reach every notebook front end
    done = subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", *deps], capture_output=True, text=True
    )
    importlib.invalidate_caches()
    if said := (done.stdout + done.stderr).strip():  # pip's warnings (conflicts with other packages), errors
        print(said, flush=True)
    if done.returncode != 0:
        raise InstallError(f"pip install exited {done.returncode} (its messages are above); then run again")
    added, replaced = changes(before, installed())
    return summary(added, replaced, imported(replaced))
