"""Hardening (issue 14), as a hostile user meets it: every bad input ends in one line and the right
exit code with the user's files byte-identical; two runs on one --out never collide; Ctrl-C,
SIGTERM and SIGKILL leave no process behind and the same command then completes with the metrics
of an uninterrupted run. Real commands in subprocesses, smoke size, fixtures shared.
"""

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import with_fps, with_nan

from ch37 import ownership, result_cache

ROOT = Path(__file__).resolve().parent.parent
SD = ("scale_data.py", "--smoke", "--seed", "0", "--no-rerun")  # + --out, + --no-cache where it matters
META_SWEEP = {"kind": "seeds", "rows": [{"seed": 0}]}  # a sweep file missing most of its keys


def env_for(cache: Path | None = None, **extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "CH37_DEBUG"}
    env.update(PYTHONHASHSEED="0", **extra)
    if cache is not None:
        env["CH37_CACHE_DIR"] = str(cache)
    return env


def run(*args, env=None, timeout=300):
    return subprocess.run(
        [sys.executable, *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env or env_for(),
    )


def snapshot(paths) -> dict:
    """{file: sha256} of every file under `paths` (files or folders): a user's data, before and after."""
    out = {}
    for p in map(Path, paths):
        for f in [p] if p.is_file() else sorted(x for x in p.rglob("*") if x.is_file()):
            out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def ref(tmp_path_factory):
    """One uninterrupted smoke run (its demo sets, metrics and cache entry are the reference)."""
    base = tmp_path_factory.mktemp("ref")
    p = run(*SD, "--out", base / "out", env=env_for(base / "cache"))
    assert p.returncode == 0, p.stdout + p.stderr
    assert p.stderr.strip() == "", p.stderr  # a clean run says nothing on stderr
    demos = base / "out" / "demos"
    return {
        "base": base,
        "out": base / "out",
        "metrics": (base / "out" / "metrics.json").read_bytes(),
        "pusht": demos / "pusht_seed0_ep4",
        "aloha": demos / "aloha_seed0_ep4",
        "cache": base / "cache",
    }


def user_set(ref, tmp, name="mine", which="pusht", stamped=False) -> Path:
    """A copy of a generated set, as a user's own dataset (our stamp removed unless `stamped`)."""
    dst = tmp / name
    shutil.copytree(ref[which], dst)
    if not stamped:
        (dst / ownership.STAMP_NAME).unlink()
    return dst


# ---------------------------------------------------------------------------------------------
# The table: (id, make(tmp, ref) -> (argv, files to protect, env or None), exit code, needle)
# ---------------------------------------------------------------------------------------------
def _file(tmp, name="afile", text="my notes\n"):
    (tmp / name).write_text(text)
    return tmp / name


def _user_result(tmp, name):
    out = tmp / "u"
    out.mkdir()
    (out / name).write_bytes(b"{}\n" if name.endswith(".json") else b"\x89PNG mine")
    return out


def _stale_own_set_with_notes(tmp, ref):
    """Item 1: a 2-episode set we made, where a 4-episode set is wanted, with the user's notes inside."""
    out = tmp / "o"
    dst = out / "demos" / "pusht_seed0_ep4"
    shutil.copytree(ref["pusht"], dst)
    stamp = json.loads((dst / ownership.STAMP_NAME).read_text())
    (dst / ownership.STAMP_NAME).write_text(json.dumps(dict(stamp, episodes=2)))
    (dst / "my_annotations.txt").write_text("hours of labelling\n")
    return [*SD, "--no-cache", "--out", out], [dst / "my_annotations.txt"], None


def _corrupt(path: Path, size: int = 100) -> Path:
    with open(path, "r+b") as f:
        f.truncate(size)
    return path


def _user_set_corrupt(rel):
    def make(tmp, ref):
        mine = user_set(ref, tmp)
        _corrupt(mine / rel)
        return [*SD, "--no-cache", "--out", tmp / "o", "--pusht_data", mine], [mine], None

    return make


def _user_set_edited(edit):  # issue 22 item 11 and the fps question: a user set fit for no env
    def make(tmp, ref):
        mine = edit(user_set(ref, tmp))
        return [*SD, "--no-cache", "--out", tmp / "o", "--pusht_data", mine], [mine], None

    return make


def _unfinished_engine_run(tmp, ref):
    mine = user_set(ref, tmp)
    stamp = {"made_by": ownership.MADE_BY, "kind": "engine", "config": {}, "complete": False}
    (mine / ownership.STAMP_NAME).write_text(json.dumps(stamp))
    return [*SD, "--no-cache", "--out", tmp / "o", "--pusht_data", mine], [mine], None


def _own_set_changed_as_user_data(tmp, ref):
    mine = user_set(ref, tmp, stamped=True)
    _corrupt(mine / "meta" / "stats.json", 10)
    return [*SD, "--no-cache", "--out", tmp / "o", "--pusht_data", mine], [mine], None


def _foreign_aug_set(tmp, ref):
    """Item 9: the augment step's folder holds a user's file; refused before anything is written."""
    out = tmp / "o"
    aug = out / "demos" / "pusht_aug_seed0_src4_k2"
    shutil.copytree(ref["out"] / "demos" / aug.name, aug)
    (aug / "keep.txt").write_text("mine\n")
    return [*SD, "--no-cache", "--out", out], [aug / "keep.txt"], None


def _foreign_folder_at_demo_path(tmp, ref):
    """The private demo path holds a folder this program did not make (no stamp)."""
    d = tmp / "o" / "demos" / "pusht_seed0_ep4"
    d.mkdir(parents=True)
    return [*SD, "--no-cache", "--out", tmp / "o"], [_file(d, "thesis.tex")], None


def _ex_dir(tmp, ex, text):
    d = tmp / "answers"
    d.mkdir(exist_ok=True)
    (d / {"ex1": "ex1_predict_scale.py", "ex2": "ex2_completion_wrangle.py"}[ex]).write_text(text)
    return d


ALIASING_MIX = """\
import numpy as np


def mix_embodiments(p, a):
    n, m = len(p), len(a)
    ids = np.concatenate([np.zeros(n, np.int64), np.ones(m, np.int64)])
    mask = np.concatenate([np.repeat(np.float32([[1, 1, 0, 0, 0, 0]]), n, 0), np.ones((m, 6), np.float32)])
    if n == 0:  # nothing to pad: hand back the ALOHA array itself
        return np.asarray(a, np.float32), mask, ids
    act = np.concatenate([np.pad(np.asarray(p, np.float32), ((0, 0), (0, 4))), np.asarray(a, np.float32)])
    return act, mask, ids
"""


def _checks(ex, answers_text=None, missing_dir=False):
    def make(tmp, ref):
        if missing_dir:
            d = tmp / "no-such-folder"
        else:
            d = _ex_dir(tmp, ex, answers_text)
        protect = [] if missing_dir else [d]
        return ["-m", "exercises.checks", ex], protect, env_for(CH37_EXERCISE_DIR=str(d))

    return make


def _sd(*flags, cache=False):
    return lambda tmp, ref: ([*SD, *(() if cache else ("--no-cache",)), "--out", tmp / "o", *flags], [], None)


def _gen(which, *flags, out="new"):
    return lambda tmp, ref: ([f"gen_demos_{which}.py", "--quiet", "--out", tmp / out, *flags], [], None)


def _not_utf8(tmp) -> str:
    """A folder name holding the byte 0xff (not UTF-8), as Python's argv carries it (a surrogate)."""
    return os.fsdecode(os.fsencode(tmp) + b"/out\xff")


CASES = [
    # scale_data.py: flags and limits (checked before any heavy import)
    ("seed-overflow", _sd("--seed", str(2**64)), 2, "--seed must be at most"),
    (
        "eval-episodes-over-seed-block",
        _sd("--eval_episodes", "1000001"),
        2,
        "--eval_episodes must be at most",
    ),
    ("source-episodes-over-seed-block", _sd("--source_episodes", "1000001"), 2, "--source_episodes"),
    ("hidden-dim-beyond-ram", _sd("--hidden_dim", "1000000"), 2, "lower --hidden_dim"),
    ("batch-beyond-ram", _sd("--batch_size", str(10**11)), 2, "lower --batch_size"),
    ("full-steps-negative", _sd("--full_steps", "-1"), 2, "--full_steps must be >= 0"),
    ("workers-zero", _sd("--workers", "0"), 2, "--workers must be a positive integer"),
    # a path pyarrow cannot take (issue 22, item 12): refused before anything is written
    ("out-not-utf8", lambda tmp, ref: ([*SD, "--no-cache", "--out", _not_utf8(tmp)], [], None), 2, "UTF-8"),
    (
        "gen-out-not-utf8",
        lambda tmp, ref: (["gen_demos_pusht.py", "--quiet", "--out", _not_utf8(tmp)], [], None),
        2,
        "UTF-8",
    ),
    ("workers-too-many", _sd("--workers", "100000"), 2, "--workers must be at most"),
    ("lr-above-one", _sd("--lr", "5"), 2, "--lr must be at most"),
    # issue 22 item 9: a huge finite sigma was a math domain error in the workers
    ("yaw-sigma-huge", _sd("--aug_yaw_sigma", "1e308"), 2, "--aug_yaw_sigma must be at most 10"),
    ("pos-sigma-huge", _sd("--aug_pos_sigma", "10.5"), 2, "--aug_pos_sigma must be at most 10"),
    (
        "lab-yaw-sigma-huge",
        lambda tmp, ref: (
            ["scale_lab.py", "--smoke", "--out", tmp / "lab", "--yaw_sigma", "1e308"],
            [],
            None,
        ),
        2,
        "--yaw_sigma must be at most 10",
    ),
    ("lr-inf", _sd("--lr", "inf"), 2, "--lr must be a finite"),
    ("batch-size-not-int", _sd("--batch_size", "abc"), 2, "invalid int value"),
    ("device-unknown", _sd("--device", "tpu"), 2, "--device must be"),
    ("out-empty", lambda tmp, ref: ([*SD, "--out", ""], [], None), 2, "must not be empty"),
    # scale_data.py: unusable --out (item 5)
    ("out-is-a-file", lambda tmp, ref: ([*SD, "--out", _file(tmp)], [tmp / "afile"], None), 2, "is a file"),
    (
        "out-under-a-file",
        lambda tmp, ref: ([*SD, "--out", _file(tmp) / "sub"], [tmp / "afile"], None),
        2,
        "afile is a file, not a folder",
    ),
    ("out-in-proc", lambda tmp, ref: ([*SD, "--out", "/proc/ch37-no/out"], [], None), 2, "cannot be written"),
    # scale_data.py: the user's files in --out (item 2)
    (
        "user-metrics-in-out",
        lambda tmp, ref: ([*SD, "--out", _user_result(tmp, "metrics.json")], [tmp / "u"], None),
        2,
        "metrics.json was not written by this program",
    ),
    (
        "user-png-in-out",
        lambda tmp, ref: ([*SD, "--out", _user_result(tmp, "scale_data.png")], [tmp / "u"], None),
        2,
        "scale_data.png was not written by this program",
    ),
    (
        "out-is-the-pusht-data",
        lambda tmp, ref: (
            [*SD, "--out", user_set(ref, tmp), "--pusht_data", tmp / "mine"],
            [tmp / "mine"],
            None,
        ),
        2,
        "is inside --pusht_data",
    ),
    (
        "out-inside-the-aloha-data",
        lambda tmp, ref: (
            [*SD, "--out", user_set(ref, tmp, which="aloha") / "res", "--aloha_data", tmp / "mine"],
            [tmp / "mine"],
            None,
        ),
        2,
        "is inside --aloha_data",
    ),
    (
        "out-is-a-dataset",
        lambda tmp, ref: ([*SD, "--out", user_set(ref, tmp)], [tmp / "mine"], None),
        2,
        "is a dataset folder",
    ),
    # scale_data.py: demo folders in the way (items 1, 9)
    (
        "foreign-folder-at-demo-path",
        _foreign_folder_at_demo_path,
        2,
        "did not make",
    ),
    ("foreign-file-in-aug-set", _foreign_aug_set, 2, "holds files this program did not write (keep.txt)"),
    ("stale-own-set-with-user-file", _stale_own_set_with_notes, 2, "did not write (my_annotations.txt)"),
    # scale_data.py: datasets (item 4)
    (
        "user-data-missing",
        lambda tmp, ref: ([*SD, "--out", tmp / "o", "--pusht_data", tmp / "nope"], [], None),
        2,
        "does not exist",
    ),
    (
        "user-data-is-a-file",
        lambda tmp, ref: ([*SD, "--out", tmp / "o", "--pusht_data", _file(tmp)], [tmp / "afile"], None),
        2,
        "is a file, not a LeRobot dataset",
    ),
    (
        "user-data-truncated-parquet",
        _user_set_corrupt("data/chunk-000/file-000.parquet"),
        2,
        "cannot be read",
    ),
    (
        "user-data-truncated-episodes-meta",
        _user_set_corrupt("meta/episodes/chunk-000/file-000.parquet"),
        2,
        "cannot be read",
    ),
    ("user-data-bad-info-json", _user_set_corrupt("meta/info.json"), 2, "not a LeRobot v3 dataset"),
    ("own-set-given-damaged", _own_set_changed_as_user_data, 2, "is damaged: meta/stats.json changed"),
    ("user-data-nan", _user_set_edited(with_nan), 2, "holds non-finite values (NaN or inf) in action"),
    (
        "user-data-nan-state",
        _user_set_edited(lambda p: with_nan(p, "observation.state", 0)),
        2,
        "non-finite values (NaN or inf) in observation.state in 1 frames, the first at row 0",
    ),
    ("user-data-50fps", _user_set_edited(lambda p: with_fps(p, 50)), 2, "recorded at 50 fps, but the env"),
    ("user-data-unfinished-engine-run", _unfinished_engine_run, 2, "unfinished augment_demos.py run"),
    # the generators
    (
        "gen-pusht-out-holds-data",
        lambda tmp, ref: (["gen_demos_pusht.py", "--out", ref["pusht"]], [ref["pusht"]], None),
        2,
        "already holds data",
    ),
    (
        "gen-pusht-out-under-file",
        lambda tmp, ref: (["gen_demos_pusht.py", "--out", _file(tmp) / "x"], [tmp / "afile"], None),
        2,
        "afile is a file, not a folder",
    ),
    (
        "gen-aloha-out-in-proc",
        lambda tmp, ref: (["gen_demos_aloha.py", "--out", "/proc/ch37-no/x"], [], None),
        2,
        "cannot be written",
    ),
    ("gen-aloha-too-many-episodes", _gen("aloha", "--episodes", "1000001"), 2, "--episodes must be in"),
    ("gen-pusht-seed-overflow", _gen("pusht", "--seed", str(2**64)), 2, "--seed must be in"),
    ("gen-aloha-noise-nan", _gen("aloha", "--noise", "nan"), 2, "--noise must be a finite"),
    ("gen-pusht-unknown-flag", _gen("pusht", "--bogus"), 2, "unrecognized arguments: --bogus"),
    # the tools (item 10)
    (
        "tools-regions-missing-script",
        lambda tmp, ref: (["-m", "tools.regions", "--script", tmp / "gone.py"], [], None),
        2,
        "gone.py: no such file",
    ),
    (
        "tools-meta-incomplete-sweep",
        lambda tmp, ref: (
            [
                "-m",
                "tools.meta",
                "--sweep",
                _file(tmp, "s.json", json.dumps(META_SWEEP)),
                "--meta",
                tmp / "m.yaml",
            ],
            [tmp / "s.json"],
            None,
        ),
        2,
        "is incomplete",
    ),
    (
        "tools-meta-corrupt-sweep",
        lambda tmp, ref: (
            ["-m", "tools.meta", "--sweep", _file(tmp, "s.json", '{"kind": "se'), "--meta", tmp / "m.yaml"],
            [tmp / "s.json"],
            None,
        ),
        2,
        "is not a readable JSON sweep file",
    ),
    # issue 31 #4: the LeRobot lab's flags go through the one checker, its --out through the one error path
    (
        "lab-seeds-negative",
        lambda tmp, ref: (["-m", "tools.lerobot", "lab", "--seeds", "-1", "--out", tmp / "ll"], [], None),
        2,
        "--seeds must be >= 0, got -1",
    ),
    (
        "lab-out-is-a-file",
        lambda tmp, ref: (
            ["-m", "tools.lerobot", "lab", "--seeds", "0", "--out", _file(tmp)],
            [tmp / "afile"],
            None,
        ),
        2,
        "afile is a file, not a folder",
    ),
    # an unusable Hugging Face cache is named as the cause, not the (good) data set (issue 22, item 13)
    (
        "hf-home-is-a-file",
        lambda tmp, ref: (
            [*SD, "--no-cache", "--out", tmp / "o"],
            [_file(tmp, "hf")],
            env_for(HF_HOME=str(tmp / "hf")),
        ),
        2,
        "the Hugging Face cache",
    ),
    # issue 42 #1: tools.replay value's --out holding the user's own aloha_value.json; a bad --device up front
    (
        "aloha-value-out-holds-users-json",
        lambda tmp, ref: (
            [
                "-m",
                "tools.replay",
                "value",
                "--smoke",
                "--seeds",
                "1",
                "--out",
                _user_result(tmp, "aloha_value.json"),
            ],
            [tmp / "u" / "aloha_value.json"],
            None,
        ),
        2,
        "aloha_value.json exists and was not written by this tool; pass another --out",
    ),
    (
        "aloha-value-device-bogus",
        lambda tmp, ref: (
            ["-m", "tools.replay", "value", "--smoke", "--device", "bogus", "--out", tmp / "av"],
            [],
            None,
        ),
        2,
        "argument --device: invalid choice: 'bogus'",
    ),
    # issue 42 #6: the lab checks its memory as the lesson does; #8: the flag named is one that can help
    (
        "lab-hidden-dim-beyond-ram",
        lambda tmp, ref: (
            ["scale_lab.py", "--smoke", "--hidden_dim", str(10**12), "--out", tmp / "l"],
            [],
            None,
        ),
        2,
        "lower --hidden_dim",
    ),
    (
        "lab-batch-beyond-ram",
        lambda tmp, ref: (
            ["scale_lab.py", "--smoke", "--batch_size", str(10**12), "--out", tmp / "l"],
            [],
            None,
        ),
        2,
        "lower --batch_size",
    ),
    (
        "aug-per-demo-beyond-ram",
        _sd("--aug_per_demo", str(10**12)),
        2,
        "lower --source_episodes/--aug_per_demo",
    ),
    # the exercise checks (item 10)
    ("checks-ex2-output-aliases-input", _checks("ex2", ALIASING_MIX), 1, "shares memory with an input array"),
    ("checks-ex1-no-prediction", _checks("ex1", "WHY = 'no letter'\n"), 1, "PREDICTION is missing"),
    ("checks-missing-answer-folder", _checks("ex2", missing_dir=True), 1, "not found"),
    ("checks-unknown-exercise", lambda tmp, ref: (["-m", "exercises.checks", "ex9"], [], None), 2, "usage"),
]


@pytest.mark.parametrize("make, code, needle", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_nothing_is_touched(ref, tmp_path, make, code, needle):
    argv, protect, env = make(tmp_path, ref)
    before, listing = snapshot(protect), set(tmp_path.rglob("*"))
    assert all(Path(p).exists() for p in protect) and (before or not protect)
    p = run(*argv, env=env)
    err = [line for line in p.stderr.splitlines() if line.strip()]
    assert p.returncode == code, p.stdout[-2000:] + p.stderr
    assert len(err) == 1 and needle in err[0], p.stderr
    assert "Traceback" not in p.stdout + p.stderr
    assert snapshot(protect) == before  # the user's files, byte for byte
    # a refused run wrote nothing: at most the folder it claimed, with its lock and empty stamp
    new = {x for x in set(tmp_path.rglob("*")) - listing if not x.is_dir()}
    assert {x.name for x in new} <= {ownership.LOCK_NAME, ownership.STAMP_NAME}, sorted(map(str, new))


def test_the_table_is_big_enough():
    assert len(CASES) >= 30 and len({c[0] for c in CASES}) == len(CASES)


def test_genuine_bugs_keep_their_traceback_and_ch37_debug_shows_every_one(tmp_path):
    import errno

    from ch37 import errors

    with pytest.raises(ValueError):  # not a user's problem: it surfaces as it is
        errors.run_main(int, "not a number")
    assert errors.one_line(ValueError("x")) is None and errors.one_line(RuntimeError("x")) is None
    code, line = errors.one_line(OSError(errno.ENOSPC, "No space left on device", "/x/metrics.json"))
    assert code == 2 and line == (
        "error: /x/metrics.json: No space left on device; free some disk space, "
        "then run the same command again"
    )
    assert errors.one_line(KeyboardInterrupt())[0] == 130 and errors.one_line(errors.Terminated())[0] == 143
    p = run(*SD, "--out", _file(tmp_path), env=env_for(CH37_DEBUG="1"))
    assert p.returncode == 1 and "Traceback" in p.stderr and "DataError: --out" in p.stderr


# ---------------------------------------------------------------------------------------------
# Recovery: damaged cache entries and damaged sets of ours are discarded and remade, one line
# ---------------------------------------------------------------------------------------------
def test_damaged_cache_entry_and_damaged_own_set_are_remade(ref, tmp_path):
    """A truncated cached metrics.json is never replayed: one warning line, the run recomputes. A
    truncated parquet in a demo set this program made under --out is rebuilt, not crashed on."""
    cache = tmp_path / "cache"
    shutil.copytree(ref["cache"], cache)
    (entry,) = [d for d in cache.iterdir() if d.is_dir()]
    _corrupt(entry / "metrics.json", 50)
    out = tmp_path / "o"
    shutil.copytree(ref["out"] / "demos", out / "demos")
    _corrupt(out / "demos" / "pusht_seed0_ep4" / "data" / "chunk-000" / "file-000.parquet")
    (out / "notes.txt").write_text("mine\n")
    before = snapshot([out / "notes.txt"])
    p = run(*SD, "--out", out, env=env_for(cache))
    assert p.returncode == 0, p.stdout + p.stderr
    err = p.stderr.strip().splitlines()
    assert (
        len(err) == 1 and err[0].startswith("warning: the cached result") and "fails its checksum" in err[0]
    )
    assert (
        "reusing" not in p.stdout and "data/chunk-000/file-000.parquet had changed since written" in p.stdout
    )
    assert (out / "metrics.json").read_bytes() == ref["metrics"]
    assert snapshot([out / "notes.txt"]) == before
    assert result_cache.read_entry(entry)["metrics.json"] == ref["metrics"]  # the entry is whole again


@pytest.mark.parametrize(
    "damage, why",
    [
        (lambda e: (e / "scale_data.png").unlink(), "scale_data.png is missing"),
        (lambda e: (e / result_cache.MANIFEST).unlink(), "manifest.json is missing"),
        (lambda e: (e / result_cache.MANIFEST).write_text("[1, 2"), "cannot be read"),
        (lambda e: (e / result_cache.MANIFEST).write_text('{"../x": "0"}'), "incomplete"),
        (
            lambda e: (e / result_cache.SUMMARY).write_text("headline: made up\n"),
            "summary.txt fails its checksum",
        ),
    ],
)
def test_damaged_cache_entries_are_refused_before_anything_is_copied(
    ref, tmp_path, monkeypatch, capsys, damage, why
):
    (entry,) = [d for d in ref["cache"].iterdir() if d.is_dir()]
    copy = tmp_path / "cache" / entry.name
    shutil.copytree(entry, copy)
    damage(copy)
    monkeypatch.setenv("CH37_CACHE_DIR", str(tmp_path / "cache"))
    cache = result_cache.ResultCache.__new__(result_cache.ResultCache)
    cache.enabled, cache.out, cache.key = True, tmp_path / "out", entry.name
    assert cache.replay() is False
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and why in err[0] and "discarded" in err[0]
    assert not (tmp_path / "out").exists() and not copy.exists()


def test_discarding_a_cache_entry_never_follows_a_link_and_deletes_only_what_it_recorded(
    ref, tmp_path, monkeypatch, capsys
):
    """Issue 31 #1: an entry folder replaced by a link to a user's folder holding files of an entry's
    names is left as it is, the user's files byte-identical (the discard unlinked them through the
    link); in a real entry whose manifest fails, only the files its manifest lists go."""
    (entry,) = [d for d in ref["cache"].iterdir() if d.is_dir()]
    mine = tmp_path / "mine"
    mine.mkdir()
    for name in ("metrics.json", "scale_data.html", result_cache.SUMMARY):
        (mine / name).write_text(f"my own {name}\n")
    monkeypatch.setenv("CH37_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / entry.name).symlink_to(mine, target_is_directory=True)
    before = snapshot([mine])
    cache = result_cache.ResultCache.__new__(result_cache.ResultCache)
    cache.enabled, cache.out, cache.key = True, tmp_path / "out", entry.name
    assert cache.replay() is False
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a link" in err[0] and "left as it is" in err[0], err
    assert snapshot([mine]) == before and (tmp_path / "cache" / entry.name).is_symlink()
    # a real entry: a damaged metrics.json (listed) goes, a scale_data.html it never recorded stays
    (tmp_path / "cache" / entry.name).unlink()
    copy = tmp_path / "cache" / entry.name
    shutil.copytree(entry, copy)
    listed = json.loads((copy / result_cache.MANIFEST).read_text())
    assert "scale_data.html" in listed  # the smoke run's entry records its poster: drop it from the manifest
    (copy / result_cache.MANIFEST).write_text(
        json.dumps({k: v for k, v in listed.items() if k != "scale_data.html"})
    )
    (copy / "scale_data.html").write_text("the user's page\n")
    _corrupt(copy / "metrics.json", 10)
    assert cache.replay() is False
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fails its checksum" in err[0], err
    assert sorted(p.name for p in copy.iterdir()) == ["scale_data.html"]
    assert (copy / "scale_data.html").read_text() == "the user's page\n"


def test_cache_stores_only_what_this_run_wrote(tmp_path, monkeypatch):
    """A stray scale_data.rrd in --out (another seed's) never enters the cache."""
    monkeypatch.setenv("CH37_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "out"
    claim = ownership.claim(out, results=result_cache.RESULT_FILES)
    try:
        ownership.write_atomic(out / "metrics.json", "{}\n", claim)
        (out / "scale_data.rrd").write_bytes(b"another seed's recording")
        cache = result_cache.ResultCache.__new__(result_cache.ResultCache)
        cache.enabled, cache.out, cache.key, cache.claim = True, out, "k" * 24, claim
        cache.store([out / "metrics.json", out / "scale_data.rrd"], "summary\n")
        assert not (tmp_path / "cache" / cache.key).exists()
        cache.store([out / "metrics.json"], "summary\n")
        got = result_cache.read_entry(tmp_path / "cache" / cache.key)
        assert set(got) == {"metrics.json", "summary.txt"}
    finally:
        claim.release()


def test_an_engine_output_is_a_pusht_set_like_any_other(ref, tmp_path):
    """Issue 22 item 14: an augment_demos.py output (stamp kind "engine") passed as --pusht_data is
    used as given, not refused as a mismatched generated set; it is never modified."""
    eng = tmp_path / "eng"
    p = run(
        "augment_demos.py",
        "--src",
        ref["pusht"],
        "--out",
        eng,
        "--per_demo",
        "2",
        "--workers",
        "1",
        "--quiet",
    )
    assert p.returncode == 0, p.stdout + p.stderr
    assert json.loads((eng / ownership.STAMP_NAME).read_text())["kind"] == "engine"
    before = snapshot([eng])
    p = run(*SD, "--no-cache", "--out", tmp_path / "o", "--pusht_data", eng)
    assert p.returncode == 0 and p.stderr.strip() == "", p.stdout[-2000:] + p.stderr
    assert "(your own set, used as given)" in p.stdout and "Traceback" not in p.stdout
    assert (tmp_path / "o" / "metrics.json").exists() and snapshot([eng]) == before


def test_a_replay_prints_exactly_the_numbers_of_the_run_it_replays(tmp_path):
    """Issue 22 item 5: --out 0 then --out 1 (same flags): the replay's summary is the run's, with only
    the written paths under 1/ (the old "{out}" text replacement turned every 0 into a 1)."""
    mine = _file(tmp_path, "notes.txt")
    before = snapshot([mine])
    env, outs = env_for(tmp_path / "cache"), {}
    for out in ("0", "1"):
        p = subprocess.run(
            [sys.executable, ROOT / "scale_data.py", *SD[1:], "--out", out],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
            env=env,
        )
        assert p.returncode == 0 and p.stderr.strip() == "", p.stdout + p.stderr
        outs[out] = p.stdout
    run_lines, replay_lines = outs["0"].splitlines(), outs["1"].splitlines()
    assert "reusing the result" in outs["1"] and "reusing" not in outs["0"]
    summary = run_lines[run_lines.index(next(x for x in run_lines if x.startswith("headline:"))) :]
    wrote = summary[-1]
    assert wrote.startswith("wrote 0/cross_embodiment.json") and "0.00 -> " in summary[0]
    assert replay_lines[-len(summary) :] == [*summary[:-1], wrote.replace(" 0/", " 1/")]
    assert (tmp_path / "1" / "metrics.json").read_bytes() == (tmp_path / "0" / "metrics.json").read_bytes()
    assert snapshot([mine]) == before


# ---------------------------------------------------------------------------------------------
# Ownership, file by file
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "theirs, command",
    [
        (("scale_lab.json", "scale_lab.png"), SD),  # the lesson on a finished lab's folder
        (result_cache.RESULT_FILES[:3], ("scale_lab.py", "--smoke", "--no-rerun")),  # and the reverse
    ],
)
def test_one_commands_results_are_never_cleared_by_another(tmp_path, theirs, command):
    """Issue 22 #2: results of another command in --out (ours, so not a user's file) stop the run with
    one line naming them; nothing is deleted."""
    out = tmp_path / "out"
    c = ownership.claim(out, results=theirs)  # as that command's run leaves them: written under its claim
    for name in theirs:
        ownership.write_atomic(out / name, f"{name} of a finished run\n", c)
    c.release()
    before = snapshot([out])
    p = run(*command, "--out", out, env=env_for(tmp_path / "cache"))
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "Traceback" not in p.stderr, p.stderr
    assert "another command's results" in err[0] and theirs[0] in err[0]
    assert {k: v for k, v in snapshot([out]).items() if not k.endswith(ownership.LOCK_NAME)} == {
        k: v for k, v in before.items() if not k.endswith(ownership.LOCK_NAME)
    }


def _results_of(out: Path) -> dict:
    return {k: v for k, v in snapshot([out]).items() if not k.endswith(ownership.LOCK_NAME)}


def test_a_mistyped_input_after_a_finished_run_leaves_its_results_intact(ref, tmp_path):
    """Issue 33 #1: every input (--pusht_data, --aloha_data, --device) is checked before anything, ours
    included, is removed: a typo is one line and exit 2, and the last run's results are all still there."""
    out = tmp_path / "o"
    p = run(*SD, "--out", out, env=env_for(ref["cache"]))  # the finished run (replayed from its cache)
    assert p.returncode == 0 and (out / "metrics.json").read_bytes() == ref["metrics"], p.stdout + p.stderr
    before = _results_of(out)
    assert {"metrics.json", "scale_data.png", "scale_data.html"} <= {Path(k).name for k in before}
    typos = [
        ("--pusht_data", tmp_path / "my_pushtt", "does not exist or is empty"),
        ("--aloha_data", ROOT / "README.md", "is a file, not a LeRobot dataset folder"),
    ]
    import torch

    if not torch.cuda.is_available():
        typos.append(("--device", "cuda", "--device cuda is not available"))
    for flag, value, needle in typos:
        p = run(*SD, "--no-cache", "--out", out, flag, value, env=env_for(ref["cache"]))
        err = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(err) == 1 and needle in err[0], p.stdout + p.stderr
        assert _results_of(out) == before, f"{flag} {value} removed results of the finished run"


def test_claimed_out_refuses_a_foreign_file_and_clears_only_its_own(tmp_path):
    from ch37.errors import DataError

    out = tmp_path / "out"
    claim = ownership.claim(out, results=("metrics.json", "b.json"))
    ownership.write_atomic(out / "metrics.json", "1\n", claim)
    (out / "b.json").write_text("user's\n")
    with pytest.raises(DataError, match="b.json was not written by this program"):
        ownership.write_atomic(out / "b.json", "2\n", claim)
    assert (out / "b.json").read_text() == "user's\n"
    claim.release()
    (out / "metrics.json").write_text("edited by the user\n")  # ours once, changed since: theirs now
    with pytest.raises(DataError, match="metrics.json was not written by this program"):
        ownership.claim(out, results=("metrics.json",))
    (out / "metrics.json").unlink()
    (out / "b.json").unlink()
    claim = ownership.claim(out, results=("metrics.json",))
    ownership.write_atomic(out / "metrics.json", "3\n", claim)
    (out / "notes.txt").write_text("kept\n")
    claim.release()
    claim = ownership.claim(out, results=("metrics.json",))  # the next run clears its own old result only
    assert not (out / "metrics.json").exists() and (out / "notes.txt").read_text() == "kept\n"
    claim.release()


def test_replace_own_dir_deletes_only_listed_files(ref, tmp_path):
    from ch37.errors import DataError

    mine = user_set(ref, tmp_path, stamped=True)
    ownership.replace_own_dir(mine)
    assert not mine.exists()
    mine = user_set(ref, tmp_path, name="m2", stamped=True)
    (mine / "data" / "extra.txt").write_text("x")
    with pytest.raises(DataError, match=r"did not write \(data/extra.txt\)"):
        ownership.replace_own_dir(mine)
    assert (mine / "data" / "extra.txt").read_text() == "x" and (mine / ownership.STAMP_NAME).exists()


def test_leftovers_of_dead_processes_are_swept_and_live_ones_kept(tmp_path):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    gone, alive = int(dead.stdout), os.getppid()
    (tmp_path / f".set.ch37-partial-{gone}").mkdir()  # ours: our stamp inside (ownership.partial_dir)
    ours = json.dumps({"made_by": ownership.MADE_BY, "kind": "partial"})
    (tmp_path / f".set.ch37-partial-{gone}" / ownership.STAMP_NAME).write_text(ours)
    (tmp_path / f".set.ch37-partial-{gone}" / "x").write_text("half")
    (tmp_path / f".empty.ch37-partial-{gone}").mkdir()  # cut off before its stamp: nothing to lose
    (tmp_path / f".metrics.json.ch37-tmp-{gone}").write_text("half")
    (tmp_path / f".metrics.json.ch37-tmp-{alive}").write_text("in flight")
    users = [".hidden.txt", f".thesis.old-{gone}", f".notes.tmp-{gone}", f".mine.ch37-partial-{gone}"]
    for name in users:  # a user's, whatever the name looks like: no file or folder of ours says so
        (tmp_path / name).write_text("user's") if "partial" not in name else (tmp_path / name).mkdir()
    (tmp_path / f".project.partial-{gone}").mkdir()
    (tmp_path / f".project.partial-{gone}" / ownership.STAMP_NAME).write_text('{"made_by": "me"}')
    (tmp_path / f".mine.ch37-partial-{gone}" / "draft.txt").write_text("user's")
    kept = sorted([*users, f".metrics.json.ch37-tmp-{alive}", f".project.partial-{gone}"])
    assert sorted(ownership.sweep_leftovers(tmp_path)) == sorted(
        [f".empty.ch37-partial-{gone}", f".metrics.json.ch37-tmp-{gone}", f".set.ch37-partial-{gone}"]
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == kept


def _lookalikes(folder: Path, target: str) -> list[Path]:
    """A user's files named like a crashed run's leftovers (issue 22, item 1); none is ours."""
    folder.mkdir(parents=True, exist_ok=True)
    made = [_file(folder, ".thesis.old-2024", "chapter 1\n"), _file(folder, ".zshrc.old-2023", "alias\n")]
    for name in (".project.tmp-31337", ".backup.partial-4242", f".{target}.ch37-partial-4242"):
        (folder / name).mkdir()
        made.append(_file(folder / name, "work.txt", "mine\n"))
    return made


@pytest.mark.parametrize("which", ["scale_data", "gen_demos_pusht"])
def test_a_users_lookalike_leftovers_are_never_swept(ref, tmp_path, which):
    """scale_data.py sweeps its --out, the generators the parent of theirs: only what we wrote goes."""
    if which == "scale_data":  # the cached run: its claim of --out sweeps there as a full run's does
        out, env = tmp_path / "o", env_for(ref["cache"])
        argv, protect = [*SD, "--out", out], _lookalikes(out, "demos")
    else:
        out, env = tmp_path / "home" / "my_pusht", env_for()
        argv = ["gen_demos_pusht.py", "--quiet", "--episodes", "1", "--no-video", "--out", out]
        protect = _lookalikes(out.parent, out.name)
    before = snapshot(protect)
    p = run(*argv, env=env)
    assert p.returncode == 0 and p.stderr.strip() == "", p.stdout[-2000:] + p.stderr
    assert "Traceback" not in p.stdout + p.stderr
    assert snapshot(protect) == before and len(before) == len(protect)  # every one, byte for byte


def test_ex2_check_refuses_an_output_that_shares_memory_with_its_input():
    from exercises import checks
    from exercises.checks import ExerciseError

    namespace = {}
    exec(ALIASING_MIX, namespace)
    with pytest.raises(ExerciseError, match="shares memory"):
        checks.check_mix(namespace["mix_embodiments"])
    p, a = np.zeros((0, 2), np.float32), np.ones((4, 6), np.float32)
    assert np.shares_memory(namespace["mix_embodiments"](p, a)[0], a)  # the check's premise


# ---------------------------------------------------------------------------------------------
# Processes: concurrent runs, interrupts, kills
# ---------------------------------------------------------------------------------------------
def session_pids(sid: int) -> list[int]:
    """Every live process in session `sid` (a run started with start_new_session: it and its workers)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
            if fields[0] != "Z" and int(fields[3]) == sid:
                pids.append(int(d.name))
    return pids


def wait_for(pred, timeout=120.0, step=0.05):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return False


linux_only = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")


@linux_only
def test_two_runs_on_one_out_never_collide(ref, tmp_path):
    """Started together on one --out: one waits for the other (saying so), both succeed, same bytes."""
    out, env = tmp_path / "o", env_for(tmp_path / "cache")
    procs = [
        subprocess.Popen(
            [sys.executable, *SD, "--out", str(out)],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (so, se) in zip(procs, outs):
        assert p.returncode == 0 and se.strip() == "" and "Traceback" not in so, so + se
    assert sum("waiting: another run" in so for so, _ in outs) == 1
    assert (out / "metrics.json").read_bytes() == ref["metrics"]
    assert not [p for p in (out / "demos").iterdir() if p.name.startswith(".")]  # no half-written set


@linux_only
def test_kill_term_and_ctrl_c_leave_nothing_behind_and_the_same_command_continues(ref, tmp_path):
    """SIGKILL and SIGTERM to the run, and Ctrl-C (SIGINT to the whole process group, as a terminal
    sends it), while worker processes run, in evaluation (env workers) or augmentation (a pool): no
    process is left, SIGTERM and Ctrl-C print one line (exit 143 / 130) saying the same command
    continues, and it does, with the metrics of an uninterrupted run and no leftovers."""
    out = tmp_path / "o"
    cmd = [sys.executable, *SD, "--no-cache", "--out", str(out)]
    for sig, phase, code, word in (
        (signal.SIGKILL, "eval", -9, None),
        (signal.SIGTERM, "augment", 143, "terminated"),
        (signal.SIGINT, "eval", 130, "interrupted"),
    ):
        log, errlog = tmp_path / f"{sig.name}.out", tmp_path / f"{sig.name}.err"
        with open(log, "w") as stdout, open(errlog, "w") as stderr:  # files: a stray worker holds no pipe
            p = subprocess.Popen(
                cmd,
                cwd=ROOT,
                env=env_for(PYTHONUNBUFFERED="1"),
                stdout=stdout,
                stderr=stderr,
                start_new_session=True,
                # as a terminal starts it: a launcher in the background (nohup, `cmd &`) passes SIGINT
                # ignored, and a Python started so never sees Ctrl-C
                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
            )
        try:
            # evaluation: after the short budget, the full budget's env workers; augment: the first pool
            ready = (lambda: "\nbudget short:" in log.read_text()) if phase == "eval" else (lambda: True)
            seen = wait_for(lambda: p.poll() is not None or (ready() and len(session_pids(p.pid)) > 1))
            assert seen and p.poll() is None, f"the run ended before its {phase} workers were seen"
            if sig == signal.SIGINT:
                os.killpg(p.pid, sig)
            else:
                os.kill(p.pid, sig)
            p.wait(timeout=60)
            left = [] if wait_for(lambda: not session_pids(p.pid), timeout=10) else session_pids(p.pid)
        finally:
            for pid in session_pids(p.pid):  # whatever this test started and is still there
                os.kill(pid, signal.SIGKILL)
        so, se = log.read_text(), errlog.read_text()
        assert p.returncode == code, so + se
        assert not left, f"left behind after {sig.name}: {left}"
        if word:
            err = se.strip().splitlines()
            assert len(err) == 1 and err[0].startswith(word) and "run the same command again" in err[0], se
            assert "Traceback" not in so + se
    p = subprocess.run(cmd, cwd=ROOT, env=env_for(), capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and p.stderr.strip() == "", p.stdout + p.stderr
    assert (out / "metrics.json").read_bytes() == ref["metrics"]
    assert not [x for x in out.rglob(".*") if x.name != ownership.LOCK_NAME]  # no temp file, no partial set


# A finalizer that is running when the signal's handler runs: the interrupt is raised inside it
FINALIZER = """
import signal, sys, time
from ch37 import errors
class Closing:
    def __del__(self):
        signal.raise_signal(signal.SIG{sig})
        sum(range(1000))  # the handler runs here, inside the finalizer
def run(argv):
    Closing()
    time.sleep(30)  # the run goes on
    print("finished")
    return 0
{entry}
time.sleep(30)
print("finished")
"""


@pytest.mark.parametrize("sig,code,word", [("INT", 130, "interrupted"), ("TERM", 143, "terminated")])
@pytest.mark.parametrize("entry", ["errors.guard(); Closing()", "errors.main(run)"])
def test_ctrl_c_in_a_finalizer_still_stops_the_run(sig, code, word, entry):
    """Python swallows an exception raised in a finalizer ("Exception ignored in ..."): a Ctrl-C that
    landed while a worker pipe's __del__ ran let the run finish with exit 0 (a clean-clone CI run of
    the test above). Both ways in (guard, main) stop with the one line and the signal's exit code."""
    script = FINALIZER.format(sig=sig, entry=entry)
    # the signal must end the run's sleep (a blocking wait), not the sleep's own end (timeout: the test fails)
    p = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, env=env_for(), capture_output=True, text=True, timeout=25
    )
    assert p.returncode == code, p.stdout + p.stderr
    assert "finished" not in p.stdout and p.stderr.strip().startswith(word), p.stdout + p.stderr
    assert "Traceback" not in p.stderr and "Exception ignored" not in p.stderr, p.stderr


@pytest.fixture
def small_disk(tmp_path):
    """A 3 MB tmpfs; fill(free) leaves `free` bytes beside a user's file. Skipped where mounts fail."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    mount = ["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mnt)]
    if subprocess.run(mount, capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here (needs root); the full-disk rows run where it can")

    def fill(free: int) -> Path:
        st = os.statvfs(mnt)
        filler = mnt / "my_big_file"
        filler.write_bytes(b"x" * max(0, st.f_bavail * st.f_frsize - free))
        return filler

    yield mnt, fill
    subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.mark.parametrize("free", [0, 128 << 10])
def test_a_full_disk_under_the_engine_is_one_line(ref, small_disk, free):
    """Issue 22 #7: augment_demos.py writing onto a full disk (before, during or after its first shard) ends
    in one line naming the cause and exit 2, the user's file untouched; with space, the same command works."""
    mnt, fill = small_disk
    user = fill(free)
    before = snapshot([user])
    cmd = ["augment_demos.py", "--src", ref["pusht"], "--out", mnt / "aug", "--per_demo", "10", "--quiet"]
    p = run(*cmd, "--workers", "1")
    err = p.stderr.strip().splitlines()
    assert "Traceback" not in p.stdout + p.stderr
    assert snapshot([user]) == before
    if p.returncode == 0:  # it fit: nothing to report
        return
    assert p.returncode == 2 and len(err) == 1 and "free some disk space" in err[0], p.stderr
    user.unlink()  # space again: the same command finishes
    p = run(*cmd, "--workers", "1")
    assert p.returncode == 0, p.stderr


@linux_only
def test_a_full_disk_during_the_merge_is_one_line_naming_the_file(ref, tmp_path):
    """Issue 31 #3: the shards fit, the merged set does not (an 8 MB tmpfs filled to 64 KB free after
    every shard is made): exactly one `error:` line naming where, exit 2, nothing else on stderr (no
    writer left open to complain at exit), the user's file untouched; with space, the same command
    finishes with the bytes of an uninterrupted run."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    if subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=8m", "tmpfs", str(mnt)], capture_output=True
    ).returncode:
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        out = mnt / "aug"
        argv = ["augment_demos.py", "--src", ref["pusht"], "--per_demo", "10", "--shard_size", "2", "--quiet"]
        argv += ["--workers", "2", "--out"]
        full = run(*argv, tmp_path / "full")
        assert full.returncode == 0, full.stderr
        p = subprocess.Popen([sys.executable, *map(str, argv), str(out)], cwd=ROOT, env=env_for())
        shard_dir = out / "shards"
        assert wait_for(lambda: p.poll() is not None or len(list(shard_dir.glob("shard-*"))) == 20, 300)
        p.kill()
        p.wait()
        assert p.returncode == -signal.SIGKILL, "the run ended before it was killed"
        st = os.statvfs(mnt)
        user = mnt / "my_big_file"
        user.write_bytes(b"x" * (st.f_bavail * st.f_frsize - (64 << 10)))
        before = snapshot([user])
        p = run(*argv, out)
        err = [line for line in p.stderr.splitlines() if line.strip()]
        assert p.returncode == 2 and len(err) == 1, p.stdout + p.stderr
        assert err[0].startswith("error: ") and str(out) in err[0] and "free some disk space" in err[0], err
        assert snapshot([user]) == before
        user.unlink()
        p = run(*argv, out)
        assert p.returncode == 0 and p.stderr.strip() == "", p.stderr
        skip = (ownership.STAMP_NAME, "generation_report.json", ownership.LOCK_NAME)
        assert snapshot([out]).keys() and {
            k.replace(str(out), ""): v for k, v in snapshot([out]).items() if Path(k).name not in skip
        } == {
            k.replace(str(tmp_path / "full"), ""): v
            for k, v in snapshot([tmp_path / "full"]).items()
            if Path(k).name not in skip
        }
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.fixture(scope="module")
def as_nobody(ref):
    """Run a command as an unprivileged user (uid 65534) with a world-readable copy of this interpreter,
    in a world-readable scratch folder holding a copy of the reference PushT set. Skipped unless root."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to run a case as an unprivileged user")
    import site
    import tempfile

    work = Path(tempfile.mkdtemp(prefix="ch37-nobody-"))
    try:
        py = work / "python"
        shutil.copytree(sys.base_prefix, py, symlinks=True)
        shutil.copytree(ref["pusht"], work / "src")
        for p in [work, *work.rglob("*")]:
            if not p.is_symlink():
                p.chmod(0o755 if p.is_dir() or os.access(p, os.X_OK) else 0o644)
        path = os.pathsep.join([*site.getsitepackages(), str(ROOT)])
        env = {
            "PATH": "/usr/bin:/bin",
            "HOME": "/nonexistent",
            "LD_LIBRARY_PATH": str(py / "lib"),
            "PYTHONPATH": path,
        }
        exe = py / "bin" / Path(sys.executable).resolve().name

        def run_nobody(*args):
            cmd = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", str(exe), *map(str, args)]
            return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env, timeout=300)

        if run_nobody("-c", "import numpy, ch37").returncode:
            pytest.skip(
                "this checkout or its .venv is not readable by an unprivileged user (a private folder such "
                "as /root): clone it into a world-readable folder to run these"
            )
        yield work, run_nobody
    finally:
        shutil.rmtree(work, ignore_errors=True)


