"""The maneuver a log records, recognised from its rudder, propeller and heading.

`recognise(run)` reads only the run's signals; `scenario_of(run)` is the name metrics tables,
reports and MLflow keys use: the protocol's name of a paper test file, else the recognised
maneuver, else (a log too short to tell) the maneuver its folder names.

Rules, in this order (δ rudder angle [deg], n propeller speed [rps], ψ heading [deg]; every
threshold is a fraction of the log's own duration or a whole-degree angle, so they hold at
any ship scale):

1. **berthing** or **random**: the propeller turns astern (n < 0) in at least 5 % of the
   samples. Berthing is low-speed harbour work on the engine: the propeller is reversed
   at least ``BERTHING_REVERSALS_PER_MIN`` times a minute *and* the rudder stays amidships
   (|δ| < 2°) at least ``BERTHING_AMIDSHIPS`` of the time, with short kicks; anything else
   astern is random.
2. **straight**: the rudder stays within 5° of amidships in at least 90 % of the samples
   and the heading changes by less than 90° overall.
3. **turning**: the heading turns through at least 270° net with the rudder held over (below)
   and on the side it turns to in at least ``TURN_SIDE_SHARE`` of the samples it is over. Its
   angle is the median |δ| while the rudder is over, rounded to whole 5° (``Turning 35``).
4. **zig-zag**: the rudder swings between both sides at least twice (|δ| beyond half its
   amplitude), it is held over (below) and the heading changes by less than 90° net. ``Zigzag A/B``: A the rudder
   amplitude, B the median heading deviation from the base course when the rudder leaves
   its side (between the last sample held at |δ| >= 0.9 A and the next) before each
   reversal, both rounded to whole 5°.
5. otherwise **random**.

*Held over*: from the first sample beyond half the amplitude A (the 90th percentile of |δ|
where |δ| >= 5°), |δ| stays at or above 0.9 A in at least ``HELD_MIN_SHARE`` of the samples.
A turning circle or a zig-zag holds its rudder angle between the moves; a meandering run whose
rudder wanders over its range (and may turn through 270° or swing side to side) does not.

On the 39 processed FRT-DS-ESSO logs the rules give each log's own folder
(tests/data/test_scenario.py); the propeller-astern berthing logs reverse 2.5 to 6.2 times
a minute with the rudder amidships 69 to 84 % of the time, the random ones at most 2.2
times a minute or at most 57 % amidships.
Their turning and zig-zag logs hold the rudder over in 71 to 99 % of the samples, the turns
keep it on their turning side in 75 to 100 % of the samples it is over; runs under a rudder
drawn at random every 5-15 s from +-30° hold it in 11 to 18 % and turn with it on either side
alike (48 to 56 %).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sysid.data.recordings import Run
from sysid.channel_names import INPUTS, STATE

ASTERN_SHARE = 0.05               # share of samples with n < 0 that marks astern work
BERTHING_REVERSALS_PER_MIN = 2.0  # propeller reversals (ahead <-> astern) per minute
BERTHING_AMIDSHIPS = 0.6          # share of samples with |δ| < AMIDSHIPS_DEG
AMIDSHIPS_DEG = 2.0
STRAIGHT_RUDDER_DEG = 5.0
STRAIGHT_SHARE = 0.9
TURN_DEG = 270.0                  # net heading change of a turning circle
COURSE_KEPT_DEG = 90.0            # net heading change below which a log keeps its course
ROUND_DEG = 5.0
HELD_SHARE = 0.9                  # |δ| at this share of the amplitude: the rudder is held over
HELD_MIN_SHARE = 0.5              # share of the samples after the first execute held over
TURN_SIDE_SHARE = 2.0 / 3.0       # share of the over-rudder samples on a turn's side
MIN_SECONDS = 30.0                # a shorter log is named by its folder


class Maneuver(str, enum.Enum):
    """The maneuver kinds a log is recognised as."""

    TURNING = "turning"
    ZIGZAG = "zigzag"
    RANDOM = "random"
    BERTHING = "berthing"
    STRAIGHT = "straight"


# folder names (lower case) that name a maneuver
FOLDERS = {"turning": Maneuver.TURNING, "turn": Maneuver.TURNING, "zigzag": Maneuver.ZIGZAG,
           "zig-zag": Maneuver.ZIGZAG, "random": Maneuver.RANDOM, "berthing": Maneuver.BERTHING,
           "straight": Maneuver.STRAIGHT}


@dataclass(frozen=True)
class Scenario:
    """A recognised maneuver: its `kind`, the rudder angle of a turn or the rudder amplitude
    of a zig-zag ``rudder_deg`` [deg], a zig-zag's heading deviation ``heading_deg`` [deg],
    and ``source``: "signals" (recognised) or "folder"."""

    kind: Maneuver
    rudder_deg: float | None = None
    heading_deg: float | None = None
    source: str = "signals"

    @property
    def name(self) -> str:
        """``Turning 35``, ``Zigzag 20/20``, ``Berthing``, ``Random``, ``Straight``."""
        if self.kind is Maneuver.TURNING and self.rudder_deg is not None:
            return f"Turning {self.rudder_deg:g}"
        if self.kind is Maneuver.ZIGZAG and self.rudder_deg is not None and self.heading_deg is not None:
            return f"Zigzag {self.rudder_deg:g}/{self.heading_deg:g}"
        return {Maneuver.ZIGZAG: "Zigzag"}.get(self.kind, self.kind.value.capitalize())


def _rounded(value_deg: float) -> float:
    return float(ROUND_DEG * round(value_deg / ROUND_DEG))


def folder_scenario(path: str | Path) -> Scenario | None:
    """The maneuver the log's folder names (``turning/``, ``zigzag/``, ...), else None."""
    kind = FOLDERS.get(Path(path).parent.name.lower())
    return Scenario(kind, source="folder") if kind is not None else None


