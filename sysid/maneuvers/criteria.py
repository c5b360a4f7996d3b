"""The IMO Standards for Ship Manoeuvrability (Resolution MSC.137(76)) applied to indices.

Criteria (L: length between perpendiculars, U: approach speed; at full scale):

- turning ability (35 deg turning test): advance <= 4.5 L, tactical diameter <= 5 L;
- initial turning ability (10 deg rudder): distance run until 10 deg of heading change
  <= 2.5 L;
- yaw checking, 10/10 zig-zag: first overshoot <= 10 deg if L/U < 10 s, <= 20 deg if
  L/U >= 30 s, else <= (5 + 0.5 L/U) deg; second overshoot <= 25 deg, 40 deg, or
  (17.5 + 0.75 L/U) deg likewise; 20/20 zig-zag: first overshoot <= 25 deg;
- stopping ability (crash stop): track reach <= 15 L.

Lengths enter as ratios to L, which Froude scaling keeps (model and full scale alike). L/U
is a time and does not scale that way: at full scale it is the model's L/U times the
square root of the scale factor. Without a scale factor (ship file ``[maneuvering]
scale``) the 10/10 overshoot limits, the only ones that need L/U, are not assessed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sysid.maneuvers.indices import ManeuverIndices


@dataclass(frozen=True)
class Criterion:
    """One index of one maneuver against its IMO limit.

    maneuver : maneuver name; index : index column (``advance_m``); value : the index [m,
    deg]; limit : its IMO limit in the same unit (NaN where not assessed); ratio : value /
    L for lengths, value in deg for angles; limit_ratio : the limit in those terms; met :
    True, False, or None where not assessed or the index is missing; rule : the criterion
    in words.
    """

    maneuver: str
    index: str
    value: float
    limit: float
    ratio: float
    limit_ratio: float
    met: bool | None
    rule: str


def full_scale_L_over_U(L: float, U: float, scale: float | None) -> float | None:
    """L/U [s] at full scale from the model's L [m] and U [m/s] and the scale factor (full
    over model length); None without a scale factor."""
    if scale is None:
        return None
    return L / U * math.sqrt(scale)


def overshoot_limits_10_10(L_over_U: float) -> tuple[float, float]:
    """IMO limits [deg] of the first and second overshoot of the 10/10 zig-zag for a
    full-scale L/U [s]."""
    if L_over_U < 10.0:
        return 10.0, 25.0
    if L_over_U >= 30.0:
        return 20.0, 40.0
    return 5.0 + 0.5 * L_over_U, 17.5 + 0.75 * L_over_U


def _length(maneuver: str, index: str, value: float, L: float, factor: float, rule: str) -> Criterion:
    limit = factor * L
    met = None if math.isnan(value) else bool(value <= limit)
    return Criterion(maneuver, index, value, limit, value / L, factor, met, rule)


def _angle(maneuver: str, index: str, value: float, limit: float | None, rule: str) -> Criterion:
    if limit is None:
        return Criterion(maneuver, index, value, math.nan, value, math.nan, None, rule)
    met = None if math.isnan(value) else bool(value <= limit)
    return Criterion(maneuver, index, value, limit, value, limit, met, rule)


def criteria_for(maneuver, indices: ManeuverIndices, L: float, U: float, scale: float | None) -> list[Criterion]:
    """The IMO criteria that apply to `maneuver` (a `sysid.maneuvers.base` spec) with these
    `indices`, for a ship of length L [m] approaching at U [m/s] and `scale` (or None)."""
    name, kind = maneuver.name, maneuver.kind
    out: list[Criterion] = []
    if kind == "turning" and math.isclose(maneuver.rudder_deg, 35.0):
        out.append(_length(name, "advance_m", indices.advance_m, L, 4.5, "advance <= 4.5 L"))
        out.append(_length(name, "tactical_diameter_m", indices.tactical_diameter_m, L, 5.0,
                           "tactical diameter <= 5 L"))
    if kind in ("turning", "zigzag") and math.isclose(maneuver.rudder_deg, 10.0):
        out.append(_length(name, "initial_turning_distance_m", indices.initial_turning_distance_m, L, 2.5,
                           "distance run to 10 deg heading change with 10 deg rudder <= 2.5 L"))
    if kind == "zigzag" and math.isclose(maneuver.rudder_deg, 10.0) and math.isclose(maneuver.check_deg, 10.0):
        lu = full_scale_L_over_U(L, U, scale)
        if lu is None:
            why = " (not assessed: the limit needs L/U at full scale; give [maneuvering] scale in the ship file)"
            out.append(_angle(name, "first_overshoot_deg", indices.first_overshoot_deg, None,
                              "first overshoot <= f(L/U)" + why))
            out.append(_angle(name, "second_overshoot_deg", indices.second_overshoot_deg, None,
                              "second overshoot <= g(L/U)" + why))
        else:
            first, second = overshoot_limits_10_10(lu)
            out.append(_angle(name, "first_overshoot_deg", indices.first_overshoot_deg, first,
                              f"first overshoot <= {first:.1f} deg (L/U = {lu:.1f} s at full scale)"))
            out.append(_angle(name, "second_overshoot_deg", indices.second_overshoot_deg, second,
                              f"second overshoot <= {second:.1f} deg (L/U = {lu:.1f} s at full scale)"))
    if kind == "zigzag" and math.isclose(maneuver.rudder_deg, 20.0) and math.isclose(maneuver.check_deg, 20.0):
        out.append(_angle(name, "first_overshoot_deg", indices.first_overshoot_deg, 25.0,
                          "first overshoot <= 25 deg"))
    if kind == "crash_stop":
        out.append(_length(name, "track_reach_m", indices.track_reach_m, L, 15.0, "track reach <= 15 L"))
    return out
