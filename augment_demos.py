"""Grow a PushT demo set: perturbed starts of every source demo, re-solved by the expert, kept on success.

    python augment_demos.py --src my_pusht --per_demo 100 --out big [--workers N | --ray [ADDRESS]]

--src is any LeRobot v3 PushT set (observation.state float32[10], action float32[2], laid out as in
pusht_env.py): one from gen_demos_pusht.py or your own. It is only read. --out becomes a LeRobot v3
set of the kept demos, every frame carrying its provenance (aug.source_episode: the source episode;
aug.start: block x, y, yaw, pusher x, y it was solved from), with generation_report.json beside it.

The same command gives the same bytes with any --workers, with --ray, and after a killed run is
re-run (finished shards are kept, only the missing ones are made). The engine lives in ch37:
engine.py (one attempt), shards.py (shards, merge, stats), executors.py (local processes, Ray).
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import time
from pathlib import Path

from ch37.errors import DataError, fail

SIGMA_DEFAULTS = (0.08, 0.5)  # m, rad: the chapter's --aug_pos_sigma and --aug_yaw_sigma


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--src", type=Path, required=True, help="source LeRobot v3 PushT set (never modified)")
    p.add_argument(
        "--per_demo", type=int, default=10, help="attempts (perturbed starts) per source episode (default 10)"
    )
    p.add_argument(
        "--out", type=Path, required=True, help="output folder: new, or a run of this command to finish"
    )
    p.add_argument("--seed", type=int, default=0, help=">= 0; seeds draw disjoint perturbations (default 0)")
    p.add_argument(
        "--pos_sigma", type=float, default=SIGMA_DEFAULTS[0], help="m; block and pusher xy noise std"
    )
    p.add_argument("--yaw_sigma", type=float, default=SIGMA_DEFAULTS[1], help="rad; block yaw noise std")
    p.add_argument(
        "--mode",
        choices=("resolve", "replay"),  # ch37.engine.MODES (not imported here: --help stays instant)
        default="resolve",
        help="resolve: the expert solves each start; replay: the source path transformed into the new "
        "block pose, executed open-loop, kept only on success (MimicGen's move; most attempts fail here)",
    )
    p.add_argument(
        "--workers", type=int, default=min(8, os.cpu_count() or 1), help="local processes (default: cores)"
    )
    p.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="run on Ray: alone, a local Ray with --workers CPUs; with ADDRESS, join that cluster",
    )
    p.add_argument(
        "--shard_size", type=int, help="attempts per shard (default 100); part of the run's settings"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.error = lambda msg: fail(f"{msg} (see --help)")
    a = p.parse_args(argv)
    from ch37.shards import SHARD_SIZE

    a.shard_size = a.shard_size if a.shard_size is not None else SHARD_SIZE
    for name in ("per_demo", "workers", "shard_size"):
        if getattr(a, name) <= 0:
            fail(f"--{name} must be a positive integer, got {getattr(a, name)}")
    if a.seed < 0:
        fail(f"--seed must be >= 0, got {a.seed}")
    for name in ("pos_sigma", "yaw_sigma"):
        if not math.isfinite(getattr(a, name)) or getattr(a, name) < 0:
            fail(f"--{name} must be a finite number >= 0, got {getattr(a, name)}")
    return a


def read_source(src: Path) -> dict:
    """The source set's columns, or DataError with one line saying what is wrong with it."""
    import json

    import pusht_env
    from ch37.lerobot_io import load_arrays, schema_problem

    if not src.is_dir():
        raise DataError(f"--src {src} is not a folder; make a PushT set with gen_demos_pusht.py")
    problem = schema_problem(src, pusht_env.OBS_DIM, pusht_env.ACT_DIM)
    if problem:
        raise DataError(f"--src {problem} (a PushT set has state [10] and action [2])")
    feats = json.loads((src / "meta" / "info.json").read_text())["features"]
    for key, want in (("observation.state", pusht_env.STATE_NAMES), ("action", pusht_env.ACTION_NAMES)):
        names = feats[key].get("names")
        if names is not None and list(names) != list(want):
            raise DataError(f"--src {src}: {key} names {names} are not PushT's {list(want)}")
    import datasets
    import pyarrow.parquet as pq

    for f in sorted(src.glob("data/*/*.parquet")) + sorted(src.glob("meta/episodes/*/*.parquet")):
        try:
            pq.read_metadata(f)
        except Exception as e:  # pyarrow's errors for a broken file vary by what is broken
            raise DataError(
                f"--src {src}: {f.relative_to(src)} is not a readable parquet file ({e})"
            ) from None
    datasets.logging.set_verbosity(datasets.logging.CRITICAL)  # a failure below is our one line, not a log
    try:
        arrays = load_arrays(src, keys=("observation.state", "action", "episode_index"))
    except Exception as e:  # pyarrow, datasets and lerobot each raise their own kinds for a broken set
        first = (str(e).strip().splitlines() or [""])[0][:160]
        raise DataError(
            f"--src {src} could not be read as a LeRobot dataset ({type(e).__name__}: {first})"
        ) from None
    import numpy as np

    if len(arrays["action"]) == 0:
        raise DataError(f"--src {src} holds no frames")
    if not (np.isfinite(arrays["observation.state"]).all() and np.isfinite(arrays["action"]).all()):
        raise DataError(f"--src {src} holds non-finite states or actions")
    return arrays


