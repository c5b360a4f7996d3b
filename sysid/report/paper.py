"""The seed paper's Tables 7 (30 s) and 8 (100 s): RMSE of u, v_m [m/s] and r [rad/s].

Copied from shared/spec/paper_tables_7_8.csv. MMG rows are independent of the data set.
"""
from __future__ import annotations

import re

import pandas as pd

_ROWS = {  # scenario -> model -> (D1 30 s, D2 30 s, D1 100 s, D2 100 s), each (u, v_m, r)
    "Berthing": {
        "MMG": [(.0103, .0132, .0115), (.0103, .0132, .0115), (.0237, .0173, .0161), (.0237, .0173, .0161)],
        "NN": [(.0076, .0063, .0071), (.0114, .0062, .0062), (.0207, .0062, .0080), (.0331, .0074, .0066)],
        "Hybrid": [(.0069, .0071, .0052), (.0062, .0076, .0048), (.0170, .0095, .0082), (.0222, .0060, .0061)]},
    "Turning 20": {
        "MMG": [(.0189, .0227, .0105), (.0189, .0227, .0105), (.0372, .0294, .0138), (.0372, .0294, .0138)],
        "NN": [(.0086, .0076, .0048), (.0107, .0074, .0044), (.0132, .0091, .0051), (.0192, .0075, .0040)],
        "Hybrid": [(.0087, .0069, .0041), (.0094, .0068, .0035), (.0099, .0067, .0039), (.0169, .0068, .0032)]},
    "Turning 35": {
        "MMG": [(.0220, .0173, .0089), (.0220, .0173, .0089), (.0455, .0224, .0098), (.0455, .0224, .0098)],
        "NN": [(.0093, .0081, .0052), (.0075, .0090, .0036), (.0101, .0096, .0065), (.0087, .0126, .0052)],
        "Hybrid": [(.0101, .0084, .0044), (.0085, .0081, .0022), (.0173, .0122, .0055), (.0107, .0109, .0032)]},
    "Zigzag 20/20": {
        "MMG": [(.0262, .0363, .0126), (.0262, .0363, .0126), (.0645, .0398, .0144), (.0645, .0398, .0144)],
        "NN": [(.0247, .0199, .0106), (.0245, .0217, .0124), (.0170, .0239, .0114), (.0286, .0270, .0140)],
        "Hybrid": [(.0199, .0134, .0057), (.0237, .0120, .0042), (.0233, .0163, .0093), (.0145, .0115, .0056)]},
    "Zigzag 30/30": {
        "MMG": [(.0354, .0529, .0241), (.0354, .0529, .0241), (.0273, .0520, .0217), (.0273, .0520, .0217)],
        "NN": [(.0336, .0404, .0287), (.0264, .0499, .0339), (.0659, .0355, .0254), (.0682, .0478, .0323)],
        "Hybrid": [(.0239, .0262, .0153), (.0315, .0282, .0132), (.0283, .0260, .0160), (.0347, .0288, .0144)]},
    "Random": {
        "MMG": [(.0210, .0120, .0075), (.0210, .0120, .0075), (.0299, .0154, .0085), (.0299, .0154, .0085)],
        "NN": [(.0340, .0182, .0086), (.0164, .0062, .0055), (.0373, .0273, .0082), (.0138, .0079, .0070)],
        "Hybrid": [(.0199, .0109, .0063), (.0149, .0071, .0034), (.0230, .0148, .0086), (.0126, .0086, .0041)]},
}
def scenario_key(name: str) -> str:
    """Spelling-independent scenario key: "Turning 20°", "turning 20 test" and "Turning 20"
    all give "turning20"; "Zigzag 20°/20°" gives "zigzag20/20"."""
    name = name.lower().replace("maneuver", "").replace("manoeuvre", "").replace("test", "")
    return re.sub(r"[^a-z0-9/]", "", name)


_BY_KEY = {scenario_key(k): k for k in _ROWS}
_CELLS = [("D1", 30), ("D2", 30), ("D1", 100), ("D2", 100)]
PAPER_MODELS = {"mmg": "MMG", "nn": "NN", "hybrid": "Hybrid"}


def paper_rmse(scenario: str, kind: str, dataset: str, horizon_s: float) -> tuple[float, float, float] | None:
    """The paper's (u, v_m, r) RMSE for a scenario, model kind ("mmg", "nn", "hybrid"),
    data set and horizon [s]; None when the paper has no such cell (held-out files, ...)."""
    model = PAPER_MODELS.get(kind)
    rows = _ROWS.get(_BY_KEY.get(scenario_key(scenario), scenario), {}).get(model)
    if rows is None:
        return None
    if kind == "mmg" and dataset not in ("D1", "D2"):
        dataset = "D1"  # the paper's MMG rows are the same for both data sets
    try:
        return rows[_CELLS.index((dataset, int(round(horizon_s))))]
    except ValueError:
        return None


def paper_table() -> pd.DataFrame:
    """The paper's numbers as rows scenario, model, dataset, horizon_s, rmse_u, rmse_v, rmse_r."""
    rows = []
    for scenario, models in _ROWS.items():
        for model, cells in models.items():
            for (dataset, horizon), (u, v, r) in zip(_CELLS, cells):
                rows.append((scenario, model, dataset, horizon, u, v, r))
    return pd.DataFrame(rows, columns=["scenario", "model", "dataset", "horizon_s", "rmse_u", "rmse_v", "rmse_r"])
