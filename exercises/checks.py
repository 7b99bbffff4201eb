"""Checks for the chapter 3.7 exercises, run from the repository root with the project's Python:
`.venv/bin/python -m pytest exercises/checks.py -k ex1` (ex2, ex3), or `.venv/bin/python -m exercises.checks
ex2` without pytest (a failure is one `error:` line, exit 1); with .venv activated, `python` alone.
A prediction the data contradicts does not fail: the check says so, and that is the lesson.

For instructors and the test suite: CH37_EXERCISE_DIR (answer files, default exercises/), CH37_META
(default <repo>/meta.yaml), CH37_EXERCISE_OUT (default outputs/exercises), CH37_EXERCISE_SMOKE=1 (tiny
runs: the pipeline, keys and ranges only; bands skipped).
"""

import functools
import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from ch37 import errors
from ch37.config import CHAPTER

from .rules import ARMS, CANNOT_TELL, EFFECTS, ex3_answer, step_interval, step_verdict

ROOT = Path(__file__).resolve().parent.parent
FILES = {"ex1": "ex1_predict_scale.py", "ex2": "ex2_completion_wrangle.py", "ex3": "ex3_hparam_aug_amount.py"}
EX1_CHOICES = {"A": "augmentation helps", "B": "augmentation hurts", "C": "augmentation does not matter"}
EX3_CHOICES = ("climb", "plateau", "fall")
# Tinier than --smoke (ch37.config.SMOKE: twice the test time), with aug_per_demo left to each run.
SMOKE_FLAGS = tuple(
    "--source_episodes 1 --epochs 2 --hidden_dim 16 --batch_size 64 --eval_episodes 1 --device cpu".split()
)
FULL_FLAGS = ()  # the chapter's defaults: what meta.yaml's bands describe
KEYS = "arms budgets effects scale_effect kept attempts yield augmented_frames source_frames".split()
ARM_KEYS = ("success", "ci95", "frames", "steps", "final_loss")


class ExerciseError(AssertionError):
    """A check failed; the message says what to fix and where."""


def checker(problems):
    """A check written as a generator: its first `yield` is the problem that fails it (the generator is
    never resumed, so each test may assume the ones above it held); what it returns is the result."""

    @functools.wraps(problems)
    def check(*args, **kwargs):
        try:
            problem = next(problems(*args, **kwargs))
        except StopIteration as done:
            return done.value
        raise ExerciseError(problem)

    return check


def smoke_mode() -> bool:
    return errors.env_flag("CH37_EXERCISE_SMOKE")


@checker
def load_meta(path: Path | None = None):
    path = Path(path or os.environ.get("CH37_META") or ROOT / "meta.yaml")
    if not path.is_file():
        yield f"{path} not found: it holds the bands of the measured checks; restore it from the repository"
    meta = yaml.safe_load(path.read_text()) or {}
    if "exercise_checks" not in meta:
        yield f"{path} has no exercise_checks section"
    return meta["exercise_checks"]


@checker
def load_exercise(ex: str, directory: Path | None = None):
    """The answer module; a crash or a sys.exit at import is a failed check, not a pass or a traceback."""
    given = os.environ.get("CH37_EXERCISE_DIR", "")
    folder = Path(directory or given or ROOT / "exercises")
    if not folder.is_absolute() and not folder.exists():
        folder = ROOT / folder  # relative to the repository root when not to the current folder
    path = folder.resolve() / FILES[ex]
    if not path.is_file():
        yield f"{ex}: {path} not found (CH37_EXERCISE_DIR={given!r})"
    spec = importlib.util.spec_from_file_location(f"ch37_answer_{ex}_{abs(hash(str(path)))}", path)
    mod = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(mod)
    except (Exception, SystemExit) as e:
        yield f"{ex}: {path.name} does not import: {type(e).__name__}: {e}"
    return mod


def _where(mod) -> str:
    path = Path(getattr(mod, "__file__", "your answer file"))
    return str(path.relative_to(ROOT) if path.is_relative_to(ROOT) else path)


