"""The answer rules of exercises 1 and 3 and the bands their measured checks assert, in one home:
`python -m tools.meta` derives meta.yaml's exercise_checks with them (publishing RULES beside them), and
checks.py judges a learner's curve with the same ex3_answer. A rule given bad input raises ValueError.
"""

# metrics.json's 2x2: data {source, augmented} x budget {short, full}; effects are differences of arms.
ARMS = ("source_short", "augmented_short", "source_full", "augmented_full")
EFFECTS = {
    "data_full": ("augmented_full", "source_full"),
    "data_short": ("augmented_short", "source_short"),
    "compute_source": ("source_full", "source_short"),
    "compute_augmented": ("augmented_full", "augmented_short"),
}
PLATEAU_TOL = 0.04  # a step of success smaller than this reads as flat (ex3)
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


def ex3_answer(s0: float, s4: float, s8: float, tol: float = PLATEAU_TOL) -> str:
    """What the curve does at the end: the last step (4 -> 8) decides, the first (s0 -> s4) is printed for
    the learner, not judged. Rounded to 6 decimals first, so a step of exactly tol (0.26 - 0.22) is flat."""
    step = round(s8 - s4, 6)
    return "climb" if step > tol else "fall" if step < -tol else "plateau"


def derive_checks(seeds: dict, aug: dict) -> dict:
    """exercise_checks from a seed sweep and an aug sweep (the JSON files `python -m tools.sweep` writes)."""
    rows, by_k = {r["seed"]: r for r in seeds["rows"]}, {r["aug_per_demo"]: r for r in aug["rows"]}
    if 0 not in rows:
        raise ValueError("the seed sweep must include seed 0 (ex1 and ex3 are run at seed 0)")
    if aug.get("seed", 0) != 0:
        raise ValueError("the aug sweep must be at seed 0")
    if sorted(by_k) != [0, 4, 8]:
        raise ValueError(f"the aug sweep must cover aug_per_demo 0, 4, 8; it has {sorted(by_k)}")
    r0, s = rows[0], {k: r["augmented_full"] for k, r in by_k.items()}
    answer, curve = ex1_answer(r["delta"] for r in seeds["rows"]), ex3_answer(s[0], s[4], s[8])
    ex1 = {"seed": 0, "answer": answer, "band": ex1_band(answer, r0["delta"], r0["ci95"]["augmented_full"])}
    ex3 = {"seed": 0, "aug_per_demo": [0, 4, 8], "answer": curve, "plateau_tol": PLATEAU_TOL}
    bands = {str(k): success_band(s[k], by_k[k]["ci95"]["augmented_full"]) for k in (0, 4, 8)}
    density = round(seeds["action_dims"]["pusht"] / seeds["padded_action_dim"], 6)
    return {"ex1": ex1, "ex2": {"pusht_mask_density": density}, "ex3": {**ex3, "band": bands}}


# The rules above in words, published in meta.yaml's reference_run beside the numbers they made.
RULES = {
    "ex1_answer": "A if augmented > source at the full budget (equal steps) on every sweep seed, B if "
    "augmented < source on every seed, else C",
    "ex1_band": "A: scale_effect_min = seed-0 effect / 2; B: scale_effect_max = seed-0 effect / 2; "
    "C: seed-0 effect +- max(0.06, Wilson half-width / 2) of the seed-0 augmented arm at the full budget",
    "ex3_answer": f"all three runs at the aug_per_demo 8 run's full budget (the same steps); "
    f"the last step s8-s4 of augmented-arm success decides: climb if > +{PLATEAU_TOL}, "
    f"fall if < -{PLATEAU_TOL}, else plateau; the first step s4-s0 is printed, not judged",
    "ex3_band": "measured success +- max(0.06, Wilson 95% half-width / 2), clipped to [0, 1]",
}
