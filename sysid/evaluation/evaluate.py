"""All evaluation: windowed predictions, the protocol's RMSE table (docs: the paper's protocol, the metric)
and the per-step traces behind the report's figures.

Every window of every file is integrated in one batched call: each window starts from the
recorded state at its first sample, runs H-1 Euler steps of dt = 1 s with the recorded
inputs held over each step, and is scored at its H points (first included) on u, v_m, r,
pooled over the windows of a file. Each window's own RMSE (`WindowErrors`) feeds the verdict
(`sysid.evaluation.judgement`); a window whose prediction diverged
(`sysid.evaluation.divergence`) marks its row ``diverged`` and keeps it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import torch
from torch import nn

from sysid.data.recordings import Run, protocol_windows, stack_windows
from sysid.data.scenario import scenario_of
from sysid.dynamics.equations import eager_predict
from sysid.hybrid.rollout_gate import with_rollout_gate
from sysid.dynamics.integrators import EULER, Integrator
from sysid.config.checks import whole_samples
from sysid.errors import DataError
from sysid.evaluation.divergence import PhysicalRange, diverged_windows
from sysid.evaluation.judgement import Divergence
from sysid.records.columns import (METRICS_COLUMNS, REQUIRED_METRICS_COLUMNS, TRACE_COLUMNS,  # noqa: F401 (their home before)
                                   trace_name)
from sysid.channel_names import FORCE, FORCE_COMPONENTS, INPUTS, STATE, VELOCITY_INDEX



@dataclass
class WindowPrediction:
    """Predictions of all windows of one file at one horizon.

    observed, predicted : (H, W, 6) states; inputs : (H, W, 4); starts : (W,) sample
    indices of the windows; t : (H, W) time [s].
    """

    run: Run
    horizon: int
    starts: np.ndarray
    t: np.ndarray
    observed: torch.Tensor
    predicted: torch.Tensor
    inputs: torch.Tensor

    def metrics_row(self, horizon_s: float, divergence: Divergence | None = None) -> dict:
        """A `METRICS_COLUMNS` row (NaN RMSE without windows); the scenario is the
        protocol's name of a test file, else the maneuver the log records
        (`sysid.data.scenario.scenario_of`); `divergence` marks it."""
        rmse = self.rmse() if len(self.starts) else np.full(3, np.nan)
        return {"scenario": scenario_of(self.run), "file": self.run.name,
                "horizon_s": horizon_s, "n_windows": len(self.starts),
                "rmse_u": rmse[0], "rmse_v": rmse[1], "rmse_r": rmse[2],
                "diverged": divergence is not None,
                "diverged_at_s": divergence.time_s if divergence is not None else np.nan}

    def rmse(self) -> np.ndarray:
        """Pooled RMSE of (u [m/s], v_m [m/s], r [rad/s]) over every window point."""
        idx = list(VELOCITY_INDEX)
        err = (self.predicted[..., idx] - self.observed[..., idx]).reshape(-1, 3)
        return torch.sqrt((err**2).mean(0)).detach().cpu().numpy()

    def window_rmse(self) -> np.ndarray:
        """(W, 3) RMSE of (u [m/s], v_m [m/s], r [rad/s]) of each window over its H points:
        their mean square is the pooled `rmse`'s."""
        idx = list(VELOCITY_INDEX)
        err = self.predicted[..., idx] - self.observed[..., idx]
        return torch.sqrt((err**2).mean(0)).detach().cpu().numpy().reshape(-1, 3)

    def divergence(self, horizon_s: float, limits: PhysicalRange | None = None) -> Divergence | None:
        """Where this file's prediction first diverged, by the one rule (`diverged_windows`,
        against the training range `limits`; None: non-finite only), or None."""
        return diverged_windows(self.predicted.detach().cpu().numpy(), self.t, self.run.name,
                                horizon_s, limits, self.observed.detach().cpu().numpy())[1]

    def errors(self, horizon_s: float, limits: PhysicalRange | None = None) -> "WindowErrors":
        """This file's `WindowErrors` at `horizon_s`, divergence checked against `limits`."""
        return WindowErrors(scenario_of(self.run), self.run.name, float(horizon_s),
                            np.asarray(self.t[0], dtype=float), self.window_rmse(), self.divergence(horizon_s, limits))


