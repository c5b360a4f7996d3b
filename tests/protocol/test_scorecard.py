"""The reproduction's scorecard from a small comparison table whose answers are known by
construction: the cut against MMG-only per scenario, the cells beating the paper's hybrid
and the cells where the hybrid (seed mean) beats NN-only (seed mean)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from sysid.protocol.reproduce import scorecard
from sysid.runs.reproduction import Reproduction

MMG = np.array([0.2, 0.1, 0.004])          # u, v_m [m/s], r [rad/s] of the baseline in every cell
HYBRID = {("Berthing", 30): 0.5, ("Random", 30): 0.9, ("Berthing", 100): 0.6, ("Random", 100): 0.7}
# NN-only / MMG per cell and channel: the hybrid beats NN where NN's ratio is above the hybrid's
NN = {("Berthing", 30): (0.4, 0.6, 0.7), ("Random", 30): (1.2, 0.8, 0.95),
      ("Berthing", 100): (0.5, 0.55, 0.9), ("Random", 100): (0.8, 0.8, 0.8)}
# hybrid beats NN: Berthing 30 v, r (2); Random 30 u, r (2); Berthing 100 r (1); Random 100 u, v, r (3) -> 8 of 12
PAPER_HYBRID = (0.11, 0.05, 0.001)   # only Berthing 30 s u (0.5 * 0.2 = 0.1) is below
PAPER_NN = (0.12, 0.04, 0.002)       # the paper's hybrid beats its NN on u, r of each cell -> 8 of 12


def _table(dataset_nn: tuple[str, ...] = ("D1", "D2")) -> pd.DataFrame:
    rows = []
    nan3 = [float("nan")] * 3
    for dataset in ("D1", "D2"):
        for (scenario, horizon), ratio in HYBRID.items():
            rows.append([scenario, "MMG (lab X'vr)", dataset, horizon, *MMG, *nan3, *nan3, 1])
            rows.append([scenario, "Hybrid", dataset, horizon, *(ratio * MMG), *PAPER_HYBRID, *(0.1 * MMG), 5])
            if dataset in dataset_nn:
                rows.append([scenario, "NN", dataset, horizon, *(np.array(NN[scenario, horizon]) * MMG), *PAPER_NN,
                             *(0.1 * MMG), 5])
    return pd.DataFrame(rows, columns=["scenario", "model", "dataset", "horizon_s", "rmse_u", "rmse_v", "rmse_r",
                                       "paper_u", "paper_v", "paper_r", "std_u", "std_v", "std_r", "n_seeds"])


def test_scorecard_counts_the_cells_where_the_hybrid_beats_nn_only():
    card = scorecard(_table(), "MMG (lab X'vr)")
    for score in card.datasets.values():
        assert score.reduction_vs_mmg_30s_by_scenario == pytest.approx({"Berthing": 0.5, "Random": 0.1})
        assert score.reduction_vs_mmg_30s_mean == pytest.approx(0.3)
        assert score.reduction_vs_mmg_100s_mean == pytest.approx(0.35)
        assert (score.cells_beating_paper_hybrid, score.cells) == (1, 12)
        assert (score.nn, score.cells_beating_nn, score.paper_cells_hybrid_beating_nn) == ("NN", 8, 8)
        assert score.nn_text() == "beats NN on 8/12 cells (the paper's hybrid beats its NN on 8/12)"
        assert score.by_scenario_text() == "Berthing 50 %, Random 10 %"


def test_without_nn_only_the_count_is_absent_and_old_summaries_still_read(tmp_path):
    card = scorecard(_table(dataset_nn=("D2",)), "MMG (lab X'vr)")
    assert card.D1.cells_beating_nn is None and card.D1.nn is None and card.D1.nn_text() == ""
    assert card.D2.cells_beating_nn == 8
    path = tmp_path / "summary.json"
    path.write_text(Reproduction(seeds=5, scorecard=card).to_text())
    again = Reproduction.read(path)
    assert again.scorecard == card
    # a summary written before the NN counts existed reads with them None
    old = json.loads(path.read_text())
    for ds in ("D1", "D2"):
        for key in ("nn", "cells_beating_nn", "paper_cells_hybrid_beating_nn"):
            del old["scorecard"][ds][key]
    path.write_text(json.dumps(old))
    assert Reproduction.read(path).scorecard.D2.cells_beating_nn is None


def test_a_partial_reproduction_scores_the_data_sets_it_holds():
    table = _table()
    card = scorecard(table[table.dataset == "D1"], "MMG (lab X'vr)")
    assert card.D2 is None and card.D1.cells_beating_nn == 8


def test_without_the_papers_horizons_there_is_no_score():
    table = _table()
    assert scorecard(table[table.horizon_s == 30], "MMG (lab X'vr)").datasets == {}
