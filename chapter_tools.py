"""Course packaging for chapter 3.7 (plumbing, not the lesson): regions, sweeps, meta.yaml, wall-clock, notebook.

    python chapter_tools.py regions                      each region of scale_data.py: name, lines, sha256
    python chapter_tools.py hashes --check               exit 1 naming every region that drifted from meta.yaml
    python chapter_tools.py hashes --write               refresh meta.yaml's region_hashes (nothing else)
    python chapter_tools.py sweep --seeds 3 [FLAGS]      scale_data.py at seeds 0..2 -> outputs/sweep/sweep_seeds.json
    python chapter_tools.py sweep --aug 0 4 8 [FLAGS]    seed 0 at aug_per_demo 0, 4, 8 -> outputs/sweep/sweep_aug.json
    python chapter_tools.py meta                         reference_run + exercise_checks + region_hashes -> meta.yaml
    python chapter_tools.py wallclock [--dry-run]        time the default run here, write this tier's wallclock.csv row
    python chapter_tools.py notebook [--check]           scale_data.ipynb from the regions (--check: exit 1 if stale)

FLAGS after `sweep` go to scale_data.py unchanged (for example --smoke, --epochs 200); the sweep owns
--seed, --out and --rerun. A --smoke sweep writes under outputs/sweep-smoke/ so it can never replace a
real sweep, and `meta` marks what it derives from a smoke sweep `provisional: true`.

Region hash: sha256 (hex) of the region's body, that is the lines strictly between its
`# --- region: NAME ---` and `# --- endregion ---` markers, each line ending in "\\n", UTF-8.
Markers are excluded (the name is the key; the parser enforces the order).

Exit codes: 0 ok, 1 a check failed (drift, stale notebook), 2 bad input (malformed markers, bad flags).
"""
from __future__ import annotations

import argparse
import ast
import csv
import datetime
import hashlib
import importlib.metadata
import io as _io
import json
import math
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent
SCRIPT = ROOT / "scale_data.py"
META = ROOT / "meta.yaml"
WALLCLOCK = ROOT / "wallclock.csv"
NOTEBOOK = ROOT / "scale_data.ipynb"
CHAPTER_ID = "ch3.7-scale-data"
REGION_ORDER = ("setup", "wrangle", "augment", "measure", "emit")


class ToolError(Exception):
    """Bad input: reported as one `error:` line and exit code 2."""


class RegionError(ToolError):
    pass


# ----------------------------------------------------------------------------------------------
# Regions
# ----------------------------------------------------------------------------------------------
OPEN_RE = re.compile(r"# --- region: (\S+) ---")
CLOSE = "# --- endregion ---"
MARKERISH = re.compile(r"^\s*#\s*-{2,}\s*(end\s*)?region\b", re.IGNORECASE)  # anything that tries to be a marker


@dataclass(frozen=True)
class Region:
    name: str
    start: int  # 1-based line of the opening marker
    end: int  # 1-based line of the endregion marker
    body: str  # lines strictly between the markers, each ending in "\n"

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.body.encode("utf-8")).hexdigest()

    @property
    def intent(self) -> list[str]:
        """The comment block that opens the region (its statement of intent), without '# '."""
        out = []
        for line in self.body.splitlines():
            if not line.startswith("#"):
                break
            out.append(line[1:].strip())
        return out

    @property
    def code(self) -> str:
        """The body after the intent comment, blank lines at both ends removed."""
        lines = self.body.splitlines()
        return "\n".join(lines[len(self.intent):]).strip("\n")