@dataclass(frozen=True, eq=False)
class WindowErrors:
    """One file at one horizon, window by window: start time [s] (W,), RMSE of u, v_m [m/s]
    and r [rad/s] (W, 3), and where its prediction diverged (None: it did not)."""

    scenario: str
    file: str
    horizon_s: float
    start_s: np.ndarray
    rmse: np.ndarray
    divergence: Divergence | None = None


def predict_windows(model: nn.Module, runs: Sequence[Run], horizon_s: float,
                    integrator: Integrator = EULER, dtype=torch.float64,
                    device: str | torch.device = "cpu") -> list[WindowPrediction]:
    """Predict the protocol windows of every run in one batched integration (compiled
    when `integrator` is compiled: only then is `sysid.fast` imported)."""
    predict: Callable[..., torch.Tensor] = eager_predict
    if integrator.compiled:
        from sysid.fast.compiled import predict
    chunks, meta = [], []
    dt = None
    for run in runs:
        if dt is None:
            dt = run.dt
        elif abs(run.dt - dt) > 1e-9:
            raise DataError(f"{run.path}: sample period {run.dt} s differs from {dt} s of the other files")
        H = window_samples("horizon", horizon_s, run.dt, DataError)
        starts = protocol_windows(len(run), H)
        meta.append((run, H, starts))
        if len(starts):
            chunks.append(stack_windows(run, starts, H, dtype, device))
    if not meta:
        return []
    if chunks:
        observed = torch.cat([c[0] for c in chunks], 1)
        inputs = torch.cat([c[1] for c in chunks], 1)
        # eager: the kNN gate's decisions along the rollout from earlier steps' scans (`RolloutGate`)
        predicted = predict(model if integrator.compiled else with_rollout_gate(model), observed[0], inputs, dt,
                            integrator)
    out, col = [], 0
    for run, H, starts in meta:
        W = len(starts)
        sl = slice(col, col + W)
        col += W
        t = run.t[starts[None, :] + np.arange(H)[:, None]] if W else np.zeros((H, 0))
        if W:
            out.append(WindowPrediction(run, H, starts, t, observed[:, sl], predicted[:, sl], inputs[:, sl]))
        else:
            empty = torch.zeros(H, 0, 6, dtype=dtype)
            out.append(WindowPrediction(run, H, starts, t, empty, empty, torch.zeros(H, 0, 4, dtype=dtype)))
    return out


def short_runs(runs: Sequence[Run], horizons: Sequence[float], name: str = "--horizon",
               error: type[Exception] = DataError) -> list[tuple[Run, float]]:
    """(run, horizon [s]) pairs where the run holds fewer samples than one window: their
    metrics rows would be empty. Every horizon must be a whole number of every run's
    samples, at least two: a window of one sample is its start state alone, no step is
    predicted and its RMSE is 0 by construction (else `error` naming `name`)."""
    for h in horizons:
        for run in runs:
            window_samples(name, h, run.dt, error)
    return [(run, h) for h in horizons for run in runs if len(run) < whole_samples(name, h, run.dt, error)]


def window_samples(name: str, horizon_s: float, dt: float, error: type[Exception] = DataError) -> int:
    """The samples of one window of `horizon_s` [s] (its start state and H - 1 predicted
    steps, `dt` [s] apart): a whole number >= 2, else `error` naming `name`."""
    H = whole_samples(name, horizon_s, dt, error)
    if H < 2:
        raise error(f"{name} {horizon_s:g}: a window of one {dt:g}-s sample is its start state alone, so "
                    f"nothing is predicted and its RMSE is 0; give a horizon of at least {2 * dt:g} s")
    return H


