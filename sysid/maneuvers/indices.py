"""Indices of standard maneuvers, each a pure function of a trajectory.

A `Track` starts at the execute (sample 0); positions are taken relative to it and
resolved along the approach course (the heading at the execute, "along") and across it
(positive to the side the ship turns to, "across"). Heading change is the unwrapped heading
minus the heading at the execute. Samples are equally spaced in time. Quantities at a given
heading change or at the stop are interpolated linearly between the samples around it;
heading peaks are refined by the parabola through the three samples around the largest.
An index that the trajectory does not reach (a turn that never reaches 180 deg, a ship that
never stops) is NaN.

Definitions (IMO MSC.137(76) and its explanatory notes, MSC/Circ.1053):

- advance [m]: distance along the approach course from the execute to the midship position
  where the heading has changed by 90 deg;
- transfer [m]: distance across the approach course at 90 deg heading change;
- tactical diameter [m]: distance across the approach course at 180 deg heading change;
- steady turning diameter [m]: distance between the midship positions half a turn apart at
  the end of the run (heading change of the last sample and 180 deg before it; needs at least
  360 deg of heading change): the diameter of the turn where it has settled;
- speed loss ratio [-]: 1 - U_steady / U_0, U = sqrt(u^2 + v_m^2), U_steady its mean over
  that last half turn, U_0 at the execute;
- initial turning distance [m]: distance run along the track until the heading has changed
  by 10 deg (with 10 deg rudder);
- first and second overshoot [deg]: in a zig-zag, the largest heading deviation beyond the
  check angle after the first (second) rudder reversal, before the next one;
- head reach [m]: distance along the approach course from the execute to where the ship's
  surge speed u reaches zero (crash stop); track reach [m]: distance along the track to
  the same point.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

DEG = math.pi / 180.0


@dataclass(frozen=True)
class Track:
    """A trajectory from the execute on: t (T,) [s]; x, y (T,) earth-frame midship position
    [m]; psi (T,) heading [rad]; u, v (T,) surge and midship sway speed [m/s]."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @classmethod
    def of(cls, t: np.ndarray, states: np.ndarray) -> "Track":
        """From times (T,) [s] and states (T, 6) = x, u, y, v, psi, r (`sysid.channel_names`)."""
        s = np.asarray(states, dtype=float)
        return cls(np.asarray(t, dtype=float), s[:, 0], s[:, 2], s[:, 4], s[:, 1], s[:, 3])

    def __len__(self) -> int:
        return len(self.t)

    @property
    def heading_change(self) -> np.ndarray:
        """(T,) unwrapped heading minus the heading at the execute [rad]."""
        return np.unwrap(self.psi) - self.psi[0]

    @property
    def turn_sign(self) -> float:
        """+1 if the ship turns to starboard (heading increasing), else -1: the sign of the
        largest heading change."""
        change = self.heading_change
        return 1.0 if change[np.argmax(np.abs(change))] >= 0 else -1.0

    @property
    def along(self) -> np.ndarray:
        """(T,) displacement along the approach course [m]."""
        c, s = math.cos(self.psi[0]), math.sin(self.psi[0])
        return (self.x - self.x[0]) * c + (self.y - self.y[0]) * s

    @property
    def across(self) -> np.ndarray:
        """(T,) displacement across the approach course toward the turn [m]."""
        c, s = math.cos(self.psi[0]), math.sin(self.psi[0])
        return self.turn_sign * (-(self.x - self.x[0]) * s + (self.y - self.y[0]) * c)

    @property
    def distance_run(self) -> np.ndarray:
        """(T,) distance along the track from the execute [m] (sum of chords)."""
        return np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(self.x), np.diff(self.y)))))

    @property
    def speed(self) -> np.ndarray:
        """(T,) U = sqrt(u^2 + v_m^2) [m/s]."""
        return np.hypot(self.u, self.v)


def first_crossing(level: np.ndarray, value: float) -> float:
    """Fractional sample index where `level` (T,) first reaches `value` from below, or NaN."""
    above = np.nonzero(level >= value)[0]
    if not len(above):
        return math.nan
    i = int(above[0])
    if i == 0:
        return 0.0
    lo, hi = level[i - 1], level[i]
    return i - 1 + (value - lo) / (hi - lo)