@pytest.mark.parametrize(
    "case, needle",
    [("read_only_out", "cannot be written"), ("unwritable_home", "the Hugging Face cache")],
)
def test_unprivileged_cases_are_one_line(as_nobody, case, needle):
    """Issue 22 #7 and #13, as an unprivileged user: --out inside a read-only folder, and a HOME that
    cannot hold the Hugging Face cache (the good source set must not be blamed)."""
    work, run_nobody = as_nobody
    (work / "ro").mkdir(mode=0o555, exist_ok=True)
    (work / "rw").mkdir(mode=0o777, exist_ok=True)
    (work / "rw").chmod(0o777)
    out = work / "ro" / "aug" if case == "read_only_out" else work / "rw" / case
    before = snapshot([work / "src"])
    p = run_nobody(ROOT / "augment_demos.py", "--src", work / "src", "--out", out, "--per_demo", "2")
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and needle in err[0], p.stderr
    assert "Traceback" not in p.stdout + p.stderr and snapshot([work / "src"]) == before


# ---------------------------------------------------------------------------------------------
# Issue 48: a malformed meta/info.json (#4), --out inside --src (#9), the tools' result files (#12)
# ---------------------------------------------------------------------------------------------
def _info_edited(edit, command="augment"):
    """A user's copy of the PushT set whose meta/info.json is edit(info), given to augment_demos.py as
    --src (or to scale_data.py as --pusht_data)."""

    def make(tmp, ref):
        mine = user_set(ref, tmp)
        info = json.loads((mine / "meta" / "info.json").read_text())
        (mine / "meta" / "info.json").write_text(json.dumps(edit(info), indent=4))
        if command == "augment":
            return ["augment_demos.py", "--src", mine, "--out", tmp / "o", "--per_demo", "1"], [mine], None
        return [*SD, "--no-cache", "--out", tmp / "o", "--pusht_data", mine], [mine], None

    return make


