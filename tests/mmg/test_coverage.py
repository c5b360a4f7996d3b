"""Samples and windows outside a one-quadrant propeller model (`sysid.mmg.coverage`) against
a hand-made record with a known number of astern samples, and windows counted one by one."""
from __future__ import annotations

import numpy as np

from sysid.mmg.coverage import astern_samples, one_quadrant_propeller, windows_touching

STANDARD = {"hull": "standard", "propeller": "standard", "rudder": "standard"}
FOUR = {"hull": "yoshimura_low_speed", "propeller": "four_quadrant", "rudder": "four_quadrant"}


def test_astern_revolutions_and_going_astern_are_outside_only_a_one_quadrant_propeller():
    n = np.full(100, 12.0)
    u = np.full(100, 0.8)
    n[20:32] = -5.0          # 12 samples of astern revolutions (crash stop order)
    u[28:35] = -0.1          # going astern, 4 of them under astern revolutions: 3 more
    flagged = astern_samples(STANDARD, u, n)
    assert int(flagged.sum()) == 12 + 3
    assert np.flatnonzero(flagged).tolist() == list(range(20, 35))
    assert one_quadrant_propeller(STANDARD) and not one_quadrant_propeller(FOUR)
    assert not astern_samples(FOUR, u, n).any()


def test_windows_touching_counts_every_window_with_one_flagged_sample():
    flagged = np.zeros(100, dtype=bool)
    flagged[[10, 47, 48, 99]] = True
    for length in (1, 6, 30):
        starts = np.arange(0, 100 - length + 1, 2)
        by_hand = np.array([flagged[s:s + length].any() for s in starts])
        np.testing.assert_array_equal(windows_touching(flagged, starts, length), by_hand)
    # 30-s test windows at 0, 30, 60 (the protocol's): the first two hold flagged samples, 60..89 none
    assert windows_touching(flagged, np.array([0, 30, 60]), 30).tolist() == [True, True, False]
