"""Exercise 3 (hyperparameter investigation): how much augmentation is enough?

Objective
    Measure the data-scale curve instead of assuming it, and read it against its noise. With
    --aug_per_demo k, every one of the 12 PushT source demos gets k perturbed re-solves. The
    augmented sets are nested (the set at k = 4 is part of the set at k = 8), so the curve compares
    more of the same kind of data. Every point trains for one and the same number of gradient
    steps: the full budget of the k = 8 run (500 passes over its source + augmented set). So the
    curve moves the data alone, and you read the source + augmented arm at that budget.

What to do
    1. Predict what success does as aug_per_demo grows to 8 at those equal steps (0 means source
       demos only). Set PREDICTION to one word:
         "climb"    still rising at k = 8
         "plateau"  levelled off: more augmented demos barely move it
         "fall"     too much augmentation hurts
    2. Set WHY to one sentence (at least three words) saying why.
    3. Run the check. It validates your answer, then measures k = 0, 4, 8 at seed 0 without training
       anything it already has: k = 8 is the README's first command (replayed from the result cache
       when you made it, or exercise 1 did), k = 0 is that run's source-only arm (the same data,
       steps and initial weights), and only k = 4 trains, at the k = 8 run's full budget (folder
       outputs/exercises/seed0_aug4). It checks each success against meta.yaml's bands and prints
       each step with its 95% interval.
    4. Read the steps against their intervals. With 50 evaluation starts one seed's interval is about
       +-0.1, so a step smaller than that is noise: the check then says "cannot tell from one seed"
       instead of a verdict. Your prediction is scored against what several seeds show: meta.yaml's
       answer, read from the Scale Lab's re-solve curve at the same steps (three seeds, 100 starts
       each, k = 0, 2, 8 as 12, 36 and 108 demos), with the same rule.
    5. Where does the curve bend past k = 8? `.venv/bin/python scale_lab.py` (the Scale Lab, see the
       README) measures it at 12 to 972 demos, for fresh expert demos and both data engines.

How to check (from the repository root, after the README's set-up)
    .venv/bin/python -m pytest exercises/checks.py -k ex3
    (with .venv activated: python -m pytest exercises/checks.py -k ex3)

Estimated time: 15 minutes (most of it waiting for the k = 4 run).
"""

PREDICTION = ""  # "climb", "plateau" or "fall"
WHY = ""  # one sentence
