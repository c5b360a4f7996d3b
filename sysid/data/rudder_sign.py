"""The rudder's sign read from a log's own yaw response (docs: Input formats, the rudder check).

sysid's MMG counts the rudder angle delta [rad] and the yaw rate r [rad/s] positive to
starboard (x to the bow, y to starboard, z down). Its rudder yaw moment

    N_R = -(x_R + a_H x_H) F_N cos(delta),   F_N ~ U_R^2 sin(delta)    (docs: MMG equations)

has x_R + a_H x_H < 0 (the rudder and the hull's interaction force lie aft), so going ahead
a positive delta gives a positive moment: dr/dt grows with delta, the ship turns to
starboard. A logger that counts the rudder to port turns this relation over.

Over the samples going ahead (u > `AHEAD_SPEED`) the yaw acceleration, by central
differences of r over about 1 s, is fitted by least squares as

    dr/dt = a u^2 delta + b |u| r + c

(the rudder's moment, the yaw damping, a bias; a first-order Nomoto model with the rudder
force's speed scaling), and the partial correlation of dr/dt with u^2 delta given the other
two terms says which way the rudder turns the ship: positive for this convention (below
`CORRELATION_WEAK` in size it says nothing, a log whose r does not answer its rudder). It is read
only with enough rudder (`EXCITED_S` of samples ahead with |delta| >= `EXCITED_ANGLE`);
straight running and harbour logs give no claim. Of the 39 FRT-DS-ESSO logs, 29 (turning,
zig-zag, random) are read, at 10 Hz and at 1 Hz alike, with partial correlations of +0.37 to
+0.93 (the same logs with delta negated: -0.37 to -0.93); the 8 berthing logs and 2 random
ones have less than 30 s of rudder going ahead and are not read.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

AHEAD_SPEED = 0.15               # u [m/s] above which a sample is going ahead
EXCITED_ANGLE = np.radians(3.0)  # |delta| [rad] of a sample with rudder
EXCITED_S = 30.0                 # rudder time [s] ahead the relation needs
REVERSED_CORRELATION = 0.3       # a partial correlation at or below -0.3: the sign is reversed
CORRELATION_WEAK = 0.1           # |partial correlation| below 0.1: no relation to read a sign from
SPAN_S = 1.0                     # half-width of the central differences of r [s]


class RudderSign(enum.Enum):
    """Which way positive rudder turns the ship in a log."""

    STARBOARD = "starboard"      # sysid's convention
    PORT_CLEAR = "port"          # reversed, clearly
    PORT_WEAK = "port (weak)"    # a negative relation too weak to claim
    UNCLEAR = "unclear"          # rudder enough, but no relation between it and dr/dt
    NOT_READ = "not read"        # too little rudder going ahead


@dataclass(frozen=True)
class RudderResponse:
    """A log's yaw response to its rudder.

    Attributes
    ----------
    sign : `RudderSign`.
    correlation : partial correlation of dr/dt with u^2 delta given |u| r and a bias [-]
        (NaN when not read).
    excited_s : time going ahead with |delta| >= `EXCITED_ANGLE` [s].
    samples : samples going ahead used in the fit.
    """

    sign: RudderSign
    correlation: float
    excited_s: float
    samples: int


def _residual(y: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """y minus its least-squares fit on the columns of `basis` (N, k)."""
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    return y - basis @ coef


def rudder_response(t: np.ndarray, u: np.ndarray, r: np.ndarray, delta: np.ndarray) -> RudderResponse:
    """The sign of the yaw response to the rudder from (N,) time t [s], surge u [m/s], yaw
    rate r [rad/s] and rudder angle delta [rad] (SI, as read). Cost O(N)."""
    steps = np.diff(t)
    period = float(np.median(steps)) if len(steps) else 0.0
    span = max(1, int(round(SPAN_S / period))) if period > 0 else 1
    if len(t) < 2 * span + 5:
        return RudderResponse(RudderSign.NOT_READ, np.nan, 0.0, 0)
    r_dot = (r[2 * span:] - r[:-2 * span]) / (t[2 * span:] - t[:-2 * span])
    mid = slice(span, len(t) - span)
    u_m, r_m, d_m = u[mid], r[mid], delta[mid]
    ahead = np.isfinite(r_dot) & np.isfinite(u_m) & np.isfinite(d_m) & (u_m > AHEAD_SPEED)
    excited_s = float(np.count_nonzero(ahead & (np.abs(d_m) >= EXCITED_ANGLE))) * period
    samples = int(np.count_nonzero(ahead))
    if excited_s < EXCITED_S:
        return RudderResponse(RudderSign.NOT_READ, np.nan, excited_s, samples)
    u_a = u_m[ahead]
    rudder = u_a ** 2 * d_m[ahead]
    others = np.column_stack([np.abs(u_a) * r_m[ahead], np.ones(samples)])
    y, x = _residual(r_dot[ahead], others), _residual(rudder, others)
    power = float(np.sqrt(np.einsum("i,i->", x, x) * np.einsum("i,i->", y, y)))
    corr = float(np.einsum("i,i->", x, y)) / power if power > 0 else 0.0
    if abs(corr) < CORRELATION_WEAK:
        sign = RudderSign.UNCLEAR
    elif corr > 0:
        sign = RudderSign.STARBOARD
    elif corr <= -REVERSED_CORRELATION:
        sign = RudderSign.PORT_CLEAR
    else:
        sign = RudderSign.PORT_WEAK
    return RudderResponse(sign, corr, excited_s, samples)
