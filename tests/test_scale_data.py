"""scale_data.py end to end at --smoke size: determinism, no data loss, bad flags, the lesson's invariants."""

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, run_script

from ch37 import ownership
from ch37.process import has_avx2_fma
from ch37.seeds import env_seed
from lerobot_v3 import dataset as lerobot_io


def smoke(out, *extra, check=True, cache=False):
    flags = () if cache else ("--no-cache",)
    return run_script(
        "scale_data.py", "--smoke", "--seed", "0", "--no-rerun", "--out", out, *flags, *extra, check=check
    )


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Smoke runs shared by the tests below: A and B identical flags in separate folders."""
    a, b = tmp_path_factory.mktemp("a"), tmp_path_factory.mktemp("b")
    out = {"a": (a, smoke(a)), "b": (b, smoke(b))}
    return out


def tree_digest(path):
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        h.update(str(p.relative_to(path)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def test_smoke_twice_is_byte_identical(runs):
    (a, pa), (b, _) = runs["a"], runs["b"]
    for name in ("metrics.json", "cross_embodiment.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert "headline:" in pa.stdout and "metrics.json" in pa.stdout.strip().splitlines()[-1]
    m = json.loads((a / "metrics.json").read_text())
    assert m["smoke"] is True and m["seed"] == 0 and m["action_dims"] == {"aloha": 6, "pusht": 2}
    assert m["attempts"] == m["source_demos"] * m["config"]["aug_per_demo"]
    assert (a / "scale_data.png").stat().st_size > 1000
    assert pa.stderr.count("Traceback") == 0


def test_seeds_draw_different_data(runs, tmp_path):
    smoke(tmp_path, "--seed", "1")  # --seed given twice: argparse keeps the last
    a = json.loads((runs["a"][0] / "cross_embodiment.json").read_text())
    b = json.loads((tmp_path / "cross_embodiment.json").read_text())
    assert a["embodiments"][0]["stats"] != b["embodiments"][0]["stats"]


def test_stats_match_lerobot_meta_stats(runs):
    a = runs["a"][0]
    cross = json.loads((a / "cross_embodiment.json").read_text())
    for e in cross["embodiments"]:
        (root,) = (a / "demos").glob(f"{e['name']}_seed0_*")
        meta = json.loads((root / "meta" / "stats.json").read_text())
        raw = lerobot_io.load_arrays(root)
        for part, key in (("state", "observation.state"), ("action", "action")):
            ours, theirs = e["stats"][part], meta[key]
            for stat in ("min", "max", "mean"):
                np.testing.assert_allclose(
                    ours[stat], theirs[stat], atol=1e-5, err_msg=f"{e['name']} {key} {stat}"
                )
            np.testing.assert_allclose(ours["std"], theirs["std"], atol=1e-4, rtol=1e-3)
            # ours are global quantiles; LeRobot's q01/q99 are count-weighted means of per-episode
            # (histogram) quantiles. Check ours against the data, and LeRobot's convention against it too.
            x, ep = raw[key], raw["episode_index"]
            span = np.maximum(np.array(theirs["max"]) - np.array(theirs["min"]), 1e-6)
            for q, frac in (("q01", 0.01), ("q99", 0.99)):
                np.testing.assert_allclose(ours[q], np.quantile(x, frac, axis=0), atol=1e-5)
                per_ep = sum(
                    np.quantile(x[ep == i], frac, axis=0) * (ep == i).sum() for i in np.unique(ep)
                ) / len(ep)
                assert np.all(np.abs(per_ep - np.array(theirs[q])) <= 0.05 * span + 1e-6), (e["name"], key, q)
            assert np.all(np.array(ours["q01"]) <= np.array(ours["q99"]))


def test_masked_loss_gives_padded_dims_exactly_zero_gradient(runs):
    cross = json.loads((runs["a"][0] / "cross_embodiment.json").read_text())
    assert cross["padded_dim_max_grad"] == 0.0
    assert cross["padded_action_dim"] == 6
    dens = {e["name"]: e["mask_density"] for e in cross["embodiments"]}
    assert dens == {"pusht": pytest.approx(1 / 3, abs=1e-6), "aloha": 1.0}
    assert cross["state_index_2_means"] == {"pusht": "block_x", "aloha": "right_grip"}


def test_aug_zero_reproduces_source_arm_to_the_digit(runs, tmp_path):
    """--aug_per_demo 0: the two data rows of the 2x2 are the same data, so they must agree to the digit,
    and the source row must equal the source row of the run with augmentation (same short budget).
    Issue 60 #3: that arm trains once, not twice, and the run says "no augmentation" instead of
    "0 attempts, 0 kept of 0 wanted, yield 0.00"."""
    a = runs["a"][0]
    shutil.copytree(a / "demos", tmp_path / "demos")  # reuse the cached demo sets
    said = smoke(tmp_path, "--aug_per_demo", "0").stdout
    assert "no augmentation (--aug_per_demo 0)" in said and "yield" not in said, said
    assert said.count("steps for the one data arm (no augmented data)") == 2, said  # short and full
    m0 = json.loads((tmp_path / "metrics.json").read_text())
    m2 = json.loads((a / "metrics.json").read_text())
    assert m0["kept"] == 0 and m0["augmented_frames"] == 0
    assert m0["budgets"]["short"] == m0["budgets"]["full"] == m2["budgets"]["short"]
    for budget in ("short", "full"):
        src, aug = dict(m0["arms"][f"source_{budget}"]), dict(m0["arms"][f"augmented_{budget}"])
        assert src.pop("data") == "source" and aug.pop("data") == "augmented"
        assert src == aug  # success, interval, steps, frames and the final loss to the digit
    assert m0["arms"]["source_short"] == m2["arms"]["source_short"]
    assert all(v == 0 for v in m0["effects"].values())


def test_the_arms_of_a_budget_take_equal_steps(runs):
    m = json.loads((runs["a"][0] / "metrics.json").read_text())
    for budget, steps in m["budgets"].items():
        assert m["arms"][f"source_{budget}"]["steps"] == m["arms"][f"augmented_{budget}"]["steps"] == steps
    assert m["budgets"]["full"] > m["budgets"]["short"]  # more data, more steps at --epochs passes
    batch, epochs = m["config"]["batch_size"], m["config"]["epochs"]
    assert m["budgets"]["short"] == -(-epochs * m["source_frames"] // batch)
    total = m["source_frames"] + m["augmented_frames"]
    assert m["budgets"]["full"] == -(-epochs * total // batch)
    assert m["scale_effect"] == m["effects"]["data_full"]


def test_augmentation_is_nested(runs, tmp_path):
    a = runs["a"][0]
    shutil.copytree(a / "demos", tmp_path / "demos", ignore=shutil.ignore_patterns("pusht_aug*"))
    smoke(tmp_path, "--aug_per_demo", "1")
    starts = {}
    for out, k in ((tmp_path, 1), (a, 2)):
        (root,) = (out / "demos").glob(f"pusht_aug_seed0_*_k{k}")
        d = lerobot_io.load_arrays(root, keys=("aug.start", "aug.source_episode", "episode_index"))
        first = np.unique(d["episode_index"], return_index=True)[1]
        starts[k] = {
            tuple(np.round(d["aug.start"][i], 6)) + (int(np.ravel(d["aug.source_episode"])[i]),)
            for i in first
        }
    assert starts[1] and starts[1] < starts[2]


def test_aug_set_loads_with_provenance(runs):
    (root,) = (runs["a"][0] / "demos").glob("pusht_aug_seed0_*")
    ds = lerobot_io.open_dataset(root)
    m = json.loads((runs["a"][0] / "metrics.json").read_text())
    assert ds.num_episodes == m["kept"] and ds.num_frames == m["augmented_frames"]
    item = ds[0]
    assert item["aug.start"].shape == (5,) and "aug.source_episode" in item


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--epochs", "0"], "--epochs"),
        (["--aug_pos_sigma", "-0.1"], "--aug_pos_sigma"),
        (["--device", "tpu"], "--device"),
        (["--batch_size", "abc"], "batch_size"),
        (["--seed", "-2"], "--seed"),
        (["--source_episodes", "-3"], "--source_episodes"),
        (["--lr", "nan"], "--lr"),
    ],
)
def test_bad_flags_one_clear_line(tmp_path, argv, needle):
    p = run_script("scale_data.py", *argv, "--out", tmp_path / "o", check=False)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and needle in err[0] and "Traceback" not in p.stderr
    assert not (tmp_path / "o").exists()


def test_help_shows_every_default():
    """Issue 33 #7: the README promises every flag with its default; each option's entry says one."""
    text = run_script("scale_data.py", "--help").stdout.split("options:", 1)[1]
    entries = re.split(r"\n(?=  -)", text.strip("\n"))
    assert len(entries) > 15 and entries[0].startswith("  -h, --help")
    missing = [e.split()[0] for e in entries[1:] if "(default" not in " ".join(e.split())]
    assert not missing, f"--help gives no default for {missing}"


