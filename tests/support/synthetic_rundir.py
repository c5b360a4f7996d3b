"""Synthetic run and reproduction directories following `sysid.runs.layout`, for report tests.

"Measured" runs are simulated with a perturbed MMG (no real data needed); the MMG runs
predict with the bundled ship, NN and hybrid runs are made-up blends of the measurement
and the MMG prediction. Forces, relative wind and kNN gate traces are filled in so every
figure of the report has data.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from sysid import MMG, integrate, load_ship
from sysid.data.recordings import Run
from sysid.evaluation.evaluate import predict_windows
from sysid.store.manifest import write_manifest
from sysid.mmg.wind import relative_wind
from sysid.evaluation.evaluate import REQUIRED_METRICS_COLUMNS, TRACE_COLUMNS, trace_name
from sysid.protocol.paper import COMPARISON_COLUMNS

DEG = math.pi / 180.0
SCENARIOS = {  # scenario -> (file stem, duration [s])
    "Berthing": ("berthing_12-Nov-2020_11_49_21", 128),
    "Turning 20": ("turn_14-Oct-2020_14_56_07", 311),
    "Turning 35": ("turn_14-Sep-2020_14_50_41", 520),
    "Zigzag 20/20": ("zigzag_31-Jul-2020_13_04_24", 140),
    "Zigzag 30/30": ("zigzag_31-Jul-2020_13_14_21", 121),
    "Random": ("random_06-Aug-2020_16_24_25_1", 672),
}
RUNS = {  # run name -> (model, dataset, error factor of the MMG blend)
    "mmg_paper": ("mmg", "-", None), "mmg_lab": ("mmg", "-", None),
    "nn_D1": ("nn", "D1", 0.6), "nn_D2": ("nn", "D2", 0.45),
    "hybrid_D1": ("hybrid", "D1", 0.4), "hybrid_D2": ("hybrid", "D2", 0.3),
}
KNN_THRESHOLD = 1.0


def _inputs(scenario: str, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 4) n_prop [rps], delta [rad], true wind speed [m/s] and direction [rad]."""
    n = np.full_like(t, 10.0)
    delta = np.zeros_like(t)
    if scenario == "Berthing":
        n = np.clip(6.0 - t / 20.0, 0.0, None)
        delta = 25 * DEG * np.sin(t / 15.0)
    elif scenario.startswith("Turning"):
        angle = 20 if scenario.endswith("20") else -35
        n = np.full_like(t, 10.0 if angle == 20 else 8.0)
        delta = np.where(t > 10, -angle * DEG if angle == 20 else 35 * DEG, 0.0)
    elif scenario.startswith("Zigzag"):
        amp = 20 if "20/" in scenario else 30
        n = np.full_like(t, 16.67)
        delta = amp * DEG * np.sign(np.sin(2 * math.pi * t / (60 if amp == 20 else 70)) + 1e-9)
    else:
        steps = (t // 20).astype(int)
        levels = rng.uniform(-35, 35, steps.max() + 1) * DEG
        revs = rng.uniform(4, 14, steps.max() + 1)
        delta, n = levels[steps], revs[steps]
    wind_speed = 1.5 + 0.5 * np.sin(t / 40.0)
    wind_dir = (1.0 + 0.3 * np.sin(t / 90.0)) % (2 * math.pi)
    return np.stack([n, delta, wind_speed, wind_dir], 1)


def measured_runs(scale: float = 1.0, seed: int = 0) -> dict[str, Run]:
    """A simulated 1 Hz run per scenario (durations times `scale`)."""
    rng = np.random.default_rng(seed)
    truth = MMG(load_ship("esso_osaka", {"C_D": 1.3, "X_0F": -0.03, "N_r": -0.055}))
    runs = {}
    for scenario, (stem, duration) in SCENARIOS.items():
        t = np.arange(max(101, int(duration * scale)), dtype=float)
        inputs = _inputs(scenario, t, rng)
        x0 = torch.tensor([0.0, 0.5, 0.0, 0.0, 0.3, 0.0], dtype=torch.float64)
        with torch.no_grad():
            states = integrate(truth, x0, torch.as_tensor(inputs), 1.0).numpy()
        states[:, [1, 3, 5]] += rng.normal(0, [0.002, 0.002, 0.0005], (len(t), 3))
        runs[scenario] = Run(stem, Path(f"{stem}.csv"), t, states, inputs,
                             np.zeros((len(t), 2)), 1.0)
    return runs


def _trace(run: Run, horizon: int, model: MMG, kind: str, factor: float | None,
           dataset: str, scenario: str, rng: np.random.Generator) -> pd.DataFrame:
    pred = predict_windows(model, [run], horizon)[0]
    obs = pred.observed
    diff = pred.predicted - obs
    diff[..., 4] = torch.atan2(torch.sin(diff[..., 4]), torch.cos(diff[..., 4]))  # heading may wrap
    predicted = pred.predicted if factor is None else obs + factor * diff
    H, W = predicted.shape[:2]
    with torch.no_grad():
        forces = model(predicted, pred.inputs)
        measured_forces = model(obs, pred.inputs)
    wind = relative_wind(predicted[..., 1], predicted[..., 3], predicted[..., 4],
                         pred.inputs[..., 2], pred.inputs[..., 3])
    cols: dict[str, np.ndarray] = {
        "window": np.repeat(np.arange(W)[None], H, 0), "t": pred.t,
        "t_rel": np.repeat(np.arange(H, dtype=float)[:, None], W, 1)}
    for i, c in enumerate(("x", "u", "y", "v", "psi", "r")):
        cols[f"obs_{c}"] = obs[..., i].numpy()
        cols[f"pred_{c}"] = predicted[..., i].numpy()
    for i, c in enumerate(("n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true")):
        cols[c] = pred.inputs[..., i].numpy()
    cols["wind_velo_relative"] = wind.U_A.numpy()
    cols["wind_dir_relative"] = wind.gamma_A.numpy()
    parts = {"H": forces.hull, "P": forces.propeller, "R": forces.rudder, "A": forces.wind}
    correction = 0.3 * (measured_forces.mmg - forces.mmg) + 0.05 * forces.hull
    if kind == "nn":
        parts = {k: torch.zeros_like(v) for k, v in parts.items()}
        correction = forces.mmg + correction
    elif kind == "mmg":
        correction = torch.zeros_like(correction)
    knn = np.full((H, W), np.nan)
    gate = np.ones((H, W))
    if kind == "hybrid":
        spread = 1.6 if (dataset == "D1" and scenario == "Random") else 0.7
        knn = np.abs(spread + 0.5 * np.sin(pred.t / 17.0) + rng.normal(0, 0.1, (H, W)))
        gate = (knn < KNN_THRESHOLD).astype(float)
        correction = correction * torch.as_tensor(gate)[..., None]
    parts["NN"] = correction
    for key, value in parts.items():
        for j, axis in enumerate("XYN"):
            cols[f"{axis}{key}"] = value[..., j].numpy()
    cols["knn_distance"], cols["gate_on"] = knn, gate
    frame = pd.DataFrame({k: np.asarray(v).reshape(-1) for k, v in cols.items()})
    return frame.sort_values(["window", "t_rel"], kind="stable")[TRACE_COLUMNS]


def write_run(out: Path, name: str, runs: dict[str, Run], horizons=(30, 100), seed: int = 0) -> Path:
    """A run directory `out` for run `name` of `RUNS`."""
    rng = np.random.default_rng(seed)
    kind, dataset, factor = RUNS[name]
    overrides = {"X_vr": 0.4535} if name == "mmg_paper" else {}
    model = MMG(load_ship("esso_osaka", overrides))
    (out / "traces").mkdir(parents=True, exist_ok=True)
    rows = []
    for scenario, run in runs.items():
        for horizon in horizons:
            trace = _trace(run, horizon, model, kind, factor, dataset, scenario, rng)
            trace.to_csv(out / "traces" / trace_name(run.name, horizon), index=False)
            err = trace[["pred_u", "pred_v", "pred_r"]].to_numpy() - trace[["obs_u", "obs_v", "obs_r"]].to_numpy()
            rmse = np.sqrt((err ** 2).mean(0))
            rows.append([scenario, run.name, horizon, int(trace["window"].nunique()), *rmse])
    pd.DataFrame(rows, columns=REQUIRED_METRICS_COLUMNS).to_csv(out / "metrics.csv", index=False)
    summary = {"name": name, "model": kind, "dataset": dataset if kind != "mmg" else None,
               "ship": "esso_osaka", "seed": seed, "created": "2026-11-22T05:00:00Z",
               "train_seconds": 0.0 if kind == "mmg" else 123.4,
               "epochs": 0 if kind == "mmg" else 40, "best_epoch": 0 if kind == "mmg" else (21 if kind == "hybrid" else 31),
               "n_train_windows": 0 if kind == "mmg" else 2500, "n_val_windows": 0 if kind == "mmg" else 1070,
               "versions": {"sysid": "0.1.0", "torch": torch.__version__, "python": "3.11"},
               "mmg_overrides": overrides, "identified": {},
               "gate": {"k": 10, "alpha": 0.95, "threshold": KNN_THRESHOLD} if kind == "hybrid" else {}}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "config.toml").write_text(
        f'[experiment]\nname = "{name}"\nmodel = "{kind}"\ndataset = "{dataset}"\nship = "esso_osaka"\n\n'
        '[train]\nepochs = 40\nlearning_rate = 0.001\nbatch_size = 64\nwindow = 5\nstride_s = 2\n'
        'validation_share = 0.3\n\n[model]\nhidden = [64, 64]\nactivation = "tanh"\n')
    if kind != "mmg":
        epochs = np.arange(1, 41)
        train = 0.02 * np.exp(-epochs / 8) + 0.002
        stage = np.where(epochs <= 10, "mmg", "fnn") if kind == "hybrid" else np.full(len(epochs), "train")
        epochs = np.where(epochs <= 10, epochs, epochs - 10) if kind == "hybrid" else epochs
        history = pd.DataFrame({"stage": stage, "epoch": epochs, "train_loss": train, "early_stopping_loss": train * 1.3,
                                "train_velocity": train * 0.9, "train_penalty": train * 0.1,
                                "seconds": epochs * 3.0})
        history.to_csv(out / "history.csv", index=False)
    if kind == "hybrid":
        torch.save({"bank": torch.randn(50, 64), "threshold": torch.tensor(KNN_THRESHOLD),
                    "k": torch.tensor(10), "alpha": torch.tensor(0.95)}, out / "knn.pt")
    write_manifest(out, "run")  # complete, as `sysid train` seals it
    return out


