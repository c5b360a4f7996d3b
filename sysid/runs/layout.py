"""Run directories: their layout, and saving and loading them (the contract between
`sysid.runs.lifecycle`, `sysid.evaluation.evaluate` and `sysid.report`).

A **run directory** (``sysid train CONFIG -o runs/NAME``)::

    config.toml        resolved experiment config (all defaults filled in; its logs and ship file
                       named relative to the run directory, `sysid.runs.log_paths`)
    summary.json       {"name", "model": "mmg"|"nn"|"hybrid", "status": "complete"|"failed: ...",
                        "dataset": "D1"|"D2"|..., "ship", "seed", "created", "train_seconds",
                        "epochs", "best_epoch", "val_loss_multistep" (the run's validation
                        loss, "val_loss_definition"), "verdict" (`BaselineVerdict.to_dict`:
                        model vs physics baselines per split, horizon and channel) and
                        "beats_baseline", "data" (the logs used: training source, every file
                        with its SHA-256, absolute path and path relative to the run
                        directory, test set "files"|"paper"|"none"),
                        "training_range" ({speed, yaw_rate, factor}: beyond factor times
                        the training logs' largest speed or |r| a prediction diverged),
                        "stopped": {stage: "early stop"|"epoch limit"|...},
                        "n_train_windows", "n_val_windows", "versions": {...},
                        "mmg_overrides": {...}, "identified": {...}, "identified_initial": {...},
                        "identified_uncertainty": {names, estimate, std_error, correlation,
                        undetermined, ...} | null, "identification": {"solver":
                        "gradient"|"levenberg_marquardt", "start_states", "iterations"|"epochs",
                        ...} | null (the estimator of both), "gate": {...},
                        "training": {...}}
    model.pt           state dict (torch.save of plain tensors; weights_only=True safe)
    standardization.json  input/output mean and std of the FNN (Eqs. 8, 10)
    knn.pt             {"bank": (N, F) gate vectors, "threshold": (), "train_distances": (N,),
                        "k": (), "alpha": ()}
    history.csv        stage, epoch, train_loss, train_velocity, train_penalty, early_stopping_loss
                       (L_v on the validation windows during training, before the kNN gate), seconds
    metrics.csv        `sysid.records.columns.METRICS_COLUMNS`
    baseline_metrics.csv  the physics baselines on the same test logs: "baseline" (its label,
                       `sysid.evaluation.verdict`) + METRICS_COLUMNS; with a verdict and test logs
    traces/            one CSV per (file, horizon): ``{file_stem}_h{H}.csv``, `TRACE_COLUMNS`
    baseline_traces/LABEL/  each physics baseline's traces on the same windows, as traces/
                       (LABEL: `sysid.records.columns.baseline_folder` of its label); with
                       baseline_metrics.csv, the report draws them beside the model's
    ship/NAME.toml     the ship file the run was made with, byte for byte (a bundled ship's too;
                       NAME: the file's own name, `sysid.runs.rundir.ship_copy_name`): the run's
                       MMG and physics baseline are read from it (`RunDir.read_experiment`)
    manifest.json      written last: every other file with its SHA-256 (`sysid.store.manifest`)

Untrained MMG-only runs have no model.pt, knn.pt or history.csv. A run is written into a
staging directory and moved into place complete (`write_run`); it is read through
`sysid.runs.rundir.RunDir`, which refuses a run whose manifest is missing or disagrees
with its files. summary.json is `sysid.records.summary.RunSummary`, knn.pt
`sysid.runs.knn_bank.KnnBank`.

A **reproduction directory** (``sysid reproduce -o OUTDIR``)::

    runs/{name}/        run directories (`sysid.protocol.reproduce.PROTOCOL`); with ``--seeds N`` a
                        learned run is a folder of N run directories ``seed{k}/``, and
                        ``runs/{variant}_ensemble_{dataset}/`` is their mean-of-seeds
                        ensemble (config ``[ensemble] members``)
    comparison.csv      `sysid.protocol.paper.COMPARISON_COLUMNS`: ours beside the paper's, every cell
    table7.md, table8.md  the paper's layout (30 s, 100 s), ours (paper)
    reproduction.json   `sysid.runs.reproduction.Reproduction` (summary.json in reproductions
                        written before): total time, gate shares,
                        scorecards against the paper; "runs" (the protocol
                        entries run) and "protocol" (all of them): fewer is a partial
                        reproduction, and its report says so on page 1
    manifest.json       written last, as in a run directory
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import pandas as pd
import torch

from sysid.hybrid.correction import INPUT_NAMES, OUTPUT_NAMES
from sysid.hybrid.ensemble import SeedEnsemble
from sysid.errors import CheckpointError
from sysid.evaluation.divergence import PhysicalRange
from sysid.evaluation.evaluate import Evaluation
from sysid.config.experiment import Experiment, is_ship_path, ship_overrides
from sysid.store.files import write_bytes, write_csv, write_text
from sysid.mmg.model import MMG
from sysid.hybrid.force_models import CorrectedModel, build_model
from sysid.records.columns import baseline_folder
from sysid.runs.rundir import BASELINE_METRICS_COLUMNS, RunDir
from sysid.runs.knn_bank import KnnBank
from sysid.runs.log_paths import portable_provenance, relative_to
from sysid.records.summary import (VAL_LOSS_DEFINITION, DataSummary, GateSummary, IdentificationSummary, RangeSummary,
                                   RunSummary, TrainingDetails, UncertaintySummary, VerdictSummary)
from sysid.runs.tensor_files import save_tensors
from sysid.store.staging import staged_directory
from sysid.store.versions import software_versions


def model_state(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """State dict without the kNN bank (stored on its own in knn.pt)."""
    return {k: v.detach().cpu() for k, v in model.state_dict().items() if not k.startswith("gate.")}


def save_model(model: torch.nn.Module, run_dir: Path) -> None:
    """model.pt, standardization.json and knn.pt of a trained model."""
    if isinstance(model, MMG) and not model.coefficients.trainable_names:
        return
    if isinstance(model, SeedEnsemble):  # the members' run directories hold the weights
        return
    run = RunDir(run_dir)
    save_tensors(model_state(model), run.model)
    if isinstance(model, CorrectedModel):
        net = model.correction_net
        stats = {"inputs": list(INPUT_NAMES), "outputs": list(OUTPUT_NAMES),
                 "input_mean": net.input_mean.tolist(), "input_std": net.input_std.tolist(),
                 "output_mean": net.output_mean.tolist(), "output_std": net.output_std.tolist(),
                 "units": {"outputs": "N, N, N m"}}
        write_text(json.dumps(stats, indent=2), run.standardization)
        if model.gate is not None:
            KnnBank.of(model.gate).save(run.knn)


def load_model(run_dir: str | os.PathLike, dtype: torch.dtype = torch.float64, _within: tuple[Path, ...] = (),
               *, ship: str | None = None):
    """(experiment, model) of a run directory; clear errors for a missing or corrupt one, and
    for an ensemble whose members lead back to itself. The model's MMG (and the experiment's
    ship, the physics baseline's) is the run's copy of its ship file, or `ship` when given
    (`RunDir.read_experiment`)."""
    run = RunDir.open(run_dir)
    exp = run.read_experiment(ship)
    if exp.ensemble.members:
        here = run.path.resolve()
        chain = (*_within, here)
        members = []
        for member in exp.ensemble.members:
            path = (run.path / member).resolve()
            if path in chain:
                raise CheckpointError(f"{run.config}: [ensemble] members names {member!r}, which is "
                                      f"{'this run itself' if path == here else f'the ensemble {path} it belongs to'}"
                                      "; an ensemble's members are other run directories: remove it from the list")
            members.append(load_model(path, dtype, chain, ship=ship)[1])
        return exp, SeedEnsemble(members)
    model = build_model(exp, dtype)
    if not exp.needs_training:
        return exp, model
    try:
        model.load_state_dict(run.read_model_state())
    except RuntimeError as exc:
        raise CheckpointError(f"{run.model}: does not fit the config's model ({str(exc)[:300]})") from None
    if isinstance(model, CorrectedModel) and exp.gate.enabled:
        model.gate, model.gate_enabled = run.read_knn_bank(model.gate_width).gate(dtype), True
    return exp, model


def _parsed(record, value, at: str):
    """A part of the summary as its `record` type: a record as it is, a dict parsed; None
    stays None."""
    if value is None or isinstance(value, record):
        return value
    return record.from_json(value, "summary.json (being written)", at)


# the trainer's parts that are records of their own in summary.json (`TrainingSummary` attributes)
_TRAINER_RECORDS = {"identified_uncertainty": UncertaintySummary, "identification": IdentificationSummary,
                    "gate": GateSummary}


def _trainer_records(training) -> dict:
    """identified_uncertainty, identification and gate (a `GateSummary` without the off
    shares) of the trainer's `TrainingSummary`: records, or None."""
    return {key: getattr(training, key, None) for key in _TRAINER_RECORDS}