def _tool_over_users_result(name, command):
    """A tool (`command`: "-m tools.X flags", bench engine's --src the reference set) whose --out holds
    the user's own file `name`."""
    return lambda tmp, ref: (
        [*command.split(), *(["--src", ref["pusht"]] if "bench engine" in command else [])]
        + ["--out", _user_result(tmp, name)],
        [tmp / "u" / name],
        None,
    )


ISSUE48_CASES = [
    # 4: one line naming what is malformed, not a traceback (nor PushT's widths blamed)
    (
        "info-feature-entry-a-list",
        _info_edited(lambda i: i | {"features": i["features"] | {"observation.state": [5]}}),
        2,
        "meta/info.json's feature 'observation.state' is a list, not an object",
    ),
    (
        "info-features-a-list",
        _info_edited(lambda i: i | {"features": list(i["features"])}),
        2,
        "meta/info.json's features is a list, not an object",
    ),
    ("info-a-list", _info_edited(lambda i: [i]), 2, "meta/info.json holds a list, not an object"),
    ("info-fps-a-string", _info_edited(lambda i: i | {"fps": "10"}), 2, "fps is '10' (a string)"),
    (
        "info-a-list-scale-data",
        _info_edited(lambda i: [i], "scale_data"),
        2,
        "meta/info.json holds a list, not an object",
    ),
    (
        "info-fps-a-string-scale-data",
        _info_edited(lambda i: i | {"fps": "10"}, "scale_data"),
        2,
        "fps is '10' (a string)",
    ),
    # 12: a tool's re-run may replace its own result, never the user's file of that name
    (
        "replay-yield-out-holds-users-json",
        _tool_over_users_result(
            "replay_yield.json", "-m tools.replay yield --tasks pusht --seeds 1 --sources 1 --attempts 1"
        ),
        2,
        "replay_yield.json exists and was not written by this tool; pass another --out",
    ),
    (
        "replay-compare-out-holds-users-json",
        _tool_over_users_result("replay_compare.json", "-m tools.replay compare --smoke --seeds 1"),
        2,
        "replay_compare.json exists and was not written by this tool; pass another --out",
    ),
    (
        "replay-sigma-out-holds-users-json",
        _tool_over_users_result(
            "replay_sigma.json", "-m tools.replay compare --smoke --sigma 1 --attempts 1 --sigma_seeds 1"
        ),
        2,
        "replay_sigma.json exists and was not written by this tool; pass another --out",
    ),
    (
        "replay-sigma-out-holds-users-png",
        _tool_over_users_result(
            "replay_sigma.png", "-m tools.replay compare --smoke --sigma 1 --attempts 1 --sigma_seeds 1"
        ),
        2,
        "replay_sigma.png exists and was not written by this tool; pass another --out",
    ),
    (
        "bench-engine-costs-out-holds-users-json",
        _tool_over_users_result(
            "bench_engine_costs.json",
            "-m tools.bench engine --costs_only --cost_repeats 1 --cost_attempts_per_demo 1",
        ),
        2,
        "bench_engine_costs.json exists and was not written by this tool; pass another --out",
    ),
    (
        "bench-engine-out-holds-users-json",
        _tool_over_users_result(
            "bench_engine.json", "-m tools.bench engine --cost_repeats 0 --sizes 1 --executors local"
        ),
        2,
        "bench_engine.json exists and was not written by this tool; pass another --out",
    ),
]


