"""The verdict on validation windows judges each validation log as its own cell, resampled by
log as the test logs are: a synthetic case with a known truth (the model 40 % better than its
baseline on one log, 60 % worse on the other), one log against the old pseudo-log, a
diverged window named by its log and time, seeds pooled as members, and summary.json."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from sysid.dynamics.rollouts import WindowOrigins, WindowSet
from sysid.evaluation.judgement import CHANNELS, CellDecision, Outcome, VerdictRule
from sysid.evaluation.verdict import (SHIP_FILE_MMG, VALIDATION, VALIDATION_LOG, BaselineVerdict, pseudo_log,
                                      seed_mean_verdict, validation_cells, window_score, baseline_verdict)

RULE = VerdictRule(resamples=1000)
T, DT, HORIZON = 30, 1.0, 30.0
W_GOOD, W_BAD = 120, 24          # windows of the log where the model is better, and of the one where it is worse
TRUE_FACTOR = {"turn_good": 0.6, "zigzag_bad": 1.6}   # the model's error / the baseline's, per log


def errors(factor: np.ndarray, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(T, W, 3) velocity errors of a baseline and of a model whose error is `factor` (W,) x
    the baseline's, each window's scaled by a random lognormal spread around that truth."""
    rng = np.random.default_rng(seed)
    W = factor.size
    level = 0.01 * np.exp(rng.normal(0, 0.3, (1, W, 3)))                  # each window's own error level
    baseline = level * rng.normal(0, 1, (T, W, 3))
    model = baseline * (factor[None, :, None] * np.exp(rng.normal(0, 0.15, (1, W, 3))))
    return torch.as_tensor(model), torch.as_tensor(baseline)


def origins() -> WindowOrigins:
    """The good log's windows first (starts every 2 s), then the bad log's (from t = 100 s)."""
    return WindowOrigins(("turn_good",) * W_GOOD + ("zigzag_bad",) * W_BAD,
                         np.concatenate([2.0 * np.arange(W_GOOD), 100 + 2.0 * np.arange(W_BAD)]))


def scores(model: torch.Tensor, baseline: torch.Tensor, where: WindowOrigins | None) -> dict:
    windows = WindowSet(torch.zeros(T + 1, model.shape[1], 6, dtype=torch.float64),
                        torch.zeros(T + 1, model.shape[1], 4, dtype=torch.float64), DT)
    w_v = torch.ones(3, dtype=torch.float64)
    return {HORIZON: {"model": window_score(None, windows, w_v, model, where),
                      SHIP_FILE_MMG: window_score(None, windows, w_v, baseline, where)}}


def case(seed: int = 0):
    factor = np.array([TRUE_FACTOR["turn_good"]] * W_GOOD + [TRUE_FACTOR["zigzag_bad"]] * W_BAD)
    return errors(factor, seed)


def test_a_log_materially_worse_fails_the_verdict_and_is_named_where_the_pseudo_log_averaged_it_away():
    model, baseline = case()
    per_log = baseline_verdict("hybrid", scores(model, baseline, origins()), None, RULE)
    j = per_log.judgements[SHIP_FILE_MMG]
    assert per_log.decided_on == VALIDATION and (j.n_logs, j.n_windows) == (2, W_GOOD + W_BAD)
    by = {(c.log, c.channel): c for c in j.cells}
    assert {log for log, _ in by} == set(TRUE_FACTOR)
    m, b = model.numpy(), baseline.numpy()
    for (log, channel), c in by.items():
        index = slice(0, W_GOOD) if log == "turn_good" else slice(W_GOOD, None)
        k = CHANNELS.index(channel)
        rmse_m, rmse_b = np.sqrt((m[:, index, k] ** 2).mean(0)), np.sqrt((b[:, index, k] ** 2).mean(0))
        # the cell's change: the log's windows only, pooled; within the noise of the truth
        assert c.change == pytest.approx(math.sqrt(np.mean(rmse_m**2) / np.mean(rmse_b**2)) - 1, rel=1e-9)
        assert c.change == pytest.approx(TRUE_FACTOR[log] - 1, abs=0.1)
        assert c.n_windows == (W_GOOD if log == "turn_good" else W_BAD)
        assert c.decision is (CellDecision.BETTER if log == "turn_good" else CellDecision.MATERIALLY_WORSE)
    # the truth: better overall (geometric mean of 0.6 and 1.6 is 0.98) but 60 % worse on one log
    assert j.outcome is Outcome.WORSE and not per_log.beats_baseline
    assert {c.log for c in j.materially_worse} == {"zigzag_bad"} and j.worst[0].log == "zigzag_bad"
    sentence = per_log.statement()
    assert "is WORSE than its physics baseline MMG (ship file): more than 10 % worse at 95 % confidence in " \
           "zigzag_bad " in sentence and "on 2 logs, 144 windows" in sentence
    # with two logs the overall interval resamples logs: it spans both logs' changes
    assert j.change_low < 0 < j.change_high

    pooled = baseline_verdict("hybrid", scores(model, baseline, None), None, RULE).judgements[SHIP_FILE_MMG]
    # one pseudo-log pools every window: the 120 better windows drown the 24 worse ones
    assert pooled.n_logs == 1 and {c.log for c in pooled.cells} == {VALIDATION_LOG}
    assert pooled.outcome is Outcome.BEATS and all(c.change < 0 for c in pooled.cells)


