"""The exercise checks can pass and can fail: reference answers pass, wrong answers fail with a clear message.

The check logic (exercises/checks.py) is called directly with modules, functions and metrics
dicts; a few tests run `pytest exercises/checks.py -k ...` in a subprocess, as a learner would.
"""

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from bc_recipe import wilson
from exercises import checks, rules
from exercises.checks import ExerciseError

ROOT = Path(__file__).resolve().parent.parent
SOLUTIONS = ROOT / "exercises" / "solutions"
META = ROOT / "meta.yaml"  # written by python -m tools.meta from the sweeps
# a meta.yaml derived from smoke-sized sweeps says so; its answers and bands are not the chapter's
PROVISIONAL = bool((yaml.safe_load(META.read_text()).get("reference_run") or {}).get("provisional"))
EXERCISE_VARS = ("CH37_EXERCISE_DIR", "CH37_EXERCISE_SMOKE", "CH37_EXERCISE_OUT", "CH37_META")
EX1 = tuple(checks.EX1_CHOICES)
EX3 = checks.EX3_CHOICES
WHY = "twelve demos cover little of the start space"


@pytest.fixture(scope="module")
def meta():
    return checks.load_meta(META)


def run_checks(*args, env_extra=None, unset=(), timeout=600):
    """`python -m pytest exercises/checks.py ARGS` from the repo root, as a learner runs it."""
    env = {
        k: v for k, v in os.environ.items() if k not in EXERCISE_VARS and k not in unset
    }  # keeps CH37_CACHE_DIR
    env.update({"CH37_META": str(META), "PYTHONHASHSEED": "0", **(env_extra or {})})
    return subprocess.run(
        [sys.executable, "-m", "pytest", "exercises/checks.py", "-p", "no:cacheprovider", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# ---------------------------------------------------------------- meta.yaml: the schema checks.py reads
def test_meta_has_the_exercise_checks_schema(meta):
    assert meta["ex1"]["seed"] == 0 and meta["ex1"]["answer"] in EX1
    assert {"scale_effect_min", "scale_effect_max"} & set(meta["ex1"]["band"])
    assert meta["ex2"]["pusht_mask_density"] == pytest.approx(1 / 3, abs=1e-6)
    ex3 = meta["ex3"]
    assert (
        ex3["seed"] == 0
        and ex3["aug_per_demo"] == [0, 4, 8]
        and ex3["answer"] in EX3
        and len(ex3["answer_from"]["steps_ci95"]) == 2  # from several seeds' numbers (issue 60 #4)
    )
    for k in ("0", "4", "8"):
        lo, hi = ex3["band"][k]
        assert 0.0 <= lo <= hi <= 1.0


def test_missing_meta_is_a_clear_failure(tmp_path):
    with pytest.raises(ExerciseError, match="not found"):
        checks.load_meta(tmp_path / "meta.yaml")
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({"id": "x"}))
    with pytest.raises(ExerciseError, match="no exercise_checks"):
        checks.load_meta(tmp_path / "m.yaml")


# ---------------------------------------------------------------- rules: meta.yaml's answers and bands
def test_ex1_answer_rule_both_ways():
    assert rules.ex1_answer([0.28, 0.12, 0.12]) == "A"
    assert rules.ex1_answer([-0.1, -0.02]) == "B"
    assert rules.ex1_answer([0.2, 0.0, 0.1]) == "C"  # a tie on one seed is not "helps on every seed"
    assert rules.ex1_answer([0.2, -0.1]) == "C"
    with pytest.raises(ValueError):
        rules.ex1_answer([])


def test_ex1_band_rule():
    assert rules.ex1_band("A", 0.28, [0.2, 0.4]) == {"scale_effect_min": 0.14}
    assert rules.ex1_band("B", -0.1, [0.0, 0.1]) == {"scale_effect_max": -0.05}
    c = rules.ex1_band("C", 0.02, [0.1, 0.5])  # Wilson half-width 0.2 -> margin 0.1 > 0.06
    assert c == {"scale_effect_min": -0.08, "scale_effect_max": 0.12}
    assert rules.ex1_band("C", 0.0, [0.0, 0.1]) == {"scale_effect_min": -0.06, "scale_effect_max": 0.06}


def test_ex3_answer_rule_both_ways():
    """Issue 60 #4: a step is judged against its own 95% interval; only the last one decides."""
    tol = rules.PLATEAU_TOL
    assert rules.ex3_answer([[-0.5, 0.5], [0.02, 0.12]]) == "climb"
    assert rules.ex3_answer([[0.02, 0.12], [-0.12, -0.02]]) == "fall"
    assert rules.ex3_answer([[0.02, 0.12], [-tol, tol]]) == "plateau"  # narrow, around 0: flat
    assert rules.ex3_answer([[0.02, 0.12], [-0.19, 0.07]]) == rules.CANNOT_TELL  # wide: noise
    assert rules.step_verdict([0.0, 0.1]) == rules.step_verdict([-0.1, 0.0]) == rules.CANNOT_TELL


def test_step_interval_is_newcombes():
    # seed 0's published 4 -> 8 step: 0.14 [0.0695, 0.2619] -> 0.08 [0.0315, 0.1884]: it holds 0
    lo, hi = rules.step_interval(0.14, [0.069507, 0.261865], 0.08, [0.031549, 0.188385])
    assert lo == pytest.approx(-0.19, abs=0.01) and hi == pytest.approx(0.074, abs=0.01)
    assert rules.step_verdict([lo, hi]) == rules.CANNOT_TELL
    # the Scale Lab's 36 -> 108 demos at the same steps, three seeds pooled: above 0
    lo, hi = rules.step_interval(0.07, [0.046237, 0.104637], 0.14, [0.105271, 0.183832])
    assert 0 < lo < 0.07 < hi and rules.step_verdict([lo, hi]) == "up"


def test_published_ex3_rule_says_what_the_code_does():
    text = rules.RULES["ex3_answer"]
    assert "several seeds" in text and "resolve_fixed" in text and "95% interval" in text
    assert rules.CANNOT_TELL in text and f"+-{rules.PLATEAU_TOL}" in text
    # the first step never changes the answer
    assert rules.ex3_answer([[-0.9, -0.5], [0.02, 0.2]]) == "climb"


def test_success_band_rule_margin_and_clipping():
    assert rules.band_margin([0.19, 0.44]) == pytest.approx(0.0625)  # Wilson half-width 0.125, halved
    assert rules.success_band(0.3, [0.19, 0.44]) == [0.2375, 0.3625]
    assert rules.success_band(0.3, [0.25, 0.35]) == [0.24, 0.36]  # narrow interval: the 0.06 floor
    assert rules.success_band(0.02, [0.0, 0.1]) == [0.0, 0.08]  # clipped at 0, margin 0.06
    assert rules.success_band(0.98, [0.9, 1.0]) == [0.92, 1.0]  # clipped at 1


def test_derive_checks_refuses_bad_sweeps():
    row = {"seed": 0, "delta": 0.1, "source_full": 0.0, "augmented_full": 0.1}
    row["ci95"] = {"augmented_full": [0.2, 0.4]}
    seeds = {"rows": [row], "action_dims": {"pusht": 2}, "padded_action_dim": 6}
    aug = {
        "seed": 0,
        "rows": [
            {"aug_per_demo": k, "augmented_full": 0.3, "ci95": {"augmented_full": [0.2, 0.4]}}
            for k in (0, 4, 8)
        ],
    }
    point = {"success": 0.3, "ci95": [0.25, 0.35]}
    lab = {"curves": {"resolve_fixed": {n: point for n in (12, 36, 108)}}}
    ex = rules.derive_checks(seeds, aug, lab)
    assert ex["ex1"]["answer"] == "A" and ex["ex2"] == {"pusht_mask_density": 0.333333}
    assert ex["ex3"]["answer"] == rules.CANNOT_TELL  # a flat step wider than +-tol: several seeds too few
    with pytest.raises(ValueError, match="must include seed 0"):
        rules.derive_checks(dict(seeds, rows=[dict(row, seed=1)]), aug, lab)
    with pytest.raises(ValueError, match="must be at seed 0"):
        rules.derive_checks(seeds, dict(aug, seed=1), lab)
    with pytest.raises(ValueError, match="must cover aug_per_demo 0, 4, 8"):
        rules.derive_checks(seeds, dict(aug, rows=aug["rows"][:2]), lab)
    with pytest.raises(ValueError, match="must cover N = 12, 36, 108"):
        rules.derive_checks(seeds, aug, {"curves": {"resolve_fixed": {12: point}}})


def test_checks_judges_with_the_published_rule():
    assert checks.ex3_answer is rules.ex3_answer
    src = (ROOT / "exercises" / "checks.py").read_text()
    assert "sys.path" not in src  # the rule is a package import, not a path hack


def test_solutions_point_to_their_exercise_instead_of_copying_it():
    for ex, name in checks.FILES.items():
        task = (ROOT / "exercises" / name).read_text()
        solution = (SOLUTIONS / name).read_text()
        doc = solution.split('"""')[1]
        assert "\n" not in doc and f"exercises/{name}" in doc, ex
        assert "What to do" in task and "What to do" not in solution, ex


# ---------------------------------------------------------------- predictions: ex1 and ex3
def test_reference_predictions_pass_and_match_meta(meta):
    got = {
        "ex1": checks.check_prediction(checks.load_exercise("ex1", SOLUTIONS), EX1, "ex1"),
        "ex3": checks.check_prediction(checks.load_exercise("ex3", SOLUTIONS), EX3, "ex3"),
    }
    if PROVISIONAL:
        pytest.skip("meta.yaml is provisional (smoke-sized sweep): its answers are not the chapter's yet")
    assert got == {"ex1": meta["ex1"]["answer"], "ex3": meta["ex3"]["answer"]}, (
        "exercises/solutions/ disagree with meta.yaml's answers: update the reference answers (and their WHY)"
    )


@pytest.mark.parametrize("ex,allowed", [("ex1", EX1), ("ex3", EX3)])
def test_unfilled_exercise_files_fail(ex, allowed):
    with pytest.raises(ExerciseError, match=rf"{ex}: PREDICTION is empty.*exercises/{checks.FILES[ex]}"):
        checks.check_prediction(checks.load_exercise(ex, ROOT / "exercises"), allowed, ex)


WRONG_PREDICTIONS = [
    ("ex1", {"WHY": WHY}, "PREDICTION is missing"),
    ("ex1", {"PREDICTION": "D", "WHY": WHY}, "must be one of"),
    ("ex1", {"PREDICTION": "AB", "WHY": WHY}, "must be one of"),
    ("ex1", {"PREDICTION": "helps", "WHY": WHY}, "must be one of"),
    ("ex1", {"PREDICTION": 1, "WHY": WHY}, "must be a string"),
    ("ex1", {"PREDICTION": "  ", "WHY": WHY}, "PREDICTION is empty"),
    ("ex1", {"PREDICTION": "A", "WHY": ""}, "WHY needs one sentence"),
    ("ex1", {"PREDICTION": "A"}, "WHY needs one sentence"),
    ("ex1", {"PREDICTION": "A", "WHY": "more data"}, "at least three words"),
    ("ex3", {"WHY": WHY}, "PREDICTION is missing"),
    ("ex3", {"PREDICTION": "rise", "WHY": WHY}, "must be one of"),
    ("ex3", {"PREDICTION": "A", "WHY": WHY}, "must be one of"),
    ("ex3", {"PREDICTION": "", "WHY": WHY}, "PREDICTION is empty"),
    ("ex3", {"PREDICTION": "plateau", "WHY": "   "}, "WHY needs one sentence"),
    ("ex3", {"PREDICTION": "climb", "WHY": None}, "WHY needs one sentence"),
]


@pytest.mark.parametrize("ex,fields,needle", WRONG_PREDICTIONS)
def test_wrong_predictions_fail(ex, fields, needle):
    mod = SimpleNamespace(__file__=str(ROOT / "exercises" / checks.FILES[ex]), **fields)
    with pytest.raises(ExerciseError, match=needle):
        checks.check_prediction(mod, EX1 if ex == "ex1" else EX3, ex)


def test_predictions_ignore_case_and_spaces():
    assert checks.check_prediction(SimpleNamespace(PREDICTION=" a ", WHY=WHY), EX1, "ex1") == "A"
    assert checks.check_prediction(SimpleNamespace(PREDICTION="Plateau", WHY=WHY), EX3, "ex3") == "plateau"


def test_answer_file_that_does_not_import_fails_clearly(tmp_path):
    (tmp_path / checks.FILES["ex1"]).write_text('PREDICTION = "A\n')
    with pytest.raises(ExerciseError, match="does not import: SyntaxError"):
        checks.load_exercise("ex1", tmp_path)
    with pytest.raises(ExerciseError, match="not found"):
        checks.load_exercise("ex3", tmp_path)


# ---------------------------------------------------------------- ex2: zero-pad + action mask
def _ids(n, m):
    return np.concatenate([np.zeros(n, np.int64), np.ones(m, np.int64)])


def pad_left(p, a):
    _, mask, ids = checks.expected_mix(p, a)
    act = np.concatenate([np.pad(np.asarray(p, np.float32), ((0, 0), (4, 0))), np.asarray(a, np.float32)])
    return act, mask, ids


def mask_all_ones(p, a):
    act, mask, ids = checks.expected_mix(p, a)
    return act, np.ones_like(mask), ids


def aloha_first(p, a):
    act = np.concatenate([np.asarray(a, np.float32), np.pad(np.asarray(p, np.float32), ((0, 0), (0, 4)))])
    mask = np.concatenate(
        [np.ones((len(a), 6), np.float32), np.repeat(np.float32([[1, 1, 0, 0, 0, 0]]), len(p), 0)]
    )
    return act, mask, np.concatenate([np.ones(len(a), np.int64), np.zeros(len(p), np.int64)])


def float64_out(p, a):
    act, mask, ids = checks.expected_mix(p, a)
    return act.astype(np.float64), mask, ids


def mutates_inputs(p, a):
    out = checks.expected_mix(p.copy(), a.copy())
    np.clip(a, -0.5, 0.5, out=a)  # "normalizes" the caller's array in place
    return out


def swapped_ids(p, a):
    act, mask, _ = checks.expected_mix(p, a)
    return act, mask, 1 - _ids(len(p), len(a))


def int32_ids(p, a):
    act, mask, ids = checks.expected_mix(p, a)
    return act, mask, ids.astype(np.int32)


def not_implemented(p, a):
    raise NotImplementedError


def two_outputs(p, a):
    return checks.expected_mix(p, a)[:2]


def garbage_in_padding(p, a):
    act, mask, ids = checks.expected_mix(p, a)
    act[: len(p), 2:] = 1.0
    return act, mask, ids


def mask_from_nonzero(p, a):  # issue 33 #3: real demos hold exact zeros (ALOHA's right_vy 265 times)
    act, _, ids = checks.expected_mix(p, a)
    return act, (act != 0).astype(np.float32), ids


def exits_early(p, a):
    sys.exit(0)  # an unfinished answer that ends the process "successfully"


WRONG_MIXES = [
    (pad_left, "pad on the right"),
    (mask_all_ones, "mask is all ones"),
    (aloha_first, "ALOHA rows come first"),
    (float64_out, "actions has dtype float64, expected float32"),
    (mutates_inputs, "modified its input arrays"),
    (swapped_ids, "embodiment_id is wrong"),
    (int32_ids, "embodiment_id has dtype int32"),
    (not_implemented, r"not implemented yet \(NotImplementedError\)"),
    (two_outputs, "return a tuple"),
    (garbage_in_padding, "must be exactly zero"),
    (exits_early, r"raised SystemExit: 0 \(case 1"),
    (mask_from_nonzero, "a real action can be exactly 0"),
]


def test_reference_mix_passes(meta):
    fn = checks.load_exercise("ex2", SOLUTIONS).mix_embodiments
    assert checks.check_mix(fn, meta["ex2"]["pusht_mask_density"]) == len(checks.ex2_cases())
    shapes = {(len(p), len(a)) for p, a in checks.ex2_cases()}
    dtypes = {(p.dtype.name, a.dtype.name) for p, a in checks.ex2_cases()}
    assert {(0, 4), (3, 0), (1, 1)} <= shapes and {("float32", "float32"), ("float64", "float64")} <= dtypes


@pytest.mark.parametrize("fn,needle", WRONG_MIXES, ids=[f.__name__ for f, _ in WRONG_MIXES])
def test_wrong_mixes_fail(fn, needle):
    with pytest.raises(ExerciseError, match=needle):
        checks.check_mix(fn)


def test_ex2_unfilled_fails_clearly_and_solutions_pass_under_pytest():
    p = run_checks("-k", "ex2", unset=("CH37_EXERCISE_DIR",))
    assert p.returncode == 1, p.stdout + p.stderr
    assert (
        "ex2: mix_embodiments is not implemented yet (NotImplementedError); "
        "fill in exercises/ex2_completion_wrangle.py"
    ) in p.stdout
    assert "Traceback" not in p.stdout and "1 failed, 2 deselected" in p.stdout
    p = run_checks("-k", "ex2", env_extra={"CH37_EXERCISE_DIR": "exercises/solutions"})
    assert p.returncode == 0, p.stdout + p.stderr
    assert "matches the specification" in p.stdout and "1 passed, 2 deselected" in p.stdout


def test_printed_commands_work_as_printed():
    """Issue 33 #4: the README's commands come after it says how to activate .venv, none is a bare
    `pytest`, and each exercise file prints a check command that runs as printed from the root."""
    readme = (ROOT / "README.md").read_text()
    activate = readme.index("source .venv/bin/activate")
    commands = list(re.finditer(r"^    (?:python|pytest|rerun|CH37_\w+=\S+ python)\b.*$", readme, re.M))
    assert commands and all(m.start() > activate for m in commands), commands[0].group(0)
    assert not re.search(r"(^|`)pytest ", readme, re.M), "a bare pytest: not found outside the venv"
    venv_python = ROOT / ".venv" / "bin" / "python"
    for ex, name in checks.FILES.items():
        text = (ROOT / "exercises" / name).read_text()
        assert f"    .venv/bin/python -m pytest exercises/checks.py -k {ex}\n" in text, name
        assert not re.search(r"^\s+pytest ", text, re.M), name
    if not venv_python.exists():
        pytest.skip("no .venv here: the commands are printed for the README's set-up")
    env = {k: v for k, v in os.environ.items() if k not in EXERCISE_VARS}
    env.update(CH37_EXERCISE_DIR="exercises/solutions", CH37_META=str(META))
    cmd = ".venv/bin/python -m pytest exercises/checks.py -k ex2 -p no:cacheprovider".split()
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    assert p.returncode == 0 and "matches the specification" in p.stdout, p.stdout + p.stderr


def test_the_first_runs_banner_reminds_of_the_ex1_prediction(monkeypatch, tmp_path):
    """Issue 33 #2: until exercises/ex1_predict_scale.py holds a prediction, the banner says so."""
    from exercises import ex1_reminder

    monkeypatch.setenv("CH37_EXERCISE_DIR", str(ROOT / "exercises"))  # the unfilled file
    assert "exercises/ex1_predict_scale.py" in ex1_reminder()
    monkeypatch.setenv("CH37_EXERCISE_DIR", str(SOLUTIONS))
    assert ex1_reminder() is None
    (tmp_path / checks.FILES["ex1"]).write_text('PREDICTION = "A"\nWHY = "more"\n')  # WHY too short
    monkeypatch.setenv("CH37_EXERCISE_DIR", str(tmp_path))
    assert ex1_reminder() is not None


def test_checks_and_the_reminder_work_without_pytest(tmp_path):
    """Issue 41 #6: a notebook runtime has no pytest. `python -m exercises.checks ex2` (offered as "without
    pytest") passes the reference answer, and exercise 1's reminder still shows, with `import pytest`
    failing in that interpreter (sys.modules['pytest'] = None: an ImportError, as where it is missing)."""
    (tmp_path / checks.FILES["ex1"]).write_text('PREDICTION = ""\nWHY = ""\n')  # not written yet
    env = {k: v for k, v in os.environ.items() if k not in EXERCISE_VARS}
    env.update(CH37_META=str(META), PYTHONHASHSEED="0")
    no_pytest = "import runpy, sys; sys.modules['pytest'] = None; sys.argv[0] = 'checks'; "
    run = "runpy.run_module('exercises.checks', run_name='__main__')"
    p = subprocess.run(
        [sys.executable, "-c", no_pytest + run, "ex2"],
        cwd=ROOT,
        env=dict(env, CH37_EXERCISE_DIR="exercises/solutions"),
        capture_output=True,
        text=True,
    )
    assert p.returncode == 0 and "matches the specification" in p.stdout, p.stdout + p.stderr
    reminder = "from exercises import ex1_reminder; print(ex1_reminder())"
    p = subprocess.run(
        [sys.executable, "-c", no_pytest + reminder],
        cwd=ROOT,
        env=dict(env, CH37_EXERCISE_DIR=str(tmp_path)),
        capture_output=True,
        text=True,
    )
    assert p.returncode == 0 and "exercise 1: this run answers its question" in p.stdout, p.stdout + p.stderr


@pytest.mark.parametrize(
    "answer",
    ["import sys\nsys.exit(0)\n", "import sys\n\ndef mix_embodiments(p, a):\n    sys.exit(0)\n"],
    ids=["at-import", "in-mix_embodiments"],
)
def test_ex2_answer_that_exits_fails_the_command(tmp_path, answer):
    """sys.exit(0) at import or inside mix_embodiments is a failed check (exit 1, one line), never a pass."""
    (tmp_path / checks.FILES["ex2"]).write_text(answer)
    env = {k: v for k, v in os.environ.items() if k not in EXERCISE_VARS}
    env.update(CH37_EXERCISE_DIR=str(tmp_path), CH37_META=str(META))
    p = subprocess.run(
        [sys.executable, "-m", "exercises.checks", "ex2"], cwd=ROOT, env=env, capture_output=True, text=True
    )
    assert p.returncode == 1 and p.stdout == "", p.stdout + p.stderr
    assert p.stderr.count("\n") == 1 and "SystemExit" in p.stderr and "Traceback" not in p.stderr


# ---------------------------------------------------------------- measured claims: ex1 and ex3
def make_metrics(
    source=0.1,
    augmented=0.3,
    short=(0.0, 0.02),
    aug_frames=6000,
    kept=96,
    attempts=96,
    src_frames=838,
    full=9000,
):
    """A well-formed metrics.json of the 2x2: `source`/`augmented` at the full budget, `short` the pair
    (source, augmented) at the short one."""

    def arm(s, frames, steps):
        ci95 = [max(0.0, s - 0.1), min(1.0, s + 0.1)]
        return {"success": s, "ci95": ci95, "frames": frames, "steps": steps, "final_loss": 0.01}

    arms = {
        "source_short": arm(short[0], src_frames, 3500),
        "augmented_short": arm(short[1], src_frames + aug_frames, 3500),
        "source_full": arm(source, src_frames, full),
        "augmented_full": arm(augmented, src_frames + aug_frames, full),
    }
    effects = {k: round(arms[a]["success"] - arms[b]["success"], 6) for k, (a, b) in checks.EFFECTS.items()}
    return {
        "arms": arms,
        "budgets": {"short": 3500, "full": full},
        "effects": effects,
        "scale_effect": effects["data_full"],
        "kept": kept,
        "attempts": attempts,
        "yield": kept / attempts if attempts else 0.0,
        "augmented_frames": aug_frames,
        "source_frames": src_frames,
    }


def test_ex1_band_passes_inside_and_fails_outside():
    band = {"scale_effect_min": 0.1}
    assert "holds" in checks.check_ex1_measured(make_metrics(0.02, 0.30), band)[0]
    checks.check_ex1_measured(make_metrics(0.0, 0.1), band)  # on the edge: holds
    for src, aug in ((0.1, 0.14), (0.2, 0.2), (0.3, 0.1)):
        with pytest.raises(ExerciseError, match="outside the band"):
            checks.check_ex1_measured(make_metrics(src, aug), band)
    b = {"scale_effect_max": -0.05}  # answer B
    checks.check_ex1_measured(make_metrics(0.3, 0.1), b)
    with pytest.raises(ExerciseError, match="outside the band"):
        checks.check_ex1_measured(make_metrics(0.1, 0.3), b)
    c = {"scale_effect_min": -0.06, "scale_effect_max": 0.06}  # answer C
    checks.check_ex1_measured(make_metrics(0.2, 0.22), c)
    for src, aug in ((0.1, 0.3), (0.3, 0.1)):
        with pytest.raises(ExerciseError, match="outside the band"):
            checks.check_ex1_measured(make_metrics(src, aug), c)
    with pytest.raises(ExerciseError, match="neither"):
        checks.check_ex1_measured(make_metrics(), {})


def test_ex1_band_from_meta(meta):
    band = meta["ex1"]["band"]
    lo, hi = band.get("scale_effect_min"), band.get("scale_effect_max")
    inside = lo if lo is not None else hi
    checks.check_ex1_measured(make_metrics(0.5 - inside / 2, 0.5 + inside / 2), band)
    outside = lo - 0.05 if lo is not None else hi + 0.05
    with pytest.raises(ExerciseError, match="outside the band"):
        checks.check_ex1_measured(make_metrics(0.5 - outside / 2, 0.5 + outside / 2), band)


@pytest.mark.parametrize(
    "broken,needle",
    [
        (lambda m: m.pop("scale_effect"), "lacks scale_effect"),
        (lambda m: m["arms"].pop("source_short"), "lacks arms.source_short"),
        (lambda m: m["arms"]["source_full"].pop("ci95"), "lacks arms.source_full.ci95"),
        (lambda m: m["arms"]["augmented_full"].update(success=1.2, ci95=[0.9, 1.3]), "not a valid rate"),
        (lambda m: m["arms"]["augmented_full"].update(success=0.9), "not a valid rate"),
        (lambda m: m["effects"].update(data_full=0.5), "effects.data_full 0.5 is not augmented_full minus"),
        (lambda m: m["effects"].update(compute_source=0.5), "effects.compute_source 0.5 is not source_full"),
        (lambda m: m.update(scale_effect=0.5), "is not the data effect at the full budget"),
        (lambda m: m["arms"]["augmented_full"].update(steps=100), "full budget's arms took \\[100, 9000\\]"),
        (lambda m: m["arms"]["source_short"].update(steps=3000), "short budget's arms took \\[3000, 3500\\]"),
        (lambda m: m.update(kept=100), "kept 100 of 96"),
        (lambda m: m["arms"]["augmented_full"].update(frames=838), "source \\+ augmented frames"),
    ],
)
def test_broken_metrics_fail(broken, needle):
    m = make_metrics()
    broken(m)
    with pytest.raises(ExerciseError, match=needle):
        checks.check_run_sane(m)


def _pts(*rates, n=50):
    """{k: (success, its Wilson interval over n starts)} for k = 0, 4, 8."""
    return {k: (r, wilson(r, n)) for k, r in zip((0, 4, 8), rates)}


@pytest.mark.parametrize(
    "rates,n,shape",
    [
        ((0.0, 0.14, 0.08), 50, rules.CANNOT_TELL),  # seed 0's published curve: the last step is noise
        ((0.0, 0.14, 0.20), 50, rules.CANNOT_TELL),  # a rise inside the noise is no climb either
        ((0.0, 0.10, 0.60), 50, "climb"),
        ((0.0, 0.60, 0.10), 50, "fall"),
        ((0.0, 0.10, 0.10), 5000, "plateau"),  # a flat step measured tightly
    ],
)
def test_curve_shape_reads_a_step_against_its_noise(rates, n, shape):
    """Issue 60 #4: ex3 judged "4 -> 8: -0.06 ... fall" where both points' intervals overlapped; a step
    within the run's own 95% interval is now "cannot tell from one seed", never a verdict."""
    assert checks.curve_shape(_pts(*rates, n=n)) == shape


def test_step_lines_have_signs_intervals_and_verdicts():
    lines = checks.step_lines(_pts(0.0, 0.14, 0.08))
    assert lines[0].startswith("0 -> 4: +0.14 [") and lines[1].startswith("4 -> 8: -0.06 [-0.")
    assert lines[1].endswith(rules.CANNOT_TELL)


def test_ex3_bands_pass_inside_and_fail_outside(meta):
    band = meta["ex3"]["band"]
    mid = {int(k): (lo + hi) / 2 for k, (lo, hi) in band.items()}
    lines = checks.check_ex3_measured(mid, band)
    assert len(lines) == 3 and all("holds" in x for x in lines)
    for k in (0, 4, 8):
        lo, hi = band[str(k)]
        for bad in (lo - 0.02, hi + 0.02):
            if 0.0 <= bad <= 1.0:
                with pytest.raises(ExerciseError, match=f"at aug_per_demo {k} is outside the band"):
                    checks.check_ex3_measured({**mid, k: bad}, band)
    with pytest.raises(ExerciseError, match="no band for aug_per_demo 2"):
        checks.check_ex3_measured({0: 0.0, 2: 0.1, 8: 0.2}, band)


def test_ex3_nested_sizes():
    runs = {4: make_metrics(aug_frames=3000, attempts=48, kept=48), 8: make_metrics(aug_frames=6000)}
    checks.check_ex3_nested(runs)
    bad = {**runs, 8: make_metrics(aug_frames=3000)}
    with pytest.raises(ExerciseError, match="should grow"):
        checks.check_ex3_nested(bad)
    bad = {**runs, 4: make_metrics(aug_frames=3000, src_frames=500)}
    with pytest.raises(ExerciseError, match="source set differs"):
        checks.check_ex3_nested(bad)
    bad = {**runs, 4: make_metrics(aug_frames=3000, full=5000)}  # each run at its own budget: refused
    with pytest.raises(ExerciseError, match="full budget differs between runs"):
        checks.check_ex3_nested(bad)


# ---------------------------------------------------------------- end to end: the runs themselves
def test_ex1_ex3_end_to_end_smoke(tmp_path):
    """Smoke-size runs (seconds each): the pipeline, keys, ranges and nested sizes; bands skipped, said so."""
    p = run_checks(
        "-k",
        "ex1 or ex3",
        env_extra={
            "CH37_EXERCISE_DIR": str(SOLUTIONS),
            "CH37_EXERCISE_SMOKE": "1",
            "CH37_EXERCISE_OUT": str(tmp_path),
        },
    )
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
    assert "2 passed, 1 deselected" in p.stdout
    assert "ex1: smoke run" in p.stdout and "ex3: smoke run" in p.stdout and "bands are skipped" in p.stdout
    assert "ex3: steps, each with its 95% interval: 0 -> 4: " in p.stdout
    # k = 0 is the k = 8 run's source-only arm: no run of its own (issue 60 #3)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["smoke_seed0_aug4", "smoke_seed0_aug8"]


def test_ex1_runs_the_readmes_first_command():
    """Issue 60 #3: ex1's check ran `--aug_per_demo 8 --no-rerun`, another cache key than the README's
    `python scale_data.py --seed 0`, so it trained the learner's run again (3 minutes). Its flags are
    now exactly the README's first command, --out aside; the other runs name only what differs."""
    assert checks.chapter_flags(0, checks.CHAPTER.aug_per_demo, smoke=False) == ["--seed", "0"]
    assert "python scale_data.py --seed 0 " in (ROOT / "README.md").read_text()
    assert (
        checks.chapter_flags(0, 4, False, ("--full_steps", "9"))
        == "--seed 0 --aug_per_demo 4 --full_steps 9".split()
    )


def test_ex1_reuses_the_learners_run_without_training(tmp_path):
    """Issue 60 #3: the learner's run (here smoke-sized, the flags ex1's smoke mode adds) is made once;
    ex1's check then replays it from the result cache: no second training, the same metrics."""
    env = dict(os.environ, CH37_CACHE_DIR=str(tmp_path / "cache"), PYTHONHASHSEED="0")
    learner = tmp_path / "learner"
    flags = checks.chapter_flags(0, checks.CHAPTER.aug_per_demo, smoke=True)
    first = subprocess.run(
        [sys.executable, "scale_data.py", *flags, "--out", str(learner)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert first.returncode == 0 and "budget full:" in first.stdout, first.stdout + first.stderr
    p = run_checks(
        "-k",
        "ex1",
        env_extra={
            "CH37_EXERCISE_DIR": str(SOLUTIONS),
            "CH37_EXERCISE_SMOKE": "1",
            "CH37_EXERCISE_OUT": str(tmp_path / "ex"),
            "CH37_CACHE_DIR": str(tmp_path / "cache"),
        },
    )
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
    assert "reusing the result of an identical earlier run" in p.stdout, p.stdout[-4000:]
    assert "budget full:" not in p.stdout and "augment (" not in p.stdout  # nothing trained or grown
    got = (tmp_path / "ex" / "smoke_seed0_aug8" / "metrics.json").read_bytes()
    assert got == (learner / "metrics.json").read_bytes()


def test_full_mode_asserts_bands_and_scores_predictions(tmp_path, monkeypatch):
    """The non-smoke path (bands asserted, prediction scored) on tiny runs, with bands written for them.

    Same configurations as the smoke test above, so scale_data.py's result cache (one per test
    session) replays them when that test ran first.
    """
    monkeypatch.setattr(checks, "FULL_FLAGS", checks.SMOKE_FLAGS)
    meta = {
        "exercise_checks": {
            "ex1": {"seed": 0, "answer": "C", "band": {"scale_effect_min": -0.5, "scale_effect_max": 0.5}},
            "ex2": {"pusht_mask_density": 0.333333},
            "ex3": {
                "seed": 0,
                "aug_per_demo": [0, 4, 8],
                "answer": "plateau",
                "band": {"0": [0.0, 1.0], "4": [0.0, 1.0], "8": [0.0, 1.0]},
            },
        }
    }
    (tmp_path / "meta.yaml").write_text(yaml.safe_dump(meta))
    for k in EXERCISE_VARS:
        monkeypatch.delenv(k, raising=False)
    monkeypatch.setenv("CH37_META", str(tmp_path / "meta.yaml"))
    monkeypatch.setenv("CH37_EXERCISE_DIR", str(SOLUTIONS))
    monkeypatch.setenv("CH37_EXERCISE_OUT", str(tmp_path / "runs"))
    out = []
    checks.run_ex1(out.append)
    checks.run_ex3(out.append)
    text = "\n".join(out)
    assert "smoke" not in text and "band scale_effect >= -0.500 and scale_effect <= +0.500: holds" in text
    assert (
        "ex1: your prediction was A (augmentation helps); the measurement says C" in text
    )  # scored, not failed
    assert "aug_per_demo 8: success" in text and "ex3: steps, each with its 95% interval: 0 -> 4: " in text
    runs = {k: json.loads((tmp_path / "runs" / f"seed0_aug{k}" / "metrics.json").read_text()) for k in (4, 8)}
    assert (
        len({m["budgets"]["full"] for m in runs.values()}) == 1
    )  # one budget: the curve moves the data alone
    # one evaluation start per arm: every step is inside the noise, so no verdict, and the prediction is
    # scored against the several-seed answer (this meta's "plateau")
    assert f"ex3: this run's last step lies within its own noise: {rules.CANNOT_TELL}, not a verdict" in text
    assert "several seeds (meta.yaml) say plateau; your prediction was climb" in text


@pytest.mark.slow
def test_ex1_ex3_end_to_end_full(tmp_path):
    """Full size at seed 0, bands asserted (three default-size runs; the aug-8 run is shared through the
    result cache)."""
    if PROVISIONAL:
        pytest.skip("meta.yaml is provisional (smoke-sized sweep): its bands do not describe full-size runs")
    p = run_checks(
        "-k",
        "ex1 or ex3",
        env_extra={"CH37_EXERCISE_DIR": str(SOLUTIONS), "CH37_EXERCISE_OUT": str(tmp_path)},
        timeout=7200,
    )
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
    assert "2 passed, 1 deselected" in p.stdout and "smoke" not in p.stdout
    assert "ex1: your prediction " in p.stdout and "matched the measurement" in p.stdout
    assert "ex3: the data shows a " in p.stdout and "4 -> 8: " in p.stdout