def parse_regions(path: Path = SCRIPT, text: str | None = None) -> list[Region]:
    """The five regions of the chapter script, in order; RegionError on any malformed marker layout."""
    path = Path(path)
    text = path.read_text(encoding="utf-8") if text is None else text
    where = path.name
    try:
        tree = ast.parse(text)
    except SyntaxError as e:
        raise RegionError(f"{where}:{e.lineno}: not valid Python ({e.msg})") from None
    doc_lines: set[int] = set()
    if tree.body and isinstance(tree.body[0], ast.Expr) and isinstance(getattr(tree.body[0], "value", None), ast.Constant) \
            and isinstance(tree.body[0].value.value, str):
        doc_lines = set(range(tree.body[0].lineno, tree.body[0].end_lineno + 1))
    lines = text.splitlines()
    regions: list[Region] = []
    seen: set[str] = set()
    open_name, open_line, body = None, 0, []
    for n, raw in enumerate(lines, 1):
        line = raw.rstrip()
        m = OPEN_RE.fullmatch(line)
        if m:
            name = m.group(1)
            if open_name is not None:
                raise RegionError(f"{where}:{n}: region {name!r} opens inside region {open_name!r} "
                                  f"(opened at line {open_line}); regions do not nest, close it with '{CLOSE}' first")
            if name not in REGION_ORDER:
                raise RegionError(f"{where}:{n}: unknown region name {name!r}; the regions are {', '.join(REGION_ORDER)}")
            if name in seen:
                raise RegionError(f"{where}:{n}: duplicate region {name!r}")
            expected = REGION_ORDER[len(regions)]
            if name != expected:
                raise RegionError(f"{where}:{n}: region {name!r} is out of order: expected {expected!r} here "
                                  f"(order: {', '.join(REGION_ORDER)})")
            seen.add(name)
            open_name, open_line, body = name, n, []
        elif line == CLOSE:
            if open_name is None:
                raise RegionError(f"{where}:{n}: '{CLOSE}' without an open region")
            regions.append(Region(open_name, open_line, n, "".join(b + "\n" for b in body)))
            open_name = None
        elif MARKERISH.match(raw):
            raise RegionError(f"{where}:{n}: malformed region marker {raw.strip()!r}; markers are exactly "
                              f"'# --- region: NAME ---' and '{CLOSE}' at column 0")
        elif open_name is not None:
            body.append(raw)
        elif line.strip() and n not in doc_lines and not (n == 1 and line.startswith("#!")):
            raise RegionError(f"{where}:{n}: code outside any region: {line.strip()[:60]!r} "
                              "(only the module docstring may live outside the regions)")
    if open_name is not None:
        raise RegionError(f"{where}:{open_line}: region {open_name!r} has no '{CLOSE}'")
    missing = [r for r in REGION_ORDER if r not in seen]
    if missing:
        raise RegionError(f"{where}: missing region(s) {', '.join(missing)}; the regions are {', '.join(REGION_ORDER)}")
    return regions


def region_hashes(path: Path = SCRIPT) -> dict[str, str]:
    return {r.name: r.sha256 for r in parse_regions(path)}


def drifted(current: dict[str, str], recorded: dict | None) -> list[str]:
    """Region names whose hash differs from (or is missing in) meta.yaml's region_hashes."""
    recorded = recorded or {}
    names = list(current) + [k for k in recorded if k not in current]
    return [k for k in names if current.get(k) != recorded.get(k)]


def module_docstring(path: Path = SCRIPT) -> str:
    return ast.get_docstring(ast.parse(Path(path).read_text(encoding="utf-8"))) or ""


# ----------------------------------------------------------------------------------------------
# meta.yaml
# ----------------------------------------------------------------------------------------------
META_HEADER = """\
# Chapter 3.7 metadata. Written by `python chapter_tools.py meta` (reference_run, exercise_checks,
# region_hashes: never typed by hand) and `python chapter_tools.py hashes --write` (region_hashes only).
# id, title, track, objectives and mimicgen are kept as found here; edit them freely (comments are not kept).
"""

META_STATIC = {
    "id": CHAPTER_ID,
    "title": "Datasets at Scale",
    "track": "robot learning / data",
    "objectives": [
        "Pool demos from two robots (PushT, 2-D actions; a bimanual ALOHA handoff, 6-D actions) into one "
        "cross-embodiment set: per-embodiment normalization, zero-padding to the widest action, and an action "
        "mask that keeps padded dimensions out of the loss.",
        "Say what a shared policy can carry across embodiments (a network, an action head) and what it cannot "
        "(the meaning of a raw state number: index 2 is the block's x in PushT, the right gripper in ALOHA).",
        "Grow the PushT set MimicGen-style: perturb each source start, re-solve it with the same scripted expert "
        "in the real physics, keep only successes, and report the yield.",
        "Measure the data-scale effect: the same behaviour-cloning MLP on source demos alone and on source plus "
        "augmented, with a compute-matched control, rolled out on the same held-out starts.",
    ],
    "mimicgen": {
        "repo": "NVlabs/mimicgen",
        "tag": "v1.0.0",
        "commit": "ea0988523f468ccf7570475f1906023f854962e9",
        "files": [
            {"path": "mimicgen/utils/pose_utils.py", "symbol": "transform_source_data_segment_using_object_pose",
             "why": "how MimicGen moves a source end-effector segment into the new object's frame; this chapter "
                    "re-solves with its expert instead of replaying, because it owns an expert for any start"},
            {"path": "mimicgen/scripts/generate_dataset.py",
             "why": "the generate-execute-keep-only-successes loop and its success_rate = successes / attempts, "
                    "the same bookkeeping as this chapter's yield"},
        ],
    },
}
META_ORDER = ("id", "title", "track", "objectives", "mimicgen", "reference_run", "exercise_checks", "region_hashes")


def load_yaml(path: Path) -> dict:
    import yaml

    path = Path(path)
    if not path.exists():
        return {}
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    if data is not None and not isinstance(data, dict):
        raise ToolError(f"{path} is not a YAML mapping")
    return data or {}


