"""The trim's shortcuts give numpy's numbers bit for bit."""

import numpy as np

from calib_core.robust.inliers import _row_medians, _row_norms


def test_row_medians_and_norms_equal_numpys_bit_for_bit():
    """``_row_medians`` is ``np.median(axis=1)`` (odd and even rows, ties, a NaN row) and ``_row_norms`` is
    ``np.linalg.norm(axis=1)``, the same numbers."""
    rng = np.random.default_rng(3)
    for K in range(1, 40):
        a = np.abs(rng.normal(size=(6, K))) * 10.0 ** rng.integers(-6, 3)
        if K > 3:
            a[:, 1] = a[:, 2]
        assert np.array_equal(_row_medians(a), np.median(a, axis=1))
        v = rng.normal(size=(K, 2))
        assert np.array_equal(_row_norms(v), np.linalg.norm(v, axis=1))
    a[2, 1] = np.nan
    assert np.array_equal(_row_medians(a), np.median(a, axis=1), equal_nan=True)
