"""A verdict, always: a learned model beside its physics baseline(s), channel by channel.

Baselines are the ship file's MMG (with ``[mmg] overrides``) and, when identification ran,
the identified MMG. Each cell is the RMSE of one channel (u, v_m [m/s], r [rad/s]) at one
horizon on one split:

- validation: the windows of ``val_loss_multistep`` (`sysid.identify.trainer.VAL_LOSS_DEFINITION`),
  RMSE over their predicted steps; the baselines' ``val_loss_multistep`` beside the model's;
- test: the benchmark protocol's windows of every test log at each evaluation horizon,
  RMSE pooled over every window point of every test log.

On the deciding split (the test logs, or validation when there are none) the model *beats
its baseline* when its RMSE is lower on average over the cells (geometric mean of the
ratios, every channel and horizon alike) and no cell is more than 10 % (`MATERIAL`) worse.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
import torch

from sysid.identify.trainer import WindowSet, rollout_errors, velocity_loss

CHANNELS = ("u", "v_m", "r")
UNITS = {"u": "m/s", "v_m": "m/s", "r": "rad/s"}
SHIP_FILE_MMG = "MMG (ship file)"
IDENTIFIED_MMG = "MMG (identified)"
VALIDATION, TEST = "validation", "test"
MODEL_NAMES = {"mmg": "identified MMG", "nn": "NN-only model", "hybrid": "hybrid"}
MATERIAL = 0.10   # a cell this much worse than its baseline fails the verdict, whatever the average


def percent_text(change: float) -> str:
    """A relative change as "+20 %", "-3.4 %" (one decimal below 10 %), "-" when undefined."""
    if not math.isfinite(change):
        return "-"
    pct = 100 * change
    return f"{pct:+.1f} %" if abs(pct) < 10 else f"{pct:+.0f} %"


@dataclass(frozen=True)
class ChannelCell:
    """One channel at one horizon on one split: the model's RMSE and each baseline's
    [m/s or rad/s]; `model_std` the spread (std) over seeds when the cell is a seed mean."""

    split: str
    horizon_s: float
    channel: str
    model: float
    baselines: dict[str, float]
    model_std: float | None = None

    def change(self, baseline: str) -> float:
        """(model - baseline) / baseline: negative is better than the baseline."""
        ref = self.baselines[baseline]
        return (self.model - ref) / ref if ref > 0 else math.nan

    def worse_than(self, baseline: str) -> bool:
        return not self.model < self.baselines[baseline]

    @property
    def finite(self) -> bool:
        return math.isfinite(self.model) and all(math.isfinite(v) for v in self.baselines.values())

    def text(self, baseline: str) -> str:
        """"u at 30 s: 0.0528 against 0.0377 m/s (+40 %)"."""
        return (f"{self.channel} at {self.horizon_s:g} s: {self.model:.4f} against {self.baselines[baseline]:.4f} "
                f"{UNITS[self.channel]} ({percent_text(self.change(baseline))})")


@dataclass(frozen=True)
class BaselineVerdict:
    """A learned model against its physics baselines on validation and test (summary.json
    ``verdict``).

    model : "hybrid" | "nn" | "mmg" (identified); baselines : labels, the ship file's MMG
    first; cells : every split x horizon x channel; val_loss_multistep : label ("model" or a
    baseline) -> validation loss; decided_on : "test" or "validation"; seeds : how many
    runs a seed-mean verdict averages (1: a single run).
    """

    model: str
    baselines: tuple[str, ...]
    cells: tuple[ChannelCell, ...]
    val_loss_multistep: dict[str, float] = field(default_factory=dict)
    decided_on: str = TEST
    seeds: int = 1

    @property
    def deciding(self) -> list[ChannelCell]:
        return [c for c in self.cells if c.split == self.decided_on and c.finite]

    @property
    def worse(self) -> list[tuple[ChannelCell, str]]:
        """(cell, baseline) where the model is not better, on the deciding split."""
        return [(c, b) for c in self.deciding for b in self.baselines if c.worse_than(b)]

    @property
    def material(self) -> list[tuple[ChannelCell, str]]:
        """(cell, baseline) where the model is more than `MATERIAL` worse, on the deciding split."""
        return [(c, b) for c, b in self.worse if c.change(b) > MATERIAL]

    def mean_change(self, baseline: str) -> float:
        """The model's RMSE against the baseline's over the deciding cells: the geometric mean
        of the ratios, minus 1 (-0.3: 30 % lower on average; every channel weighs alike)."""
        ratios = [c.model / c.baselines[baseline] for c in self.deciding if c.baselines[baseline] > 0]
        return math.exp(float(np.mean(np.log(ratios)))) - 1.0 if ratios else math.nan

    @property
    def beats_baseline(self) -> bool:
        """Lower RMSE than every baseline on average over the deciding cells, and no cell more
        than `MATERIAL` worse."""
        return (bool(self.deciding) and all(self.mean_change(b) < 0 for b in self.baselines)
                and not self.material)

    @property
    def model_name(self) -> str:
        return MODEL_NAMES.get(self.model, self.model)

    def statement(self) -> str:
        """The verdict in one or two sentences (the report's first line, the CLI's last)."""
        where = "the test logs" if self.decided_on == TEST else "the validation windows (there is no test set)"
        spread = f" (mean over {self.seeds} seeds)" if self.seeds > 1 else ""
        base = " and ".join(self.baselines)
        cells = self.deciding
        if not cells:
            return f"No verdict: neither test logs nor validation windows gave the {self.model_name} a score."
        average = "; ".join(f"{percent_text(abs(self.mean_change(b)))[1:]} {'lower' if self.mean_change(b) < 0 else 'higher'}"
                            + (f" than {b}" if len(self.baselines) > 1 else "") for b in self.baselines)
        average = f"RMSE {average} on average over the {len(cells)} cells (u, v_m, r at {_horizons(cells)} s)"
        worse = sorted(self.worse, key=lambda cb: -cb[0].change(cb[1]))
        listed = "; ".join(f"{c.text(b)}" + (f" vs {b}" if len(self.baselines) > 1 else "") for c, b in worse[:4])
        listed += "; ..." if len(worse) > 4 else ""
        if self.beats_baseline:
            if not worse:
                return f"The {self.model_name}{spread} beats its physics baseline, {base}, on {where}: {average}, " \
                       "lower in every cell."
            return (f"The {self.model_name}{spread} beats its physics baseline, {base}, on {where}: {average}; "
                    f"not lower in {listed}, within the {100 * MATERIAL:.0f} % tolerance.")
        return (f"The {self.model_name}{spread} is WORSE than its physics baseline, {base}, on {where}: {listed}; "
                f"{average}. Use the baseline, or train and check again, before trusting this model.")

    def warning(self) -> str | None:
        """The WARNING line for stderr, or None when the model beats its baseline."""
        return None if self.beats_baseline else "WARNING: " + self.statement()

    def to_dict(self) -> dict:
        return {"model": self.model, "baselines": list(self.baselines), "decided_on": self.decided_on,
                "beats_baseline": self.beats_baseline, "seeds": self.seeds,
                "val_loss_multistep": dict(self.val_loss_multistep),
                "statement": self.statement(), "cells": [asdict(c) for c in self.cells]}

    @classmethod
    def from_dict(cls, d: Mapping) -> "BaselineVerdict":
        cells = tuple(ChannelCell(**{**c, "baselines": dict(c["baselines"])}) for c in d["cells"])
        return cls(d["model"], tuple(d["baselines"]), cells, dict(d.get("val_loss_multistep") or {}),
                   d.get("decided_on", TEST), int(d.get("seeds", 1)))


def _horizons(cells: Sequence[ChannelCell]) -> str:
    hs = sorted({c.horizon_s for c in cells})
    return " and ".join(f"{h:g}" for h in hs)


@dataclass(frozen=True)
class WindowScore:
    """A model on validation windows: ``val_loss_multistep`` and the RMSE of u, v_m [m/s], r
    [rad/s] over the windows' predicted steps."""

    val_loss_multistep: float
    rmse: tuple[float, float, float]


