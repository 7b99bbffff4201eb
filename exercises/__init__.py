"""Chapter 3.7 exercises: ex1..ex3 answer files, their checks (checks.py) and reference answers (solutions/)."""
