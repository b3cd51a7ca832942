"""Validity studies of the evaluators (docs/validity.md): they read a release and score references only."""
