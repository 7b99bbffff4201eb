"""meta.yaml from the result files: reference_run, exercise_checks and region_hashes, never typed by hand.

    python -m tools.meta [--sweep F] [--aug-sweep F] [--replay DIR] [--scale-lab F] [--meta F]
    python -m tools.meta --environment           meta.yaml's `environment` alone, from requirements.lock

reference_run comes from the seed sweep (--sweep, from `python -m tools.sweep --seeds 3`) and the aug
sweep (--aug-sweep, from `python -m tools.sweep --aug 0 4 8`), exercise_checks from them through
exercises/rules.py; `replay` from --replay DIR (`python -m tools.replay compare --seeds 5` and `--sigma ...`)
and `scale_lab` from --scale-lab (`python scale_lab.py`) when their files exist, left as found
otherwise. What smoke-sized runs give is marked `provisional: true`. id, title, track, objectives and
mimicgen are kept as found in meta.yaml.

Exit codes: 0 ok, 2 bad input (a missing, corrupt or incomplete sweep file, bad flags).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import yaml

from ch37 import CHAPTER_ID, ROOT, errors
from ch37.errors import DataError
from ch37.ownership import write_atomic
from exercises.rules import RULES, derive_checks
from tools.common import META, drifted, parser, region_hashes, rel
from tools.lock import LOCK, environment_section, versions

META_HEADER = """\
# Chapter 3.7 metadata. Written by `python -m tools.meta` (environment, reference_run, exercise_checks,
# region_hashes: never typed by hand), `python -m tools.regions --write` (region_hashes only) and
# `python -m tools.meta --environment` (environment only: requirements.lock's versions).
# id, title, track, objectives and mimicgen are kept as found here; edit them freely (comments are not kept).
"""

META_STATIC = {
    "id": CHAPTER_ID,
    "title": "Datasets at Scale",
    "track": "robot learning / data",
    "objectives": [
        "Pool demos from two robots (PushT, 2-D actions; a bimanual ALOHA handoff, 6-D actions) into one "
        "cross-embodiment set: per-embodiment normalization, zero-padding to the widest action, and an "
        "action mask that keeps padded dimensions out of the loss.",
        "Say what a shared policy can carry across embodiments (a network, an action head) and what it "
        "cannot (the meaning of a raw state number: index 2 is the block's x in PushT, the right gripper "
        "in ALOHA).",
        "Grow the PushT set MimicGen-style: perturb each source start, re-solve it with the same scripted "
        "expert in the real physics, keep only successes, and report the yield.",
        "Measure the data-scale effect: the same behaviour-cloning MLP on source demos alone and on source "
        "plus augmented for the same number of gradient steps, at a short and a full budget (a 2x2 of data x "
        "compute), rolled out on the same held-out starts.",
    ],
    "mimicgen": {
        "repo": "NVlabs/mimicgen",
        "tag": "v1.0.0",
        "commit": "ea0988523f468ccf7570475f1906023f854962e9",
        "files": [
            {
                "path": "mimicgen/utils/pose_utils.py",
                "symbol": "transform_source_data_segment_using_object_pose",
                "why": "how MimicGen moves a source end-effector segment into the new object's frame; "
                "datagen.poses.transform_segment is it in SE(3), with planar tasks as its SE(2) case, "
                "used by --aug_mode replay; "
                "the chapter's default re-solves with its expert, because it owns one for any start",
            },
            {
                "path": "mimicgen/datagen/data_generator.py",
                "why": "the one generation loop for every task (parse a source into subtask segments by "
                "their end signals, select a source, transform, interpolate into the segment, execute, keep "
                "on success); datagen/replay.py is that loop here; a task only describes",
            },
            {
                "path": "mimicgen/scripts/generate_dataset.py",
                "why": "the generate-execute-keep-only-successes loop and its success_rate = successes / "
                "attempts, the same bookkeeping as this chapter's yield",
            },
        ],
    },
}
META_ORDER = "id title track objectives mimicgen environment reference_run replay scale_lab exercise_checks"
META_ORDER += " region_hashes"
# What each sweep file must hold for reference_run and derive_checks: top-level keys, then keys of every row.
SWEEP_KEYS = {
    "seeds": ("rows mean paired pooled action_dims padded_action_dim", "seed delta ci95"),
    "aug": ("rows", "aug_per_demo augmented_full ci95"),
}
PROVENANCE_KEYS = "command date_utc git platform packages device config script_region_hashes".split()
SIGMA_ROW_KEYS = "multiplier mode attempts kept yield ci95 failures kept_block_shift_m".split()
SCALE_LAB_KEYS = "command config expert generation curves points seconds".split()


def load_yaml(path: Path) -> dict:
    """A YAML mapping ({} when the file does not exist); anything else is a DataError."""
    path = Path(path)
    if not path.exists():
        return {}
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise DataError(f"{rel(path)} is not readable YAML ({' '.join(str(e).split())})") from None
    if data is not None and not isinstance(data, dict):
        raise DataError(f"{rel(path)} is not a YAML mapping")
    return data or {}


class _Dumper(yaml.SafeDumper):
    """Short all-scalar lists and mappings on one line ({n: 3, wins: 3}), the rest in block style."""


def _flow(value) -> bool:
    items = value.values() if isinstance(value, dict) else value
    short = (int, float, bool, type(None))
    scalar = all(isinstance(v, short) or (isinstance(v, str) and len(v) < 40) for v in items)
    return scalar and len(json.dumps(value)) <= 100


_Dumper.add_representer(dict, lambda d, v: d.represent_mapping("tag:yaml.org,2002:map", v.items(), _flow(v)))
_Dumper.add_representer(list, lambda d, v: d.represent_sequence("tag:yaml.org,2002:seq", v, _flow(v)))


def write_meta(path: Path, meta: dict) -> None:
    """meta.yaml in META_ORDER (unknown keys after), under META_HEADER, written atomically."""
    ordered = {k: meta[k] for k in META_ORDER.split() if k in meta} | meta
    text = yaml.dump(ordered, Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=110)
    write_atomic(Path(path), META_HEADER + text)


def _read_json(path: Path, what: str, again: str):
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise DataError(f"{rel(path)} is not a readable {what} ({e}); {again}") from None


def run_platform(meta: dict) -> dict:
    """The platform the reference run recorded: Python, CPU, MKL branch ({} when meta.yaml has none)."""
    return meta.get("reference_run", {}).get("seeds", {}).get("provenance", {}).get("platform", {})


def environment(meta: dict, lock: Path = LOCK) -> dict:
    """meta.yaml's `environment`: the lock's versions, and the CPU and MKL kernel branch the reference
    run's numbers came from (docs/reproducibility.md: the same branch gives the same bits on any x86-64)."""
    ran = run_platform(meta)
    where = {"cpu": ran.get("cpu_model"), "kernel_path": ran.get("kernel_path") or ran.get("mkl_cbwr")}
    return environment_section(lock, ran.get("python")) | {k: v for k, v in where.items() if v}


