"""The answer rules of exercises 1 and 3 and the bands their measured checks assert, in one home:
`python -m tools.meta` derives meta.yaml's exercise_checks with them (publishing RULES beside them), and
checks.py judges a learner's curve with the same ex3_answer. A rule given bad input raises ValueError.
"""

import math

# metrics.json's 2x2: data {source, augmented} x budget {short, full}; effects are differences of arms.
ARMS = ("source_short", "augmented_short", "source_full", "augmented_full")
EFFECTS = {
    "data_full": ("augmented_full", "source_full"),
    "data_short": ("augmented_short", "source_short"),
    "compute_source": ("source_full", "source_short"),
    "compute_augmented": ("augmented_full", "augmented_short"),
}
# ex3: a step is read against its own 95% interval; PLATEAU_TOL only names a flat end when that interval
# is this narrow on both sides (seeds pooled), never a step one seed measured
PLATEAU_TOL = 0.04
CANNOT_TELL = "cannot tell from one seed"
BAND_MIN_MARGIN = 0.06  # the narrowest half-width a band may have


def band_margin(ci95) -> float:
    """Half the Wilson 95% half-width, at least BAND_MIN_MARGIN: room for another run's noise."""
    return max(BAND_MIN_MARGIN, (ci95[1] - ci95[0]) / 4)


def success_band(success: float, ci95) -> list[float]:
    m = band_margin(ci95)
    return [round(max(0.0, success - m), 4), round(min(1.0, success + m), 4)]


def ex1_answer(deltas) -> str:
    """A if augmented beat source on every sweep seed, B if it lost on every seed, else C."""
    deltas = list(deltas)
    if not deltas:
        raise ValueError("ex1: the seed sweep has no rows")
    return "A" if all(d > 0 for d in deltas) else "B" if all(d < 0 for d in deltas) else "C"


def ex1_band(answer: str, effect0: float, ci95_aug0) -> dict:
    """A or B: half the seed-0 effect as the floor or the ceiling, so a run must keep its sign with room
    for noise; C: the seed-0 effect +- band_margin of the seed-0 augmented arm's interval."""
    if answer in ("A", "B"):
        return {"scale_effect_min" if answer == "A" else "scale_effect_max": round(effect0 / 2, 4)}
    m = band_margin(ci95_aug0)
    return {"scale_effect_min": round(effect0 - m, 4), "scale_effect_max": round(effect0 + m, 4)}


def step_interval(a: float, ci_a, b: float, ci_b) -> list[float]:
    """95% interval of the difference b - a of two success rates, from each rate's own Wilson interval
    (Newcombe's hybrid score interval), rounded to 6 decimals."""
    d = b - a
    lo = d - math.sqrt((b - ci_b[0]) ** 2 + (ci_a[1] - a) ** 2)
    hi = d + math.sqrt((ci_b[1] - b) ** 2 + (a - ci_a[0]) ** 2)
    return [round(lo, 6), round(hi, 6)]


def step_verdict(interval) -> str:
    """up or down only when the step's 95% interval leaves out 0; else the data cannot tell."""
    lo, hi = interval
    return "up" if lo > 0 else "down" if hi < 0 else CANNOT_TELL


def ex3_answer(steps) -> str:
    """The curve's end from its last step's verdict (step_verdict): up = climb, down = fall, and a step
    within its own noise = plateau when the interval is narrow (every end within PLATEAU_TOL of 0),
    else the data cannot tell."""
    interval = list(steps)[-1]
    verdict = step_verdict(interval)
    if verdict != CANNOT_TELL:
        return {"up": "climb", "down": "fall"}[verdict]
    return "plateau" if max(map(abs, interval)) <= PLATEAU_TOL else CANNOT_TELL