def at_index(values: np.ndarray, where: float) -> float:
    """`values` (T,) linearly interpolated at the fractional sample index `where` (NaN: NaN)."""
    if math.isnan(where):
        return math.nan
    i = min(int(math.floor(where)), len(values) - 2)
    frac = where - i
    return float(values[i] + frac * (values[i + 1] - values[i]))


def at_heading_change(track: Track, values: np.ndarray, angle_deg: float) -> float:
    """`values` (T,) where the heading has first changed by `angle_deg` toward the turn."""
    return at_index(values, first_crossing(track.turn_sign * track.heading_change, angle_deg * DEG))


def advance(track: Track) -> float:
    """Advance [m]: along the approach course at 90 deg heading change."""
    return at_heading_change(track, track.along, 90.0)


def transfer(track: Track) -> float:
    """Transfer [m]: across the approach course (toward the turn) at 90 deg heading change."""
    return at_heading_change(track, track.across, 90.0)


def tactical_diameter(track: Track) -> float:
    """Tactical diameter [m]: across the approach course at 180 deg heading change."""
    return at_heading_change(track, track.across, 180.0)


def _last_half_turn(track: Track) -> tuple[float, float] | None:
    """Fractional sample indices (start, end) of the last 180 deg of heading change, or None
    before 360 deg of heading change."""
    turned = track.turn_sign * track.heading_change
    total = float(turned[-1])
    if total < 2.0 * math.pi:
        return None
    return first_crossing(turned, total - math.pi), float(len(track) - 1)


def steady_turning_diameter(track: Track) -> float:
    """Steady turning diameter [m]: distance between the midship positions half a turn
    apart at the end of the run (NaN before 360 deg of heading change)."""
    span = _last_half_turn(track)
    if span is None:
        return math.nan
    (a, b) = span
    return math.hypot(at_index(track.x, b) - at_index(track.x, a), at_index(track.y, b) - at_index(track.y, a))


def speed_loss_ratio(track: Track) -> float:
    """Speed loss ratio [-]: 1 - U_steady / U_0, U_steady the mean speed over the last half
    turn, U_0 the speed at the execute (NaN before 360 deg of heading change)."""
    span = _last_half_turn(track)
    if span is None or not math.isfinite(span[0]):
        return math.nan
    first = int(math.ceil(span[0]))
    return float(1.0 - track.speed[first:].mean() / track.speed[0])


def initial_turning_distance(track: Track, heading_deg: float = 10.0) -> float:
    """Initial turning distance [m]: distance run along the track until the heading has
    changed by `heading_deg` to either side (IMO: 10 deg, with 10 deg rudder)."""
    return at_index(track.distance_run, first_crossing(np.abs(track.heading_change), heading_deg * DEG))


def _peak(values: np.ndarray, lo: int, hi: int) -> float:
    """Largest of values[lo:hi], refined by the parabola through its neighbours; NaN when it
    lies on the last sample of the whole series (the peak not yet reached)."""
    seg = values[lo:hi]
    if not len(seg):
        return math.nan
    j = lo + int(np.argmax(seg))
    if j == len(values) - 1:
        return math.nan
    if j == 0:
        return float(values[0])
    y0, y1, y2 = values[j - 1], values[j], values[j + 1]
    curvature = y0 - 2.0 * y1 + y2
    if curvature >= 0.0:
        return float(y1)
    offset = 0.5 * (y0 - y2) / curvature
    return float(y1 - 0.25 * (y0 - y2) * offset)


def rudder_reversals(rudder: np.ndarray, threshold: float = 0.5 * DEG) -> tuple[float, list[int]]:
    """(sign of the first rudder order, sample indices where the rudder changes side) of a
    rudder series (T,) [rad]; angles within `threshold` of amidships do not count."""
    side = np.sign(np.where(np.abs(rudder) > threshold, rudder, 0.0))
    nonzero = np.nonzero(side)[0]
    if not len(nonzero):
        return 0.0, []
    reversals, current = [], side[nonzero[0]]
    for i in nonzero[1:]:
        if side[i] != current:
            reversals.append(int(i))
            current = side[i]
    return float(side[nonzero[0]]), reversals