def check_out(out: Path, src: Path, config: dict | None = None) -> dict | None:
    """None for a new run; the run's stamp for a run of this command (with `config`, when given);
    DataError for anything else: --out overlapping --src, data this program did not make, other settings."""
    from ch37.stamps import MADE_BY, holds_data, read_stamp

    o, s = out.resolve(), src.resolve()
    if o == s or s in o.parents or o in s.parents:
        raise DataError(f"--out {out} overlaps --src {src}; the source is never written: pick another --out")
    if not holds_data(out):
        return None
    stamp = read_stamp(out)
    if not out.is_dir() or stamp is None or stamp.get("made_by") != MADE_BY or stamp.get("kind") != "engine":
        raise DataError(f"{out} holds data this program did not make; move it or pass another --out")
    old = stamp.get("config") or {}
    if config is not None and old != config:
        diff = ", ".join(
            f"{k} differs" if isinstance(v, dict) else f"{k}={old.get(k)} (now {v})"
            for k, v in config.items()
            if old.get(k) != v
        )
        raise DataError(f"{out} holds a run with other settings ({diff}); pass another --out")
    return stamp


def lock_folder(out: Path) -> None:
    """Hold an exclusive lock on `out` until this process ends: two runs never write one folder."""
    try:
        import fcntl
    except ImportError:  # not a Unix: no lock
        return
    global _LOCK
    _LOCK = os.open(out, os.O_RDONLY)
    try:
        fcntl.flock(_LOCK, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        raise DataError(f"another run is writing {out}; wait for it or pass another --out") from None


_LOCK = None


def length_stats(hist: dict) -> dict:
    import numpy as np

    if not hist:
        return {}
    x = np.repeat([int(n) for n in hist], list(hist.values()))
    return {"min": int(x.min()), "max": int(x.max()), "mean": float(x.mean()), "median": float(np.median(x)),
            "p90": float(np.quantile(x, 0.9))}  # fmt: skip


def report_of(stamps: list[dict], failures_known, base: dict) -> dict:
    """The generation report from the shard stamps (so a resumed run reports the whole run)."""
    failures = dict.fromkeys(failures_known, 0)
    per_source, lengths = {}, {}
    for st in stamps:
        for why, n in st["failures"].items():
            failures[why] = failures.get(why, 0) + n
        for e, (att, kept) in st["per_source"].items():
            t = per_source.setdefault(e, [0, 0])
            t[0], t[1] = t[0] + att, t[1] + kept
        for n, c in st["lengths"].items():
            lengths[n] = lengths.get(n, 0) + c
    attempts, kept = sum(st["attempts"] for st in stamps), sum(st["kept"] for st in stamps)
    return base | {
        "attempts": attempts,
        "kept": kept,
        "yield": kept / attempts if attempts else 0.0,
        "failures": failures,
        "frames": sum(st["frames"] for st in stamps),
        "episode_length": length_stats(lengths),
        "per_source": {
            e: {"attempts": a, "kept": k, "yield": k / a}
            for e, (a, k) in sorted(per_source.items(), key=lambda kv: int(kv[0]))
        },
    }


def summary_line(r: dict, out: Path) -> str:
    return (
        f"augment_demos: {r['attempts']} attempts, {r['kept']} kept (yield {r['yield']:.3f}), "
        f"{r['frames']} frames in {r['seconds']:.1f} s ({r['demos_per_s']:.1f} demos/s) -> {out} "
        f"(LeRobot v3; report {out / 'generation_report.json'})"
    )


def run(a: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    from tqdm import tqdm

    from ch37 import engine, executors, shards
    from ch37.files import dump_json, round_floats, write_atomic
    from ch37.stamps import MADE_BY, STAMP_NAME, stamp_text

    check_out(a.out, a.src)  # before reading the source: a folder that is not ours is refused at once
    arrays = read_source(a.src)
    sources = engine.sources(arrays)
    if max(sources) >= 1_000_000:
        raise DataError(f"--src {a.src}: episode indices must be below 1,000,000 (the seed block)")
    identity = shards.source_identity(arrays)
    versions = shards.versions()
    config = {
        "mode": a.mode,
        "per_demo": a.per_demo,
        "seed": a.seed,
        "pos_sigma": a.pos_sigma,
        "yaw_sigma": a.yaw_sigma,
        "shard_size": a.shard_size,
        "source": identity,
        "engine": shards.ENGINE_VERSION,
        "versions": versions,
    }
    stamp = check_out(a.out, a.src, config)
    report_path = a.out / shards.REPORT_NAME
    if stamp and stamp.get("complete"):
        old = shards.read_json(report_path)
        if old:
            shards.remove_shards(a.out)  # left over if a run was stopped right after its stamp
            print("already complete (same command, same settings); nothing to do")
            print(summary_line(old, a.out))
            return 0
    a.out.mkdir(parents=True, exist_ok=True)
    lock_folder(a.out)
    run_stamp = {"made_by": MADE_BY, "kind": "engine", "config": config, "complete": False}
    write_atomic(a.out / STAMP_NAME, stamp_text(run_stamp))  # the folder is ours from here on

    plan = shards.plan(sources, a.per_demo, a.shard_size)
    done = shards.finished(a.out, config, len(plan))
    todo = [i for i in range(len(plan)) if i not in done]
    scratch = None if a.ray not in (None, "local") else str(a.out / shards.SHARDS_DIR)  # this machine's disk
    (a.out / shards.SHARDS_DIR).mkdir(exist_ok=True)
    tasks = [
        (i, plan[i], {e: sources[e] for e in sorted({e for e, _ in plan[i]})}, config, scratch) for i in todo
    ]
    timing = {"start_s": 0.0}
    if not tasks:
        executor, results = "none (every shard was already made)", []
    elif a.ray is None:
        executor = f"local processes ({min(a.workers, max(1, len(tasks)))})"
        results = executors.run_local(shards.make_shard, tasks, workers=a.workers)
    else:
        address = None if a.ray == "local" else a.ray
        executor = f"ray {'local, ' + str(a.workers) + ' CPUs' if address is None else address}"
        results = executors.run_ray(
            shards.make_shard, tasks, address=address, workers=a.workers, timing=timing
        )
    attempts_done = sum(st["attempts"] for st in done.values())
    total = sum(len(s) for s in plan)
    bar = tqdm(total=total, initial=attempts_done, desc="augment", unit="attempt", leave=False,
               disable=a.quiet or not sys.stderr.isatty())  # fmt: skip
    made = {"attempts": 0, "kept": 0}
    t_gen = time.perf_counter()
    for r in results:
        st = r["stamp"]
        if st["versions"] != versions:
            raise DataError(
                f"a worker has {st['versions']}, this machine {versions}: install the same versions"
            )
        shards.save_shard(a.out, st["shard"], r)
        done[st["shard"]] = st
        made["attempts"] += st["attempts"]
        made["kept"] += st["kept"]
        bar.update(st["attempts"])
        rate = made["kept"] / max(time.perf_counter() - t_gen, 1e-9)
        bar.set_postfix_str(f"{rate:.1f} demos/s, yield {made['kept'] / made['attempts']:.3f}")
    bar.close()
    t_merge = time.perf_counter()
    merged = shards.merge(a.out, len(plan))
    seconds = time.perf_counter() - t0
    import platform

    vers = {"python": platform.python_version(), **versions}
    if a.ray is not None:
        import ray

        vers["ray"] = ray.__version__
    report = report_of(
        [done[i] for i in range(len(plan))],
        engine.FAILURES[a.mode],
        {
            "source": {"path": str(a.src.resolve()), **identity},
            "settings": {
                k: config[k] for k in ("mode", "per_demo", "seed", "pos_sigma", "yaw_sigma", "shard_size")
            },
            "shards": {"total": len(plan), "made_this_run": len(todo), "reused": len(plan) - len(todo)},
            "executor": executor,
            "seconds": seconds,
            "seconds_generate": t_merge - t_gen,
            "seconds_start_executor": timing["start_s"],  # of seconds_generate: starting or joining Ray
            "seconds_merge": time.perf_counter() - t_merge,
            "demos_per_s": made["kept"] / seconds,
            "command": " ".join(shlex.quote(x) for x in [Path(sys.executable).name, *sys.argv]),
            "versions": vers,
            "dataset": {"episodes": merged, "load": f"LeRobotDataset('local/pusht_aug', root='{a.out}')"},
        },
    )
    assert report["kept"] == merged, (report["kept"], merged)
    write_atomic(report_path, dump_json(round_floats(report, 4)))
    write_atomic(a.out / STAMP_NAME, stamp_text(run_stamp | {"complete": True}))
    shards.remove_shards(a.out)
    if merged == 0:
        print(f"no attempt succeeded: no dataset written, only {report_path}")
    print(summary_line(report, a.out))
    return 0


def main(argv=None) -> int:
    a = parse(argv)
    try:
        return run(a)
    except DataError as e:
        fail(str(e))
    except KeyboardInterrupt:
        print(
            "interrupted: the shards saved so far are kept; run the same command to finish", file=sys.stderr
        )
        return 130


if __name__ == "__main__":
    sys.exit(main())
