"""requirements.lock (tools/lock.py): .venv is exactly the lock, the lock covers pyproject.toml, and
meta.yaml records the lock its numbers ran on."""

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import yaml
from conftest import ROOT, run_script
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from tools import lock


def test_installed_packages_are_exactly_the_lock():
    """Fails when any package differs from requirements.lock: swapped, missing or unlocked."""
    bad = lock.drift()
    assert not bad, (
        "this .venv is not requirements.lock (reinstall: rm -r .venv, then bash run_tests.sh):\n"
        + ("\n".join(bad))
    )


def test_a_swapped_package_is_named(tmp_path):
    """The checker pointed at a lock with another torch (and without tqdm) names both differences."""
    text = lock.LOCK.read_text()
    torch = lock.locked_here()["torch"]
    assert f"\ntorch=={torch} " in text
    tqdm = lock.locked_here()["tqdm"]
    swapped = text.replace(f"\ntorch=={torch} ", "\ntorch==2.10.0 ").replace(f"\ntqdm=={tqdm} \\\n", "\n")
    assert swapped.count("==") == text.count("==") - 1  # tqdm's pin gone (its hash lines are only options)
    copy = tmp_path / "requirements.lock"
    copy.write_text(swapped)
    bad = lock.drift(copy)
    assert f"torch: installed {torch}, locked 2.10.0" in bad
    assert any(line.startswith("tqdm: installed") and line.endswith("not in the lock") for line in bad)
    p = run_script("-m", "tools.lock", "--lock", copy, check=False)
    assert p.returncode == 1 and f"drift: torch: installed {torch}, locked 2.10.0" in p.stdout
    assert run_script("-m", "tools.lock").returncode == 0


def test_a_malformed_lock_is_one_line(tmp_path):
    bad = tmp_path / "requirements.lock"
    bad.write_text("torch>=2\n")
    p = run_script("-m", "tools.lock", "--lock", bad, check=False)
    assert p.returncode == 2 and p.stderr.startswith("error:") and len(p.stderr.strip().splitlines()) == 1


