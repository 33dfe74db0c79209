"""Every interval the reports state, in one place: the Wilson score interval of a rate, the normal half-width of a
paired mean difference, the paired percentile bootstrap over trials, and scipy's bootstrap of a statistic."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.stats import bootstrap

Z95 = 1.959963984540054
"""The standard normal's 97.5% quantile: a two-sided 95% interval is +- Z95 standard errors."""
N_RESAMPLES = 2000
"""Resamples of ``bootstrap_interval``."""


def wilson_interval(k, n, z: float = Z95) -> tuple[np.ndarray, np.ndarray]:
    """Wilson score interval of a proportion ``k/n`` (arrays broadcast); NaN where ``n == 0``."""
    k = np.asarray(k, float)
    n = np.asarray(n, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        denom = 1.0 + z * z / n
        centre = (p + z * z / (2 * n)) / denom
        half = z / denom * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return np.clip(centre - half, 0.0, 1.0), np.clip(centre + half, 0.0, 1.0)


def paired_half_width(diffs, axis: int = 0):
    """95% half-width of the mean of paired differences (normal approximation, ``Z95`` standard errors); NaN for
    fewer than two pairs."""
    d = np.asarray(diffs, float)
    n = d.shape[axis]
    if n < 2:
        return np.full(np.delete(d.shape, axis), np.nan) if d.ndim > 1 else np.nan
    return Z95 * d.std(axis=axis, ddof=1) / np.sqrt(n)


def paired_bootstrap(statistic: Callable[[np.ndarray], np.ndarray], n: int, n_boot: int,
                     seed: int) -> tuple[float, float]:
    """95% percentile interval of a paired statistic over ``n`` trials: ``statistic(idx)`` takes (R, n) trial
    indices (each row one resample, every method's rows resampled together) and returns (R,) values; NaN values
    are dropped; (NaN, NaN) when none is left."""
    idx = np.random.default_rng(seed).integers(0, n, size=(n_boot, n))
    boot = np.asarray(statistic(idx), float)
    boot = boot[~np.isnan(boot)]
    if not len(boot):
        return np.nan, np.nan
    return float(np.quantile(boot, 0.025, method="lower")), float(np.quantile(boot, 0.975, method="higher"))


def bootstrap_interval(samples: tuple, statistic, seed: int, paired: bool = False) -> tuple[float, float]:
    """95% percentile bootstrap interval of ``statistic(*samples, axis)`` (scipy.stats.bootstrap,
    ``N_RESAMPLES`` resamples)."""
    ci = bootstrap(samples, statistic, n_resamples=N_RESAMPLES, method="percentile", random_state=seed,
                   paired=paired).confidence_interval
    return float(ci.low), float(ci.high)
