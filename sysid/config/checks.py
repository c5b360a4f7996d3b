"""Numbers a user hands sysid, each kind checked in one place: finite, inside its range, and
whole where it counts samples, cores or ships.

Commands check their options with these as they parse them (`OptionError`, exit 2); configs
check their keys the same way (`ConfigError`). The error line names the option or key, the
value given, its unit and the range allowed, with the reason where the bound is physical.
Torch-free: the CLI checks options before it imports a model.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass

from sysid.errors import OptionError

ErrorType = type[Exception]


def shown(value) -> str:
    """A number as the user typed it, more or less: 1.4, nan, inf, 1e+09, 100000."""
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


@dataclass(frozen=True)
class Range:
    """The values one kind of number may take.

    low, high : bounds in `unit`; low_open : `low` itself is refused (> low, not >= low).
    whole : an integer (a count of samples, cores, ships). reason : why `high`, shown.
    """

    low: float = -math.inf
    high: float = math.inf
    unit: str = ""
    low_open: bool = False
    whole: bool = False
    reason: str = ""

    def describe(self) -> str:
        """'a finite number > 0 and <= 10 s (why)'."""
        bounds = []
        if self.low > -math.inf:
            bounds.append(f"{'>' if self.low_open else '>='} {shown(self.low)}")
        if self.high < math.inf:
            bounds.append(f"<= {shown(self.high)}")
        text = " ".join(["a whole number" if self.whole else "a finite number", " and ".join(bounds)]).strip()
        text += f" {self.unit}" if self.unit else ""
        return text + (f" ({self.reason})" if self.reason else "")

    def admits(self, value) -> bool:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if self.whole and not isinstance(value, int):
            return False
        try:
            x = float(value)
        except OverflowError:  # an int beyond any float
            return False
        if not math.isfinite(x):
            return False
        return (x > self.low if self.low_open else x >= self.low) and x <= self.high

    def check(self, name: str, value, error: ErrorType = OptionError):
        """`value` unchanged, or `error` naming `name` (``--dt``, ``file: [training] threads``)."""
        if not self.admits(value):
            raise error(f"{name} {shown(value)}: must be {self.describe()}")
        return value


MAX_STEP_S = 10.0

# kinds of numbers (SI units)
DURATION = Range(0.0, unit="s", low_open=True)                  # a horizon, a dropout
TIME = Range(unit="s")                                           # a time stamp: finite
NON_NEGATIVE_SECONDS = Range(0.0, unit="s")                      # a gap, a start offset
RATE = Range(0.0, unit="Hz", low_open=True)
STEP = Range(0.0, MAX_STEP_S, "s", low_open=True,
             reason="one explicit step of a ship's equations of motion; a ship's sway and yaw "
                    "respond within seconds, and a longer step jumps past them")
NOISE = Range(0.0, 100.0, "m", reason="a GNSS fix that far off is no fix")
LATITUDE = Range(-90.0, 90.0, "deg")
LONGITUDE = Range(-180.0, 180.0, "deg")
COUNT = Range(0, whole=True)
POSITIVE_COUNT = Range(1, whole=True)
MAX_BATCH = 4096
BATCH = Range(1, MAX_BATCH, "ships", whole=True,
              reason="ships per call: each holds a row of distances to the whole kNN bank")


def cpu_cores() -> int:
    """CPU cores this process may run on (its affinity mask, else the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _on_this_machine(low: int, meaning: str) -> Range:
    cores = cpu_cores()
    return Range(low, cores, whole=True, reason=f"this machine lets sysid use {cores} CPU core"
                 f"{'s' if cores != 1 else ''}{meaning}")


def threads(name: str, value, error: ErrorType = OptionError) -> int:
    """Torch threads: 0 (one per core) up to the cores this process may use."""
    return _on_this_machine(0, "; 0 means one per core").check(name, value, error)


def workers(name: str, value, error: ErrorType = OptionError, cluster: str | None = None) -> int:
    """Processes side by side: 1 up to the cores this process may use, or any number >= 1
    on the cluster at address `cluster` (its cores are not this machine's)."""
    return (POSITIVE_COUNT if cluster else _on_this_machine(1, "")).check(name, value, error)


def whole_samples(name: str, seconds: float, dt: float, error: ErrorType = OptionError) -> int:
    """`seconds` as a whole number (>= 1) of samples `dt` [s] apart, or `error` naming `name`."""
    DURATION.check(name, seconds, error)
    samples = round(seconds / dt)
    if samples < 1 or abs(samples * dt - seconds) > 1e-6 * max(1.0, seconds):
        whole = max(1, samples) * dt
        raise error(f"{name} {shown(seconds)}: not a whole number of the data's {dt:g}-s samples "
                    f"(the nearest is {whole:g} s)")
    return samples


# a name that becomes one file or folder name: ASCII only, no separator, never "." or ".."
_COMPONENT = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.,=+-]*")
_STRICT_COMPONENT = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")
MAX_COMPONENT = 120


def path_component(name: str, value, error: ErrorType = OptionError, strict: bool = False) -> str:
    """`value` if it is a safe single path component (a file or folder name on any system):
    ASCII letters A-Z a-z and digits 0-9 first, then those and ``_ - . , = +`` (`strict`:
    ``_`` and ``-`` only), at most `MAX_COMPONENT` characters; else `error` stating that rule."""
    allowed = "'_' and '-'" if strict else "'_', '-', '.', ',', '=' and '+'"
    rule = _STRICT_COMPONENT if strict else _COMPONENT
    if not isinstance(value, str) or not rule.fullmatch(value) or len(value) > MAX_COMPONENT:
        raise error(f"{name} = {value!r}: a name here becomes a file or folder name, so it is ASCII letters "
                    f"(A-Z, a-z) and digits (0-9) followed by those, {allowed}, at most {MAX_COMPONENT} "
                    "characters (no spaces, accents or other scripts, no '/')")
    return value
