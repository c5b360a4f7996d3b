"""Layout of run directories and reproduction directories (the contract between
`sysid.train`, `sysid.evaluate` and `sysid.report`).

A **run directory** (``sysid train CONFIG -o runs/NAME``)::

    config.toml        resolved experiment config (all defaults filled in)
    summary.json       {"name", "model": "mmg"|"nn"|"hybrid", "dataset": "D1"|"D2"|..., "ship",
                        "seed", "created", "train_seconds", "epochs", "best_epoch",
                        "n_train_windows", "n_val_windows", "versions": {...},
                        "mmg_overrides": {...}, "identified": {...}, "gate": {...}}
    model.pt           state dict (torch.save of plain tensors; weights_only=True safe)
    standardization.json  input/output mean and std of the FNN (Eqs. 8, 10)
    knn.pt             {"bank": (N, 64) features, "threshold": (), "k": (), "alpha": ()}
    history.csv        epoch, train_loss, val_loss, train_velocity, train_penalty, seconds
    metrics.csv        scenario, file, horizon_s, n_windows, rmse_u, rmse_v, rmse_r
    traces/            one CSV per (file, horizon): ``{file_stem}_h{H}.csv``, see TRACE_COLUMNS

MMG-only runs have no model.pt, knn.pt or history.csv.

A **reproduction directory** (``sysid reproduce -o OUTDIR``)::

    runs/{model}_{dataset}/     run directories: mmg_paper (X'vr = 0.4535), mmg_lab,
                                nn_D1, nn_D2, hybrid_D1, hybrid_D2
    comparison.csv              TABLE_COLUMNS: ours beside the paper's, every cell
    table7.md, table8.md        the paper's layout (30 s, 100 s), ours / paper / change
    summary.json                total time, gate shares, wins against the paper
"""
from __future__ import annotations

import re

TRACE_COLUMNS = (
    ["window", "t", "t_rel"]
    + [f"obs_{c}" for c in ("x", "u", "y", "v", "psi", "r")]
    + [f"pred_{c}" for c in ("x", "u", "y", "v", "psi", "r")]
    + ["n_prop", "delta_rudder", "wind_velo_true", "wind_dir_true",
       "wind_velo_relative", "wind_dir_relative"]  # relative wind seen by the predicted state
    + [f"{a}{k}" for k in ("H", "P", "R", "A", "NN") for a in ("X", "Y", "N")]  # N, N m
    + ["knn_distance", "gate_on"]  # NaN / 1 where the model has no gate
)

TABLE_COLUMNS = ["scenario", "model", "dataset", "horizon_s",
                 "rmse_u", "rmse_v", "rmse_r", "paper_u", "paper_v", "paper_r"]

METRICS_COLUMNS = ["scenario", "file", "horizon_s", "n_windows", "rmse_u", "rmse_v", "rmse_r"]


def trace_name(file_stem: str, horizon_s: float) -> str:
    """File name of a trace: ``{file_stem}_h{H}.csv``."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", file_stem)
    return f"{safe}_h{int(round(horizon_s))}.csv"
