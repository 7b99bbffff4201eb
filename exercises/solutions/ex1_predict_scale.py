"""Reference answer. Exercise 1 (predict, then run): does growing the PushT demos help the policy?

Objective
    Commit to a prediction about the data-scale effect before you see it, then measure it.
    scale_data.py trains the same behaviour-cloning MLP twice: on the 12 source PushT demos
    alone, and on those 12 plus the augmented demos (each source start perturbed 8 times and
    re-solved by the scripted expert, kept only when the expert succeeds). Same initial
    weights, same batch order, same 50 held-out starts: the data is the only difference.

What to do
    1. Set PREDICTION below to one letter:
         "A"  augmentation helps: source + augmented succeeds more often than source-only
         "B"  augmentation hurts: it succeeds less often
         "C"  it does not matter: about the same success either way
    2. Set WHY to one sentence (at least three words) saying why you expect that. Think about
       what 12 demos cover of the start space, and what the augmented demos add.
    3. Run the check. It validates your answer first, then runs
           python scale_data.py --seed 0 --no-rerun --out outputs/exercises/seed0_aug8
       (a few minutes on a laptop CPU), checks the measured effect against the band recorded
       in meta.yaml, and prints whether your prediction matched the measurement. A wrong
       prediction does not fail the check; a missing one does.
    4. Afterwards, compare with the compute-matched arm in metrics.json: is the gain "more
       data" or just "more gradient steps"?

How to check
    pytest exercises/checks.py -k ex1

Estimated time: 10 minutes (about 3 of them waiting for the run).
"""

PREDICTION = "A"  # "A", "B" or "C"
WHY = ("Twelve demos cover only a few cells of the start space, and every augmented demo is the expert "
       "solving a new nearby start in the real physics, so the policy sees starts like the test ones.")
