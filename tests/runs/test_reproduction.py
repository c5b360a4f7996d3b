"""A reproduction's summary as `Reproduction`: the scorecard of a comparison table with known
ratios, written as ``sysid reproduce`` writes it, reads back to the same record and bytes."""
from __future__ import annotations

import json

import pandas as pd
import pytest

from sysid.errors import CheckpointError
from sysid.protocol.reproduce import scorecard
from sysid.runs.reproduction import Reproduction

# hybrid RMSE / MMG RMSE per (scenario, horizon [s]), the same for u, v_m, r
RATIO = {("Berthing", 30): 0.5, ("Random", 30): 0.8, ("Berthing", 100): 0.6, ("Random", 100): 0.7}


def _table() -> pd.DataFrame:
    rows = []
    for dataset in ("D1", "D2"):
        for (scenario, horizon), ratio in RATIO.items():
            mmg = [0.2, 0.1, 0.004]
            paper = [0.11, 0.05, 0.001] if dataset == "D1" else [1.0, 1.0, 1.0]  # D1: only Berthing's 30-s u beats it
            rows.append([scenario, "MMG", dataset, horizon, *mmg, *[float("nan")] * 3])
            rows.append([scenario, "Hybrid", dataset, horizon, *[ratio * m for m in mmg], *paper])
    return pd.DataFrame(rows, columns=["scenario", "model", "dataset", "horizon_s", "rmse_u", "rmse_v", "rmse_r",
                                       "paper_u", "paper_v", "paper_r"])


def test_scorecard_of_known_ratios_round_trips(tmp_path):
    card = scorecard(_table())
    d1 = card.D1
    assert d1.reduction_vs_mmg_30s_by_scenario == pytest.approx({"Berthing": 0.5, "Random": 0.2})
    assert d1.reduction_vs_mmg_30s_mean == pytest.approx(0.35) and d1.least_reduction_30s == pytest.approx(0.2)
    assert d1.reduction_vs_mmg_100s_mean == pytest.approx(0.35)
    assert (d1.cells_beating_paper_hybrid, d1.cells) == (1, 12)        # u 0.5 * 0.2 < 0.11
    assert (card.D2.cells_beating_paper_hybrid, card.D2.cells) == (12, 12)
    summary = Reproduction(seconds=12.5, runs=("mmg_lab", "hybrid_D1"), failed={}, protocol=("mmg_lab", "hybrid_D1"),
                           seeds=1, scorecard=card, gate_off_share_random_30s={"hybrid_D1": None})
    path = tmp_path / "summary.json"
    path.write_text(summary.to_text())
    again = Reproduction.read(path)
    assert again == summary and again.to_text() == path.read_text()
    data = json.loads(path.read_text())
    assert list(data) == ["seconds", "runs", "failed", "protocol", "seeds", "scorecard", "gate_off_share_random_30s"]
    assert list(data["scorecard"]) == ["baseline", "model", "D1", "D2"]


def test_a_malformed_reproduction_summary_names_the_key(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text(json.dumps({"runs": ["mmg_lab"], "scorecard": {"baseline": "MMG", "model": "Hybrid",
                                                                   "D1": {"cells": 36}}}))
    with pytest.raises(CheckpointError, match=r"summary.json: key 'scorecard\.D1\.reduction_vs_mmg_30s_by_scenario' "
                                              r"is missing"):
        Reproduction.read(path)