@pytest.mark.parametrize(
    "make, code, needle", [c[1:] for c in ISSUE48_CASES], ids=[c[0] for c in ISSUE48_CASES]
)
def test_issue48_bad_input_is_one_line_and_nothing_is_touched(ref, tmp_path, make, code, needle):
    test_bad_input_is_one_line_and_nothing_is_touched(ref, tmp_path, make, code, needle)


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["augment_demos.py", "--per_demo", "1", "--src"], "overlaps --src"),
        ([*SD, "--no-cache", "--pusht_data"], "is inside --pusht_data"),
    ],
    ids=["augment_demos", "scale_data"],
)
def test_out_inside_the_source_is_refused_before_anything_is_written_there(ref, tmp_path, argv, needle):
    """Issue 48 #9: --out inside the source is refused before any write: the probe that --out can be
    written never lands in the source (its folder's mtime unchanged, nothing left by a kill there)."""
    src = user_set(ref, tmp_path, "src")
    before, mtime = snapshot([src]), src.stat().st_mtime_ns
    time.sleep(0.05)  # a write after this moves the folder's mtime past the one read
    p = run(*argv, src, "--out", src / "sub")
    err = [line for line in p.stderr.splitlines() if line.strip()]
    assert p.returncode == 2 and len(err) == 1 and needle in err[0], p.stderr
    assert src.stat().st_mtime_ns == mtime and snapshot([src]) == before
    assert not (src / "sub").exists()


