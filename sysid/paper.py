"""The seed paper's Tables 7 (30 s) and 8 (100 s): RMSE of u, v_m [m/s] and r [rad/s].

One source: ``configs/paper/tables_7_8.csv`` (the paper's numbers; MMG rows are the same for
both data sets). Scenario names match in any spelling ("Turning 20°", "turning 20 test").
"""
from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

import pandas as pd

from sysid.errors import ConfigError

TABLE = Path(__file__).resolve().parents[1] / "configs" / "paper" / "tables_7_8.csv"
PAPER_MODELS = {"mmg": "MMG", "nn": "NN", "hybrid": "Hybrid"}


def scenario_key(name: str) -> str:
    """Spelling-independent scenario key: "Turning 20°", "turning 20 test" and "Turning 20"
    all give "turning20"; "Zigzag 20°/20°" gives "zigzag20/20"."""
    name = name.lower().replace("maneuver", "").replace("manoeuvre", "").replace("test", "")
    return re.sub(r"[^a-z0-9/]", "", name)


@lru_cache(maxsize=1)
def paper_table() -> pd.DataFrame:
    """Rows scenario, model (MMG/NN/Hybrid), dataset, horizon_s, rmse_u, rmse_v, rmse_r."""
    if not TABLE.is_file():
        raise ConfigError(f"{TABLE}: the paper's Tables 7/8 are missing")
    return pd.read_csv(TABLE)


@lru_cache(maxsize=1)
def _cells() -> dict:
    return {(scenario_key(r.scenario), r.model, r.dataset, int(r.horizon_s)): (r.rmse_u, r.rmse_v, r.rmse_r)
            for r in paper_table().itertuples()}


def paper_rmse(scenario: str, kind: str, dataset: str, horizon_s: float) -> tuple[float, float, float] | None:
    """The paper's (u, v_m, r) RMSE for a scenario, model kind ("mmg", "nn", "hybrid"),
    data set and horizon [s]; None when the paper has no such cell (held-out files, ...)."""
    model = PAPER_MODELS.get(kind)
    if kind == "mmg" and dataset not in ("D1", "D2"):
        dataset = "D1"  # the paper's MMG rows are the same for both data sets
    return _cells().get((scenario_key(scenario), model, dataset, int(round(horizon_s))))
