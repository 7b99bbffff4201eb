"""Exercise 1 (predict, then run): does growing the PushT demos help the policy?

Objective
    Commit to a prediction about the data-scale effect before you see it, then measure it.
    scale_data.py trains the same behaviour-cloning MLP on the 12 source PushT demos alone, and
    on those 12 plus the augmented demos (each source start perturbed 8 times and re-solved by
    the scripted expert, kept only when the expert succeeds). The question is about the full
    budget: both arms take exactly the same number of gradient steps (500 passes over the
    source + augmented set), from the same initial weights and batch-order seed, and roll out on
    the same 50 held-out starts, so the data is the only difference.

What to do
    1. Set PREDICTION below to one letter:
         "A"  augmentation helps: source + augmented succeeds more often than source-only
         "B"  augmentation hurts: it succeeds less often
         "C"  it does not matter: about the same success either way
    2. Set WHY to one sentence (at least three words) saying why you expect that. Think about
       what 12 demos cover of the start space, and what the augmented demos add.
    3. Run the check. It validates your answer first, then runs
           scale_data.py --seed 0 --out outputs/exercises/seed0_aug8
       the README's first command with its own --out: if you made that run, scale_data.py's result
       cache replays it in seconds (same flags, same code); if not, it trains (a few minutes on a
       laptop CPU). It checks the measured effect against the band recorded in meta.yaml, and prints
       whether your prediction matched the measurement. A wrong prediction does not fail the
       check; a missing one does.
    4. Afterwards, read the whole 2x2 the run prints (and metrics.json's "effects"): at the short
       budget (500 passes over the source set only) does the extra data still help? What does
       that say about data and compute?

How to check (from the repository root, after the README's set-up)
    .venv/bin/python -m pytest exercises/checks.py -k ex1
    (with .venv activated: python -m pytest exercises/checks.py -k ex1)

Estimated time: 10 minutes (seconds of waiting after the README's run; a few minutes without it).
"""

PREDICTION = ""  # "A", "B" or "C"
WHY = ""  # one sentence