@checker
def check_prediction(mod, allowed, ex: str = "ex1"):
    """The normalised PREDICTION (case and spaces ignored) with a WHY: committing to a reason before the
    run is the exercise."""
    where, choices = _where(mod), ", ".join(f'"{a}"' for a in allowed)
    pred = getattr(mod, "PREDICTION", None)
    if not hasattr(mod, "PREDICTION"):
        yield f"{ex}: PREDICTION is missing; set PREDICTION = one of {choices} in {where}"
    if not isinstance(pred, str):
        yield f"{ex}: PREDICTION must be a string, one of {choices}; got {pred!r} in {where}"
    if not pred.strip():
        yield f"{ex}: PREDICTION is empty; write one of {choices} in {where} before running the experiment"
    norm = {a.lower(): a for a in allowed}.get(pred.strip().lower())
    if norm is None:
        yield f"{ex}: PREDICTION must be one of {choices}; got {pred!r} in {where}"
    why = getattr(mod, "WHY", None)
    if not isinstance(why, str) or len(why.split()) < 3:
        yield f"{ex}: WHY needs one sentence of at least three words on why {norm!r}; got {why!r} in {where}"
    return norm


def expected_mix(pusht_actions, aloha_actions):
    """The specification of ex2, written apart from solutions/ so that the reference answer is tested."""
    n, m = len(pusht_actions), len(aloha_actions)
    actions, mask = np.zeros((n + m, 6), np.float32), np.zeros((n + m, 6), np.float32)
    actions[:n, :2], actions[n:] = pusht_actions, aloha_actions
    mask[:n, :2], mask[n:] = 1.0, 1.0
    return actions, mask, np.repeat(np.int64([0, 1]), [n, m])


def ex2_cases():
    """Values bounded away from 0 with random signs, so a zero or a copy in the wrong place shows, except
    a few exact zeros in real dimensions, as real demos hold them (ALOHA's right_vy, column 1, and left_vy,
    column 4, when an arm stands still; a PushT pusher at rest): a mask built from the values drops them."""
    rng, out = np.random.default_rng(37), []
    for i, (n, m) in enumerate([(5, 3), (5, 3), (1, 1), (1, 4), (0, 4), (3, 0), (0, 0), (64, 17)]):
        p, a = (rng.uniform(0.1, 1.0, (k, d)) * rng.choice([-1, 1], (k, d)) for k, d in ((n, 2), (m, 6)))
        p[::3, 1], a[::2, 1], a[1::3, [0, 3, 4]] = 0.0, 0.0, 0.0  # real dimensions that are exactly 0
        out.append((p.astype((np.float32, np.float64)[i % 2]), a.astype((np.float32, np.float64)[i % 2])))
    return out + [(out[0][0].astype(np.float64), out[0][1])]  # mixed dtypes


def _wrong_values(name, got, p, a) -> str:
    """Why `got` differs from the specification, named after the common mistakes."""
    n = len(p)
    if name == "embodiment_id":
        return "0 for every PushT row, 1 for every ALOHA row, PushT rows first"
    if name == "mask" and n and np.all(got == 1):
        return "the mask is all ones: padded dimensions (columns 2..5 of PushT rows) must be 0"
    if name == "mask" and np.array_equal(got, expected_mix(p, a)[0] != 0):
        return (
            "the mask follows the values (actions != 0), but a real action can be exactly 0 (an arm at rest: "
            "the ALOHA demos hold hundreds of exact zeros), and such a mask drops it from the loss; mark "
            "a dimension real by which robot the row is from, not by its value"
        )
    if name == "mask":
        return "1.0 for real dimensions, 0.0 for padding: [1, 1, 0, 0, 0, 0] for PushT, all ones for ALOHA"
    if n and np.array_equal(got[:n, 4:], p) and not np.array_equal(got[:n, :2], p):
        return "PushT actions sit in the last two columns: pad on the right (PushT in 0..1, zeros in 2..5)"
    if n and len(a) and np.array_equal(got[: len(a)], a):
        return "ALOHA rows come first: put the PushT rows first, then the ALOHA rows"
    if n and np.array_equal(got[:n, :2], p) and np.any(got[:n, 2:] != 0):
        return "the padded columns 2..5 of PushT rows must be exactly zero"
    return "values differ from the specification"


