"""Time the default run here and write this tier's row of wallclock.csv (on a CPU: this CPU model's).

    python -m tools.wallclock              time `scale_data.py --seed 0` cold, write this tier's row
    python -m tools.wallclock --dry-run    print the row, write nothing
    python -m tools.wallclock --smoke      time the --smoke run instead (printed only, never written)
    python -m tools.wallclock --tier t4    name the tier instead of reading it from the device

The run is cold (a fresh output folder, demos generated, the result cache off). The row's tier is the
one the banner of scale_data.py reads its expected wall-clock from (ch37.cli.device_tier): on a CPU
named from the machine, cpu-<cores>core-<vendor> (cpu-2core-amd, cpu-8core-intel), one row per kind of
machine and CPU model measured (its `cpu`: a Zen 3 and a Zen 4 are both cpu-2core-amd and differ twofold);
mps and the GPUs (ch37.cli.TIERS) keep a pending row until measured. config_hash
is ch37.cli.config_hash: the first 12 hex of sha256 over the run's config without the device, workers,
cache and rerun, so the same configuration hashes the same on every tier; the banner shows a row's
minutes only to a run of that configuration. python, torch, numpy, mujoco and lerobot are the versions
the timed run ran on (installed from requirements.lock; a warning when .venv differs from it).

Exit codes: 0 ok, 2 bad input (bad flags, a failed run, a malformed wallclock.csv).
"""

from __future__ import annotations

import csv
import datetime
import io
import json
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ch37 import CHAPTER_ID, ROOT, errors
from ch37.cli import TIERS, config_hash, device_tier, this_cpu
from ch37.config import CHAPTER
from ch37.errors import DataError
from ch37.ownership import write_atomic
from tools.common import WALLCLOCK, in_fresh_process, parser, rel, supports_flag
from tools.lock import drift, ran_versions

# the versions the timed run ran on (tools.lock; setup_env.sh installs them from requirements.lock); rows
# measured before they were recorded leave them empty
VERSION_FIELDS = ("python", "torch", "numpy", "mujoco", "lerobot")
# step_ms: ch37.cli.step_probe on the machine that measured the row, just before the timed run: the banner
# scales the row's minutes to another machine by the two probes (rows measured before it leave it empty)
# cpu: ch37.cli.cpu_model of the machine that measured a CPU row: the banner shows that row as it ran to a run
# on the same CPU model and scales it by the probes for any other (rows measured before it leave it empty)
WALLCLOCK_FIELDS = (
    "chapter",
    "tier",
    "minutes",
    "config_hash",
    "date",
    "status",
    "step_ms",
    "cpu",
    *VERSION_FIELDS,
)
OPTIONAL_FIELDS = ("step_ms", "cpu", *VERSION_FIELDS)


def _pending(tier: str) -> dict:
    return dict.fromkeys(WALLCLOCK_FIELDS, "") | dict(chapter=CHAPTER_ID, tier=tier, status="pending")


def read_wallclock(path: Path) -> list[dict]:
    """The rows of wallclock.csv, plus a pending row for every tier it lacks."""
    path = Path(path)
    if not path.exists():
        return [_pending(t) for t in TIERS]
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and not set(WALLCLOCK_FIELDS) - set(OPTIONAL_FIELDS) <= set(rows[0]) <= set(WALLCLOCK_FIELDS):
        raise DataError(f"{rel(path)}: columns must be {','.join(WALLCLOCK_FIELDS)}")
    rows = [dict.fromkeys(OPTIONAL_FIELDS, "") | r for r in rows]  # a file from before the later columns
    have = {r["tier"] for r in rows}
    return rows + [_pending(t) for t in TIERS if t not in have]


