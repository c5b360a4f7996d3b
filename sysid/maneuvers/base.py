"""Standard maneuvers (IMO Resolution MSC.137(76)) as typed specifications, the conditions
they are run in, and what a simulation of one gives.

Signs follow `sysid.channel_names`: a positive rudder angle turns the ship to starboard, the heading
psi runs from x0 toward y0, and a starboard maneuver orders starboard (positive) rudder
first. Time is counted from the execute (the first rudder or engine order), where the ship
is at the origin, heading 0 (along x0), in straight running at the approach speed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Union

import numpy as np

from sysid.config.choices import Choice, Method
from sysid.errors import SysidError
from sysid.maneuvers.indices import ManeuverIndices


class ManeuverError(SysidError):
    """A maneuver cannot be set up: a bad option, no approach speed, no straight running."""


class Side(Choice):
    """Side of the first rudder order."""

    STARBOARD = "starboard"
    PORT = "port"

    @property
    def sign(self) -> float:
        """+1 for starboard (positive rudder), -1 for port."""
        return 1.0 if self is Side.STARBOARD else -1.0

    @classmethod
    def of(cls, value: "Side | str") -> "Side":
        """`Side.parse` with `ManeuverError` (one line) for anything else."""
        try:
            return cls.parse(value, "side")
        except ValueError as exc:
            raise ManeuverError(str(exc)) from None


def check_number(what: str, value: float, unit: str, positive: bool = False, low: float | None = None) -> float:
    """`value` as a float, or `ManeuverError` (one line) unless finite, > 0 if `positive`,
    >= `low` if given."""
    value = float(value)
    if not math.isfinite(value) or (positive and value <= 0.0) or (low is not None and value < low):
        need = " and > 0" if positive else (f" and >= {low:g}" if low is not None else "")
        raise ManeuverError(f"{what} {value:g} {unit}: must be a finite number{need}")
    return value


def _number(value: float) -> str:
    """12 -> "12", 12.5 -> "12.5" (names of maneuvers)."""
    return f"{value:g}"


def _check_angle(what: str, value: float, high: float = 90.0) -> float:
    value = float(value)
    if not (math.isfinite(value) and 0.0 < value <= high):
        raise ManeuverError(f"{what} {value:g} deg: must be a finite angle in (0, {high:g}] deg")
    return value


@dataclass(frozen=True)
class TurningCircle:
    """Rudder `rudder_deg` [deg] to `side` at the execute, held (IMO turning test: 35 deg)."""

    rudder_deg: float = 35.0
    side: Side = Side.STARBOARD
    kind: ClassVar[str] = "turning"

    def __post_init__(self):
        object.__setattr__(self, "rudder_deg", _check_angle("turning rudder angle", self.rudder_deg))
        object.__setattr__(self, "side", Side.of(self.side))

    @property
    def name(self) -> str:
        """``turning_35_starboard``."""
        return f"turning_{_number(self.rudder_deg)}_{self.side.value}"


@dataclass(frozen=True)
class ZigZag:
    """Zig-zag `rudder_deg`/`check_deg` [deg]: rudder to `side`; whenever the heading
    deviation from the approach course reaches the check angle on the side the rudder is
    turning to, the rudder is reversed (IMO: 10/10 and 20/20)."""

    rudder_deg: float = 10.0
    check_deg: float = 10.0
    side: Side = Side.STARBOARD
    kind: ClassVar[str] = "zigzag"

    def __post_init__(self):
        object.__setattr__(self, "rudder_deg", _check_angle("zig-zag rudder angle", self.rudder_deg))
        object.__setattr__(self, "check_deg", _check_angle("zig-zag check angle", self.check_deg, 180.0))
        object.__setattr__(self, "side", Side.of(self.side))

    @property
    def name(self) -> str:
        """``zigzag_10_10_starboard``."""
        return f"zigzag_{_number(self.rudder_deg)}_{_number(self.check_deg)}_{self.side.value}"


@dataclass(frozen=True)
class CrashStop:
    """Propeller from the approach revolutions to `astern_rps` [rps] (default: minus the
    approach revolutions) over `reversal_s` [s] (0: at once), rudder amidships."""

    astern_rps: float | None = None
    reversal_s: float = 0.0
    kind: ClassVar[str] = "crash_stop"

    def __post_init__(self):
        if self.astern_rps is not None and not (math.isfinite(self.astern_rps) and self.astern_rps <= 0.0):
            raise ManeuverError(f"crash stop astern revolutions {self.astern_rps:g} rps: must be finite and <= 0")
        if not (math.isfinite(self.reversal_s) and self.reversal_s >= 0.0):
            raise ManeuverError(f"crash stop reversal time {self.reversal_s:g} s: must be finite and >= 0")

    @property
    def name(self) -> str:
        return "crash_stop"


Maneuver = Union[TurningCircle, ZigZag, CrashStop]


def imo_maneuvers(sides: tuple[Side, ...] = (Side.STARBOARD, Side.PORT)) -> list[Maneuver]:
    """The maneuvers IMO MSC.137(76) asks for: 35 deg turning, 10/10 and 20/20 zig-zag
    on each of `sides`, and a crash stop."""
    out: list[Maneuver] = [TurningCircle(35.0, s) for s in sides]
    out += [ZigZag(a, a, s) for a in (10.0, 20.0) for s in sides]
    return out + [CrashStop()]


@dataclass(frozen=True)
class Conditions:
    """How every maneuver of one simulation is run.

    speed : approach speed U0 [m/s] (surge; straight running, v = r = 0 at the execute).
    rps : approach propeller revolutions [rps].
    rudder_rate : steering gear rate [deg/s].
    dt : integration step [s]; the rudder held over a step is its mean over the step.
    duration : simulated time after the execute [s].
    wind_speed : true wind speed [m/s]; wind_direction : direction it comes from [rad],
        from x0 toward y0.
    method : integration rule (`Method`).
    """

    speed: float
    rps: float
    rudder_rate: float
    dt: float = 0.1
    duration: float = 600.0
    wind_speed: float = 0.0
    wind_direction: float = 0.0
    method: Method = Method.RK4

    def __post_init__(self):
        try:
            object.__setattr__(self, "method", Method.parse(self.method, "integrator"))
        except ValueError as exc:
            raise ManeuverError(str(exc)) from None
        for what, value, unit, positive in (
                ("approach speed", self.speed, "m/s", True), ("propeller revolutions", self.rps, "rps", False),
                ("rudder rate", self.rudder_rate, "deg/s", True), ("time step", self.dt, "s", True),
                ("duration", self.duration, "s", True), ("wind direction", self.wind_direction, "rad", False)):
            check_number(what, value, unit, positive)
        check_number("wind speed", self.wind_speed, "m/s", low=0.0)
        if self.duration < 2 * self.dt:
            raise ManeuverError(f"duration {self.duration:g} s: must hold at least two steps of {self.dt:g} s")

    @property
    def steps(self) -> int:
        """Number of integration steps (the duration rounded to whole steps)."""
        return int(round(self.duration / self.dt))


@dataclass
class ManeuverResult:
    """One simulated (or recorded) maneuver.

    t : (T,) time from the execute [s]; states : (T, 6) x, u, y, v, psi, r (`sysid.channel_names`);
    rudder : (T,) rudder angle at t [rad]; inputs : (T, 4) the inputs held over the step
    from t (n_prop [rps], delta_rudder [rad] mean over the step, wind speed [m/s], wind
    direction [rad]; the last row repeats the one before); indices : `ManeuverIndices`;
    gate_off_share : share of steps with the kNN gate off at the step's start (None without
    a gate); model : label of the model that ran it; diverged_at_s : time from the execute
    [s] at which the simulation diverged (`sysid.maneuvers.simulate.first_divergence`; None:
    it did not), divergence : why, in words; gate_on : (T,) the kNN gate's decision at each
    step's start (1 on: the FNN acts; 0 off: the physics MMG alone; NaN on the last row,
    which starts no step), knn_distance : (T,) d_kNN [feature units] of the state at t with
    the inputs held from t, knn_threshold : the gate's threshold delta_kNN (off where
    d_kNN exceeds it); all three None without a gate.
    """

    maneuver: Maneuver
    t: np.ndarray
    states: np.ndarray
    rudder: np.ndarray
    inputs: np.ndarray
    indices: ManeuverIndices | None = None
    gate_off_share: float | None = None
    model: str = ""
    members: list["ManeuverResult"] = field(default_factory=list)
    diverged_at_s: float | None = None
    divergence: str = ""
    gate_on: np.ndarray | None = None
    knn_distance: np.ndarray | None = None
    knn_threshold: float | None = None

    @property
    def diverged(self) -> bool:
        return self.diverged_at_s is not None

    @property
    def knn_distance_max(self) -> float | None:
        """The largest d_kNN along the maneuver, its last row too (NaN rows of a diverged
        run skipped; NaN when every row is); None without a gate."""
        if self.knn_distance is None:
            return None
        finite = self.knn_distance[~np.isnan(self.knn_distance)]
        return float(finite.max()) if finite.size else math.nan