def _yaml_dumper():
    import yaml

    class Dumper(yaml.SafeDumper):
        """Short all-scalar lists and mappings on one line ({n: 3, wins: 3}), everything else in block style."""

    def flow(value) -> bool:
        items = value.values() if isinstance(value, dict) else value
        return all(isinstance(v, (int, float, bool, type(None))) or (isinstance(v, str) and len(v) < 40) for v in items) \
            and len(json.dumps(value)) <= 100

    Dumper.add_representer(dict, lambda d, v: d.represent_mapping("tag:yaml.org,2002:map", v.items(), flow_style=flow(v)))
    Dumper.add_representer(list, lambda d, v: d.represent_sequence("tag:yaml.org,2002:seq", v, flow_style=flow(v)))
    return Dumper


def write_meta(path: Path, meta: dict) -> None:
    import yaml

    ordered = {k: meta[k] for k in META_ORDER if k in meta}
    ordered.update({k: v for k, v in meta.items() if k not in ordered})
    text = META_HEADER + yaml.dump(ordered, Dumper=_yaml_dumper(), sort_keys=False, allow_unicode=True, width=110)
    write_atomic(Path(path), text)


def write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


PLATEAU_TOL = 0.04
BAND_MIN_MARGIN = 0.06


def band_margin(ci95) -> float:
    """Band half-width around a measured success: max(0.06, half of the Wilson 95% half-width)."""
    return max(BAND_MIN_MARGIN, (ci95[1] - ci95[0]) / 4)


def ex1_answer(deltas) -> str:
    """A if augmented beat source on every sweep seed, B if it lost on every seed, else C."""
    deltas = list(deltas)
    if not deltas:
        raise ToolError("ex1: the seed sweep has no rows")
    if all(d > 0 for d in deltas):
        return "A"
    if all(d < 0 for d in deltas):
        return "B"
    return "C"


def ex1_band(answer: str, effect0: float, ci95_aug0) -> dict:
    """A: scale_effect_min = half the seed-0 effect; B: scale_effect_max = half of it (negative);
    C: the seed-0 effect +- band_margin(the seed-0 augmented arm's interval)."""
    if answer == "A":
        return {"scale_effect_min": round(effect0 / 2, 4)}
    if answer == "B":
        return {"scale_effect_max": round(effect0 / 2, 4)}
    m = band_margin(ci95_aug0)
    return {"scale_effect_min": round(effect0 - m, 4), "scale_effect_max": round(effect0 + m, 4)}


def ex3_answer(s0: float, s4: float, s8: float, tol: float = PLATEAU_TOL) -> str:
    """The question is what the curve does at the end (4 -> 8): climb if the last step is above
    +tol, fall if it is below -tol, plateau otherwise; the first step (0 -> 4) is printed, not judged.
    Steps are rounded to 6 decimals first, so a step of exactly tol (0.26 - 0.22) reads as flat."""
    step2 = round(s8 - s4, 6)
    if step2 > tol:
        return "climb"
    if step2 < -tol:
        return "fall"
    return "plateau"


def success_band(success: float, ci95) -> list[float]:
    m = band_margin(ci95)
    return [round(max(0.0, success - m), 4), round(min(1.0, success + m), 4)]


def derive_checks(seeds: dict, aug: dict) -> dict:
    """exercise_checks from a seed sweep and an aug sweep (the JSON files `sweep` writes)."""
    rows = {r["seed"]: r for r in seeds["rows"]}
    if 0 not in rows:
        raise ToolError("the seed sweep must include seed 0 (ex1 and ex3 are run at seed 0)")
    r0 = rows[0]
    answer = ex1_answer(r["delta"] for r in seeds["rows"])
    by_k = {r["aug_per_demo"]: r for r in aug["rows"]}
    if aug.get("seed", 0) != 0:
        raise ToolError("the aug sweep must be at seed 0")
    if sorted(by_k) != [0, 4, 8]:
        raise ToolError(f"the aug sweep must cover aug_per_demo 0, 4, 8; it has {sorted(by_k)}")
    s = {k: by_k[k]["augmented"] for k in (0, 4, 8)}
    dims = seeds["action_dims"]
    return {
        "ex1": {"seed": 0, "answer": answer, "band": ex1_band(answer, r0["delta"], r0["ci95"]["augmented"])},
        "ex2": {"pusht_mask_density": round(dims["pusht"] / seeds["padded_action_dim"], 6)},
        "ex3": {"seed": 0, "aug_per_demo": [0, 4, 8], "answer": ex3_answer(s[0], s[4], s[8]), "plateau_tol": PLATEAU_TOL,
                "band": {str(k): success_band(s[k], by_k[k]["ci95"]["augmented"]) for k in (0, 4, 8)}},
    }