def test_a_tools_figure_is_replaced_only_beside_its_own_result(tmp_path):
    """Issue 48 #12: a figure (tools.replay compare's replay_sigma.png) has no mark of its own: it may be
    replaced beside a result of the tool, never where the user's file of that name stands alone."""
    from ch37.errors import DataError

    png = tmp_path / "replay_sigma.png"
    png.write_bytes(b"\x89PNG mine")
    with pytest.raises(DataError, match="replay_sigma.png exists and was not written by this tool"):
        ownership.check_own_result(tmp_path / "replay_sigma.json", "replay_sigma", beside=[png])
    (tmp_path / "replay_sigma.json").write_text(json.dumps({"kind": "replay_sigma"}))
    ownership.check_own_result(tmp_path / "replay_sigma.json", "replay_sigma", beside=[png])


def test_the_gpu_check_refuses_a_bad_argument_before_it_starts(tmp_path):
    """Issue 62 #10: tools/gpu_check.sh --bogus, --run with no command and a --wheels word it has no list
    for started the check (a pip install into /tmp/site, a log in $OUT) or ran nothing with pip's lines;
    each is one `error:` line, exit 2, with nothing written and no GPU asked for. --help prints the usage
    and exits 0, also without writing."""
    out = tmp_path / "out"
    env = {**os.environ, "OUT": str(out), "PATH": "/usr/bin:/bin"}  # no python3 from the venv either
    script = ROOT / "tools" / "gpu_check.sh"
    for args, needle in (
        (["--bogus"], "'--bogus'"),
        (["--run"], "--run needs a command"),
        (["--wheels", "all"], "'all'"),
        (["--wheels", "value", "again"], "--wheels takes one word"),
        ([""], "unknown argument ''"),
    ):
        p = subprocess.run(["bash", script, *args], capture_output=True, text=True, env=env, timeout=60)
        err = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(err) == 1 and err[0].startswith("error:"), (args, p.stderr)
        assert needle in err[0] and p.stdout == "" and not out.exists(), (args, p.stderr)
    p = subprocess.run(["bash", script, "--help"], capture_output=True, text=True, env=env, timeout=60)
    assert p.returncode == 0 and p.stdout.startswith("usage: bash tools/gpu_check.sh"), p.stdout + p.stderr
    assert "--run CMD" in p.stdout and p.stderr == "" and not out.exists()