def test_one_validation_log_judges_as_the_pseudo_log_did():
    factor = np.full(W_GOOD, 0.8)
    model, baseline = errors(factor, 3)
    one = WindowOrigins(("random_31-Jul",) * W_GOOD, 5.0 + 2.0 * np.arange(W_GOOD))
    per_log = baseline_verdict("hybrid", scores(model, baseline, one), None, RULE).judgements[SHIP_FILE_MMG]
    before = baseline_verdict("hybrid", scores(model, baseline, None), None, RULE).judgements[SHIP_FILE_MMG]
    assert {c.log for c in per_log.cells} == {"random_31-Jul"} and {c.log for c in before.cells} == {VALIDATION_LOG}
    assert per_log.outcome is before.outcome is Outcome.BEATS
    for field in ("change", "change_low", "change_high", "member_changes", "n_logs", "n_windows", "n_members"):
        assert getattr(per_log, field) == getattr(before, field), field
    for a, b in zip(per_log.cells, before.cells):
        assert (a.channel, a.n_windows, a.model_rmse, a.baseline_rmse, a.change, a.change_low, a.change_high,
                a.decision) == (b.channel, b.n_windows, b.model_rmse, b.baseline_rmse, b.change, b.change_low,
                                b.change_high, b.decision)
    assert per_log.sentence.replace("random_31-Jul", VALIDATION_LOG) == before.sentence


def test_a_non_finite_validation_window_names_its_log_and_time():
    model, baseline = case()
    w = W_GOOD + 5                  # the bad log's sixth window, from t = 110 s
    model[7:, w, :] = math.nan      # its prediction non-finite from step 8 on: sample 8, t = 118 s
    verdict = baseline_verdict("hybrid", scores(model, baseline, origins()), None, RULE)
    j = verdict.judgements[SHIP_FILE_MMG]
    assert j.outcome is Outcome.DIVERGED and not verdict.beats_baseline
    assert [d.text() for d in j.divergences] == \
        ["zigzag_bad at 30 s, t = 118 s: non-finite (in 1 of its 24 validation windows)"]
    assert {c.log for c in j.cells if c.decision is CellDecision.DIVERGED} == {"zigzag_bad"}
    assert "DIVERGED (non-finite or far outside the training data's range) in zigzag_bad at 30 s, t = 118 s" \
        in verdict.statement()


def test_seeds_pool_per_log_on_the_same_windows_and_as_the_pseudo_log_on_different_ones():
    def seed(factor: float, where: WindowOrigins | None) -> BaselineVerdict:
        _, baseline = errors(np.full(W_GOOD + W_BAD, 1.0), 0)      # the same baseline in every seed
        return baseline_verdict("hybrid", scores(baseline * factor, baseline, where), None, RULE)

    same = seed_mean_verdict([seed(0.7, origins()), seed(0.8, origins())], RULE)
    j = same.judgements[SHIP_FILE_MMG]
    assert (j.n_logs, j.n_windows, j.n_members) == (2, W_GOOD + W_BAD, 2) and j.outcome is Outcome.BEATS
    assert j.member_changes == pytest.approx([-0.3, -0.2])

    # validation blocks drawn per seed: the second seed's windows start 1 s later, so no log pairs
    shifted = WindowOrigins(origins().logs, origins().start_s + 1.0)
    seeds = [seed(0.7, origins()), seed(0.8, shifted)]
    differ = seed_mean_verdict(seeds, RULE)
    k = differ.judgements[SHIP_FILE_MMG]
    assert (k.n_logs, k.n_windows, k.n_members) == (1, W_GOOD + W_BAD, 2) and {c.log for c in k.cells} == {VALIDATION_LOG}
    # as the pseudo-log verdicts of before pool: the same numbers
    before = seed_mean_verdict([seed(0.7, None), seed(0.8, None)], RULE).judgements[SHIP_FILE_MMG]
    assert (k.change, k.change_low, k.change_high, k.outcome) == (before.change, before.change_low,
                                                                  before.change_high, before.outcome)
    first = seeds[0].evidence[VALIDATION][SHIP_FILE_MMG]
    again = pseudo_log(first)
    assert [c.n_windows for c in again] == [W_GOOD + W_BAD] * 3
    assert np.array_equal(again[0].model, np.concatenate([first[0].model, first[3].model], axis=1))


def test_per_log_validation_cells_read_back_from_summary_json():
    model, baseline = case()
    verdict = baseline_verdict("hybrid", scores(model, baseline, origins()), None, RULE)
    again = BaselineVerdict.from_dict(verdict.to_dict())
    assert again.statement() == verdict.statement() and again.outcome is Outcome.WORSE
    cells = again.evidence[VALIDATION][SHIP_FILE_MMG]
    assert [c.log for c in cells] == ["turn_good"] * 3 + ["zigzag_bad"] * 3
    assert np.array_equal(cells[3].window_start_s, 100 + 2.0 * np.arange(W_BAD))
    # the cells are those `validation_cells` gives for the same scores
    found = validation_cells(*scores(model, baseline, origins())[HORIZON].values(), HORIZON)
    assert all(np.array_equal(a.model, b.model) and a.key == b.key for a, b in zip(found, cells))
