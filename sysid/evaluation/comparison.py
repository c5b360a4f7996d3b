"""Models side by side on the same logs and horizons (``sysid compare``), each judged by the
project's one rule (`sysid.evaluation.judgement.judge`) against a reference.

Every model predicts the protocol's windows (`sysid.evaluation.evaluate.predict_windows`) of
the same logs at the same horizons. A window's error in a channel is the RMSE over its H
points (first included) [m/s for u and v_m, rad/s for r]; `window_errors` gives every model's
errors on the same windows, (M, W) per log, horizon and channel, M its members (the seeds of a
seed folder, else 1). `compare` pairs each model with its reference (the first model, or each
model's physics baseline: the ship file's MMG with its ``[mmg] overrides``) cell by cell and
judges the pair in one call. No I/O here: `sysid.cli.compare_commands` loads the models and
writes the tables.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
import pandas as pd
import torch
from torch import nn

from sysid.data.recordings import Run
from sysid.data.scenario import scenario_of
from sysid.dynamics.integrators import EULER, Integrator
from sysid.evaluation.divergence import PhysicalRange
from sysid.evaluation.evaluate import predict_windows
from sysid.evaluation.judgement import (CHANNELS, DEFAULT_RULE, UNITS, Divergence, Judgement, PairedCell, VerdictRule,
                                       judge)
from sysid.channel_names import VELOCITY_INDEX

FIRST, BASELINE = "first", "baseline"   # what every model is judged against (``--against``)
# one row per log, horizon, channel and model (comparison.csv)
TABLE_COLUMNS = ["log", "scenario", "horizon_s", "channel", "unit", "n_windows", "model", "n_members",
                 "rmse", "rmse_std", "reference", "reference_rmse", "change", "change_low", "change_high",
                 "decision"]
# one row per model (verdicts.csv)
VERDICT_COLUMNS = ["model", "reference", "outcome", "change", "change_low", "change_high", "n_logs",
                   "n_windows", "n_members", "sentence"]


@dataclass(frozen=True)
class Contender:
    """A model in the comparison. label : its name in every table; members : one force model,
    or the seeds of a seed folder (their spread is the evidence's); kind : "mmg", "nn" or
    "hybrid"; baseline : the label of its physics baseline (a `Contender` of the same
    comparison; its own label for a ship file's MMG); limits : its training range, beyond
    which a prediction diverged (`sysid.evaluation.divergence`; None: non-finite only, a
    ship file's MMG)."""

    label: str
    members: tuple[nn.Module, ...]
    kind: str = "mmg"
    baseline: str = ""
    limits: PhysicalRange | None = None


@dataclass(frozen=True)
class WindowErrors:
    """Every model's per-window RMSE on one log at one horizon, on the same windows.

    window_start_s : (W,) start time [s] of each window; errors : label -> (M, W, 3) RMSE of
    u, v_m [m/s] and r [rad/s] of each member; divergence : label -> where its prediction
    first diverged (`sysid.evaluation.divergence.diverged_windows` against the contender's
    training range; absent when it did not)."""

    log: str
    scenario: str
    horizon_s: float
    window_start_s: np.ndarray
    errors: dict[str, np.ndarray]
    divergence: dict[str, Divergence]

    @property
    def n_windows(self) -> int:
        return int(self.window_start_s.size)


def _per_window_rmse(observed: torch.Tensor, predicted: torch.Tensor) -> np.ndarray:
    """(W, 3) RMSE over each window's H points of u, v_m, r, from (H, W, 6) states."""
    idx = list(VELOCITY_INDEX)
    err = (predicted[..., idx] - observed[..., idx]).detach().cpu().double()
    return torch.sqrt((err**2).mean(0)).numpy()


def window_errors(contenders: Sequence[Contender], runs: Sequence[Run], horizons: Sequence[float],
                  integrator: Integrator = EULER,
                  on_done: Callable[[], None] | None = None) -> list[WindowErrors]:
    """Per-window errors of every contender's members on every run at every horizon (the
    protocol's windows; every member of every model on the same windows). `on_done` is
    called after each member's predictions (progress)."""
    found: dict[tuple[str, float], WindowErrors] = {}
    for contender in contenders:
        for m, member in enumerate(contender.members):
            for horizon in horizons:
                with torch.no_grad():
                    predictions = predict_windows(member, runs, horizon, integrator)
                for pred in predictions:
                    key = (pred.run.name, float(horizon))
                    if key not in found:
                        t0 = pred.t[0] if len(pred.starts) else np.zeros(0)
                        found[key] = WindowErrors(pred.run.name, scenario_of(pred.run), float(horizon),
                                                  np.asarray(t0, dtype=float), {}, {})
                    cell = found[key]
                    errors = cell.errors.setdefault(
                        contender.label, np.zeros((len(contender.members), cell.n_windows, 3)))
                    if cell.n_windows:
                        errors[m] = _per_window_rmse(pred.observed, pred.predicted)
                        where = pred.divergence(float(horizon), contender.limits)
                        if where is not None and contender.label not in cell.divergence:
                            cell.divergence[contender.label] = where
                if on_done is not None:
                    on_done()
    order = {run.name: i for i, run in enumerate(runs)}
    return sorted(found.values(), key=lambda c: (c.horizon_s, order[c.log]))


def paired_cells(errors: Sequence[WindowErrors], model: str, reference: str) -> list[PairedCell]:
    """The cells (log, horizon, channel) pairing `model` with `reference` on the same
    windows; logs without a window at a horizon give no cell."""
    cells = []
    for e in errors:
        if not e.n_windows:
            continue
        for j, channel in enumerate(CHANNELS):
            cells.append(PairedCell(e.log, e.scenario, e.horizon_s, channel, e.errors[model][..., j],
                                    e.errors[reference][..., j], e.window_start_s, e.divergence.get(model)))
    return cells


@dataclass(frozen=True)
class Comparison:
    """What `compare` found. table : `TABLE_COLUMNS` rows; verdicts : label -> its
    `Judgement` against its reference (the reference itself has none); references : label
    -> the label it is judged against; against : `FIRST` or `BASELINE`; horizons [s]."""

    table: pd.DataFrame
    verdicts: dict[str, Judgement]
    references: dict[str, str]
    against: str
    horizons: tuple[float, ...]
    errors: tuple[WindowErrors, ...]

    def verdict_table(self) -> pd.DataFrame:
        """`VERDICT_COLUMNS`, one row per judged model."""
        rows = [{"model": label, "reference": self.references[label], "outcome": j.outcome.name.lower(),
                 "change": j.change, "change_low": j.change_low, "change_high": j.change_high,
                 "n_logs": j.n_logs, "n_windows": j.n_windows, "n_members": j.n_members, "sentence": j.sentence}
                for label, j in self.verdicts.items()]
        return pd.DataFrame(rows, columns=VERDICT_COLUMNS)

    def window_table(self) -> pd.DataFrame:
        """Every window's RMSE per model and member: log, horizon_s, window, t_start_s,
        model, member, err_u, err_v_m [m/s], err_r [rad/s] (the evidence of the verdicts)."""
        rows = []
        for e in self.errors:
            for label, errors in e.errors.items():
                for m in range(errors.shape[0]):
                    for w in range(e.n_windows):
                        rows.append((e.log, e.horizon_s, w, e.window_start_s[w], label, m, *errors[m, w]))
        return pd.DataFrame(rows, columns=["log", "horizon_s", "window", "t_start_s", "model", "member",
                                           "err_u", "err_v_m", "err_r"])


def references_of(contenders: Sequence[Contender], against: str) -> dict[str, str]:
    """label -> the label it is judged against: the first contender (`FIRST`), or its
    physics baseline (`BASELINE`); a contender that is its own reference is not judged."""
    if against not in (FIRST, BASELINE):
        raise ValueError(f"against {against!r}: choose {FIRST} or {BASELINE}")
    first = contenders[0].label
    out = {}
    for c in contenders:
        reference = first if against == FIRST else (c.baseline or c.label)
        if reference != c.label:
            out[c.label] = reference
    return out


def compare(contenders: Sequence[Contender], runs: Sequence[Run], horizons: Sequence[float],
            against: str = FIRST, integrator: Integrator = EULER, rule: VerdictRule = DEFAULT_RULE,
            on_done: Callable[[], None] | None = None) -> Comparison:
    """Every contender on the same `runs` and `horizons` [s], each judged against its
    reference (`references_of`) by `judge` under `rule`. Labels must be unique; a
    contender's ``baseline`` must be one of the contenders when `against` is `BASELINE`."""
    labels = [c.label for c in contenders]
    if len(set(labels)) != len(labels):
        raise ValueError(f"two models share a label: {labels}")
    references = references_of(contenders, against)
    unknown = sorted(set(references.values()) - set(labels))
    if unknown:
        raise ValueError(f"reference(s) {unknown} are not among the models {labels}")
    errors = window_errors(contenders, runs, horizons, integrator, on_done)
    verdicts = {label: judge(paired_cells(errors, label, reference), rule, model=label, baseline=reference)
                for label, reference in references.items()}
    return Comparison(_table(contenders, errors, verdicts, references), verdicts, references, against,
                      tuple(float(h) for h in horizons), tuple(errors))


def _table(contenders: Sequence[Contender], errors: Sequence[WindowErrors], verdicts: Mapping[str, Judgement],
           references: Mapping[str, str]) -> pd.DataFrame:
    decided = {label: {(c.log, c.horizon_s, c.channel): c for c in j.cells} for label, j in verdicts.items()}
    rows = []
    for e in errors:
        for j, channel in enumerate(CHANNELS):
            for c in contenders:
                err = e.errors[c.label][..., j]                       # (M, W)
                per_member = np.sqrt(np.mean(err**2, axis=1)) if e.n_windows else np.full(len(c.members), np.nan)
                reference = references.get(c.label, "")
                cell = decided.get(c.label, {}).get((e.log, e.horizon_s, channel))
                rows.append({
                    "log": e.log, "scenario": e.scenario, "horizon_s": e.horizon_s, "channel": channel,
                    "unit": UNITS[channel], "n_windows": e.n_windows, "model": c.label, "n_members": len(c.members),
                    "rmse": float(np.sqrt(np.mean(err**2))) if e.n_windows else math.nan,
                    "rmse_std": float(np.std(per_member, ddof=1)) if len(per_member) > 1 else math.nan,
                    "reference": reference,
                    "reference_rmse": cell.baseline_rmse if cell else math.nan,
                    "change": cell.change if cell else math.nan,
                    "change_low": cell.change_low if cell else math.nan,
                    "change_high": cell.change_high if cell else math.nan,
                    "decision": cell.decision.value if cell else ("reference" if not reference else ""),
                })
    return pd.DataFrame(rows, columns=TABLE_COLUMNS)


def judge_against_baselines(model: Contender, baselines: Sequence[Contender], runs: Sequence[Run],
                            horizons: Sequence[float], integrator: Integrator = EULER,
                            rule: VerdictRule = DEFAULT_RULE) -> tuple[list[WindowErrors], dict[str, Judgement]]:
    """A model beside each of its physics baselines on the same windows (``sysid evaluate
    RUN``): the per-window errors of all of them, and the model's `Judgement` against each
    baseline (label -> judgement)."""
    errors = window_errors([model, *baselines], runs, horizons, integrator)
    return errors, {b.label: judge(paired_cells(errors, model.label, b.label), rule, model=model.label,
                                   baseline=b.label) for b in baselines}


def metrics_of(errors: Sequence[WindowErrors], label: str) -> pd.DataFrame:
    """The protocol's metrics table (`sysid.evaluation.evaluate.METRICS_COLUMNS`) of one
    model from its per-window errors: RMSE pooled over every window point (members pooled)."""
    from sysid.evaluation.evaluate import METRICS_COLUMNS

    rows = []
    for e in errors:
        err = e.errors[label]
        rmse = np.sqrt(np.mean(err**2, axis=(0, 1))) if e.n_windows else np.full(3, np.nan)
        rows.append({"scenario": e.scenario, "file": e.log, "horizon_s": e.horizon_s,
                     "n_windows": e.n_windows, "rmse_u": rmse[0], "rmse_v": rmse[1], "rmse_r": rmse[2]})
    return pd.DataFrame(rows, columns=METRICS_COLUMNS)
