"""Zero-phase Butterworth low-pass of the FOG yaw rate (paper: 0.2 Hz cut-off)."""
from __future__ import annotations

import numpy as np
from scipy import signal


def design_cutoff(cutoff: float, order: int) -> float:
    """Per-pass Butterworth corner [Hz] whose forward-backward response is -3 dB at `cutoff`.

    One pass has |H|^2 = 1 / (1 + (f/fc)^(2 order)); forward-backward squares it, so the
    combined -3 dB point is at fc (sqrt(2) - 1)^(1 / (2 order)) and fc is set to match.
    """
    return cutoff / (np.sqrt(2.0) - 1.0) ** (1.0 / (2 * order))


def lowpass(x: np.ndarray, sample_rate: float, cutoff: float = 0.2, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of `x` (shape (N,)), -3 dB at `cutoff` overall.

    `sample_rate`, `cutoff` in Hz; `order` is the order of one pass (the forward-backward
    pass doubles it). Records shorter than the filter's padding come back as a copy.
    """
    x = np.asarray(x, float)
    sos = signal.butter(order, design_cutoff(cutoff, order), btype="low", fs=sample_rate,
                        output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if len(x) <= padlen:
        return x.copy()
    return signal.sosfiltfilt(sos, x)