@checker
def check_mix(fn, pusht_mask_density: float = 1 / 3, where: str = "exercises/ex2_completion_wrangle.py"):
    """Compare a learner's mix_embodiments with the specification; returns the number of cases passed."""
    for i, (p, a) in enumerate(cases := ex2_cases()):
        case = f"case {i + 1}: pusht {p.shape} {p.dtype}, aloha {a.shape} {a.dtype}"
        inputs = p.copy(), a.copy()
        try:
            res = fn(*inputs)
        except NotImplementedError:
            yield f"ex2: mix_embodiments is not implemented yet (NotImplementedError); fill in {where}"
        except (Exception, SystemExit) as e:  # sys.exit in an answer must fail the check, not end it
            yield f"ex2: mix_embodiments raised {type(e).__name__}: {e} ({case})"
        if not all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(inputs, (p, a))):
            yield f"ex2: mix_embodiments modified its input arrays ({case}); build new arrays instead"
        if not isinstance(res, (tuple, list)) or len(res) != 3:
            yield f"ex2: return a tuple (actions, mask, embodiment_id); got {type(res).__name__} ({case})"
        for name, got, want in zip(("actions", "mask", "embodiment_id"), res, expected_mix(p, a)):
            if not isinstance(got, np.ndarray):
                yield f"ex2: {name} must be a numpy array, got {type(got).__name__} ({case})"
            if any(np.shares_memory(got, x) for x in inputs):
                yield (
                    f"ex2: {name} shares memory with an input array ({case}): a later change to one changes "
                    "the other; build new arrays (np.zeros, np.concatenate, astype copies)"
                )
            for what, g, w in (("shape", got.shape, want.shape), ("dtype", got.dtype, want.dtype)):
                if g != w:
                    yield f"ex2: {name} has {what} {g}, expected {w} ({case})"
            if not np.array_equal(got, want):
                yield f"ex2: {name} is wrong: {_wrong_values(name, got, p, a)} ({case})"
        density = res[1][: len(p)].mean() if len(p) else pusht_mask_density  # meta.yaml's density vs the spec
        if not math.isclose(density, pusht_mask_density, abs_tol=1e-6):
            yield f"ex2: PushT mask density {density:.4f}, expected {pusht_mask_density:.4f}"
    return len(cases)


def _shown(python: str) -> str:
    """The interpreter as a learner types it from the repository root (.venv/bin/python), else in full."""
    path = Path(python)
    return str(path.relative_to(ROOT)) if path.is_absolute() and path.is_relative_to(ROOT) else python


def chapter_flags(seed: int, aug_per_demo: int, smoke: bool, extra: tuple = ()) -> list[str]:
    """scale_data.py's flags for one configuration, --out aside: at the chapter's defaults exactly the
    README's first command (`python scale_data.py --seed 0`), so its result cache replays the learner's
    run instead of training it again; otherwise only the flags that differ."""
    flags = ["--seed", str(seed)]
    if aug_per_demo != CHAPTER.aug_per_demo:
        flags += ["--aug_per_demo", str(aug_per_demo)]
    return flags + [*(SMOKE_FLAGS if smoke else FULL_FLAGS), *extra]


@checker
def run_chapter(seed: int, aug_per_demo: int, smoke: bool, say=print, extra: tuple = ()):
    """scale_data.py's metrics for one configuration, its report streamed because a full run takes
    minutes; a run made before with the same flags (the README's first command, exercise 1's) is
    replayed from scale_data.py's result cache in seconds, so only what is missing trains."""
    out = Path(os.environ.get("CH37_EXERCISE_OUT") or ROOT / "outputs" / "exercises")
    out /= f"{'smoke_' if smoke else ''}seed{seed}_aug{aug_per_demo}"
    flags = [*chapter_flags(seed, aug_per_demo, smoke, extra), "--out", str(out)]
    say(f"running: {_shown(sys.executable)} scale_data.py {' '.join(flags)}")
    argv, env = [sys.executable, str(ROOT / "scale_data.py"), *flags], dict(os.environ, PYTHONHASHSEED="0")
    with tempfile.TemporaryFile("w+") as err:  # progress bars: kept for the error message only
        p = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=err, text=True, env=env)
        lines = []
        for line in p.stdout:
            lines.append(line.rstrip())
            say("  | " + lines[-1])
        rc = p.wait()
        err.seek(0)
        tail = "\n".join(lines[-10:] + err.read().strip().splitlines()[-5:])
    if rc != 0:
        yield f"scale_data.py exited {rc} for seed {seed}, aug_per_demo {aug_per_demo}:\n{tail}"
    if not (out / "metrics.json").is_file():
        yield f"scale_data.py finished but wrote no {out / 'metrics.json'}"
    return json.loads((out / "metrics.json").read_text())


