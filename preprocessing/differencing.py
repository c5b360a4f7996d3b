"""Second-order central difference of a uniformly sampled signal.

v(t) = (p(t + dt) - p(t - dt)) / (2 dt), dt = the differential time (paper: 1.0 s). Near
the ends, where t +- dt leaves the record, the half-width shrinks to what is available and
the first/last sample use a one-sided difference.
"""
from __future__ import annotations

import numpy as np


def difference_span(n: int, sample_dt: float, diff_dt: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Sample indices (lo, hi), each shape (n,), that the difference at each sample spans.

    hi - lo = 2 k with k = round(diff_dt / sample_dt), shrunk near the ends; the first and
    last samples use a one-sided pair. Needs n >= 2.
    """
    k = max(1, int(round(diff_dt / sample_dt)))
    idx = np.arange(n)
    half = np.minimum(k, np.minimum(idx, n - 1 - idx))
    lo = idx - half
    hi = idx + half
    hi[0], lo[-1] = 1, n - 2              # one-sided at the very ends
    return lo, hi


def noise_scale(n: int, sample_dt: float, diff_dt: float = 1.0) -> np.ndarray:
    """Variance of each sample's difference (shape (n,)) relative to a full-width one's.

    White position noise of std sigma gives a difference over hi - lo steps a std of
    sqrt(2) sigma / ((hi - lo) sample_dt): the one-sided difference at either end, over one
    step instead of 2 k, is 2 k times as noisy (20 times at 10 Hz and 1.0 s), so its
    variance scale is (2 k / (hi - lo))^2 = 400.
    """
    if n < 2:
        return np.ones(n)
    lo, hi = difference_span(n, sample_dt, diff_dt)
    return (float(np.max(hi - lo)) / (hi - lo)) ** 2


def central_difference(p: np.ndarray, sample_dt: float, diff_dt: float = 1.0) -> np.ndarray:
    """Derivative of `p` (shape (N,), step `sample_dt` [s]) with half-width `diff_dt` [s]."""
    p = np.asarray(p, float)
    n = len(p)
    if n < 2:
        return np.zeros(n)
    lo, hi = difference_span(n, sample_dt, diff_dt)
    return (p[hi] - p[lo]) / ((hi - lo) * sample_dt)
