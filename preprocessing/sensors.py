"""Sensor layout on the hull: where the antennas, anemometers and gyro sit.

Body frame from midship, x to the bow, y to starboard, metres. The layout is a value
object; `sysid.mmg.ship` builds one from a ship definition's ``[sensors]`` table, so this
package never imports `sysid`.
"""
from __future__ import annotations

from dataclasses import dataclass
import math


@dataclass(frozen=True)
class SensorLayout:
    """Body-frame positions of the onboard sensors.

    Attributes
    ----------
    gnss_fore, gnss_aft : (x, y) [m] of the fore and aft GNSS antennas.
    gnss_baseline : nominal fore-aft antenna distance [m].
    heading_offset : a turn [rad] of the antenna pair about midship beyond the listed
        positions (clockwise seen from above): the aft->fore baseline points at the
        positions' own direction plus it, and the antennas sit at the positions turned by it.
        The positions' direction (antennas off the centreline or not parallel to it) needs
        no offset.
    anemometer_1, anemometer_2 : (x, y) [m] of the two anemometers.
    fog : (x, y) [m] of the fibre-optic gyro (its position does not affect a yaw rate).
    """

    gnss_fore: tuple[float, float] = (1.20, 0.0)
    gnss_aft: tuple[float, float] = (-1.20, 0.0)
    gnss_baseline: float = 2.40
    heading_offset: float = 0.0
    anemometer_1: tuple[float, float] = (0.90, 0.0)
    anemometer_2: tuple[float, float] = (-0.60, 0.0)
    fog: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("gnss_fore", "gnss_aft", "anemometer_1", "anemometer_2", "fog"):
            value = getattr(self, name)
            if len(value) != 2 or not all(math.isfinite(float(c)) for c in value):
                raise ValueError(f"sensors.{name}: expected [x, y] in metres, got {value!r}")
            object.__setattr__(self, name, (float(value[0]), float(value[1])))
        if not (self.gnss_baseline > 0.0 and math.isfinite(self.gnss_baseline)):
            raise ValueError(f"sensors.gnss_baseline: must be > 0 m, got {self.gnss_baseline!r}")
        if not math.isfinite(self.heading_offset) or abs(self.heading_offset) > 2 * math.pi:
            raise ValueError(
                f"sensors.heading_offset: must be a finite angle in radians, got {self.heading_offset!r}"
            )
        geometric = math.dist(self.gnss_fore, self.gnss_aft)
        if abs(geometric - self.gnss_baseline) > 0.05:
            raise ValueError(
                f"sensors.gnss_baseline: {self.gnss_baseline} m disagrees with the antenna "
                f"positions ({geometric:.3f} m apart)"
            )