def test_help_readme_and_printed_lines_tell_one_story():
    """Issue 60 #6: --workers' help named --ray, which scale_data.py refuses; the README offered
    --aug_mode resolve|replay where the flag also takes replay_live; --eval_episodes said +-0.14 where the
    README said about +-0.1. One story now."""
    from ch37 import config

    text = " ".join(run_script("scale_data.py", "--help").stdout.split())
    workers = text[text.rindex("--workers WORKERS") :]  # its entry, after the usage line
    assert "--ray" not in workers and "Ray" not in workers, workers
    readme = (ROOT / "README.md").read_text()
    assert f"`--aug_mode {'|'.join(config.MODES)}`" in readme
    evals = text[text.rindex("--eval_episodes EVAL_EPISODES") :][:200]
    assert "about +-0.1" in evals and "about +-0.1" in readme, evals


def test_unavailable_device_is_refused(tmp_path):
    import torch

    # every machine lacks one of the two: CUDA on a Mac, MPS on Linux and Windows
    absent = "mps" if torch.cuda.is_available() else "cuda"
    p = run_script("scale_data.py", "--device", absent, "--out", tmp_path / "o", check=False)
    assert p.returncode == 2 and "not available" in p.stderr and len(p.stderr.strip().splitlines()) == 1


def test_user_dataset_is_used_as_given_and_never_touched(runs, tmp_path):
    (src,) = (runs["a"][0] / "demos").glob("pusht_seed0_*")
    mine = tmp_path / "my_pusht"
    shutil.copytree(src, mine)
    (mine / ownership.STAMP_NAME).unlink()  # the user's own set: no stamp of ours
    before = tree_digest(mine)
    p = smoke(tmp_path / "o", "--pusht_data", mine)
    assert "used as given" in p.stdout
    assert tree_digest(mine) == before


