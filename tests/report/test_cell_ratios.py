"""The reproduction's cell figure: every Table 7/8 cell of NN-only and the hybrid relative to
MMG-only (lab X'vr), seed means with min-max bars, the paper's printed hybrid beside them.
Checked against ratios known by construction and against a synthetic reproduction's
metrics.csv; the figure's plotted values are read back from its artists."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest

from sysid.protocol.paper import paper_rmse
from sysid.report.cell_ratios import CellRatios, ModelSeeds, dataset_cells, paper_ratios, relative_cells
from sysid.report.figures import relative_rmse
from sysid.report.source import read_source

from synthetic_rundir import write_reproduction

SCENARIOS = ("Berthing", "Random")
HORIZONS = (30, 100)
MMG = {"u": 0.2, "v": 0.1, "r": 0.004}   # baseline RMSE [m/s, m/s, rad/s] of every cell


def _seeds(factors: dict[int, float], offset: float = 0.0) -> pd.DataFrame:
    """Per seed: RMSE = factor x MMG (+ offset x MMG for Random)."""
    rows = []
    for seed, factor in factors.items():
        for s in SCENARIOS:
            for h in HORIZONS:
                f = factor + (offset if s == "Random" else 0.0)
                rows.append({"seed": seed, "scenario": s, "horizon_s": h,
                             **{f"rmse_{c}": f * v for c, v in MMG.items()}})
    return pd.DataFrame(rows)


def _cells(hybrid_seeds: dict[int, float], nn_seeds: dict[int, float]) -> CellRatios:
    baseline = _seeds({0: 1.0})
    models = [ModelSeeds("NN D1", "#e06c00", _seeds(nn_seeds)),
              ModelSeeds("Hybrid D1", "#8fd18f", _seeds(hybrid_seeds, offset=0.5))]
    return CellRatios("D1", "MMG (lab X'vr)", "#7fb2f0", tuple(models), relative_cells(models, baseline),
                      paper_ratios(baseline, "D1"), SCENARIOS, HORIZONS)


def _artist_values(fig, gid: str) -> np.ndarray:
    """The y values of the artist with `gid`: a marker line's points or a bar collection's (low, high)."""
    for ax in fig.axes:
        for line in ax.lines:
            if line.get_gid() == gid:
                return np.asarray(line.get_ydata(), float)
        for coll in ax.collections:
            if coll.get_gid() == gid:
                return np.array([[seg[0][1], seg[1][1]] for seg in coll.get_segments()])
    raise AssertionError(f"no artist {gid}")


def test_seed_means_and_min_max_relative_to_mmg_are_plotted():
    cells = _cells({0: 0.4, 1: 0.6, 2: 0.5}, {0: 0.7, 1: 0.9})
    hybrid = cells.cells[cells.cells.model == "Hybrid D1"].set_index(["scenario", "horizon_s", "channel"])
    # Berthing: seeds 0.4, 0.6, 0.5 -> mean 0.5, min 0.4, max 0.6; Random: each + 0.5
    assert hybrid.loc[("Berthing", 30, "u"), ["ratio", "low", "high"]].tolist() == pytest.approx([0.5, 0.4, 0.6])
    assert hybrid.loc[("Random", 100, "r"), ["ratio", "low", "high"]].tolist() == pytest.approx([1.0, 0.9, 1.1])
    assert set(hybrid.n_seeds) == {3} and cells.seeds == 3
    # hybrid 0.5 < NN 0.8 on Berthing, 1.0 > 0.8 on Random: 6 of 12 cells
    assert cells.beating("Hybrid D1", "NN D1") == (6, 12)

    fig = relative_rmse(cells, "cells")
    for h in HORIZONS:
        for c in ("u", "v", "r"):
            assert _artist_values(fig, f"Hybrid D1|{h}|{c}") == pytest.approx([0.5, 1.0])   # Berthing, Random
            assert _artist_values(fig, f"NN D1|{h}|{c}") == pytest.approx([0.8, 0.8])
            assert _artist_values(fig, f"Hybrid D1|{h}|{c}|spread") == pytest.approx(np.array([[0.4, 0.6], [0.9, 1.1]]))
            i = "uvr".index(c)
            paper = [paper_rmse(s, "hybrid", "D1", h)[i] / MMG[c] for s in SCENARIOS]
            bars = _artist_values(fig, f"paper|{h}|{c}")
            assert bars[:, 0] == pytest.approx(paper) and bars[:, 1] == pytest.approx(paper)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log" and "RMSE / RMSE of MMG (lab X'vr) [-]" == ax.get_ylabel()


def test_one_seed_draws_points_without_spread():
    cells = _cells({0: 0.5}, {0: 0.7})
    fig = relative_rmse(cells, "cells")
    assert _artist_values(fig, "Hybrid D1|30|u") == pytest.approx([0.5, 1.0])
    with pytest.raises(AssertionError, match="no artist"):
        _artist_values(fig, "Hybrid D1|30|u|spread")


@pytest.mark.slow
def test_a_reproductions_cells_are_its_metrics_over_mmg_lab(tmp_path):
    out = write_reproduction(tmp_path / "repro", scale=0.3, names=("mmg_paper", "mmg_lab", "nn_D1", "hybrid_D1"))
    (cells,) = dataset_cells(read_source(out))
    assert cells.dataset == "D1" and cells.baseline == "MMG (lab X'vr)" and cells.seeds == 1
    mmg = pd.read_csv(out / "runs" / "mmg_lab" / "metrics.csv").set_index(["scenario", "horizon_s"])
    hyb = pd.read_csv(out / "runs" / "hybrid_D1" / "metrics.csv").set_index(["scenario", "horizon_s"])
    assert len(cells.cells) == 2 * 36 and cells.scenarios[0] == "Berthing" and cells.scenarios[-1] == "Random"
    fig = relative_rmse(cells, "cells")
    for h in (30, 100):
        for c in ("u", "v", "r"):
            expected = [hyb.loc[(s, h), f"rmse_{c}"] / mmg.loc[(s, h), f"rmse_{c}"] for s in cells.scenarios]
            assert _artist_values(fig, f"Hybrid D1|{h}|{c}") == pytest.approx(expected, rel=1e-9)
