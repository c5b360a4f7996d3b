"""Run directories: their layout, and saving and loading them (the contract between
`sysid.runs.lifecycle`, `sysid.evaluation.evaluate` and `sysid.report`).

A **run directory** (``sysid train CONFIG -o runs/NAME``)::

    config.toml        resolved experiment config (all defaults filled in)
    summary.json       {"name", "model": "mmg"|"nn"|"hybrid", "status": "complete"|"failed: ...",
                        "dataset": "D1"|"D2"|..., "ship", "seed", "created", "train_seconds",
                        "epochs", "best_epoch", "val_loss" (validation multi-step loss of
                        the final model), "stopped": {stage: "early stop"|"epoch limit"|...},
                        "n_train_windows", "n_val_windows", "versions": {...},
                        "mmg_overrides": {...}, "identified": {...}, "identified_initial": {...},
                        "identified_uncertainty": {names, estimate, std_error, correlation,
                        undetermined, ...} | null, "identification": {"solver":
                        "gradient"|"levenberg_marquardt", "start_states", "iterations"|"epochs",
                        ...} | null (the estimator of both), "gate": {...},
                        "training": {...}}
    model.pt           state dict (torch.save of plain tensors; weights_only=True safe)
    standardization.json  input/output mean and std of the FNN (Eqs. 8, 10)
    knn.pt             {"bank": (N, 64) features, "threshold": (), "k": (), "alpha": ()}
    history.csv        stage, epoch, train_loss, train_velocity, train_penalty, val_loss, seconds
    metrics.csv        `sysid.evaluation.evaluate.METRICS_COLUMNS`
    traces/            one CSV per (file, horizon): ``{file_stem}_h{H}.csv``, `TRACE_COLUMNS`
    manifest.json      written last: every other file with its SHA-256 (`sysid.store.manifest`)

Untrained MMG-only runs have no model.pt, knn.pt or history.csv. A run is written into a
staging directory and moved into place complete (`write_run`); readers refuse a run whose
manifest is missing or disagrees with its files (`verify_run_dir`).

A **reproduction directory** (``sysid reproduce -o OUTDIR``)::

    runs/{name}/        run directories (`sysid.protocol.reproduce.PROTOCOL`); with ``--seeds N`` a
                        learned run is a folder of N run directories ``seed{k}/``, and
                        ``runs/{variant}_ensemble_{dataset}/`` is their mean-of-seeds
                        ensemble (config ``[ensemble] members``)
    comparison.csv      `sysid.protocol.paper.COMPARISON_COLUMNS`: ours beside the paper's, every cell
    table7.md, table8.md  the paper's layout (30 s, 100 s), ours (paper)
    summary.json        total time, gate shares, wins against the paper; "runs" (the protocol
                        entries run) and "protocol" (all of them): fewer is a partial
                        reproduction, and its report says so on page 1
    manifest.json       written last, as in a run directory
"""
from __future__ import annotations

import json
import os
import time
import warnings
from pathlib import Path

import pandas as pd
import torch

from sysid.hybrid.correction import INPUT_NAMES, OUTPUT_NAMES
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.errors import CheckpointError, ConfigError
from sysid.evaluation.evaluate import METRICS_COLUMNS, TRACE_COLUMNS, Evaluation, trace_name  # noqa: F401 (layout)
from sysid.config.experiment import Experiment, load_experiment, ship_overrides
from sysid.store.files import atomic_path, write_csv, write_text
from sysid.store.manifest import verify_manifest
from sysid.mmg.model import MMG
from sysid.hybrid.force_models import CorrectedModel, build_model
from sysid.hybrid.knn_gate import KNNGate
from sysid.store.staging import staged_directory
from sysid.store.versions import software_versions


def _save_tensors(obj, path: Path) -> None:
    with atomic_path(path, ".pt") as tmp:
        torch.save(obj, tmp)


def _load_tensors(path: Path):
    if not path.is_file():
        raise CheckpointError(f"{path}: missing (the run directory is incomplete)")
    try:
        with warnings.catch_warnings():  # torch's pickle-protocol warnings on a foreign file
            warnings.simplefilter("ignore")
            return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated, not a torch file, unsafe pickle
        reason = (str(exc).strip().splitlines() or [""])[0][:160]
        if "weights_only" in str(exc):  # torch's multi-line advice is not for our users
            reason = "not a checkpoint of plain tensors: truncated, another kind of file, or unsafe objects"
        raise CheckpointError(f"{path}: cannot be loaded safely ({reason})") from None