def lock_mismatch(sweep: dict, lock: Path = LOCK) -> list[str]:
    """`name ran X, locked Y` for each package whose version in a sweep's provenance is not the lock's."""
    ran, pins = sweep.get("packages") or {}, versions(lock)
    return [f"{p} ran {v}, locked {pins[p]}" for p, v in ran.items() if p in pins and v != pins[p]]


def reference_run(seeds: dict, aug: dict) -> dict:
    """The sweeps' rows and statistics with their provenance; per-run wall time left out (wallclock.csv
    is the timing of record)."""
    provisional = bool(seeds.get("smoke") or aug.get("smoke"))
    if provisional:
        note = "smoke-sized sweep: exercises the pipeline only; refresh with a full sweep"
    else:
        note = "default configuration; every number below was written by python -m tools.meta from the sweeps"

    def rows(sweep):
        return [{k: v for k, v in r.items() if k != "wall_s"} for r in sweep["rows"]]

    def prov(sweep):
        return {"provenance": {k: sweep[k] for k in PROVENANCE_KEYS if k in sweep}}

    seed_part = {"rows": rows(seeds)} | {k: seeds[k] for k in ("mean", "paired", "pooled")} | prov(seeds)
    aug_part = {"seed": aug.get("seed", 0), "rows": rows(aug)} | prov(aug)
    return {"provisional": provisional, "note": note} | dict(seeds=seed_part, aug_curve=aug_part, rules=RULES)