def lab_curve(lab: dict) -> dict:
    """{k: (success, ci95)} of the Scale Lab's resolve_fixed curve (every N at the default run's full
    budget, seeds pooled), k = N / 12 - 1 augmented demos per source demo."""
    curve = lab["curves"]["resolve_fixed"]
    return {int(n) // 12 - 1: (float(p["success"]), list(p["ci95"])) for n, p in curve.items()}


def multi_seed_band(values) -> list[float]:
    """The range several seeds gave, widened by BAND_MIN_MARGIN and clipped to [0, 1]: one seed's run
    on any kernel path should land inside."""
    return [
        round(max(0.0, min(values) - BAND_MIN_MARGIN), 4),
        round(min(1.0, max(values) + BAND_MIN_MARGIN), 4),
    ]


def derive_checks(seeds: dict, aug: dict, lab: dict | None) -> dict:
    """exercise_checks from a seed sweep and an aug sweep (the JSON files `python -m tools.sweep` writes)
    and the Scale Lab's section of meta.yaml (lab: its curves): ex3's answer and bands from several seeds."""
    rows, by_k = {r["seed"]: r for r in seeds["rows"]}, {r["aug_per_demo"]: r for r in aug["rows"]}
    if 0 not in rows:
        raise ValueError("the seed sweep must include seed 0 (ex1 and ex3 are run at seed 0)")
    if aug.get("seed", 0) != 0:
        raise ValueError("the aug sweep must be at seed 0")
    if sorted(by_k) != [0, 4, 8]:
        raise ValueError(f"the aug sweep must cover aug_per_demo 0, 4, 8; it has {sorted(by_k)}")
    r0 = rows[0]
    answer = ex1_answer(r["delta"] for r in seeds["rows"])
    ex1 = {"seed": 0, "answer": answer, "band": ex1_band(answer, r0["delta"], r0["ci95"]["augmented_full"])}
    density = round(seeds["action_dims"]["pusht"] / seeds["padded_action_dim"], 6)
    if not lab:
        raise ValueError("ex3's answer is read from the Scale Lab's curves: run python scale_lab.py first")
    curve = lab_curve(lab)
    if not {0, 2, 8} <= set(curve):
        raise ValueError("the Scale Lab's resolve_fixed curve must cover N = 12, 36, 108 (k = 0, 2, 8)")
    ks = [0, 2, 8]
    steps = [step_interval(*curve[a], *curve[b]) for a, b in zip(ks, ks[1:])]
    k0 = [float(r["source_full"]) for r in seeds["rows"]]  # k = 0 is the source arm at the full budget
    k8 = [float(r["augmented_full"]) for r in seeds["rows"]]
    bands = {"0": multi_seed_band(k0), "4": [multi_seed_band(k0)[0], multi_seed_band(k8)[1]]}
    ex3 = {
        "seed": 0,
        "aug_per_demo": [0, 4, 8],
        "answer": ex3_answer(steps),
        "answer_from": {
            "curve": "scale_lab resolve_fixed (seeds pooled, the default run's full budget)",
            "k": ks,
            "success": [curve[k][0] for k in ks],
            "steps_ci95": steps,
        },
        "band": {**bands, "8": multi_seed_band(k8)},
    }
    return {"ex1": ex1, "ex2": {"pusht_mask_density": density}, "ex3": ex3}


# The rules above in words, published in meta.yaml's reference_run beside the numbers they made.
RULES = {
    "ex1_answer": "A if augmented > source at the full budget (equal steps) on every sweep seed, B if "
    "augmented < source on every seed, else C",
    "ex1_band": "A: scale_effect_min = seed-0 effect / 2; B: scale_effect_max = seed-0 effect / 2; "
    "C: seed-0 effect +- max(0.06, Wilson half-width / 2) of the seed-0 augmented arm at the full budget",
    "ex3_answer": "from several seeds, not one: the Scale Lab's resolve_fixed curve (seeds pooled, "
    "every N at the default run's full budget) at k = 0, 2, 8 augmented demos per source (N = 12, 36, "
    "108); its last step decides: climb if its 95% interval (Newcombe, from the pooled Wilson intervals) "
    f"is above 0, fall if below, plateau if it holds 0 and lies within +-{PLATEAU_TOL}; a learner's "
    "one-seed step is judged the same way, and one whose interval holds 0 is 'cannot tell from one seed'",
    "ex3_band": "k = 0 and 8: the range of the five sweep seeds' source and source + augmented arms at the "
    "full budget, widened by 0.06 and clipped to [0, 1]; k = 4: from the k = 0 band's floor to the k = 8 "
    "band's ceiling",
}