@checker
def check_run_sane(metrics: dict, ex: str = "ex1"):
    """What any run, even a smoke run, must satisfy: the keys, valid rates, and each budget's two arms at
    the same steps on the frames they claim, so that the data is the only difference between them."""
    arms = metrics.get("arms") if isinstance(metrics.get("arms"), dict) else {}
    missing = [k for k in KEYS if k not in metrics]
    for name, arm in ((name, arms.get(name)) for name in ARMS):
        ok = isinstance(arm, dict)
        missing += [f"arms.{name}.{k}" for k in ARM_KEYS if k not in arm] if ok else [f"arms.{name}"]
    if missing:
        yield f"{ex}: metrics.json lacks {', '.join(missing)}; is scale_data.py up to date?"
    for name, arm in arms.items():
        s, (lo, hi), frames, steps, loss = (arm[k] for k in ARM_KEYS)
        if not (0.0 <= lo <= s <= hi <= 1.0):
            yield f"{ex}: arm {name}: success {s} with interval [{lo}, {hi}] is not a valid rate"
        if frames <= 0 or steps <= 0 or not math.isfinite(loss):
            yield f"{ex}: arm {name} has frames {frames}, steps {steps}, loss {loss}"
    for budget in ("short", "full"):
        want = metrics["budgets"].get(budget)
        steps = sorted({arms[f"{d}_{budget}"]["steps"] for d in ("source", "augmented")})
        if steps != [want]:
            yield (
                f"{ex}: the {budget} budget's arms took {steps} steps, not both {want}; "
                "the data is then not the only difference"
            )
        if arms[f"augmented_{budget}"]["frames"] != metrics["source_frames"] + metrics["augmented_frames"]:
            yield f"{ex}: the augmented arms should train on source + augmented frames"
    if not (0 <= metrics["kept"] <= metrics["attempts"] and 0.0 <= metrics["yield"] <= 1.0):
        yield f"{ex}: kept {metrics['kept']} of {metrics['attempts']} attempts, yield {metrics['yield']}"
    for key, (plus, minus) in EFFECTS.items():
        got = metrics["effects"].get(key)
        if got is None or abs(got - (arms[plus]["success"] - arms[minus]["success"])) > 1e-5:
            yield f"{ex}: effects.{key} {got} is not {plus} minus {minus} success"
    if abs(metrics["scale_effect"] - metrics["effects"]["data_full"]) > 1e-9:
        yield f"{ex}: scale_effect {metrics['scale_effect']} is not the data effect at the full budget"


@checker
def check_ex1_measured(metrics: dict, band: dict):
    """The data effect at the full budget against meta.yaml's band: outside it, the chapter's claim fails
    on this run. Returns the lines to print."""
    check_run_sane(metrics, "ex1")
    arms, eff, budgets = metrics["arms"], metrics["scale_effect"], metrics["budgets"]
    lo, hi = band.get("scale_effect_min", -math.inf), band.get("scale_effect_max", math.inf)
    want = " and ".join(f"scale_effect {o} {v:+.3f}" for o, v in ((">=", lo), ("<=", hi)) if math.isfinite(v))
    if not want:
        yield "ex1: meta.yaml's exercise_checks.ex1.band has neither scale_effect_min nor scale_effect_max"
    s, a = arms["source_full"]["success"], arms["augmented_full"]["success"]
    measured = f"source only {s:.2f} -> source + augmented {a:.2f} ({eff * 100:+.0f} points)"
    measured = f"at {budgets['full']} steps each, {measured}"
    if not lo - 1e-9 <= eff <= hi + 1e-9:
        yield (
            f"ex1: measured scale effect {eff:+.3f} ({measured}) is outside the band in meta.yaml "
            f"({want}); the chapter's claim does not hold on this run: report it, with your metrics.json"
        )
    s, a = arms["source_short"]["success"], arms["augmented_short"]["success"]
    return [
        f"measured: {measured}; at the short budget ({budgets['short']} steps) {s:.2f} -> {a:.2f}; "
        f"meta.yaml band {want}: holds"
    ]


def point(metrics: dict, arm: str) -> tuple[float, list]:
    """(success, its 95% interval) of one arm of a run."""
    return float(metrics["arms"][arm]["success"]), list(metrics["arms"][arm]["ci95"])