def test_the_lock_covers_pyproject():
    """Every requirement of pyproject.toml (dependencies and the dev, ray, train extras the set-up installs)
    is pinned at a version it admits: a pyproject.toml edit without `bash tools/lock.sh` fails here."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    pins = lock.read_lock()
    for spec in project["dependencies"] + extras["dev"] + extras["ray"] + extras["train"]:
        req = Requirement(spec)
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} is not in requirements.lock: run bash tools/lock.sh"
        assert req.specifier.contains(pins[name][0], prereleases=True), f"{spec} vs locked {pins[name][0]}"


def test_meta_records_the_lock_its_numbers_ran_on():
    meta = yaml.safe_load((ROOT / "meta.yaml").read_text())
    env = meta["environment"]
    assert env["lock_sha256"] == lock.lock_digest(), "meta.yaml is stale: python -m tools.meta --environment"
    pins = lock.locked_here()
    assert {p: env[p] for p in lock.META_PACKAGES} == {p: pins[p] for p in lock.META_PACKAGES}
    for part in ("seeds", "aug_curve"):  # the published sweeps ran on the locked versions
        prov = meta["reference_run"][part]["provenance"]
        assert prov["platform"]["python"] == env["python"]
        assert {p: pins[p] for p in prov["packages"]} == prov["packages"], (
            f"reference_run.{part} ran other versions than requirements.lock: re-run the sweeps on it"
        )


@pytest.mark.parametrize("marker,here", [(None, True), ("sys_platform == 'emscripten'", False)])
def test_markers_decide_what_applies_here(marker, here):
    assert lock.applies(marker) is here


def _set_up(folder, env) -> tuple[int, str]:
    """setup_env.sh sourced in `folder` (a copy of the set-up beside its own .venv): (exit code, output)."""
    import subprocess

    p = subprocess.run(
        ["bash", "-c", "source setup_env.sh"], cwd=folder, env=env, capture_output=True, text=True
    )
    return p.returncode, p.stdout + p.stderr


def test_the_set_up_recovers_from_a_stopped_set_up_by_itself(tmp_path):
    """Issue 42 #9: a set-up killed while `python -m venv` ran left .venv/bin/python without pip, and every
    later run failed with `No module named pip` until `rm -r .venv`; a stamped .venv missing a locked
    package ended in a ModuleNotFoundError. The set-up completes the first in place and installs the
    second again; a complete stamped .venv stays a no-op. A lock of one pin (pip, from Python's own
    wheel, no index) stands for the real one: the repair decision is tested, not the multi-GB install."""
    import ensurepip
    import hashlib
    import shutil
    import subprocess
    import sys

    wheels = Path(ensurepip.__file__).parent / "_bundled"
    wheel = next(wheels.glob("pip-*.whl"))
    version = wheel.name.split("-")[1]
    digest = hashlib.sha256(wheel.read_bytes()).hexdigest()
    for name in ("setup_env.sh", "tools", "ch37"):
        (shutil.copytree if name != "setup_env.sh" else shutil.copy)(ROOT / name, tmp_path / name)
    (tmp_path / "requirements.lock").write_text(f"pip=={version} \\\n    --hash=sha256:{digest}\n")
    base = Path(sys._base_executable).parent  # a Python 3.12 first on PATH; no uv: pip installs
    env = {"PATH": f"{base}:/usr/bin:/bin", "HOME": str(tmp_path), "PIP_NO_INDEX": "1"}
    env |= {"PIP_FIND_LINKS": str(wheels), "PIP_DISABLE_PIP_VERSION_CHECK": "1"}
    venv = tmp_path / ".venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", venv], check=True)  # killed mid-venv
    code, out = _set_up(tmp_path, env)
    assert code == 0 and "repairing .venv" in out, out
    stamps = list(venv.glob(".installed-*"))
    assert len(stamps) == 1 and subprocess.run([venv / "bin" / "python", "-c", "import pip"]).returncode == 0
    # stamped, but a locked package is gone (its metadata removed: installed nothing, as pip sees it)
    site = next(venv.glob("lib/python3*/site-packages"))
    shutil.rmtree(next(site.glob(f"pip-{version}.dist-info")))
    code, out = _set_up(tmp_path, env)
    assert code == 0 and f"pip: installed nothing, locked {version}" in out, out
    assert next(site.glob(f"pip-{version}.dist-info")) and list(venv.glob(".installed-*")) == stamps
    # complete and stamped: nothing said, nothing changed
    before = {p: p.stat().st_mtime_ns for p in [venv, *stamps, *site.iterdir()]}
    assert _set_up(tmp_path, env) == (0, "")
    assert {p: p.stat().st_mtime_ns for p in before} == before
    # issue 42 #7: tools.lock in such a .venv (no packaging) names what is missing instead of a traceback
    p = subprocess.run(
        [venv / "bin" / "python", "-m", "tools.lock", "--lock", ROOT / "requirements.lock"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    lines = p.stdout.strip().splitlines()
    assert p.returncode == 1 and "Traceback" not in p.stdout + p.stderr, p.stdout + p.stderr
    assert "drift: packaging: installed nothing" in p.stdout and "rm -r .venv" in lines[-1], p.stdout


@pytest.mark.parametrize("kind", ["file", "dangling link", "python 3.11 venv"])
def test_the_set_up_refuses_a_venv_it_cannot_use_and_leaves_it_as_it_is(tmp_path, kind):
    """Issue 48 #8: a .venv made with Python 3.11 was kept and the 3.12 lock installed into it (the download
    happened, then pip failed); a .venv that is a file ended in venv's own "Unable to create directory", a
    dangling link in "[Errno 17] File exists", both exit 1. Each is the user's: one `error:` line saying what
    to do, exit 2, the file, link or venv untouched."""
    import shutil
    import subprocess
    import sys

    for name in ("setup_env.sh", "tools", "ch37"):
        (shutil.copytree if name != "setup_env.sh" else shutil.copy)(ROOT / name, tmp_path / name)
    shutil.copy(ROOT / "requirements.lock", tmp_path / "requirements.lock")
    venv = tmp_path / ".venv"
    if kind == "file":
        venv.write_text("my notes\n")
    elif kind == "dangling link":
        venv.symlink_to(tmp_path / "gone")
    else:  # a real 3.11 where the machine has one (this image does), else a venv whose config says 3.11
        py311 = shutil.which("python3.11")
        if py311 and subprocess.run([py311, "-m", "venv", "--without-pip", venv]).returncode == 0:
            pass
        else:
            subprocess.run([sys.executable, "-m", "venv", "--without-pip", venv], check=True)
            cfg = venv / "pyvenv.cfg"
            cfg.write_text(cfg.read_text().replace("version = 3.12", "version = 3.11"))

    def state():
        if venv.is_symlink():
            return ("link", os.readlink(venv))
        if venv.is_file():
            return ("file", venv.read_bytes())
        return sorted((str(p), p.is_symlink() or p.read_bytes()) for p in venv.rglob("*") if not p.is_dir())

    before = state()
    base = Path(sys._base_executable).parent
    env = {"PATH": f"{base}:/usr/bin:/bin", "HOME": str(tmp_path), "PIP_NO_INDEX": "1"}
    code, out = _set_up(tmp_path, env)
    lines = out.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: .venv "), out
    assert "run again" in lines[0] and state() == before


def test_a_timing_names_the_versions_its_imports_load_also_from_pythonpath(tmp_path):
    """The GPU check carries wheels on PYTHONPATH (tools/gpu_check.sh): a wallclock.csv row must still name
    mujoco's and lerobot's versions. A distribution found only on PYTHONPATH, ahead of .venv's, wins."""
    info = tmp_path / "mujoco-9.9.9.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: mujoco\nVersion: 9.9.9\n")
    code = "import json; from tools.lock import ran_versions; print(json.dumps(ran_versions()))"
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    p = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    got = json.loads(p.stdout)
    assert got["mujoco"] == "9.9.9"
    assert got["torch"] == lock.locked_here()["torch"] and got["lerobot"] == lock.locked_here()["lerobot"]