def test_bench_engine_measures_every_task_and_refuses_an_unknown_one_in_one_line(tmp_path):
    """Issue 51 #2 refused gym-pusht and Pusher, whose sets keep part of the observation in
    observation.environment_state; issue 58 #6: the costs read a source as a run does, so every registered
    task is measured (gym-pusht here, on a 2-episode set, one attempt per source, one round). A task the
    engine does not know is one `error:` line, exit 2, before anything is made."""
    p = run("-m", "tools.bench", "engine", "--task", "nope", "--costs_only", "--out", tmp_path / "o")
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "invalid choice: 'nope'" in err[0], p.stderr[-2000:]
    assert not (tmp_path / "o").exists()
    src = tmp_path / "src"
    assert (
        run("gen_demos.py", "--task", "gym_pusht", "--episodes", "2", "--quiet", "--out", src).returncode == 0
    )
    args = ["--task", "gym_pusht", "--costs_only", "--src", src, "--cost_attempts_per_demo", "1"]
    p = run("-m", "tools.bench", "engine", *args, "--cost_repeats", "1", "--out", tmp_path / "o")
    assert p.returncode == 0, p.stderr[-2000:]
    costs = json.loads((tmp_path / "o" / "bench_engine_costs.json").read_text())["per_demo_costs"]
    assert costs["task"] == "gym_pusht" and costs["attempts"] == 2 and costs["physics_s"] > 0
    # the run on the clocks: the expert acted on every simulated frame, and the physics stepped them
    assert costs["task_calls"] >= costs["simulated_frames"] > 0
    assert costs["task_s"] > 0 and costs["physics_in_run_s"] > 0 and costs["engine_over_physics"] >= 1


