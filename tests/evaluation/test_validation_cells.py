"""The verdict on validation windows judges each validation log as its own cell, resampled by
log as the test logs are: a synthetic case with a known truth (the model 40 % better than its
baseline on one log, 60 % worse on the other), one log against the old pseudo-log, a
diverged window named by its log and time, seeds pooled as members, and summary.json; the
windows judged are each log's non-overlapping ones, whose intervals hold the truth as often as
their confidence says (overlapping ones, resampled as if independent, do not)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from sysid.dynamics.rollouts import WindowOrigins, WindowSet
from sysid.evaluation.judgement import CHANNELS, CellDecision, Outcome, VerdictRule
from sysid.evaluation.verdict import (SHIP_FILE_MMG, VALIDATION, VALIDATION_LOG, BaselineVerdict, WindowScore,
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
    """The good log's windows first, then the bad log's (from t = 100 s), each starting one
    horizon after the last: independent draws cut as non-overlapping windows, so the verdict
    judges every one."""
    return WindowOrigins(("turn_good",) * W_GOOD + ("zigzag_bad",) * W_BAD,
                         np.concatenate([HORIZON * np.arange(W_GOOD), 100 + HORIZON * np.arange(W_BAD)]))


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
    one = WindowOrigins(("random_31-Jul",) * W_GOOD, 5.0 + HORIZON * np.arange(W_GOOD))
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
    w = W_GOOD + 5                  # the bad log's sixth window, from t = 250 s
    model[7:, w, :] = math.nan      # its prediction non-finite from step 8 on: sample 8, t = 258 s
    verdict = baseline_verdict("hybrid", scores(model, baseline, origins()), None, RULE)
    j = verdict.judgements[SHIP_FILE_MMG]
    assert j.outcome is Outcome.DIVERGED and not verdict.beats_baseline
    assert [d.text() for d in j.divergences] == \
        ["zigzag_bad at 30 s, t = 258 s: non-finite (in 1 of its 24 validation windows)"]
    assert {c.log for c in j.cells if c.decision is CellDecision.DIVERGED} == {"zigzag_bad"}
    assert "DIVERGED (non-finite or far outside the training data's range) in zigzag_bad at 30 s, t = 258 s" \
        in verdict.statement()


def test_seeds_pair_only_on_the_same_windows():
    """Seeds pair window by window only on the same windows (log, horizon, start time): then
    each seed is a member. Validation blocks drawn per seed give the same number of windows
    on other stretches (here 1 s later): no window pairs with another seed's, each log is a
    cell of its own, and the two seeds' windows over one stretch count once. Windows of unknown
    identity (no origins) never pair by position: no validation verdict across seeds."""
    def seed(factor: float, where: WindowOrigins | None) -> BaselineVerdict:
        _, baseline = errors(np.full(W_GOOD + W_BAD, 1.0), 0)      # the same baseline in every seed
        return baseline_verdict("hybrid", scores(baseline * factor, baseline, where), None, RULE)

    same = seed_mean_verdict([seed(0.7, origins()), seed(0.8, origins())], RULE)
    j = same.judgements[SHIP_FILE_MMG]
    assert (j.n_logs, j.n_windows, j.n_members) == (2, W_GOOD + W_BAD, 2) and j.outcome is Outcome.BEATS
    assert j.member_changes == pytest.approx([-0.3, -0.2])

    shifted = WindowOrigins(origins().logs, origins().start_s + 1.0)
    differ = seed_mean_verdict([seed(0.7, origins()), seed(0.8, shifted)], RULE)
    k = differ.judgements[SHIP_FILE_MMG]
    assert (k.n_logs, k.n_windows, k.n_members) == (2, W_GOOD + W_BAD, 1)   # a stretch of both seeds: one window
    assert {c.log for c in k.cells} == {"turn_good", "zigzag_bad"} and k.outcome is Outcome.BEATS
    # each stretch's RMSE pools its two windows: 0.7 and 0.8 x the same baseline, sqrt((0.49 + 0.64) / 2)
    assert k.change == pytest.approx(math.sqrt((0.49 + 0.64) / 2) - 1, rel=1e-9)

    unknown = seed_mean_verdict([seed(0.7, None), seed(0.8, None)], RULE)
    assert VALIDATION not in unknown.evidence and not unknown.judgements


def test_a_log_worse_in_every_seed_on_different_blocks_stays_materially_worse():
    """Known truth: the model's error is 1.6 x the baseline's on the bad log and 0.6 x on the
    good one, in each of two seeds whose validation blocks differ but hold the same number of
    windows. Paired by position in one pseudo-log (before), the 120 good windows drowned the
    24 bad ones and the seeds BEAT the baseline; per log the bad log is a materially worse
    cell and the verdict WORSE, as each seed's alone."""
    other = WindowOrigins(origins().logs, origins().start_s + HORIZON / 2)   # other blocks, the same counts
    seeds = []
    for k, where in enumerate((origins(), other)):
        model, baseline = case(20 + k)
        alone = baseline_verdict("hybrid", scores(model, baseline, where), None, RULE)
        assert alone.outcome is Outcome.WORSE
        seeds.append(alone)
    pooled = seed_mean_verdict(seeds, RULE)
    j = pooled.judgements[SHIP_FILE_MMG]
    assert pooled.decided_on == VALIDATION and j.outcome is Outcome.WORSE and j.n_members == 1
    assert {c.log for c in j.cells} == set(TRUE_FACTOR)
    bad = [c for c in j.cells if c.log == "zigzag_bad"]
    assert len(bad) == 3 and all(c.decision is CellDecision.MATERIALLY_WORSE for c in bad)
    assert all(0.4 < c.change < 0.8 for c in bad)   # the truth: +60 %
    # windows half a horizon apart share half their samples: a stretch holds both seeds' window
    assert all(c.n_windows == W_BAD for c in bad)


