"""Reference answer to exercises/ex3_hparam_aug_amount.py: the task is that file's docstring."""

PREDICTION = "plateau"  # "climb", "plateau" or "fall"
WHY = (
    "Four perturbed starts per demo already put a block start in 31 of the 36 cells where twelve demos "
    "reach 12, so doubling to eight adds one cell and little the policy has not seen at this budget."
)
