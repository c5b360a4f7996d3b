"""A verdict, always: a learned model beside its physics baseline(s), judged by one stated rule
on per-log evidence (`sysid.evaluation.judgement.judge`; docs: How sysid judges a model).

Baselines are the ship file's MMG (with ``[mmg] overrides``) and, when identification ran,
the identified MMG. The evidence is paired per-window RMSE of u, v_m [m/s] and r [rad/s]:

- test: the benchmark protocol's windows of every test log at each evaluation horizon, one
  cell per (log, horizon, channel);
- validation: the windows of ``val_loss_multistep`` (`sysid.records.summary.VAL_LOSS_DEFINITION`),
  over their predicted steps, one cell per (validation log, horizon, channel) with that log's
  non-overlapping windows, as the test logs' (`WindowOrigins.non_overlapping`: a held-out log,
  or a training log's validation blocks; the loss and `ChannelCell` keep every window); scores
  without origins (`WindowScore.origins` None) are one pseudo-log, `VALIDATION_LOG`, of every
  window.

The test logs decide whenever there are any (a diverged prediction there is a DIVERGED
verdict, never a fall back to validation); without them the validation windows decide. The
validation windows are judged by the same rule either way. The model *beats its baseline*
only when it beats every baseline. `ChannelCell` keeps each split's pooled RMSE per horizon
and channel (the table beside the sentence, and the verdict of runs written before the rule).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Mapping, Sequence

import numpy as np
import pandas as pd
import torch

from sysid.channel_names import VELOCITY_INDEX
from sysid.dynamics.rollouts import WindowOrigins, WindowSet, rollout_errors, velocity_loss
from sysid.evaluation.divergence import DIVERGENCE_FACTOR, PhysicalRange, diverged_steps
from sysid.evaluation.judgement import (CHANNELS, DEFAULT_RULE, ONE_MEMBER, UNITS, Divergence, Judgement, Outcome, PairedCell,
                                        VerdictRule, judge, percent_text)

if TYPE_CHECKING:
    from sysid.evaluation.evaluate import Evaluation
SHIP_FILE_MMG = "MMG (ship file)"
IDENTIFIED_MMG = "MMG (identified)"
VALIDATION, TEST = "validation", "test"
MODEL_NAMES = {"mmg": "identified MMG", "nn": "NN-only model", "hybrid": "hybrid"}
MATERIAL = VerdictRule().material   # a cell this much worse than its baseline, with confidence, fails the verdict
VALIDATION_LOG = "validation windows"   # the one pseudo-log of validation windows whose logs are not known


@dataclass(frozen=True)
class ChannelCell:
    """One channel at one horizon on one split: the model's RMSE and each baseline's
    [m/s or rad/s]; `model_std` the spread (std) over seeds when the cell is a seed mean."""

    split: str
    horizon_s: float
    channel: str
    model: float
    baselines: dict[str, float]
    model_std: float | None = None

    def change(self, baseline: str) -> float:
        """(model - baseline) / baseline: negative is better than the baseline."""
        ref = self.baselines[baseline]
        return (self.model - ref) / ref if ref > 0 else math.nan

    def worse_than(self, baseline: str) -> bool:
        return not self.model < self.baselines[baseline]

    @property
    def finite(self) -> bool:
        return math.isfinite(self.model) and all(math.isfinite(v) for v in self.baselines.values())

    def text(self, baseline: str) -> str:
        """"u at 30 s: 0.0528 against 0.0377 m/s (+40 %)"."""
        return (f"{self.channel} at {self.horizon_s:g} s: {self.model:.4f} against {self.baselines[baseline]:.4f} "
                f"{UNITS[self.channel]} ({percent_text(self.change(baseline))})")


@dataclass(frozen=True)
class BaselineVerdict:
    """A learned model against its physics baselines on validation and test (summary.json
    ``verdict``).

    model : "hybrid" | "nn" | "mmg" (identified); baselines : labels, the ship file's MMG
    first; cells : every split x horizon x channel, pooled; val_loss_multistep : label
    ("model" or a baseline) -> validation loss; decided_on : "test" or "validation"; seeds :
    how many runs a seed verdict rests on (1: a single run); judgements : baseline label ->
    `Judgement` on the deciding split; validation_judgements : the same on the validation
    windows; evidence : split -> baseline label -> the `PairedCell`s judged (what a seed
    verdict judges again with every seed as a member). A verdict read from a run written
    before the rule has no judgements and keeps its old pooled decision (`legacy_beats`).
    """

    model: str
    baselines: tuple[str, ...]
    cells: tuple[ChannelCell, ...]
    val_loss_multistep: dict[str, float] = field(default_factory=dict)
    decided_on: str = TEST
    seeds: int = 1
    judgements: dict[str, Judgement] = field(default_factory=dict)
    validation_judgements: dict[str, Judgement] = field(default_factory=dict)
    evidence: dict[str, dict[str, tuple[PairedCell, ...]]] = field(default_factory=dict, repr=False)
    legacy_beats: bool | None = None

    @property
    def deciding(self) -> list[ChannelCell]:
        return [c for c in self.cells if c.split == self.decided_on and c.finite]

    @property
    def worse(self) -> list[tuple[ChannelCell, str]]:
        """(cell, baseline) where the pooled model RMSE is not lower, on the deciding split."""
        return [(c, b) for c in self.deciding for b in self.baselines if c.worse_than(b)]

    def mean_change(self, baseline: str) -> float:
        """The overall relative change against `baseline` on the deciding split (the
        judgement's; for an old run the geometric mean of the pooled cells' ratios, minus 1)."""
        if baseline in self.judgements:
            return self.judgements[baseline].change
        ratios = [c.model / c.baselines[baseline] for c in self.deciding if c.baselines[baseline] > 0]
        return math.exp(float(np.mean(np.log(ratios)))) - 1.0 if ratios else math.nan

    def member_spread(self, split: str, log: str, horizon_s: float, channel: str) -> float | None:
        """The std over seeds (members) of the model's RMSE in one cell [m/s or rad/s]; None
        with one seed or without the evidence."""
        for cells in self.evidence.get(split, {}).values():
            for c in cells:
                if (c.log, float(c.horizon_s), c.channel) == (log, float(horizon_s), channel) and len(c.model) > 1:
                    return float(np.std(np.sqrt(np.mean(c.model**2, axis=1)), ddof=1))
            return None
        return None

    @property
    def outcome(self) -> Outcome | None:
        """The worst outcome over the baselines (DIVERGED, WORSE, NOT_DISTINGUISHABLE, BEATS);
        None for a run written before the rule."""
        order = (Outcome.DIVERGED, Outcome.WORSE, Outcome.NOT_DISTINGUISHABLE, Outcome.BEATS)
        found = {j.outcome for j in self.judgements.values()}
        return next((o for o in order if o in found), None)

    @property
    def beats_baseline(self) -> bool:
        """The model beats every baseline under the rule (`judge`) on the deciding split."""
        if self.judgements:
            return all(j.beats for j in self.judgements.values())
        return bool(self.legacy_beats)

    @property
    def model_name(self) -> str:
        return MODEL_NAMES.get(self.model, self.model)

    @property
    def horizons_s(self) -> tuple[float, ...]:
        """The horizons [s] that decided."""
        return tuple(sorted({h for j in self.judgements.values() for h in j.horizons_s}))

    @property
    def validation_windows(self) -> str:
        """"the non-overlapping validation windows" when every judged validation cell's windows
        start at least its horizon apart (per-log cells of one seed's or of seeds on the same
        windows), else "the validation windows" (the pseudo-log of overlapping ones, or the
        seeds' windows pooled per log, `seed_logs_text`)."""
        if self.seed_logs_text:
            return "the validation windows"
        cells = [c for by in self.evidence.get(VALIDATION, {}).values() for c in by]
        apart = cells and all(c.log != VALIDATION_LOG and np.all(np.diff(np.sort(c.window_start_s))
                                                                  >= c.horizon_s - 1e-6 * max(1.0, c.horizon_s)) for c in cells)
        return "the non-overlapping validation windows" if apart else "the validation windows"

    @property
    def seed_logs_text(self) -> str:
        """" (each log's windows of all N seeds ...)" when the seeds' validation windows were
        pooled per log as one model's (`seed_logs`), else ""."""
        members = {j.n_members for j in self.validation_judgements.values()}
        if self.seeds <= 1 or members != {1}:
            return ""
        return (f" (each log's windows of all {self.seeds} seeds pooled as one model's, a stretch of log several seeds "
                "drew counted once: the seeds drew different validation blocks, so no window pairs with another seed's)")

    def decided_text(self) -> str:
        """"Decided on the test logs at 30 s and 100 s." (what the report and log say)."""
        hs = " and ".join(f"{h:g} s" for h in self.horizons_s)
        if self.decided_on == TEST:
            return f"Decided on the test logs at {hs}."
        return f"Decided on {self.validation_windows}{self.seed_logs_text} at {hs}: there are no test logs."

    def statement(self) -> str:
        """The verdict in a few sentences (the report's first lines, the CLI's last)."""
        if not self.judgements:
            return self._legacy_statement()
        text = " ".join(j.sentence for j in self.judgements.values()) + " " + self.decided_text()
        if self.decided_on == TEST:
            off = [j.outcome.value.replace("its baseline", label) for label, j in self.validation_judgements.items()
                   if j.outcome is not Outcome.BEATS]
            if off:
                text += (f" On {self.validation_windows}{self.seed_logs_text} the {self.model_name} "
                         + " and ".join(off) + ".")
        if not self.beats_baseline:
            text += {Outcome.DIVERGED: " Use the baseline; train again with a smaller step or check the logs.",
                     Outcome.WORSE: " Use the baseline, or train and check again, before trusting this model.",
                     Outcome.NOT_DISTINGUISHABLE: " More test logs or windows would decide; until then the "
                                                  "baseline is as good."}.get(self.outcome, "")
        return text

    def _legacy_statement(self) -> str:
        where = "the test logs" if self.decided_on == TEST else "the validation windows"
        cells = self.deciding
        if not cells:
            return f"No verdict: neither test logs nor validation windows gave the {self.model_name} a score."
        base = " and ".join(self.baselines)
        average = "; ".join(f"{percent_text(self.mean_change(b))} against {b}" for b in self.baselines)
        why = (f"the pooled rule on the mean over {self.seeds} seeds, whose windows differ and cannot be paired "
               f"per log" if self.seeds > 1 else "the pooled rule of a run written before sysid judged per log")
        if self.legacy_beats:
            every = "; every seed beats it" if self.seeds > 1 else ""
            return (f"The {self.model_name} beats its physics baseline, {base}, on {where} ({why}{every}): "
                    f"RMSE {average} on average.")
        return (f"The {self.model_name} is WORSE than its physics baseline, {base}, on {where} ({why}): "
                f"RMSE {average} on average.")

    def warning(self) -> str | None:
        """The WARNING line for stderr, or None when the model beats its baseline."""
        return None if self.beats_baseline else "WARNING: " + self.statement()

    def to_dict(self) -> dict:
        return {"model": self.model, "baselines": list(self.baselines), "decided_on": self.decided_on,
                "beats_baseline": self.beats_baseline, "seeds": self.seeds,
                "outcome": self.outcome.name.lower() if self.outcome else None,
                "val_loss_multistep": dict(self.val_loss_multistep),
                "statement": self.statement(), "cells": [asdict(c) for c in self.cells],
                "judgements": {k: j.to_dict() for k, j in self.judgements.items()},
                "validation_judgements": {k: j.to_dict() for k, j in self.validation_judgements.items()},
                "evidence": {split: {label: [cell_to_dict(c) for c in cells] for label, cells in by.items()}
                             for split, by in self.evidence.items()}}

    @classmethod
    def from_dict(cls, d: Mapping) -> "BaselineVerdict":
        cells = tuple(ChannelCell(**{**c, "baselines": dict(c["baselines"])}) for c in d["cells"])
        judgements = {k: Judgement.from_dict(v) for k, v in (d.get("judgements") or {}).items()}
        return cls(d["model"], tuple(d["baselines"]), cells, dict(d.get("val_loss_multistep") or {}),
                   d.get("decided_on", TEST), int(d.get("seeds", 1)), judgements,
                   {k: Judgement.from_dict(v) for k, v in (d.get("validation_judgements") or {}).items()},
                   {split: {label: tuple(cell_from_dict(c) for c in cells) for label, cells in by.items()}
                    for split, by in (d.get("evidence") or {}).items()},
                   None if judgements else bool(d.get("beats_baseline")))


def cell_to_dict(cell: PairedCell) -> dict:
    """A `PairedCell` as JSON (non-finite errors as null)."""
    def plain(a):
        return [[float(v) if math.isfinite(v) else None for v in row] for row in np.atleast_2d(a)]
    return {"log": cell.log, "scenario": cell.scenario, "horizon_s": cell.horizon_s, "channel": cell.channel,
            "model": plain(cell.model), "baseline": plain(cell.baseline),
            "window_start_s": [float(v) for v in cell.window_start_s],
            "divergence": cell.divergence.to_dict() if cell.divergence else None}


def cell_from_dict(d: Mapping) -> PairedCell:
    def array(rows):
        return np.array([[math.nan if v is None else v for v in row] for row in rows], dtype=float)
    return PairedCell(str(d["log"]), str(d.get("scenario", "")), float(d["horizon_s"]), str(d["channel"]),
                      array(d["model"]), array(d["baseline"]), np.asarray(d["window_start_s"], dtype=float),
                      Divergence.from_dict(d["divergence"]) if d.get("divergence") else None)


@dataclass(frozen=True)
class WindowScore:
    """A model on validation windows: ``val_loss_multistep``, the RMSE of u, v_m [m/s], r
    [rad/s] over the windows' predicted steps, and each window's own (W, 3); origins: the log
    and start time of each window (None: not known, one pseudo-log); diverged_after_s (W,):
    the time [s] from a window's first sample to its first diverged predicted one (the one
    rule, `sysid.evaluation.divergence`), NaN where the prediction did not diverge."""

    val_loss_multistep: float
    rmse: tuple[float, float, float]
    window_rmse: np.ndarray | None = None
    origins: WindowOrigins | None = None
    diverged_after_s: np.ndarray | None = None


def window_score(model, windows: WindowSet, w_v: torch.Tensor, errors: torch.Tensor | None = None,
                 origins: WindowOrigins | None = None, limits: PhysicalRange | None = None) -> WindowScore:
    """`WindowScore` of `model` on `windows` (Euler rollouts, as in training); `errors`: the
    velocity errors (T, W, 3) of those rollouts when already computed (`rollout_errors`);
    `origins`: the log and start time of each window; `limits`: the training range beyond
    which a prediction diverged (None: non-finite only)."""
    err = rollout_errors(model, windows) if errors is None else errors
    if origins is not None and len(origins) != err.shape[1]:
        raise ValueError(f"{len(origins)} window origins for {err.shape[1]} validation windows")
    rmse = torch.sqrt((err * err).reshape(-1, 3).mean(0))
    per_window = torch.sqrt((err * err).mean(0)).reshape(-1, 3)
    observed = windows.states[1:].detach().cpu().double().numpy()        # (T, W, 6): step k predicts sample k + 1
    predicted = observed.copy()
    predicted[..., list(VELOCITY_INDEX)] += err.detach().cpu().double().numpy()
    bad = diverged_steps(predicted, limits, observed)                    # (T, W)
    after = np.where(bad.any(0), (bad.argmax(0) + 1) * float(windows.dt), math.nan)
    return WindowScore(float(velocity_loss(err, w_v)), tuple(float(v) for v in rmse),  # type: ignore[arg-type]
                       per_window.detach().cpu().double().numpy(), origins, after)


def pooled_rmse(metrics: pd.DataFrame) -> dict[float, tuple[float, float, float]]:
    """horizon [s] -> RMSE of (u, v_m, r) pooled over every window point of every log of a
    metrics table (`sysid.evaluation.evaluate.METRICS_COLUMNS`); logs without windows skipped."""
    out = {}
    for horizon, block in metrics.groupby("horizon_s", sort=True):
        block = block[block.n_windows > 0]
        n = block.n_windows.to_numpy(dtype=float)
        if not n.sum():
            continue
        out[float(horizon)] = tuple(float(np.sqrt((n * block[c].to_numpy() ** 2).sum() / n.sum()))
                                    for c in ("rmse_u", "rmse_v", "rmse_r"))
    return out  # type: ignore[return-value]


def test_cells(model: "Evaluation", baseline: "Evaluation") -> list[PairedCell]:
    """One `PairedCell` per (test log, horizon, channel) with windows: the model's and the
    baseline's per-window RMSE on the same windows."""
    out = []
    for m, b in zip(model.windows, baseline.windows):
        if (m.file, m.horizon_s) != (b.file, b.horizon_s) or not len(m.start_s):
            continue
        for j, channel in enumerate(CHANNELS):
            out.append(PairedCell(m.file, m.scenario, m.horizon_s, channel, m.rmse[:, j][None, :],
                                  b.rmse[:, j][None, :], m.start_s, m.divergence))
    return out


def validation_cells(model: WindowScore, baseline: WindowScore, horizon_s: float) -> list[PairedCell]:
    """The model's and the baseline's per-window RMSE on the validation windows of one horizon
    [s]: one `PairedCell` per (validation log, channel) when the windows' origins are known,
    holding that log's non-overlapping windows (`WindowOrigins.non_overlapping`: starts at least
    `horizon_s` apart, as the test logs' windows; a divergence in any of its windows named by its
    log and time); else, origins unknown, one per channel with every window, overlapping ones
    too, in the one pseudo-log `VALIDATION_LOG` (its interval then narrower than its evidence)."""
    if model.window_rmse is None or baseline.window_rmse is None or not len(model.window_rmse):
        return []
    origins = model.origins if model.origins is not None else baseline.origins
    if origins is not None:
        after = model.diverged_after_s if model.diverged_after_s is not None else np.full(len(origins), math.nan)
        return _cells_per_log(model.window_rmse, baseline.window_rmse, after, origins, horizon_s)
    W = len(model.window_rmse)
    bad = ~np.all(np.isfinite(model.window_rmse), axis=1)
    if model.diverged_after_s is not None:   # the one rule: beyond the training range too
        bad |= np.isfinite(model.diverged_after_s)
    divergence = Divergence(VALIDATION_LOG, horizon_s, float(np.argmax(bad)), "", "non-finite or beyond "
                            f"{DIVERGENCE_FACTOR:g} x the training range (window {int(np.argmax(bad))} of {W})"
                            ) if bad.any() else None
    return [PairedCell(VALIDATION_LOG, "", horizon_s, channel, model.window_rmse[:, j][None, :],
                       baseline.window_rmse[:, j][None, :], np.arange(W, dtype=float), divergence)
            for j, channel in enumerate(CHANNELS)]


def _cells_per_log(model: np.ndarray, baseline: np.ndarray, diverged_after_s: np.ndarray, origins: WindowOrigins,
                   horizon_s: float) -> list[PairedCell]:
    """One `PairedCell` per (log of `origins`, channel) at `horizon_s` [s] from the per-window
    RMSE (W, 3) of model and baseline, on the log's non-overlapping windows (starts at least
    `horizon_s` apart); a log with a diverged window, kept or not (a non-finite RMSE, or
    `diverged_after_s` (W,) [s] after its start, NaN where it did not diverge), diverged at the
    first such time."""
    if len(origins) != len(model):
        raise ValueError(f"{len(origins)} window origins for {len(model)} validation windows")
    kept = origins.non_overlapping(horizon_s)
    out = []
    for log, index in origins.by_log().items():
        nonfinite = ~np.all(np.isfinite(model[index]), axis=1)
        far = np.isfinite(diverged_after_s[index]) & ~nonfinite
        bad = np.flatnonzero(nonfinite | far)
        divergence = None
        if bad.size:
            at = origins.start_s[index][bad] + np.nan_to_num(diverged_after_s[index][bad])   # log time [s]
            reason = ("non-finite" if not far.any() else f"beyond {DIVERGENCE_FACTOR:g} x the training range"
                      if not nonfinite.any() else f"non-finite or beyond {DIVERGENCE_FACTOR:g} x the training range")
            divergence = Divergence(log, horizon_s, float(at.min()), "",
                                    f"{reason} (in {bad.size} of its {index.size} validation windows)")
        judged = kept[log]
        out += [PairedCell(log, "", horizon_s, channel, model[judged, j][None, :], baseline[judged, j][None, :],
                           origins.start_s[judged], divergence) for j, channel in enumerate(CHANNELS)]
    return out


def judged(model: str, label: str, cells: Sequence[PairedCell], rule: VerdictRule, seeds: int = 1,
           ensemble_of: int = 0) -> Judgement:
    """`judge` with the sentence's names: "The hybrid" against "its physics baseline MMG (ship file)";
    `seeds` > 1 on cells of one member (`seed_logs`: the seeds' windows pooled per log) says so,
    as does `ensemble_of` > 0 (one model, the mean-of-seeds ensemble of that many seeds)."""
    name = MODEL_NAMES.get(model, model)
    pooled = seeds > 1 and all(c.model.shape[0] == 1 for c in cells)
    spread = (f" ({seeds} seeds' windows pooled)" if pooled else f" (mean over {seeds} seeds)") if seeds > 1 else ""
    one_member = ONE_MEMBER
    if pooled:   # one member: every seed's windows, no seed's spread of its own
        one_member = f"{seeds} seeds' windows pooled as one model's (no spread per seed)"
    if ensemble_of:
        spread = f" ensemble (the mean of {ensemble_of} seeds' forces)"
        if not pooled:
            one_member = "one model (the ensemble: no spread)"
    return judge(cells, rule, model=f"The {name}{spread}", baseline=f"its physics baseline {label}",
                 one_member=one_member)


def baseline_verdict(model: str, validation: Mapping[float, Mapping[str, WindowScore]] | None,
                     test: Mapping[str, "Evaluation"] | None, rule: VerdictRule = DEFAULT_RULE,
                     ensemble_of: int = 0) -> BaselineVerdict:
    """The verdict from scores keyed "model" and by baseline label (`SHIP_FILE_MMG`, ...):
    `validation` window scores per horizon [s], `test` evaluations on the test logs (None or
    empty: not available). A label's validation loss is the mean over the horizons, as
    ``val_loss_multistep``. `ensemble_of` > 0: the model is the mean-of-seeds ensemble of that
    many seeds (one model; the sentence names it so)."""
    first = next(iter(validation.values())) if validation else None
    labels = [k for k in (first or test or {}) if k != "model"]
    cells: list[ChannelCell] = []
    evidence: dict[str, dict[str, tuple[PairedCell, ...]]] = {}
    for horizon, scores in (validation or {}).items():
        for j, channel in enumerate(CHANNELS):
            cells.append(ChannelCell(VALIDATION, horizon, channel, scores["model"].rmse[j],
                                     {b: scores[b].rmse[j] for b in labels}))
        for b in labels:
            found = validation_cells(scores["model"], scores[b], horizon)
            evidence.setdefault(VALIDATION, {}).setdefault(b, ())
            evidence[VALIDATION][b] += tuple(found)
    if VALIDATION in evidence and not all(evidence[VALIDATION].values()):
        del evidence[VALIDATION]
    if test:
        pooled = {k: pooled_rmse(v.metrics) for k, v in test.items()}
        for horizon, values in pooled["model"].items():
            for j, channel in enumerate(CHANNELS):
                cells.append(ChannelCell(TEST, horizon, channel, values[j],
                                         {b: pooled[b].get(horizon, (math.nan,) * 3)[j] for b in labels}))
        by = {b: tuple(test_cells(test["model"], test[b])) for b in labels}
        if all(by.values()):
            evidence[TEST] = by
    losses = {k: float(np.mean([scores[k].val_loss_multistep for scores in validation.values()]))
              for k in (first or {})}
    return verdict_of(model, tuple(labels), tuple(cells), losses, evidence, rule, ensemble_of=ensemble_of)


def verdict_of(model: str, labels: tuple[str, ...], cells: tuple[ChannelCell, ...], losses: dict[str, float],
               evidence: dict[str, dict[str, tuple[PairedCell, ...]]], rule: VerdictRule,
               seeds: int = 1, ensemble_of: int = 0) -> BaselineVerdict:
    """Judge the evidence of every split against every baseline; the test logs decide when
    there are any."""
    decided = TEST if TEST in evidence else VALIDATION
    on_validation = {b: judged(model, b, cs, rule, seeds, ensemble_of) for b, cs in evidence.get(VALIDATION, {}).items()}
    # `judge` is pure: decided on the validation windows, their judgements are the same ones
    judgements = (dict(on_validation) if decided == VALIDATION else
                  {b: judged(model, b, cs, rule, seeds, ensemble_of) for b, cs in evidence.get(decided, {}).items()})
    return BaselineVerdict(model, labels, cells, losses, decided, seeds, judgements, on_validation, evidence)


def _members(seeds: Sequence[tuple[PairedCell, ...]]) -> tuple[PairedCell, ...] | None:
    """The cells of several seeds (each seed's cells in the same order) as one model's, every
    seed a member (a baseline the same in every seed counts once); None when the seeds' cells
    are not on the same windows, a window known by its identity: log, horizon and start
    time. Windows of the pseudo-log `VALIDATION_LOG` are known by position only, so they
    never pair across seeds."""
    first = seeds[0]
    if any(len(cells) != len(first) for cells in seeds) or any(c.log == VALIDATION_LOG for c in first):
        return None
    same_baseline = all(np.array_equal(cells[i].baseline, c.baseline, equal_nan=True)
                        for cells in seeds for i, c in enumerate(first))
    stacked = []
    for i, c in enumerate(first):
        others = [cells[i] for cells in seeds]
        if any(o.key != c.key or not np.array_equal(o.window_start_s, c.window_start_s) for o in others):
            return None
        stacked.append(PairedCell(c.log, c.scenario, c.horizon_s, c.channel, np.concatenate([o.model for o in others]),
                                  c.baseline if same_baseline else np.concatenate([o.baseline for o in others]),
                                  c.window_start_s, next((o.divergence for o in others if o.divergence is not None), None)))
    return tuple(stacked)


def stretches(start_s: np.ndarray, span_s: float) -> np.ndarray:
    """(W,) the stretch of log each window belongs to, numbered 0, 1, ... in time order, from
    window start times `start_s` (W,) [s] and their span [s]: in time order a window opens a
    new stretch when it starts at least one span after the stretch's first window (1e-6
    relative slack, as `WindowOrigins.non_overlapping`), else it joins it. Stretches start at
    least a span apart, as a log's non-overlapping windows; the windows of one stretch
    share most of their samples."""
    slack = 1e-6 * max(1.0, span_s)
    order = np.argsort(start_s, kind="stable")
    label = np.empty(len(start_s), dtype=int)
    n, opened = -1, -math.inf
    for i in order:                # one pass per log; a few hundred windows
        if start_s[i] >= opened + span_s - slack:
            n, opened = n + 1, float(start_s[i])
        label[i] = n
    return label


def _stretch_rms(errors: np.ndarray, label: np.ndarray) -> np.ndarray:
    """(1, S) root mean square of per-window RMSE `errors` (W,) over each stretch `label` (W,)."""
    n = int(label.max()) + 1 if label.size else 0
    return np.sqrt(np.bincount(label, weights=errors**2, minlength=n) / np.bincount(label, minlength=n))[None, :]


def _stretch_starts(start_s: np.ndarray, label: np.ndarray) -> np.ndarray:
    """(S,) the start [s] of each stretch `label` (W,): its first window's."""
    first = np.full(int(label.max()) + 1 if label.size else 0, math.inf)
    np.minimum.at(first, label, start_s)
    return first


def seed_logs(seeds: Sequence[Sequence[PairedCell]]) -> tuple[PairedCell, ...] | None:
    """Validation cells of several seeds whose validation windows differ (blocks drawn per
    seed, so no window pairs with another seed's): one cell per (log, horizon, channel) of
    any seed holding every seed's windows of that log as one model's (one member), each paired
    with the baseline on its own window. Windows of different seeds over the same stretch of
    log (`stretches`: starts less than a horizon apart) are one piece of evidence, not
    several: each stretch becomes one window of the cell, its model's and baseline's RMSE the
    root mean square over its windows (as `judge` pools windows), starting at the stretch's
    first window. The bootstrap then resamples each stretch once, as a test log's windows,
    and a log worse in the seeds stays a cell of its own. None when a seed's cells have
    several members or are windows of unknown identity (`VALIDATION_LOG`)."""
    if any(c.model.shape[0] != 1 or c.baseline.shape[0] != 1 or c.log == VALIDATION_LOG
           for cells in seeds for c in cells):
        return None
    groups: dict[tuple, list[PairedCell]] = {}
    for cells in seeds:
        for c in cells:
            groups.setdefault(c.key, []).append(c)
    out = []
    for g in groups.values():
        starts = np.concatenate([c.window_start_s for c in g])
        label = stretches(starts, float(g[0].horizon_s))
        out.append(PairedCell(g[0].log, g[0].scenario, g[0].horizon_s, g[0].channel,
                              _stretch_rms(np.concatenate([c.model[0] for c in g]), label),
                              _stretch_rms(np.concatenate([c.baseline[0] for c in g]), label),
                              _stretch_starts(starts, label),
                              next((c.divergence for c in g if c.divergence is not None), None)))
    return tuple(out)


def seed_mean_verdict(verdicts: Sequence[BaselineVerdict], rule: VerdictRule = DEFAULT_RULE) -> BaselineVerdict:
    """The verdict of several seeds of one experiment: every seed is a member of the model
    (the bootstrap draws seeds too; their spread is shown); a baseline the same in every seed
    (the ship file's MMG) counts once, one identified per seed counts every seed. A seed's
    cells pair with another's on the same windows (same log, horizon and start time);
    validation blocks drawn per seed (``[training] validation = "blocks"``) give the seeds
    different windows, and their validation cells are then judged per log with every seed's
    windows, each stretch of log once (`seed_logs`); validation windows of unknown identity
    (`VALIDATION_LOG`) of several seeds are not judged. The pooled cells are the seeds' mean with their std, matched by split,
    horizon and channel; a cell some seed lacks is left out of them."""
    first = verdicts[0]
    if len(verdicts) == 1:
        return first
    cells = []
    by_seed = [{(c.split, float(c.horizon_s), c.channel): c for c in v.cells} for v in verdicts]
    for cell in first.cells:   # those of every seed (a seed's blocks may hold no window of a long horizon)
        key = (cell.split, float(cell.horizon_s), cell.channel)
        if not all(key in mine for mine in by_seed):
            continue
        values = np.array([mine[key].model for mine in by_seed])
        baselines = {b: float(np.mean([mine[key].baselines[b] for mine in by_seed])) for b in first.baselines}
        cells.append(ChannelCell(cell.split, cell.horizon_s, cell.channel, float(values.mean()), baselines,
                                 float(values.std(ddof=1))))
    losses = {k: float(np.mean([v.val_loss_multistep.get(k, math.nan) for v in verdicts]))
              for k in first.val_loss_multistep}
    evidence: dict[str, dict[str, tuple[PairedCell, ...]]] = {}
    for split, by in first.evidence.items():
        if not all(split in v.evidence and v.evidence[split].keys() == by.keys() for v in verdicts):
            continue
        evidence[split] = {}
        for label in by:
            seeds = [v.evidence[split][label] for v in verdicts]
            stacked = _members(seeds)
            if stacked is None and split == VALIDATION:
                # validation blocks drawn per seed: the seeds' windows differ, so none pairs with
                # another seed's; every seed's windows of a log in that log's cell (`seed_logs`)
                stacked = seed_logs(seeds)
            if stacked is not None:
                evidence[split][label] = stacked
        if len(evidence[split]) != len(by):
            del evidence[split]
    if not evidence:
        return BaselineVerdict(first.model, first.baselines, tuple(cells), losses, first.decided_on, len(verdicts),
                               legacy_beats=all(v.beats_baseline for v in verdicts))
    return verdict_of(first.model, first.baselines, tuple(cells), losses, evidence, rule, len(verdicts))
