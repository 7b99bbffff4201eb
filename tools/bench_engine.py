"""Validated demos per second of the data engine, end to end: local processes, Ray, two Ray nodes,
each beside the cost of its own physics.

    python -m tools.bench_engine                                  # 10^3, 10^4, 10^5 demos; local, ray, ray2
    python -m tools.bench_engine --sizes 1000 --executors local   # quicker
    python -m tools.bench_engine --task aloha --costs_only        # where one core's time goes (ALOHA)

Each point is one real `augment_demos.py` run (re-solve + shard write + merge + stats) from a
12-episode gen_demos_pusht.py set, timed from outside, with the peak memory of its process tree
sampled every 0.2 s (psutil): the driver alone, the largest single process, and the whole tree.
`ray` is a private local Ray of --workers CPUs; `ray2` is a cluster of two Ray nodes on this
machine (`ray start --head` and a second `ray start --address`, --workers / 2 CPUs each) that the
run joins with `--ray ADDRESS`. Runs of one size must give the same bytes on every executor; the
table says whether they did. Then an estimate for 10^5 and 10^6 demos on 64 and 1,024 cores from
the measured per-core rate and the measured merge cost per demo (assumptions printed beside it).
The physics floor: the env alone stepped through the very frames a run kept, from their recorded
starts (aug.start, the task's place()) with their recorded actions; no expert, no recording, no
writing (the least of FLOOR_REPEATS passes, right after the run). A row's "x phys" is the run's
generation worker-seconds (the shard writes included) over that floor: 1.0 would be a generator that
costs only its physics. First, in this process, the same split for the first --cost_attempts_per_demo
attempts of every source episode: one attempt at a time (datagen.engine.attempt), in lockstep
(datagen.lockstep.attempts_lockstep), the floor, and the write of the kept set (datagen.engine.save),
each run --cost_repeats times alternated, medians.
Writes OUT/bench_engine.json (default outputs/bench_engine; bench_engine_costs.json with
--costs_only); the runs' own folders are removed. Asserts nothing: the figures are for
docs/engine.md.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import gen_demos
from ch37 import ROOT, errors
from ch37.config import DEFAULTS, check
from ch37.errors import DataError
from ch37.ownership import (
    check_out_path,
    check_own_result,
    dump_json,
    is_ours,
    read_stamp,
    round_floats,
    write_atomic,
)
from datagen import Perturbation, engine, known_tasks, lockstep, resume
from lerobot_v3.dataset import load_arrays
from tools.common import parser, provenance

SOURCE_EPISODES = DEFAULTS["source_episodes"]
TABLE = {  # printed column: row key
    "wall s": "wall_s",
    "gen s": "generate_s",
    "write s": "write_s",
    "merge s": "merge_s",
    "merge %": "merge_pct",
    "demos/s": "demos_per_s",
    "/worker": "generate_demos_per_s_per_worker",
    "phys s": "physics_s",
    "x phys": "gen_over_physics",
}
KIND, COSTS = "bench_engine", "bench_engine_costs"  # each JSON's "kind" and name: a re-run replaces its own
EXECUTORS = ("local", "ray", "ray2")  # ray2: two Ray nodes on this machine, joined by address


def tree_digest(root: Path) -> str:
    """sha256 over every file of a run but its report (which holds timings)."""
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.name != "generation_report.json":
            h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def run_sampled(cmd: list[str], env: dict | None = None) -> dict:
    """Run `cmd`; wall seconds and peak RSS (MB) of the driver, of the largest process, of the tree
    (the tree: the driver's descendants; a joined cluster's workers are not its children)."""
    import psutil

    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    root = psutil.Process(proc.pid)
    peak = {"driver": 0, "largest": 0, "tree": 0}
    while proc.poll() is None:
        try:
            procs = [root, *root.children(recursive=True)]
        except psutil.NoSuchProcess:
            break
        rss = {}
        for p in procs:
            try:
                rss[p.pid] = p.memory_info().rss
            except psutil.Error:
                pass
        peak["driver"] = max(peak["driver"], rss.get(proc.pid, 0))
        peak["largest"] = max(peak["largest"], max(rss.values(), default=0))
        peak["tree"] = max(peak["tree"], sum(rss.values()))
        time.sleep(0.2)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        last = (err.strip().splitlines() or [""])[-1]
        raise DataError(f"{' '.join(cmd[1:])} exited {proc.returncode}: {last}")
    return {"wall_s": wall, **{f"peak_rss_{k}_mb": v / 2**20 for k, v in peak.items()}, "stdout": out}


@contextlib.contextmanager
def two_ray_nodes(workers: int):
    """A Ray cluster of two nodes on this machine, as an operator starts one: its address, then stopped.
    `ray start` enables token authentication, so the run that joins needs RAY_AUTH_MODE=token."""
    ray = [str(Path(sys.executable).with_name("ray"))]
    env = os.environ | {"RAY_AUTH_MODE": "token"}
    with socket.socket() as s:  # a free port for the head's GCS
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cpus = [str(max(1, workers // 2)), str(max(1, workers - workers // 2))]
    quiet = dict(env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        head = ["--head", f"--port={port}", "--include-dashboard=false"]
        for where, n in ((head, cpus[0]), ([f"--address=127.0.0.1:{port}"], cpus[1])):
            subprocess.run([*ray, "start", *where, f"--num-cpus={n}", "--disable-usage-stats"], **quiet)
        yield f"127.0.0.1:{port}", env
    finally:
        subprocess.run(
            [*ray, "stop", "--force"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )


def remove_run(run_dir: Path) -> None:
    """Remove an engine run this tool made (resume.foreign finds nothing else in it); refuse otherwise."""
    if not run_dir.exists():
        return
    stamp = read_stamp(run_dir)
    if not is_ours(stamp) or stamp.get("kind") != "engine" or resume.foreign(run_dir, stamp):
        raise DataError(f"{run_dir} holds files this tool did not write; move it elsewhere")
    shutil.rmtree(run_dir)


def point(src: Path, out: Path, n: int, executor: str, a) -> dict:
    workers, shard_size = a.workers, a.shard_size
    attempts_per_demo = math.ceil(n / SOURCE_EPISODES)
    run_dir = out / "runs" / f"n{n}-{executor}"
    remove_run(run_dir)  # an earlier run of this tool; anything else is refused
    cmd = [sys.executable, str(a.checkout / "augment_demos.py"), "--src", str(src), "--out", str(run_dir)]
    # --per_demo: augment_demos' --attempts_per_demo under the spelling every --checkout understands
    cmd += ["--per_demo", str(attempts_per_demo), "--workers", str(workers), "--quiet"]
    cmd += ["--shard_size", str(shard_size)] if shard_size else []
    cmd += ["--seed", str(a.seed), "--mode", a.mode]
    if executor == "ray2":
        with two_ray_nodes(workers) as (address, env):
            m = run_sampled([*cmd, "--ray", address], env)
    else:
        m = run_sampled(cmd + (["--ray"] if executor == "ray" else []))
    rep = json.loads((run_dir / "generation_report.json").read_text())
    gen, start, merge = rep["seconds_generate"], rep["seconds_start_executor"], rep["seconds_merge"]
    shards, wall = rep["shards"]["total"], m.pop("wall_s")
    row = {"demos_requested": n, "executor": executor, "workers": workers, "shards": shards}
    row |= {k: rep[k] for k in ("attempts", "kept", "yield", "frames")} | {"wall_s": wall}
    row |= {"generate_s": gen, "start_executor_s": start, "merge_s": merge}  # start_executor_s: of generate_s
    row |= {"write_s": rep.get("seconds_write", math.nan)}  # worker seconds, inside generate_s
    row |= {
        "other_s": wall - gen - merge,
        "demos_per_s": rep["kept"] / wall,
        "merge_s_per_shard": merge / shards,
        "merge_s_per_demo": merge / max(rep["kept"], 1),
        "merge_pct": 100 * merge / wall,
    }
    row |= {"generate_demos_per_s_per_worker": rep["kept"] / (gen - start) / workers}
    row |= {"shard_size": rep["settings"]["shard_size"], "sha256": tree_digest(run_dir)}
    # the run's generation worker-seconds (its shard writes included) over its kept frames' physics
    kept = rep["kept"]
    row["physics_s"] = (
        physics_floor(known_tasks()[a.task], kept_runs(run_dir), FLOOR_REPEATS) if kept else math.nan
    )
    row["gen_over_physics"] = (gen - start) * workers / row["physics_s"]
    row |= {"summary": m.pop("stdout").strip().splitlines()[-1], **m}  # m: the peak RSS
    remove_run(run_dir)
    return row


FLOOR_REPEATS = 3  # a run's floor is the least of 3: bursts of load on this machine slow one by up to 1.7x


def physics_floor(task, runs, repeats: int = 1) -> float:
    """Seconds the env alone takes over kept frames: for each (start, actions (T, act_dim)) in `runs`,
    task.place(env, start) then env.step per action; no expert, no recording, no writing. The least
    of `repeats` passes."""
    env = task.make_env()
    runs = [([float(v) for v in start], list(actions)) for start, actions in runs]
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for start, actions in runs:
            task.place(env, start)
            for act in actions:
                env.step(act)
        best = min(best, time.perf_counter() - t0)
    return best


def kept_runs(root: Path) -> list:
    """(recorded start, recorded actions) of every episode of an engine run's merged set."""
    arrays = load_arrays(root, keys=("episode_index", "action", "aug.start"))
    cuts = np.flatnonzero(np.diff(arrays["episode_index"])) + 1
    return [(s[0], a) for s, a in zip(np.split(arrays["aug.start"], cuts), np.split(arrays["action"], cuts))]


