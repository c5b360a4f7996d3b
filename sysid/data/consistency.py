"""A log checked against its own GNSS track (docs: Input formats, the track check).

Every processed log carries the midship track (x north, y east [m]) and the heading psi
[rad] beside the body velocities u, v_m [m/s] and the yaw rate r [rad/s]. The track's
velocity, by central differences over about 1 s and turned into the body frame by psi,

    u_trk =  dx/dt cos psi + dy/dt sin psi        [m/s]
    v_trk = -dx/dt sin psi + dy/dt cos psi        [m/s]
    r_trk =  d(unwrap psi)/dt                     [rad/s]

must be the logged u, v and r. Per channel the scale factor k (log = k x track) is
fitted by least squares of the track's rate on the log's (k = 1 / b, b = sum(log trk) /
sum(log^2)), twice, the second time without samples whose residual is beyond 4 MADs
(GNSS jumps and frozen stretches), with the correlation of the kept samples. A channel in
the wrong unit shows the ratio of the units (knots under an m/s name: k = 1.94, deg/s
under rad/s: 57.3), a flipped sign k = -1, time in ms: every channel k = 1000, swapped u
and v a poor fit of each that is good crosswise.

The bounds (`FACTOR_CLEAR`, `FACTOR_MARGINAL`, `CORRELATION_CLEAR`, `CORRELATION_MARGINAL`)
lie well outside the spread measured on the 39 FRT-DS-ESSO logs (u: k 0.985-1.004,
correlation >= 0.994; v: k 1.007-1.32, >= 0.969; r: k 0.977-1.017, >= 0.959; docs).
"""
from __future__ import annotations

import enum
import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from sysid.data.columns import QUANTITY, UNITS, ColumnMap
from sysid.data.rudder_sign import EXCITED_ANGLE, RudderResponse, RudderSign, rudder_response
from sysid.errors import DataError

# per channel, k outside [1/b, b] (or k < 0): a clear mismatch (b = FACTOR_CLEAR), a marginal one
# (b = FACTOR_MARGINAL). The 39 FRT-DS-ESSO logs: u 0.985-1.004, v 1.007-1.32, r 0.977-1.017
FACTOR_CLEAR = {"u": 1.25, "v": 1.7, "r": 1.25}
FACTOR_MARGINAL = {"u": 1.08, "v": 1.45, "r": 1.08}
# a correlation below these (with enough motion): a clear / marginal mismatch. The 39 logs: u >= 0.994,
# v >= 0.969, r >= 0.959
CORRELATION_CLEAR = 0.5
CORRELATION_MARGINAL = 0.8
# RMS of the track's rate below which a channel is too still to check
MIN_MOTION = {"u": 0.03, "v": 0.01, "r": 0.003}  # m/s, m/s, rad/s
SPAN_S = 1.0  # half-width of the central differences [s]
MIN_SAMPLES = 10    # samples a channel's factor needs before it is graded
MAX_PERIOD_S = 2.0  # sampled more coarsely, central differences of a turn's heading and track are biased
CHECKED = ("u", "v", "r")
_WHAT = {"u": "the track's speed", "v": "the track's sway velocity", "r": "the heading's rate dpsi/dt"}


class Verdict(enum.Enum):
    """How a channel agrees with the track."""

    CONSISTENT = "ok"
    MARGINAL = "marginal"
    MISMATCH = "mismatch"
    UNCHECKED = "not checked"
    USER_CHECKED = "sign checked by the user"   # the rudder read as reversed, named in [data] rudder_sign_checked