def test_mismatching_user_dataset_is_refused_untouched(runs, tmp_path):
    (aloha,) = (runs["a"][0] / "demos").glob("aloha_seed0_*")
    mine = tmp_path / "wrong"
    shutil.copytree(aloha, mine)
    (mine / ownership.STAMP_NAME).unlink()
    before = tree_digest(mine)
    p = smoke(tmp_path / "o", "--pusht_data", mine, check=False)
    assert p.returncode == 2 and "action" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert tree_digest(mine) == before
    # a set we stamped for another request is refused too, not rebuilt
    (pusht,) = (runs["a"][0] / "demos").glob("pusht_seed0_*")
    ours = tmp_path / "ours"
    shutil.copytree(pusht, ours)
    before = tree_digest(ours)
    p = smoke(tmp_path / "o2", "--pusht_data", ours, "--seed", "1", check=False)
    assert p.returncode == 2 and "does not match" in p.stderr
    assert tree_digest(ours) == before


def test_foreign_directory_at_cache_path_is_refused_untouched(tmp_path):
    cache = tmp_path / "demos" / "pusht_seed0_ep4"
    cache.mkdir(parents=True)
    (cache / "thesis.tex").write_text("do not lose me")
    p = smoke(tmp_path, check=False)
    assert p.returncode == 2 and "did not make" in p.stderr
    assert [x.name for x in cache.iterdir()] == ["thesis.tex"] and (
        cache / "thesis.tex"
    ).read_text() == "do not lose me"


def test_stale_set_we_made_is_rebuilt(runs, tmp_path):
    shutil.copytree(runs["a"][0] / "demos", tmp_path / "demos")
    (root,) = (tmp_path / "demos").glob("pusht_seed0_*")
    stamp = json.loads((root / ownership.STAMP_NAME).read_text())
    stamp["generator_version"] = -1
    (root / ownership.STAMP_NAME).write_text(json.dumps(stamp))
    p = smoke(tmp_path)
    assert "generated" in p.stdout
    assert json.loads((root / ownership.STAMP_NAME).read_text())["generator_version"] != -1
    assert (tmp_path / "metrics.json").read_bytes() == (runs["a"][0] / "metrics.json").read_bytes()


def test_worker_count_never_changes_the_result(runs, tmp_path):
    a = runs["a"][0]  # default workers (the CPU count)
    shutil.copytree(a / "demos", tmp_path / "demos", ignore=shutil.ignore_patterns("pusht_aug*"))
    smoke(tmp_path, "--workers", "1")
    assert (tmp_path / "metrics.json").read_bytes() == (a / "metrics.json").read_bytes()
    (r1,) = (tmp_path / "demos").glob("pusht_aug*")
    (r2,) = (a / "demos").glob("pusht_aug*")
    d1, d2 = (lerobot_io.load_arrays(r, keys=("observation.state", "action", "aug.start")) for r in (r1, r2))
    assert all(d1[k].tobytes() == d2[k].tobytes() for k in d1)


