"""Run scale_data.py over seeds or over aug_per_demo values and tabulate what it measured.

    python -m tools.sweep --seeds 3 [FLAGS]     seeds 0..2 -> outputs/sweep/sweep_seeds.json
    python -m tools.sweep --aug 0 4 8 [FLAGS]   seed 0 at aug_per_demo 0, 4, 8 -> outputs/sweep/sweep_aug.json

FLAGS go to scale_data.py unchanged (for example --smoke, --epochs 200); the sweep owns --seed,
--out and --rerun. A --smoke sweep writes under outputs/sweep-smoke/ so it can never replace a real
sweep, and `python -m tools.meta` marks what it derives from a smoke sweep `provisional: true`.

Exit codes: 0 ok, 2 bad input (bad flags, a run that failed).
"""

from __future__ import annotations

import json
import math
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

from ch37 import ROOT
from ch37.files import write_atomic
from exercises.rules import PLATEAU_TOL, ex3_answer
from tools.common import ToolError, _rel, parser, provenance, run_cli

SWEEP_OWNED = {"--seed", "--out", "--rerun", "--no-rerun"}
MEAN_KEYS = ("source", "augmented", "compute_matched", "delta", "yield", "kept", "coverage_union")


def _seed_demo_cache(root: Path, target: Path, seed: int) -> None:
    """Copy this seed's source demo sets already generated in this sweep into `target` (same name, same
    request; scale_data.py still checks each set's stamp and rebuilds a stale one)."""
    dst = target / "demos"
    for d in sorted(root.glob(f"*/*/demos/*_seed{seed}_*")):
        if d.is_dir() and "_aug_" not in d.name and not (dst / d.name).exists() and d.parent.parent != target:
            dst.mkdir(parents=True, exist_ok=True)
            shutil.copytree(d, dst / d.name)


def run_one(script: Path, out: Path, seed: int, flags: list[str], root: Path) -> dict:
    """One scale_data.py run into `out` (its output kept in run.log); its metrics.json plus _wall_s."""
    out.mkdir(parents=True, exist_ok=True)
    _seed_demo_cache(root, out, seed)
    cmd = [sys.executable, str(script), "--seed", str(seed), "--no-rerun", "--out", str(out), *flags]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    write_atomic(out / "run.log", f"$ {shlex.join(cmd)}\n{p.stdout}\n--- stderr ---\n{p.stderr}")
    if p.returncode != 0:
        tail = "\n".join((p.stdout + p.stderr).strip().splitlines()[-15:])
        raise ToolError(
            f"{shlex.join(cmd)} exited {p.returncode}; last lines:\n{tail}\n(full log: {out / 'run.log'})"
        )
    metrics = json.loads((out / "metrics.json").read_text())
    metrics["_wall_s"] = round(time.perf_counter() - t0, 1)
    return metrics


def row_of(m: dict, **extra) -> dict:
    a = m["arms"]
    return {
        **extra,
        "source": a["source"]["success"],
        "augmented": a["augmented"]["success"],
        "compute_matched": a["compute_matched"]["success"],
        "delta": round(m["scale_effect"], 6),
        "yield": m["yield"],
        "kept": m["kept"],
        "attempts": m["attempts"],
        "coverage_source": m["coverage"]["source"],
        "coverage_union": m["coverage"]["union"],
        "ci95": {k: a[k]["ci95"] for k in ("source", "augmented", "compute_matched")},
        "wall_s": m["_wall_s"],
    }


def mean_row(rows: list[dict]) -> dict:
    return {k: round(sum(r[k] for r in rows) / len(rows), 6) for k in MEAN_KEYS}


def paired(rows: list[dict]) -> dict:
    """Augmented vs source on the same seed: wins, mean paired delta, its sample std and sem."""
    d = [r["augmented"] - r["source"] for r in rows]
    n = len(d)
    mean = sum(d) / n
    std = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1)) if n > 1 else None
    return {
        "n": n,
        "wins": sum(x > 0 for x in d),
        "ties": sum(x == 0 for x in d),
        "losses": sum(x < 0 for x in d),
        "mean_delta": round(mean, 6),
        "std_delta": None if std is None else round(std, 6),
        "sem_delta": None if std is None else round(std / math.sqrt(n), 6),
    }


def format_table(rows: list[dict], key: str, mean: dict | None = None) -> str:
    cols = (
        f"{'source':>7s} {'augmented':>9s} {'compute-matched':>15s} {'delta':>7s} {'yield':>6s} {'kept':>5s}"
    )
    out = [f"{key:>12s} {cols} {'coverage':>12s}"]
    for r in rows + ([dict(mean, **{key: "mean"})] if mean else []):
        if "coverage_source" in r:
            cov = f"{r['coverage_source']} -> {r['coverage_union']}"
        else:
            cov = f"union {r['coverage_union']:.1f}"
        kept = f"{r['kept']:5d}" if isinstance(r["kept"], int) else f"{r['kept']:5.1f}"
        out.append(
            f"{r[key]!s:>12s} {r['source']:7.3f} {r['augmented']:9.3f} {r['compute_matched']:15.3f} "
            f"{r['delta']:+7.3f} {r['yield']:6.3f} {kept} {cov:>12s}"
        )
    return "\n".join(out)


