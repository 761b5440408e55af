"""Evaluation: the stability suite, error against run time, ablations and the
``swingar report`` that puts them in one folder (docs/design.md §10)."""