def test_result_cache_reuses_only_the_same_configuration(tmp_path, monkeypatch):
    monkeypatch.setenv("CH37_CACHE_DIR", str(tmp_path / "cache"))
    first = smoke(tmp_path / "one", cache=True)
    assert "reusing" not in first.stdout
    again = smoke(tmp_path / "two", cache=True)  # same flags, another --out: served from the cache
    assert "reusing the result" in again.stdout  # nothing recomputed:
    assert "augment (resolve):" not in again.stdout
    assert (tmp_path / "two" / "metrics.json").read_bytes() == (
        tmp_path / "one" / "metrics.json"
    ).read_bytes()
    assert str(tmp_path / "two") in again.stdout.strip().splitlines()[-1]
    other = smoke(tmp_path / "three", "--aug_yaw_sigma", "0.4", cache=True)  # a flag --smoke does not pin
    assert "reusing" not in other.stdout and "augment (resolve):" in other.stdout
    assert (tmp_path / "three" / "metrics.json").read_bytes() != (
        tmp_path / "one" / "metrics.json"
    ).read_bytes()


def test_result_key_changes_with_every_input():
    from ch37 import result_cache

    base = {
        "seed": 0,
        "epochs": 500,
        "smoke": False,
        "device": "cpu",
        "out": "a",
        "workers": 2,
        "cache": True,
    }
    k = result_cache.result_key(base)
    assert (
        result_cache.result_key(dict(base, out="b", workers=1, cache=False)) == k
    )  # where and how fast: same result
    for field, value in (("seed", 1), ("epochs", 499), ("smoke", True), ("device", "cuda"), ("lr", 0.01)):
        assert result_cache.result_key(dict(base, **{field: value})) != k, field
    # another MKL kernel branch (other bits, another result): the test of issue 48 #10 below


def test_a_cached_result_goes_stale_when_any_imported_file_changes(tmp_path, monkeypatch):
    """The cache records every project file the run imported (code_files): an edit to any one of them
    makes the entry stale, so it is never replayed."""
    from ch37 import result_cache

    recorded = result_cache.code_files()
    for name in recorded:
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(result_cache.ROOT / name, tmp_path / name)
    monkeypatch.setattr(result_cache, "ROOT", tmp_path)
    assert not result_cache.stale_code(recorded)
    stale = 0
    for name in recorded:
        saved = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(saved + b"\n")
        stale += result_cache.stale_code(recorded)
        (tmp_path / name).write_bytes(saved)
    assert stale == len(recorded) and not result_cache.stale_code(recorded)
    (tmp_path / next(iter(recorded))).unlink()  # a file gone is a change too
    assert result_cache.stale_code(recorded)


def test_code_files_hold_every_file_the_lesson_imports():
    """Whatever the lesson imports from the three packages, the envs and the experts (and the model
    files the envs load) is in the code a cache entry records, with no list to keep by hand."""
    import importlib

    import ch37
    from ch37 import result_cache

    lesson = {"pusht_env.py", "pusht.xml", "aloha_env.py", "aloha.xml", "scripted_expert.py", "bc_recipe.py"}
    lesson |= {"gen_demos_pusht.py", "gen_demos_aloha.py"}
    for name in (p[: -len(".py")] for p in lesson if p.endswith(".py")):
        importlib.import_module(name)
    packages = set()
    for pkg in ("ch37", "lerobot_v3", "datagen"):
        for path in sorted((ch37.ROOT / pkg).glob("*.py")):
            importlib.import_module(pkg if path.stem == "__init__" else f"{pkg}.{path.stem}")
            packages.add(f"{pkg}/{path.name}")
    got = set(result_cache.code_files())
    assert lesson | packages <= got, sorted((lesson | packages) - got)
    from datagen import demos

    emb = importlib.import_module("gen_demos_pusht").PUSHT  # a demo set's digest reads a subset of them
    expert = importlib.import_module(emb.expert.cls.__module__)
    assert set(ch37.code_files((demos, importlib.import_module("pusht_env"), expert))) <= got
    assert not any(name.startswith(("tests/", ".venv/")) for name in got)