@dataclass(frozen=True)
class ChannelCheck:
    """One channel against the track.

    Attributes
    ----------
    channel : "u", "v", "r", "t" (every rate off by one factor: the time's unit), or
        "delta_rudder" (the rudder's sign from the yaw response, `sysid.data.rudder_sign`).
    factor : k in log = k x track [-] (NaN when unchecked); for delta_rudder +1 or -1, the
        sign of the yaw response against sysid's convention.
    correlation : Pearson correlation of log and track on the kept samples [-]; for
        delta_rudder the partial correlation of dr/dt with the rudder term.
    samples : samples the fit kept.
    verdict : `Verdict`.
    hint : the likely cause ("knots under an m/s name?"), "" when none is known.
    """

    channel: str
    factor: float
    correlation: float
    samples: int
    verdict: Verdict
    hint: str = ""

    def sentence(self) -> str:
        """"u is 1.94 x the track's speed (correlation 1.00): knots under an m/s name?"."""
        if self.channel == "delta_rudder":
            head = ("delta_rudder: the rudder sign looks reversed: positive rudder turns the ship to port here"
                    if self.factor < 0 else
                    f"delta_rudder turns the ship to starboard (partial correlation {self.correlation:.2f})")
        elif self.channel == "t":
            head = f"t: every rate is {self.factor:.3g} x the track's"
        elif self.channel == "uv":
            head = f"u and v are the track's v and u ({self.factor:.3g} x)"
        elif self.channel == "psi" and self.factor < 0:
            head = "psi turns against r and does not turn u, v onto the track"
        elif self.channel == "psi":
            head = f"psi changes {self.factor:.3g} x as fast as r says"
        elif not np.isfinite(self.factor) or abs(self.correlation) < CORRELATION_CLEAR:
            head = (f"{self.channel} does not follow {_WHAT[self.channel]} (correlation {self.correlation:.2f}, "
                    f"factor {self.factor:.3g})")
        else:
            head = f"{self.channel} is {self.factor:.3g} x {_WHAT[self.channel]} (correlation {self.correlation:.2f})"
        return f"{head}: {self.hint}" if self.hint else head


@dataclass(frozen=True)
class TrackCheck:
    """A log's channels against its track: `channels`, or `reason` why it was not possible."""

    path: Path
    channels: tuple[ChannelCheck, ...] = ()
    reason: str = ""

    @property
    def checked(self) -> bool:
        return not self.reason

    def worst(self, verdict: Verdict) -> tuple[ChannelCheck, ...]:
        return tuple(c for c in self.channels if c.verdict is verdict)

    def rudder_sign_checked(self) -> TrackCheck:
        """This check with a rudder read as reversed (clearly or marginally) marked
        `Verdict.USER_CHECKED`: the user has checked this log's rudder sign (``[data]
        rudder_sign_checked``), so it is read as it is."""
        mark = (Verdict.MISMATCH, Verdict.MARGINAL)
        return replace(self, channels=tuple(
            replace(c, verdict=Verdict.USER_CHECKED, hint="named in [data] rudder_sign_checked")
            if c.channel == "delta_rudder" and c.verdict in mark else c
            for c in self.channels))

    @property
    def rudder_overridden(self) -> ChannelCheck | None:
        """The rudder's check the user overrode (`rudder_sign_checked`), else None."""
        return next((c for c in self.channels if c.verdict is Verdict.USER_CHECKED), None)

    def lines(self, verdict: Verdict) -> list[str]:
        """One line per channel with `verdict`, naming the file, the channel and the factor."""
        return [f"{self.path}: {c.sentence()}" for c in self.worst(verdict)]


def central_rate(t: np.ndarray, q: np.ndarray, span: int) -> np.ndarray:
    """(N - 2 span,) dq/dt by central differences over `span` samples either side."""
    return (q[2 * span:] - q[:-2 * span]) / (t[2 * span:] - t[:-2 * span])


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """sum a_i b_i of two (N,) arrays on this thread (numpy's own loop: the BLAS ``a @ b`` of
    a long log wakes its thread pool, milliseconds a call on a busy machine, and its sum's
    round-off depends on the pool's size)."""
    return float(np.einsum("i,i->", a, b))


def scale_factor(log: np.ndarray, track: np.ndarray) -> tuple[float, float, int]:
    """(k, correlation, samples kept): log = k x track, from the least-squares slope of the
    track on the log refitted without residuals beyond 4 MADs (at least 0.1 % of the track's
    RMS, so a noise-free log keeps its samples). k = 0 for a log that is
    zero where the track moves, inf for a log that moves where the track does not."""
    keep = np.isfinite(log) & np.isfinite(track)
    for _ in range(2):
        a, b = log[keep], track[keep]
        power = _dot(a, a)
        if power <= 0.0:
            return 0.0, 0.0, int(keep.sum())
        slope = _dot(a, b) / power
        residual = track - slope * log
        mad = float(np.median(np.abs(residual[keep] - np.median(residual[keep]))))
        floor = 1e-3 * float(np.sqrt(np.mean(b**2)))   # a noise-free log: MAD near 0
        keep = keep & (np.abs(residual) <= max(4.0 * 1.4826 * mad, floor) + 1e-12)
    a, b = log[keep], track[keep]
    power = _dot(a, a)
    slope = _dot(a, b) / power if power > 0 else 0.0
    corr = float(np.corrcoef(a, b)[0, 1]) if len(a) > 2 and a.std() > 0 and b.std() > 0 else 0.0
    return (1.0 / slope if slope != 0 else np.inf), corr, int(keep.sum())


