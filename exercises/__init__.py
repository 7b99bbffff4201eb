"""Chapter 3.7 exercises: the answer files ex1..ex3, their checks (checks.py), the rules that derive
their answers and bands (rules.py) and reference answers (solutions/)."""
