"""Accuracy metrics of a tracked motion against ground truth."""
