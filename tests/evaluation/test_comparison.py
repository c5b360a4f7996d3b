"""`sysid.evaluation.comparison` on logs with a known truth: simulated by an MMG whose
coefficients differ from the ship file's (`synthetic_rundir.measured_runs`), so the truth
model must beat the ship file's MMG, which must be worse than the truth; a model that blows
up is DIVERGED; the per-window errors pool to the protocol's metrics."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from sysid import MMG, load_ship
from sysid.evaluation.comparison import BASELINE, FIRST, Contender, compare, metrics_of, paired_cells
from sysid.evaluation.evaluate import evaluate_model
from sysid.evaluation.judgement import Outcome
from synthetic_rundir import measured_runs

TRUTH = {"C_D": 1.3, "X_0F": -0.03, "N_r": -0.055}   # the coefficients the logs were simulated with


class Exploding(torch.nn.Module):
    """An MMG whose forces are 10^6 times too large: its predictions leave the finite numbers."""

    def __init__(self, mmg: MMG):
        super().__init__()
        self.mmg, self.coefficients = mmg, mmg.coefficients

    def forward(self, state, inputs):
        f = self.mmg(state, inputs)
        return type(f)(**{k: (v * 1e6 if isinstance(v, torch.Tensor) and k != "relative_wind" else v)
                          for k, v in vars(f).items()})


@pytest.fixture(scope="module")
def runs():
    found = measured_runs(scale=0.4)
    return [found[s] for s in ("Turning 35", "Zigzag 20/20", "Random")]


def test_the_truth_beats_the_ship_file_mmg_and_the_tables_pool_to_the_metrics(runs):
    truth = Contender("truth", (MMG(load_ship("esso_osaka", TRUTH)),), baseline="ship")
    ship = Contender("ship", (MMG(load_ship("esso_osaka")),))
    result = compare([ship, truth], runs, (30.0,), against=FIRST)
    assert list(result.verdicts) == ["truth"] and result.references == {"truth": "ship"}
    assert result.verdicts["truth"].outcome is Outcome.BEATS
    assert result.verdicts["truth"].change_high < 0 and result.verdicts["truth"].n_logs == 3
    # against the baseline: the same pair, the same judgement
    again = compare([truth, ship], runs, (30.0,), against=BASELINE)
    assert again.verdicts["truth"].change == pytest.approx(result.verdicts["truth"].change, rel=1e-12)
    # the other way round the ship file's MMG is worse than the truth
    reverse = compare([truth, ship], runs, (30.0,), against=FIRST)
    assert reverse.verdicts["ship"].outcome is Outcome.WORSE
    # per-window errors pool to the protocol's metrics of each model
    for contender in (truth, ship):
        expected = evaluate_model(contender.members[0], runs, (30.0,), traces=False).metrics
        pooled = metrics_of(result.errors, contender.label)
        np.testing.assert_allclose(pooled[["rmse_u", "rmse_v", "rmse_r"]].to_numpy(),
                                   expected[["rmse_u", "rmse_v", "rmse_r"]].to_numpy(), rtol=1e-10)
        assert list(pooled.n_windows) == [len(r) // 30 for r in runs]
    cells = paired_cells(result.errors, "truth", "ship")
    assert len(cells) == 9 and all(c.model.shape == c.baseline.shape == (1, c.n_windows) for c in cells)


def test_a_model_that_blows_up_is_diverged_and_named_where(runs):
    ship = Contender("ship", (MMG(load_ship("esso_osaka")),))
    wild = Contender("wild", (Exploding(MMG(load_ship("esso_osaka"))),))
    result = compare([ship, wild], runs[:1], (30.0,))
    judgement = result.verdicts["wild"]
    assert judgement.outcome is Outcome.DIVERGED and not judgement.beats
    assert judgement.divergences and judgement.divergences[0].log == runs[0].name
    assert math.isfinite(judgement.divergences[0].time_s)
    assert set(result.table[result.table.model == "wild"].decision) == {"diverged"}


def test_seeds_are_members_with_a_spread(runs):
    seeds = (MMG(load_ship("esso_osaka", TRUTH)), MMG(load_ship("esso_osaka", {**TRUTH, "N_r": -0.06})))
    ship = Contender("ship", (MMG(load_ship("esso_osaka")),))
    result = compare([ship, Contender("seeds", seeds)], runs, (30.0,))
    rows = result.table[result.table.model == "seeds"]
    assert (rows.n_members == 2).all() and (rows.rmse_std > 0).all()
    assert result.verdicts["seeds"].n_members == 2 and len(result.verdicts["seeds"].member_changes) == 2
    with pytest.raises(ValueError, match="share a label"):
        compare([ship, ship], runs, (30.0,))
