"""Run directories as artefacts: save, reload, evaluate (layout in `sysid.rundir`).

Everything is plain tensors, JSON, TOML and CSV: a run reloads with
``torch.load(..., weights_only=True)`` and predicts exactly what it predicted when saved.
"""
from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd
import torch

from sysid.correction import INPUT_NAMES, OUTPUT_NAMES, ForceCorrection
from sysid.data import Run
from sysid.datasets import TEST_FILES
from sysid.errors import CheckpointError, ConfigError
from sysid.evaluate import predict_windows
from sysid.experiment import Experiment, load_experiment, ship_overrides
from sysid.files import atomic_path, write_csv, write_text
from sysid.mmg.model import MMG
from sysid.models import CorrectedModel
from sysid.ood import KNNGate
from sysid.rundir import METRICS_COLUMNS, TRACE_COLUMNS, trace_name
from sysid.ship import load_ship

SCENARIO_OF = {Path(v).stem: k for k, v in TEST_FILES.items()}


def versions() -> dict[str, str]:
    import numpy, pandas, scipy, torchdiffeq
    from sysid import __version__
    return {"sysid": __version__, "python": platform.python_version(), "torch": torch.__version__,
            "torchdiffeq": getattr(torchdiffeq, "__version__", "?"), "numpy": numpy.__version__,
            "pandas": pandas.__version__, "scipy": scipy.__version__}


def build_model(exp: Experiment, dtype: torch.dtype = torch.float64) -> torch.nn.Module:
    """An untrained model with the experiment's structure (MMG, NN-only or hybrid)."""
    ship = load_ship(exp.experiment.ship, ship_overrides(exp))
    identify = list(exp.identify.parameters)
    bounds = {k: tuple(v) for k, v in exp.identify.bounds.items() if k in identify}
    mmg = MMG(ship, trainable=identify, bounds=bounds or None, dtype=dtype)
    if exp.experiment.model == "mmg":
        return mmg
    net = ForceCorrection(exp.network.hidden, dtype, exp.network.members)
    return CorrectedModel(mmg, net, None, physics=exp.experiment.model == "hybrid", gate_space=exp.gate.space)


def _save_tensors(obj, path: Path) -> None:
    with atomic_path(path, ".pt") as tmp:
        torch.save(obj, tmp)


def _load_tensors(path: Path):
    if not path.is_file():
        raise CheckpointError(f"{path}: missing (the run directory is incomplete)")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated, not a torch file, unsafe pickle
        raise CheckpointError(f"{path}: cannot be loaded safely ({type(exc).__name__}: {exc})") from None