def step_lines(points: dict) -> list[str]:
    """points {k: (success, ci95)}: each step with its 95% interval and what it can say."""
    ks = sorted(int(k) for k in points)
    lines = []
    for a, b in zip(ks, ks[1:]):
        (ra, ca), (rb, cb) = points[a], points[b]
        lo, hi = step_interval(ra, ca, rb, cb)
        lines.append(f"{a} -> {b}: {rb - ra:+.2f} [{lo:+.2f}, {hi:+.2f}] {step_verdict([lo, hi])}")
    return lines


def curve_shape(points: dict) -> str:
    """What one run's curve says at its end (the last step, judged against its own 95% interval):
    climb, fall, or (a step within its own noise) cannot tell from one seed."""
    ks = sorted(int(k) for k in points)
    return ex3_answer([step_interval(*points[a], *points[b]) for a, b in zip(ks, ks[1:])])


@checker
def check_ex3_nested(runs: dict):
    """runs {k: metrics}, k > 0 (k = 0 is the largest k's source-only arm): nested augmented sets
    (frames growing with k), one source set and one full budget (the same steps) in every run, so the
    curve moves the data alone."""
    ks = sorted(runs)
    frames = [runs[k]["augmented_frames"] for k in ks]
    if not all(x < y for x, y in zip(frames, frames[1:])) or frames[0] <= 0:
        yield f"ex3: augmented frames should grow with aug_per_demo {ks}, got {frames}"
    if len({runs[k]["source_frames"] for k in ks}) != 1:
        yield "ex3: the source set differs between runs; the runs are not comparable"
    steps = {k: runs[k]["budgets"]["full"] for k in ks}
    if len(set(steps.values())) != 1:
        yield f"ex3: the full budget differs between runs ({steps} steps): the curve mixes data and training"


@checker
def check_ex3_measured(rates: dict, band: dict):
    """rates {k: success}: each must lie in meta.yaml's band[str(k)] (from several seeds); returns the
    lines to print."""
    lines = []
    for k in sorted(int(k) for k in rates):
        if str(k) not in band:
            yield f"ex3: meta.yaml has no band for aug_per_demo {k}"
        r, (lo, hi) = float(rates[k]), band[str(k)]
        if not (lo - 1e-9 <= r <= hi + 1e-9):
            yield (
                f"ex3: measured success {r:.3f} at aug_per_demo {k} is outside the band "
                f"[{lo:.3f}, {hi:.3f}] in meta.yaml (what several seeds gave); the chapter's claim does not "
                "hold on this run: report it, with your metrics.json files"
            )
        lines.append(
            f"aug_per_demo {k}: success {r:.2f} (band [{lo:.2f}, {hi:.2f}], from several seeds): holds"
        )
    return lines


def verdict(pred: str, measured: str) -> str:
    if pred == measured:
        return f"your prediction {pred} matched the measurement."
    return f"your prediction was {pred}; the measurement says {measured}. Why might that be?"


def _smoke_note(ex: str, checked: str) -> str:
    return (
        f"{ex}: smoke run (CH37_EXERCISE_SMOKE=1): {checked} checked; numbers are not meaningful, "
        "so the meta.yaml bands are skipped and the prediction is not scored"
    )


def run_ex1(say=print) -> None:
    meta = load_meta()["ex1"]
    pred = check_prediction(load_exercise("ex1"), tuple(EX1_CHOICES), "ex1")
    say(f"ex1: prediction {pred} ({EX1_CHOICES[pred]}) recorded; running the experiment")
    smoke = smoke_mode()
    m = run_chapter(int(meta.get("seed", CHAPTER.seed)), CHAPTER.aug_per_demo, smoke, say)
    if smoke:
        check_run_sane(m, "ex1")
        return say(_smoke_note("ex1", "keys and ranges"))
    for line in check_ex1_measured(m, meta["band"]):
        say("ex1: " + line)
    # the band held, so this run agrees with the chapter's measured answer (meta.yaml, from a seed sweep)
    named = {k: f"{k} ({v})" for k, v in EX1_CHOICES.items()}
    say("ex1: " + verdict(named[pred], named[meta["answer"]]))


def run_ex2(say=print) -> None:
    try:  # ex2 needs no run; the density is 1/3 by construction when meta.yaml is not around
        density = float(load_meta()["ex2"].get("pusht_mask_density", 1 / 3))
    except ExerciseError:
        density = 1 / 3
    mod = load_exercise("ex2")
    if not callable(getattr(mod, "mix_embodiments", None)):
        raise ExerciseError(f"ex2: {_where(mod)} defines no function mix_embodiments")
    n = check_mix(mod.mix_embodiments, density, _where(mod))
    say(f"ex2: mix_embodiments matches the specification on {n} cases (N=0, M=0, N=1; float32 and float64)")


