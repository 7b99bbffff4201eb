"""Reference answer to exercises/ex3_hparam_aug_amount.py: the task is that file's docstring."""

PREDICTION = "fall"  # "climb", "plateau" or "fall"
WHY = (
    "Four perturbed starts per demo already put a block start in 31 of the 36 cells where twelve demos "
    "reach 12, so eight add one cell while the same steps now visit each demo half as often; at one seed "
    "that reads as a fall, and over seeds the Scale Lab's curves are the better guide."
)