def test_bench_kernels_parts_splits_a_held_step_around_its_bare_products():
    """Issue 59 #1: python -m tools.bench kernels --parts times bc_recipe.train's own calls inside a held
    step (one round of a few steps here): every part took time, together less than the step, and the bare
    products beside it on numpy's OpenBLAS, one arm's and two arms' at once."""
    import re

    p = run("-m", "tools.bench", "kernels", "--paths", "held", "--rounds", "1", "--steps", "20", "--parts")
    assert p.returncode == 0, p.stderr[-2000:]
    step = float(re.search(r"held 2 +threads +([0-9.]+) ms/step", p.stdout).group(1))
    got = re.search(
        r"held 2 +a step's parts, ms \(medians\): (.*); the rest \(batch, loss, bar\) (-?[0-9.]+)", p.stdout
    )
    parts = {n: float(v) for n, v in (x.rsplit(" ", 1) for x in got.group(1).split(", "))}
    assert list(parts) == ["forward", "backward", "Adam", "zero_grad", "scheduler"], parts
    assert all(v > 0 for v in parts.values()) and sum(parts.values()) < step and float(got.group(2)) > 0
    bare = re.search(
        r"one thread ([0-9.]+), two arms' at once on two threads ([0-9.]+) \((\d+)% of", p.stdout
    )
    one, two, share = map(float, bare.groups())
    assert 0 < one < step and 0 < two and share == pytest.approx(100 * two / step, abs=0.5)


@pytest.mark.parametrize("sub", ["reference", "host"])
def test_bench_reference_refuses_what_is_not_a_reference_checkout_in_one_line(tmp_path, sub):
    """Issue 59 #1's one command for the other host kind (`host`) and its first step (`reference`): a --ref
    without the reference chapter's script, a --ref_python that is not a program, --rounds 0: one `error:`
    line each, exit 2, nothing run or made."""
    from tools import bench

    (tmp_path / "ref").mkdir()
    fake_py = tmp_path / "python"
    fake_py.write_text("")
    out = tmp_path / "o"
    for args, said in (
        (["--ref", tmp_path / "ref", "--ref_python", sys.executable], "no curriculum/phase3_advanced"),
        (["--ref", ROOT, "--ref_python", fake_py, "--rounds", "0"], "--rounds"),
    ):
        p = run("-m", "tools.bench", sub, *args, "--out", out)
        err = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(err) == 1 and said in err[0], p.stderr[-2000:]
        assert not out.exists()
    script = tmp_path / "ref" / bench.REF_SCRIPT
    script.parent.mkdir(parents=True)
    script.write_text("")
    p = run("-m", "tools.bench", sub, "--ref", tmp_path / "ref", "--ref_python", fake_py, "--out", out)
    assert p.returncode == 2 and "not an executable Python" in p.stderr and not out.exists(), p.stderr[-2000:]
    # the reference's work: two arms of 500 epochs, a last short minibatch each epoch counted as a step
    assert bench.ref_arm_steps({"source_frames": 420, "aug_frames": 3070}) == 500 * (4 + 28)


def test_bench_versus_gives_the_median_and_the_fastest_run_of_each_chapter_per_unit_of_work():
    """tools.bench.versus: each side's median and fastest wall-clock, and ours over the reference per unit of
    training work (arm-steps), from a sitting's runs; the fastest is not the median's pair."""
    from tools import bench

    runs = {
        "ours": [{"wall_s": s} for s in (3.0, 1.0, 2.0)],
        "reference": [{"wall_s": s} for s in (10, 4, 6)],
    }
    got = bench.versus(runs, {"ours": 200, "reference": 100})
    assert got["median"] == (2.0, 6, pytest.approx(2 / 6 * 100 / 200))
    assert got["fastest"] == (1.0, 4, pytest.approx(1 / 4 * 100 / 200))