def heading_reversals(track: Track, check_deg: float) -> tuple[float, list[int]]:
    """(sign of the first turn, sample indices where the heading deviation first reaches the
    check angle on alternating sides): the reversals of a zig-zag ruled by its heading."""
    change = track.heading_change / DEG
    over = np.nonzero(np.abs(change) >= check_deg)[0]
    if not len(over):
        return 0.0, []
    first = float(np.sign(change[over[0]]))
    reversals, side, k = [], first, int(over[0])
    while True:
        reversals.append(k)
        side = -side
        later = np.nonzero(side * change[k:] >= check_deg)[0]
        if not len(later):
            return first, reversals
        k += int(later[0])


def zigzag_overshoots(track: Track, check_deg: float, rudder: np.ndarray | None = None) -> tuple[float, float]:
    """(first, second) overshoot angle [deg] of a zig-zag with check angle `check_deg` [deg].

    The reversals are the rudder's changes of side when `rudder` (T,) [rad] is given (a
    recorded or open-loop run), else the samples where the heading deviation reaches the
    check angle on alternating sides. Overshoot k is the peak of the heading deviation
    toward the side of the k-th excursion (first: the first order's side) between reversal
    k and reversal k + 1 (or the end), minus the check angle; NaN when the run ends first.
    """
    first, reversals = rudder_reversals(rudder) if rudder is not None else heading_reversals(track, check_deg)
    change = track.heading_change / DEG
    out = []
    for k in (0, 1):
        if first == 0.0 or len(reversals) <= k:
            out.append(math.nan)
            continue
        side = first if k == 0 else -first
        end = reversals[k + 1] if len(reversals) > k + 1 else len(change)
        out.append(_peak(side * change, reversals[k], end) - check_deg)
    return out[0], out[1]


def stop_index(track: Track) -> float:
    """Fractional sample index where the surge speed u first reaches zero, or NaN."""
    return first_crossing(-track.u, 0.0)


def head_reach(track: Track) -> float:
    """Head reach [m]: along the approach course from the execute to where u reaches zero."""
    return at_index(track.along, stop_index(track))


def track_reach(track: Track) -> float:
    """Track reach [m]: along the track from the execute to where u reaches zero."""
    return at_index(track.distance_run, stop_index(track))


@dataclass(frozen=True)
class ManeuverIndices:
    """The indices of one maneuver (NaN where not applicable or not reached); units in the
    names: m, deg, or a ratio."""

    advance_m: float = math.nan
    transfer_m: float = math.nan
    tactical_diameter_m: float = math.nan
    steady_turning_diameter_m: float = math.nan
    speed_loss_ratio: float = math.nan
    initial_turning_distance_m: float = math.nan
    first_overshoot_deg: float = math.nan
    second_overshoot_deg: float = math.nan
    head_reach_m: float = math.nan
    track_reach_m: float = math.nan

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


INDEX_COLUMNS: tuple[str, ...] = tuple(f.name for f in fields(ManeuverIndices))
# which indices belong to which kind of maneuver (the others stay NaN)
KIND_INDICES = {
    "turning": ("advance_m", "transfer_m", "tactical_diameter_m", "steady_turning_diameter_m",
                "speed_loss_ratio", "initial_turning_distance_m"),
    "zigzag": ("initial_turning_distance_m", "first_overshoot_deg", "second_overshoot_deg"),
    "crash_stop": ("head_reach_m", "track_reach_m"),
}


def maneuver_indices(maneuver, track: Track, rudder: np.ndarray | None = None) -> ManeuverIndices:
    """The indices of `maneuver` (a `sysid.maneuvers.base` spec) on `track`; `rudder` (T,)
    [rad] rules a zig-zag's reversals when given. The initial turning distance is given for
    10 deg rudder only (IMO's initial turning ability)."""
    kind = maneuver.kind
    if kind == "turning":
        out = dict(advance_m=advance(track), transfer_m=transfer(track), tactical_diameter_m=tactical_diameter(track),
                   steady_turning_diameter_m=steady_turning_diameter(track), speed_loss_ratio=speed_loss_ratio(track))
    elif kind == "zigzag":
        first, second = zigzag_overshoots(track, maneuver.check_deg, rudder)
        out = dict(first_overshoot_deg=first, second_overshoot_deg=second)
    else:
        out = dict(head_reach_m=head_reach(track), track_reach_m=track_reach(track))
    if kind in ("turning", "zigzag") and math.isclose(maneuver.rudder_deg, 10.0):
        out["initial_turning_distance_m"] = initial_turning_distance(track)
    return ManeuverIndices(**out)
