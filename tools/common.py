"""What every tool shares: the paths it works on, ToolError and the CLI wrapper, run provenance."""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

from ch37 import ROOT
from ch37.errors import run_main

SCRIPT = ROOT / "scale_data.py"
META = ROOT / "meta.yaml"
WALLCLOCK = ROOT / "wallclock.csv"
NOTEBOOK = ROOT / "scale_data.ipynb"


class ToolError(Exception):
    """Bad input: reported as one `error:` line and exit code 2."""


def parser(prog: str, doc: str) -> argparse.ArgumentParser:
    """An argument parser whose errors are ToolErrors (one line, exit 2), with the usual --script."""
    p = argparse.ArgumentParser(
        prog=f"python -m tools.{prog}",
        description=doc,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        allow_abbrev=False,
    )

    def error(msg):
        raise ToolError(f"{msg} (see --help)")

    p.error = error
    p.add_argument("--script", type=Path, default=SCRIPT, help="chapter script (default scale_data.py)")
    return p


def run_cli(main) -> None:
    """sys.exit(main(argv)); a ToolError becomes one `error:` line on stderr and exit code 2, and so do
    the problems ch37.errors.run_main handles (Ctrl-C: exit 130)."""
    try:
        code = run_main(main, sys.argv[1:])
    except ToolError as e:
        print(f"error: {e}", file=sys.stderr)
        code = 2
    sys.exit(code)


def _rel(p: Path) -> str:
    """`p` relative to the repository root when it lies inside it, else as given (absolute)."""
    p = Path(p).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def supports_flag(script: Path, flag: str) -> bool:
    """Whether the chapter script defines `flag` (read from its source, so nothing is run)."""
    return f'"{flag}"' in Path(script).read_text(encoding="utf-8")


def _cpu_model() -> str:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    if not cpu and sys.platform == "darwin":
        try:
            cmd = ["sysctl", "-n", "machdep.cpu.brand_string"]
            cpu = subprocess.run(cmd, capture_output=True, text=True).stdout.strip()
        except OSError:
            pass
    return cpu


def _git() -> dict | None:
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True, text=True
        )
    except OSError:
        return None
    return (
        {"commit": head.stdout.strip(), "dirty": bool(dirty.stdout.strip())} if head.returncode == 0 else None
    )


def provenance(script: Path) -> dict:
    """Where and with what a run happened: date, git commit, platform, package versions, region hashes."""
    from tools.regions import RegionError, region_hashes

    def version(pkg):
        try:
            return importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            return None

    try:
        hashes = region_hashes(script)
    except RegionError:
        hashes = None
    return {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "git": _git(),
        "platform": {
            "python": platform.python_version(),
            "os": platform.platform(),
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "cpu_model": _cpu_model(),
        },
        "packages": {p: version(p) for p in ("torch", "lerobot", "mujoco", "numpy")},
        "script_region_hashes": hashes,
    }