def _check_finite(tensors: dict, path: Path) -> None:
    """Refuse weights holding NaN or inf (a diverged training): they predict nothing; and
    standard deviations (``*_std``, the FNN's scaling) that are not > 0."""
    for key, value in tensors.items():
        if isinstance(value, torch.Tensor) and value.is_floating_point() and not torch.isfinite(value).all():
            raise CheckpointError(f"{path}: {key} holds NaN or inf values (a diverged training); train the run again")
        if key.endswith("_std") and isinstance(value, torch.Tensor) and not bool((value > 0).all()):
            raise CheckpointError(f"{path}: {key} holds a standard deviation <= 0 (the FNN would divide by it); "
                                  "train the run again")


def gate_features(exp: Experiment) -> int:
    """Width F of the vectors the run's kNN gate compares: the FNN's last hidden layer
    (space "features") or its standardised inputs (space "inputs")."""
    return len(INPUT_NAMES) if exp.gate.space == "inputs" else exp.network.hidden[-1]


KNN_FIELDS = ("bank", "threshold", "train_distances", "k", "alpha")


def read_knn_bank(path: str | os.PathLike, exp: Experiment | None = None) -> dict[str, torch.Tensor]:
    """knn.pt checked against its own contract, whether or not a manifest vouches for it.

    bank (N, F) finite with N >= k >= 1 (F = `gate_features` of `exp` when given);
    threshold, k and alpha single numbers, threshold >= 0,
    0 < alpha < 1; train_distances (N,) finite and >= 0. `CheckpointError` names the file
    and the field at fault.
    """
    path = Path(path)
    knn = _load_tensors(path)

    def bad(what: str) -> CheckpointError:
        return CheckpointError(f"{path}: {what}; the kNN bank is broken: train the run again")

    if not isinstance(knn, dict) or any(not isinstance(knn.get(f), torch.Tensor) for f in KNN_FIELDS):
        raise bad(f"not a kNN bank (expected tensors {', '.join(KNN_FIELDS)})")
    _check_finite(knn, path)
    bank, k, alpha = knn["bank"], knn["k"], knn["alpha"]
    features = gate_features(exp) if exp is not None else None
    if bank.dim() != 2 or not bank.is_floating_point():
        raise bad(f"bank has shape {tuple(bank.shape)}, expected (N, {features or 'F'}) floats")
    if features is not None and bank.shape[1] != features:
        turned = " (transposed?)" if bank.shape[0] == features else ""
        raise bad(f"bank has shape {tuple(bank.shape)}, expected (N, {features}) for [gate] space = "
                  f"'{exp.gate.space}'{turned}")
    if bank.shape[0] == 0:
        raise bad("bank is empty (0 training features)")
    for name in ("threshold", "k", "alpha"):
        if knn[name].numel() != 1:
            raise bad(f"{name} has shape {tuple(knn[name].shape)}, expected a single number")
    if k.is_floating_point() or not 1 <= int(k) <= bank.shape[0]:
        raise bad(f"k = {k.item()} for a bank of {bank.shape[0]} features (need 1 <= k <= {bank.shape[0]})")
    if not 0.0 < float(alpha) < 1.0 or float(knn["threshold"]) < 0:
        raise bad(f"alpha = {float(alpha):g}, threshold = {float(knn['threshold']):g} "
                  "(need 0 < alpha < 1 and threshold >= 0)")
    if tuple(knn["train_distances"].shape) != (bank.shape[0],) or bool((knn["train_distances"] < 0).any()):
        raise bad(f"train_distances has shape {tuple(knn['train_distances'].shape)}, expected "
                  f"({bank.shape[0]},) distances >= 0")
    return knn


RUN_FILES = ("config.toml", "summary.json", "metrics.csv")


def verify_run_dir(path: str | os.PathLike) -> dict:
    """Refuse an incomplete or changed run directory (`IncompleteOutputError` naming the
    directory and the file); returns its manifest."""
    return verify_manifest(path, "run", RUN_FILES)


