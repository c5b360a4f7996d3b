"""The identified ship replayed through raw logs and the preprocessing: the bias that the
processing itself puts into identified coefficients, estimated by simulation.

The prescribed preprocessing smooths (0.2 Hz zero-phase low-pass on the FOG, 2-s central
differences of the positions, Kalman/RTS on the velocities). Where the motion has kinks
(a rudder step) the processed states are rounded off, and identification from them is
biased by a fixed amount that no noise-based sigma contains. That amount can be measured:
integrate the *identified* model under the runs' logged 10 Hz inputs, write raw logs from
it with the synthesiser (`preprocessing.synth`, the ship file's sensor layout, noise as
set), process them by the same pipeline, identify again from the identified values; the
difference again - identified estimates the bias at the identified values (a parametric
bootstrap; the bias changes slowly with the coefficients), and identified - bias is the
corrected estimate.
"""
from __future__ import annotations

import tempfile
from types import SimpleNamespace
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import torch
from torch import nn

from preprocessing import writer
from preprocessing.pipeline import Pipeline
from preprocessing.sensors import SensorLayout
from preprocessing.synth import SynthSettings, synthesise
from sysid.data.recordings import read_run, sliding_windows, stack_windows
from sysid.dynamics.equations import integrate
from sysid.mmg.wind import relative_wind

STATE_COLUMNS = ("x_position_mid", "u_velo", "y_position_mid", "vm_velo", "psi_hat", "r_angvelo")


def noise_free(run_index: int) -> SynthSettings:
    """Synthesiser settings with every noise source off (GNSS, FOG noise and drift,
    anemometers): the replay then measures the processing's deterministic bias."""
    return SynthSettings(seed=run_index, gnss_noise=0.0, gnss_correlated=0.0, fog_drift=0.0, fog_noise=0.0,
                         anemo_speed_noise=0.0, anemo_dir_noise=0.0)


def replay_run(model: nn.Module, logged: pd.DataFrame, start: Sequence[float] | np.ndarray) -> pd.DataFrame:
    """The model's motion under a run's logged inputs, as a processed-schema truth.

    logged : processed-schema columns (bare names) at the log's rate (uniform t [s]):
        n_prop [rps], delta_rudder [rad], wind_velo_true [m/s], wind_dir_true [rad]
        (each held over its sample interval); other columns are copied.
    start : (6,) state (x, u, y, v_m, psi, r) at the first sample [m, m/s, m, m/s, rad, rad/s].
    Returns a copy of `logged` with the six state columns and the relative wind replaced
    by the model's (RK4 with the log's sample interval).
    """
    t = logged["t"].to_numpy(float)
    dt = float(np.median(np.diff(t)))
    inputs = torch.tensor(logged[["n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true"]].to_numpy(float),
                          dtype=torch.float64)
    with torch.no_grad():
        s = integrate(model, torch.tensor(np.array(start, dtype=float)), inputs, dt, "rk4").numpy()
    wind_speed, wind_dir = (torch.tensor(logged[c].to_numpy(float)) for c in ("wind_velo_true", "wind_dir_true"))
    U_A, gamma_A = relative_wind(torch.tensor(s[:, 1]), torch.tensor(s[:, 3]), torch.tensor(s[:, 4]),
                                 wind_speed, wind_dir)
    out = logged.copy()
    for k, column in enumerate(STATE_COLUMNS):
        out[column] = s[:, k]
    out["wind_velo_relative_mid"], out["wind_dir_relative_mid"] = U_A.numpy(), gamma_A.numpy()
    return out


def processed_windows(truths: dict[str, pd.DataFrame], layout: SensorLayout, window: int,
                      settings: Callable[[int], SynthSettings]) -> SimpleNamespace:
    """Raw logs synthesised from each truth (run i with `settings(i)`), processed by
    `Pipeline(layout)` to 1 Hz, cut into consecutive windows of `window` steps (sharing their
    boundary sample): ``states`` (window+1, W, 6), ``inputs`` (window+1, W, 4), ``dt`` = 1 s,
    ``first`` {run name: first processed state (6,)}."""
    states, inputs, first = [], [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for i, (name, truth) in enumerate(truths.items()):
            raw = synthesise(truth, layout, settings(i)).raw
            result = Pipeline(layout).run(raw, name)
            for path in writer.write_segments(tmp, name, result.segments, result.report):
                if path.suffix != ".csv":
                    continue
                processed = read_run(path)
                first.setdefault(name, processed.states[0])
                starts = sliding_windows(len(processed), window + 1, window)
                s, u = stack_windows(processed, starts, window + 1)
                states.append(s)
                inputs.append(u)
    return SimpleNamespace(states=torch.cat(states, 1), inputs=torch.cat(inputs, 1), dt=1.0, first=first)


def processing_bias(model: nn.Module, identify: Callable[[SimpleNamespace], dict[str, float]],
                    logged: dict[str, pd.DataFrame], first: dict[str, np.ndarray], layout: SensorLayout,
                    window: int, settings: Sequence[Callable[[int], SynthSettings]]) -> tuple[dict[str, float], np.ndarray]:
    """Bias of identification through raw logs at the model's coefficients.

    model : the identified model (replayed; left unchanged).
    identify : windows -> {name: estimate}, started from the identified values.
    logged : {run name: logged inputs at 10 Hz (see `replay_run`)}; first : {run name: (6,)
        processed first state, the replay's start}.
    settings : one synthesiser setting per replicate (run index -> SynthSettings); noise-free
        settings measure the processing's deterministic part, noisy ones the whole bias.
    Returns the mean over replicates of (estimate - identified) per name, and the
    replicates' estimates (B, p).
    """
    truths = {name: replay_run(model, run, first[name]) for name, run in logged.items()}
    estimates = []
    for setting in settings:
        estimates.append(identify(processed_windows(truths, layout, window, setting)))
    names = list(estimates[0])
    again = np.array([[e[n] for n in names] for e in estimates])
    now = np.array([float(getattr(model.coefficients, n)) for n in names])
    return dict(zip(names, (again.mean(0) - now).tolist())), again