def run_summary(exp: Experiment, evaluation: Evaluation, training=None, seconds: float | None = None,
                verdict=None, data: dict | None = None, limits: PhysicalRange | None = None) -> RunSummary:
    """summary.json of a run; `training` is the trainer's `TrainingSummary` (None if untrained),
    `verdict` its `sysid.evaluation.verdict.BaselineVerdict`, `data` the logs it used
    (`sysid.data.splits.provenance`), `limits` the training logs' `PhysicalRange` (None: none)."""
    info = training.to_dict() if training is not None else {}
    parts = _trainer_records(training) if training is not None else {}
    for key in _TRAINER_RECORDS:
        info.pop(key, None)
    failure = info.pop("failure", None)
    gate = parts.get("gate") or GateSummary()
    return RunSummary(
        name=exp.experiment.name, model=exp.experiment.model,
        status=f"failed: {failure}" if failure else "complete",
        dataset="files" if exp.data.train else (exp.experiment.dataset if exp.needs_training else "-"),
        ship=exp.experiment.ship, seed=exp.experiment.seed,
        created=time.strftime("%Y-%m-%dT%H:%M:%S%z"), seconds=seconds,
        train_seconds=info.pop("train_seconds", None),
        epochs=info.pop("epochs", 0),
        best_epoch=info.pop("best_epoch", None),
        val_loss_multistep=info.pop("val_loss_multistep", None),
        val_loss_definition=VAL_LOSS_DEFINITION,
        verdict=_parsed(VerdictSummary, verdict.to_dict() if verdict is not None else None, "verdict"),
        beats_baseline=verdict.beats_baseline if verdict is not None else None,
        data=_parsed(DataSummary, data, "data"),
        training_range=_parsed(RangeSummary, limits.to_dict() if limits is not None else None, "training_range"),
        stopped=info.pop("stopped", {}),
        n_train_windows=info.pop("n_train_windows", None),
        n_val_windows=info.pop("n_val_windows", None),
        versions=software_versions(), mmg_overrides=ship_overrides(exp),
        identified=info.pop("identified", {}) or {},
        identified_initial=info.pop("identified_initial", {}) or {},
        identified_uncertainty=parts.get("identified_uncertainty"),
        identification=parts.get("identification"),
        gate=dataclasses.replace(gate, off_share=_parsed(GateSummary, {"off_share": evaluation.gate_off_share},
                                                         "gate").off_share),
        training=_parsed(TrainingDetails, info, "training"),
    )


