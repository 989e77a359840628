"""Evaluation: metrics against the truth, method comparisons, reports."""