RULES = {
    "ex1_answer": "A if augmented > source on every sweep seed, B if augmented < source on every seed, else C",
    "ex1_band": "A: scale_effect_min = seed-0 effect / 2; B: scale_effect_max = seed-0 effect / 2; "
                "C: seed-0 effect +- max(0.06, Wilson half-width / 2) of the seed-0 augmented arm",
    "ex3_answer": f"steps s4-s0 and s8-s4 of augmented-arm success: climb if both > +{PLATEAU_TOL}, "
                  f"fall if s8-s4 < -{PLATEAU_TOL}, else plateau",
    "ex3_band": "measured success +- max(0.06, Wilson 95% half-width / 2), clipped to [0, 1]",
}


def _public(row: dict) -> dict:
    """A sweep row for meta.yaml: per-run wall time left out (wallclock.csv is the timing of record)."""
    return {k: v for k, v in row.items() if k != "wall_s"}


def reference_run(seeds: dict, aug: dict) -> dict:
    provisional = bool(seeds.get("smoke") or aug.get("smoke"))
    keep = ("command", "date_utc", "git", "platform", "packages", "device", "config", "script_region_hashes")
    return {
        "provisional": provisional,
        "note": ("smoke-sized sweep: exercises the pipeline only; refresh with a full sweep" if provisional else
                 "default configuration; every number below was written by chapter_tools.py from the sweep files"),
        "seeds": {"rows": [_public(r) for r in seeds["rows"]], "mean": seeds["mean"], "paired": seeds["paired"],
                  "provenance": {k: seeds[k] for k in keep if k in seeds}},
        "aug_curve": {"seed": aug.get("seed", 0), "rows": [_public(r) for r in aug["rows"]], "provenance": {k: aug[k] for k in keep if k in aug}},
        "rules": RULES,
    }


# ----------------------------------------------------------------------------------------------
# Sweep
# ----------------------------------------------------------------------------------------------
def provenance(script: Path) -> dict:
    def version(pkg):
        try:
            return importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            return None

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    if not cpu and sys.platform == "darwin":
        try:
            cpu = subprocess.run(["sysctl", "-n", "machdep.cpu.brand_string"], capture_output=True, text=True).stdout.strip()
        except OSError:
            pass
    git = None
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True, text=True)
        if head.returncode == 0:
            git = {"commit": head.stdout.strip(), "dirty": bool(dirty.stdout.strip())}
    except OSError:
        pass
    try:
        hashes = region_hashes(script)
    except RegionError:
        hashes = None
    return {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "git": git,
        "platform": {"python": platform.python_version(), "os": platform.platform(), "machine": platform.machine(),
                     "cpu_count": os.cpu_count(), "cpu_model": cpu},
        "packages": {p: version(p) for p in ("torch", "lerobot", "mujoco", "numpy")},
        "script_region_hashes": hashes,
    }


SWEEP_OWNED = {"--seed", "--out", "--rerun", "--no-rerun"}


def _seed_demo_cache(root: Path, target: Path, seed: int) -> None:
    """Copy this seed's source demo sets already generated in this sweep into `target` (same name, same
    request; scale_data.py still checks each set's stamp and rebuilds a stale one)."""
    dst = target / "demos"
    for d in sorted(root.glob(f"*/*/demos/*_seed{seed}_*")):
        if d.is_dir() and "_aug_" not in d.name and not (dst / d.name).exists() and d.parent.parent != target:
            dst.mkdir(parents=True, exist_ok=True)
            shutil.copytree(d, dst / d.name)


def run_one(script: Path, out: Path, seed: int, flags: list[str], root: Path) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    _seed_demo_cache(root, out, seed)
    cmd = [sys.executable, str(script), "--seed", str(seed), "--no-rerun", "--out", str(out), *flags]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    (out / "run.log").write_text(f"$ {shlex.join(cmd)}\n{p.stdout}\n--- stderr ---\n{p.stderr}")
    if p.returncode != 0:
        tail = "\n".join((p.stdout + p.stderr).strip().splitlines()[-15:])
        raise ToolError(f"{shlex.join(cmd)} exited {p.returncode}; last lines:\n{tail}\n(full log: {out / 'run.log'})")
    metrics = json.loads((out / "metrics.json").read_text())
    metrics["_wall_s"] = round(time.perf_counter() - t0, 1)
    return metrics


def row_of(m: dict, **extra) -> dict:
    a = m["arms"]
    return {**extra,
            "source": a["source"]["success"], "augmented": a["augmented"]["success"],
            "compute_matched": a["compute_matched"]["success"], "delta": round(m["scale_effect"], 6),
            "yield": m["yield"], "kept": m["kept"], "attempts": m["attempts"],
            "coverage_source": m["coverage"]["source"], "coverage_union": m["coverage"]["union"],
            "ci95": {k: a[k]["ci95"] for k in ("source", "augmented", "compute_matched")},
            "wall_s": m["_wall_s"]}


MEAN_KEYS = ("source", "augmented", "compute_matched", "delta", "yield", "kept", "coverage_union")


def mean_row(rows: list[dict]) -> dict:
    return {k: round(sum(r[k] for r in rows) / len(rows), 6) for k in MEAN_KEYS}