def per_demo_costs(
    task, src: Path, attempts_per_demo: int, seed: int, repeats: int, mode: str = "resolve"
) -> dict:
    """Where one core's time goes, in this process, for augment_demos.py's first attempts_per_demo
    attempts of every source episode at `seed` in `mode`: one attempt at a time, in lockstep (where the
    task's mode has lanes; else the same one at a time), the physics floor of the kept frames, and the
    engine's write of the kept set; `repeats` rounds, alternated, medians."""
    sources = engine.sources(load_arrays(src))
    jobs = [(e, k) for e in sorted(sources) for k in range(attempts_per_demo)]
    how = Perturbation(seed=seed, pos_sigma=DEFAULTS["aug_pos_sigma"], yaw_sigma=DEFAULTS["aug_yaw_sigma"])
    sims = engine.Simulators()  # the envs (and plans) both sides reuse, made once
    engine.attempt(task, sources[jobs[0][0]], 10**6, how, mode=mode, sims=sims)  # warm up
    times = {"one_at_a_time_s": [], "lockstep_s": [], "physics_s": [], "write_s": []}
    for _ in range(repeats):
        t0 = time.perf_counter()
        one = [engine.attempt(task, sources[e], k, how, mode=mode, sims=sims) for e, k in jobs]
        t1 = time.perf_counter()
        together = lockstep.attempts_lockstep(task, sources, jobs, how, mode=mode, sims=sims)
        t2 = time.perf_counter()
        kept = [r.episode for r in together if r.kept]
        if sum(r.kept for r in one) != len(kept):
            raise DataError("lockstep kept another set than one attempt at a time")
        physics = physics_floor(task, ((ep["aug.start"][0], ep["action"]) for ep in kept))
        with tempfile.TemporaryDirectory() as tmp:  # the engine's own writer, whatever columns it adds
            t3 = time.perf_counter()
            engine.save(task, Path(tmp) / "set", kept, repo_id="local/x", stamp={})
            t4 = time.perf_counter()
        for key, v in zip(times, (t1 - t0, t2 - t1, physics, t4 - t3)):
            times[key].append(v)
    med = {k: float(np.median(v)) for k, v in times.items()}
    frames = sum(len(ep["action"]) for ep in kept)
    return {
        "task": task.name,
        "mode": mode,
        "attempts": len(jobs),
        "kept": len(kept),
        "frames": frames,
        **med,
        "runs": times,
        "one_at_a_time_over_physics": med["one_at_a_time_s"] / med["physics_s"],
        "lockstep_over_physics": med["lockstep_s"] / med["physics_s"],
        "lockstep_and_write_over_physics": (med["lockstep_s"] + med["write_s"]) / med["physics_s"],
        "physics_us_per_frame": med["physics_s"] / frames * 1e6,
        "write_us_per_frame": med["write_s"] / frames * 1e6,
    }


