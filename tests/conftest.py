import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
# scale_data.py's result cache: one private folder per test session, never the user's outputs/
os.environ.setdefault("CH37_CACHE_DIR", tempfile.mkdtemp(prefix="ch37-cache-"))


def run_script(*args, cwd=ROOT, check=True, timeout=600):
    """Run a project script with this interpreter; returns the CompletedProcess (text)."""
    env = dict(os.environ, PYTHONHASHSEED="0")
    p = subprocess.run(
        [sys.executable, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )
    if check and p.returncode != 0:
        raise AssertionError(f"{args} exited {p.returncode}\nstdout:\n{p.stdout}\nstderr:\n{p.stderr}")
    return p


@pytest.fixture(scope="session")
def root():
    return ROOT