def test_bench_host_keeps_each_steps_output_and_sums_up_issue_59s_figures(tmp_path):
    """`python -m tools.bench host`: a step's output is shown and kept (tee), a failed step is one line
    naming its log; a user's file where a log would go is refused before any work; the summary reads the
    figures issue 59's note gives from what the steps wrote (here: a kept Zen 4 sitting's files)."""
    from ch37.errors import DataError
    from tools import bench

    log = tmp_path / "step.txt"
    bench.tee([sys.executable, "-c", "print('one'); print('two')"], log)
    assert log.read_text() == "one\ntwo\n"
    with pytest.raises(DataError, match=f"exited 3; its output is in {log}"):
        bench.tee([sys.executable, "-c", "print('half'); raise SystemExit(3)"], log)
    assert log.read_text() == "half\n"
    # a user's file where the host check writes a log, and no result of ours beside it: refused
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "bench_lesson.txt").write_text("mine")
    script = tmp_path / "ref" / bench.REF_SCRIPT
    script.parent.mkdir(parents=True)
    script.write_text("")
    args = ["--ref", tmp_path / "ref", "--ref_python", sys.executable, "--out", tmp_path / "o"]
    p = run("-m", "tools.bench", "host", *args)
    assert p.returncode == 2 and "bench_lesson.txt exists and was not written by this tool" in p.stderr
    assert (tmp_path / "o" / "bench_lesson.txt").read_text() == "mine"
    # the summary, from a kept sitting's files under the names the host check writes
    out = tmp_path / "kept"
    out.mkdir()
    sitting = ROOT / "results" / "zen4_arms"
    shutil.copy(sitting / "0f380e6" / "bench_reference.json", out)
    shutil.copy(sitting / "0f380e6" / "bench_lesson.txt", out)
    shutil.copy(sitting / "bench_kernels_parts.txt", out / "bench_kernels.txt")
    v = json.loads((out / "bench_reference.json").read_text())
    summary = "\n".join(bench.host_summary(out, "AMD EPYC family 25 model 17"))
    assert summary.startswith("host: AMD EPYC family 25 model 17, commit 0f380e6\n")
    med = v["median_wall_s"]
    medians = (
        f"ours {med['ours']:.1f} s, the reference {med['reference']:.1f} s: {v['ratio_per_unit_of_work']:.3f}"
    )
    assert f"medians of 3: {medians} per unit" in summary
    ours, ref = (min(r["wall_s"] for r in v["runs"][k]) for k in ("ours", "reference"))  # 68.6 s, 85.8 s
    fastest = ours / ref * v["arm_steps"]["reference"] / v["arm_steps"]["ours"]
    assert f"fastest of 3: ours {ours:.1f} s, the reference {ref:.1f} s: {fastest:.3f} per unit" in summary
    assert "the banner against each of our runs: -4%, -4%, -6%" in summary
    assert "in-run training: 111 GFLOP/s on OpenBLAS Haswell kernels, 101% of this machine's best" in summary
    for path, weights in (("held", "ebffe19e"), ("compatible", "fec0e134"), ("native", "87d74143")):
        assert f"{path}: " in summary and f"weights {weights}" in summary


# ---------------------------------------------------------------------------------------------
# Issue 62: datagen.check's arguments (#3), --out through a link (#5), a relative --out (#6)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, needle",
    [
        (["pusher", "--seed", "-1", "--episodes", "1"], "--seed must be >= 0, got -1"),
        (["aloha_transfer_cube", "--seed", "-1", "--episodes", "1"], "--seed must be >= 0, got -1"),
        (["pusht", "--tol", "nan", "--episodes", "1"], "--tol must be a finite non-negative number, got nan"),
        (["pusht", "--tol", "-1", "--episodes", "1"], "--tol must be a finite non-negative number, got -1.0"),
        (["pusht", "--episodes", "0"], "--episodes must be a positive integer, got 0"),
    ],
    ids=["seed-pusher", "seed-transfer-cube", "tol-nan", "tol-negative", "episodes-0"],
)
def test_the_check_commands_arguments_are_one_line_each(argv, needle):
    """Issue 62 #3: `python -m datagen.check` took --seed -1 to a traceback (pusher, transfer-cube),
    --tol nan as a round trip that can never fail and --tol -1 as one that always does: one `error:`
    line each (ch37.config's bounds, as every command's flags), exit 2, before any env is made."""
    p = run("-m", "datagen.check", *argv)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and err[0] == f"error: {needle}", p.stderr[-2000:]
    assert p.stdout == "", p.stdout


def test_out_through_a_link_to_a_folder_is_written_there_and_a_dangling_link_is_refused(tmp_path):
    """Issue 62 #5: gen_demos.py's --out given as a link to an empty folder was "Not a directory; a part
    of the path is a file", where augment_demos.py writes through the same link: both write into the folder
    it points to, the link left as it is. A link to nothing is refused by both in one line naming the
    user's path (not an internal .ch37-partial-* one), nothing created."""
    (tmp_path / "sets").mkdir()
    (tmp_path / "set_link").symlink_to("sets")
    p = run("gen_demos_pusht.py", "--quiet", "--episodes", "1", "--out", tmp_path / "set_link")
    assert p.returncode == 0, p.stdout + p.stderr
    assert (tmp_path / "set_link").is_symlink() and (tmp_path / "sets" / "meta" / "info.json").is_file()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no partial folder left

    (tmp_path / "dangling").symlink_to("nowhere")
    before = sorted(os.listdir(tmp_path))
    for argv in (
        ["gen_demos_pusht.py", "--quiet", "--episodes", "1"],
        ["augment_demos.py", "--src", tmp_path / "set_link", "--per_demo", "1", "--quiet"],
        [*SD, "--no-cache"],
    ):
        p = run(*argv, "--out", tmp_path / "dangling")
        err = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(err) == 1, (argv, p.stderr[-2000:])
        assert f"--out {tmp_path / 'dangling'} is a link to nowhere, which does not exist" in err[0], err
        assert sorted(os.listdir(tmp_path)) == before and not (tmp_path / "nowhere").exists()


# ---------------------------------------------------------------------------------------------
# Issue 62 #1, #2: a user's task whose member returns a NaN or the wrong shape
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pusht_source():
    """One seed-0 PushT expert demo as a source (the engine's Source)."""
    import pusht_env
    from ch37.seeds import env_seed
    from datagen import PUSHT, Source, rollout
    from scripted_expert import PushTExpert

    env = pusht_env.PushTEnv()
    ep = rollout(PUSHT, env, PushTExpert(noise=0.0), env.reset(env_seed(0, "demo", 0)))
    return Source(0, ep["observation.state"], ep["action"])


def _nan_start(self, first, rng, how):
    from datagen.tasks.pusht import PushT

    return (float("nan"),) + tuple(PushT.perturb(self, first, rng, how))[1:]


def _short_start(self, first, rng, how):
    from datagen.tasks.pusht import PushT

    return tuple(PushT.perturb(self, first, rng, how))[:3]


BROKEN_MEMBERS = [  # (id, the member overridden, its code, the mode that calls it, the one line's words)
    ("perturb-nan", "perturb", _nan_start, "resolve", "PushT.perturb returned a non-finite number (nan"),
    ("perturb-short", "perturb", _short_start, "resolve", "PushT.perturb returned shape (3,); it owes (5,)"),
    (
        "object-pose-3x3",
        "object_pose",
        lambda self, state: np.eye(3),
        "replay",
        "object_pose returned shape (3, 3); it owes (3,) or (4, 4)",
    ),
    (
        "action-3-wide",
        "replay",
        "an action kind whose to_action returns 3 numbers",  # made in the test: ThreeWide below
        "replay",
        "replay.action.to_action returned shape (3,); it owes (2,)",
    ),
]


def three_wide_replay():
    """PushT's replay settings with an action kind that answers 3 numbers for PushT's 2-wide action (issue
    58 #4 moved the action's conversion from Task.target_to_action into the ReplaySpec's action kind)."""
    from dataclasses import replace

    from datagen.task import VelocityCommand
    from datagen.tasks.pusht import PushT

    class ThreeWide(VelocityCommand):
        def to_action(self, *a, **k):
            return np.zeros(3, np.float32)

    action = PushT.replay.action
    return replace(PushT.replay, action=ThreeWide(action.columns, action.gain, action.limit, action.grips))


@pytest.mark.parametrize(
    "member, code, mode, needle", [b[1:] for b in BROKEN_MEMBERS], ids=[b[0] for b in BROKEN_MEMBERS]
)
def test_a_users_task_member_that_returns_nan_or_the_wrong_shape_is_refused_naming_it(
    pusht_source, member, code, mode, needle
):
    """Issue 62 #1, #2: a task whose perturb returned a NaN was grown as if real (non-finite aug.start,
    actions and states written); a perturb 5 numbers short, an object_pose of shape (3, 3) or a
    target_to_action (now the replay's action kind) 3 wide for a 2-wide action were tracebacks deep in the
    env or the replay. Each is now one DataError line naming the member, the shape it gave and the one it
    owes, before anything is simulated from it; datagen.check's perturb check says the same before a long
    run."""
    from ch37.errors import DataError
    from datagen import Perturbation, engine
    from datagen.check import perturb_problem
    from datagen.tasks.pusht import PushT

    code = three_wide_replay() if member == "replay" else code
    task = type("PushT", (PushT,), {member: code})()
    with pytest.raises(DataError) as e:
        engine.attempt(task, pusht_source, 0, Perturbation(0, 0.02, 0.1), mode=mode)
    assert len(str(e.value).splitlines()) == 1 and needle in str(e.value), str(e.value)
    if member == "perturb":
        problem, _ = perturb_problem(task, [pusht_source.states[0]], 0)
        assert problem is not None and needle in problem, problem
    else:  # the engine's own task passes the same check
        assert perturb_problem(PushT(), [pusht_source.states[0]], 0)[0] is None
