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
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

from ch37 import ROOT, errors
from ch37.config import check
from ch37.errors import DataError
from ch37.ownership import write_atomic
from exercises.rules import ARMS, EFFECTS, ex3_answer, step_interval
from tools.common import mean_ci, parser, provenance, rel

SWEEP_OWNED = {"--seed", "--out", "--rerun", "--no-rerun"}
MEAN_KEYS = (*ARMS, *EFFECTS, "yield", "kept", "coverage_union")


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
        raise DataError(
            f"{shlex.join(cmd)} exited {p.returncode}; last lines:\n{tail}\n(full log: {out}/run.log)"
        )
    return json.loads((out / "metrics.json").read_text()) | {"_wall_s": round(time.perf_counter() - t0, 1)}


def row_of(m: dict, **extra) -> dict:
    """One run's 2x2 as a sweep row: each arm's success, the effects, steps per budget, episodes."""
    a, n = m["arms"], m["config"]["eval_episodes"]
    row = extra | {arm: a[arm]["success"] for arm in ARMS} | {e: round(m["effects"][e], 6) for e in EFFECTS}
    row["delta"] = round(m["scale_effect"], 6)  # the headline: data effect at the full budget
    row |= {"steps": m["budgets"], "eval_episodes": n}
    row["successes"] = {k: round(a[k]["success"] * n) for k in ARMS}
    row |= {k: m[k] for k in ("yield", "kept", "attempts")}
    row |= {"coverage_source": m["coverage"]["source"], "coverage_union": m["coverage"]["union"]}
    return row | {"ci95": {arm: a[arm]["ci95"] for arm in ARMS}, "wall_s": m["_wall_s"]}


def mean_row(rows: list[dict]) -> dict:
    return {k: round(sum(r[k] for r in rows) / len(rows), 6) for k in MEAN_KEYS}


def paired(rows: list[dict]) -> dict:
    """Per effect (data at each budget, compute per data set), the seeds' paired differences: wins,
    ties, losses, mean, sample std, and a 95% t-interval over seeds (None with one seed)."""
    out = {}
    for key in EFFECTS:
        d = [r[key] for r in rows]
        mean, std, ci = mean_ci(d)
        out[key] = {"n": len(d), "wins": sum(x > 0 for x in d), "ties": sum(x == 0 for x in d)}
        out[key] |= {"losses": sum(x < 0 for x in d), "mean": round(mean, 6)}
        out[key]["std"] = None if std is None else round(std, 6)
        out[key]["ci95"] = None if ci is None else [round(x, 6) for x in ci]
    return out


def pooled(rows: list[dict]) -> dict:
    """Each arm's successes over all seeds' evaluation episodes, with a Wilson 95% interval."""
    from bc_recipe import wilson  # here, not at the top: it loads torch, which the sweep itself never needs

    n = sum(r["eval_episodes"] for r in rows)
    out = {}
    for arm in ARMS:
        k = sum(r["successes"][arm] for r in rows)
        ci = [round(v, 6) for v in wilson(k / n, n)]
        out[arm] = {"successes": k, "episodes": n, "success": round(k / n, 6), "ci95": ci}
    return out


def format_table(rows: list[dict], key: str, mean: dict | None = None) -> str:
    head = " ".join(f"{a:>15s}" for a in ARMS)
    cols = f"{'data@full':>9s} {'data@short':>10s} {'yield':>6s} {'kept':>5s} {'coverage':>10s}"
    out = [f"{key:>12s} {head} {cols}"]
    for r in rows + ([dict(mean, **{key: "mean"})] if mean else []):
        run = "coverage_source" in r  # a run's row, not the mean
        cov = f"{r['coverage_source']} -> {r['coverage_union']}" if run else f"{r['coverage_union']:.1f}"
        kept = f"{r['kept']:5d}" if isinstance(r["kept"], int) else f"{r['kept']:5.1f}"
        cells = " ".join(f"{r[a]:15.3f}" for a in ARMS)
        data = f"{r['data_full']:+9.3f} {r['data_short']:+10.3f} {r['yield']:6.3f}"
        out.append(f"{r[key]!s:>12s} {cells} {data} {kept} {cov:>10s}")
    return "\n".join(out)


def _print_summary(result: dict, rows: list[dict], kind: str) -> None:
    steps = rows[0]["steps"]
    print(f"\nsteps per arm: short {steps['short']}, full {steps['full']}" + " (seed 0)" * (kind == "seeds"))
    print(format_table(rows, "seed" if kind == "seeds" else "aug_per_demo", result.get("mean")))
    if kind == "seeds":
        for key, pr in result["paired"].items():
            ci = "n/a" if pr["ci95"] is None else f"[{pr['ci95'][0]:+.3f}, {pr['ci95'][1]:+.3f}]"
            seeds = f"> 0 on {pr['wins']} of {pr['n']} seeds (ties {pr['ties']}, losses {pr['losses']})"
            print(f"paired {key}: {seeds}; mean {pr['mean']:+.3f}, 95% interval over seeds {ci}")
        for arm, pl in result["pooled"].items():
            ci = f"[{pl['ci95'][0]:.3f}, {pl['ci95'][1]:.3f}]"
            print(f"pooled {arm}: {pl['successes']}/{pl['episodes']} = {pl['success']:.3f} {ci}")
        return
    s = {r["aug_per_demo"]: (r["augmented_full"], r["ci95"]["augmented_full"]) for r in rows}
    if sorted(s) == [0, 4, 8]:  # read as ex3 reads a learner's curve: each step against its 95% interval
        curve = ex3_answer([step_interval(*s[a], *s[b]) for a, b in ((0, 4), (4, 8))])
        print(f"curve 0 -> 4 -> 8 at {steps['full']} steps each, one seed: {curve}")