def _print_summary(result: dict, rows: list[dict], kind: str) -> None:
    print()
    print(format_table(rows, "seed" if kind == "seeds" else "aug_per_demo", result.get("mean")))
    if kind == "seeds":
        pr = result["paired"]
        std = "n/a" if pr["std_delta"] is None else f"{pr['std_delta']:.3f}"
        sem = "n/a" if pr["sem_delta"] is None else f"{pr['sem_delta']:.3f}"
        print(
            f"paired: augmented beat source on {pr['wins']} of {pr['n']} seeds (ties {pr['ties']}, losses "
            f"{pr['losses']}); mean paired delta {pr['mean_delta']:+.3f}, std {std}, sem {sem}"
        )
    else:
        s = {r["aug_per_demo"]: r["augmented"] for r in rows}
        if sorted(s) == [0, 4, 8]:
            print(f"curve 0 -> 4 -> 8: {ex3_answer(s[0], s[4], s[8])} (plateau_tol {PLATEAU_TOL})")


def sweep(
    *,
    seeds: int | None,
    aug: list[int] | None,
    flags: list[str],
    out_root: Path | None,
    script: Path,
    argv: list[str],
) -> Path:
    """Run the sweep, write sweep_seeds.json or sweep_aug.json under `out_root`, print its table."""
    bad = sorted({f.split("=")[0] for f in flags} & SWEEP_OWNED)
    if bad:
        raise ToolError(f"{', '.join(bad)}: the sweep sets these itself (use --seeds/--aug and --out-root)")
    smoke = "--smoke" in flags
    out_root = Path(out_root or ("outputs/sweep-smoke" if smoke else "outputs/sweep"))
    if not out_root.is_absolute():
        out_root = ROOT / out_root
    prov = provenance(script)
    if seeds is not None:
        kind, runs = "seeds", [(s, [], f"seed{s}", {"seed": s}) for s in range(seeds)]
    else:
        kind, runs = "aug", [(0, ["--aug_per_demo", str(k)], f"aug{k}", {"aug_per_demo": k}) for k in aug]
    rows, metrics = [], []
    for seed, extra, name, label in runs:
        print(f"sweep {kind}: {name} ...", end="", flush=True)
        m = run_one(script, out_root / kind / name, seed, flags + extra, out_root)
        print(
            f" done ({m['_wall_s']:.0f} s): source {m['arms']['source']['success']:.2f} "
            f"augmented {m['arms']['augmented']['success']:.2f}",
            flush=True,
        )
        effective = {}
        if kind == "aug":
            effective = {"effective_aug_per_demo": m["config"]["aug_per_demo"]}
            if m["config"]["aug_per_demo"] != label["aug_per_demo"]:
                print(
                    f"  warning: the run used aug_per_demo {m['config']['aug_per_demo']} (--smoke pins it), "
                    f"not {label['aug_per_demo']}",
                    file=sys.stderr,
                )
        rows.append(row_of(m, **label, **effective))
        metrics.append(m)
    varied = {"seed", "aug_per_demo"} if kind == "aug" else {"seed"}  # what changes from run to run
    config = {k: v for k, v in metrics[0]["config"].items() if k not in varied}
    runs_command = [
        "python",
        "scale_data.py",
        "--seed",
        "{seed}",
        "--no-rerun",
        "--out",
        str(out_root / kind / "{run}"),
    ]
    runs_command += [*flags] + (["--aug_per_demo", "{k}"] if kind == "aug" else [])
    result = {
        "kind": kind,
        "smoke": smoke,
        "command": shlex.join(["python", "-m", "tools.sweep", *argv]),
        "runs_command": shlex.join(runs_command),
        **prov,
        "device": metrics[0]["config"].get("device"),
        "config": config,
        "action_dims": metrics[0]["action_dims"],
        "padded_action_dim": metrics[0]["padded_action_dim"],
        "rows": rows,
    }
    if kind == "seeds":
        result["mean"] = mean_row(rows)
        result["paired"] = paired(rows)
    else:
        result["seed"] = 0
    path = out_root / f"sweep_{kind}.json"
    write_atomic(path, json.dumps(result, indent=1, sort_keys=False) + "\n")
    _print_summary(result, rows, kind)
    if smoke:
        print("smoke sweep: numbers exercise the pipeline only")
    print(f"wrote {_rel(path)}")
    return path


def main(argv: list[str] | None = None) -> int:
    argv = list(argv or [])
    p = parser("sweep", __doc__)
    p.add_argument("--seeds", type=int, help="run seeds 0..N-1")
    p.add_argument("--aug", type=int, nargs="+", help="run seed 0 at these aug_per_demo values (ex3: 0 4 8)")
    p.add_argument("--out-root", type=Path, help="default outputs/sweep (outputs/sweep-smoke with --smoke)")
    a, flags = p.parse_known_args(argv)
    if (a.seeds is None) == (a.aug is None):
        raise ToolError("give exactly one of --seeds N or --aug K [K ...]")
    if a.seeds is not None and a.seeds < 1:
        raise ToolError("--seeds must be >= 1")
    if a.aug is not None and (not a.aug or min(a.aug) < 0):
        raise ToolError("--aug needs one or more values >= 0")
    sweep(seeds=a.seeds, aug=a.aug, flags=flags, out_root=a.out_root, script=a.script, argv=argv)
    return 0


if __name__ == "__main__":
    run_cli(main)
