"""Windowed predictions and the protocol's RMSE table (BENCHMARK_PROTOCOL.md).

Every window of every file is integrated in one batched call: each window starts from the
recorded state at its first sample, runs H-1 Euler steps of dt = 1 s with the recorded
inputs held over each step, and is scored at its H points (first included) on u, v_m, r,
pooled over the windows of a file.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pandas as pd
import torch
from torch import nn

from sysid.data import Run, protocol_windows, stack_windows
from sysid.compiled import predict
from sysid.integrators import IntegratorLike
from sysid.state import VELOCITY_INDEX

METRIC_COLUMNS = ["file", "horizon_s", "n_windows", "rmse_u", "rmse_v", "rmse_r"]


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

    def metrics_row(self, horizon_s: float) -> dict:
        """``file, horizon_s, n_windows, rmse_u, rmse_v, rmse_r`` (NaN RMSE without windows)."""
        rmse = self.rmse() if len(self.starts) else np.full(3, np.nan)
        return {"file": self.run.name, "horizon_s": horizon_s, "n_windows": len(self.starts),
                "rmse_u": rmse[0], "rmse_v": rmse[1], "rmse_r": rmse[2]}

    def rmse(self) -> np.ndarray:
        """Pooled RMSE of (u [m/s], v_m [m/s], r [rad/s]) over every window point."""
        idx = list(VELOCITY_INDEX)
        err = (self.predicted[..., idx] - self.observed[..., idx]).reshape(-1, 3)
        return torch.sqrt((err**2).mean(0)).detach().cpu().numpy()


def predict_windows(model: nn.Module, runs: Sequence[Run], horizon_s: float,
                    method: IntegratorLike = "euler", dtype=torch.float64,
                    device: str | torch.device = "cpu") -> list[WindowPrediction]:
    """Predict the protocol windows of every run in one batched integration."""
    chunks, meta = [], []
    dt = None
    for run in runs:
        if dt is None:
            dt = run.dt
        elif abs(run.dt - dt) > 1e-9:
            raise ValueError(f"{run.path}: sample period {run.dt} s differs from {dt} s of the other files")
        H = int(round(horizon_s / run.dt))
        starts = protocol_windows(len(run), H)
        meta.append((run, H, starts))
        if len(starts):
            chunks.append(stack_windows(run, starts, H, dtype, device))
    if not meta:
        return []
    if chunks:
        observed = torch.cat([c[0] for c in chunks], 1)
        inputs = torch.cat([c[1] for c in chunks], 1)
        predicted = predict(model, observed[0], inputs, dt, method)
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


def metrics_table(model: nn.Module, runs: Sequence[Run], horizons: Sequence[float],
                  method: IntegratorLike = "euler", **kwargs) -> pd.DataFrame:
    """Rows ``file, horizon_s, n_windows, rmse_u, rmse_v, rmse_r`` per file and horizon."""
    rows = []
    for horizon in horizons:
        rows += [pred.metrics_row(horizon) for pred in predict_windows(model, runs, horizon, method, **kwargs)]
    return pd.DataFrame(rows, columns=METRIC_COLUMNS)
