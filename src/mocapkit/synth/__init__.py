"""Synthetic recording sessions rendered from real motion, with ground truth."""