def test_one_stretch_drawn_by_two_seeds_is_one_piece_of_evidence():
    """Two seeds whose windows start 1 s apart over the same stretches, with the same errors
    (the same evidence twice): pooled per log, the interval of a cell is the one seed's alone,
    not the narrower one of twice as many independent windows."""
    model, baseline = case(5)
    shifted = WindowOrigins(origins().logs, origins().start_s + 1.0)
    one = baseline_verdict("hybrid", scores(model, baseline, origins()), None, RULE)
    two = seed_mean_verdict([one, baseline_verdict("hybrid", scores(model, baseline, shifted), None, RULE)], RULE)
    for a, b in zip(one.judgements[SHIP_FILE_MMG].cells, two.judgements[SHIP_FILE_MMG].cells):
        assert (a.log, a.channel, a.n_windows) == (b.log, b.channel, b.n_windows)
        assert b.change == pytest.approx(a.change, rel=1e-9)
        assert b.change_high - b.change_low == pytest.approx(a.change_high - a.change_low, rel=0.15)


def test_per_log_validation_cells_read_back_from_summary_json():
    model, baseline = case()
    verdict = baseline_verdict("hybrid", scores(model, baseline, origins()), None, RULE)
    again = BaselineVerdict.from_dict(verdict.to_dict())
    assert again.statement() == verdict.statement() and again.outcome is Outcome.WORSE
    cells = again.evidence[VALIDATION][SHIP_FILE_MMG]
    assert [c.log for c in cells] == ["turn_good"] * 3 + ["zigzag_bad"] * 3
    assert np.array_equal(cells[3].window_start_s, 100 + HORIZON * np.arange(W_BAD))
    # the cells are those `validation_cells` gives for the same scores
    found = validation_cells(*scores(model, baseline, origins())[HORIZON].values(), HORIZON)
    assert all(np.array_equal(a.model, b.model) and a.key == b.key for a, b in zip(found, cells))


# Overlapping validation windows: a log of N samples (dt 1 s) cut into windows of SPAN samples slid
# by one sample, as `[training] stride_s` slides them; the verdict judges the non-overlapping ones.
SPAN, N_SAMPLES, LOGS_DRAWN = 10, 600, 120
TRUE_CHANGE = -0.02      # the model's RMSE 2 % below its baseline's, in truth