def run_ex3(say=print) -> None:
    meta = load_meta()["ex3"]
    pred = check_prediction(load_exercise("ex3"), EX3_CHOICES, "ex3")
    say(f"ex3: prediction {pred!r} recorded; measuring aug_per_demo {meta['aug_per_demo']}")
    seed, smoke = int(meta.get("seed", CHAPTER.seed)), smoke_mode()
    ks = sorted(map(int, meta["aug_per_demo"]))
    if ks[0] != 0 or len(ks) < 3:  # the first point is read from a run's source-only arm: k = 0
        raise ExerciseError(f"ex3: meta.yaml's aug_per_demo must be 0 and at least two more, got {ks}")
    # the largest k is the README's first command (replayed from the cache when it ran); the ones between
    # train at its full budget; k = 0 is its source-only arm at those same steps, so it is not trained again
    runs = {ks[-1]: run_chapter(seed, ks[-1], smoke, say)}
    steps = runs[ks[-1]]["budgets"]["full"]
    runs |= {k: run_chapter(seed, k, smoke, say, ("--full_steps", str(steps))) for k in ks[1:-1]}
    for m in runs.values():
        check_run_sane(m, "ex3")
    check_ex3_nested(runs)
    points = {ks[0]: point(runs[ks[-1]], "source_full")} | {
        k: point(runs[k], "augmented_full") for k in ks[1:]
    }
    say(
        f"ex3: aug_per_demo {ks[0]} is the aug_per_demo {ks[-1]} run's source-only arm, at the same {steps} "
        "steps"
    )
    say("ex3: steps, each with its 95% interval: " + "; ".join(step_lines(points)))
    if smoke:
        frames = [runs[k]["augmented_frames"] for k in ks[1:]]
        checked = f"keys, ranges, nested sizes (augmented frames {frames}) and equal budgets"
        return say(_smoke_note("ex3", checked))
    for line in check_ex3_measured({k: r for k, (r, _) in points.items()}, meta["band"]):
        say("ex3: " + line)
    shape, answer = curve_shape(points), meta["answer"]
    seen = meta.get("answer_from", {})
    several = (
        f"several seeds (meta.yaml: the Scale Lab at the same steps, aug_per_demo {seen['k']}: success "
        f"{', '.join(f'{x:.2f}' for x in seen['success'])}) say {answer}"
        if seen
        else f"several seeds (meta.yaml) say {answer}"
    )
    if shape == CANNOT_TELL:
        say(
            f"ex3: this run's last step lies within its own noise: {CANNOT_TELL}, not a verdict; {several}; "
            + verdict(pred, answer)
        )
    else:
        say(f"ex3: this run's last step says {shape}; {several}; {verdict(pred, answer)}")


RUNS = {"ex1": run_ex1, "ex2": run_ex2, "ex3": run_ex3}


def main(argv: list[str]) -> int:
    """python -m exercises.checks ex1|ex2|ex3: a failed check is one `error:` line and exit 1, as a failed
    test; a wrong command is exit 2, as any command's wrong flag."""
    if len(argv) != 1 or argv[0] not in RUNS:
        raise errors.DataError(
            f"usage: .venv/bin/python -m exercises.checks ex1|ex2|ex3, got {' '.join(argv)!r}"
        )
    try:
        RUNS[argv[0]](print)
    except ExerciseError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


def _as_test(ex: str, capsys) -> None:
    """The report is for the learner, so pytest's capture steps aside; a failure shows its message only.
    pytest is imported here, not at the top: `python -m exercises.checks` and the chapter's exercise-1
    reminder run where pytest is not installed (a notebook runtime)."""
    import pytest

    with capsys.disabled():
        print()
        problem = None
        try:
            RUNS[ex](print)
        except ExerciseError as e:
            problem = str(e)
    if problem:  # failed outside the except block, so pytest shows the message without a chained traceback
        pytest.fail(problem, pytrace=False)


def test_ex1(capsys):
    _as_test("ex1", capsys)


def test_ex2(capsys):
    _as_test("ex2", capsys)


def test_ex3(capsys):
    _as_test("ex3", capsys)


if __name__ == "__main__":
    errors.main(main)
