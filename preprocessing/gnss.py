"""Two-antenna GNSS: baseline check, raw heading, midship position.

Inputs are earth-frame antenna positions (x0 north, y0 east) [m], arrays of shape (N,),
NaN where a fix is missing. The antenna body positions come from a `SensorLayout`.
"""
from __future__ import annotations

import numpy as np

from preprocessing.frames import body_to_earth
from preprocessing.sensors import SensorLayout


def antenna_positions(layout: SensorLayout) -> tuple[tuple[float, float], tuple[float, float]]:
    """Effective body (x, y) [m] of the fore and aft antennas.

    `heading_offset` is read as a rotation of the antenna pair about midship: the measured
    baseline direction is the geometric one plus the offset, and the antennas sit at the
    listed positions turned by it (identical to them when the offset is 0).
    """
    c, s = np.cos(layout.heading_offset), np.sin(layout.heading_offset)
    return tuple((px * c - py * s, px * s + py * c)  # type: ignore[return-value]
                 for px, py in (layout.gnss_fore, layout.gnss_aft))


def baseline_error(fore_x, fore_y, aft_x, aft_y, layout: SensorLayout) -> np.ndarray:
    """Measured fore-aft distance minus the nominal baseline [m], shape (N,)."""
    return np.hypot(fore_x - aft_x, fore_y - aft_y) - layout.gnss_baseline


def baseline_ok(error: np.ndarray, tolerance: float) -> np.ndarray:
    """True where |baseline error| < tolerance [m] (the paper keeps errors under 5 cm)."""
    with np.errstate(invalid="ignore"):
        return np.abs(error) < tolerance


def antenna_heading(fore_x, fore_y, aft_x, aft_y, layout: SensorLayout) -> np.ndarray:
    """Heading [rad] of the aft->fore vector minus the mounting offset, wrapped, shape (N,).

    The baseline direction in the body frame is atan2 of (fore - aft) body coordinates plus
    `heading_offset`; both are removed so the result is the bow direction.
    """
    bx = layout.gnss_fore[0] - layout.gnss_aft[0]
    by = layout.gnss_fore[1] - layout.gnss_aft[1]
    mount = np.arctan2(by, bx) + layout.heading_offset
    return np.arctan2(fore_y - aft_y, fore_x - aft_x) - mount


def midship_position(fore_x, fore_y, aft_x, aft_y, psi, layout: SensorLayout):
    """Midship (x0, y0) [m], mean of the two antennas each moved back by its body offset."""
    fore, aft = antenna_positions(layout)
    fx, fy = body_to_earth(psi, *fore)
    ax, ay = body_to_earth(psi, *aft)
    return 0.5 * (fore_x - fx + aft_x - ax), 0.5 * (fore_y - fy + aft_y - ay)