def _held_over(delta: np.ndarray, swung: np.ndarray, amplitude: float) -> bool:
    """Whether the rudder `delta` (N,) [deg] is held at >= ``HELD_SHARE`` x `amplitude` [deg]
    in at least ``HELD_MIN_SHARE`` of the samples from the first one in `swung` (N,) on."""
    if not swung.any():
        return False
    after = np.abs(delta[int(np.flatnonzero(swung)[0]):])
    return float(np.mean(after >= HELD_SHARE * amplitude)) >= HELD_MIN_SHARE


def recognise(run: Run) -> Scenario:
    """The maneuver `run` records, from its rudder, propeller and heading (module rules);
    a log shorter than ``MIN_SECONDS`` is named by its folder, else random."""
    if run.duration < MIN_SECONDS or len(run) < 3:
        return folder_scenario(run.path) or Scenario(Maneuver.RANDOM, source="folder")
    minutes = run.duration / 60.0
    delta = np.degrees(run.inputs[:, INPUTS.index("delta_rudder")])             # (N,) deg
    n = run.inputs[:, INPUTS.index("n_prop")]                                    # (N,) rps
    psi = np.degrees(np.unwrap(run.states[:, STATE.index("psi")]))               # (N,) deg
    turned = float(psi[-1] - psi[0])

    if np.mean(n < 0) >= ASTERN_SHARE:
        sign = np.sign(n[np.abs(n) > 1e-9])
        reversals = int(np.count_nonzero(np.diff(sign))) / minutes
        amidships = float(np.mean(np.abs(delta) < AMIDSHIPS_DEG))
        if reversals >= BERTHING_REVERSALS_PER_MIN and amidships >= BERTHING_AMIDSHIPS:
            return Scenario(Maneuver.BERTHING)
        return Scenario(Maneuver.RANDOM)
    if np.mean(np.abs(delta) < STRAIGHT_RUDDER_DEG) >= STRAIGHT_SHARE and abs(turned) < COURSE_KEPT_DEG:
        return Scenario(Maneuver.STRAIGHT)
    over = np.abs(delta) >= STRAIGHT_RUDDER_DEG
    amplitude = float(np.percentile(np.abs(delta[over]), 90)) if over.any() else 0.0
    swung = np.abs(delta) > amplitude / 2
    held_over = _held_over(delta, swung, amplitude)
    one_sided = over.any() and float(np.mean(np.sign(delta[over]) == np.sign(turned))) >= TURN_SIDE_SHARE
    if abs(turned) >= TURN_DEG and held_over and one_sided:
        return Scenario(Maneuver.TURNING, _rounded(float(np.median(np.abs(delta[over])))))
    sides = np.sign(delta[swung])
    switches = np.flatnonzero(np.diff(sides)) + 1 if len(sides) else np.array([], int)
    if len(switches) >= 2 and abs(turned) < COURSE_KEPT_DEG and held_over:
        first = int(np.flatnonzero(swung)[0])          # the first execute: the base course
        held = np.flatnonzero(np.abs(delta) >= HELD_SHARE * amplitude)
        over_at = np.flatnonzero(swung)
        held_at = []                                    # the last sample the old side was held
        for before in over_at[switches - 1]:            # the last sample over on the old side
            old_side = held[(held <= before) & (np.sign(delta[held]) == np.sign(delta[before]))]
            held_at.append(old_side[-1] if len(old_side) else before)
        at = np.asarray(held_at, dtype=int)
        leaving = (psi[at] + psi[np.minimum(at + 1, len(psi) - 1)]) / 2   # between two samples
        deviation = float(np.median(np.abs(leaving - psi[first])))
        return Scenario(Maneuver.ZIGZAG, _rounded(amplitude), _rounded(deviation))
    return Scenario(Maneuver.RANDOM)


def scenario_of(run: Run) -> str:
    """The scenario name of a log in metrics, reports and MLflow keys: the protocol's name
    of a paper test file (``Turning 20``), else `recognise`'s."""
    from sysid.data.datasets import TEST_FILES

    known = {Path(v).stem: k for k, v in TEST_FILES.items()}
    if run.name in known:
        return known[run.name]
    return recognise(run).name


__all__ = ["Maneuver", "Scenario", "folder_scenario", "recognise", "scenario_of"]
