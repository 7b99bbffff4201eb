"""Exercise 3 (hyperparameter investigation): how much augmentation is enough?

Objective
    Measure the data-scale curve instead of assuming it. With --aug_per_demo k, every one of the
    12 PushT source demos gets k perturbed re-solves. The augmented sets are nested (the set at
    k = 4 is part of the set at k = 8), so the curve compares more of the same kind of data.
    All three runs train for one and the same number of gradient steps: the full budget of the
    k = 8 run (500 passes over its source + augmented set), passed to the k = 0 and k = 4 runs
    with --full_steps. So the curve moves the data alone, and you read the source + augmented arm
    at that full budget.

What to do
    1. Predict the shape of the policy's success rate as aug_per_demo goes 0 -> 4 -> 8
       (0 means source demos only). Set PREDICTION to one word:
         "climb"    success is still rising at the end: 4 -> 8 goes up
         "plateau"  it levels off: 4 -> 8 barely moves
         "fall"     the last step goes down: too much augmentation hurts
       The check judges the last step (4 -> 8) and reads a step smaller than meta.yaml's
       plateau_tol (a few points of success) as flat: climb = above +tol, fall = below -tol,
       anything else is a plateau. The first step (0 -> 4) is printed for you to think about.
    2. Set WHY to one sentence (at least three words) saying why.
    3. Run the check. It validates your answer, then runs scale_data.py at seed 0 with
       --aug_per_demo 8, then 0 and 4 at the k = 8 run's full budget (folders
       outputs/exercises/seed0_aug{0,4,8}; the k = 8 run is the one exercise 1 already made and is
       reused if it is there), checks each measured success against the bands in meta.yaml, and
       prints each step and the shape the data shows.
    4. Look at the 95% intervals in each metrics.json: with 50 evaluation starts, which of the
       steps could be noise?
    5. Three points cannot say whether the curve keeps climbing past them, or where it bends:
       `.venv/bin/python scale_lab.py` (the Scale Lab, see the README) measures it at 12 to 972 demos,
       for fresh expert demos and both data engines, over three seeds.

How to check (from the repository root, after the README's set-up)
    .venv/bin/python -m pytest exercises/checks.py -k ex3
    (with .venv activated: python -m pytest exercises/checks.py -k ex3)

Estimated time: 20 minutes (most of it waiting for three runs; fewer if exercise 1 ran first).
"""

PREDICTION = ""  # "climb", "plateau" or "fall"
WHY = ""  # one sentence
