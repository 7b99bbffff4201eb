"""Course tooling (tools/): region markers, the meta.yaml drift check, notebook, sweeps, meta, wall-clock."""

import ast
import base64
import contextlib
import csv
import importlib.metadata
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import textwrap

import pytest
import yaml
from conftest import ROOT, run_script

import ch37.cli
from ch37 import CHAPTER_ID
from exercises import rules
from tools import common, notebook, wallclock
from tools import meta as meta_tool
from tools import sweep as sweep_tool

# ----------------------------------------------------------------------------------------------
# Region parser
# ----------------------------------------------------------------------------------------------
DOC = '"""Doc.\n\nMore doc.\n"""\n'


def script(*regions, head=DOC, between="\n"):
    """A minimal chapter script: the docstring, then NAME/BODY regions."""
    parts = [f"# --- region: {name} ---\n{body}# --- endregion ---\n" for name, body in regions]
    return head + between.join(parts)


GOOD = [(n, f"# intent of {n}\nx_{n} = 1\n") for n in common.REGION_ORDER]


def parse(tmp_path, text):
    p = tmp_path / "scale_data.py"
    p.write_text(text)
    return common.parse_regions(p)


def test_parser_accepts_a_well_formed_script(tmp_path):
    found = parse(tmp_path, script(*GOOD))
    assert [r.name for r in found] == list(common.REGION_ORDER)
    r = found[0]
    assert (r.start, r.end) == (5, 8)
    assert (
        r.body == "# intent of setup\nx_setup = 1\n"
        and r.intent == ["intent of setup"]
        and r.code == "x_setup = 1"
    )


@pytest.mark.parametrize(
    "text, message",
    [
        (script(*GOOD[:2], ("mystery", "y = 1\n"), *GOOD[2:]), "unknown region name 'mystery'"),
        (script(*GOOD[:2], GOOD[1], *GOOD[2:]), "duplicate region 'wrangle'"),
        (script(GOOD[1], GOOD[0], *GOOD[2:]), "out of order: expected 'setup'"),
        (script(*GOOD[:4]), "missing region(s) emit"),
        (
            script(*GOOD).replace("x_measure = 1\n# --- endregion ---", "x_measure = 1"),
            "opens inside region 'measure'",
        ),
        (script(*GOOD).rsplit("# --- endregion ---", 1)[0], "region 'emit' has no '# --- endregion ---'"),
        (script(*GOOD) + "# --- endregion ---\n", "without an open region"),
        (
            script(*GOOD).replace(
                "x_augment = 1\n# --- endregion ---\n", "x_augment = 1\n# --- endregion ---\nstray = 2\n"
            ),
            "code outside any region: 'stray = 2'",
        ),
        (script(*GOOD, head=DOC + "import os\n"), "code outside any region: 'import os'"),
        (script(*GOOD, head=DOC + "# a comment\n"), "code outside any region"),
        (
            script(*GOOD).replace("# --- region: augment ---", "# --- region augment ---"),
            "malformed region marker",
        ),
        (
            script(*GOOD).replace("# --- region: augment ---", "    # --- region: augment ---"),
            "malformed region marker",
        ),
        (
            script(*GOOD).replace("# --- region: augment ---", "# --- region: augment"),
            "malformed region marker",
        ),
        (script(*GOOD) + "def broken(:\n", "not valid Python"),
    ],
)
def test_parser_rejects_malformed_markers(tmp_path, text, message):
    with pytest.raises(common.RegionError) as e:
        parse(tmp_path, text)
    assert message in str(e.value)
    assert str(e.value).startswith("scale_data.py")  # names the file (and the line where there is one)


def test_regions_cli_prints_every_region():
    p = run_script("-m", "tools.regions")
    lines = [
        ln.split() for ln in p.stdout.splitlines() if ln.split() and ln.split()[0] in common.REGION_ORDER
    ]
    assert [ln[0] for ln in lines] == list(common.REGION_ORDER)
    assert all(len(ln[-1]) == 64 for ln in lines)


