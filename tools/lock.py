"""requirements.lock, the hashed lock setup_env.sh installs: read it, check .venv against it, record it.

    python -m tools.lock                  exit 1 naming every installed package that differs from the lock
    python -m tools.meta --environment    refresh meta.yaml's `environment` (nothing else) from the lock
    bash tools/lock.sh [--upgrade]        make the lock itself (uv pip compile; see that script)

The lock pins every package the set-up installs (pyproject.toml's dependencies plus its dev, ray and
train extras) with the hashes of every wheel, for Python 3.12 on every platform; a line's marker
(`; sys_platform == 'linux'`) says where it applies. What is installed must be exactly what applies
here: no locked package missing or at another version, nothing unlocked besides pip itself.

Exit codes: 0 ok, 1 drift, 2 bad input (a missing or malformed lock, bad flags).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import platform
import re
import site
from pathlib import Path

from ch37 import ROOT, errors
from ch37.errors import DataError
from tools.common import parser, rel
from tools.install import canonicalize_name  # stdlib only, as this module must be

LOCK = ROOT / "requirements.lock"
# meta.yaml's and wallclock.csv's record of what the numbers came from: the packages that move floats
# (torch, numpy), the physics (mujoco), the data format (lerobot) and the two the chapter's tools drive
META_PACKAGES = ("torch", "numpy", "mujoco", "lerobot", "gymnasium", "ray")
# installed by the venv itself, never by the lock: the installer
UNLOCKED_OK = {"pip"}
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;\\]+)\s*(?:;\s*([^\\]+?))?\s*\\?$")


def read_lock(path: Path = LOCK) -> dict[str, tuple[str, str | None]]:
    """{canonical name: (version, marker or None)} of every pin in the lock; a DataError if malformed."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(f"{rel(path)} is not readable ({e}); make it with: bash tools/lock.sh") from None
    pins = {}
    for n, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith(("#", "--")):  # comments, hashes, pip options
            continue
        m = PIN.match(line)
        if not m:
            raise DataError(f"{rel(path)} line {n}: not a `name==version` pin: {line.strip()[:80]}")
        name, version, marker = m.groups()
        pins[canonicalize_name(name)] = (version, marker)
    if not pins:
        raise DataError(f"{rel(path)} pins nothing; make it with: bash tools/lock.sh")
    return pins


def applies(marker: str | None) -> bool:
    """Whether a pin's environment marker holds on this interpreter and platform."""
    if marker is None:
        return True
    from packaging.markers import InvalidMarker, Marker  # installed by the lock; missing(): without it

    try:
        return Marker(marker).evaluate()
    except InvalidMarker as e:
        raise DataError(f"requirements.lock has a malformed marker ({e})") from None


def locked_here(path: Path = LOCK) -> dict[str, str]:
    """{canonical name: version} of the pins that apply here: what setup_env.sh installs on this machine."""
    return {name: v for name, (v, marker) in read_lock(path).items() if applies(marker)}


def installed() -> dict[str, str]:
    """{canonical name: version} of every distribution installed in this interpreter's site-packages
    (where pip installs). A folder an import adds to sys.path is no installation: setuptools puts its
    vendored packages there (packaging, importlib-metadata, ...), and pygame imports it."""
    found = importlib.metadata.distributions(path=site.getsitepackages())
    return {canonicalize_name(d.metadata["Name"]): d.version for d in found}


def drift(path: Path = LOCK, have: dict[str, str] | None = None) -> list[str]:
    """One line per difference between the installed packages (`have`, default installed()) and the lock."""
    want, have = locked_here(path), installed() if have is None else have
    out = [
        f"{n}: installed {have.get(n, 'nothing')}, locked {v}"
        for n, v in sorted(want.items())
        if have.get(n) != v
    ]
    out += [
        f"{n}: installed {v}, not in the lock"
        for n, v in sorted(have.items())
        if n not in want.keys() | UNLOCKED_OK
    ]
    return out


def missing(path: Path = LOCK) -> list[str]:
    """One line per pin without a marker (it applies everywhere) that is not installed at its version;
    stdlib only, so it runs in a .venv whose set-up stopped mid-install (setup_env.sh's check of a
    stamped .venv, and this command's first pass)."""
    have = installed()
    pins = {n: v for n, (v, marker) in read_lock(path).items() if marker is None}
    return [
        f"{n}: installed {have.get(n, 'nothing')}, locked {v}"
        for n, v in sorted(pins.items())
        if have.get(n) != v
    ]


def lock_digest(path: Path = LOCK) -> str:
    """First 16 hex of the lock's sha256: the key of setup_env.sh's install stamp, and meta.yaml's."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def versions(path: Path = LOCK) -> dict[str, str]:
    """This python and META_PACKAGES' locked versions: what meta.yaml and wallclock.csv record."""
    pins = locked_here(path)
    return {"python": platform.python_version()} | {p: pins.get(p, "") for p in META_PACKAGES}


def ran_versions(names=("python", *META_PACKAGES)) -> dict[str, str]:
    """This interpreter's python and the versions of `names` its imports load: what a timing ran on.
    Looked up along sys.path, as an import is, so a package carried on PYTHONPATH (the GPU check's
    wheels, tools/gpu_check.sh) is named too; one not found at all is ""."""

    def version(name: str) -> str:
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            return ""

    return {n: platform.python_version() if n == "python" else version(n) for n in names}


def environment_section(path: Path = LOCK, python: str | None = None) -> dict:
    """meta.yaml's `environment`: the lock, its digest and the versions the published numbers ran on."""
    v = versions(path)
    if python:  # the interpreter a result recorded, not the one writing meta.yaml
        v["python"] = python
    note = f"installed by setup_env.sh from {rel(path)} ({len(read_lock(path))} pins, hashed); check: "
    return {"lock": rel(path), "lock_sha256": lock_digest(path), "note": note + "python -m tools.lock"} | v


def main(argv: list[str]) -> int:
    p = parser("lock", __doc__)
    p.add_argument("--lock", type=Path, default=LOCK, help="default requirements.lock")
    p.add_argument("--missing", action="store_true", help="only the pins that apply everywhere (stdlib only)")
    a = p.parse_args(argv)
    incomplete = a.missing or importlib.util.find_spec("packaging") is None  # no markers can be read
    if bad := (missing(a.lock) if incomplete else drift(a.lock)):
        for line in bad:
            print(f"drift: {line}")
        print(f"{len(bad)} difference(s) from {rel(a.lock)}; reinstall: rm -r .venv, then bash run_tests.sh")
        return 1
    if a.missing:
        print(f"ok: every pin of {rel(a.lock)} that applies everywhere is installed")
        return 0
    print(f"ok: the installed packages are exactly {rel(a.lock)}'s {len(locked_here(a.lock))} pins for here")
    return 0


if __name__ == "__main__":
    errors.main(main)
