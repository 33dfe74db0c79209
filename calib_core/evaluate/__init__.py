"""Evaluation without ground truth: leave-one-pose-out answers and their jackknife spread (``crossval``), and the
held-out scores of a fold (``held_out``)."""