@dataclass
class Evaluation:
    """Metrics (`METRICS_COLUMNS`), traces (file name -> `TRACE_COLUMNS` frame), the
    share of steps on which the kNN gate switched the FNN off, per trace name (file and
    horizon; without traces, only for a model with a gate), and every file's
    per-window errors at every horizon (`WindowErrors`, in the metrics' row order)."""

    metrics: pd.DataFrame
    traces: dict[str, pd.DataFrame]
    gate_off_share: dict[str, float]
    windows: list[WindowErrors] = field(default_factory=list)

    @property
    def divergences(self) -> list[Divergence]:
        """Where a prediction diverged, per file and horizon."""
        return [w.divergence for w in self.windows if w.divergence is not None]


def trace_frame(model: nn.Module, pred: WindowPrediction) -> pd.DataFrame:
    """Per-step table of one file's windows: record, prediction, inputs, forces, gate."""
    H, W = pred.predicted.shape[:2]
    with torch.no_grad():
        f = model(pred.predicted, pred.inputs)
    cols: dict[str, np.ndarray] = {
        "window": np.repeat(np.arange(W)[None, :], H, 0), "t": pred.t,
        "t_rel": pred.t - pred.t[:1]}
    for j, c in enumerate(STATE):
        cols[f"obs_{c}"] = pred.observed[..., j].numpy()
        cols[f"pred_{c}"] = pred.predicted[..., j].numpy()
    for j, c in enumerate(INPUTS):
        cols[c] = pred.inputs[..., j].numpy()
    cols["wind_velo_relative"] = f.relative_wind[..., 0].numpy()
    cols["wind_dir_relative"] = f.relative_wind[..., 1].numpy()
    for component, key in FORCE_COMPONENTS.items():
        for j, a in enumerate(FORCE):
            cols[f"{a}{key}"] = getattr(f, component)[..., j].numpy()
    cols["knn_distance"] = f.ood_distance.numpy() if f.ood_distance is not None else np.full((H, W), np.nan)
    cols["gate_on"] = f.gate_on.numpy().astype(int) if f.gate_on is not None else np.ones((H, W), dtype=int)
    # rows ordered window by window, then time
    frame = pd.DataFrame({k: np.asarray(v).T.reshape(-1) for k, v in cols.items()})
    return frame[TRACE_COLUMNS]


def predicted_gate_off_share(model: nn.Module, pred: WindowPrediction) -> float | None:
    """Share of one file's window points (each window's start state and predicted states,
    as its trace's ``gate_on``) at which the model's kNN gate switches its FNN off; None
    for a model without a gate."""
    with torch.no_grad():
        on = model(pred.predicted, pred.inputs).gate_on
    return None if on is None else float(1.0 - on.double().mean())


def evaluate_model(model: nn.Module, runs: Sequence[Run], horizons: Sequence[float],
                   integrator: Integrator = EULER, traces: bool = True,
                   limits: PhysicalRange | None = None) -> Evaluation:
    """The protocol's windowed RMSE per file and horizon, with per-step traces and per-window
    errors; a prediction non-finite or beyond `limits` (the training logs' range) is marked
    diverged in its row."""
    rows, frames, shares, windows = [], {}, {}, []
    for horizon in horizons:
        for pred in predict_windows(model, runs, horizon, integrator):
            errors = pred.errors(horizon, limits)
            windows.append(errors)
            rows.append(pred.metrics_row(horizon, errors.divergence))
            if traces and len(pred.starts):
                frame = trace_frame(model, pred)
                name = trace_name(pred.run.name, horizon)
                frames[name] = frame
                shares[name] = float(1.0 - frame["gate_on"].mean())
            elif len(pred.starts) and (share := predicted_gate_off_share(model, pred)) is not None:
                shares[trace_name(pred.run.name, horizon)] = share
    return Evaluation(pd.DataFrame(rows, columns=METRICS_COLUMNS), frames, shares, windows)