def model_state(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """State dict without the kNN bank (stored on its own in knn.pt)."""
    return {k: v.detach().cpu() for k, v in model.state_dict().items() if not k.startswith("gate.")}


def save_model(model: torch.nn.Module, run_dir: Path) -> None:
    """model.pt, standardization.json and knn.pt of a trained model."""
    if isinstance(model, MMG) and not model.coefficients.trainable_names:
        return
    _save_tensors(model_state(model), run_dir / "model.pt")
    if isinstance(model, CorrectedModel):
        net = model.correction_net
        stats = {"inputs": list(INPUT_NAMES), "outputs": list(OUTPUT_NAMES),
                 "input_mean": net.input_mean.tolist(), "input_std": net.input_std.tolist(),
                 "output_mean": net.output_mean.tolist(), "output_std": net.output_std.tolist(),
                 "units": {"outputs": "N, N, N m"}}
        write_text(json.dumps(stats, indent=2), run_dir / "standardization.json")
        if model.gate is not None:
            g = model.gate
            _save_tensors({"bank": g.bank.cpu(), "threshold": g.threshold.cpu(),
                           "train_distances": g.train_distances.cpu(), "k": torch.tensor(g.k),
                           "alpha": torch.tensor(g.alpha, dtype=torch.float64)}, run_dir / "knn.pt")


def load_model(run_dir: str | os.PathLike, dtype: torch.dtype = torch.float64):
    """(experiment, model) of a run directory; clear errors for a missing or corrupt one."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise CheckpointError(f"{run_dir}: run directory not found")
    try:
        exp = load_experiment(run_dir / "config.toml")
    except ConfigError as exc:
        raise CheckpointError(f"{run_dir}: bad run config ({exc})") from None
    model = build_model(exp, dtype)
    if exp.experiment.model == "mmg" and not exp.identify.parameters:
        return exp, model
    state = _load_tensors(run_dir / "model.pt")
    if not isinstance(state, dict):
        raise CheckpointError(f"{run_dir / 'model.pt'}: not a state dict")
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        raise CheckpointError(f"{run_dir / 'model.pt'}: does not fit the config's model ({str(exc)[:300]})") from None
    if isinstance(model, CorrectedModel) and exp.gate.enabled:
        knn = _load_tensors(run_dir / "knn.pt")
        try:
            gate = KNNGate(int(knn["k"]), float(knn["alpha"]), knn["bank"].shape[1], dtype)
            gate.bank, gate.threshold = knn["bank"].to(dtype), knn["threshold"].to(dtype)
            gate.train_distances = knn["train_distances"].to(dtype)
        except (KeyError, TypeError, IndexError, AttributeError) as exc:
            raise CheckpointError(f"{run_dir / 'knn.pt'}: malformed kNN bank ({exc})") from None
        model.gate, model.gate_enabled = gate, True
    return exp, model


@dataclass
class Evaluation:
    """Metrics (METRICS_COLUMNS), traces (name -> DataFrame of TRACE_COLUMNS), gate shares."""

    metrics: pd.DataFrame
    traces: dict[str, pd.DataFrame]
    gate_off_share: dict[str, float]


def trace_frame(model, pred) -> pd.DataFrame:
    """Per-step table of one file's windows: record, prediction, inputs, forces, gate."""
    H, W = pred.predicted.shape[:2]
    with torch.no_grad():
        f = model(pred.predicted, pred.inputs)
    cols: dict[str, np.ndarray] = {
        "window": np.repeat(np.arange(W)[None, :], H, 0), "t": pred.t,
        "t_rel": pred.t - pred.t[:1]}
    for j, c in enumerate(("x", "u", "y", "v", "psi", "r")):
        cols[f"obs_{c}"] = pred.observed[..., j].numpy()
        cols[f"pred_{c}"] = pred.predicted[..., j].numpy()
    for j, c in enumerate(("n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true")):
        cols[c] = pred.inputs[..., j].numpy()
    cols["wind_velo_relative"] = f.relative_wind[..., 0].numpy()
    cols["wind_dir_relative"] = f.relative_wind[..., 1].numpy()
    for comp, key in (("hull", "H"), ("propeller", "P"), ("rudder", "R"), ("wind", "A"), ("correction", "NN")):
        for j, a in enumerate("XYN"):
            cols[f"{a}{key}"] = getattr(f, comp)[..., j].numpy()
    cols["knn_distance"] = f.ood_distance.numpy() if f.ood_distance is not None else np.full((H, W), np.nan)
    cols["gate_on"] = f.gate_on.numpy().astype(int) if f.gate_on is not None else np.ones((H, W), dtype=int)
    # rows ordered window by window, then time
    frame = pd.DataFrame({k: np.asarray(v).T.reshape(-1) for k, v in cols.items()})
    return frame[TRACE_COLUMNS]


def evaluate_model(model, runs: Sequence[Run], horizons: Sequence[float], integrator: str = "euler",
                   traces: bool = True) -> Evaluation:
    """The protocol's windowed RMSE per file and horizon, with per-step traces."""
    rows, frames, shares = [], {}, {}
    for horizon in horizons:
        for pred in predict_windows(model, runs, horizon, integrator):
            rows.append({"scenario": SCENARIO_OF.get(pred.run.name, ""), **pred.metrics_row(horizon)})
            if traces and len(pred.starts):
                frame = trace_frame(model, pred)
                name = trace_name(pred.run.name, horizon)
                frames[name] = frame
                shares[name] = float(1.0 - frame["gate_on"].mean())
    return Evaluation(pd.DataFrame(rows, columns=METRICS_COLUMNS), frames, shares)


def write_run(run_dir: str | os.PathLike, exp: Experiment, model, evaluation: Evaluation,
              history: pd.DataFrame | None = None, info: dict | None = None,
              seconds: float | None = None) -> Path:
    """Write a complete run directory (config, weights, kNN bank, history, metrics, traces)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    write_text(exp.to_toml(), run_dir / "config.toml")
    save_model(model, run_dir)
    if history is not None and len(history):
        write_csv(history, run_dir / "history.csv", float_format="%.6g")
    write_csv(evaluation.metrics, run_dir / "metrics.csv", float_format="%.6g")
    for name, frame in evaluation.traces.items():
        write_csv(frame, run_dir / "traces" / name, float_format="%.8g")
    info = dict(info or {})
    summary = {
        "name": exp.experiment.name, "model": exp.experiment.model,
        "dataset": "files" if exp.data.files else (
            "-" if exp.experiment.model == "mmg" and not exp.identify.parameters else exp.experiment.dataset),
        "ship": exp.experiment.ship, "seed": exp.experiment.seed,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "seconds": seconds,
        "train_seconds": info.pop("train_seconds", None),
        "epochs": int(history["epoch"].max()) if history is not None and len(history) else 0,
        "best_epoch": info.pop("best_epoch", None),
        "n_train_windows": info.pop("n_train_windows", None),
        "n_val_windows": info.pop("n_val_windows", None),
        "versions": versions(), "mmg_overrides": ship_overrides(exp),
        "identified": info.pop("identified", {}),
        "gate": {**info.pop("gate", {}), "off_share": evaluation.gate_off_share},
        "training": info,
    }
    write_text(json.dumps(summary, indent=2, default=str), run_dir / "summary.json")
    return run_dir