def read_sweep(path: Path, kind: str, flag: str) -> dict:
    """A sweep file of `kind` ("seeds" or "aug") with every key meta needs; else a one-line DataError."""
    path = Path(path)
    if not path.exists():
        raise DataError(
            f"{rel(path)} not found; run the sweeps first: python -m tools.sweep --seeds 3 "
            "and python -m tools.sweep --aug 0 4 8"
        )
    data = _read_json(path, "JSON sweep file", "re-run the sweep")
    got = data.get("kind") if isinstance(data, dict) else type(data).__name__
    if got != kind:
        raise DataError(
            "--sweep takes the sweep_seeds.json file and --aug-sweep the sweep_aug.json file; "
            f"{flag} {rel(path)} holds {got!r}, not a {kind!r} sweep"
        )
    top, per_row = (keys.split() for keys in SWEEP_KEYS[kind])
    missing = [k for k in top if k not in data]
    rows = data.get("rows")
    if "rows" not in missing and (not isinstance(rows, list) or not rows):
        missing.append("rows (a non-empty list)")
    elif isinstance(rows, list):
        for i, r in enumerate(rows):
            if not isinstance(r, dict):
                missing.append(f"rows[{i}] (a mapping)")
                continue
            missing += [f"rows[{i}].{k}" for k in per_row if k not in r]
            if "ci95" in r and not (isinstance(r["ci95"], dict) and "augmented_full" in r["ci95"]):
                missing.append(f"rows[{i}].ci95.augmented_full")
    if missing:
        raise DataError(f"{rel(path)} is incomplete: it lacks {', '.join(missing[:5])}; re-run the sweep")
    return data


def _compare(d: dict) -> dict:
    """replay_compare.json for meta.yaml: the pooled results and each seed's arms and replay yield."""
    rows = d["rows"]
    per_seed = [
        {"seed": r["seed"], **{a: v["success"] for a, v in r["arms"].items()}}
        | {f"replay_{k}": r["modes"]["replay"][k] for k in ("kept", "attempts")}
        for r in rows
    ]
    return (
        {"command": d["command"], "seeds": [r["seed"] for r in rows], "steps": [r["steps"] for r in rows]}
        | {k: d[k] for k in ("modes", "pooled", "differences")}
        | {"per_seed": per_seed}
    )


def replay_section(folder: Path) -> dict | None:
    """meta.yaml's `replay` section from `tools.replay compare`'s two files in `folder` (None if
    neither is there)."""
    out = {}
    for name, kind in (("replay_compare.json", "compare"), ("replay_sigma.json", "sigma")):
        f = Path(folder) / name
        if not f.exists():
            continue
        try:
            d = json.loads(f.read_text(encoding="utf-8"))
            if kind == "compare":
                out[kind] = _compare(d)
            else:
                rows = [{k: r[k] for k in SIGMA_ROW_KEYS} for r in d["rows"]]
                out[kind] = {"command": d["command"], "rows": rows}
            out["provisional"] = bool(out.get("provisional") or d.get("smoke"))
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise DataError(
                f"{rel(f)} is not a complete tools.replay compare file ({e}); "
                "re-run python -m tools.replay compare"
            ) from None
    return out or None


def read_scale_lab(path: Path) -> dict | None:
    """scale_lab.json with every key the section needs; None when the file does not exist."""
    path = Path(path)
    if not path.exists():
        return None
    data = _read_json(path, "scale_lab.json", "re-run scale_lab.py")
    if not isinstance(data, dict) or data.get("kind") != "scale_lab":
        raise DataError(f"--scale-lab {rel(path)} is not a scale_lab.json written by scale_lab.py")
    if missing := [k for k in SCALE_LAB_KEYS if k not in data]:
        raise DataError(f"{rel(path)} is incomplete: it lacks {', '.join(missing)}; re-run scale_lab.py")
    return data


def scale_lab_section(lab: dict) -> dict:
    """meta.yaml's scale_lab: per curve per N the mean success over seeds, its pooled Wilson interval,
    the demos actually trained on (mean over seeds) and the steps per seed; engine yields; wall time."""
    cfg, provisional = lab["config"], bool(lab["config"].get("smoke"))
    curves = {
        curve: {int(n): {k: r[k] for k in ("success", "ci95", "demos", "steps")} for n, r in rows.items()}
        for curve, rows in lab["curves"].items()
    }
    generation = {}
    for mode, by_seed in lab["generation"].items():
        attempts, kept = (sum(g[k] for g in by_seed.values()) for k in ("attempts", "kept"))
        generation[mode] = {"attempts": attempts, "kept": kept}
        generation[mode]["yield"] = round(kept / attempts, 4) if attempts else 0
    if provisional:
        note = "smoke-sized lab: exercises the pipeline only; refresh with python scale_lab.py"
    else:
        note = "success vs total PushT demos; every number below was written by python -m tools.meta from "
        note += "scale_lab.json"
    return {
        "provisional": provisional,
        "note": note,
        "command": lab["command"],
        "seeds": cfg["seeds"],
        "eval_episodes": cfg["eval_episodes"],
        "interval": "Wilson 95% over all seeds' evaluation episodes pooled",
        "expert": {"success": lab["expert"]["success"], "ci95": lab["expert"]["ci95"]},
        "fixed_steps": lab.get("fixed_steps"),
        "generation": generation,
        "curves": {c: dict(sorted(by_n.items())) for c, by_n in curves.items()},  # N in numeric order
        "wall_s": round(lab["seconds"]["total"]),
    }


