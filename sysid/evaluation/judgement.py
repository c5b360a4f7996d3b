"""How sysid judges a model: one stated statistical decision on per-log cells (docs: How sysid
judges a model).

A *cell* (`PairedCell`) is one log, one horizon and one channel (u, v_m [m/s], r [rad/s]),
holding the per-window RMSE of the model and of its baseline on the *same* windows. The
relative change of a cell is ``RMSE_model / RMSE_baseline - 1`` with each RMSE pooled over the
cell's windows (and over the model's members). `judge` bootstraps it, paired, over windows
within logs, over logs and over members, and decides at a stated confidence (`VerdictRule`):

- DIVERGED: a model prediction went non-finite or far outside the training data's physical
  range in some cell; such a model never beats its baseline;
- WORSE: some cell is materially worse (its interval lies above ``+material``), or the model
  is worse overall (the interval of the overall change lies above 0);
- BEATS: better overall (interval below 0) and no cell more than ``material`` worse, neither
  with confidence nor in its point estimate (a cell +12 % worse on too few windows to be sure
  keeps the verdict open: more windows only sharpen a decision, never flip it);
- NOT_DISTINGUISHABLE: otherwise, "on N windows"; always when no horizon has ``min_windows``
  windows over all logs (one window's resampled interval has no width: no evidence either
  way; one stretch of a log at several horizons is one piece of evidence, not several).

The overall change is the geometric mean of the cells' ratios minus 1, every log, horizon and
channel alike, so a scenario with few windows weighs as much as one with many. Every interval
is the bootstrap's percentile interval widened for few windows (`widening`: a percentile
interval on 3 to 5 windows covers 70-85 %, not 95 %; benchmarks/verdict_coverage.md); the
overall interval by the degrees of freedom of the logs' and windows' spread (`deciding_windows`:
two logs that disagree are two pieces of evidence, however many windows they hold).
`judge` is pure: no I/O, no torch; the same cells, rule and seed give the same judgement,
whatever the order of the cells.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any, Mapping, Sequence

import numpy as np

CHANNELS = ("u", "v_m", "r")
UNITS = {"u": "m/s", "v_m": "m/s", "r": "rad/s"}


class Outcome(str, Enum):
    """The verdict, as the words a user reads after "The model ..."."""

    BEATS = "beats its baseline"
    WORSE = "is worse than its baseline"
    NOT_DISTINGUISHABLE = "cannot be told apart from its baseline"
    DIVERGED = "diverged"


class CellDecision(str, Enum):
    """One cell's decision at the rule's confidence."""

    BETTER = "better"
    WORSE = "worse, within the tolerance"
    MATERIALLY_WORSE = "materially worse"
    NOT_DISTINGUISHABLE = "not distinguishable"
    TOO_FEW_WINDOWS = "too few windows"
    DIVERGED = "diverged"
    BASELINE_DIVERGED = "baseline diverged"


@dataclass(frozen=True)
class Divergence:
    """Where a prediction left the physics: a non-finite state or one far outside the
    training data's range. time_s : the log's time [s] of the first such sample;
    channel : the state channel ("u", "v_m", "r", or "" when every one is non-finite);
    reason : "non-finite" or "|u| 3.1 m/s beyond 3 x the training range 0.9 m/s"."""

    log: str
    horizon_s: float
    time_s: float
    channel: str = ""
    reason: str = "non-finite"

    def text(self) -> str:
        """"zigzag_31-Jul at 30 s, t = 412 s: non-finite"."""
        where = f", {self.channel}" if self.channel else ""
        return f"{self.log} at {self.horizon_s:g} s, t = {self.time_s:g} s{where}: {self.reason}"

    def to_dict(self) -> dict:
        return {"log": self.log, "horizon_s": self.horizon_s, "time_s": self.time_s,
                "channel": self.channel, "reason": self.reason}

    @classmethod
    def from_dict(cls, d: Mapping) -> "Divergence":
        return cls(str(d["log"]), float(d["horizon_s"]), float(d["time_s"]), str(d.get("channel", "")),
                   str(d.get("reason", "non-finite")))


@dataclass(frozen=True, eq=False)
class PairedCell:
    """One log, horizon and channel: per-window RMSE of the model and of its baseline on the
    same windows.

    model : (M, W) per-window RMSE of each of M members (seeds or ensemble members; M = 1
    for one model) [m/s or rad/s]; baseline : (B, W), B usually 1 (B = M > 1: member k's own
    baseline in row k, drawn with it); window_start_s : (W,)
    start time of each window [s]; divergence : where a model prediction diverged, or None.
    """

    log: str
    scenario: str
    horizon_s: float
    channel: str
    model: np.ndarray
    baseline: np.ndarray
    window_start_s: np.ndarray
    divergence: Divergence | None = None

    def __post_init__(self):
        model = np.atleast_2d(np.asarray(self.model, dtype=float))
        baseline = np.atleast_2d(np.asarray(self.baseline, dtype=float))
        starts = np.asarray(self.window_start_s, dtype=float).reshape(-1)
        if self.channel not in CHANNELS:
            raise ValueError(f"cell {self.log}: channel {self.channel!r} is not one of {CHANNELS}")
        if model.ndim != 2 or baseline.ndim != 2 or model.shape[1] != baseline.shape[1] \
                or model.shape[1] != starts.size:
            raise ValueError(f"cell {self.log} {self.channel} at {self.horizon_s:g} s: model {model.shape}, "
                             f"baseline {baseline.shape} and {starts.size} window starts do not pair")
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "baseline", baseline)
        object.__setattr__(self, "window_start_s", starts)

    @property
    def n_windows(self) -> int:
        return int(self.window_start_s.size)

    @property
    def model_diverged(self) -> bool:
        return self.divergence is not None or not np.all(np.isfinite(self.model))

    @property
    def baseline_diverged(self) -> bool:
        return not np.all(np.isfinite(self.baseline))

    @property
    def key(self) -> tuple:
        return (self.log, self.scenario, float(self.horizon_s), CHANNELS.index(self.channel))


@dataclass(frozen=True)
class VerdictRule:
    """The decision's settings. confidence : of every interval (two-sided); material : a cell
    whose interval lies above this relative change is materially worse (0.10: 10 %);
    min_windows : fewer windows than this and a cell is not decided alone; resamples : of the
    bootstrap; seed : of its draws; small_sample : widen each interval by `widening` of the
    windows it rests on (False: the plain percentile interval, which covers less than its
    confidence on few windows; benchmarks/verdict_coverage.py)."""

    confidence: float = 0.95
    material: float = 0.10
    min_windows: int = 3
    resamples: int = 2000
    seed: int = 0
    small_sample: bool = True

    def __post_init__(self):
        if not 0.5 <= self.confidence < 1:
            raise ValueError(f"confidence {self.confidence}: choose a value in [0.5, 1)")
        if self.material < 0 or self.min_windows < 1 or self.resamples < 100:
            raise ValueError("material >= 0, min_windows >= 1 and resamples >= 100, please")


DEFAULT_RULE = VerdictRule()   # the stated rule: 95 % confidence, 10 % material
ONE_MEMBER = "1 seed (no spread: one model)"   # the evidence of a model of one member, in the sentence


@dataclass(frozen=True)
class CellJudgement:
    """One cell decided: RMSE of model and baseline pooled over its windows (and members)
    [m/s or rad/s], the relative change (negative: the model is better) with its interval at
    the rule's confidence, and the decision."""

    log: str
    scenario: str
    horizon_s: float
    channel: str
    n_windows: int
    n_members: int
    model_rmse: float
    baseline_rmse: float
    change: float
    change_low: float
    change_high: float
    decision: CellDecision
    divergence: Divergence | None = None

    @property
    def where(self) -> str:
        """"Zigzag 30/30 u at 100 s" (the log's name when it has no scenario)."""
        return f"{self.scenario or self.log} {self.channel} at {self.horizon_s:g} s"

    def text(self, place: str | None = None) -> str:
        """"Zigzag 30/30 u at 100 s +141 % (+120 % to +160 %, 1 window)"; `place` names the
        log instead of its scenario (`place_names`)."""
        where = f"{place} {self.channel} at {self.horizon_s:g} s" if place else self.where
        if self.decision is CellDecision.DIVERGED:
            return f"{where} diverged" + (f" ({self.divergence.text()})" if self.divergence else "")
        if self.decision is CellDecision.BASELINE_DIVERGED:
            return f"{where}: the baseline diverged"
        windows = f"{self.n_windows} window" + ("s" if self.n_windows != 1 else "")
        if self.decision is CellDecision.TOO_FEW_WINDOWS:
            return f"{where} {percent_text(self.change)} ({windows}, too few to decide)"
        return f"{where} {percent_text(self.change)} ({interval_text(self.change_low, self.change_high)}, {windows})"

    def to_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("log", "scenario", "horizon_s", "channel", "n_windows", "n_members",
                                           "model_rmse", "baseline_rmse", "change", "change_low", "change_high")}
        d = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}
        d["decision"] = self.decision.name.lower()
        d["divergence"] = self.divergence.to_dict() if self.divergence else None
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> "CellJudgement":
        num = {k: math.nan if d.get(k) is None else float(d[k])
               for k in ("model_rmse", "baseline_rmse", "change", "change_low", "change_high")}
        return cls(str(d["log"]), str(d.get("scenario", "")), float(d["horizon_s"]), str(d["channel"]),
                   int(d["n_windows"]), int(d.get("n_members", 1)), decision=CellDecision[str(d["decision"]).upper()],
                   divergence=Divergence.from_dict(d["divergence"]) if d.get("divergence") else None, **num)


