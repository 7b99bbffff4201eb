"""Chapter 3.7 exercises: the answer files ex1..ex3, their checks (checks.py), the rules that derive
their answers and bands (rules.py) and reference answers (solutions/)."""


def ex1_reminder() -> str | None:
    """A line for a learner who runs the chapter before writing exercise 1's prediction, which this run
    answers; None once exercises/ex1_predict_scale.py holds one (read as its check reads it)."""
    try:
        from exercises.checks import EX1_CHOICES, ExerciseError, check_prediction, load_exercise
    except ImportError:  # the exercises' packages (pytest) are not here: nothing to remind of
        return None
    try:
        check_prediction(load_exercise("ex1"), tuple(EX1_CHOICES), "ex1")
        return None
    except ExerciseError:
        return (
            "exercise 1: this run answers its question; write your PREDICTION and WHY in "
            "exercises/ex1_predict_scale.py before you read the numbers (Ctrl-C stops the run)"
        )
