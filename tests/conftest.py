import json
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
# headless rendering in this process (tests/test_gym_envs.py): mujoco picks its GL backend when first
# imported, which a test module's imports do before ours could choose (EGL, the demo generators' choice)
if sys.platform.startswith("linux"):
    os.environ.setdefault("MUJOCO_GL", "egl")
# Nothing may download: the Hugging Face switches (lerobot_v3.OFFLINE_ENV; the chapter's own code never
# sets them, lerobot_v3.hub_offline makes its process offline). Tests that import lerobot themselves
# (test_lerobot, test_merge, test_writer) may do it before the chapter's first LeRobot call (which would
# then refuse): offline for the whole session, and given explicitly to every script run_script starts
# (lerobot-train is LeRobot's program, not ours: only its environment keeps it off the Hub).
OFFLINE_ENV = {"HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1"}
os.environ.update(OFFLINE_ENV)


def run_script(*args, cwd=ROOT, check=True, timeout=600):
    """Run a project script (or LeRobot's lerobot-train) with this interpreter, offline (OFFLINE_ENV);
    returns the CompletedProcess (text)."""
    env = dict(os.environ, **OFFLINE_ENV, PYTHONHASHSEED="0")
    p = subprocess.run(
        [sys.executable, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env
    )
    if check and p.returncode != 0:
        raise AssertionError(f"{args} exited {p.returncode}\nstdout:\n{p.stdout}\nstderr:\n{p.stderr}")
    return p


@pytest.fixture(scope="session")
def root():
    return ROOT


def with_nan(root: Path, key: str = "action", row: int = 3) -> Path:
    """Put a NaN into `key` at `row` of the set's first data parquet, schema and metadata kept."""
    return with_value(root, key, row, 0, float("nan"))


def with_value(root: Path, key: str, row: int, col: int, value: float) -> Path:
    """Set `key`[row][col] (a scalar column: `key`[row]) of the set's first data parquet to `value`, schema
    and metadata kept."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    f = sorted((root / "data").rglob("*.parquet"))[0]
    t = pq.read_table(f)
    values = t[key].to_pylist()
    if isinstance(values[row], list):
        values[row][col] = value
    else:
        values[row] = value
    i = t.schema.get_field_index(key)
    pq.write_table(t.set_column(i, t.schema.field(key), pa.array(values, t.schema.field(key).type)), f)
    return root


def with_fps(root: Path, fps: int) -> Path:
    """Record a different frame rate in the set's meta/info.json (its frames unchanged)."""
    info = json.loads((root / "meta" / "info.json").read_text())
    (root / "meta" / "info.json").write_text(json.dumps(dict(info, fps=fps), indent=4))
    return root