@dataclass(frozen=True)
class Judgement:
    """A model against its baseline on per-log cells (`judge`).

    change, change_low, change_high : the overall relative change (geometric mean of the
    cells' RMSE ratios minus 1) and its interval at `confidence`; member_changes : the
    overall change of each member alone (the spread over seeds or members); worst : up to
    three cells, diverged first, then the largest changes; sentence : what a user reads.
    """

    outcome: Outcome
    confidence: float
    material: float
    cells: tuple[CellJudgement, ...]
    change: float
    change_low: float
    change_high: float
    member_changes: tuple[float, ...]
    worst: tuple[CellJudgement, ...]
    n_logs: int
    n_windows: int
    n_members: int
    horizons_s: tuple[float, ...]
    sentence: str
    divergences: tuple[Divergence, ...] = ()

    @property
    def beats(self) -> bool:
        return self.outcome is Outcome.BEATS

    @property
    def materially_worse(self) -> tuple[CellJudgement, ...]:
        return tuple(c for c in self.cells if c.decision is CellDecision.MATERIALLY_WORSE)

    def evidence(self, one_member: str = ONE_MEMBER) -> str:
        """"6 logs, 78 windows, 1 seed (no spread: one model)" or "..., 5 seeds or members (each
        alone -31 % to -36 %)"; `one_member` says what a single member is (`ONE_MEMBER`: one
        model of one seed)."""
        logs = f"{self.n_logs} log" + ("s" if self.n_logs != 1 else "")
        windows = f"{self.n_windows} window" + ("s" if self.n_windows != 1 else "")
        finite = [c for c in self.member_changes if math.isfinite(c)]
        if self.n_members == 1:
            members = one_member
        elif finite:
            members = f"{self.n_members} seeds or members (each alone {percent_text(min(finite))} to {percent_text(max(finite))})"
        else:
            members = f"{self.n_members} seeds or members"
        return f"{logs}, {windows}, {members}"

    def to_dict(self) -> dict:
        def num(v):
            return v if math.isfinite(v) else None
        return {"outcome": self.outcome.name.lower(), "confidence": self.confidence, "material": self.material,
                "change": num(self.change), "change_low": num(self.change_low), "change_high": num(self.change_high),
                "member_changes": [num(v) for v in self.member_changes],
                "n_logs": self.n_logs, "n_windows": self.n_windows, "n_members": self.n_members,
                "horizons_s": list(self.horizons_s), "sentence": self.sentence,
                "cells": [c.to_dict() for c in self.cells], "worst": [c.to_dict() for c in self.worst],
                "divergences": [d.to_dict() for d in self.divergences]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Judgement":
        def num(v):
            return math.nan if v is None else float(v)
        return cls(Outcome[str(d["outcome"]).upper()], float(d["confidence"]), float(d["material"]),
                   tuple(CellJudgement.from_dict(c) for c in d.get("cells", ())),
                   num(d.get("change")), num(d.get("change_low")), num(d.get("change_high")),
                   tuple(num(v) for v in d.get("member_changes", ())),
                   tuple(CellJudgement.from_dict(c) for c in d.get("worst", ())),
                   int(d["n_logs"]), int(d["n_windows"]), int(d["n_members"]),
                   tuple(float(h) for h in d.get("horizons_s", ())), str(d["sentence"]),
                   tuple(Divergence.from_dict(v) for v in d.get("divergences", ())))


def percent_text(change: float) -> str:
    """A relative change as "+20 %", "-3.4 %" (one decimal below 10 %), "-" when undefined."""
    if not math.isfinite(change):
        return "-"
    pct = 100 * change
    return f"{pct:+.1f} %" if abs(pct) < 10 else f"{pct:+.0f} %"


def interval_text(low: float, high: float) -> str:
    """"-41 % to -24 %"."""
    return f"{percent_text(low)} to {percent_text(high)}"


def _counts(rng: np.random.Generator, n: int, resamples: int) -> np.ndarray:
    """(resamples, n) how often each of n items is drawn in a resample of n with replacement."""
    if n == 1:
        return np.ones((resamples, 1))
    return rng.multinomial(n, np.full(n, 1.0 / n), size=resamples).astype(float)


def _pooled_mse(errors: np.ndarray, members: np.ndarray, windows: np.ndarray) -> np.ndarray:
    """(R,) mean squared per-window RMSE over resampled members (R, M) and windows (R, W)."""
    sq = errors**2
    return ((members @ sq) * windows).sum(1) / (members.sum(1) * windows.sum(1))


RATIO_CAP = 1e6   # the largest RMSE ratio of a draw: one whose baseline is exact and whose model is not


def _resampled_ratio(mse_model: np.ndarray, mse_baseline: np.ndarray) -> np.ndarray:
    """(R,) RMSE ratio model / baseline of each draw, rounded to 12 digits (a model equal to
    its baseline gives exactly 1), within [1 / `RATIO_CAP`, `RATIO_CAP`]. A draw whose
    baseline error is exactly 0 (an exact baseline on every window drawn: straight running
    with v = r = 0 in noise-free logs) is 1 when the model's is 0 too, else `RATIO_CAP`; one
    whose model error alone is 0 is 1 / `RATIO_CAP`: every ratio's log, every quantile and
    the overall change stay finite."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.sqrt(mse_model / mse_baseline)
    ratio = np.where(mse_baseline > 0, ratio, np.where(mse_model > 0, RATIO_CAP, 1.0))
    return np.round(np.clip(ratio, 1 / RATIO_CAP, RATIO_CAP), 12)


def deciding_windows(scores: Sequence[np.ndarray]) -> float:
    """The windows an overall interval rests on, as `widening` takes them: 1 + the degrees of
    freedom of the spread that the bootstrap over logs and windows gives the mean of the logs'
    mean scores, one (W_l,) array of per-window scores per log. That spread is a between-log
    part B = sum((m_l - m)^2) / L^2 (m_l a log's mean score, m their mean), L - 1 degrees of
    freedom, and a within-log part w_l = sum((x - m_l)^2) / (W_l^2 L^2) per log, W_l - 1 each;
    the degrees of freedom of their sum are Welch-Satterthwaite's,
    (B + sum w_l)^2 / (B^2 / (L - 1) + sum w_l^2 / (W_l - 1)). The logs' windows alike (w = 0):
    L, the logs; the logs' means equal (B = 0): N - L + 1, N the windows; one log: its W; L
    logs of one window: L. 0 without any spread beyond round-off (no interval width to widen)."""
    scores = [np.asarray(x, dtype=float).reshape(-1) for x in scores if np.size(x)]
    L = len(scores)
    if L == 0:
        return 0.0
    means = np.round([x.mean() for x in scores], 12)   # 12 digits, as `_resampled_ratio`: round-off is no spread
    between = float(np.round(means - means.mean(), 12) @ np.round(means - means.mean(), 12)) / L**2
    within = np.array([float((np.round(x - x.mean(), 12) ** 2).sum()) / (x.size**2 * L**2) for x in scores])
    dof = np.array([x.size - 1 for x in scores], dtype=float)
    total = between + float(within.sum())
    if not total > 0:
        return 0.0
    spread = (between**2 / (L - 1) if L > 1 else 0.0) + float((within[dof > 0] ** 2 / dof[dof > 0]).sum())
    return 1 + total**2 / spread


def widening(n: float, confidence: float) -> float:
    """The factor by which an interval resting on `n` windows is widened about its point
    estimate, in log-ratio: t_{n-1}(q) / z(q) * sqrt(n / (n - 1)), q = (1 + confidence) / 2,
    the Student-t small-sample correction of a percentile bootstrap interval (its spread is
    the plug-in one, divided by n, not n - 1). 2.69 at n = 3, 1.44 at 6, 1.10 at 20, 1.02 at
    100; 1 below 2 windows (no spread to widen). `n` may be an effective number of windows
    (`deciding_windows`), not a whole one."""
    if n < 2:
        return 1.0
    # the quantile functions themselves (scipy.stats' t.ppf and norm.ppf call them), lazily:
    # importing scipy.stats costs each process about 1 s of CPU, scipy.special 0.2 s
    from scipy.special import ndtri, stdtrit

    q = (1 + confidence) / 2
    return float(stdtrit(n - 1, q) / ndtri(q) * math.sqrt(n / (n - 1)))


def _widened(point: float, low: float, high: float, factor: float) -> tuple[float, float]:
    """The interval [low, high] of a ratio widened by `factor` about `point` in log-ratio
    (ratios > 0; 1 leaves it as it is)."""
    if factor == 1.0 or not (point > 0 and low > 0 and high > 0):
        return low, high
    centre = math.log(point)
    return (math.exp(centre + factor * (math.log(low) - centre)), math.exp(centre + factor * (math.log(high) - centre)))


def _decided(cell: CellJudgement, low: float, high: float, rule: VerdictRule) -> CellJudgement:
    """`cell` with its interval [low, high] of the relative change and the decision it gives."""
    if cell.n_windows < rule.min_windows:
        decision = CellDecision.TOO_FEW_WINDOWS
    elif high < 0:
        decision = CellDecision.BETTER
    elif low > rule.material:
        decision = CellDecision.MATERIALLY_WORSE
    elif low > 0:
        decision = CellDecision.WORSE
    else:
        decision = CellDecision.NOT_DISTINGUISHABLE
    return replace(cell, change_low=float(low), change_high=float(high), decision=decision)


def judge(cells: Sequence[PairedCell], rule: VerdictRule = VerdictRule(), model: str = "The model",
          baseline: str = "its baseline", one_member: str = ONE_MEMBER) -> Judgement:
    """The verdict on `cells` under `rule` (see the module docstring); `model` and
    `baseline` name them in the sentence ("The hybrid", "MMG (ship file)"), `one_member` the
    model's evidence when it has one member (`Judgement.evidence`: "one model (the ensemble:
    no spread)")."""
    cells, groups = _checked(cells)
    M, B = cells[0].model.shape[0], cells[0].baseline.shape[0]
    alpha = (1 - rule.confidence) / 2
    R = rule.resamples
    rng = np.random.default_rng(rule.seed)   # drawn in this order: members, baselines, each log's windows, logs
    members = _counts(rng, M, R)
    baselines = members if B == M > 1 else _counts(rng, B, R)   # B = M: each member's own baseline, paired
    judged, compared = _cell_judgements(groups, rng, R, M, members, baselines)
    if compared.ratios:   # every compared cell's interval, in one call
        bounds = iter(np.quantile(np.stack(compared.ratios, 1), [alpha, 1 - alpha], axis=0).T)   # (cells, 2) ratios
        decided: list[CellJudgement] = []
        for cell in judged:
            if math.isfinite(cell.change):
                low, high = next(bounds)
                if rule.small_sample:
                    low, high = _widened(cell.change + 1, low, high, widening(cell.n_windows, rule.confidence))
                cell = _decided(cell, float(low) - 1, float(high) - 1, rule)
            decided.append(cell)
        judged = decided
    change, change_low, change_high, member_changes = _overall_change(compared, rng, R, M, alpha)

    diverged = [c for c in judged if c.decision is CellDecision.DIVERGED]
    material = [c for c in judged if c.decision is CellDecision.MATERIALLY_WORSE]
    unjudged_material = [c for c in judged if c.decision is not CellDecision.MATERIALLY_WORSE
                         and c.change > rule.material]
    n_windows = sum(group[0].n_windows for group in groups.values())
    per_horizon: dict[float, int] = {}
    for (_log, h), group in groups.items():
        per_horizon[h] = per_horizon.get(h, 0) + group[0].n_windows
    deciding = max(per_horizon.values())   # the windows of one horizon: another's cover the same stretches
    if rule.small_sample and math.isfinite(change):
        horizon = min(h for h, n in per_horizon.items() if n == deciding)
        n = deciding_windows(_window_scores(groups, horizon)) or float(deciding)   # the logs' spread counts
        low, high = _widened(change + 1, change_low + 1, change_high + 1, widening(n, rule.confidence))
        change_low, change_high = low - 1, high - 1
    enough = deciding >= rule.min_windows   # fewer: the resampled interval is no evidence (one window: no width)
    if diverged:
        outcome = Outcome.DIVERGED
    elif material or (enough and change_low > 0):
        outcome = Outcome.WORSE
    elif enough and change_high < 0 and not unjudged_material:
        outcome = Outcome.BEATS
    else:
        outcome = Outcome.NOT_DISTINGUISHABLE
    ranked = sorted((c for c in judged if math.isfinite(c.change)), key=lambda c: -c.change)
    worst = tuple(diverged[:3] + ranked[:max(0, 3 - len(diverged))])
    divergences = tuple(dict.fromkeys(c.divergence for c in diverged if c.divergence is not None))
    result = Judgement(outcome, rule.confidence, rule.material, tuple(judged), change, change_low, change_high,
                       member_changes, worst, len({c.log for c in cells}), n_windows, M,
                       tuple(sorted({float(c.horizon_s) for c in cells})), "", divergences)
    return _with_sentence(result, model, baseline, material, unjudged_material, diverged,
                          None if enough else (deciding, rule.min_windows), one_member)


def _checked(cells: Sequence[PairedCell]) -> tuple[list[PairedCell], dict[tuple[str, float], list[PairedCell]]]:
    """`cells` sorted by log, horizon and channel, and grouped by (log, horizon [s]);
    `ValueError` for none, a repeated cell, members that differ or channels of one log and
    horizon on different windows."""
    if not cells:
        raise ValueError("no cells to judge")
    cells = sorted(cells, key=lambda c: c.key)
    keys = [c.key for c in cells]
    if len(set(keys)) != len(keys):
        raise ValueError("two cells share a log, horizon and channel")
    M, B = cells[0].model.shape[0], cells[0].baseline.shape[0]
    if any(c.model.shape[0] != M or c.baseline.shape[0] != B for c in cells):
        raise ValueError("every cell needs the same members of the model and of the baseline")
    groups: dict[tuple[str, float], list[PairedCell]] = {}
    for c in cells:
        groups.setdefault((c.log, float(c.horizon_s)), []).append(c)
    for (log, h), group in groups.items():
        if any(not np.array_equal(g.window_start_s, group[0].window_start_s) for g in group):
            raise ValueError(f"{log} at {h:g} s: the channels' cells are not on the same windows")
    return cells, groups


def _window_scores(groups: dict[tuple[str, float], list[PairedCell]], horizon: float) -> list[np.ndarray]:
    """Per log, the (W,) score of each of its windows at `horizon` [s]: the mean over the log's
    compared channels of the window's log RMSE ratio (members and baselines pooled, capped as
    `_resampled_ratio`), as the overall change weighs every channel alike. Logs with no
    compared channel at that horizon give none."""
    scores = []
    for (_log, h), group in groups.items():
        compared = [c for c in group if h == horizon and c.n_windows and not c.model_diverged
                    and not c.baseline_diverged]
        if compared:
            scores.append(np.mean([np.log(_resampled_ratio(np.mean(c.model**2, axis=0), np.mean(c.baseline**2, axis=0)))
                                   for c in compared], axis=0))
    return scores


@dataclass
class _Compared:
    """The cells compared (model and baseline finite): per log the resampled log-ratios of
    its cells, each cell's point log-ratio, its (R,) resampled RMSE ratio and the (M,)
    log-ratio of each member alone (against its own baseline when each member has one)."""

    log_ratios: dict[str, list[np.ndarray]] = field(default_factory=dict)
    point_logs: list[float] = field(default_factory=list)
    ratios: list[np.ndarray] = field(default_factory=list)
    member_logs: list[np.ndarray] = field(default_factory=list)


def _cell_judgements(groups: dict[tuple[str, float], list[PairedCell]], rng: np.random.Generator, R: int, M: int,
                     members: np.ndarray, baselines: np.ndarray) -> tuple[list[CellJudgement], _Compared]:
    """Each cell's judgement before its interval (diverged, baseline diverged, or compared:
    not distinguishable until `_decided`), and what the compared cells give the overall change.
    One draw of windows per (log, horizon) from `rng`, in the groups' order."""
    judged: list[CellJudgement] = []
    compared = _Compared()
    for (log, _h), group in groups.items():
        W = group[0].n_windows
        windows = _counts(rng, W, R)
        for c in group:
            mse_m, mse_b = np.mean(c.model**2), np.mean(c.baseline**2)
            model_rmse, baseline_rmse = math.sqrt(mse_m), math.sqrt(mse_b)
            common: dict[str, Any] = dict(log=c.log, scenario=c.scenario, horizon_s=float(c.horizon_s), channel=c.channel,
                                          n_windows=W, n_members=M, model_rmse=model_rmse,
                                          baseline_rmse=baseline_rmse)
            if c.model_diverged:
                judged.append(CellJudgement(**common, change=math.nan, change_low=math.nan, change_high=math.nan,
                                            decision=CellDecision.DIVERGED, divergence=c.divergence))
                continue
            if c.baseline_diverged or W == 0:
                judged.append(CellJudgement(**common, change=math.nan, change_low=math.nan, change_high=math.nan,
                                            decision=CellDecision.BASELINE_DIVERGED))
                continue
            ratio = _resampled_ratio(_pooled_mse(c.model, members, windows),
                                     _pooled_mse(c.baseline, baselines, windows))
            change = float(_resampled_ratio(np.array([mse_m]), np.array([mse_b]))[0]) - 1   # an exact baseline too
            judged.append(CellJudgement(**common, change=change, change_low=math.nan, change_high=math.nan,
                                        decision=CellDecision.NOT_DISTINGUISHABLE))
            compared.ratios.append(ratio)
            with np.errstate(divide="ignore"):
                compared.log_ratios.setdefault(log, []).append(np.log(ratio))
                compared.point_logs.append(math.log(change + 1))
                own = np.mean(c.baseline**2, axis=1) if c.baseline.shape[0] == M > 1 else np.full(M, mse_b)
                compared.member_logs.append(np.log(_resampled_ratio(np.mean(c.model**2, axis=1), own)))
    return judged, compared


def _overall_change(compared: _Compared, rng: np.random.Generator, R: int, M: int,
                    alpha: float) -> tuple[float, float, float, tuple[float, ...]]:
    """(change, its low and high bound, each member's change) overall: the geometric mean of
    the compared cells' ratios minus 1, logs resampled with replacement; NaN without any."""
    logs = sorted(compared.log_ratios)
    if not logs:
        return math.nan, math.nan, math.nan, tuple(math.nan for _ in range(M))
    sums = np.stack([np.sum(compared.log_ratios[name], axis=0) for name in logs], 1)     # (R, L)
    sizes = np.array([len(compared.log_ratios[name]) for name in logs], dtype=float)      # (L,)
    draws = _counts(rng, len(logs), R)
    overall = np.exp((draws * sums).sum(1) / (draws @ sizes)) - 1
    change = math.exp(float(np.mean(compared.point_logs))) - 1
    change_low, change_high = (float(q) for q in np.quantile(overall, [alpha, 1 - alpha]))
    member_changes = tuple(float(v) for v in np.exp(np.mean(compared.member_logs, axis=0)) - 1)
    return change, change_low, change_high, member_changes


def place_names(cells: Sequence[CellJudgement]) -> dict[str, str]:
    """log -> the name its cells go by: the scenario it records, or "scenario: log" when
    another log among `cells` records the same scenario (a user's several turning circles of
    20 deg); the log's own name when it has no scenario."""
    logs_of: dict[str, set[str]] = {}
    for c in cells:
        logs_of.setdefault(c.scenario, set()).add(c.log)
    return {c.log: c.scenario if c.scenario and len(logs_of[c.scenario]) == 1
            else f"{c.scenario}: {c.log}" if c.scenario else c.log for c in cells}


def _listed(cells: Sequence[CellJudgement], names: Mapping[str, str], limit: int = 3) -> str:
    more = f"; and {len(cells) - limit} more" if len(cells) > limit else ""
    return "; ".join(c.text(names.get(c.log)) for c in cells[:limit]) + more


def _with_sentence(j: Judgement, model: str, baseline: str, material: list[CellJudgement],
                   unjudged_material: list[CellJudgement], diverged: list[CellJudgement],
                   too_few: tuple[int, int] | None = None, one_member: str = ONE_MEMBER) -> Judgement:
    """`j` with its sentence; `too_few`: (the most windows of one horizon, the windows a
    decision needs) when there are fewer; `one_member`: as `judge`."""
    conf = f"{100 * j.confidence:g} %"
    tolerance = f"{100 * j.material:g} %"
    overall = (f"RMSE {percent_text(j.change)} overall ({conf} interval {interval_text(j.change_low, j.change_high)})"
               if math.isfinite(j.change) else "no cell to compare")
    evidence = f"on {j.evidence(one_member)}"
    names = place_names(j.cells)
    worst = f"; worst cells: {_listed(j.worst, names)}" if j.worst else ""
    if j.outcome is Outcome.DIVERGED:
        places = list(dict.fromkeys(c.divergence.text() if c.divergence
                                    else f"{names[c.log]} {c.channel} at {c.horizon_s:g} s"
                                    for c in diverged))
        where = "; ".join(places[:3]) + (f"; and {len(places) - 3} more" if len(places) > 3 else "")
        finite = f"{overall} in the cells that stayed finite" if math.isfinite(j.change) else "no cell stayed finite"
        text = (f"{model} DIVERGED (non-finite or far outside the training data's range) in {where}, "
                f"so it does not beat {baseline}; {finite}, {evidence}.")
    elif j.outcome is Outcome.WORSE and material and j.change < 0:   # worse in cells, better overall
        cells = f"{len(material)} cell{'s' if len(material) != 1 else ''}"
        text = (f"{model} is WORSE than {baseline} in {cells}, {'each ' if len(material) != 1 else ''}more than {tolerance} worse at {conf} confidence "
                f"({_listed(material, names)}), although better overall: RMSE {percent_text(j.change)} "
                f"({conf} interval {interval_text(j.change_low, j.change_high)}), {evidence}.")
    elif j.outcome is Outcome.WORSE:
        why = (f"more than {tolerance} worse at {conf} confidence in {_listed(material, names)}" if material
               else f"worse overall at {conf} confidence")
        text = f"{model} is WORSE than {baseline}: {why}; {overall}, {evidence}."
    elif j.outcome is Outcome.BEATS:
        text = (f"{model} beats {baseline} at {conf} confidence: {overall}, {evidence}; no cell more than "
                f"{tolerance} worse at that confidence{worst}.")
    elif too_few is not None:
        most, needed = too_few
        count = (f"{j.n_windows} window{'s are' if j.n_windows != 1 else ' is'}" if most == j.n_windows else
                 f"{j.n_windows} windows, {most} at the most at one horizon, are")
        at = "" if most == j.n_windows else " at one horizon"
        text = (f"{model} cannot be told apart from {baseline}: {overall}, {evidence}; {count} too few to decide "
                f"at {conf} confidence (a verdict needs at least {needed}{at}){worst}.")
    elif unjudged_material:
        text = (f"{model} cannot be told apart from {baseline} on {j.n_windows} windows: {overall}, {evidence}; "
                f"but {len(unjudged_material)} cell{'s are' if len(unjudged_material) > 1 else ' is'} more than "
                f"{tolerance} worse without the evidence to decide at {conf} confidence: "
                f"{_listed(sorted(unjudged_material, key=lambda c: -c.change), names)}.")
    else:
        includes = " includes no change" if math.isfinite(j.change) else ""
        text = (f"{model} cannot be told apart from {baseline} on {j.n_windows} windows: {overall}{includes}, "
                f"{evidence}{worst}.")
    return replace(j, sentence=text)
