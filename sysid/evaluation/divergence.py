"""When a prediction has diverged: a non-finite state, or a velocity far outside the physical
range of the training data.

The rule (docs: How sysid judges a model): a predicted state diverged when any of its six
channels is not finite, or when its speed sqrt(u^2 + v_m^2) exceeds `DIVERGENCE_FACTOR` times
the largest speed in the training logs and in the window's own record, or its |r| that
factor times their largest |r|.
Without training logs (an MMG used as defined) only non-finite states count.

`diverged_windows` is the one place this rule is applied to window predictions: ``sysid
train``, ``sysid evaluate``, ``sysid compare`` and the ensemble verdict of ``sysid reproduce
--seeds N`` all call it, each with the model's training range (`PhysicalRange`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from sysid.evaluation.judgement import Divergence
from sysid.records.summary import RunSummary
from sysid.channel_names import VELOCITY_INDEX

DIVERGENCE_FACTOR = 3.0   # a prediction this many times faster or turning faster than any training sample diverged


@dataclass(frozen=True)
class PhysicalRange:
    """The training logs' largest speed sqrt(u^2 + v_m^2) [m/s] and |r| [rad/s]; a prediction
    beyond `factor` times either has diverged."""

    speed: float
    yaw_rate: float
    factor: float = DIVERGENCE_FACTOR

    @classmethod
    def of_runs(cls, runs: Sequence, factor: float = DIVERGENCE_FACTOR) -> "PhysicalRange | None":
        """The range of `runs` (`sysid.data.recordings.Run`); None without runs."""
        if not runs:
            return None
        return cls.of_states(np.concatenate([np.asarray(run.states) for run in runs]), factor)

    @classmethod
    def of_states(cls, states: np.ndarray, factor: float = DIVERGENCE_FACTOR) -> "PhysicalRange | None":
        """The range of states (N, 6); None without a finite one."""
        vel = np.asarray(states, dtype=float)[:, list(VELOCITY_INDEX)]
        vel = vel[np.all(np.isfinite(vel), axis=1)]
        if not len(vel):
            return None
        return cls(float(np.hypot(vel[:, 0], vel[:, 1]).max()), float(np.abs(vel[:, 2]).max()), factor)

    def to_dict(self) -> dict:
        return {"speed": self.speed, "yaw_rate": self.yaw_rate, "factor": self.factor}

    @classmethod
    def widest(cls, ranges: Sequence["PhysicalRange | None"]) -> "PhysicalRange | None":
        """The widest of `ranges` (the seeds of an ensemble: each its own training logs); None
        when none is given."""
        kept = [r for r in ranges if r is not None]
        if not kept:
            return None
        return cls(max(r.speed for r in kept), max(r.yaw_rate for r in kept), kept[0].factor)

    @classmethod
    def of_summary(cls, summary: RunSummary) -> "PhysicalRange | None":
        """The training range a run recorded in summary.json (None: it recorded none)."""
        kept = summary.training_range
        return None if kept is None else cls(kept.speed, kept.yaw_rate, kept.factor)


def diverged_steps(predicted: np.ndarray, limits: PhysicalRange | None = None,
                   observed: np.ndarray | None = None) -> np.ndarray:
    """(H, W) True where a predicted state (H, W, 6) diverged by the rule, against `limits`
    widened to the `observed` (H, W, 6) states of these windows (as `diverged_windows`)."""
    return _diverged(np.asarray(predicted, dtype=float), limits, observed)[0]


def _diverged(predicted: np.ndarray, limits: PhysicalRange | None, observed: np.ndarray | None):
    """(bad, non-finite, too fast, turning too fast, the limits widened) of states (H, W, 6)."""
    if limits is not None and observed is not None:
        seen = PhysicalRange.of_states(np.asarray(observed, dtype=float).reshape(-1, predicted.shape[-1]))
        if seen is not None:
            limits = PhysicalRange(max(limits.speed, seen.speed), max(limits.yaw_rate, seen.yaw_rate), limits.factor)
    bad_finite = ~np.all(np.isfinite(predicted), axis=-1)                    # (H, W)
    bad = bad_finite.copy()
    speed = yaw = None
    if limits is not None:
        u, v, r = (predicted[..., i] for i in VELOCITY_INDEX)
        with np.errstate(invalid="ignore"):
            speed = np.hypot(u, v) > limits.factor * limits.speed
            yaw = np.abs(r) > limits.factor * limits.yaw_rate
        bad |= speed | yaw
    return bad, bad_finite, speed, yaw, limits


def diverged_windows(predicted: np.ndarray, t: np.ndarray, log: str, horizon_s: float,
                     limits: PhysicalRange | None = None,
                     observed: np.ndarray | None = None) -> tuple[np.ndarray, Divergence | None]:
    """(W,) True for each window whose prediction diverged, and where it first did (the
    earliest time over the windows), or None.

    predicted, observed : (H, W, 6) predicted and recorded states (`sysid.channel_names.STATE`); t :
    (H, W) log time [s]. The range is the training logs' (`limits`), widened to the recorded
    states of these windows: a prediction as fast as the record never counts as diverged.
    """
    predicted = np.asarray(predicted, dtype=float)
    H, W = predicted.shape[:2]
    if not W:
        return np.zeros(0, dtype=bool), None
    bad, bad_finite, speed, yaw, limits = _diverged(predicted, limits, observed)
    flags = bad.any(0)
    if not flags.any():
        return flags, None
    step, window = np.argwhere(bad)[np.argmin(np.asarray(t)[bad])]
    if bad_finite[step, window]:
        channel, reason = "", "non-finite"
    elif speed is not None and speed[step, window]:
        value = float(np.hypot(predicted[step, window, VELOCITY_INDEX[0]], predicted[step, window, VELOCITY_INDEX[1]]))
        channel, reason = "speed", (f"{value:.3g} m/s, beyond {limits.factor:g} x the largest speed of the "
                                    f"training logs and this record, {limits.speed:.3g} m/s")
    else:
        value = float(abs(predicted[step, window, VELOCITY_INDEX[2]]))
        channel, reason = "r", (f"|r| {value:.3g} rad/s, beyond {limits.factor:g} x the largest |r| of the "
                                f"training logs and this record, {limits.yaw_rate:.3g} rad/s")
    return flags, Divergence(log, float(horizon_s), float(np.asarray(t)[step, window]), channel, reason)