def model_state(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """State dict without the kNN bank (stored on its own in knn.pt)."""
    return {k: v.detach().cpu() for k, v in model.state_dict().items() if not k.startswith("gate.")}


def save_model(model: torch.nn.Module, run_dir: Path) -> None:
    """model.pt, standardization.json and knn.pt of a trained model."""
    if isinstance(model, MMG) and not model.coefficients.trainable_names:
        return
    if isinstance(model, SeedEnsemble):  # the members' run directories hold the weights
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
    verify_run_dir(run_dir)
    try:
        exp = load_experiment(run_dir / "config.toml")
    except ConfigError as exc:
        raise CheckpointError(f"{run_dir}: bad run config ({exc})") from None
    if exp.ensemble.members:
        members = [load_model((run_dir / member).resolve(), dtype)[1] for member in exp.ensemble.members]
        return exp, SeedEnsemble(members)
    model = build_model(exp, dtype)
    if not exp.needs_training:
        return exp, model
    state = _load_tensors(run_dir / "model.pt")
    if not isinstance(state, dict):
        raise CheckpointError(f"{run_dir / 'model.pt'}: not a state dict")
    _check_finite(state, run_dir / "model.pt")
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        raise CheckpointError(f"{run_dir / 'model.pt'}: does not fit the config's model ({str(exc)[:300]})") from None
    if isinstance(model, CorrectedModel) and exp.gate.enabled:
        knn = read_knn_bank(run_dir / "knn.pt", exp)
        gate = KNNGate(int(knn["k"]), float(knn["alpha"]), knn["bank"].shape[1], dtype)
        gate.bank, gate.threshold = knn["bank"].to(dtype), knn["threshold"].reshape(()).to(dtype)
        gate.train_distances = knn["train_distances"].to(dtype)
        model.gate, model.gate_enabled = gate, True
    return exp, model


def run_summary(exp: Experiment, evaluation: Evaluation, training=None, seconds: float | None = None) -> dict:
    """summary.json of a run; `training` is the trainer's `TrainingSummary` (None if untrained)."""
    info = training.to_dict() if training is not None else {}
    return {
        "name": exp.experiment.name, "model": exp.experiment.model,
        "status": f"failed: {info.pop('failure')}" if info.get("failure") else "complete",
        "dataset": "files" if exp.data.files else (exp.experiment.dataset if exp.needs_training else "-"),
        "ship": exp.experiment.ship, "seed": exp.experiment.seed,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "seconds": seconds,
        "train_seconds": info.pop("train_seconds", None),
        "epochs": info.pop("epochs", 0),
        "best_epoch": info.pop("best_epoch", None),
        "val_loss": info.pop("val_loss", None),
        "stopped": info.pop("stopped", {}),
        "n_train_windows": info.pop("n_train_windows", None),
        "n_val_windows": info.pop("n_val_windows", None),
        "versions": software_versions(), "mmg_overrides": ship_overrides(exp),
        "identified": info.pop("identified", {}) or {},
        "identified_initial": info.pop("identified_initial", {}) or {},
        "identified_uncertainty": info.pop("identified_uncertainty", None),
        "identification": info.pop("identification", None),
        "gate": {**(info.pop("gate", None) or {}), "off_share": evaluation.gate_off_share},
        "training": info,
    }


def write_run(run_dir: str | os.PathLike, exp: Experiment, model, evaluation: Evaluation,
              history: pd.DataFrame | None = None, training=None,
              seconds: float | None = None, overwrite: bool = False) -> Path:
    """Write a complete run directory (config, weights, kNN bank, history, metrics, traces).

    Staged (`sysid.store.staging`): the files go into a hidden directory beside `run_dir`, sealed
    with a manifest and moved into place complete; an existing `run_dir` is refused unless
    `overwrite`, which replaces all of it.
    """
    with staged_directory(run_dir, "run", overwrite) as staging:
        _write_run_files(staging, exp, model, evaluation, history, training, seconds)
    return Path(run_dir)


def _write_run_files(run_dir: Path, exp: Experiment, model, evaluation: Evaluation,
                     history: pd.DataFrame | None, training, seconds: float | None) -> Path:
    write_text(exp.to_toml(), run_dir / "config.toml")
    save_model(model, run_dir)
    if history is not None and len(history):
        write_csv(history, run_dir / "history.csv", float_format="%.6g")
    write_csv(evaluation.metrics, run_dir / "metrics.csv", float_format="%.6g")
    for name, frame in evaluation.traces.items():
        write_csv(frame, run_dir / "traces" / name, float_format="%.8g")
    summary = run_summary(exp, evaluation, training, seconds)
    write_text(json.dumps(summary, indent=2, default=str), run_dir / "summary.json")
    return run_dir