def paired(rows: list[dict]) -> dict:
    """Augmented vs source on the same seed: wins, mean paired delta, its sample std and sem."""
    d = [r["augmented"] - r["source"] for r in rows]
    n = len(d)
    mean = sum(d) / n
    std = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1)) if n > 1 else None
    return {"n": n, "wins": sum(x > 0 for x in d), "ties": sum(x == 0 for x in d), "losses": sum(x < 0 for x in d),
            "mean_delta": round(mean, 6), "std_delta": None if std is None else round(std, 6),
            "sem_delta": None if std is None else round(std / math.sqrt(n), 6)}


def format_table(rows: list[dict], key: str, mean: dict | None = None) -> str:
    head = f"{key:>12s} {'source':>7s} {'augmented':>9s} {'compute-matched':>15s} {'delta':>7s} {'yield':>6s} {'kept':>5s} {'coverage':>12s}"
    out = [head]
    for r in rows + ([dict(mean, **{key: "mean"})] if mean else []):
        cov = f"{r['coverage_source']} -> {r['coverage_union']}" if "coverage_source" in r else f"union {r['coverage_union']:.1f}"
        kept = f"{r['kept']:5d}" if isinstance(r["kept"], int) else f"{r['kept']:5.1f}"
        out.append(f"{r[key]!s:>12s} {r['source']:7.3f} {r['augmented']:9.3f} {r['compute_matched']:15.3f} "
                   f"{r['delta']:+7.3f} {r['yield']:6.3f} {kept} {cov:>12s}")
    return "\n".join(out)


def sweep(*, seeds: int | None, aug: list[int] | None, flags: list[str], out_root: Path | None, script: Path,
          argv: list[str]) -> Path:
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
        print(f" done ({m['_wall_s']:.0f} s): source {m['arms']['source']['success']:.2f} "
              f"augmented {m['arms']['augmented']['success']:.2f}", flush=True)
        if kind == "aug" and m["config"]["aug_per_demo"] != label["aug_per_demo"]:
            print(f"  warning: the run used aug_per_demo {m['config']['aug_per_demo']} (--smoke pins it), "
                  f"not {label['aug_per_demo']}", file=sys.stderr)
        rows.append(row_of(m, **label, **({"effective_aug_per_demo": m["config"]["aug_per_demo"]} if kind == "aug" else {})))
        metrics.append(m)
    varied = {"seed", "aug_per_demo"} if kind == "aug" else {"seed"}  # what changes from run to run
    config = {k: v for k, v in metrics[0]["config"].items() if k not in varied}
    result = {
        "kind": kind, "smoke": smoke,
        "command": shlex.join(["python", "chapter_tools.py", *argv]),
        "runs_command": shlex.join(["python", "scale_data.py", "--seed", "{seed}", "--no-rerun", "--out",
                                    str(out_root / kind / "{run}"), *flags] + (["--aug_per_demo", "{k}"] if kind == "aug" else [])),
        **prov,
        "device": metrics[0]["config"].get("device"),
        "config": config,
        "action_dims": metrics[0]["action_dims"], "padded_action_dim": metrics[0]["padded_action_dim"],
        "rows": rows,
    }
    if kind == "seeds":
        result["mean"] = mean_row(rows)
        result["paired"] = paired(rows)
    else:
        result["seed"] = 0
    path = out_root / f"sweep_{kind}.json"
    write_atomic(path, json.dumps(result, indent=1, sort_keys=False) + "\n")
    print()
    print(format_table(rows, "seed" if kind == "seeds" else "aug_per_demo", result.get("mean")))
    if kind == "seeds":
        pr = result["paired"]
        std = "n/a" if pr["std_delta"] is None else f"{pr['std_delta']:.3f}"
        sem = "n/a" if pr["sem_delta"] is None else f"{pr['sem_delta']:.3f}"
        print(f"paired: augmented beat source on {pr['wins']} of {pr['n']} seeds (ties {pr['ties']}, losses {pr['losses']}); "
              f"mean paired delta {pr['mean_delta']:+.3f}, std {std}, sem {sem}")
    else:
        s = {r["aug_per_demo"]: r["augmented"] for r in rows}
        if sorted(s) == [0, 4, 8]:
            print(f"curve 0 -> 4 -> 8: {ex3_answer(s[0], s[4], s[8])} (plateau_tol {PLATEAU_TOL})")
    if smoke:
        print("smoke sweep: numbers exercise the pipeline only")
    print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    return path


# ----------------------------------------------------------------------------------------------
# Wall-clock
# ----------------------------------------------------------------------------------------------
WALLCLOCK_FIELDS = ("chapter", "tier", "minutes", "config_hash", "date", "status")
TIERS = ("cpu-2core", "mps", "t4", "4090", "h100")


HASH_EXCLUDE = ("device", "workers", "cache")  # the tier names the device; workers and cache only change speed