def main(argv: list[str]) -> int:
    p = parser("meta", __doc__)
    out = ROOT / "outputs"
    p.add_argument("--sweep", type=Path, default=out / "sweep/sweep_seeds.json", help="the seed sweep")
    p.add_argument("--aug-sweep", type=Path, default=out / "sweep/sweep_aug.json", help="the aug sweep")
    p.add_argument("--replay", type=Path, default=out / "replay", help="tools.replay compare's folder")
    p.add_argument("--scale-lab", type=Path, default=out / "scale_lab/scale_lab.json", help="the lab's")
    p.add_argument("--meta", type=Path, default=META, help="default meta.yaml")
    p.add_argument("--environment", action="store_true", help="refresh the environment (the lock) alone")
    p.add_argument("--lock", type=Path, default=LOCK, help="with --environment; default requirements.lock")
    a = p.parse_args(argv)
    if a.environment:
        meta = load_yaml(a.meta)
        meta["environment"] = environment(meta, a.lock)
        write_meta(a.meta, meta if meta.get("id") else {**META_STATIC, **meta})
        print(f"wrote environment of {rel(a.lock)} to {rel(a.meta)}")
        return 0
    seeds, aug = read_sweep(a.sweep, "seeds", "--sweep"), read_sweep(a.aug_sweep, "aug", "--aug-sweep")
    lab, current = read_scale_lab(a.scale_lab), region_hashes(a.script)
    for name, s in (("seed", seeds), ("aug", aug)):
        if stale := ", ".join(drifted(current, s.get("script_region_hashes"))):
            why = f"the {name} sweep ran a different scale_data.py (regions {stale} changed since)"
            print(f"warning: {why}; re-run it if those changes can move the numbers", file=sys.stderr)
        if off := lock_mismatch(s):
            why = f"the {name} sweep did not run on {rel(LOCK)}'s versions ({', '.join(off)})"
            print(f"warning: {why}; re-run it in a .venv made from the lock", file=sys.stderr)
    old = load_yaml(a.meta)
    meta = {k: old.get(k, v) for k, v in META_STATIC.items()} | old
    try:
        meta["reference_run"] = reference_run(seeds, aug)
        kept_lab = meta.get("scale_lab")
        if lab is not None:
            meta["scale_lab"] = scale_lab_section(lab)
        # ex3 reads the lab's curves; a smoke lab (provisional) has not the N the answer needs: the lab kept
        ex3_lab = (
            kept_lab if meta.get("scale_lab", {}).get("provisional") and kept_lab else meta.get("scale_lab")
        )
        meta["exercise_checks"] = derive_checks(seeds, aug, ex3_lab)
    except ValueError as e:
        raise DataError(str(e)) from None
    except (KeyError, TypeError, IndexError) as e:
        raise DataError(f"a sweep file or scale_lab.json is malformed ({type(e).__name__}: {e}); re-run it")
    if (replay := replay_section(a.replay)) is not None:  # a file not there keeps its part from before
        meta["replay"] = (old.get("replay") or {}) | replay
    meta["region_hashes"] = current
    meta["environment"] = environment(meta)
    write_meta(a.meta, meta)
    ex = meta["exercise_checks"]
    smoke = " (provisional: smoke sweep)" if meta["reference_run"]["provisional"] else ""
    print(
        f"wrote {rel(a.meta)}: ex1 answer {ex['ex1']['answer']} band {ex['ex1']['band']}, "
        f"ex3 answer {ex['ex3']['answer']} bands {ex['ex3']['band']}{smoke}"
    )
    return 0


if __name__ == "__main__":
    errors.main(main)
