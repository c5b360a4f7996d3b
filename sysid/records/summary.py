"""summary.json of a run directory as a typed record (`RunSummary`), key for key, and the
run's validation loss in words (`VAL_LOSS_DEFINITION`). Torch-free.

Written by `sysid.runs.layout.write_run`, read by `sysid.runs.rundir.RunDir.read_summary`
(the report, sweeps, seed runs and the CLI read it there). Keys it does not know are kept
(`extra`, see `sysid.records.base`): a run written by a newer sysid still opens. Runs written
before a key existed read it as its default.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from sysid.config.choices import GateSpace, ModelKind, Solver, StartStates, TestLogs
from sysid.records.base import JsonRecord

LEGACY_VAL_LOSS = "val_loss"  # val_loss_multistep's key in runs written before it was renamed
# summary.json's "val_loss_definition": the run's one validation loss (`sysid.identify.trainer`)
VAL_LOSS_DEFINITION = (
    "val_loss_multistep: mean over the validation windows and their steps k = 1..K of "
    "sum over u, v_m, r of w_j (predicted_j - recorded_j)^2, w_j = 1 / variance of channel j in the "
    "training windows; Euler rollouts from each window's recorded first state with its recorded inputs; "
    "K = h / dt for each horizon h of [evaluation] horizons (or [training] objective_s when set) that the "
    "validation data hold a window of, the losses averaged over those horizons (T = [training] steps when none "
    "fits); the final model, kNN gate included. Validation windows: "
    "the validation blocks of the training logs, or whole validation logs: [data] validation, or the training "
    "logs held out by [training] validation = \"files\" (never a test file).")


def start_state_verdict(start_states: str, largest: str, largest_sigma: float | None, agrees: bool) -> str:
    """A start-state check (`sysid.identify.levenberg_marquardt.StartStateCheck.verdict`, and
    summary.json's ``identification.start_state_check``) in one clause, the same in the
    training log and the report: how far the estimates move in sigma (`largest_sigma`, None:
    no finite sigma; `largest`: that coefficient) and whether that stays within the ± 2 sigma."""
    if largest_sigma is None:
        return f"with start states {start_states}: no estimate has a finite σ to compare with"
    said = (f"with start states {start_states} the estimates move by at most "
            f"{abs(largest_sigma):.1f}σ ({largest})")
    if agrees:
        return said + ", within the ± 2σ"
    return (said + ": beyond the ± 2σ, so the data carry noisy start states or a model-structure error "
            "and the ± 2σ, which measures the noise only, is a lower bound on the uncertainty")


@dataclass(frozen=True)
class WeakDirection(JsonRecord):
    """A combination of coefficients the data do not determine: its sigma relative to the
    estimates, and the unit vector (coefficient name -> weight) in relative coordinates."""

    relative_sigma: float
    combination: dict[str, float]
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class UncertaintySummary(JsonRecord):
    """"identified_uncertainty": the identified coefficients' estimates, standard errors
    (None: infinite) and correlations (`sysid.identify.uncertainty.CoefficientUncertainty`)."""

    names: tuple[str, ...]
    estimate: tuple[float | None, ...] = ()
    std_error: tuple[float | None, ...] = ()
    correlation: tuple[tuple[float | None, ...], ...] = ()
    undetermined: tuple[bool, ...] = ()
    weak_directions: tuple[WeakDirection, ...] = ()
    residual_rms: float | None = None
    n_residuals: int | None = None
    n_windows: int | None = None
    method: str | None = None      # "sandwich" | "gauss_newton"
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class StartStateCheckSummary(JsonRecord):
    """"identification.start_state_check": the Levenberg-Marquardt fit again with the other
    start-state treatment, its distance from the configured fit in sigma and its validation loss."""

    start_states: StartStates                 # the other treatment
    coefficients: dict[str, float]
    difference_sigma: dict[str, float | None]  # (other - configured) / sigma; None: no finite sigma
    largest: str
    largest_sigma: float | None
    limit_sigma: float
    agrees: bool
    val_loss_multistep: float                 # the other fit's validation loss (`RunSummary.val_loss_multistep`)
    extra: dict[str, Any] = field(default_factory=dict)

    def verdict(self) -> str:
        """The check in one clause (the training log's and the report's wording)."""
        return start_state_verdict(self.start_states, self.largest, self.largest_sigma, self.agrees)


@dataclass(frozen=True)
class IdentificationSummary(JsonRecord):
    """"identification": the estimator of the identified coefficients and of their sigma.
    Gradient: solver, start_states, epochs, stage, integrator, covariance; Levenberg-Marquardt:
    solver, start_states, prior_weight, iterations, windows, integrator, covariance,
    start_state_check."""

    SPARSE = True
    solver: Solver | None = None
    start_states: StartStates | None = None
    prior_weight: float | None = None
    iterations: int | None = None
    epochs: int | None = None
    stage: str | None = None                 # "before" | "joint with the FNN"
    windows: int | None = None
    integrator: str | None = None
    covariance: str | None = None
    start_state_check: StartStateCheckSummary | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class GateSummary(JsonRecord):
    """"gate": the kNN gate of a hybrid (k, alpha, space, bank rows, threshold; absent
    without one) and, for every run, the share of prediction steps with the gate off per
    trace file (``off_share``)."""

    SPARSE = True
    k: int | None = None
    alpha: float | None = None
    space: GateSpace | None = None
    bank: int | None = None
    threshold: float | None = None
    off_share: dict[str, float] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SplitFile(JsonRecord):
    """One training file's windows in the training/validation split and its data issues. Under
    a one-quadrant propeller model the trainer adds, after these, astern_windows (its windows
    holding a sample outside that model's quadrant: astern revolutions or going astern) and
    astern_samples (its samples outside it); read, they are in `extra`."""

    file: str
    train_windows: int
    val_windows: int
    issues: tuple[str, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SplitSummary(JsonRecord):
    """"training.split" (`sysid.identify.trainer.SplitReport`); astern_windows: the windows
    outside a one-quadrant propeller model, left out when astern_excluded (``[data]
    exclude_astern``), both absent under a four-quadrant propeller."""

    SPARSE = True
    files: tuple[SplitFile, ...] = ()
    dropped_copies: tuple[str, ...] = ()
    suspect_windows: int = 0
    astern_windows: int | None = None
    astern_excluded: bool | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TrainingDetails(JsonRecord):
    """"training": the rest of the trainer's `TrainingSummary` (empty when untrained).
    Losses are multi-step losses (dimensionless); residual forces in N, N, N m."""

    SPARSE = True
    split: SplitSummary | None = None
    device: str | None = None
    mmg_train_loss: float | None = None
    mmg_val_loss: float | None = None
    residual_force_mean: tuple[float, ...] | None = None
    residual_force_std: tuple[float, ...] | None = None
    warm_val_loss: float | None = None
    ensemble_val_loss: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class VerdictCell(JsonRecord):
    """One channel at one horizon on one split of a verdict: the model's RMSE and each
    baseline's [m/s or rad/s] (`sysid.evaluation.verdict.ChannelCell`)."""

    split: str                                # "validation" | "test"
    horizon_s: float
    channel: str                              # "u" | "v_m" | "r"
    model: float
    baselines: dict[str, float]
    model_std: float | None = None            # spread over seeds of a seed-mean cell
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class VerdictSummary(JsonRecord):
    """"verdict": the run against its physics baselines
    (`sysid.evaluation.verdict.BaselineVerdict.to_dict`; ``BaselineVerdict.from_dict(
    summary.to_json())`` gives it back as that dataclass): the rule's outcome and judgement
    per baseline (`sysid.evaluation.judgement.Judgement`), the per-window evidence, the
    pooled cells. A run written before the rule has no outcome or judgements: its
    beats_baseline stands."""

    model: str
    baselines: tuple[str, ...]
    decided_on: str                           # "test" | "validation"
    beats_baseline: bool
    seeds: int
    val_loss_multistep: dict[str, float]      # "model" or a baseline label -> validation loss
    statement: str
    cells: tuple[VerdictCell, ...]
    outcome: str | None = None                # "beats" | "worse" | "not_distinguishable" | "diverged"; None: before the rule
    judgements: dict[str, Any] = field(default_factory=dict)             # baseline -> `Judgement.to_dict`
    validation_judgements: dict[str, Any] = field(default_factory=dict)  # the same on the validation windows
    evidence: dict[str, Any] = field(default_factory=dict)               # split -> baseline -> paired per-window cells
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RangeSummary(JsonRecord):
    """"training_range": the training logs' largest speed sqrt(u^2 + v_m^2) [m/s] and |r|
    [rad/s]; a prediction beyond `factor` times either diverged
    (`sysid.evaluation.divergence.PhysicalRange.to_dict`)."""

    speed: float
    yaw_rate: float
    factor: float
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class LogFile(JsonRecord):
    """A log a run used: file, its absolute path when the run was made (in runs written
    before `relative`, the path its config names); sha256, of its bytes; relative, the path
    its config names, relative to the run directory (`sysid.runs.log_paths`; None: a run
    written before, or a log of the paper's data set); rudder_sign_checked, astern_samples,
    astern_windows: the log's conditions (`sysid.data.splits.log_conditions`), absent when
    they do not apply."""

    SPARSE = True
    file: str
    sha256: str
    relative: str | None = None
    rudder_sign_checked: float | None = None    # the rudder check's partial correlation the user overrode
    astern_samples: int | None = None           # samples outside a one-quadrant propeller model
    astern_windows: dict[str, int] | None = None   # a test log's windows holding one, per horizon [s]
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class DataSummary(JsonRecord):
    """"data": what a run was trained, validated and tested on (`sysid.data.splits.provenance`).

    training : "files", "D1", "D2" or "-"; validation : the validation logs, or how the
    validation blocks were drawn (a sentence), or "none"; test_set : "files", "paper" or "none";
    held_out : with ``[training] validation = "files"``, the draw of the validation logs from
    the training logs: {"val_fraction", "split_seed", "groups": {group: [log names]}}.
    """

    training: str
    train: tuple[LogFile, ...] = ()
    validation: Any = "none"                  # tuple of `LogFile` as read: see `validation_logs`
    test_set: TestLogs = TestLogs.NONE
    test: tuple[LogFile, ...] = ()
    held_out: dict[str, Any] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def validation_logs(self) -> tuple[LogFile, ...]:
        """The validation logs (empty: validation blocks of the training logs)."""
        if not isinstance(self.validation, (list, tuple)):
            return ()
        return tuple(LogFile.from_json(f, "summary.json", f"data.validation[{i}]")
                     for i, f in enumerate(self.validation))


@dataclass(frozen=True)
class RunSummary(JsonRecord):
    """summary.json of a run directory.

    status : "complete" or "failed: why"; dataset : "D1", "D2", "files" or "-" (an MMG used
    as defined); seconds, train_seconds : wall time of the run and of its training [s];
    epochs : the largest epoch of any stage; best_epoch : of the last stage;
    val_loss_multistep : the run's validation loss, the final model's (kNN gate included)
    validation multi-step loss (the sweep objective), defined in words by
    val_loss_definition; verdict, beats_baseline : the run against its physics baselines
    (None without training); data : the logs it used; stopped : stage ->
    why it stopped; identified, identified_initial : coefficient -> value after and before
    identification.
    """

    name: str
    model: ModelKind = ModelKind.MMG
    status: str = "complete"
    dataset: str | None = None
    ship: str | None = None
    seed: int | None = None
    created: str | None = None
    seconds: float | None = None
    train_seconds: float | None = None
    epochs: int = 0
    best_epoch: int | None = None
    val_loss_multistep: float | None = None
    val_loss_definition: str | None = None
    verdict: VerdictSummary | None = None
    beats_baseline: bool | None = None
    data: DataSummary | None = None
    training_range: RangeSummary | None = None   # None: no training logs (an MMG used as defined) or an older run
    stopped: dict[str, str] = field(default_factory=dict)
    n_train_windows: int | None = None
    n_val_windows: int | None = None
    versions: dict[str, str] = field(default_factory=dict)
    mmg_overrides: dict[str, float] = field(default_factory=dict)
    identified: dict[str, float] = field(default_factory=dict)
    identified_initial: dict[str, float] = field(default_factory=dict)
    identified_uncertainty: UncertaintySummary | None = None
    identification: IdentificationSummary | None = None
    gate: GateSummary = field(default_factory=GateSummary)
    training: TrainingDetails = field(default_factory=TrainingDetails)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def failed(self) -> bool:
        return self.status.startswith("failed")

    @property
    def objective(self) -> float:
        """`val_loss_multistep`, NaN when there is none (an untrained or failed run). A run
        written before the rename has it under its older name, val_loss (kept in `extra`)."""
        value = self.val_loss_multistep if self.val_loss_multistep is not None else self.extra.get(LEGACY_VAL_LOSS)
        return float(value) if value is not None else math.nan

    @property
    def stopped_text(self) -> str:
        """"identify: early stop; train: epoch limit"."""
        return "; ".join(f"{stage}: {why}" for stage, why in self.stopped.items())