def unit_hint(channel: str, factor: float, declared: str) -> str:
    """The unit whose values under the `declared` unit's name are `factor` x too large
    (within 4 %), as "knots under an m/s name?"; "" when none is."""
    if factor < 0:
        rest = unit_hint(channel, -factor, declared)
        side = {"u": "astern positive", "v": "positive to port", "r": "positive to port"}.get(channel, "")
        return "a flipped sign" + (f" ({side})" if side else "") + (f" and {rest}" if rest else "") + "?"
    quantity = QUANTITY.get(channel, "")
    table = UNITS.get(quantity, {})
    if declared.strip().lower() not in table or not np.isfinite(factor) or factor <= 0:
        return ""
    to_si = table[declared.strip().lower()]
    for name, value in table.items():
        if value != to_si and abs(np.log(to_si / value / factor)) < 0.04:
            article = "an" if declared[0] in "aeiou" or declared in ("m/s", "m", "s", "ms", "h", "rps", "rpm") else "a"
            return f"{name} under {article} {declared} name?"
    return ""


def _grade(channel: str, factor: float, corr: float) -> Verdict:
    clear, marginal = FACTOR_CLEAR[channel], FACTOR_MARGINAL[channel]
    if not np.isfinite(factor) or factor <= 0 or corr < CORRELATION_CLEAR or not 1.0 / clear <= factor <= clear:
        return Verdict.MISMATCH
    if corr < CORRELATION_MARGINAL or not 1.0 / marginal <= factor <= marginal:
        return Verdict.MARGINAL
    return Verdict.CONSISTENT


def check_track(path: str | Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, psi: np.ndarray,
                u: np.ndarray, v: np.ndarray, r: np.ndarray, columns: ColumnMap | None = None,
                delta: np.ndarray | None = None) -> TrackCheck:
    """A log's u, v_m [m/s] and r [rad/s] against the rates of its own midship track x, y
    [m] (earth frame, north and east) and heading psi [rad], all (N,) at times t (N,) [s]
    as read (SI by `columns`, whose declared units name the likely cause); with the rudder
    angle `delta` [rad] (N,), its sign read from the yaw response too (`check_rudder`),
    unless r itself disagrees with the heading. Cost O(N).

    A log sampled more coarsely than every `MAX_PERIOD_S` is left unchecked (a turn's heading
    and track sampled this coarsely bias central differences), unless its time unit is off:
    one factor in every rate is still told apart."""
    path = Path(path)
    columns = columns if columns is not None else ColumnMap()
    steps = np.diff(t)
    period = float(np.median(steps)) if len(steps) else 0.0
    result = _against_track(path, t, x, y, psi, u, v, r, columns, period)
    if period > MAX_PERIOD_S and not any(c.channel == "t" for c in result.channels):
        return TrackCheck(path, reason=f"sampled every {period:g} s: too coarse to check u, v and r against "
                                       f"the track's central differences (at most {MAX_PERIOD_S:g} s)")
    if delta is None or any(c.channel in ("r", "t", "psi") and c.verdict is Verdict.MISMATCH for c in result.channels):
        return result  # r's own fault is named first; the rudder is read once r is right
    rudder = check_rudder(t, u, r, delta, columns)
    if rudder.verdict is Verdict.UNCHECKED:
        return result
    return TrackCheck(path, result.channels + (rudder,), result.reason)


