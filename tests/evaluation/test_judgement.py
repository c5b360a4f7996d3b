"""The verdict's rule (`sysid.evaluation.judgement.judge`): its properties over generated cells,
and the issue's cases with numbers, among them the paper's own Tables 7/8 (NN-only D1 is more
than 10 % worse than the MMG in 8 scenario-channel cells and must not be called better)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from sysid.evaluation.judgement import (CHANNELS, CellDecision, Divergence, Outcome, PairedCell, VerdictRule,
                                        deciding_windows, interval_text, judge, widening)
from sysid.protocol.paper import SCENARIO_ORDER, paper_table

RULE = VerdictRule(resamples=1000)
PROPERTY = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def cells_of(ratios: dict[tuple[str, float, str], np.ndarray], baseline: dict | None = None, members: int = 1,
             rng: np.random.Generator | None = None) -> list[PairedCell]:
    """Cells whose model per-window RMSE is the baseline's times `ratios[(log, horizon, channel)]`
    (one ratio per window); the baseline's per-window RMSE is drawn once per (log, horizon)."""
    rng = rng or np.random.default_rng(1)
    out = []
    for (log, horizon, channel), ratio in sorted(ratios.items()):
        ratio = np.atleast_1d(np.asarray(ratio, dtype=float))
        base = (baseline or {}).get((log, horizon, channel))
        if base is None:
            base = 0.01 + 0.02 * rng.random(ratio.size)
        model = np.tile(base * ratio, (members, 1))
        out.append(PairedCell(log, log.title(), horizon, channel, model, base[None, :],
                              horizon * np.arange(ratio.size)))
    return out


def uniform(logs: int, windows: int, ratio_of, horizons=(30.0, 100.0)) -> dict:
    """(log, horizon, channel) -> per-window ratios ratio_of(log index, horizon, channel, windows)."""
    return {(f"log{i}", h, c): ratio_of(i, h, c, windows) for i in range(logs) for h in horizons for c in CHANNELS}


# -- properties -----------------------------------------------------------------------------

ratio_sets = st.integers(2, 5).flatmap(lambda logs: st.tuples(
    st.just(logs), st.integers(3, 12),
    st.lists(st.floats(0.3, 1.5), min_size=logs * 6, max_size=logs * 6),
    st.integers(0, 10_000)))


def generated(logs: int, windows: int, means: list[float], seed: int, spread: float = 0.2) -> dict:
    """Each cell's windows scattered by +-spread around its mean ratio."""
    rng = np.random.default_rng(seed)
    keys = sorted(uniform(logs, windows, lambda *a: None))
    return {k: m * (1 + spread * (2 * rng.random(windows) - 1)) for k, m in zip(keys, means)}


@PROPERTY
@given(ratio_sets, st.integers(0, 10 ** 6))
def test_a_non_finite_cell_is_never_better(data, pick):
    logs, windows, means, seed = data
    ratios = generated(logs, windows, means, seed)
    cells = cells_of(ratios)
    bad = cells[pick % len(cells)]
    model = bad.model.copy()
    model[0, pick % windows] = [math.nan, math.inf][pick % 2]
    cells[pick % len(cells)] = PairedCell(bad.log, bad.scenario, bad.horizon_s, bad.channel, model, bad.baseline,
                                          bad.window_start_s)
    j = judge(cells, RULE)
    assert j.outcome is Outcome.DIVERGED and not j.beats
    assert [c.decision for c in j.cells].count(CellDecision.DIVERGED) == 1
    assert "DIVERGED" in j.sentence and bad.scenario in j.sentence


@PROPERTY
@given(ratio_sets, st.randoms(use_true_random=False))
def test_the_order_of_logs_changes_nothing(data, random):
    logs, windows, means, seed = data
    cells = cells_of(generated(logs, windows, means, seed))
    shuffled = list(cells)
    random.shuffle(shuffled)
    assert judge(shuffled, RULE).to_dict() == judge(cells, RULE).to_dict()