def window_score(model, windows: WindowSet, w_v: torch.Tensor) -> WindowScore:
    """`WindowScore` of `model` on `windows` (Euler rollouts, as in training)."""
    err = rollout_errors(model, windows)
    rmse = torch.sqrt((err * err).reshape(-1, 3).mean(0))
    return WindowScore(float(velocity_loss(err, w_v)), tuple(float(v) for v in rmse))  # type: ignore[arg-type]


def pooled_rmse(metrics: pd.DataFrame) -> dict[float, tuple[float, float, float]]:
    """horizon [s] -> RMSE of (u, v_m, r) pooled over every window point of every log of a
    metrics table (`sysid.evaluation.evaluate.METRICS_COLUMNS`); logs without windows skipped."""
    out = {}
    for horizon, block in metrics.groupby("horizon_s", sort=True):
        block = block[block.n_windows > 0]
        n = block.n_windows.to_numpy(dtype=float)
        if not n.sum():
            continue
        out[float(horizon)] = tuple(float(np.sqrt((n * block[c].to_numpy() ** 2).sum() / n.sum()))
                                    for c in ("rmse_u", "rmse_v", "rmse_r"))
    return out  # type: ignore[return-value]


def baseline_verdict(model: str, validation: Mapping[str, WindowScore] | None, validation_horizon_s: float,
                     test: Mapping[str, pd.DataFrame] | None) -> BaselineVerdict:
    """The verdict from scores keyed "model" and by baseline label (`SHIP_FILE_MMG`, ...):
    `validation` window scores, `test` metrics tables (None or empty: not available)."""
    labels = [k for k in (validation or test or {}) if k != "model"]
    cells: list[ChannelCell] = []
    if validation:
        for j, channel in enumerate(CHANNELS):
            cells.append(ChannelCell(VALIDATION, validation_horizon_s, channel, validation["model"].rmse[j],
                                     {b: validation[b].rmse[j] for b in labels}))
    if test:
        pooled = {k: pooled_rmse(v) for k, v in test.items()}
        for horizon, values in pooled["model"].items():
            for j, channel in enumerate(CHANNELS):
                cells.append(ChannelCell(TEST, horizon, channel, values[j],
                                         {b: pooled[b][horizon][j] for b in labels}))
    losses = {k: v.val_loss_multistep for k, v in (validation or {}).items()}
    decided = TEST if any(c.split == TEST and c.finite for c in cells) else VALIDATION
    return BaselineVerdict(model, tuple(labels), tuple(cells), losses, decided)


def seed_mean_verdict(verdicts: Sequence[BaselineVerdict]) -> BaselineVerdict:
    """The verdict of the seeds' mean RMSE per cell, with its std over the seeds (the
    baselines are the same physics in every seed, so their mean is theirs)."""
    first = verdicts[0]
    if len(verdicts) == 1:
        return first
    cells = []
    for i, cell in enumerate(first.cells):
        values = np.array([v.cells[i].model for v in verdicts])
        baselines = {b: float(np.mean([v.cells[i].baselines[b] for v in verdicts])) for b in first.baselines}
        cells.append(ChannelCell(cell.split, cell.horizon_s, cell.channel, float(values.mean()), baselines,
                                 float(values.std(ddof=1))))
    losses = {k: float(np.mean([v.val_loss_multistep.get(k, math.nan) for v in verdicts]))
              for k in first.val_loss_multistep}
    return BaselineVerdict(first.model, first.baselines, tuple(cells), losses, first.decided_on, len(verdicts))