def estimate(rows: list[dict], cores_list=(64, 1024)) -> dict:
    """10^5 and 10^6 demos on clusters of `cores_list` cores, from the largest measured local run."""
    big = max(r["demos_requested"] for r in rows)
    at = {r["executor"]: r for r in rows if r["demos_requested"] == big}
    base = at.get("local") or next(iter(at.values()))
    rate = base["generate_demos_per_s_per_worker"]  # validated demos per second per core, write included
    ray = at.get("ray2") or at.get("ray")
    busy = lambda r: r["generate_s"] - r["start_executor_s"]  # noqa: E731
    ray_factor = busy(ray) / busy(base) if ray and base is not ray else 1.0
    fixed = (ray or base)["other_s"] + (ray or base)["start_executor_s"]  # imports, source, Ray
    merge_per_demo = base["merge_s_per_demo"]
    out = {
        "measured_at_demos": big,
        "per_core_demos_per_s": rate,
        "ray_vs_local_generate_time": ray_factor,
        "fixed_s": fixed,
        "merge_s_per_demo": merge_per_demo,
        "assumptions": [
            f"every cluster core makes demos at this machine's measured rate per worker ({rate:.1f}/s, "
            "write included) and shards scale perfectly (they share nothing)",
            f"Ray's overhead on the generation is the measured ratio to the local pool ({ray_factor:.2f})",
            f"fixed cost (imports, reading the source, starting Ray) as measured here ({fixed:.0f} s)",
            f"the merge runs on the driver alone, linear in demos at {merge_per_demo * 1e3:.2f} ms a demo"
            " (it places each shard once, counts the stats as it writes, and reads the numbers back"
            " once or twice for the exact quantiles)",
            "shard bytes reach the driver as fast as they are made (~0.4 MB per 100 demos; 10^6: ~4 GB)",
            "yield as measured (about 1.0 for resolve)",
        ],
    }
    for cores in cores_list:
        for n in (10**5, 10**6):
            gen = n / (rate * cores) * ray_factor
            merge = n * merge_per_demo
            total = fixed + gen + merge
            out[f"{n}@{cores}"] = {
                "generate_s": gen,
                "merge_s": merge,
                "total_s": total,
                "demos_per_s": n / total,
            }
    return out


