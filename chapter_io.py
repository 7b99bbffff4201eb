"""Plumbing for scale_data.py: the demo cache, atomic writes, the wall-clock banner.

None of this is the lesson; it keeps the chapter's regions short and keeps user data safe:
a directory is deleted only when a stamp written by this project says the project made it.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import sys
from pathlib import Path

import demo_data
import demo_gen

ROOT = Path(__file__).resolve().parent


def fail(msg: str, code: int = 2):
    """One clear line on stderr and a non-zero exit: the contract for bad input."""
    print(f"error: {msg}", file=sys.stderr)
    sys.exit(code)


def ensure_demos(emb, path: Path, *, user_given: bool, episodes: int, seed: int, noise: float,
                 quiet: bool) -> str:
    """Make sure `path` holds the demo set this run needs; return how it was obtained.

    user_given: a set named by --pusht_data/--aloha_data. It is never modified. A set stamped by
    this project must match the request; an unstamped set must have the right schema and is used
    as given. Otherwise (our private cache) a stale set we made is rebuilt, and a directory we did
    not make is refused.
    """
    m = emb.env_module
    want = demo_gen.stamp_for(emb, episodes=episodes, seed=seed, noise=noise, video=False)
    stamp = demo_data.read_stamp(path)
    ours = stamp is not None and stamp.get("made_by") == want["made_by"]
    if user_given:
        if not demo_data.holds_data(path):
            raise demo_data.DataError(f"{path} does not exist or is empty; generate it with gen_demos_{emb.name}.py first")
        if ours and stamp != want:
            diff = ", ".join(f"{k}={stamp.get(k)} (need {v})" for k, v in want.items() if stamp.get(k) != v)
            raise demo_data.DataError(f"{path} does not match this run: {diff}; pass matching flags or another set")
        problem = demo_data.schema_problem(path, len(m.STATE_NAMES), len(m.ACTION_NAMES))
        if problem:
            raise demo_data.DataError(problem)
        return "matches its stamp" if ours else "your own set, used as given"
    if ours and stamp == want:
        return "cached"
    replace_own_dir(path)  # a stale set we made is rebuilt; anything else is refused
    s = demo_gen.generate(emb, path, episodes=episodes, seed=seed, noise=noise, quiet=quiet)
    return f"generated ({s['successes']}/{s['episodes']} expert successes)"


def replace_own_dir(path: Path) -> None:
    """Clear `path` for rewriting if this project made it; refuse if it holds anything else."""
    if not demo_data.holds_data(path):
        return
    stamp = demo_data.read_stamp(path)
    if stamp is None or stamp.get("made_by") != demo_data.MADE_BY:
        raise demo_data.DataError(f"{path} holds data this program did not make; move it or pass another --out")
    shutil.rmtree(path)


def write_atomic(path: Path, text: str) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, text.encode())


def dump_json(obj) -> str:
    return json.dumps(obj, sort_keys=True, indent=1) + "\n"


def round_floats(obj, digits: int = 4):
    """Round every float in a nested structure so metrics.json is stable and readable."""
    if isinstance(obj, float):
        return round(obj, digits)
    if isinstance(obj, dict):
        return {k: round_floats(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [round_floats(v, digits) for v in obj]
    return obj


def device_tier(device: str) -> str:
    """wallclock.csv tier name for the device in use."""
    if device == "cuda":
        import torch

        name = torch.cuda.get_device_name(0).lower()
        for tier in ("t4", "4090", "a100", "h100", "h200", "l4"):
            if tier in name:
                return tier
        return "cuda-other"
    return {"mps": "mps"}.get(device, "cpu-2core")


def expected_wallclock(tier: str, csv_path: Path = ROOT / "wallclock.csv") -> str:
    try:
        rows = list(csv.DictReader(csv_path.open()))
    except OSError:
        rows = []
    for r in rows:
        if r.get("tier") == tier and r.get("status") == "measured":
            return f"about {float(r['minutes']):.1f} min for the default run (wallclock.csv, measured {r['date']})"
    return "default-run wall-clock not yet measured for this tier"


# --- result cache: a finished run is reused when its flags and every file that shapes it match ---
CODE_FILES = ("scale_data.py", "pusht_env.py", "pusht.xml", "aloha_env.py", "aloha.xml", "scripted_expert.py",
              "demo_gen.py", "demo_data.py", "gen_demos_pusht.py", "gen_demos_aloha.py", "chapter_viz.py",
              "chapter_io.py", "mlp_grads.py")  # chapter_io steps the evaluation envs; mlp_grads trains
RESULT_FILES = ("metrics.json", "cross_embodiment.json", "scale_data.png", "scale_data.rrd")
NOT_IN_KEY = ("out", "cache", "workers")  # where results go and how fast they come do not change them


def cache_root() -> Path:
    return Path(os.environ.get("CH37_CACHE_DIR", ROOT / "outputs" / ".result_cache"))


def _tree_digest(h, path: Path) -> None:
    for p in sorted(Path(path).rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(path)).encode())
            h.update(p.read_bytes())


def result_key(config: dict) -> str:
    """sha256 of the configuration, the code that shapes the result, package versions and user data."""
    import hashlib
    from importlib.metadata import version

    h = hashlib.sha256(json.dumps({k: str(v) for k, v in config.items() if k not in NOT_IN_KEY},
                                  sort_keys=True).encode())
    for name in CODE_FILES:
        h.update(name.encode())
        h.update((ROOT / name).read_bytes())
    for pkg in ("torch", "lerobot", "mujoco", "numpy"):
        h.update(f"{pkg}=={version(pkg)}".encode())
    for key in ("pusht_data", "aloha_data"):  # a user's own set: its bytes are part of the input
        if config.get(key):
            _tree_digest(h, Path(config[key]))
    return h.hexdigest()[:24]


def replay_cached(key: str, out: Path) -> bool:
    """Copy a cached run's outputs into `out` and print its summary; False if there is none."""
    src = cache_root() / key
    if not (src / "metrics.json").exists():
        return False
    out.mkdir(parents=True, exist_ok=True)
    for name in RESULT_FILES:
        if (src / name).exists():
            write_bytes_atomic(out / name, (src / name).read_bytes())
    print(f"reusing the result of an identical earlier run (same flags and code, cache key {key}; --no-cache runs it again)")
    print((src / "summary.txt").read_text().replace("{out}", str(out)), end="")
    return True