@pytest.mark.parametrize("workers", [1, 3])
def test_lockstep_envs_step_each_env_as_if_alone(workers):
    """The evaluation's env pool: any worker count, any subset of envs per step, the same
    trajectories as stepping each env by itself."""
    from ch37.parallel import LockstepEnvs
    from pusht_env import PushTEnv

    seeds = [env_seed(0, "eval", j) for j in range(5)]
    acts = np.random.default_rng(0).uniform(-1, 1, (30, len(seeds), 2))
    plan = [[j for j in range(len(seeds)) if (t + j) % 3] for t in range(len(acts))]  # envs stepped at t
    ref = []
    for j, s in enumerate(seeds):
        env = PushTEnv()
        traj = [env.reset(s)]
        traj += [env.step(acts[t, j])[0] for t in range(len(acts)) if j in plan[t]]
        ref.append(np.stack(traj))
    with LockstepEnvs(PushTEnv, seeds, workers=workers) as envs:
        obs = envs.reset()
        got = [[o] for o in obs]
        for t, idx in enumerate(plan):
            o, done, success = envs.step(idx, acts[t, idx])
            assert o.shape == (len(idx), 10) and done.dtype == bool and not done.any() and not success.any()
            for j, row in zip(idx, o):
                got[j].append(row)
    for j in range(len(seeds)):
        assert np.stack(got[j]).tobytes() == ref[j].tobytes()


def test_lockstep_envs_raise_a_worker_error():
    from ch37.parallel import LockstepEnvs
    from pusht_env import PushTEnv

    with LockstepEnvs(PushTEnv, [1, 2], workers=2) as envs:
        envs.reset()
        with pytest.raises(ValueError, match="non-finite action"):
            envs.step([0, 1], np.array([[0.0, 0.0], [np.nan, 0.0]]))


KERNEL_KEYS = r"""
import json, os, sys
import numpy, torch
from ch37 import cli, result_cache

base = {"seed": 0, "epochs": 500, "smoke": False, "device": "cpu"}
torch.ones(8, 8) @ torch.ones(8, 8)  # MKL reads MKL_CBWR at its first use (OpenBLAS: as numpy loads)
got = [[result_cache.result_key(base), cli.other_draw("cpu")]]
for value in sys.argv[2:]:  # a notebook's %env VAR=... between two Run-alls
    os.environ[sys.argv[1]] = value
    got.append([result_cache.result_key(base), cli.other_draw("cpu")])
print(json.dumps(got))
"""


def kernel_keys(var: str, first: str, *later: str) -> list:
    """[result key, another-draw line] of a fresh process started with `var`=first (the rest of the
    published kernel path as the setup region sets it), then after each later value set in-process."""
    p = subprocess.run(
        [sys.executable, "-c", KERNEL_KEYS, var, *later],
        cwd=ROOT,
        env=dict(os.environ, MKL_CBWR="COMPATIBLE", OPENBLAS_CORETYPE="Haswell") | {var: first},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


@pytest.mark.skipif(
    not has_avx2_fma(), reason="the published kernel path needs an x86-64 CPU with AVX2 and FMA"
)
def test_the_cache_and_the_banner_name_the_mkl_branch_in_force():
    """Issue 48 #10: MKL reads MKL_CBWR once per process, at its first use. A notebook that changed
    %env MKL_CBWR between two Run-alls stored a result computed on the first branch under the second's
    cache key (served later to a run really on that branch), and the banner named the second. Both
    now follow the branch MKL runs: after a change, the key and the banner's line are the first
    branch's, the same as a fresh process on it gives."""

    def keys(first, *later):
        return kernel_keys("MKL_CBWR", first, *later)

    (compatible,), (avx2,) = keys("COMPATIBLE"), keys("AVX2")
    assert compatible[0] != avx2[0] and compatible[1] is None and avx2[1]  # another branch, another draw
    assert keys("COMPATIBLE", "AVX2") == [compatible, compatible]  # MKL still runs COMPATIBLE
    first, changed = keys("AVX2", "COMPATIBLE")
    assert first == avx2 and changed[0] == avx2[0] and changed[1]  # still AVX2's (AUTO's on AMD)


@pytest.mark.skipif(
    not has_avx2_fma(), reason="the published kernel path needs an x86-64 CPU with AVX2 and FMA"
)
def test_the_cache_and_the_banner_name_the_openblas_kernels_in_force():
    """Issue 47: the training's products run on numpy's OpenBLAS, whose kernels are chosen once, as numpy
    loads. A process on other kernels (Sandybridge's AVX code here) is another result and another draw;
    setting OPENBLAS_CORETYPE after numpy loaded changes neither."""

    def keys(core, *later):
        return kernel_keys("OPENBLAS_CORETYPE", core, *later)

    (haswell,), (sandy,) = keys("Haswell"), keys("Sandybridge")
    assert haswell[1] is None and haswell[0] != sandy[0]
    assert "Sandybridge" in sandy[1]  # the banner's line names the kernels in force
    assert keys("Haswell", "Sandybridge") == [haswell, haswell]  # numpy's OpenBLAS still runs Haswell's