def config_hash(config: dict) -> str:
    """First 12 hex of sha256 over the run's config (metrics.json "config") as sorted compact JSON,
    without HASH_EXCLUDE, so the same default configuration hashes the same on every tier."""
    c = {k: v for k, v in config.items() if k not in HASH_EXCLUDE}
    return hashlib.sha256(json.dumps(c, sort_keys=True, separators=(",", ":")).encode()).hexdigest()[:12]


def read_wallclock(path: Path) -> list[dict]:
    path = Path(path)
    if not path.exists():
        return [{"chapter": CHAPTER_ID, "tier": t, "minutes": "", "config_hash": "", "date": "", "status": "pending"} for t in TIERS]
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and set(rows[0]) != set(WALLCLOCK_FIELDS):
        raise ToolError(f"{path}: columns must be {','.join(WALLCLOCK_FIELDS)}")
    have = {r["tier"] for r in rows}
    rows += [{"chapter": CHAPTER_ID, "tier": t, "minutes": "", "config_hash": "", "date": "", "status": "pending"}
             for t in TIERS if t not in have]
    return rows


def write_wallclock_row(path: Path, row: dict) -> list[dict]:
    """Replace (or add) the row for row['tier']; keep every other row; known tiers first, in order."""
    rows = [r for r in read_wallclock(path) if r["tier"] != row["tier"]] + [dict(row)]
    order = {t: i for i, t in enumerate(TIERS)}
    rows.sort(key=lambda r: (order.get(r["tier"], len(TIERS)), r["tier"]))
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=WALLCLOCK_FIELDS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: r.get(k, "") for k in WALLCLOCK_FIELDS} for r in rows)
    write_atomic(Path(path), buf.getvalue())
    return rows


def supports_flag(script: Path, flag: str) -> bool:
    """Whether the chapter script defines `flag` (read from its source, so nothing is run)."""
    return f'"{flag}"' in Path(script).read_text(encoding="utf-8")


def measure_wallclock(script: Path, smoke: bool, tier: str | None) -> dict:
    with tempfile.TemporaryDirectory(prefix="ch37-wallclock-") as tmp:  # cold start: demos generated, as on a first run
        cmd = [sys.executable, str(script), "--seed", "0", "--no-rerun", "--out", tmp] + (["--smoke"] if smoke else [])
        cmd += ["--no-cache"] if supports_flag(script, "--cache") else []  # time the work, never a replay
        print(f"timing: {shlex.join(cmd)}", flush=True)
        t0 = time.perf_counter()
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            raise ToolError(f"the timed run exited {p.returncode}:\n" + "\n".join((p.stdout + p.stderr).strip().splitlines()[-15:]))
        config = json.loads((Path(tmp) / "metrics.json").read_text())["config"]
    if tier is None:
        import chapter_io

        tier = chapter_io.device_tier(config["device"])
    return {"chapter": CHAPTER_ID, "tier": tier, "minutes": f"{wall / 60:.2f}", "config_hash": config_hash(config),
            "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"), "status": "measured"}


# ----------------------------------------------------------------------------------------------
# Notebook
# ----------------------------------------------------------------------------------------------
INSTALL_CELL = """\
# Install (idempotent). Open this notebook from a clone of the course repository, or on Colab first
# upload/clone the repository into the working folder. This cell finds it (here or one folder down),
# moves into it, and installs the project only when lerobot is not importable yet.
# If pip upgraded numpy or torch, Colab asks to restart the runtime: restart, then run from here again.
import importlib.util
import os
import sys
from pathlib import Path

here = Path.cwd()
repo = next((d for d in [here, *sorted(p.parent for p in here.glob("*/scale_data.py"))] if (d / "scale_data.py").is_file()), None)
if repo is None:
    raise FileNotFoundError(f"scale_data.py is not in {here} or a folder below it: get the course repository first")
os.chdir(repo)
if str(repo) not in sys.path:
    sys.path.insert(0, str(repo))
if importlib.util.find_spec("lerobot") is None:
    %pip install -q -e .
print(f"repository {repo}; lerobot {'ready' if importlib.util.find_spec('lerobot') else 'missing'}")"""

ARGV_CELL = """\
# The script's flags, exactly as on the command line (python scale_data.py --help lists them).
# Smoke run, seconds, numbers not meaningful:  sys.argv = ["scale_data.py", "--smoke", "--seed", "0"]
{cache_note}import sys

sys.argv = ["scale_data.py", "--seed", "0", "--no-cache"]"""
CACHE_NOTE = """\
# --no-cache: every cell really runs. Without it an identical earlier run (same flags, same code)
# is replayed from the result cache and the setup cell stops the notebook early ("SystemExit: 0").
"""