def store_result(key: str, out: Path, summary: str) -> None:
    dst = cache_root() / key
    tmp = dst.with_name(f".{key}.tmp-{os.getpid()}")
    tmp.mkdir(parents=True, exist_ok=True)
    for name in RESULT_FILES:
        if (out / name).exists():
            shutil.copyfile(out / name, tmp / name)
    (tmp / "summary.txt").write_text(summary.replace(str(out), "{out}"))
    if dst.exists():
        shutil.rmtree(dst)  # our own cache entry for the same key
    tmp.rename(dst)


def write_bytes_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_bytes(data)
    os.replace(tmp, path)


_FORKED_WORK: tuple = ()  # (fn, jobs), set just before forking so workers inherit it unpickled


def _run_job(i: int):
    fn, jobs = _FORKED_WORK
    return fn(jobs[i])


def parallel_map(fn, jobs: list, *, workers: int, bar) -> list:
    """[fn(j) for j in jobs], in order, on `workers` forked processes; the result never depends on
    `workers`, because every job carries its own seed. Falls back to one process without fork.
    `fn` is inherited through fork, not pickled, so a function defined in a script or notebook works."""
    import multiprocessing as mp

    global _FORKED_WORK
    out = []
    if workers > 1 and len(jobs) > 1 and "fork" in mp.get_all_start_methods():
        _FORKED_WORK = (fn, jobs)
        try:
            with mp.get_context("fork").Pool(min(workers, len(jobs))) as pool:
                for r in pool.imap(_run_job, range(len(jobs)), chunksize=max(1, len(jobs) // (4 * workers))):
                    out.append(r)
                    bar.update()
        finally:
            _FORKED_WORK = ()
    else:
        for j in jobs:
            out.append(fn(j))
            bar.update()
    bar.close()
    return out


class LockstepEnvs:
    """`len(seeds)` environments from `make_env()`, reset to `seeds` and stepped together, their
    physics spread over `workers` forked processes (env i lives in worker i % workers) while the
    caller keeps the policy. The result never depends on `workers`: every env is its own simulator
    and receives the same actions. One process (no fork, or workers=1) runs them all in place.

        with LockstepEnvs(PushTEnv, seeds, workers=2) as envs:
            obs = envs.reset()                        # (N, obs_dim)
            obs[idx], done, success = envs.step(idx, actions)   # idx: envs still running
    """

    def __init__(self, make_env, seeds, *, workers: int):
        import multiprocessing as mp

        self.seeds = [int(s) for s in seeds]
        n = max(1, min(workers, len(self.seeds)))
        self.parts = [list(range(w, len(self.seeds), n)) for w in range(n)]  # env indices per worker
        self.conns, self.procs, self.local = [], [], None
        if n == 1 or "fork" not in mp.get_all_start_methods():
            self.parts, self.local = [list(range(len(self.seeds)))], [make_env() for _ in self.seeds]
            return
        ctx = mp.get_context("fork")
        for part in self.parts:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_env_worker, args=(child, make_env, [self.seeds[i] for i in part], len(self.procs)), daemon=True)
            proc.start()
            child.close()
            self.conns.append(parent)
            self.procs.append(proc)

    def _ask(self, msgs: dict) -> dict:
        """{worker: request} -> {worker: reply}; every request is sent before any reply is read."""
        if self.local is not None:
            return {w: _env_serve(self.local, self.seeds, *m) for w, m in msgs.items()}
        for w, m in msgs.items():
            self.conns[w].send(m)
        out = {w: self.conns[w].recv() for w in msgs}
        for r in out.values():
            if isinstance(r, BaseException):
                raise r
        return out

    def reset(self):
        import numpy as np

        replies = self._ask({w: ("reset", None) for w in range(len(self.parts))})
        self.obs_dim, self.obs_dtype = replies[0].shape[1], replies[0].dtype
        obs = np.zeros((len(self.seeds), self.obs_dim), self.obs_dtype)
        for w, part in enumerate(self.parts):
            obs[part] = replies[w]
        return obs

    def step(self, idx, actions):
        """Step envs `idx` with `actions` (len(idx), act_dim); returns their
        (obs (len(idx), obs_dim), done (len(idx),) bool, success (len(idx),) bool)."""
        import numpy as np

        row = {int(i): k for k, i in enumerate(idx)}  # env index -> row of `actions`
        asks = {}  # worker -> [(its local env index, row)]
        for w, part in enumerate(self.parts):
            mine = [(j, row[i]) for j, i in enumerate(part) if i in row]
            if mine:
                asks[w] = mine
        replies = self._ask({w: ("step", ([j for j, _ in m], actions[[k for _, k in m]])) for w, m in asks.items()})
        obs = np.zeros((len(row), self.obs_dim), self.obs_dtype)
        done, success = np.zeros(len(row), bool), np.zeros(len(row), bool)
        for w, m in asks.items():
            rows = [k for _, k in m]
            obs[rows], done[rows], success[rows] = replies[w]
        return obs, done, success

    def close(self) -> None:
        for conn in self.conns:
            conn.send(None)
            conn.close()
        for proc in self.procs:
            proc.join()
        self.conns, self.procs = [], []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _env_serve(envs, seeds, cmd, arg):
    """One request on a list of envs: ("reset", None) -> obs; ("step", (local idx, actions)) ->
    (obs, done, success), arrays in the order asked."""
    import numpy as np

    if cmd == "reset":
        return np.stack([e.reset(s) for e, s in zip(envs, seeds)])
    local, actions = arg
    obs, done, success = [], np.zeros(len(local), bool), np.zeros(len(local), bool)
    for k, (j, a) in enumerate(zip(local, actions)):
        o, _, done[k], info = envs[j].step(a)
        obs.append(o)
        success[k] = info["success"]
    return np.stack(obs), done, success


def _env_worker(conn, make_env, seeds, rank: int) -> None:
    if hasattr(os, "sched_setaffinity"):  # one core each: woken together, they would otherwise
        cpus = sorted(os.sched_getaffinity(0))  # often queue on the core of the process that woke them
        os.sched_setaffinity(0, {cpus[rank % len(cpus)]})
    envs = [make_env() for _ in seeds]
    while (msg := conn.recv()) is not None:
        try:
            conn.send(_env_serve(envs, seeds, *msg))
        except Exception as e:  # the caller re-raises it
            conn.send(e)
    conn.close()