def check_rudder(t: np.ndarray, u: np.ndarray, r: np.ndarray, delta: np.ndarray,
                 columns: ColumnMap | None = None) -> ChannelCheck:
    """The rudder's sign (`sysid.data.rudder_sign.rudder_response`) of (N,) t [s], u [m/s],
    r [rad/s] and delta [rad] as a channel check: a clearly reversed sign a mismatch, a weak
    negative relation marginal, too little rudder going ahead unchecked."""
    columns = columns if columns is not None else ColumnMap()
    found: RudderResponse = rudder_response(t, u, r, delta)
    if found.sign is RudderSign.NOT_READ:
        return ChannelCheck("delta_rudder", np.nan, np.nan, found.samples, Verdict.UNCHECKED,
                            f"{found.excited_s:.0f} s of |rudder| >= {np.degrees(EXCITED_ANGLE):.0f} deg going ahead: "
                            "too little")
    if found.sign is RudderSign.UNCLEAR:
        return ChannelCheck("delta_rudder", np.nan, found.correlation, found.samples, Verdict.UNCHECKED,
                            "dr/dt does not follow the rudder")
    if found.sign is RudderSign.STARBOARD:
        return ChannelCheck("delta_rudder", 1.0, found.correlation, found.samples, Verdict.CONSISTENT)
    fix = (f"partial correlation {found.correlation:.2f} of dr/dt with the rudder over {found.excited_s:.0f} s of "
           f"rudder going ahead; negate {columns.describe('delta_rudder')} in the log (sysid's positive rudder "
           "turns the ship to starboard; [data.columns] converts units, not signs)")
    verdict = Verdict.MISMATCH if found.sign is RudderSign.PORT_CLEAR else Verdict.MARGINAL
    return ChannelCheck("delta_rudder", -1.0, found.correlation, found.samples, verdict, fix)


def _against_track(path: Path, t: np.ndarray, x: np.ndarray, y: np.ndarray, psi: np.ndarray, u: np.ndarray,
                   v: np.ndarray, r: np.ndarray, columns: ColumnMap, period: float) -> TrackCheck:
    """`check_track` at any sampling `period` [s]: each channel graded against the track's
    central differences over `SPAN_S`, then the fault that explains them named."""
    if min(np.ptp(x), np.ptp(y)) == 0.0 or np.ptp(psi) == 0.0:
        missing = [name for name, q in (("x", x), ("y", y), ("psi", psi)) if np.ptp(q) == 0.0]
        return TrackCheck(path, reason=f"{', '.join(missing)} constant: no track to check u, v and r against")
    span = max(1, int(round(SPAN_S / period))) if period > 0 else 1
    if len(t) < 2 * span + 5:
        return TrackCheck(path, reason=f"{len(t)} samples: too short to check against the track")
    heading = np.unwrap(psi)
    xdot, ydot = central_rate(t, x, span), central_rate(t, y, span)
    mid = slice(span, len(t) - span)
    c, s = np.cos(psi[mid]), np.sin(psi[mid])
    track = {"u": xdot * c + ydot * s, "v": -xdot * s + ydot * c, "r": central_rate(t, heading, span)}
    log = {"u": u[mid], "v": v[mid], "r": r[mid]}
    found = {name: _graded(name, log[name], track[name], columns) for name in CHECKED}
    return _named_fault(path, found, log, track, columns) or TrackCheck(path, tuple(found[n] for n in CHECKED))


def _graded(name: str, logged_rate: np.ndarray, track_rate: np.ndarray, columns: ColumnMap) -> ChannelCheck:
    """One channel's logged values against the track's rate: its factor, correlation, the
    samples kept and the verdict, with the likely unit named when it does not fit."""
    motion = float(np.sqrt(np.mean(track_rate ** 2)))
    logged = float(np.sqrt(np.mean(logged_rate ** 2)))
    if max(motion, logged) < MIN_MOTION[name]:
        return ChannelCheck(name, np.nan, np.nan, 0, Verdict.UNCHECKED, "too little motion")
    k, corr, kept = scale_factor(logged_rate, track_rate)
    if kept < MIN_SAMPLES:
        return ChannelCheck(name, k, corr, kept, Verdict.UNCHECKED, f"{kept} samples kept: too few")
    verdict = _grade(name, k, corr)
    hint = unit_hint(name, k, columns.spec(name).resolved_unit) if verdict is not Verdict.CONSISTENT else ""
    return ChannelCheck(name, k, corr, kept, verdict, hint)