@PROPERTY
@given(ratio_sets, st.integers(0, 10 ** 6), st.integers(1, 12), st.sampled_from([0.3, 0.5, 0.9]))
def test_one_scenario_60_percent_worse_fails_whatever_the_average(data, pick, bad_windows, others):
    """Every other cell 10-70 % better; one log's cells 60 % worse (+-20 % per window) on 1 to 12
    windows: never "beats"; on more than 3 windows (`min_windows`) "worse", naming that log. On
    exactly 3 the interval is widened 2.69 x for so few windows (`widening`), and a draw whose
    3 windows scatter widely is rightly not decided (measured: 1 draw in 40)."""
    logs, windows, _, seed = data
    rng = np.random.default_rng(seed)
    ratios = uniform(logs, windows, lambda i, h, c, w: others * (1 + 0.1 * (2 * rng.random(w) - 1)))
    bad = f"log{pick % logs}"
    for key in [k for k in ratios if k[0] == bad]:
        n = bad_windows if key[1] == 30.0 else max(1, bad_windows // 3)
        ratios[key] = 1.6 * (1 + 0.2 * (2 * rng.random(n) - 1))
    j = judge(cells_of(ratios), RULE)
    assert not j.beats
    assert all(c.log == bad for c in j.worst)
    if bad_windows > RULE.min_windows:
        assert j.outcome is Outcome.WORSE
        assert {c.log for c in j.materially_worse} == {bad} and bad.title() in j.sentence
    elif bad_windows == RULE.min_windows:
        assert j.outcome in (Outcome.WORSE, Outcome.NOT_DISTINGUISHABLE)
        assert {c.log for c in j.materially_worse} <= {bad}
    else:
        assert j.outcome is Outcome.NOT_DISTINGUISHABLE


@PROPERTY
@given(ratio_sets, st.integers(1, 5))
def test_a_model_equal_to_its_baseline_is_not_distinguishable(data, members):
    logs, windows, means, seed = data
    j = judge(cells_of(uniform(logs, windows, lambda *a: np.ones(a[3])), members=members), RULE)
    assert j.outcome is Outcome.NOT_DISTINGUISHABLE
    assert j.change == 0 and j.change_low == 0 and j.change_high == 0
    assert {c.decision for c in j.cells} == {CellDecision.NOT_DISTINGUISHABLE}
    assert f"on {logs * windows * 2} windows" in j.sentence


@PROPERTY
@given(ratio_sets, st.integers(2, 4))
def test_more_windows_of_the_same_effect_only_sharpen_the_decision(data, k):
    """Each window repeated k times: the same point changes; a decided cell or outcome stays
    decided the same way, intervals only narrow."""
    logs, windows, means, seed = data
    ratios = generated(logs, windows, means, seed)
    rng = np.random.default_rng(seed + 1)
    baseline = {key: 0.01 + 0.02 * rng.random(windows) for key in ratios}
    once = judge(cells_of(ratios, baseline), RULE)
    more = judge(cells_of({key: np.tile(r, k) for key, r in ratios.items()},
                          {key: np.tile(b, k) for key, b in baseline.items()}), RULE)
    # the change is the ratio rounded to 12 digits, minus 1: the same ratio at round-off can round
    # to the next 12-digit value, 1e-12 apart
    assert more.change == pytest.approx(once.change, abs=1.5e-12)
    if once.outcome is not Outcome.NOT_DISTINGUISHABLE:
        assert more.outcome is once.outcome
    sharper = {CellDecision.WORSE: {CellDecision.WORSE, CellDecision.MATERIALLY_WORSE}}
    for a, b in zip(once.cells, more.cells):
        assert b.change == pytest.approx(a.change, abs=1.5e-12)
        if a.decision not in (CellDecision.NOT_DISTINGUISHABLE, CellDecision.TOO_FEW_WINDOWS):
            assert b.decision in sharper.get(a.decision, {a.decision}), (a, b)
        if a.decision is not CellDecision.TOO_FEW_WINDOWS:
            assert b.change_high - b.change_low <= a.change_high - a.change_low + 0.01


def test_the_same_seed_gives_the_same_judgement_and_the_rule_is_stated():
    cells = cells_of(generated(4, 6, list(np.linspace(0.5, 1.2, 24)), 3))
    assert judge(cells, RULE).to_dict() == judge(cells, RULE).to_dict()
    j = judge(cells, VerdictRule(confidence=0.9, resamples=500, seed=7))
    assert j.confidence == 0.9 and "90 % interval" in j.sentence


# -- the cases, with numbers --------------------------------------------------------

def paper_cells(model: str, dataset: str) -> list[PairedCell]:
    """The paper's Tables 7/8 as cells: one scenario = one log, its RMSE = one window."""
    table = paper_table()
    mmg = table[(table.model == "MMG") & (table.dataset == dataset)].set_index(["scenario", "horizon_s"])
    out = []
    for row in table[(table.model == model) & (table.dataset == dataset)].itertuples():
        for channel, column in zip(CHANNELS, ("rmse_u", "rmse_v", "rmse_r")):
            out.append(PairedCell(row.scenario, row.scenario, row.horizon_s, channel, [[getattr(row, column)]],
                                  [[mmg.loc[(row.scenario, row.horizon_s), column]]], [0.0]))
    return out


def test_the_papers_nn_only_d1_is_not_called_better_and_its_worst_scenarios_are_named():
    j = judge(paper_cells("NN", "D1"), RULE, model="The NN-only model", baseline="the MMG")
    assert j.outcome is Outcome.NOT_DISTINGUISHABLE
    assert (j.n_logs, j.n_windows, j.n_members) == (6, 12, 1)
    # geometric mean of the 36 ratios: 34 % lower, yet 8 cells more than 10 % worse
    assert j.change == pytest.approx(-0.3368, abs=1e-4)
    over = sorted((c for c in j.cells if c.change > 0.10), key=lambda c: -c.change)
    assert len(over) == 8 and {c.scenario for c in over} == {"Random", "Zigzag 30/30"}
    assert over[0].where == "Zigzag 30/30 u at 100 s" and over[0].change == pytest.approx(0.0659 / 0.0273 - 1)
    assert [c.where for c in j.worst] == ["Zigzag 30/30 u at 100 s", "Random v_m at 100 s", "Random u at 30 s"]
    assert j.worst[2].change == pytest.approx(0.034 / 0.021 - 1)          # +62 %
    assert "8 cells are more than 10 % worse" in j.sentence and "Zigzag 30/30 u at 100 s +141 %" in j.sentence


def test_the_papers_hybrid_d1_beats_the_mmg():
    j = judge(paper_cells("Hybrid", "D1"), RULE)
    assert j.outcome is Outcome.BEATS
    assert j.change == pytest.approx(-0.4616, abs=1e-4) and j.change_high < 0
    assert j.worst[0].where == "Zigzag 30/30 u at 100 s" and j.worst[0].change == pytest.approx(0.0283 / 0.0273 - 1)


def test_a_model_diverging_on_one_log_and_a_little_better_elsewhere_does_not_pass():
    ratios = uniform(3, 8, lambda i, h, c, w: np.full(w, 0.95))
    cells = cells_of(ratios)
    where = Divergence("log2", 30.0, 412.0, "r", "non-finite")
    cells = [PairedCell(c.log, c.scenario, c.horizon_s, c.channel, np.full_like(c.model, np.nan), c.baseline,
                        c.window_start_s, where) if (c.log, c.horizon_s) == ("log2", 30.0) else c for c in cells]
    j = judge(cells, RULE)
    assert j.outcome is Outcome.DIVERGED and j.divergences == (where,)       # named once, not per channel
    assert "log2 at 30 s, t = 412 s, r: non-finite" in j.sentence
    assert j.change == pytest.approx(-0.05)       # the cells that stayed finite, said beside it
    # a divergence record with finite numbers (far outside the training range) counts the same
    far = Divergence("log0", 100.0, 37.0, "u", "|u| 4.1 m/s beyond 3 x the training range 1.2 m/s")
    cells = [PairedCell(c.log, c.scenario, c.horizon_s, c.channel, c.model, c.baseline, c.window_start_s, far)
             if (c.log, c.horizon_s, c.channel) == ("log0", 100.0, "u") else c for c in cells_of(ratios)]
    assert judge(cells, RULE).outcome is Outcome.DIVERGED


def test_r_a_little_worse_everywhere_passes_within_the_tolerance_and_is_said():
    """r 9.5 % worse in every log at both horizons (+-0.5 % per window), u and v_m 30 % better:
    worse with confidence, within the 10 % tolerance; the model beats its baseline and the
    sentence names r first among the worst cells."""
    rng = np.random.default_rng(0)
    ratios = uniform(4, 10, lambda i, h, c, w: (1.095 if c == "r" else 0.7) * (1 + 0.005 * (2 * rng.random(w) - 1)))
    j = judge(cells_of(ratios), RULE)
    r_cells = [c for c in j.cells if c.channel == "r"]
    assert {c.decision for c in r_cells} == {CellDecision.WORSE}
    assert all(0.09 < c.change_low and c.change_high < 0.10 for c in r_cells)
    assert j.outcome is Outcome.BEATS and {c.channel for c in j.worst} == {"r"}
    assert f"worst cells: {j.worst[0].where} +9." in j.sentence


def test_one_cell_11_percent_worse_keeps_the_verdict_open_until_the_evidence_says_worse():
    """Every cell 50 % better but one at +11 %: on 6 windows at +6 to +17 % the interval
    reaches below +10 %, so the verdict stays open ("cannot be told apart", the cell named);
    on 20 windows at +11 % +-0.5 % the cell is materially worse and so is the model."""
    rng = np.random.default_rng(0)

    def with_bad(spread, windows):
        ratios = uniform(4, windows, lambda i, h, c, w: np.full(w, 0.5))
        ratios[("log1", 30.0, "u")] = 1.11 * (1 + spread * (2 * rng.random(windows) - 1))
        return judge(cells_of(ratios), RULE)

    loose = with_bad(0.05, 6)
    cell = next(c for c in loose.cells if (c.log, c.horizon_s, c.channel) == ("log1", 30.0, "u"))
    assert cell.change_low < 0.10 < cell.change and cell.decision is CellDecision.WORSE
    assert loose.outcome is Outcome.NOT_DISTINGUISHABLE and loose.change_high < -0.4
    assert "1 cell is more than 10 % worse without the evidence to decide" in loose.sentence
    assert "Log1 u at 30 s +11 %" in loose.sentence
    tight = with_bad(0.005, 20)
    cell = next(c for c in tight.cells if (c.log, c.horizon_s, c.channel) == ("log1", 30.0, "u"))
    assert cell.change_low > 0.10 and cell.decision is CellDecision.MATERIALLY_WORSE
    assert tight.outcome is Outcome.WORSE and "Log1 u at 30 s +11 %" in tight.sentence


def test_worse_in_cells_but_better_overall_says_the_cells_first_then_the_overall_gain():
    """Every cell exactly 50 % better but Log1 u at 30 s exactly +25 % and Log2 r at 100 s
    exactly +40 % (20 windows each): WORSE by those two cells although the overall change is
    the geometric mean of the 24 ratios, -46 %; the sentence says so in that order. With the
    model worse everywhere the WORSE sentence keeps its form."""
    ratios = uniform(4, 20, lambda i, h, c, w: np.full(w, 0.5))
    ratios[("log1", 30.0, "u")] = np.full(20, 1.25)
    ratios[("log2", 100.0, "r")] = np.full(20, 1.40)
    j = judge(cells_of(ratios), RULE, model="mmg_id", baseline="hybrid")
    truth = math.exp((22 * math.log(0.5) + math.log(1.25) + math.log(1.40)) / 24) - 1
    assert j.outcome is Outcome.WORSE and j.change == pytest.approx(truth) and j.change_high < 0
    assert j.sentence == (
        "mmg_id is WORSE than hybrid in 2 cells, each more than 10 % worse at 95 % confidence "
        "(Log1 u at 30 s +25 % (+25 % to +25 %, 20 windows); Log2 r at 100 s +40 % (+40 % to +40 %, 20 windows)), "
        f"although better overall: RMSE -46 % (95 % interval {interval_text(j.change_low, j.change_high)}), "
        "on 4 logs, 160 windows, 1 seed (no spread: one model).")
    ratios[("log2", 100.0, "r")] = np.full(20, 0.5)
    one = judge(cells_of(ratios), RULE)
    assert one.sentence.startswith("The model is WORSE than its baseline in 1 cell, more than 10 % worse at 95 % "
                                   "confidence (Log1 u at 30 s +25 % (+25 % to +25 %, 20 windows)), although")
    worse = judge(cells_of(uniform(4, 20, lambda i, h, c, w: np.full(w, 1.25))), RULE)
    assert worse.change == pytest.approx(0.25)
    assert worse.sentence.startswith("The model is WORSE than its baseline: more than 10 % worse at 95 % confidence "
                                     "in Log0 u at 30 s +25 % (+25 % to +25 %, 20 windows);")
    assert "; RMSE +25 % overall (95 % interval +25 % to +25 %), on 4 logs" in worse.sentence


def test_several_members_are_resampled_and_their_spread_is_shown():
    rng = np.random.default_rng(2)
    cells = []
    for log in ("a", "b", "c"):
        base = 0.01 + 0.01 * rng.random(6)
        for channel in CHANNELS:
            model = base[None, :] * np.array([[0.6], [0.7], [0.8], [0.9], [1.3]])   # 5 seeds
            cells.append(PairedCell(log, log, 30.0, channel, model, base[None, :], np.arange(6) * 30.0))
    j = judge(cells, RULE)
    assert j.n_members == 5 and len(j.member_changes) == 5
    assert j.member_changes == pytest.approx([-0.4, -0.3, -0.2, -0.1, 0.3])
    # pooled over seeds: sqrt(mean(ratio^2)) - 1, the seeds' draw makes the interval wide
    assert j.change == pytest.approx(math.sqrt(np.mean(np.array([0.6, 0.7, 0.8, 0.9, 1.3]) ** 2)) - 1)
    assert j.change_low < -0.2 and j.change_high > 0 and j.outcome is Outcome.NOT_DISTINGUISHABLE
    assert "5 seeds or members (each alone -40 % to +30 %)" in j.sentence
    one = judge([PairedCell(c.log, c.scenario, c.horizon_s, c.channel, c.model[:1], c.baseline, c.window_start_s)
                 for c in cells], RULE)
    assert "1 seed (no spread: one model)" in one.sentence and one.outcome is Outcome.BEATS


def test_cells_that_do_not_pair_are_refused():
    with pytest.raises(ValueError, match="do not pair"):
        PairedCell("a", "", 30.0, "u", np.ones((1, 3)), np.ones((1, 2)), np.arange(3))
    cells = cells_of(uniform(1, 3, lambda *a: np.ones(a[3])))
    with pytest.raises(ValueError, match="share a log"):
        judge(cells + cells[:1], RULE)


def test_a_judgement_reads_back_from_its_dict():
    from sysid.evaluation.judgement import Judgement
    j = judge(paper_cells("NN", "D1"), RULE)
    assert Judgement.from_dict(j.to_dict()) == j


def test_every_scenario_of_the_paper_is_a_log():
    assert {c.log for c in paper_cells("NN", "D1")} == set(SCENARIO_ORDER)


def test_logs_of_one_scenario_are_named_by_the_log_in_the_sentence():
    """A user's test logs: two turning circles of 20 deg (one materially worse, one better)
    and one zig-zag. The sentence names the worse cell by its log ("Turning 20: turn_b"),
    never the bare scenario the two share; the zig-zag, alone in its scenario, keeps its
    scenario's name."""
    from sysid.evaluation.judgement import place_names

    rng = np.random.default_rng(7)
    ratios = {("turn_a", 30.0, c): np.full(12, 0.8) for c in CHANNELS}
    ratios.update({("turn_b", 30.0, c): np.full(12, 1.6 if c == "r" else 0.8) for c in CHANNELS})
    ratios.update({("zz_1", 30.0, c): np.full(12, 0.9) for c in CHANNELS})
    scenario = {"turn_a": "Turning 20", "turn_b": "Turning 20", "zz_1": "Zigzag 20/20"}
    cells = [PairedCell(c.log, scenario[c.log], c.horizon_s, c.channel, c.model, c.baseline, c.window_start_s)
             for c in cells_of(ratios, rng=rng)]
    j = judge(cells, RULE, model="The hybrid", baseline="MMG (ship file)")
    assert j.outcome is Outcome.WORSE
    assert "confidence (Turning 20: turn_b r at 30 s +60 %" in j.sentence
    assert "Turning 20 r" not in j.sentence and "turn_a" not in j.sentence
    assert place_names(j.cells) == {"turn_a": "Turning 20: turn_a", "turn_b": "Turning 20: turn_b",
                                    "zz_1": "Zigzag 20/20"}
    # the report's first page names the same logs, cell by cell
    from sysid.evaluation.verdict import BaselineVerdict
    from sysid.report.tables import verdict_table

    table = verdict_table(BaselineVerdict("hybrid", ("MMG (ship file)",), (), judgements={"MMG (ship file)": j}),
                          "hybrid")
    assert [row[1] for row in table.rows] == [place_names(j.cells)[c.log] for c in j.cells]
    assert {row[1] for row in table.rows} == {"Turning 20: turn_a", "Turning 20: turn_b", "Zigzag 20/20"}


def test_a_baseline_exact_on_some_windows_gives_finite_intervals_without_warnings():
    """Noise-free logs of the ship file's own MMG: in straight running the baseline's v_m and
    r errors are exactly 0, so some draws of a cell hold only such windows. Such a draw's
    ratio is capped (RATIO_CAP), not infinite: every interval and the overall change stay
    finite, numpy warns of nothing, and a model worse on every window is WORSE. Cells with
    no exact window are judged as before (ratios below the cap are untouched)."""
    import warnings

    from sysid.evaluation.judgement import RATIO_CAP, _resampled_ratio

    base = np.r_[np.zeros(6), np.full(4, 0.01)]     # 6 straight windows, exact; 4 turning ones
    cells = [PairedCell(log, log.title(), 30.0, ch, (base + 0.004)[None, :], base[None, :], 30.0 * np.arange(10))
             for log in ("a", "b") for ch in CHANNELS]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        j = judge(cells, RULE)
    assert j.outcome is Outcome.WORSE
    assert all(math.isfinite(v) for c in j.cells for v in (c.change, c.change_low, c.change_high))
    assert math.isfinite(j.change_low) and math.isfinite(j.change_high)
    assert j.cells[0].change == pytest.approx(math.sqrt(np.mean((base + 0.004) ** 2) / np.mean(base**2)) - 1, rel=1e-10)
    assert j.cells[0].change_high <= RATIO_CAP - 1
    np.testing.assert_array_equal(_resampled_ratio(np.array([4.0, 0.0, 1.0, 1e14]), np.array([1.0, 0.0, 0.0, 1.0])),
                                  [2.0, 1.0, RATIO_CAP, RATIO_CAP])


def test_fewer_windows_than_a_verdict_needs_decide_nothing():
    """One window (a short log's only 100-s window): its resampled interval has no width, so it
    is no evidence either way; three windows of the same halving beat the baseline."""
    def windows(n: int, ratio: float) -> list[PairedCell]:
        return [PairedCell(f"log{k}", f"Log {k}", 30.0, channel, [[ratio * 0.01]], [[0.01]], [0.0])
                for k in range(n) for channel in CHANNELS]

    better, worse = judge(windows(1, 0.5), RULE), judge(windows(1, 2.0), RULE)
    assert better.change_low == pytest.approx(-0.5) and better.change_high == pytest.approx(-0.5)
    assert better.outcome is Outcome.NOT_DISTINGUISHABLE and worse.outcome is Outcome.NOT_DISTINGUISHABLE
    assert "; 1 window is too few to decide at 95 % confidence (a verdict needs at least 3)" in better.sentence
    assert judge(windows(3, 0.5), RULE).outcome is Outcome.BEATS
    assert judge(windows(3, 2.0), RULE).outcome is Outcome.WORSE


def test_one_stretch_at_several_horizons_is_not_three_windows_of_evidence():
    """One log with one window at each of three horizons: every resampled interval has no
    width (one window, one log), so nothing is decided, whatever the sum of windows says;
    three windows at one horizon (three logs) decide."""
    one_each = [PairedCell("a", "Turn", h, ch, [[0.005]], [[0.01]], [0.0]) for h in (10.0, 30.0, 100.0) for ch in CHANNELS]
    j = judge(one_each, RULE)
    assert j.n_windows == 3 and j.change_low == j.change_high == pytest.approx(-0.5)
    assert j.outcome is Outcome.NOT_DISTINGUISHABLE
    assert ("3 windows, 1 at the most at one horizon, are too few to decide at 95 % confidence "
            "(a verdict needs at least 3 at one horizon)") in j.sentence
    three_logs = [PairedCell(f"log{k}", f"Log {k}", 30.0, ch, [[0.005 * (1 + 0.1 * k)]], [[0.01]], [0.0])
                  for k in range(3) for ch in CHANNELS]
    assert judge(three_logs, RULE).outcome is Outcome.BEATS


def test_a_model_exact_on_a_cell_is_judged_not_refused():
    """A model with no error at all against a baseline with some: the ratio is floored at
    1 / RATIO_CAP (its log finite), the model beats the baseline."""
    from sysid.evaluation.judgement import RATIO_CAP

    cells = [PairedCell("a", "Turn", 30.0, ch, [[0.0] * 4], [[0.01, 0.02, 0.01, 0.02]], 30.0 * np.arange(4))
             for ch in CHANNELS]
    j = judge(cells, RULE)
    assert j.outcome is Outcome.BEATS
    assert j.change == pytest.approx(1 / RATIO_CAP - 1) and j.member_changes == pytest.approx((1 / RATIO_CAP - 1,))


def test_a_baseline_exact_on_every_window_is_compared_not_called_diverged():
    """The baseline exact on all of a cell's windows (a noise-free log of the ship file's own
    MMG): a model with any error is RATIO_CAP times worse, materially so; a model exact too
    changes nothing. Neither is "the baseline diverged", and the sentence lists no empty cells."""
    from sysid.evaluation.judgement import RATIO_CAP

    def cells(model: float) -> list[PairedCell]:
        return [PairedCell("a", "Straight", 30.0, ch, [[model] * 4], [[0.0] * 4], 30.0 * np.arange(4)) for ch in CHANNELS]

    worse, same = judge(cells(0.01), RULE), judge(cells(0.0), RULE)
    assert worse.outcome is Outcome.WORSE and {c.decision for c in worse.cells} == {CellDecision.MATERIALLY_WORSE}
    assert worse.change == pytest.approx(RATIO_CAP - 1)
    assert same.outcome is Outcome.NOT_DISTINGUISHABLE and same.change == 0.0
    assert {c.decision for c in same.cells} == {CellDecision.NOT_DISTINGUISHABLE}
    assert "diverged" not in worse.sentence + same.sentence and "worst cells: ." not in same.sentence


def test_each_seeds_own_baseline_is_drawn_with_its_seed():
    """Seeds each with their own identified MMG (baseline rows B = M): every seed's model is
    0.8 x its own baseline on every window, the baselines 10 times apart. Drawn paired, every
    resample's ratio is 0.8: the interval is -20 % exactly; drawn apart it would mix one seed's
    model with another's baseline."""
    base = np.array([[0.01, 0.012, 0.011, 0.009], [0.1, 0.12, 0.11, 0.09], [0.05, 0.06, 0.055, 0.045]])
    cells = [PairedCell(log, log, 30.0, ch, 0.8 * base, base, 30.0 * np.arange(4)) for log in ("a", "b") for ch in CHANNELS]
    j = judge(cells, RULE)
    assert j.change_low == pytest.approx(-0.2) and j.change_high == pytest.approx(-0.2)
    assert all(c.change_low == pytest.approx(-0.2) and c.change_high == pytest.approx(-0.2) for c in j.cells)
    assert j.outcome is Outcome.BEATS


def test_each_seed_alone_is_judged_against_its_own_baseline():
    """Two seeds, each with its own identified MMG (B = M): seed 1 is 0.5 x its baseline of
    1.0, seed 2 0.5 x its baseline of 2.0, so each alone is -50 % exactly. Against the seeds'
    pooled baseline (MSE 2.5) seed 1 would read -68 % and seed 2 -37 %."""
    starts = 30.0 * np.arange(6)
    base = np.vstack([np.full(6, 1.0), np.full(6, 2.0)])
    cells = [PairedCell("a", "a", 30.0, ch, 0.5 * base, base, starts) for ch in CHANNELS]
    j = judge(cells, RULE)
    assert j.member_changes == pytest.approx((-0.5, -0.5))
    assert j.change == pytest.approx(-0.5)
    assert "2 seeds or members (each alone -50 % to -50 %)" in j.sentence


def test_the_overall_interval_rests_on_the_logs_when_each_logs_windows_are_alike():
    """Windows alike within each log, the logs different: the spread is all between logs, so
    the overall interval rests on L - 1 degrees of freedom, n = L (4 logs of 3 to 10 windows),
    not on the 25 windows. Logs whose windows are the same values in another order (no spread
    between logs): N - L + 1 = 28 on 3 logs of 10. By hand, logs [0, 2] and [2, 4]: between
    part 0.5, within parts 0.125 each, (0.75)^2 / (0.25 + 2 x 0.125^2) = 2, n = 3. One log of
    10 windows: 10; 5 logs of one window: 5 (the rule on one log or on logs of one window)."""
    alike = [np.full(n, level) for n, level in ((3, -0.3), (5, -0.1), (10, 0.2), (7, 0.0))]
    assert deciding_windows(alike) == pytest.approx(4.0, rel=1e-12)
    values = np.random.default_rng(3).normal(size=10)
    assert deciding_windows([values, values[::-1], np.roll(values, 3)]) == pytest.approx(28.0, rel=1e-9)
    assert deciding_windows([np.array([0.0, 2.0]), np.array([2.0, 4.0])]) == pytest.approx(3.0, rel=1e-12)
    assert deciding_windows([values]) == pytest.approx(10.0, rel=1e-12)
    assert deciding_windows([np.array([v]) for v in values[:5]]) == pytest.approx(5.0, rel=1e-12)

    from scipy.stats import norm, t
    cells = [PairedCell(f"log{i}", "", 30.0, ch, np.exp(x) * np.full(x.size, 0.01), np.full(x.size, 0.01),
                        30.0 * np.arange(x.size)) for i, x in enumerate(alike) for ch in CHANNELS]
    plain, rule = judge(cells, VerdictRule(resamples=1000, small_sample=False)), judge(cells, RULE)
    factor = t.ppf(0.975, 3) / norm.ppf(0.975) * math.sqrt(4 / 3)   # 3.18 / 1.96 x 1.15 = 1.87
    centre = math.log(plain.change + 1)
    for bound, widened in ((plain.change_low, rule.change_low), (plain.change_high, rule.change_high)):
        assert math.log(widened + 1) - centre == pytest.approx(factor * (math.log(bound + 1) - centre), rel=1e-9)


def test_two_logs_that_differ_widen_the_overall_interval_to_hold_the_truth():
    """Two logs of 10 windows drawn as `benchmarks/verdict_coverage.py --clustered` draws them
    (seed 34, tau 0.2): window log-ratios normal of sd 0.3 about log 0.8 + b, b = -0.008 and
    -0.25 for the two logs. The truth over logs, exp(mu + sigma^2) - 1 = -12.8 %, lay outside
    the interval widened by the 20 windows (-48 % to -14 %); the rule now widens by the logs'
    spread, and its interval holds it."""
    mu, sigma = math.log(0.8), 0.3
    rng = np.random.default_rng(34)
    b = rng.normal(0.0, 0.2, 2)
    cells = []
    for i in range(2):
        base = 0.01 * np.exp(rng.normal(0.0, 0.3, 10))
        model = base * np.exp(rng.normal(mu + b[i], sigma, 10))
        cells.append(PairedCell(f"log{i}", "", 30.0, "u", model[None], base[None], 30.0 * np.arange(10)))
    truth = math.exp(mu + sigma**2) - 1
    from scipy.stats import norm, t
    plain = judge(cells, VerdictRule(resamples=500, small_sample=False))
    by_windows = t.ppf(0.975, 19) / norm.ppf(0.975) * math.sqrt(20 / 19)   # the rule before: the 20 windows
    centre = math.log(plain.change + 1)
    high_before = math.exp(centre + by_windows * (math.log(plain.change_high + 1) - centre)) - 1
    assert high_before < truth   # the old interval missed the truth
    j = judge(cells, VerdictRule(resamples=500))
    assert j.change_low <= truth <= j.change_high
    assert j.outcome is Outcome.NOT_DISTINGUISHABLE   # not "beats" on two logs this far apart


def test_the_small_sample_widening_is_the_student_t_correction():
    """`widening` against the closed form at 2 windows (one degree of freedom: the Cauchy
    quantile tan(pi (q - 1/2))) and, bit for bit, against scipy.stats' t and normal
    quantiles at 2-500 windows and several confidences."""
    from scipy.stats import norm, t

    q = (1 + 0.95) / 2
    assert widening(2, 0.95) == pytest.approx(math.tan(math.pi * (q - 0.5)) / norm.ppf(q) * math.sqrt(2), rel=1e-12)
    assert widening(3, 0.95) == pytest.approx(2.69, abs=0.005) and widening(1, 0.95) == 1.0
    for confidence in (0.5, 0.8, 0.9, 0.95, 0.99, 0.999):
        q = (1 + confidence) / 2
        for n in range(2, 501):
            assert widening(n, confidence) == float(t.ppf(q, n - 1) / norm.ppf(q) * math.sqrt(n / (n - 1)))
