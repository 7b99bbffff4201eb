"""Reference answer to exercises/ex3_hparam_aug_amount.py: the task is that file's docstring."""

PREDICTION = "climb"  # "climb", "plateau" or "fall"
WHY = (
    "Twelve demos leave most of the start space empty, and the nested sets at 4 and 8 keep filling new cells "
    "with real expert solutions, so each step should still add coverage the policy can use."
)