def run_all(kind: str, runs: list, script: Path, out_root: Path, flags: list[str]) -> tuple[list, list]:
    """Each run (seed, extra flags, run folder name, row label) in turn: (sweep rows, their metrics)."""
    rows, metrics, full_steps = [], [], []
    for seed, extra, name, label in runs:
        print(f"sweep {kind}: {name} ...", end="", flush=True)
        m = run_one(script, out_root / kind / name, seed, flags + extra + full_steps, out_root)
        if kind == "aug" and not full_steps:
            full_steps = ["--full_steps", str(m["budgets"]["full"])]
        a, steps = m["arms"], m["budgets"]["full"]
        got = f"source {a['source_full']['success']:.2f} augmented {a['augmented_full']['success']:.2f}"
        print(f" done ({m['_wall_s']:.0f} s): at {steps} steps {got}", flush=True)
        if kind == "aug":
            k, wanted = m["config"]["aug_per_demo"], label["aug_per_demo"]
            label = label | {"effective_aug_per_demo": k}
            if k != wanted:
                warning = f"  warning: the run used aug_per_demo {k} (--smoke pins it), not {wanted}"
                print(warning, file=sys.stderr)
        rows.append(row_of(m, **label))
        metrics.append(m)
    if kind == "aug":
        rows.sort(key=lambda r: r["aug_per_demo"])
    return rows, metrics


def sweep(a, flags: list[str], argv: list[str]) -> Path:
    """Run the sweep of the parsed flags `a` (`flags` go to every run), write and print its table."""
    if bad := sorted({f.split("=")[0] for f in flags} & SWEEP_OWNED):
        raise DataError(f"{', '.join(bad)}: the sweep sets these itself (use --seeds/--aug and --out-root)")
    smoke = "--smoke" in flags
    out_root = ROOT / (a.out_root or ("outputs/sweep-smoke" if smoke else "outputs/sweep"))
    prov = provenance(a.script)
    if a.seeds is not None:
        kind, runs = "seeds", [(s, [], f"seed{s}", {"seed": s}) for s in range(a.seeds)]
    else:
        order = sorted(a.aug, reverse=True)  # the largest k first: the others train for its full budget
        kind, runs = "aug", [(0, ["--aug_per_demo", str(k)], f"aug{k}", {"aug_per_demo": k}) for k in order]
    rows, metrics = run_all(kind, runs, a.script, out_root, flags)
    varied = {"seed", "aug_per_demo", "full_steps"} if kind == "aug" else {"seed"}  # from run to run
    each = ["--aug_per_demo", "{k}", "[--full_steps {full}]"] if kind == "aug" else []
    runs_out = str(out_root / kind / "{run}")
    runs_command = [*"python scale_data.py --seed {seed} --no-rerun --out".split(), runs_out, *flags, *each]
    first = metrics[0]
    result = {"kind": kind, "smoke": smoke, "command": shlex.join(["python", "-m", "tools.sweep", *argv])}
    result |= {"runs_command": shlex.join(runs_command), **prov, "device": first["config"].get("device")}
    result["config"] = {k: v for k, v in first["config"].items() if k not in varied}
    result |= {k: first[k] for k in ("action_dims", "padded_action_dim")} | {"rows": rows}
    if kind == "seeds":
        result |= {"mean": mean_row(rows), "paired": paired(rows), "pooled": pooled(rows)}
    else:
        result |= {"seed": 0, "full_steps": rows[-1]["steps"]["full"]}
    path = out_root / f"sweep_{kind}.json"
    # not ownership.dump_json: its sorted keys would reorder the rows that tools.meta copies into meta.yaml
    write_atomic(path, json.dumps(result, indent=1) + "\n")
    _print_summary(result, rows, kind)
    if smoke:
        print("smoke sweep: numbers exercise the pipeline only")
    print(f"wrote {rel(path)}")
    return path


def main(argv: list[str]) -> int:
    p = parser("sweep", __doc__)
    p.add_argument("--seeds", type=int, help="run seeds 0..N-1")
    p.add_argument("--aug", type=int, nargs="+", help="run seed 0 at these aug_per_demo values (ex3: 0 4 8)")
    p.add_argument("--out-root", type=Path, help="default outputs/sweep (outputs/sweep-smoke with --smoke)")
    a, flags = p.parse_known_args(argv)
    if (a.seeds is None) == (a.aug is None):
        raise DataError("give exactly one of --seeds N or --aug K [K ...]")
    if a.seeds is not None:
        check(a, positive=["seeds"])
    if a.aug is not None and (not a.aug or min(a.aug) < 0):
        raise DataError("--aug needs one or more values >= 0")
    sweep(a, flags, argv)
    return 0


if __name__ == "__main__":
    errors.main(main)