def write_run(run_dir: str | os.PathLike, exp: Experiment, model, evaluation: Evaluation,
              history: pd.DataFrame | None = None, training=None,
              seconds: float | None = None, overwrite: bool = False, verdict=None,
              data: dict | None = None, baseline_metrics: pd.DataFrame | None = None, limits: PhysicalRange | None = None,
              ship_definition: bytes | None = None, baseline_traces: dict[str, dict[str, pd.DataFrame]] | None = None,
              home: str | os.PathLike | None = None) -> Path:
    """Write a complete run directory (config, ship file, weights, kNN bank, history,
    metrics, traces; `baseline_traces`: baseline label -> trace name -> `TRACE_COLUMNS` frame).

    `ship_definition`: the bytes of the ship file the run was made with, read when it
    started (`ship_definition`); None: read now. Staged (`sysid.store.staging`): the files
    go into a hidden directory beside `run_dir`, sealed with a manifest and moved into place
    complete; an existing `run_dir` is refused unless `overwrite`, which replaces all of it.
    The logs of `data` are recorded relative to the run directory (`sysid.runs.log_paths`):
    `home`, where it will live when it is written elsewhere and moved there (a sweep
    trial's); None: `run_dir`.
    """
    if ship_definition is None:
        ship_definition = read_ship_definition(exp)
    home = Path(home if home is not None else run_dir)
    if data:
        data = portable_provenance(data, home)
    with staged_directory(run_dir, "run", overwrite) as staging:
        _write_run_files(RunDir(staging), exp, model, evaluation, history, training, seconds, verdict, data,
                         baseline_metrics, limits, ship_definition, baseline_traces, home)
    return Path(run_dir)