def write_wallclock_row(path: Path, row: dict) -> list[dict]:
    """Replace (or add) the row of row['tier'] and row['cpu'] (a CPU tier keeps a row per CPU model); keep
    every other row; CPU tiers first (by name, then CPU model), then the fixed tiers in order, then any
    other."""
    key = (row["tier"], row.get("cpu", ""))
    rows = [r for r in read_wallclock(path) if (r["tier"], r["cpu"]) != key] + [dict(row)]
    order = {t: i for i, t in enumerate(TIERS)}
    rows.sort(
        key=lambda r: (
            not r["tier"].startswith("cpu-"),
            order.get(r["tier"], len(TIERS)),
            r["tier"],
            r.get("cpu", ""),
        )
    )
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=WALLCLOCK_FIELDS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: r.get(k, "") for k in WALLCLOCK_FIELDS} for r in rows)
    write_atomic(Path(path), buf.getvalue())
    return rows


def measure_wallclock(script: Path, smoke: bool, tier: str | None) -> dict:
    """Run the chapter cold once and return its wallclock.csv row (tier from the device it used)."""
    probe = step_ms(CHAPTER.hidden_dim, CHAPTER.batch_size) if not smoke else None
    with tempfile.TemporaryDirectory(prefix="ch37-wallclock-") as tmp:  # cold: demos made, as on a first run
        cmd = [sys.executable, str(script), "--seed", "0", "--no-rerun", "--out", tmp, *(["--smoke"] * smoke)]
        cmd += ["--no-cache"] if supports_flag(script, "--cache") else []  # time the work, never a replay
        print(f"timing: {shlex.join(cmd)}", flush=True)
        t0 = time.perf_counter()
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            tail = "\n".join((p.stdout + p.stderr).strip().splitlines()[-15:])
            raise DataError(f"the timed run exited {p.returncode}:\n{tail}")
        config = json.loads((Path(tmp) / "metrics.json").read_text())["config"]
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
    row = _pending(tier or device_tier(config["device"])) | {"minutes": f"{wall / 60:.2f}", "date": date}
    if off := drift():
        print(f"warning: .venv differs from requirements.lock ({'; '.join(off[:3])})", file=sys.stderr)
    row |= {
        "config_hash": config_hash(config),
        "status": "measured",
        "step_ms": f"{probe:.2f}" if probe else "",
        "cpu": this_cpu() if config["device"] == "cpu" else "",
    }
    return row | ran_versions(VERSION_FIELDS)


# the probe as the banner runs it: in a new process, on the kernel path scale_data.py's setup region sets
PROBE = """
import json, os, sys
from ch37 import cli
os.environ.update(cli.kernel_path())
print(json.dumps({"ms": cli.step_probe(int(sys.argv[1]), int(sys.argv[2]))}))
"""


def step_ms(hidden: int, batch: int) -> float:
    """ch37.cli.step_probe at these shapes, in a new Python on the published kernel path (as the banner)."""
    return in_fresh_process(PROBE, [hidden, batch], what="the step probe")["ms"]


def main(argv: list[str]) -> int:
    p = parser("wallclock", __doc__)
    p.add_argument("--dry-run", action="store_true", help="print the row, write nothing")
    p.add_argument("--smoke", action="store_true", help="time the --smoke run (printed only, never written)")
    p.add_argument(
        "--tier",
        help=f"default: the tier of the device the run used (on this CPU {device_tier('cpu')}); "
        f"fixed ones: {', '.join(TIERS)}",
    )
    p.add_argument("--csv", type=Path, default=WALLCLOCK, help="default wallclock.csv")
    a = p.parse_args(argv)
    row = measure_wallclock(a.script, a.smoke, a.tier)
    if a.smoke:
        row["status"] = "smoke"  # printed for the record, never written
    print(",".join(WALLCLOCK_FIELDS))
    print(",".join(row[k] for k in WALLCLOCK_FIELDS))
    if a.smoke or a.dry_run:
        print(f"not written ({'a smoke time never goes into wallclock.csv' if a.smoke else '--dry-run'})")
        return 0
    write_wallclock_row(a.csv, row)
    print(f"wrote the {row['tier']} row{f' of {cpu}' if (cpu := row['cpu']) else ''} of {rel(a.csv)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
