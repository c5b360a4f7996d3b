"""A run's verdict as summary.json keeps it, and the verdict of several seeds: every seed a
member of the model, the ship file's MMG counted once, the spread on page 1; a verdict written
before the rule reads back with its old decision."""
from __future__ import annotations

import numpy as np
import pytest

from sysid.evaluation.judgement import Outcome
from sysid.evaluation.verdict import SHIP_FILE_MMG, TEST, BaselineVerdict, seed_mean_verdict
from sysid.report.tables import verdict_table

from verdict_cases import RULE, seed_verdict

def test_seeds_are_members_their_spread_is_shown_and_the_mmg_counts_once():
    seeds = [seed_verdict(f) for f in (0.6, 0.8, 1.3)]
    assert [s.beats_baseline for s in seeds] == [True, True, False]
    both = seed_mean_verdict(seeds, RULE)
    j = both.judgements[SHIP_FILE_MMG]
    assert (j.n_members, j.n_logs, j.n_windows) == (3, 3, 24) and both.seeds == 3
    assert all(c.n_members == 3 for c in j.cells)
    assert j.member_changes == pytest.approx([-0.4, -0.2, 0.3])
    assert j.change == pytest.approx(np.sqrt(np.mean(np.array([0.6, 0.8, 1.3]) ** 2)) - 1)
    # one seed 30 % worse: the seeds' draw puts no change inside the interval
    assert j.change_low < 0 < j.change_high and j.outcome is Outcome.NOT_DISTINGUISHABLE
    assert both.statement().startswith("The hybrid (mean over 3 seeds) cannot be told apart from its physics "
                                       "baseline MMG (ship file) on 24 windows")
    assert "3 seeds or members (each alone -40 % to +30 %)" in both.statement()
    table = verdict_table(both, "hybrid")
    spread = np.std([0.6, 0.8, 1.3], ddof=1)
    first = both.evidence[TEST][SHIP_FILE_MMG][0]
    expected = spread * np.sqrt(np.mean(first.baseline ** 2))
    assert table.rows[0][5].endswith(f" ± {expected:.5f}") and len(table.rows) == 9


def test_a_verdict_reads_back_from_summary_json_and_an_old_one_keeps_its_decision():
    verdict = seed_verdict(0.6)
    again = BaselineVerdict.from_dict(verdict.to_dict())
    assert again.judgements == verdict.judgements and again.beats_baseline and again.outcome is Outcome.BEATS
    assert again.statement() == verdict.statement()
    first, back = verdict.evidence[TEST][SHIP_FILE_MMG][0], again.evidence[TEST][SHIP_FILE_MMG][0]
    assert np.array_equal(first.model, back.model) and np.array_equal(first.window_start_s, back.window_start_s)
    old = {k: v for k, v in verdict.to_dict().items()
           if k not in ("judgements", "validation_judgements", "evidence", "outcome")}
    for beats in (True, False):
        legacy = BaselineVerdict.from_dict({**old, "beats_baseline": beats})
        assert legacy.beats_baseline is beats and legacy.outcome is None and not legacy.judgements
        assert "the pooled rule of a run written before sysid judged per log" in legacy.statement()
    table = verdict_table(BaselineVerdict.from_dict({**old, "beats_baseline": False}), "hybrid")
    assert [r[1] for r in table.rows] == ["all (pooled)"] * 3


def test_seeds_whose_validation_horizons_differ_pool_each_cell_with_its_own():
    """Validation blocks drawn per seed: one seed's blocks may hold no 100-s window (that
    horizon left out), so the seeds' cells differ in number. Each pooled cell is the mean of
    the same split, horizon and channel in every seed (0.4 and 0.6: 0.5); a cell one seed
    lacks is left out of the table; the test cells pool as before (0.6 and 0.8 x the MMG's)."""
    from dataclasses import replace

    from sysid.evaluation.verdict import VALIDATION, ChannelCell

    def validation(model: float, horizons) -> tuple:
        return tuple(ChannelCell(VALIDATION, h, c, model, {SHIP_FILE_MMG: 1.0}) for h in horizons for c in ("u", "v_m", "r"))

    a, b = seed_verdict(0.6), seed_verdict(0.8)
    a = replace(a, cells=validation(0.4, (30.0, 100.0)) + a.cells)
    b = replace(b, cells=validation(0.6, (30.0,)) + b.cells)
    both = seed_mean_verdict([a, b], RULE)
    pooled = {(c.split, c.horizon_s, c.channel): c for c in both.cells}
    assert {k for k in pooled if k[0] == VALIDATION} == {(VALIDATION, 30.0, c) for c in ("u", "v_m", "r")}
    assert pooled[(VALIDATION, 30.0, "u")].model == pytest.approx(0.5)
    assert pooled[(VALIDATION, 30.0, "u")].model_std == pytest.approx(np.std([0.4, 0.6], ddof=1))
    assert pooled[(TEST, 30.0, "r")].model == pytest.approx(0.7)