def read_ship_definition(exp: Experiment) -> bytes:
    """The bytes of the experiment's ship file (``[experiment] ship``: a file, or a bundled
    ship's), which its run directory keeps a copy of."""
    from sysid.mmg.ship import resolve_ship_path
    return resolve_ship_path(exp.experiment.ship).read_bytes()


def _used_files(exp: Experiment, data: dict | None, home: Path) -> Experiment:
    """`exp` as the run's config.toml names it: ``[data]`` train / validation / test as the
    files used (globs and directories expanded; relative to the run directory `home` where
    `data` records that, `sysid.runs.log_paths`) and a ship file relative to `home`, so
    the run names what it was made from, found again when the project folder moves."""
    ship = exp.experiment.ship
    if is_ship_path(ship) and (relative := relative_to(ship, home)) is not None:
        exp = exp.replace(experiment={"ship": relative})
    if not data or not exp.data.train:
        return exp
    listed = {key: tuple(f.get("relative", f["file"]) for f in data[key]) for key in ("train", "validation", "test")
              if isinstance(data.get(key), list)}
    if data.get("held_out"):  # validation drawn from the training logs: all of them are [data] train
        listed["train"] += listed.pop("validation", ())
    return exp.replace(data=listed)


def _write_run_files(run: RunDir, exp: Experiment, model, evaluation: Evaluation,
                     history: pd.DataFrame | None, training, seconds: float | None, verdict=None,
                     data: dict | None = None, baseline_metrics: pd.DataFrame | None = None, limits: PhysicalRange | None = None,
                     ship_definition: bytes | None = None,
                     baseline_traces: dict[str, dict[str, pd.DataFrame]] | None = None,
                     home: Path | None = None) -> None:
    write_text(_used_files(exp, data, home if home is not None else run.path).to_toml(), run.config)
    write_bytes(ship_definition if ship_definition is not None else read_ship_definition(exp),
                run.ship_copy(exp.experiment.ship))
    save_model(model, run.path)
    if history is not None and len(history):
        write_csv(history, run.history, float_format="%.6g")
    write_csv(evaluation.metrics, run.metrics, float_format="%.6g")
    if baseline_metrics is not None and len(baseline_metrics):
        write_csv(baseline_metrics[BASELINE_METRICS_COLUMNS], run.baseline_metrics, float_format="%.6g")
    for name, frame in evaluation.traces.items():
        write_csv(frame, run.traces / name, float_format="%.8g")
    for label, frames in (baseline_traces or {}).items():
        for name, frame in frames.items():
            write_csv(frame, run.baseline_traces / baseline_folder(label) / name, float_format="%.8g")
    write_text(run_summary(exp, evaluation, training, seconds, verdict, data, limits).to_text(), run.summary)