def overlapping_log(seed: int) -> tuple[WindowScore, WindowScore]:
    """A model and its baseline on every window of one log: the baseline's error per sample
    N(0, 0.01) m/s (or rad/s), the model's that error times a factor exp(N(mu, 0.25)) drawn
    once per SPAN samples, so windows that share samples share their factors; mu sets the true
    change: sqrt(E[f^2]) = exp(mu + 0.25^2) = 1 + TRUE_CHANGE."""
    rng = np.random.default_rng(seed)
    s = 0.25
    mu = math.log(1 + TRUE_CHANGE) - s**2
    base = 0.01 * rng.normal(0, 1, (N_SAMPLES, 3))
    factor = np.repeat(np.exp(rng.normal(mu, s, (N_SAMPLES // SPAN, 3))), SPAN, axis=0)
    model = base * factor
    starts = np.arange(N_SAMPLES - SPAN + 1)                        # stride: one sample
    points = starts[:, None] + np.arange(1, SPAN)[None, :]          # each window's predicted samples
    where = WindowOrigins(("random_log",) * starts.size, starts.astype(float))

    def score(err: np.ndarray) -> WindowScore:
        per_window = np.sqrt((err[points] ** 2).mean(1))            # (W, 3)
        return WindowScore(math.nan, (math.nan,) * 3, per_window, where, np.full(starts.size, math.nan))  # type: ignore[arg-type]
    return score(model), score(base)


def test_the_validation_windows_judged_start_one_horizon_apart_and_give_the_change_on_them_alone():
    model, baseline = overlapping_log(0)
    cells = validation_cells(model, baseline, float(SPAN))
    assert [c.channel for c in cells] == list(CHANNELS)
    # greedy from t = 0 with stride 1 s and span 10 s: exactly every tenth window
    expected = 10.0 * np.arange(N_SAMPLES // SPAN)
    for c in cells:
        assert c.log == "random_log" and np.array_equal(c.window_start_s, expected)
    # recomputed independently from the per-window RMSE, windows 0, 10, 20, ...
    for j, c in enumerate(cells):
        m, b = model.window_rmse[::SPAN, j], baseline.window_rmse[::SPAN, j]
        assert np.array_equal(c.model[0], m) and np.array_equal(c.baseline[0], b)
    j = baseline_verdict("hybrid", {float(SPAN): {"model": model, SHIP_FILE_MMG: baseline}}, None,
                         RULE).judgements[SHIP_FILE_MMG]
    for c, k in zip(j.cells, range(3)):
        m, b = model.window_rmse[::SPAN, k], baseline.window_rmse[::SPAN, k]
        assert c.n_windows == 60 and c.change == pytest.approx(math.sqrt(np.mean(m**2) / np.mean(b**2)) - 1, rel=1e-9)
    assert (j.n_logs, j.n_windows) == (1, 60)


def test_greedy_thinning_keeps_windows_a_span_apart_across_gaps_and_in_time_order():
    # two validation blocks of one log (starts every 2 s), listed out of time order, and another log
    o = WindowOrigins(("a",) * 6 + ("b",) * 3 + ("a",) * 4,
                      np.array([100, 102, 104, 130, 131, 160, 0, 29.9999999, 30, 0, 2, 28, 32.0]))
    kept = o.non_overlapping(30.0)
    assert list(kept) == ["a", "b"]
    assert o.start_s[kept["a"]].tolist() == [0.0, 32.0, 100.0, 130.0, 160.0]
    assert o.start_s[kept["b"]].tolist() == [0.0, 29.9999999]      # float times within 1e-6 relative


def test_a_divergence_in_a_window_left_out_still_diverges_the_cell():
    model, baseline = overlapping_log(1)
    bad = model.window_rmse.copy()
    bad[13, 0] = math.nan              # window 13 (t = 13 s) is not among 0, 10, 20, ...
    after = model.diverged_after_s.copy()
    after[13] = 4.0
    cells = validation_cells(WindowScore(math.nan, (math.nan,) * 3, bad, model.origins, after), baseline, float(SPAN))
    assert all(np.all(np.isfinite(c.model)) for c in cells)
    assert cells[0].divergence is not None and cells[0].divergence.text() == \
        "random_log at 10 s, t = 17 s: non-finite (in 1 of its 591 validation windows)"


def test_overlapping_windows_resampled_as_independent_are_falsely_confident_the_non_overlapping_are_not():
    """Over LOGS_DRAWN logs with a known true change of -2 %, the share of cells whose 95 %
    interval misses the truth: more than half on every overlapping window (the pseudo-log, 591
    windows as if independent), about the nominal 5 % on the non-overlapping ones (60 windows)."""
    missed = {"overlapping": 0, "non-overlapping": 0}
    confident = {"overlapping": 0, "non-overlapping": 0}
    for seed in range(LOGS_DRAWN):
        model, baseline = overlapping_log(100 + seed)
        blind = [WindowScore(math.nan, s.rmse, s.window_rmse) for s in (model, baseline)]   # origins unknown
        for name, (m, b) in {"overlapping": blind, "non-overlapping": (model, baseline)}.items():
            cell = judge_u(validation_cells(m, b, float(SPAN)))
            missed[name] += not cell.change_low <= TRUE_CHANGE <= cell.change_high
            confident[name] += cell.decision is not CellDecision.NOT_DISTINGUISHABLE
    # measured: 72 and 12 of 120 missed; 68 and 17 decided with confidence (BETTER or WORSE)
    assert missed["overlapping"] / LOGS_DRAWN > 0.4
    # nominal 5 %: a percentile bootstrap on 60 windows covers a little less (binomial sd 2 %)
    assert missed["non-overlapping"] / LOGS_DRAWN < 0.15
    assert confident["overlapping"] > 3 * confident["non-overlapping"]


def judge_u(cells):
    from sysid.evaluation.judgement import judge
    return next(c for c in judge(cells, RULE).cells if c.channel == "u")


def test_seeds_on_the_same_held_out_windows_pair_on_the_same_non_overlapping_ones():
    verdicts = []
    for seed in (0, 1):
        model, baseline = overlapping_log(7 + seed)
        _, same_baseline = overlapping_log(7)
        verdicts.append(baseline_verdict("hybrid", {float(SPAN): {"model": model, SHIP_FILE_MMG: same_baseline}},
                                         None, RULE))
    j = seed_mean_verdict(verdicts, RULE).judgements[SHIP_FILE_MMG]
    assert (j.n_logs, j.n_windows, j.n_members) == (1, 60, 2) and {c.log for c in j.cells} == {"random_log"}
    cells = seed_mean_verdict(verdicts, RULE).evidence[VALIDATION][SHIP_FILE_MMG]
    assert all(np.array_equal(c.window_start_s, 10.0 * np.arange(60)) and c.model.shape == (2, 60) for c in cells)


def test_seeds_with_different_numbers_of_validation_windows_pool_every_window_per_log_and_keep_the_clause():
    """Validation blocks drawn per seed give the seeds different numbers of windows (here the
    second seed 100 of the good log's and 20 of the bad log's): no window pairs with another
    seed's, not even by position. The seeds' windows pool per log as one model's, every window
    of every seed judged: the bad log (truth 1.6 x the baseline's error) stays a materially
    worse cell, as in each seed alone, and the identified MMG's sentence keeps its validation
    clause, saying how the seeds were pooled (before, the validation verdict was dropped)."""
    from verdict_cases import seed_verdict

    from sysid.evaluation.verdict import TEST, verdict_of

    fewer = WindowOrigins(("turn_good",) * 100 + ("zigzag_bad",) * 20,
                          np.concatenate([HORIZON * np.arange(100), 100 + HORIZON * np.arange(20)]))
    factor = {True: np.array([0.6] * W_GOOD + [1.6] * W_BAD), False: np.array([0.6] * 100 + [1.6] * 20)}
    test = seed_verdict(0.8, "mmg").evidence[TEST]   # on the test logs 0.8 x the MMG's error on every window
    seeds = []
    for k, where in enumerate((origins(), fewer)):
        model, baseline = errors(factor[k == 0], 10 + k)
        on_validation = baseline_verdict("mmg", scores(model, baseline, where), None, RULE)
        assert on_validation.judgements[SHIP_FILE_MMG].outcome is Outcome.WORSE   # each seed alone
        seeds.append(verdict_of("mmg", (SHIP_FILE_MMG,), on_validation.cells, {},
                                {TEST: test, VALIDATION: on_validation.evidence[VALIDATION]}, RULE))
        assert ("On the non-overlapping validation windows the identified MMG is worse than MMG (ship file)."
                in seeds[-1].statement())
    pooled = seed_mean_verdict(seeds, RULE)
    assert pooled.decided_on == TEST and pooled.judgements[SHIP_FILE_MMG].outcome is Outcome.BEATS
    j = pooled.validation_judgements[SHIP_FILE_MMG]
    # the second seed's windows start where the first's do: each stretch of log counts once
    assert (j.n_logs, j.n_windows, j.n_members) == (2, W_GOOD + W_BAD, 1) and j.outcome is Outcome.WORSE
    bad = [c for c in j.cells if c.log == "zigzag_bad"]
    assert len(bad) == 3 and all(c.decision is CellDecision.MATERIALLY_WORSE and c.n_windows == W_BAD for c in bad)
    assert all(0.4 < c.change < 0.8 for c in bad)   # the truth: +60 %
    assert all(-0.5 < c.change < -0.3 for c in j.cells if c.log == "turn_good")   # the truth: -40 %
    assert ("On the validation windows (each log's windows of all 2 seeds pooled as one model's, a stretch of log "
            "several seeds drew counted once: the seeds drew different validation blocks, so no window pairs with another seed's) the identified MMG is worse than "
            "MMG (ship file).") in pooled.statement()
    assert "2 seeds' windows pooled as one model's (no spread per seed)" in j.sentence
    # without test logs the pooled validation windows decide, and the sentence says how
    alone = seed_mean_verdict([dataclasses.replace(v, evidence={VALIDATION: v.evidence[VALIDATION]}, decided_on=VALIDATION)
                               for v in seeds], RULE)
    assert alone.decided_on == VALIDATION and alone.outcome is Outcome.WORSE
    assert "Decided on the validation windows (each log's windows of all 2 seeds pooled" in alone.statement()


def test_a_finite_validation_prediction_beyond_the_training_range_diverges_its_log():
    """The one divergence rule on validation windows too: a prediction whose |r| runs to 0.21
    rad/s, finite but beyond 3 x the training range's 0.05 rad/s, diverges its log's cells at
    the log time of its first such sample; judged on non-finite states alone (no training
    range) it does not."""
    from sysid.evaluation.divergence import PhysicalRange

    W = 4
    states = torch.zeros(T + 1, W, 6, dtype=torch.float64)
    states[..., 1], states[..., 5] = 0.5, 0.01                       # u 0.5 m/s, r 0.01 rad/s recorded
    windows = WindowSet(states, torch.zeros(T + 1, W, 4, dtype=torch.float64), DT)
    where = WindowOrigins(("log_a", "log_a", "log_b", "log_b"), np.array([0.0, 30.0, 200.0, 230.0]))
    err = torch.full((T, W, 3), 1e-3, dtype=torch.float64)
    err[10:, 3, 2] = 0.2                                            # window 3: r = 0.21 rad/s from sample 11, t = 241 s
    w_v = torch.ones(3, dtype=torch.float64)
    limits = PhysicalRange(speed=1.0, yaw_rate=0.05)
    base = window_score(None, windows, w_v, torch.full((T, W, 3), 2e-3, dtype=torch.float64), where, limits)
    model = window_score(None, windows, w_v, err, where, limits)
    assert np.isnan(model.diverged_after_s[:3]).all() and model.diverged_after_s[3] == 11.0
    cells = validation_cells(model, base, HORIZON)
    assert {c.log for c in cells if c.divergence is not None} == {"log_b"}
    assert next(c for c in cells if c.log == "log_b").divergence.text() == \
        "log_b at 30 s, t = 241 s: beyond 3 x the training range (in 1 of its 2 validation windows)"
    verdict = baseline_verdict("hybrid", {HORIZON: {"model": model, SHIP_FILE_MMG: base}}, None, RULE)
    assert verdict.outcome is Outcome.DIVERGED
    bare = window_score(None, windows, w_v, err, where)             # no training range: finite, not diverged
    assert all(c.divergence is None for c in validation_cells(bare, base, HORIZON))


def test_windows_of_unknown_origin_diverge_by_the_same_rule():
    """The pseudo-log of windows whose logs are not known: the same finite prediction with |r|
    0.21 rad/s, beyond 3 x the training range's 0.05 rad/s in window 3, diverges it (it was
    judged on non-finite states alone there)."""
    from sysid.evaluation.divergence import PhysicalRange

    W = 4
    states = torch.zeros(T + 1, W, 6, dtype=torch.float64)
    states[..., 1], states[..., 5] = 0.5, 0.01
    windows = WindowSet(states, torch.zeros(T + 1, W, 4, dtype=torch.float64), DT)
    err = torch.full((T, W, 3), 1e-3, dtype=torch.float64)
    err[10:, 3, 2] = 0.2
    w_v = torch.ones(3, dtype=torch.float64)
    limits = PhysicalRange(speed=1.0, yaw_rate=0.05)
    base = window_score(None, windows, w_v, torch.full((T, W, 3), 2e-3, dtype=torch.float64), None, limits)
    model = window_score(None, windows, w_v, err, None, limits)
    cells = validation_cells(model, base, HORIZON)
    assert {c.log for c in cells} == {VALIDATION_LOG}
    assert all(c.divergence is not None and "window 3 of 4" in c.divergence.text() for c in cells)
    verdict = baseline_verdict("hybrid", {HORIZON: {"model": model, SHIP_FILE_MMG: base}}, None, RULE)
    assert verdict.outcome is Outcome.DIVERGED
    bare = window_score(None, windows, w_v, err)
    assert all(c.divergence is None for c in validation_cells(bare, base, HORIZON))