def _named_fault(path: Path, found: dict[str, ChannelCheck], log: dict[str, np.ndarray],
                 track: dict[str, np.ndarray], columns: ColumnMap) -> TrackCheck | None:
    """The one fault that explains the graded channels `found`: the heading in a smaller unit
    or counted to port, the time's unit, u and v swapped; None when none does."""
    rate = found["r"]
    if rate.verdict is not Verdict.UNCHECKED and 0 < rate.factor < 1.0 and not rate.hint:  # psi in a smaller unit
        psi_hint = unit_hint("psi", 1.0 / rate.factor, columns.spec("psi").resolved_unit)
        if psi_hint:
            return TrackCheck(path, (ChannelCheck("psi", 1.0 / rate.factor, rate.correlation, rate.samples, Verdict.MISMATCH,
                                                  psi_hint),))
    if rate.verdict is Verdict.MISMATCH and rate.factor < 0 and abs(rate.correlation) >= CORRELATION_CLEAR and \
            Verdict.MISMATCH in (found["u"].verdict, found["v"].verdict):  # the heading counted to port
        return TrackCheck(path, (ChannelCheck("psi", rate.factor, rate.correlation, rate.samples, Verdict.MISMATCH,
                                              "heading counted anticlockwise (toward port)?"),))
    bad = [found[n] for n in CHECKED if found[n].verdict is Verdict.MISMATCH]
    moving = [found[n] for n in CHECKED if found[n].verdict is not Verdict.UNCHECKED]
    # one factor in every rate: the time's unit
    if len(bad) >= 2 and len(bad) == len(moving) and all(c.factor > 0 and c.correlation >= CORRELATION_CLEAR
                                                         for c in bad):
        factors = np.array([c.factor for c in bad])
        if np.ptp(np.log(factors)) < np.log(1.5):  # v's own spread is up to 1.3
            steady = [c.factor for c in bad if c.channel != "v"] or list(factors)  # v carries its own bias
            k = float(np.exp(np.mean(np.log(steady))))
            hint = unit_hint("t", k, columns.spec("t").resolved_unit)
            return TrackCheck(path, (ChannelCheck("t", k, min(c.correlation for c in bad),
                                                  min(c.samples for c in bad), Verdict.MISMATCH, hint),))
    # u and v swapped: each fits the other's track
    if found["u"].verdict is Verdict.MISMATCH and found["v"].verdict is not Verdict.UNCHECKED:
        k_uv, corr_uv, kept_uv = scale_factor(log["u"], track["v"])
        k_vu, corr_vu, _ = scale_factor(log["v"], track["u"])
        if _grade("v", k_uv, corr_uv) is not Verdict.MISMATCH and _grade("u", k_vu, corr_vu) is not Verdict.MISMATCH:
            swapped = ChannelCheck("uv", k_uv, min(corr_uv, corr_vu), kept_uv, Verdict.MISMATCH,
                                   "the u and v columns swapped?")
            return TrackCheck(path, (swapped, found["r"]))
    return None


def report_checks(checks: Sequence[TrackCheck], warn=None) -> None:
    """Raise one `DataError` with a line per clear mismatch of all `checks` (file, channel,
    factor; a reversed rudder with both fixes: negate the column, or name the log in ``[data]
    rudder_sign_checked``); pass each marginal one, each rudder sign the user checked, and
    once the logs that could not be checked, to `warn` (a callable taking a line)."""
    errors = [f"{check.path}: {c.sentence()}" + (rudder_fixes(check.path) if c.channel == "delta_rudder" else
                                                 " (the track check: give the unit in [data.columns], or fix the "
                                                 "sign in the log)")
              for check in checks for c in check.worst(Verdict.MISMATCH)]
    if warn is not None:
        for check in checks:
            for line in check.lines(Verdict.MARGINAL):
                warn(f"{line} (marginal; docs: Input formats, the track check)")
            if (rudder := check.rudder_overridden) is not None:
                warn(f"{check.path}: delta_rudder: the rudder check reads the sign reversed (partial correlation "
                     f"{rudder.correlation:.2f}); read as it is: the log is named in [data] rudder_sign_checked")
        unchecked = [check for check in checks if not check.checked]
        if unchecked:
            first = unchecked[0]
            more = f" and {len(unchecked) - 1} more log(s)" if len(unchecked) > 1 else ""
            warn(f"{first.path}{more}: not checked against the GNSS track ({first.reason})")
    if errors:
        raise DataError("\n".join(errors))


def rudder_fixes(path: Path) -> str:
    """The second fix of a refused rudder sign, after the first (negate the column): the log
    named in ``[data] rudder_sign_checked`` when its sign is right and the check was fooled."""
    return (f"; or, if you have checked the log's rudder sign and it is right (strong wind or current, tugs or "
            f"little rudder can fool this check), name it in the experiment config: [data] rudder_sign_checked = "
            f"[{json.dumps(Path(path).stem)}]")
