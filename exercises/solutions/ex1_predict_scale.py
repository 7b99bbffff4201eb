"""Reference answer to exercises/ex1_predict_scale.py: the task is that file's docstring."""

PREDICTION = "A"  # "A", "B" or "C"
WHY = (
    "Twelve demos cover only a few cells of the start space, and every augmented demo is the expert "
    "solving a new nearby start in the real physics, so the policy sees starts like the test ones."
)
