"""The column names of a run directory's tables (metrics.csv, baseline_metrics.csv,
history.csv, traces/) and a trace's file name. Torch-free: written by
`sysid.evaluation.evaluate` and `sysid.runs.layout`, read by `sysid.runs.rundir.RunDir`."""
from __future__ import annotations

import re

from sysid.channel_names import FORCE, FORCE_COMPONENTS, INPUTS, STATE

# the metrics' quantity and units, as printed beside their tables (the files are SI)
RMSE_UNITS = "RMSE of u, v_m [m/s] and r [rad/s]"
# metrics.csv: one row per file and horizon; RMSE of u, v_m [m/s] and r [rad/s]; diverged: a
# window's prediction diverged, first at diverged_at_s [s] of the log (NaN otherwise)
METRICS_COLUMNS = ["scenario", "file", "horizon_s", "n_windows", "rmse_u", "rmse_v", "rmse_r",
                   "diverged", "diverged_at_s"]
REQUIRED_METRICS_COLUMNS = METRICS_COLUMNS[:7]   # what a run written before divergence was marked holds
# baseline_metrics.csv: the physics baselines on the same test logs, each under its label
BASELINE_METRICS_COLUMNS = ["baseline"] + METRICS_COLUMNS
# history.csv: the columns every trained run has (losses are multi-step losses, dimensionless)
HISTORY_COLUMNS = ["epoch", "train_loss", "early_stopping_loss"]
# traces/*.csv: one row per window step (`sysid.evaluation.evaluate.trace_frame`)
TRACE_COLUMNS = (
    ["window", "t", "t_rel"]
    + [f"obs_{c}" for c in STATE]
    + [f"pred_{c}" for c in STATE]
    + list(INPUTS) + ["wind_velo_relative", "wind_dir_relative"]  # relative wind of the predicted state
    + [f"{a}{key}" for key in FORCE_COMPONENTS.values() for a in FORCE]  # N, N m
    + ["knn_distance", "gate_on"]  # NaN / 1 where the model has no gate
)


def baseline_folder(label: str) -> str:
    """Folder of a physics baseline's traces under ``baseline_traces/``: its label
    (`sysid.evaluation.verdict`) in lower case, runs of other characters as ``_``
    ("MMG (ship file)" -> ``mmg_ship_file``)."""
    return re.sub(r"[^a-z0-9]+", "_", label.lower()).strip("_")


def trace_name(file_stem: str, horizon_s: float) -> str:
    """File name of a trace: ``{file_stem}_h{H}.csv`` (H: the horizon in whole seconds)."""
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", file_stem)
    return f"{safe}_h{int(round(horizon_s))}.csv"