def main(argv: list[str]) -> int:
    p = parser("bench_engine", __doc__)
    p.add_argument(
        "--task", choices=sorted(known_tasks()), default="pusht", help="the task grown (its generator's set)"
    )
    p.add_argument(
        "--mode", choices=("resolve", "replay"), default="resolve", help="augment_demos.py's --mode"
    )
    p.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000], help="demos per run")
    p.add_argument("--executors", nargs="+", choices=EXECUTORS, default=list(EXECUTORS))
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes / Ray CPUs")
    p.add_argument("--shard_size", type=int, help="attempts per shard (default: augment_demos.py's)")
    p.add_argument(
        "--seed", type=int, default=1, help="augment_demos.py's --seed for every run and the costs"
    )
    p.add_argument(
        "--cost_attempts_per_demo", type=int, default=50, help="attempts per source episode of the costs"
    )
    p.add_argument("--cost_repeats", type=int, default=3, help="rounds of the in-process costs (0: none)")
    p.add_argument("--costs_only", action="store_true", help="only the in-process costs (no runs)")
    p.add_argument("--src", type=Path, help="a set of --task (default: a 12-episode set made under --out)")
    p.add_argument("--out", type=Path, default=ROOT / "outputs" / "bench_engine")
    help = "the checkout whose augment_demos.py runs (default this one); another commit's for a before/after"
    p.add_argument("--checkout", type=Path, default=ROOT, help=help)
    a = p.parse_args(argv)
    check(a, positive=("workers", "cost_attempts_per_demo"), non_negative=("seed", "cost_repeats"))
    if not (a.checkout / "augment_demos.py").is_file():
        raise DataError(f"--checkout {a.checkout} has no augment_demos.py")
    if min(a.sizes) < 1:
        raise DataError("--sizes must be positive")
    if problem := check_out_path(a.out):  # before the source set and the runs are made under it
        raise DataError(problem)
    result_kind = COSTS if a.costs_only else KIND  # an earlier run's may be replaced, a user's file never
    check_own_result(a.out / f"{result_kind}.json", result_kind)
    task = known_tasks()[a.task]
    src = a.src or a.out / f"src_{task.name}_seed0_ep{SOURCE_EPISODES}"
    if a.src is None and not (src / "meta" / "info.json").exists():
        if gen_demos.main(task, ["--episodes", str(SOURCE_EPISODES), "--out", str(src), "--quiet"]) != 0:
            raise DataError(f"could not make the source set at {src}")
    costs = {}
    if a.cost_repeats:
        costs = c = per_demo_costs(task, src, a.cost_attempts_per_demo, a.seed, a.cost_repeats, a.mode)
        print(
            f"this checkout, one core, {task.title} {a.mode}: {c['attempts']} attempts, {c['kept']} kept "
            f"({c['frames']} frames), "
            f"medians of {a.cost_repeats} in this process: one at a time {c['one_at_a_time_s']:.2f} s, "
            f"lockstep {c['lockstep_s']:.2f} s, physics floor {c['physics_s']:.2f} s, write "
            f"{c['write_s']:.2f} s; lockstep {c['lockstep_over_physics']:.2f}x the physics "
            f"({c['lockstep_and_write_over_physics']:.2f}x with the write), "
            f"one at a time {c['one_at_a_time_over_physics']:.2f}x"
        )
    if a.costs_only:
        result = {"kind": COSTS, "per_demo_costs": costs, "provenance": provenance(a.script)}
        path = write_atomic(a.out / f"{COSTS}.json", dump_json(round_floats(result, 4)))
        print(f"wrote {path}")
        return 0
    rows = []
    head = " ".join(f"{h:>7s}" for h in TABLE)
    print(f"{'demos':>6s} {'executor':8s} {'kept':>6s} {head} {'RSS MB driver/largest/tree':>27s}")
    for n in a.sizes:
        for ex in a.executors:
            r = point(src, a.out, n, ex, a)
            rows.append(r)
            rss = f"{r['peak_rss_driver_mb']:.0f}/{r['peak_rss_largest_mb']:.0f}/{r['peak_rss_tree_mb']:.0f}"
            cells = " ".join(f"{r[k]:7.1f}" for k in TABLE.values())
            print(f"{n:6d} {ex:8s} {r['kept']:6d} {cells} {rss:>27s}", flush=True)
        same = {r["sha256"] for r in rows if r["demos_requested"] == n}
        if len(a.executors) > 1:
            print(f"{n:6d} outputs byte-identical across {', '.join(a.executors)}: {len(same) == 1}")
    est = estimate(rows)
    for key, e in est.items():
        if "@" in key:
            n, cores = map(int, key.split("@"))
            print(
                f"estimate {n:>9,d} demos on {cores:>5,d} Ray cores: {e['total_s'] / 60:6.1f} min "
                f"({e['demos_per_s']:.0f} demos/s; generate {e['generate_s'] / 60:.1f} min, "
                f"merge {e['merge_s'] / 60:.1f} min)"
            )
    print("assumptions: " + "; ".join(est["assumptions"]))
    same = {str(n): len({r["sha256"] for r in rows if r["demos_requested"] == n}) == 1 for n in a.sizes}
    result = {
        "kind": KIND,
        "task": task.name,
        "per_demo_costs": costs,
        "runs": rows,
        "estimate": est,
        "checkout": str(a.checkout.resolve()),
    }
    result |= {"provenance": provenance(a.script), "identical_across_executors": same}
    path = write_atomic(a.out / f"{KIND}.json", dump_json(round_floats(result, 4)))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    errors.main(main)