def write_reproduction(out: Path, scale: float = 1.0, names=tuple(RUNS)) -> Path:
    """A reproduction directory: runs/, comparison.csv, summary.json."""
    from sysid.protocol.paper import paper_rmse
    runs = measured_runs(scale)
    rows = []
    for i, name in enumerate(names):
        run_dir = write_run(out / "runs" / name, name, runs, seed=i)
        kind, dataset, _ = RUNS[name]
        for m in pd.read_csv(run_dir / "metrics.csv").itertuples(index=False):
            paper = paper_rmse(m.scenario, kind, dataset, m.horizon_s) or (np.nan,) * 3
            rows.append([m.scenario, name, dataset, m.horizon_s, m.rmse_u, m.rmse_v, m.rmse_r, *paper,
                         np.nan, np.nan, np.nan, 1])
    pd.DataFrame(rows, columns=COMPARISON_COLUMNS).to_csv(out / "comparison.csv", index=False)
    (out / "summary.json").write_text(json.dumps(
        {"total_seconds": 987.6, "gate_share_on": {"hybrid_D1": 0.62, "hybrid_D2": 0.91},
         "wins_against_paper": "n/a (synthetic)", "runs": list(names), "protocol": list(RUNS)}, indent=2))
    write_manifest(out, "reproduction")
    return out
