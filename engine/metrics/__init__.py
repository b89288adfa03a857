"""Evaluation of the pipeline's results against ground truth (paper section 5)."""
