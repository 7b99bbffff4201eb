"""requirements.lock (tools/lock.py): .venv is exactly the lock, the lock covers pyproject.toml, and
meta.yaml records the lock its numbers ran on."""

import tomllib

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