def test_regions_cli_reports_a_malformed_script_in_one_line(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text(script(*GOOD[:4]))
    p = run_script("-m", "tools.regions", "--script", bad, check=False)
    assert (
        p.returncode == 2
        and p.stderr.startswith("error: bad.py: missing region(s) emit")
        and "Traceback" not in p.stderr
    )


@pytest.mark.parametrize("mode", [[], ["--check"], ["--write"]])
def test_regions_cli_reports_a_missing_script_in_one_line(tmp_path, mode):
    meta = tmp_path / "meta.yaml"
    p = run_script(
        "-m", "tools.regions", *mode, "--script", tmp_path / "missing.py", "--meta", meta, check=False
    )
    assert p.returncode == 2 and p.stdout == "" and not meta.exists()
    assert p.stderr.startswith("error: ") and "missing.py: no such file" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr


@pytest.mark.parametrize(
    "argv",
    [
        ("tools.regions", "--no-such-flag"),
        ("tools.regions", "--check", "--write"),
        ("tools.meta", "--no-such-flag"),
        ("tools.sweep", "--seeds", "x"),
        ("tools.wallclock", "--no-such-flag"),
        ("tools.notebook", "--no-such-flag"),
    ],
)
def test_bad_flags_are_one_error_line(argv):
    p = run_script("-m", *argv, check=False)
    assert p.returncode == 2 and p.stdout == "" and p.stderr.startswith("error: "), p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr


# ----------------------------------------------------------------------------------------------
# Drift: meta.yaml region_hashes vs scale_data.py
# ----------------------------------------------------------------------------------------------
def test_meta_region_hashes_match_scale_data():
    """THE drift test: every region of scale_data.py must match meta.yaml (refresh on purpose with
    `python -m tools.regions --write`, and re-run the sweeps + meta if numbers may move)."""
    recorded = meta_tool.load_yaml(common.META).get("region_hashes")
    bad = common.drifted(common.region_hashes(common.SCRIPT), recorded)
    assert not bad, (
        f"scale_data.py region(s) {', '.join(bad)} changed but meta.yaml was not refreshed: "
        "run python -m tools.regions --write"
    )


def test_drift_check_catches_a_one_character_change(tmp_path):
    copy, meta = tmp_path / "scale_data.py", tmp_path / "meta.yaml"
    shutil.copy(common.SCRIPT, copy)
    shutil.copy(common.META, meta)
    ok = run_script("-m", "tools.regions", "--write", "--script", copy, "--meta", meta)
    assert ok.returncode == 0
    assert run_script("-m", "tools.regions", "--check", "--script", copy, "--meta", meta).returncode == 0
    text = copy.read_text()
    r = common.parse_regions(copy)[2]  # augment
    lines = text.splitlines(keepends=True)
    i = r.start  # 0-based index of the region's first body line: its intent comment
    assert lines[i].startswith("#")
    lines[i] = lines[i].rstrip("\n") + "x\n"
    copy.write_text("".join(lines))  # one character added to a comment; still valid Python
    p = run_script("-m", "tools.regions", "--check", "--script", copy, "--meta", meta, check=False)
    assert p.returncode == 1
    assert "augment" in p.stdout and "setup" not in p.stdout and "python -m tools.regions --write" in p.stdout


def test_hashes_write_keeps_the_rest_of_meta(tmp_path):
    meta = tmp_path / "meta.yaml"
    shutil.copy(common.META, meta)
    before = yaml.safe_load(meta.read_text())
    before_hashes = dict(before["region_hashes"])
    changed = dict(before, region_hashes={k: "0" * 64 for k in before_hashes})
    meta.write_text(yaml.safe_dump(changed, sort_keys=False))
    run_script("-m", "tools.regions", "--write", "--meta", meta)
    after = yaml.safe_load(meta.read_text())
    assert after["region_hashes"] == common.region_hashes(common.SCRIPT)
    assert {k: v for k, v in after.items() if k != "region_hashes"} == {
        k: v for k, v in before.items() if k != "region_hashes"
    }
    assert list(after)[:3] == ["id", "title", "track"]


def test_meta_yaml_schema():
    m = meta_tool.load_yaml(common.META)
    assert m["id"] == "ch3.7-scale-data" and m["title"] == "Datasets at Scale" and len(m["objectives"]) == 4
    assert (
        m["mimicgen"]["commit"] == "ea0988523f468ccf7570475f1906023f854962e9"
        and m["mimicgen"]["tag"] == "v1.0.0"
    )
    assert [f["path"] for f in m["mimicgen"]["files"]] == [
        "mimicgen/utils/pose_utils.py",
        "mimicgen/scripts/generate_dataset.py",
    ]
    ex = m["exercise_checks"]
    assert ex["ex1"]["seed"] == 0 and ex["ex1"]["answer"] in ("A", "B", "C") and ex["ex1"]["band"]
    assert ex["ex2"] == {"pusht_mask_density": 0.333333}
    assert ex["ex3"]["aug_per_demo"] == [0, 4, 8] and ex["ex3"]["answer"] in ("climb", "plateau", "fall")
    assert ex["ex3"]["answer_from"]["k"] == [0, 2, 8]  # several seeds' numbers, not one (issue 60 #4)
    for k in ("0", "4", "8"):
        lo, hi = ex["ex3"]["band"][k]
        assert 0.0 <= lo <= hi <= 1.0
    ref = m["reference_run"]
    assert isinstance(ref["provisional"], bool)
    prov = ref["seeds"]["provenance"]
    assert prov["command"].startswith("python -m tools.sweep --seeds") and prov["date_utc"].endswith("Z")
    assert ref["aug_curve"]["provenance"]["command"].startswith("python -m tools.sweep --aug")
    assert set(prov["packages"]) == {"torch", "lerobot", "mujoco", "numpy"} and prov["platform"]["cpu_count"]
    assert ref["provisional"] == ("--smoke" in prov["command"])
    assert ref["rules"] == rules.RULES  # the published rules are the code's (exercises/rules.py)


# ----------------------------------------------------------------------------------------------
# meta.yaml from sweep files (the rules themselves: tests/test_exercises.py)
# ----------------------------------------------------------------------------------------------
def sweep_row(extra, src, aug, short=(0.0, 0.0), n=50):
    """A sweep row as tools.sweep.row_of writes it: `src`/`aug` at the full budget, `short` the pair at
    the short one."""
    rate = {"source_short": short[0], "augmented_short": short[1], "source_full": src, "augmented_full": aug}
    return {
        **extra,
        **rate,
        "data_full": round(aug - src, 6),
        "data_short": round(short[1] - short[0], 6),
        "compute_source": round(src - short[0], 6),
        "compute_augmented": round(aug - short[1], 6),
        "delta": round(aug - src, 6),
        "steps": {"short": 1641, "full": 13641},
        "eval_episodes": n,
        "successes": {k: round(v * n) for k, v in rate.items()},
        "yield": 1.0,
        "kept": 96,
        "attempts": 96,
        "coverage_source": 12,
        "coverage_union": 32,
        "ci95": {k: [max(0, v - 0.1), min(1, v + 0.1)] for k, v in rate.items()},
        "wall_s": 1,
    }


def sweep_files(tmp_path, deltas, aug_success, smoke=False):
    row = sweep_row
    rows = [row({"seed": s}, 0.3, 0.3 + d) for s, d in enumerate(deltas)]
    seeds = {
        "kind": "seeds",
        "smoke": smoke,
        "command": "python -m tools.sweep --seeds 3",
        "date_utc": "2025-01-01T00:00:00Z",
        "platform": {"cpu_count": 2},
        "packages": {},
        "config": {},
        "action_dims": {"pusht": 2, "aloha": 6},
        "padded_action_dim": 6,
        "rows": rows,
        "mean": sweep_tool.mean_row(rows),
        "paired": sweep_tool.paired(rows),
        "pooled": sweep_tool.pooled(rows),
        "script_region_hashes": common.region_hashes(),
    }
    aug = {
        "kind": "aug",
        "smoke": smoke,
        "seed": 0,
        "command": "python -m tools.sweep --aug 0 4 8",
        "rows": [row({"aug_per_demo": k}, aug_success[0], s) for k, s in zip((0, 4, 8), aug_success)],
        "script_region_hashes": common.region_hashes(),
    }
    a, b = tmp_path / "sweep_seeds.json", tmp_path / "sweep_aug.json"
    a.write_text(json.dumps(seeds))
    b.write_text(json.dumps(aug))
    return a, b


def lab_section(rates, half=0.01) -> dict:
    """A Scale Lab section of meta.yaml: the resolve_fixed curve at N = 12, 36, 108 (k = 0, 2, 8)."""
    points = {n: {"success": r, "ci95": [r - half, r + half]} for n, r in zip((12, 36, 108), rates)}
    return {"curves": {"resolve_fixed": points}}


@pytest.mark.parametrize(
    "deltas, aug, ex1, ex3, smoke",
    [
        ([0.28, 0.12, 0.12], [0.02, 0.2, 0.3], "A", "climb", False),
        ([-0.1, -0.2], [0.3, 0.2, 0.1], "B", "fall", True),
        ([0.1, -0.1], [0.1, 0.2, 0.21], "C", "plateau", False),
    ],
)
def test_meta_command_derives_checks_from_sweep_files(tmp_path, deltas, aug, ex1, ex3, smoke):
    """ex3's answer comes from the Scale Lab's curve (several seeds), here shaped like each aug sweep."""
    a, b = sweep_files(tmp_path, deltas, aug, smoke)
    meta = tmp_path / "meta.yaml"
    kept = {"id": "ch3.7-scale-data", "title": "Custom title kept", "extra": {"kept": True}}
    meta.write_text(yaml.safe_dump(kept | {"scale_lab": lab_section(aug)}))
    run_script("-m", "tools.meta", "--sweep", a, "--aug-sweep", b, "--meta", meta)
    m = yaml.safe_load(meta.read_text())
    assert (
        m["title"] == "Custom title kept"
        and m["extra"] == {"kept": True}
        and m["mimicgen"]["tag"] == "v1.0.0"
    )
    ex = m["exercise_checks"]
    assert ex["ex1"]["answer"] == ex1 and ex["ex3"]["answer"] == ex3
    assert ex["ex2"]["pusht_mask_density"] == 0.333333
    assert set(ex["ex3"]["band"]) == {"0", "4", "8"}
    if ex1 == "A":
        assert ex["ex1"]["band"] == {"scale_effect_min": 0.14}
    assert m["reference_run"]["provisional"] is smoke
    assert m["reference_run"]["seeds"]["paired"]["data_full"]["wins"] == sum(d > 0 for d in deltas)
    assert m["reference_run"]["seeds"]["pooled"]["source_full"]["episodes"] == 50 * len(deltas)
    assert m["region_hashes"] == common.region_hashes()
    assert m["reference_run"]["rules"] == rules.RULES


def _drop(d: dict, key: str) -> dict:
    return {k: v for k, v in d.items() if k != key}


CORRUPT_SWEEPS = [  # (which file, how it is broken, what the one error line says)
    ("seeds", None, "not found; run the sweeps first: python -m tools.sweep --seeds 3"),
    ("seeds", lambda s: "{not json", "is not a readable JSON sweep file"),
    ("aug", lambda s: json.dumps(s)[:-30], "is not a readable JSON sweep file"),  # cut short
    ("seeds", lambda s: "[]", "--sweep"),
    ("aug", lambda s: json.dumps(dict(s, kind="seeds")), "--aug-sweep"),
    ("seeds", lambda s: json.dumps(_drop(s, "paired")), "lacks paired"),
    ("seeds", lambda s: json.dumps(dict(s, rows=[])), "rows (a non-empty list)"),
    ("seeds", lambda s: json.dumps(dict(s, rows=[_drop(r, "delta") for r in s["rows"]])), "rows[0].delta"),
    (
        "aug",
        lambda s: json.dumps(dict(s, rows=[dict(r, ci95={}) for r in s["rows"]])),
        "rows[0].ci95.augmented_full",
    ),
    ("aug", lambda s: json.dumps(dict(s, rows=s["rows"][:2])), "must cover aug_per_demo 0, 4, 8"),
    ("seeds", lambda s: json.dumps(dict(s, action_dims={})), "malformed"),
    ("seeds", lambda s: json.dumps(dict(s, rows=[dict(r, delta="x") for r in s["rows"]])), "malformed"),
]


@pytest.mark.parametrize("which, corrupt, needle", CORRUPT_SWEEPS)
def test_meta_command_refuses_a_corrupt_sweep_file_in_one_line(tmp_path, which, corrupt, needle):
    a, b = sweep_files(tmp_path, [0.1, 0.2], [0.1, 0.2, 0.3])
    path = a if which == "seeds" else b
    if corrupt is None:
        path.unlink()
    else:
        path.write_text(corrupt(json.loads(path.read_text())))
    meta = tmp_path / "meta.yaml"
    p = run_script("-m", "tools.meta", "--sweep", a, "--aug-sweep", b, "--meta", meta, check=False)
    assert p.returncode == 2 and p.stderr.startswith("error: ") and needle in p.stderr, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr
    assert not meta.exists()  # nothing written


# ----------------------------------------------------------------------------------------------
# Sweeps: the plumbing on a stub script (fast), then the real script at --smoke size
# ----------------------------------------------------------------------------------------------
STUB = textwrap.dedent("""
    \"\"\"Stand-in for scale_data.py: writes a metrics.json (the 2x2) whose numbers depend on --seed and
    --aug_per_demo, and whose full budget is --full_steps or grows with the data.\"\"\"
    import argparse, json, pathlib
    p = argparse.ArgumentParser()
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--aug_per_demo", type=int, default=8)
    p.add_argument("--full_steps", type=int, default=0)
    p.add_argument("--out", type=pathlib.Path)
    p.add_argument("--smoke", action="store_true")
    p.add_argument("--rerun", action=argparse.BooleanOptionalAction, default=True)
    a = p.parse_args()
    src, aug = 0.02 * (a.seed + 1), 0.02 * (a.seed + 1) + 0.03 * a.aug_per_demo
    budgets = {"short": 100, "full": a.full_steps or 100 * (1 + a.aug_per_demo)}
    rate = {"source_short": src, "augmented_short": src, "source_full": src, "augmented_full": aug}
    arm = lambda k: {"success": rate[k], "ci95": [max(0.0, rate[k] - 0.1), min(1.0, rate[k] + 0.1)]}
    effects = {"data_full": aug - src, "data_short": 0.0, "compute_source": 0.0}
    effects["compute_augmented"] = aug - src
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "metrics.json").write_text(json.dumps({
        "config": {"seed": a.seed, "aug_per_demo": a.aug_per_demo, "device": "cpu", "smoke": a.smoke,
                   "rerun": a.rerun, "eval_episodes": 50, "full_steps": a.full_steps},
        "arms": {k: arm(k) for k in rate}, "budgets": budgets, "effects": effects,
        "scale_effect": aug - src, "yield": 1.0, "kept": 12 * a.aug_per_demo, "attempts": 12 * a.aug_per_demo,
        "coverage": {"source": 12, "union": 12 + a.aug_per_demo}, "action_dims": {"pusht": 2, "aloha": 6},
        "padded_action_dim": 6}))
""")


@pytest.fixture
def stub(tmp_path):
    p = tmp_path / "stub_scale_data.py"
    p.write_text(STUB)
    return p


def test_sweep_aug_mode_and_flag_passthrough(tmp_path, stub):
    out = tmp_path / "sw"
    p = run_script(
        "-m", "tools.sweep", "--aug", "0", "4", "8", "--script", stub, "--out-root", out, "--smoke"
    )
    s = json.loads((out / "sweep_aug.json").read_text())
    assert s["kind"] == "aug" and s["smoke"] is True and s["seed"] == 0
    assert [r["aug_per_demo"] for r in s["rows"]] == [0, 4, 8]
    assert [r["effective_aug_per_demo"] for r in s["rows"]] == [0, 4, 8]
    assert s["rows"][0]["augmented_full"] == s["rows"][0]["source_full"]
    # the largest k ran first at its own full budget; the others trained for exactly that many steps
    assert {r["steps"]["full"] for r in s["rows"]} == {900} and s["full_steps"] == 900
    # 0.02 -> 0.14 -> 0.26, each +-0.1: the last step lies within its own interval (issue 60 #4)
    assert "curve 0 -> 4 -> 8 at 900 steps each, one seed: cannot tell from one seed" in p.stdout, p.stdout
    assert "--smoke" in s["command"] and s["config"]["smoke"] is True and "aug_per_demo" not in s["config"]


def test_sweep_refuses_flags_it_owns(tmp_path, stub):
    for flag in ("--seed", "--out", "--no-rerun"):
        p = run_script(
            "-m",
            "tools.sweep",
            "--seeds",
            "2",
            "--script",
            stub,
            "--out-root",
            tmp_path,
            flag,
            "1",
            check=False,
        )
        assert p.returncode == 2 and flag in p.stderr
    p = run_script("-m", "tools.sweep", "--script", stub, check=False)
    assert p.returncode == 2 and "--seeds" in p.stderr


def test_paired_stats():
    rows = [
        sweep_row({"seed": i}, src, aug)
        for i, (src, aug) in enumerate([(0.02, 0.30), (0.08, 0.20), (0.14, 0.26)])
    ]
    pr = sweep_tool.paired(rows)["data_full"]
    assert (pr["n"], pr["wins"], pr["ties"], pr["losses"]) == (3, 3, 0, 0)
    assert pr["mean"] == pytest.approx(0.173333, abs=1e-6)
    assert pr["std"] == pytest.approx(0.092376, abs=1e-6)
    half = 4.303 * 0.092376 / 3**0.5  # t(0.975, 2 degrees of freedom)
    assert pr["ci95"] == pytest.approx([0.173333 - half, 0.173333 + half], abs=1e-5)
    one = sweep_tool.paired(rows[:1])["data_full"]
    assert one["std"] is None and one["ci95"] is None
    pooled = sweep_tool.pooled(rows)["augmented_full"]  # 15 + 10 + 13 of 150 episodes
    assert (pooled["successes"], pooled["episodes"]) == (38, 150)
    assert pooled["success"] == pytest.approx(38 / 150, abs=1e-6)
    lo, hi = pooled["ci95"]
    assert lo < 38 / 150 < hi and hi - lo == pytest.approx(0.139, abs=0.002)  # Wilson at n = 150


@contextlib.contextmanager
def fresh_result_cache(path):
    """Point scale_data.py's result cache (ch37.result_cache.cache_root) at an empty folder for a while."""
    old = os.environ.get("CH37_CACHE_DIR")
    os.environ["CH37_CACHE_DIR"] = str(path)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("CH37_CACHE_DIR")
        else:
            os.environ["CH37_CACHE_DIR"] = old


@pytest.fixture(scope="module")
def smoke_sweep(tmp_path_factory):
    """The real scale_data.py at --smoke size, seeds 0 and 1."""
    out = tmp_path_factory.mktemp("sweep")
    with fresh_result_cache(tmp_path_factory.mktemp("cache")):  # really run, never replay a cached result
        p = run_script("-m", "tools.sweep", "--seeds", "2", "--smoke", "--out-root", out)
    return out, p


def test_sweep_seeds_on_smoke_writes_the_table_and_paired_stats(smoke_sweep):
    out, p = smoke_sweep
    s = json.loads((out / "sweep_seeds.json").read_text())
    assert s["kind"] == "seeds" and s["smoke"] is True and [r["seed"] for r in s["rows"]] == [0, 1]
    for r in s["rows"]:
        m = json.loads((out / "seeds" / f"seed{r['seed']}" / "metrics.json").read_text())
        assert m["seed"] == r["seed"] and m["config"]["rerun"] is False
        assert r["source_full"] == m["arms"]["source_full"]["success"] and r["kept"] == m["kept"]
        assert r["steps"] == m["budgets"] and r["successes"]["augmented_full"] == round(
            m["arms"]["augmented_full"]["success"] * m["config"]["eval_episodes"]
        )
        assert r["coverage_union"] == m["coverage"]["union"] and r["delta"] == pytest.approx(
            m["scale_effect"]
        )
    assert set(s["mean"]) >= {*sweep_tool.ARMS, *sweep_tool.EFFECTS, "yield", "kept", "coverage_union"}
    pr = s["paired"]["data_full"]
    assert pr["n"] == 2 and pr["wins"] + pr["ties"] + pr["losses"] == 2 and pr["ci95"] is not None
    assert set(s["paired"]) == set(sweep_tool.EFFECTS) and set(s["pooled"]) == set(sweep_tool.ARMS)
    assert s["command"] == "python -m tools.sweep --seeds 2 --smoke --out-root " + str(out)
    assert s["date_utc"].endswith("Z") and s["platform"]["python"] == ".".join(map(str, sys.version_info[:3]))
    assert (
        s["packages"]["torch"]
        and s["packages"]["lerobot"]
        and s["packages"]["mujoco"]
        and s["packages"]["numpy"]
    )
    assert s["config"]["smoke"] is True and "seed" not in s["config"]
    assert s["script_region_hashes"] == common.region_hashes()
    assert (
        "paired data_full: > 0 on" in p.stdout
        and "pooled augmented_full:" in p.stdout
        and "mean" in p.stdout
        and "sweep_seeds.json" in p.stdout
    )


# ----------------------------------------------------------------------------------------------
# Notebook
# ----------------------------------------------------------------------------------------------
def test_notebook_is_fresh_and_deterministic():
    text = notebook.build_notebook()
    assert text == notebook.build_notebook()
    assert common.NOTEBOOK.read_text() == text, "scale_data.ipynb is stale: run python -m tools.notebook"
    import nbformat  # the dev extra, in requirements.lock

    nb = nbformat.reads(text, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    parsed = common.parse_regions()
    assert [c.source for c in code[2 : 2 + len(parsed)]] == [r.code for r in parsed]
    figure, poster, rerun = code[2 + len(parsed) :]  # after the emit region: what it wrote, inline
    assert figure.metadata.tags == ["figure"] and '"scale_data.png"' in figure.source
    assert poster.metadata.tags == ["poster"] and '"scale_data.html"' in poster.source
    assert rerun.metadata.tags == ["rerun"] and '"scale_data.rrd"' in rerun.source
    intro = nb.cells[0].source
    assert intro.startswith("# Chapter 3.7") and "by `python -m tools.notebook`" in intro
    # issue 41 #6: it speaks to a notebook user: cells, not .venv or the command line
    assert ".venv" not in intro and "Edit the script, not this notebook" not in intro and "Run all" in intro
    flags = code[1].source
    assert (
        'sys.argv = ["scale_data.py", "--seed", "0", "--no-cache"] + (["--smoke"] if SMOKE else [])' in flags
    )
    assert flags.count("SMOKE = False") == 1  # the smoke run is that line switched, --no-cache kept
    assert "REPO_URL = None  # None: not published yet" in code[0].source  # pyproject.toml has no address yet
    assert "from tools.install import ensure_packages" in code[0].source


def test_notebook_clones_from_pyprojects_address_and_only_from_there(tmp_path):
    """The repository's address has one home, pyproject.toml's [project.urls] Repository; the notebook's
    first cell gets it at build time, so --check finds a notebook built before the address changed."""
    assert notebook.repository_url() is None  # not published yet: no invented address
    url = "https://example.org/course/ch37.git"
    built = notebook.build_notebook(repo_url=url)
    assert f"REPO_URL = {url!r}\\n" in built and "not published yet\\n" not in built.split("REPO_URL")[1]
    pyproject = tmp_path / "pyproject.toml"
    pyproject.write_text(f'[project]\nname = "x"\n\n[project.urls]\nRepository = "{url}"\n')
    assert notebook.repository_url(pyproject) == url
    pyproject.write_text('[project]\nname = "x"\n\n[project.urls]\nRepository = ""\n')
    with pytest.raises(notebook.errors.DataError, match=r"\[project.urls\] Repository must be"):
        notebook.repository_url(pyproject)


def test_notebook_check_flags_a_stale_notebook(tmp_path):
    copy, nb = tmp_path / "scale_data.py", tmp_path / "scale_data.ipynb"
    shutil.copy(common.SCRIPT, copy)
    run_script("-m", "tools.notebook", "--script", copy, "--out", nb)
    assert run_script("-m", "tools.notebook", "--check", "--script", copy, "--out", nb).returncode == 0
    copy.write_text(copy.read_text().replace("# --- endregion ---", "x = 1\n# --- endregion ---", 1))
    p = run_script("-m", "tools.notebook", "--check", "--script", copy, "--out", nb, check=False)
    assert p.returncode == 1 and "stale" in p.stdout


def test_install_says_what_it_changed_and_whether_to_restart():
    """Issue 41 #6: on a runtime whose torch, numpy and pandas are newer than lerobot 0.6's pins, the one
    line names what pip replaced, and asks for a restart only when the kernel had imported one of them."""
    from tools import install

    before = {"torch": "2.15.0", "numpy": "2.5.0", "pandas": "3.0.1", "requests": "2.32.3"}
    after = before | {
        "torch": "2.11.0",
        "numpy": "2.2.6",
        "pandas": "2.3.3",
        "lerobot": "0.6.1",
        "mujoco": "4.0.0",
    }
    added, replaced = install.changes(before, after)
    assert added == {"lerobot": "0.6.1", "mujoco": "4.0.0"} and set(replaced) == {"torch", "numpy", "pandas"}
    assert install.imported(replaced, {"numpy": None, "yaml": None}) == ["numpy"]  # numpy's module: numpy
    line = install.summary(added, replaced, ["numpy"])
    assert line == (
        "the install added 2 packages; replaced numpy 2.5.0 -> 2.2.6, pandas 3.0.1 -> 2.3.3, torch 2.15.0 -> "
        "2.11.0; restart the runtime now (Colab: Runtime > Restart session), then Run all: this Python had "
        "already imported the replaced numpy"
    )
    assert install.summary(added, replaced, []).endswith(
        "; no restart needed (no replaced package was imported yet)"
    )
    assert install.summary(added, {}, []) == (
        "the install added 2 packages; kept every preinstalled package; no restart needed"
    )
    assert install.summary({}, {}, []).startswith("pip installed nothing")
    assert "lerobot[dataset]>=0.6,<0.7" in install.dependencies(ROOT)  # pyproject.toml's, no more
    # it runs before anything is installed: the standard library only
    tree = ast.parse((ROOT / "tools" / "install.py").read_text())
    mods = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    mods |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert {m.split(".")[0] for m in mods} <= set(sys.stdlib_module_names) | {"__future__"}, mods


def kernel_manager(tmp_path):
    """A kernel of this very interpreter (the project's Python), so no installed kernel (or its absence)
    matters."""
    from jupyter_client import KernelManager
    from jupyter_client.kernelspec import KernelSpecManager

    spec = tmp_path / "kernels" / "ch37-python"
    spec.mkdir(parents=True)
    argv = [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"]
    (spec / "kernel.json").write_text(
        json.dumps({"argv": argv, "display_name": "ch3.7", "language": "python"})
    )
    return KernelManager(
        kernel_name="ch37-python", kernel_spec_manager=KernelSpecManager(kernel_dirs=[str(spec.parent)])
    )


WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"  # a notebook output showing a Jupyter widget
NOTEBOOK_ENV = dict(HF_HUB_OFFLINE="1", HF_DATASETS_OFFLINE="1", MPLBACKEND="Agg", PYTHONHASHSEED="0")


def texts(cell) -> str:
    return "".join(o.get("text", "") for o in cell.outputs)


def test_notebook_opened_alone_says_the_repository_is_unpublished_in_one_line(tmp_path):
    """Issue 41 #6: the committed notebook alone in a folder (Colab before the repository is published):
    its first cell prints one line, no traceback, and Run all stops there."""
    import nbclient
    import nbformat

    alone = tmp_path / "content"
    alone.mkdir()
    shutil.copy(common.NOTEBOOK, alone / "scale_data.ipynb")
    nb = nbformat.read(alone / "scale_data.ipynb", as_version=4)
    client = nbclient.NotebookClient(
        nb, km=kernel_manager(tmp_path), timeout=120, resources={"metadata": {"path": str(alone)}}
    )
    with pytest.raises(nbclient.exceptions.CellExecutionError):
        client.execute(env=dict(os.environ, **NOTEBOOK_ENV))
    install = nb.cells[1]
    (error,) = install.outputs
    assert error.output_type == "error" and error.ename == "Stop", error
    assert error.traceback == [
        "stopped: the course repository is not published yet, so this notebook has no address to clone "
        f"it from: put a copy of its folder in {alone} and run this cell again"
    ]
    assert [c.execution_count for c in nb.cells[2:] if c.cell_type == "code"] == [None] * 9  # stopped there
    assert sorted(os.listdir(alone)) == ["scale_data.ipynb"]  # nothing written beside it


def published_copy(tmp_path):
    """The course repository as a learner would clone it: this checkout's files (committed or not, less
    what git ignores) in a git repository of their own; returns its file:// address."""
    src = tmp_path / "published" / "ch37-course"
    names = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split("\0")
    for name in filter(None, names):
        if (ROOT / name).is_file():  # a file deleted but not yet committed is listed too
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-c", "commit.gpgsign=false"]
    for cmd in (["init", "-q"], ["add", "-A"], ["commit", "-q", "-m", "published"]):
        subprocess.run([*git, *cmd], cwd=src, check=True, capture_output=True)
    return src.as_uri()


def test_notebook_runs_alone_from_a_fresh_folder_twice_in_smoke_mode(tmp_path, smoke_sweep):
    """Issue 41 #6, Colab stood in for: a folder holding only the notebook, its first cell clones the
    repository (from a published copy of this checkout), the kernel is the project's Python so lerobot is
    importable and nothing is installed, the flags cell switched to the smoke run the way a learner
    does, Run all twice in one kernel: the second reruns, never stops at setup. The figure, the poster and
    the recording in Rerun's notebook viewer show (issue 41: its widget, holding the .rrd's bytes; the
    viewer's code left to the browser, from app.rerun.io); metrics.json equals the script's own run with
    the same flags."""
    import nbclient
    import nbformat

    url = published_copy(tmp_path)
    committed = nbformat.read(common.NOTEBOOK, as_version=4)
    nb = nbformat.reads(notebook.build_notebook(repo_url=url), as_version=4)
    install = nb.cells[1]
    assert install.source.replace(repr(url), "None  # None: not published yet") == committed.cells[1].source
    assert [c.source for c in nb.cells[2:]] == [c.source for c in committed.cells[2:]]  # the committed cells
    (argv_cell,) = [c for c in nb.cells if "argv" in c.metadata.get("tags", [])]
    argv_cell.source = argv_cell.source.replace("SMOKE = False", "SMOKE = True")
    content = tmp_path / "content"
    content.mkdir()
    env = dict(os.environ, **NOTEBOOK_ENV, CH37_CACHE_DIR=str(tmp_path / "cache"))  # an empty result cache
    env.pop("RERUN_NOTEBOOK_ASSET", None)  # the viewer's default: its code from app.rerun.io
    client = nbclient.NotebookClient(
        nb, km=kernel_manager(tmp_path), timeout=600, resources={"metadata": {"path": str(content)}}
    )
    repo = content / "ch37-course"
    rrd = (repo / "outputs" / "ch3.7-scale-data-smoke" / "scale_data.rrd").resolve()
    runs = []
    with client.setup_kernel(env=env):
        for _ in range(2):  # Run all, then Run all again in the same kernel
            for i, cell in enumerate(nb.cells):
                client.execute_cell(cell, i)
            runs.append(
                {
                    c.id: (texts(c), [o.output_type for o in c.outputs])
                    for c in nb.cells
                    if c.cell_type == "code"
                }
            )
            out = repo / "outputs" / "ch3.7-scale-data-smoke"
            got = {c.id: c.outputs for c in nb.cells if c.cell_type == "code"}
            png = [o.data["image/png"] for o in got["figure"] if o.output_type == "execute_result"]
            assert png == [base64.b64encode((out / "scale_data.png").read_bytes()).decode()]
            html = [o.data["text/html"] for o in got["poster"] if o.output_type == "execute_result"]
            assert html == [(out / "scale_data.html").read_text(encoding="utf-8")] and "<svg" in html[0]
            # issue 41: the recording in Rerun's notebook viewer, a widget (no value, no error), whose
            # code the browser loads from app.rerun.io; the kernel fetches nothing
            views = [
                o.data[WIDGET_VIEW]["model_id"] for o in got["rerun"] if WIDGET_VIEW in o.get("data", {})
            ]
            assert [o.output_type for o in got["rerun"]] == ["stream", "display_data", "display_data"]
            viewer = client.widget_state[views[-1]]
            assert viewer["_model_name"] == "AnyModel"  # anywidget's: rerun_notebook.Viewer
            assert (viewer["_width"], viewer["_height"]) == ("auto", 640)
            rerun_notebook = importlib.metadata.version("rerun-notebook")
            assert viewer["_esm"] == f"https://app.rerun.io/version/{rerun_notebook}/notebook/widget.js"
        # the viewer widget holds this run's .rrd, as it is, for the browser (sent once the viewer's code
        # has loaded there: rerun_notebook.Viewer keeps it in its queue, _event_queue, till then, and no
        # browser is here)
        probe = nbformat.v4.new_code_cell(
            "print(viewer.model_id, viewer._event_queue == [({'type': 'rrd'}, [rrd.read_bytes()])])"
        )
        nb.cells.append(probe)  # after the notebook's cells, in the same kernel
        client.execute_cell(probe, len(nb.cells) - 1)
        assert texts(probe) == f"{views[-1]} True\n"
        # the same cell after a run with --no-rerun (a recording from an earlier run left there): one line
        (rerun,) = [c for c in nb.cells if c.id == "rerun"]
        no_rerun = nbformat.v4.new_code_cell("args.rerun = False\n" + rerun.source)
        nb.cells.append(no_rerun)  # after the notebook's cells, in the same kernel
        client.execute_cell(no_rerun, len(nb.cells) - 1)
        assert [o.output_type for o in no_rerun.outputs] == ["stream"] and rrd.is_file()
        line = texts(no_rerun)
        assert line.startswith("no recording: this run had --no-rerun (") and line.count("\n") == 1
        assert "rerun scale_data.rrd" in line  # how to open the file with the desktop viewer
    first, second = runs
    assert first["install"][0] == (
        f"cloning {url} into {repo}\nrepository {repo}; lerobot "
        f"{importlib.metadata.version('lerobot')} is importable: nothing installed\n"
    )
    assert second["install"][0] == first["install"][0].split("\n", 1)[1]  # found, not cloned again
    assert sorted(os.listdir(content)) == ["ch37-course"]  # the clone, nothing else beside the notebook
    for run in runs:
        text = "".join(t for t, _ in run.values())
        assert "headline:" in text and "reusing" not in text and "SystemExit" not in text
        assert "smoke run: tiny configuration" in run["setup-code"][0]
        # issue 33 #9: no stray value (a PosixPath after the wrangle cell) and no tqdm IProgress warning
        assert [k for k, (_, kinds) in run.items() if "execute_result" in kinds] == ["figure", "poster"], run
        assert "IProgress" not in text and "TqdmWarning" not in text, text
        assert not [k for k, (_, kinds) in run.items() if "error" in kinds]
        assert run["rerun"][0].startswith(f"recording: {rrd} (") and rrd.is_file()
        assert run["rerun"][0].endswith(" MB), in Rerun's notebook viewer below\n")
    sweep_out, _ = smoke_sweep
    same_run = json.loads((sweep_out / "seeds" / "seed0" / "metrics.json").read_text())  # the script's
    metrics = json.loads((repo / "outputs" / "ch3.7-scale-data-smoke" / "metrics.json").read_text())
    assert metrics["config"].pop("rerun") is True and same_run["config"].pop("rerun") is False
    assert metrics == same_run


# ----------------------------------------------------------------------------------------------
# Wall-clock
# ----------------------------------------------------------------------------------------------
def test_wallclock_tiers_are_the_banners_tiers():
    assert wallclock.TIERS is ch37.cli.TIERS  # one list of tiers, the one the banner reads


def test_wallclock_row_replaces_only_its_tier(tmp_path):
    path = tmp_path / "wallclock.csv"
    wallclock.write_wallclock_row(
        path,
        {
            "chapter": CHAPTER_ID,
            "tier": "t4",
            "minutes": "1.37",
            "config_hash": "abc",
            "date": "2025-01-01",
            "status": "measured",
        },
    )
    rows = list(csv.DictReader(path.open()))
    assert [r["tier"] for r in rows] == list(wallclock.TIERS) and list(rows[0]) == list(
        wallclock.WALLCLOCK_FIELDS
    )
    assert [r["status"] for r in rows] == ["measured" if t == "t4" else "pending" for t in wallclock.TIERS]
    assert all(r["minutes"] == "" for r in rows if r["status"] == "pending")
    wallclock.write_wallclock_row(
        path,
        {
            "chapter": CHAPTER_ID,
            "tier": "cpu-2core-amd",
            "minutes": "1.66",
            "config_hash": "def",
            "date": "2025-01-02",
            "status": "measured",
        },
    )
    wallclock.write_wallclock_row(
        path,
        {
            "chapter": CHAPTER_ID,
            "tier": "t4",
            "minutes": "1.40",
            "config_hash": "abc",
            "date": "2025-01-03",
            "status": "measured",
        },
    )
    rows = {r["tier"]: r for r in csv.DictReader(path.open())}
    assert list(rows) == ["cpu-2core-amd", *wallclock.TIERS]  # a CPU's row first, then the fixed tiers
    assert (
        rows["t4"]["minutes"] == "1.40"
        and rows["cpu-2core-amd"]["minutes"] == "1.66"
        and rows["mps"]["status"] == "pending"
    )
    assert ch37.cli.expected_wallclock("t4", "abc", path).startswith("about 1.4 min for this configuration")
    # issue 33 #7: another configuration (a bigger --pusht_data, another seed) gets no estimate
    assert "not this configuration" in ch37.cli.expected_wallclock("t4", "def", path)
    assert "not yet measured" in ch37.cli.expected_wallclock("mps", "abc", path)


def _measured(tier: str, minutes: str, step_ms: str = "", config: str = "abc") -> dict:
    return wallclock._pending(tier) | dict(
        minutes=minutes, config_hash=config, date="2026-11-28", status="measured"
    )


def test_an_unmeasured_cpu_gets_an_estimate_from_its_probe(tmp_path):
    """Issue 59 #3: a CPU whose tier has no row is estimated from the measured CPU row of this
    configuration nearest in speed, scaled by the two probes (ms a training step); without a probe, or on
    another configuration, nothing is invented."""
    path = tmp_path / "wallclock.csv"
    wallclock.write_wallclock_row(path, _measured("cpu-2core-amd", "3.00") | {"step_ms": "10.00"})
    wallclock.write_wallclock_row(path, _measured("cpu-16core-amd", "1.00") | {"step_ms": "2.00"})
    wallclock.write_wallclock_row(path, _measured("t4", "1.40"))
    shown = ch37.cli.expected_wallclock("cpu-2core-intel", "abc", path, probe_ms=5.0)
    assert shown.startswith(
        "about 1.5 min here (this tier is unmeasured; wallclock.csv's cpu-2core-amd row"
    ), shown
    # nearest in speed: a fast machine scales from the fast row (1.00 min x 3 / 2), not the slow one
    assert ch37.cli.expected_wallclock("cpu-64core-intel", "abc", path, probe_ms=3.0).startswith(
        "about 1.5 min"
    )
    assert "not yet measured" in ch37.cli.expected_wallclock("cpu-2core-intel", "abc", path)  # no probe
    assert "not yet measured" in ch37.cli.expected_wallclock("cpu-2core-intel", "other", path, probe_ms=5.0)
    assert "not yet measured" in ch37.cli.expected_wallclock(
        "l4", "abc", path, probe_ms=5.0
    )  # GPUs: CPU rows never
    # a measured tier is scaled to this machine too (another CPU of one tier, a busier machine)
    assert ch37.cli.expected_wallclock("cpu-2core-amd", "abc", path, probe_ms=12.0).startswith(
        "about 3.6 min here"
    )
    assert ch37.cli.expected_wallclock("t4", "abc", path, probe_ms=12.0).startswith("about 1.4 min for this")


ZEN4 = (
    "processor\t: 0\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\nmodel name\t: AMD EPYC\n"
    "\nprocessor\t: 1\n"
)


def test_a_row_measured_on_this_cpu_model_is_shown_as_it_ran(tmp_path):
    """Issue 59 #3: the banner shows a row measured on this very CPU model unscaled (its probe reads the
    moment, the row a whole run) and scales it by the probes on any other CPU of the tier."""
    assert ch37.cli.cpu_model(ZEN4) == "AMD EPYC family 25 model 17"
    assert ch37.cli.cpu_model("") == "" and ch37.cli.cpu_model(GRAVITON) == ""
    path = tmp_path / "wallclock.csv"
    zen4 = ch37.cli.cpu_model(ZEN4)
    wallclock.write_wallclock_row(path, _measured("cpu-2core-amd", "1.20") | {"step_ms": "4.00", "cpu": zen4})
    same = ch37.cli.expected_wallclock("cpu-2core-amd", "abc", path, probe_ms=8.0, cpu=zen4)
    assert (
        same
        == f"about 1.2 min here (wallclock.csv's cpu-2core-amd row, measured 2026-11-28 on this CPU: {zen4})"
    )
    other = ch37.cli.expected_wallclock(
        "cpu-2core-amd", "abc", path, probe_ms=8.0, cpu="AMD EPYC family 25 model 1"
    )
    assert other.startswith("about 2.4 min here (wallclock.csv's cpu-2core-amd row took 1.20 min"), other
    assert ch37.cli.expected_wallclock("cpu-2core-amd", "abc", path, probe_ms=8.0).startswith("about 2.4 min")
    # another tier on the same CPU model (more cores given): still scaled by the probes
    assert ch37.cli.expected_wallclock("cpu-4core-amd", "abc", path, probe_ms=2.0, cpu=zen4).startswith(
        "about 0.6 min here (this tier is unmeasured"
    )


def test_a_cpu_tier_keeps_a_row_per_cpu_model(tmp_path):
    """Issue 59 #3: a Zen 3 and a Zen 4 are both cpu-2core-amd and differ twofold, so tools.wallclock keeps a
    row per CPU model of a tier (a new measurement replaces only its own model's row), and the banner shows
    each host its own model's row as it ran; a third model of the tier gets the row nearest its probe,
    scaled."""
    path = tmp_path / "wallclock.csv"
    zen4, zen3 = ch37.cli.cpu_model(ZEN4), "AMD EPYC family 25 model 1"
    row = _measured("cpu-2core-amd", "1.20") | {"step_ms": "4.00", "cpu": zen4}
    wallclock.write_wallclock_row(path, row)
    wallclock.write_wallclock_row(path, _measured("cpu-2core-amd", "2.50") | {"step_ms": "8.00", "cpu": zen3})
    wallclock.write_wallclock_row(path, row | {"minutes": "1.10"})  # zen4 again: its own row replaced
    rows = [r for r in csv.DictReader(path.open()) if r["tier"] == "cpu-2core-amd"]
    assert [(r["cpu"], r["minutes"]) for r in rows] == [(zen3, "2.50"), (zen4, "1.10")]

    def shown(cpu, probe):
        return ch37.cli.expected_wallclock("cpu-2core-amd", "abc", path, probe_ms=probe, cpu=cpu)

    assert shown(zen4, 9.0).startswith(
        f"about 1.1 min here (wallclock.csv's cpu-2core-amd row, measured 2026-11-28 on this CPU: {zen4}"
    )
    assert shown(zen3, 3.0).startswith(
        f"about 2.5 min here (wallclock.csv's cpu-2core-amd row, measured 2026-11-28 on this CPU: {zen3}"
    )
    # another model of the tier: the row nearest its probe (6.4 ms: zen3's 8.00, 2.50 x 6.4 / 8 = 2.0)
    assert shown("AMD EPYC family 25 model 160", 6.4).startswith(
        "about 2.0 min here (wallclock.csv's cpu-2core-amd row took 2.50"
    )
    assert shown("AMD EPYC family 25 model 160", 4.4).startswith(
        "about 1.2 min here (wallclock.csv's cpu-2core-amd row took 1.10"
    )
    # another configuration: no estimate from either row
    assert "not this configuration" in ch37.cli.expected_wallclock(
        "cpu-2core-amd", "other", path, probe_ms=4.0, cpu=zen4
    )


def test_the_step_probe_times_a_training_step_and_leaves_the_random_state():
    """Issue 59 #3: the banner's probe returns milliseconds a step (a positive, finite figure; its speed is
    tools.wallclock's to print, not a test's) and draws nothing from torch's random state."""
    import torch

    before = torch.random.get_rng_state()
    ms = ch37.cli.step_probe(16, 8)
    assert math.isfinite(ms) and ms > 0
    assert torch.equal(torch.random.get_rng_state(), before)
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert (
        f"the run first times {ch37.cli.PROBE_STEPS} training steps" in readme
    )  # the README says what it does


@pytest.mark.parametrize("threads", [1, 2])
def test_the_step_probe_times_what_the_runs_processes_train(monkeypatch, threads):
    """Issue 59 #3: the probe times the arms as bc_recipe.train runs them: one arm in each of two processes
    set up as its are (two torch threads and fork), else both arms side by side in this one."""
    import torch

    from ch37 import parallel

    seen, real = [], parallel.map_jobs
    monkeypatch.setattr(
        parallel, "map_jobs", lambda fn, jobs, **kw: seen.append((jobs, kw)) or real(fn, jobs, **kw)
    )
    saved = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        assert ch37.cli.step_probe(16, 8) > 0
    finally:
        torch.set_num_threads(saved)
    ((jobs, kw),) = seen
    apart = threads == 2 and parallel.can_fork()
    assert [arms for arms, *_ in jobs] == ([1, 1] if apart else [2]) and kw["workers"] == len(jobs)
    assert kw["setup"] is ch37.ensemble.arm_process_setup


INTEL = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: Intel(R) Xeon(R)\n\nprocessor\t: 1\n"
AMD = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 7B13\n"
GRAVITON = "processor\t: 0\nBogoMIPS\t: 243.75\nCPU implementer\t: 0x41\nCPU part\t: 0xd0c\n"


@pytest.mark.parametrize(
    "cores, cpuinfo, system, machine, tier",
    [
        (8, INTEL, "Linux", "x86_64", "cpu-8core-intel"),
        (2, AMD, "Linux", "x86_64", "cpu-2core-amd"),
        (4, GRAVITON, "Linux", "aarch64", "cpu-4core-arm"),
        (10, "", "Darwin", "arm64", "cpu-10core-apple"),  # macOS has no /proc/cpuinfo
        (4, "", "Darwin", "x86_64", "cpu-4core-intel"),
        (4, "processor\t: 0\nhart\t: 0\n", "Linux", "riscv64", "cpu-4core-riscv64"),  # no vendor: the arch
        (1, "", "", "", "cpu-1core-unknown"),
    ],
)
def test_cpu_tier_is_named_from_the_cores_and_vendor(cores, cpuinfo, system, machine, tier):
    """Issue 41 #7: the banner's CPU tier from the machine, no longer cpu-2core for every CPU."""
    assert ch37.cli.cpu_tier(cores, cpuinfo, system, machine) == tier


@pytest.mark.parametrize(
    "cpu_max, cores", [("max 100000\n", None), ("200000 100000\n", 2), ("150000 100000", 2), ("", None)]
)
def test_a_containers_cpu_quota_counts_its_cores(cpu_max, cores):
    assert ch37.cli.quota_cores(cpu_max) == cores


def test_the_banners_cpu_tier_is_this_machines(tmp_path):
    tier = ch37.cli.device_tier("cpu")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    with contextlib.suppress(OSError):  # a container's CPU quota caps them
        cores = min(cores, ch37.cli.quota_cores(open("/sys/fs/cgroup/cpu.max").read()) or cores)
    assert tier.startswith(f"cpu-{cores}core-") and not tier.endswith("-unknown"), tier
    # the row measured before tiers named the vendor is kept under a name no machine gets: no banner
    # shows its minutes as this machine's
    rows = {r["tier"]: r for r in csv.DictReader(common.WALLCLOCK.open())}
    assert rows["cpu-2core-vendor-unrecorded"]["status"] == "measured" and "cpu-2core" not in rows
    row = rows["cpu-2core-vendor-unrecorded"]
    shown = ch37.cli.expected_wallclock(tier, row["config_hash"], common.WALLCLOCK)
    assert ("not yet measured" in shown) == (tier not in rows or rows[tier]["status"] != "measured"), shown
    wallclock.write_wallclock_row(tmp_path / "w.csv", wallclock._pending(tier) | {"status": "measured"})
    assert "not this configuration" in ch37.cli.expected_wallclock(tier, "x", tmp_path / "w.csv")


def test_wallclock_cli_smoke_never_writes(tmp_path, stub):
    path = tmp_path / "wallclock.csv"
    p = run_script("-m", "tools.wallclock", "--smoke", "--script", stub, "--csv", path)
    assert "not written" in p.stdout and not path.exists()
    p = run_script("-m", "tools.wallclock", "--dry-run", "--script", stub, "--csv", path)
    assert "not written" in p.stdout and not path.exists()
    p = run_script("-m", "tools.wallclock", "--script", stub, "--csv", path, "--tier", "mps")
    row = {r["tier"]: r for r in csv.DictReader(path.open())}["mps"]
    assert row["status"] == "measured" and float(row["minutes"]) >= 0 and len(row["config_hash"]) == 12
    import torch

    assert row["torch"] == torch.__version__.split("+")[0] and row["python"] == platform.python_version()


def test_config_hash_ignores_only_device_workers_cache_rerun():
    c = {"seed": 0, "epochs": 500, "device": "cpu", "workers": 2, "cache": False, "rerun": False}
    h = wallclock.config_hash
    assert h(c) == h(dict(c, device="cuda", workers=8, cache=True, rerun=True)) != h(dict(c, epochs=499))
    assert h(c) != h(dict(c, seed=1)) != h(dict(c, pusht_data="big"))
    assert h(c) == h(dict(reversed(list(c.items()))))


def test_wallclock_csv_in_repo_is_well_formed():
    rows = list(csv.DictReader(common.WALLCLOCK.open()))
    assert list(rows[0]) == list(wallclock.WALLCLOCK_FIELDS)
    assert {r["tier"] for r in rows} >= set(wallclock.TIERS)
    for r in rows:
        assert r["chapter"] == CHAPTER_ID and r["status"] in ("measured", "pending")
        if r["status"] == "measured":
            assert float(r["minutes"]) > 0 and len(r["config_hash"]) == 12 and r["date"]
            # the versions it ran on: all recorded (tools.wallclock since issue 32) or none (rows before it)
            assert len({bool(r[k]) for k in wallclock.VERSION_FIELDS}) == 1, r
        else:
            assert r["minutes"] == ""


# ----------------------------------------------------------------------------------------------
# run_tests.sh: Chromium for the poster's browser checks
# ----------------------------------------------------------------------------------------------
FAKE_APT = """#!{bash}
echo "$*" >> "{log}"
if [ "$1" = install ] && [ "{installs}" = yes ]; then
    printf '#!{bash}\\n' > "{bin}/chromium"
    {chmod} +x "{bin}/chromium"
fi
"""


INSTALLING = "installing Chromium for tests/test_poster.py's browser checks: apt-get install -y chromium\n"
MISSING = "error: Chromium is missing (tests/test_poster.py's browser checks need it); install it with: "


@pytest.mark.parametrize(
    "uid, apt, chromium, rc, out, err",
    [
        (0, None, True, 0, "", ""),  # there already: nothing to do
        (0, "yes", False, 0, INSTALLING, ""),
        (0, "no", False, 2, INSTALLING, "error: apt-get install -y chromium did not install Chromium"),
        (0, None, False, 2, "", MISSING + "apt-get install -y chromium\n"),
        (1000, "yes", False, 2, "", MISSING + "sudo apt-get install -y chromium\n"),
    ],
    ids=["present", "root-apt-installs", "root-apt-fails", "root-no-apt", "not-root"],
)
def test_run_tests_installs_chromium_only_as_root_with_apt(tmp_path, uid, apt, chromium, rc, out, err):
    """Issue 41 #7: a fresh root machine with apt-get (CI, a container) gets Chromium from run_tests.sh
    itself, in one line; elsewhere it is one error line and exit 2, and apt-get is never called. Run on
    run_tests.sh's own ensure_chromium, with a PATH holding only a fake apt-get (and a chromium or not)."""
    bin_, log, bash = tmp_path / "bin", tmp_path / "apt.log", shutil.which("bash")
    bin_.mkdir()
    if apt:
        fake = FAKE_APT.format(bash=bash, log=log, bin=bin_, chmod=shutil.which("chmod"), installs=apt)
        (bin_ / "apt-get").write_text(fake)
        (bin_ / "apt-get").chmod(0o755)
    if chromium:
        (bin_ / "chromium").write_text(f"#!{bash}\n")
        (bin_ / "chromium").chmod(0o755)
    p = subprocess.run(
        [bash, "-c", f"source run_tests.sh && ensure_chromium {uid}"],
        cwd=ROOT,
        env={"PATH": str(bin_), "HOME": str(tmp_path)},
        capture_output=True,
        text=True,
    )
    assert (p.returncode, p.stdout) == (rc, out) and p.stderr.startswith(err), p
    assert p.stderr.count("\n") == bool(err), p.stderr  # one line or none
    calls = log.read_text().splitlines() if log.exists() else []
    assert calls == (["update -qq", "install -y -qq chromium"] if uid == 0 and apt else []), calls


def test_ci_runs_run_tests_alone():
    """One home for the Chromium install: .ci/run is the README's command and nothing else."""
    lines = [ln for ln in (ROOT / ".ci" / "run").read_text().splitlines() if ln and not ln.startswith("#")]
    assert lines[-1] == 'exec bash run_tests.sh "$@"' and not any("apt-get" in ln for ln in lines), lines


# ----------------------------------------------------------------------------------------------
# The tools themselves
# ----------------------------------------------------------------------------------------------
def test_every_tool_writes_through_the_one_atomic_helper():
    """Code, not strings (the notebook's install cell may touch sys.path): no write but write_atomic,
    no ROOT but ch37.ROOT, no sys.path edits."""
    for path in sorted((ROOT / "tools").glob("*.py")):
        tree = ast.parse(path.read_text())
        defs = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
        attrs = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
        paths = [
            n
            for n in ast.walk(tree)
            if isinstance(n, ast.Attribute)
            and n.attr == "path"
            and isinstance(n.value, ast.Name)
            and n.value.id == "sys"
        ]
        assigned = {
            t.id
            for n in ast.walk(tree)
            if isinstance(n, ast.Assign)
            for t in n.targets
            if isinstance(t, ast.Name)
        }
        assert "write_atomic" not in defs and not {"write_text", "write_bytes"} & attrs, path.name
        assert not paths and "ROOT" not in assigned, path.name


def test_run_chapter_takes_a_relative_out_from_the_callers_folder_and_runs_through_a_link(tmp_path):
    """Issue 62 #6: `cd elsewhere; bash REPO/run_chapter.sh --smoke --out rel_out` wrote REPO/rel_out (the
    set-up moves into the repository) and a link to run_chapter.sh (in ~/bin) could not find setup_env.sh.
    Called either way from a folder where rel_out is the caller's file, the run refuses it in one line
    (so --out was read in the caller's folder) and nothing appears in the repository. Only with the
    set-up's .venv in place (the test command's): a fresh set-up here would install the whole lock."""
    lock = subprocess.run(["sha256sum", ROOT / "requirements.lock"], capture_output=True, text=True)
    if not (ROOT / ".venv" / f".installed-{lock.stdout[:16]}").exists():
        pytest.skip("the set-up's .venv is not installed in this checkout (bash run_tests.sh makes it)")
    caller, links = tmp_path / "elsewhere", tmp_path / "bin"
    caller.mkdir()
    links.mkdir()
    (caller / "rel_out_62").write_text("my notes\n")  # the caller's file, where --out points
    (links / "run_chapter.sh").symlink_to(ROOT / "run_chapter.sh")
    for script in (ROOT / "run_chapter.sh", links / "run_chapter.sh"):
        p = subprocess.run(
            ["bash", script, "--smoke", "--no-rerun", "--out", "rel_out_62"],
            cwd=caller,
            capture_output=True,
            text=True,
            timeout=300,
        )
        err = p.stderr.strip().splitlines()
        assert p.returncode == 2 and err == [
            "error: --out rel_out_62 is a file, not a folder; pass a folder path"
        ], (
            script,
            p.stdout[-2000:] + p.stderr[-2000:],
        )
        assert not (ROOT / "rel_out_62").exists() and (caller / "rel_out_62").read_text() == "my notes\n"
