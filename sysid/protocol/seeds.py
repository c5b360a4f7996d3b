"""Seed statistics: one experiment trained with N seeds, its RMSE per file and horizon as
the mean over the seeds with their standard deviation (a cell is a result, not a lucky seed)."""
from __future__ import annotations

from typing import Sequence

import pandas as pd

from sysid.evaluation.evaluate import METRICS_COLUMNS
from sysid.runs.rundir import with_divergence

RMSE = ["rmse_u", "rmse_v", "rmse_r"]
SPREAD_COLUMNS = ["std_u", "std_v", "std_r", "n_seeds"]   # std over seeds (ddof 1), seeds counted


def seed_metrics(frames: Sequence[pd.DataFrame]) -> pd.DataFrame:
    """`METRICS_COLUMNS` averaged over the seeds' metrics frames (one per seed; diverged when
    any seed diverged, at the earliest time), plus
    `SPREAD_COLUMNS`: the sample standard deviation of each RMSE over the seeds."""
    if not frames:
        raise ValueError("no seeds to average")
    stacked = pd.concat([with_divergence(f)[METRICS_COLUMNS] for f in frames], ignore_index=True)
    stacked["scenario"] = stacked["scenario"].fillna("")
    groups = stacked.groupby(["scenario", "file", "horizon_s"], sort=False)
    mean = groups[["n_windows", *RMSE]].mean().join(groups["diverged"].any()).join(groups["diverged_at_s"].min())
    std = groups[RMSE].std(ddof=1).rename(columns=dict(zip(RMSE, SPREAD_COLUMNS[:3])))
    out = mean.join(std).assign(n_seeds=groups.size()).reset_index()
    out["n_windows"] = out["n_windows"].round().astype(int)
    return out[METRICS_COLUMNS + SPREAD_COLUMNS]
