"""Reference answer to exercises/ex3_hparam_aug_amount.py: the task is that file's docstring."""

PREDICTION = "climb"  # "climb", "plateau" or "fall"
WHY = (
    "Each step from 12 to 36 to 108 demos puts block starts in cells the fewer demos never reach, and at "
    "the same steps the Scale Lab's three seeds still rise through 108 demos; one seed's 4 -> 8 step is "
    "too noisy to show it either way."
)