def _prose(text: str) -> str:
    """Docstring paragraphs -> markdown: plain paragraphs joined, aligned/indented ones kept as text blocks."""
    out = []
    for para in re.split(r"\n\s*\n", text.strip()):
        lines = para.splitlines()
        if any(ln.startswith((" ", "\t")) or re.search(r"\S {2,}\S", ln) for ln in lines):
            out.append("```text\n" + para + "\n```")
        else:
            out.append(" ".join(ln.strip() for ln in lines))
    return "\n\n".join(out)


def _cell(kind: str, cid: str, source: str, tags: list[str] | None = None) -> dict:
    lines = source.splitlines(keepends=True)
    cell = {"cell_type": kind, "id": cid, "metadata": {"tags": tags} if tags else {}, "source": lines}
    if kind == "code":
        cell.update(execution_count=None, outputs=[])
    return cell


def build_notebook(script: Path = SCRIPT) -> str:
    """The notebook JSON text: deterministic (fixed ids, no timestamps, no outputs)."""
    regions = parse_regions(script)
    doc = module_docstring(script)
    title, _, rest = doc.partition("\n")
    cells = [
        _cell("markdown", "intro", f"# {title.strip()}\n\n{_prose(rest)}\n\n"
              f"*Built from `{script.name}` by `python chapter_tools.py notebook`: one section per region of the script. "
              "Edit the script, not this notebook.*"),
        _cell("code", "install", INSTALL_CELL, ["install"]),
        _cell("code", "argv", ARGV_CELL.format(cache_note=CACHE_NOTE if supports_flag(script, "--cache") else ""), ["argv"]),
    ]
    for i, r in enumerate(regions, 1):
        cells.append(_cell("markdown", f"{r.name}-md", f"## {i}. {r.name}\n\n{' '.join(r.intent)}"))
        cells.append(_cell("code", f"{r.name}-code", r.code, [f"region-{r.name}"]))
    nb = {
        "cells": cells,
        "metadata": {
            "colab": {"provenance": [], "toc_visible": True},
            "kernelspec": {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"},
            "language_info": {"name": "python"},
        },
        "nbformat": 4,
        "nbformat_minor": 5,
    }
    return json.dumps(nb, indent=1, sort_keys=True, ensure_ascii=False) + "\n"


# ----------------------------------------------------------------------------------------------
# CLI
# ----------------------------------------------------------------------------------------------
def _rel(p: Path) -> str:
    p = Path(p).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def cmd_regions(a) -> int:
    for r in parse_regions(a.script):
        print(f"{r.name:8s} lines {r.start:4d}-{r.end:<4d} sha256 {r.sha256}")
    print("(sha256 of the lines strictly between the markers, each ending in a newline)")
    return 0


def cmd_hashes(a) -> int:
    current = region_hashes(a.script)
    meta = load_yaml(a.meta)
    if a.write:
        meta["region_hashes"] = current
        write_meta(a.meta, {**META_STATIC, **meta} if not meta.get("id") else meta)
        print(f"wrote region_hashes of {_rel(a.script)} to {_rel(a.meta)}")
        return 0
    if not meta.get("region_hashes"):
        print(f"drift: {_rel(a.meta)} has no region_hashes; run: python chapter_tools.py hashes --write")
        return 1
    bad = drifted(current, meta.get("region_hashes"))
    if bad:
        print(f"drift: region(s) {', '.join(bad)} of {_rel(a.script)} differ from {_rel(a.meta)} region_hashes; "
              "if the change is intended, run: python chapter_tools.py hashes --write "
              "(and re-run the sweep + meta if the numbers may have moved)")
        return 1
    print(f"ok: all {len(current)} regions match {_rel(a.meta)}")
    return 0


def cmd_sweep(a, flags, argv) -> int:
    if (a.seeds is None) == (a.aug is None):
        raise ToolError("give exactly one of --seeds N or --aug K [K ...]")
    if a.seeds is not None and a.seeds < 1:
        raise ToolError("--seeds must be >= 1")
    if a.aug is not None and (not a.aug or min(a.aug) < 0):
        raise ToolError("--aug needs one or more values >= 0")
    sweep(seeds=a.seeds, aug=a.aug, flags=flags, out_root=a.out_root, script=a.script, argv=argv)
    return 0


def cmd_meta(a) -> int:
    for p in (a.sweep, a.aug_sweep):
        if not Path(p).exists():
            raise ToolError(f"{p} not found; run the sweeps first: python chapter_tools.py sweep --seeds 3 "
                            "and python chapter_tools.py sweep --aug 0 4 8")
    seeds, aug = json.loads(Path(a.sweep).read_text()), json.loads(Path(a.aug_sweep).read_text())
    if seeds.get("kind") != "seeds" or aug.get("kind") != "aug":
        raise ToolError("--sweep takes the sweep_seeds.json file and --aug-sweep the sweep_aug.json file")
    current = region_hashes(a.script)
    for name, s in (("seed", seeds), ("aug", aug)):
        stale = drifted(current, s.get("script_region_hashes"))
        if stale:
            print(f"warning: the {name} sweep ran a different scale_data.py (regions {', '.join(stale)} changed since); "
                  "re-run it if those changes can move the numbers", file=sys.stderr)
    old = load_yaml(a.meta)
    meta = {k: old.get(k, v) for k, v in META_STATIC.items()}
    meta.update({k: v for k, v in old.items() if k not in META_STATIC})
    meta["reference_run"] = reference_run(seeds, aug)
    meta["exercise_checks"] = derive_checks(seeds, aug)
    meta["region_hashes"] = current
    write_meta(a.meta, meta)
    ex = meta["exercise_checks"]
    print(f"wrote {_rel(a.meta)}: ex1 answer {ex['ex1']['answer']} band {ex['ex1']['band']}, "
          f"ex3 answer {ex['ex3']['answer']} bands {ex['ex3']['band']}"
          + (" (provisional: smoke sweep)" if meta["reference_run"]["provisional"] else ""))
    return 0


def cmd_wallclock(a) -> int:
    row = measure_wallclock(a.script, a.smoke, a.tier)
    if a.smoke:
        row["status"] = "smoke"  # printed for the record, never written
    print(",".join(WALLCLOCK_FIELDS))
    print(",".join(row[k] for k in WALLCLOCK_FIELDS))
    if a.smoke or a.dry_run:
        print("not written (" + ("a smoke time never goes into wallclock.csv" if a.smoke else "--dry-run") + ")")
        return 0
    write_wallclock_row(a.csv, row)
    print(f"wrote the {row['tier']} row of {_rel(a.csv)}")
    return 0


def cmd_notebook(a) -> int:
    text = build_notebook(a.script)
    if a.check:
        if not Path(a.out).exists() or Path(a.out).read_text(encoding="utf-8") != text:
            print(f"stale: {_rel(a.out)} does not match {_rel(a.script)}; run: python chapter_tools.py notebook")
            return 1
        print(f"ok: {_rel(a.out)} matches {_rel(a.script)}")
        return 0
    write_atomic(Path(a.out), text)
    print(f"wrote {_rel(a.out)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    p = argparse.ArgumentParser(prog="chapter_tools.py", description=__doc__.split("\n")[0], allow_abbrev=False)
    sub = p.add_subparsers(dest="cmd", required=True)

    def add(name, help_):
        s = sub.add_parser(name, help=help_, allow_abbrev=False)
        s.add_argument("--script", type=Path, default=SCRIPT, help="chapter script (default scale_data.py)")
        return s

    add("regions", "print each region's name, line range and sha256")
    s = add("hashes", "check or refresh meta.yaml region_hashes")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--check", action="store_true", help="exit 1 naming each drifted region")
    g.add_argument("--write", action="store_true", help="rewrite region_hashes in meta.yaml")
    s.add_argument("--meta", type=Path, default=META)
    s = add("sweep", "run scale_data.py over seeds (--seeds N) or aug_per_demo values (--aug ...); other flags pass through")
    s.add_argument("--seeds", type=int, help="run seeds 0..N-1")
    s.add_argument("--aug", type=int, nargs="+", help="run seed 0 at these aug_per_demo values (ex3: 0 4 8)")
    s.add_argument("--out-root", type=Path, help="default outputs/sweep (outputs/sweep-smoke with --smoke)")
    s = add("meta", "write reference_run, exercise_checks and region_hashes into meta.yaml from the sweep files")
    s.add_argument("--sweep", type=Path, default=ROOT / "outputs/sweep/sweep_seeds.json")
    s.add_argument("--aug-sweep", type=Path, default=ROOT / "outputs/sweep/sweep_aug.json")
    s.add_argument("--meta", type=Path, default=META)
    s = add("wallclock", "time `scale_data.py --seed 0 --no-rerun` here and write this tier's row of wallclock.csv")
    s.add_argument("--dry-run", action="store_true", help="print the row, write nothing")
    s.add_argument("--smoke", action="store_true", help="time the --smoke run instead (printed only, never written)")
    s.add_argument("--tier", help="tier name (default: chapter_io.device_tier of the device the run used)")
    s.add_argument("--csv", type=Path, default=WALLCLOCK)
    s = add("notebook", "build scale_data.ipynb from the regions (--check: exit 1 if the file is stale)")
    s.add_argument("--check", action="store_true")
    s.add_argument("--out", type=Path, default=NOTEBOOK)

    if argv and argv[0] == "sweep":
        a, flags = p.parse_known_args(argv)
    else:
        a, flags = p.parse_args(argv), []
    try:
        if a.cmd == "sweep":
            return cmd_sweep(a, flags, argv)
        if flags:
            raise ToolError(f"unrecognized arguments: {' '.join(flags)}")
        return {"regions": cmd_regions, "hashes": cmd_hashes, "meta": cmd_meta, "wallclock": cmd_wallclock,
                "notebook": cmd_notebook}[a.cmd](a)
    except ToolError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
