"""Downsampling by taking samples (no averaging): the wind really varies at 10 Hz."""
from __future__ import annotations

import numpy as np


def sample_indices(grid_index: np.ndarray, step: int) -> np.ndarray:
    """Positions in `grid_index` (ints, run-relative 10 Hz sample numbers) that fall on a
    multiple of `step` (e.g. 10 for 1 Hz from 10 Hz), so every segment keeps the run's
    t = t0, t0 + 1, t0 + 2, ... s grid."""
    return np.flatnonzero(np.asarray(grid_index) % step == 0)
