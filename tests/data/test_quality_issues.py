"""A log's time gaps and frozen GNSS stretches (`sysid.data.recordings._quality_issues`) on a
synthetic 10 Hz log whose faults are placed by hand."""
from __future__ import annotations

import numpy as np
import pytest

from sysid.data.recordings import _quality_issues


def _log() -> tuple[np.ndarray, np.ndarray]:
    """(t (200,) [s], values (200, 8)): x (column 1) and psi (column 5) moving, with a 1.1-s
    time gap after t = 14.9 s, x and psi frozen over steps 50-69 (2 s, at 5 s) and 100-103
    (0.4 s, shorter than the 1-s limit), and x alone frozen over steps 120-139."""
    t = np.arange(200) * 0.1
    t[150:] += 1.0
    values = np.zeros((200, 8))
    values[:, 0], values[:, 1], values[:, 5] = t, 2.0 * t, np.sin(t)
    for lo, hi, columns in ((50, 70, (1, 5)), (100, 104, (1, 5)), (120, 140, (1,))):
        for c in columns:
            values[lo:hi + 1, c] = values[lo, c]
    return t, values


def test_gaps_and_frozen_gnss_are_found_where_they_were_placed():
    t, values = _log()
    issues, suspect = _quality_issues(t, values, 0.1)
    assert issues == ["time gap of 1.10 s at t = 14.9 s", "GNSS frozen for 2.0 s at t = 5.0 s"]
    assert suspect == [pytest.approx((14.9, 16.0)), pytest.approx((5.0, 7.0))]


def test_a_log_frozen_to_its_end_and_from_its_start():
    t, values = _log()
    values[:15, 1], values[:15, 5] = values[0, 1], values[0, 5]      # steps 0-13: 1.4 s
    values[185:, 1], values[185:, 5] = values[185, 1], values[185, 5]  # steps 185-198: to the end
    issues, _ = _quality_issues(t, values, 0.1)
    frozen = [m for m in issues if m.startswith("GNSS frozen")]
    assert frozen == ["GNSS frozen for 1.4 s at t = 0.0 s", "GNSS frozen for 2.0 s at t = 5.0 s",
                      "GNSS frozen for 1.4 s at t = 19.5 s"]
