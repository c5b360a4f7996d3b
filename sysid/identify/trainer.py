"""Identification: windows, the multi-step loss (Eqs. 13-17), Adam with early stopping.

`Trainer(experiment).fit(runs)` returns self with ``model_``, ``history_`` and
``summary_`` (a `TrainingSummary`). The trainer is composed of parts: the windows
(`sysid.identify.windowing`), the losses (`sysid.identify.losses`), the training loop
(`sysid.identify.loop`), its checkpointing (`sysid.identify.checkpoint.Checkpointing`) and
logging (`sysid.identify.journal`) parts, the warm start (`sysid.identify.warm_start`) and the
identification strategies (`sysid.identify.solvers`). Stages, in order, one method each:

1. Windows of T+1 samples (T Euler steps) slid by `stride_s` within each file; each file's
   time axis is cut into 30 s blocks, 30 % of them (seeded draw) validation, and a window
   lies wholly in one part, so no validation window overlaps a training window; or, given
   validation logs (``[data] validation``, or with ``[training] validation = "files"`` a
   ``val_fraction`` of each folder's training logs held out whole), every window of those is validation and
   every window of the training logs training. Exact copies of another file (``turn_cut_...``)
   and windows touching frozen-GNSS segments are left out and reported.
2. Standardisation: FNN input statistics from the training samples (relative wind computed
   from the recorded state and true wind, as the model sees it); output statistics from the
   residual force the data implies: M * (v[k+1] - v[k]) / dt + C(v[k]) - F_MMG(x[k])
   (for NN-only without F_MMG), the force that makes one Euler step land on the record.
3. Optional identification of MMG coefficients (``[identify]``, stage "before"), by
   gradient (Adam on the multi-step loss) or by Levenberg-Marquardt on the disjoint
   training windows with start states estimated or recorded (`sysid.identify.levenberg_marquardt`),
   with their standard errors and correlations (`sysid.identify.uncertainty`, disjoint windows) and,
   for LM, the fit with the other start-state treatment beside it (`start_state_check`).
4. Warm start: the FNN regresses that residual force (one-step fit). With ``[network]
   members`` K > 1, K networks are trained side by side (each on its own loss) and averaged.
5. Multi-step training: Euler rollouts of T steps through torchdiffeq, loss
   lambda_v * L_v + lambda_F * L_F + lambda_L2 * |theta|^2, Adam, early stopping on the
   validation velocity loss L_v of the network being trained (the *early-stopping loss*;
   the kNN gate does not exist yet), best weights restored.
6. The kNN gate is fitted on the training samples: final features (the paper's) or the
   standardised inputs (``[gate] space``).

The run's one validation loss is ``val_loss_multistep`` (`VAL_LOSS_DEFINITION`): L_v of the
final model as it predicts (kNN gate included) on validation windows of each ``[evaluation]
horizons`` (the verdict's horizons; ``[training] objective_s`` when set), averaged over the
horizons. The early-stopping loss is the same sum over the training windows' T steps during
training, before the gate exists.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import os
import random
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import torch

from sysid.config.choices import DType, ModelKind, Solver, Stage
from sysid.config.experiment import Experiment
from sysid.data.recordings import Run
from sysid.device import resolve_device
from sysid.dynamics.rollouts import WindowOrigins, WindowSet, rollout_errors, velocity_loss
from sysid.errors import ConfigError, DataError
from sysid.hybrid.correction import ForceCorrection, correction_inputs
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg
from sysid.hybrid.knn_gate import KNNGate
from sysid.hybrid.rollout_gate import with_rollout_gate
from sysid.identify.checkpoint import Checkpointing, files_of
from sysid.identify.journal import TrainingJournal
from sysid.identify.loop import EpochReport, RunProgress, StageResult, TrainingLoop
from sysid.identify.losses import VEL, adam, multistep_loss, output_penalty, weight_norm
from sysid.identify.solvers.base import Identification, IdentificationData, coefficients
from sysid.identify.solvers.gradient import GradientIdentification, gradient_estimator, gradient_uncertainty
from sysid.identify.solvers.least_squares import LevenbergMarquardtIdentification
from sysid.identify.warm_start import implied_residual, standardize, warm_start
from sysid.identify.windowing import (AsternSamples, SplitReport, WindowCut, astern_of, cut_windows,
                                      held_out_validation, objective_horizons, split_windows)
from sysid.records.base import JsonRecord
from sysid.records.summary import VAL_LOSS_DEFINITION, GateSummary, IdentificationSummary, UncertaintySummary

# the trainer's names, where code and benchmarks import them from
__all__ = ["Trainer", "TrainingSummary", "Prepared", "EpochReport", "StageResult", "SplitReport", "VEL",
           "VAL_LOSS_DEFINITION", "WindowSet", "adam", "held_out_validation", "implied_residual",
           "multistep_loss", "objective_horizons", "output_penalty", "rollout_errors", "seed_everything",
           "split_windows", "velocity_loss", "weight_norm"]


@dataclass
class TrainingSummary:
    """What training found and did; written into the run's summary.json."""

    n_train_windows: int
    n_val_windows: int
    split: SplitReport
    device: str
    epochs: int = 0                       # the largest epoch number of any stage
    best_epoch: int | None = None         # of the last stage (training, else identification)
    stopped: dict = field(default_factory=dict)  # stage -> reason
    identified_initial: dict = field(default_factory=dict)
    identified: dict = field(default_factory=dict)
    mmg_train_loss: float | None = None
    mmg_val_loss: float | None = None
    residual_force_mean: list | None = None   # N, N, N m
    residual_force_std: list | None = None
    warm_val_loss: float | None = None
    ensemble_val_loss: float | None = None
    val_loss_multistep: float | None = None  # VAL_LOSS_DEFINITION: the run's validation loss (sweep objective)
    identified_uncertainty: UncertaintySummary | None = None  # `CoefficientUncertainty.summary()`
    identification: IdentificationSummary | None = None  # the estimator: solver, start_states, iterations, ...
    gate: GateSummary | None = None       # without the off shares (evaluation's)
    train_seconds: float = 0.0
    failure: str | None = None            # why the run failed (a hit wall-clock limit)

    def to_dict(self) -> dict:
        """Plain data (the records as their summary.json objects), None fields left out."""
        plain = dataclasses.asdict(dataclasses.replace(self, **dict.fromkeys(_RECORDS)))
        plain["split"] = {k: v for k, v in plain["split"].items() if v is not None}  # astern counts: one-quadrant only
        return {f.name: (copy.deepcopy(value.to_json()) if f.name in _RECORDS else plain[f.name])
                for f in dataclasses.fields(self) if (value := getattr(self, f.name)) is not None}

    @classmethod
    def from_dict(cls, d: dict) -> "TrainingSummary":
        """The summary in `d` (`to_dict`'s, as a training checkpoint holds it)."""
        records = {k: record.from_json(d[k], "training checkpoint", k) for k, record in _RECORDS.items() if k in d}
        return cls(**{**d, "split": SplitReport(**d["split"]), **records})


# `TrainingSummary` fields that are records of summary.json
_RECORDS: dict[str, type[JsonRecord]] = {"identified_uncertainty": UncertaintySummary, "identification": IdentificationSummary,
                                          "gate": GateSummary}


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


@dataclass
class Prepared:
    """What `Trainer.prepare` leaves for the training stage and `Trainer.finish`: the training
    logs `runs` (held-out validation logs removed), dtype, device, the start time
    (``time.perf_counter``), the windows, the training samples, w_v (3,), the MMG, and for a
    learned model still to train (``trains``): the model, the trained parameters and w_F (3,)
    (None: NN-only); val_origins: the log and start time of each validation window."""

    runs: Sequence[Run]
    dtype: torch.dtype
    device: torch.device
    started: float
    train: WindowSet
    val: WindowSet
    samples: tuple[torch.Tensor, torch.Tensor]
    w_v: torch.Tensor
    mmg: torch.nn.Module
    model: CorrectedModel | None = None
    params: list = field(default_factory=list)
    w_F: torch.Tensor | None = None
    val_origins: WindowOrigins | None = None

    @property
    def trains(self) -> bool:
        return self.model is not None


class Trainer:
    """Fits an MMG-only (optionally identified), NN-only or hybrid model to processed runs.

    Training runs on ``[training] device`` ("auto": CUDA when present, else CPU); the fitted
    ``model_`` stays there (``model_.cpu()`` for CPU evaluation).

    Parameters
    ----------
    experiment : validated experiment options.
    progress : show progress (a bar on a terminal, a line every 10 epochs elsewhere).
    log : callable receiving one-line messages (None: the ``logging`` logger
        ``sysid.identify.journal`` at INFO).
    checkpoint : file for the per-epoch training checkpoint (None: none written).
    resume : continue from `checkpoint` when it exists (same config required).
    on_epoch : called with an `EpochReport` after every epoch (and its checkpoint).
    """

    def __init__(self, experiment: Experiment, progress: bool = True, log: Callable[[str], None] | None = None,
                 checkpoint: str | os.PathLike | None = None, resume: bool = False,
                 on_epoch: Callable[[EpochReport], None] | None = None):
        self.experiment = experiment
        self.progress = progress
        self.journal = TrainingJournal(log, progress)
        files = files_of(experiment) if checkpoint is not None else None   # the files the config names, by bytes
        self.checkpointing = Checkpointing(checkpoint, experiment.to_toml(), resume, files)
        self.resume = resume
        self.on_epoch = on_epoch
        self._validation_runs: list[Run] = []   # fit's validation logs

    # -- the estimator ---------------------------------------------------------------
    def fit(self, runs: Sequence[Run], validation: Sequence[Run] = ()) -> "Trainer":
        """Fit to the training logs `runs`; validation windows from `validation` logs when
        given, else from logs of `runs` held out whole (``[training] validation = "files"``,
        `sysid.data.splits.hold_out_files`), else from the validation blocks of `runs`.
        Sets ``model_``, ``history_``,
        ``summary_``, ``validation_windows_`` (the windows of ``val_loss_multistep``),
        ``validation_sets_`` / ``validation_origins_`` (those windows per horizon [s], and the
        log and start time of each) and ``velocity_weights_`` (w_v (3,), 1 / variance of u,
        v_m, r in the training windows)."""
        prepared = self.prepare(runs, validation)
        stage = None
        if prepared.trains:
            stage = self.train(prepared.model, prepared.params, prepared.train, prepared.val, prepared.w_v,
                               prepared.w_F)
        return self.finish(prepared, stage)

    def prepare(self, runs: Sequence[Run], validation: Sequence[Run] = ()) -> Prepared:
        """Stages 1-4 of `fit` (split, identification before training, standardisation, warm
        start, or their results from a checkpoint of the training stage): what stage 5 and
        `finish` need. `sysid.identify.side_by_side` trains several seeds' stage 5 at once."""
        if not validation and (held_out := held_out_validation(self.experiment, runs)) is not None:
            runs, validation = held_out.train, held_out.validation
        self._validation_runs = list(validation)
        prepared = self._begin(runs)
        self.identify(prepared)
        if self.experiment.experiment.model is not ModelKind.MMG and self.summary.failure is None:
            self._prepare_network(prepared)
        return prepared

    def train(self, model: CorrectedModel, params, train: WindowSet, val: WindowSet, w_v, w_F) -> StageResult:
        """Stage 5: multi-step training of every FNN member (and joint MMG coefficients)."""
        t = self.experiment.training
        return self.loop.run(PerMember(model), params, train, val, w_v, w_F, t.epochs, t.learning_rate, "train")

    def finish(self, prepared: Prepared, stage: StageResult | None) -> "Trainer":
        """Stage 6 and the run's validation loss after the training stage `stage` (None: no
        training stage, MMG-only or a failure before it); returns self, fitted."""
        t = self.experiment.training
        model = prepared.model if prepared.model is not None else prepared.mmg
        summary, val, w_v = self.summary, prepared.val, prepared.w_v
        stopping_best = None
        if stage is not None and prepared.model is not None:
            stopping_best = self._finish_training(prepared, stage)
        self.velocity_weights_ = w_v
        self.validation_windows_ = val
        self.validation_sets_ = {round(t.steps * val.dt, 6): val}
        self.validation_origins_: dict[float, WindowOrigins] = (
            {} if prepared.val_origins is None else {round(t.steps * val.dt, 6): prepared.val_origins})
        self.validation_errors_: dict[float, torch.Tensor] = {}
        if summary.failure is None:
            summary.val_loss_multistep = self.objective(model, prepared.runs, val, w_v, prepared.dtype,
                                                        prepared.device, prepared.val_origins)
            self.journal.objective(summary.val_loss_multistep, self.validation_sets_, summary.gate is not None,
                                   stopping_best)
        history = self._run.history
        self.history_ = pd.DataFrame(history)
        summary.epochs = int(self.history_["epoch"].max()) if len(history) else 0
        summary.train_seconds = time.perf_counter() - prepared.started
        self.model_, self.summary_ = model, summary
        return self

    # -- the run so far ----------------------------------------------------------------
    @property
    def summary(self) -> TrainingSummary:
        """The `TrainingSummary` of the fit so far."""
        return self._run.summary

    def _resumed_in(self, label: str) -> bool:
        return self.checkpointing.stage(label) is not None

    def _begin(self, runs: Sequence[Run]) -> Prepared:
        """Seeds, dtype, device, the wall-clock deadline, the resumed state, stage 1 (the
        split), w_v, the MMG as configured, the run so far and its training loop."""
        exp, t = self.experiment, self.experiment.training
        seed_everything(exp.experiment.seed)
        dtype = torch.float32 if t.dtype is DType.FLOAT32 else torch.float64
        device = resolve_device(t.device)
        started = time.perf_counter()
        deadline = started + 60.0 * t.max_minutes if t.max_minutes > 0 else math.inf
        resumed = self.checkpointing.start()
        cut = self.split(runs, dtype, device)
        train, val, samples = cut.train, cut.val, cut.samples
        if exp.experiment.model is not ModelKind.MMG and exp.gate.enabled and exp.gate.k > len(samples[0]):
            raise ConfigError(f"{exp.source or 'experiment'}: [gate] k = {exp.gate.k}: more neighbours than "
                              f"the {len(samples[0])} training samples the gate's bank holds")
        # velocity weights w_v: inverse variance of the recorded velocities
        w_v = 1.0 / train.states[:, :, VEL].reshape(-1, 3).var(0)
        mmg = build_mmg(exp, dtype).to(device)
        if resumed is not None and resumed.stage == "train":  # earlier stages are done: from the checkpoint
            self._run = RunProgress(list(resumed.history), TrainingSummary.from_dict(resumed.summary))
        else:
            self._run = RunProgress([], TrainingSummary(len(train), len(val), cut.report, str(device)))
        self.loop = TrainingLoop(exp, self.checkpointing, self.journal, self._run, deadline, self.on_epoch)
        return Prepared(runs, dtype, device, started, train, val, samples, w_v, mmg, val_origins=cut.val_origins)

    # -- stages ----------------------------------------------------------------------
    def split(self, runs: Sequence[Run], dtype, device) -> WindowCut:
        """Stage 1: training and validation windows, training samples, the split report and
        the validation windows' origins."""
        exp, t = self.experiment, self.experiment.training
        cut = cut_windows(runs, t.steps, t.stride_s, t.val_fraction, exp.data.exclude_suspect, dtype, t.block_s,
                          exp.experiment.seed, device, self._validation_runs, self.astern())
        self.journal.split(cut.report, len(cut.train), len(cut.val), t.steps)
        return cut

    def astern(self) -> AsternSamples | None:
        """The samples outside the ship file's propeller model (`sysid.identify.windowing.astern_of`):
        None under a four-quadrant propeller."""
        return astern_of(self.experiment, build_mmg(self.experiment).ship.models)

    def disjoint_windows(self, runs: Sequence[Run], dtype, device) -> WindowSet:
        """Windows of T+1 samples of the training part that share no sample (slid by T+1):
        independent clusters for the sandwich sigma, and what least squares identifies on."""
        exp, t = self.experiment, self.experiment.training
        return split_windows(runs, t.steps, float(t.steps + 1) / exp.data.rate, t.val_fraction,
                             exp.data.exclude_suspect, dtype, t.block_s, exp.experiment.seed, device,
                             self._validation_runs, self.astern())[0]

    def solver(self) -> Identification:
        """The identification strategy of ``[identify] solver``."""
        if self.experiment.identify.solver is Solver.LEVENBERG_MARQUARDT:
            return LevenbergMarquardtIdentification(self.experiment)
        return GradientIdentification(self.experiment, self.loop)

    def identify(self, prepared: Prepared) -> None:
        """Stage 3 (``[identify]``): the MMG coefficients identified before training (stage
        "before", or MMG-only) by the configured strategy (`solver`), their sigma and what
        identified them into the summary; the MMG then frozen unless identified jointly."""
        exp, summary = self.experiment, self.summary
        names = list(exp.identify.parameters)
        joint = exp.identify.stage is Stage.JOINT
        if not names:
            return
        if not summary.identified_initial:
            summary.identified_initial = coefficients(prepared.mmg, names)
        if (exp.experiment.model is ModelKind.MMG or not joint) and not self._resumed_in("train"):
            data = IdentificationData(prepared.train, prepared.val, prepared.w_v,
                                      partial(self.disjoint_windows, prepared.runs, device=prepared.device))
            solver = self.solver().fit(prepared.mmg, data)
            self._say_identified(solver, prepared.mmg)
            self._run.history += solver.stage_.history
            summary.stopped["identify"] = solver.stage_.stopped
            summary.best_epoch = solver.stage_.best_epoch  # the training stage's, if one follows
            summary.identified = coefficients(prepared.mmg, names)
            summary.identified_uncertainty = solver.uncertainty_.summary()
            summary.identification = solver.estimator_
        if not joint:
            prepared.mmg.requires_grad_(False)

    def _say_identified(self, solver: Identification, mmg) -> None:
        identified = coefficients(mmg, self.experiment.identify.parameters)
        if isinstance(solver, LevenbergMarquardtIdentification):
            self.journal.least_squares(solver)
            self.journal.identified(identified)
            self.journal.start_state_check(solver.check_, solver.val_loss_, solver.check_val_loss_)
        else:
            self.journal.identified(identified)
        self.journal.uncertainty(solver.uncertainty_)

    def _prepare_network(self, prepared: Prepared) -> None:
        """The FNN of an NN-only or hybrid model: standardised and warm-started (stages 2 and
        4), or its state from a checkpoint of the training stage; its trained parameters."""
        exp, kind = self.experiment, self.experiment.experiment.model
        joint = bool(exp.identify.parameters) and exp.identify.stage is Stage.JOINT
        net = ForceCorrection(exp.network.hidden, prepared.dtype, exp.network.members).to(prepared.device)
        model = CorrectedModel(prepared.mmg, net, None, physics=(kind is ModelKind.HYBRID),
                               gate_space=exp.gate.space)
        resumed = self.checkpointing.stage("train")
        if resumed is None:
            self._warm_start(model, prepared)
        prepared.params = list(net.parameters()) + (list(prepared.mmg.parameters()) if joint else [])
        if resumed is not None:  # buffers (standardisation) first: w_F depends on them
            PerMember(model).load_state_dict(resumed.model)
        prepared.model = model
        prepared.w_F = 1.0 / net.output_std if kind is ModelKind.HYBRID else None

    def _warm_start(self, model: CorrectedModel, prepared: Prepared) -> None:
        """Stages 2 and 4 (`sysid.identify.warm_start`), the MMG's and the warm-started
        network's multi-step losses into the summary."""
        t, summary = self.experiment.training, self.summary
        train, val, w_v = prepared.train, prepared.val, prepared.w_v
        with torch.no_grad():
            summary.mmg_val_loss = float(multistep_loss(prepared.mmg, val, w_v)[0])
            summary.mmg_train_loss = float(multistep_loss(prepared.mmg, train, w_v)[0])
        self.journal.mmg_losses(summary.mmg_train_loss, summary.mmg_val_loss)
        s, residual = standardize(model, train, t.stride_s)
        summary.residual_force_mean = residual.mean(0).tolist()
        summary.residual_force_std = residual.std(0).tolist()
        if t.warm_start_epochs:
            warm_start(model.correction_net, s, residual, prepared.device, self.experiment, self.journal)
        with torch.no_grad():
            summary.warm_val_loss = float(multistep_loss(PerMember(model), val, w_v)[0])
        self.journal.warm_started(summary.warm_val_loss)

    def _finish_training(self, prepared: Prepared, stage: StageResult) -> float | None:
        """After the training stage: its history and stop, the ensemble's loss, jointly
        identified coefficients with their sigma, the gate (stage 6); the early-stopping
        loss when a gate follows it."""
        exp, summary = self.experiment, self.summary
        model, val, w_v = prepared.model, prepared.val, prepared.w_v
        assert model is not None
        self._run.history += stage.history
        summary.stopped["train"] = stage.stopped
        summary.best_epoch = stage.best_epoch
        with torch.no_grad():
            summary.ensemble_val_loss = float(multistep_loss(model, val, w_v)[0])
        self.journal.ensemble(model.correction_net.members, summary.ensemble_val_loss)
        if exp.identify.parameters and exp.identify.stage is Stage.JOINT:
            summary.identified = coefficients(prepared.mmg, exp.identify.parameters)
            disjoint = self.disjoint_windows(prepared.runs, prepared.dtype, prepared.device)
            result = gradient_uncertainty(model, disjoint, exp.identify.parameters, w_v)
            self.journal.uncertainty(result)
            summary.identified_uncertainty = result.summary()
            summary.identification = gradient_estimator(len(stage.history), joint=True)
        if exp.gate.enabled:
            summary.gate = self.fit_gate(model, prepared.samples, prepared.dtype)
        return stage.best_loss if exp.gate.enabled else None

    def fit_gate(self, model: CorrectedModel, samples: tuple[torch.Tensor, torch.Tensor], dtype) -> GateSummary:
        """Stage 6: the kNN gate on the training samples' features (or standardised inputs)."""
        gate = self.experiment.gate
        with torch.no_grad():
            states, inputs = samples
            rel = model.mmg(states, inputs).relative_wind
            z = model.gate_coordinates(correction_inputs(states, inputs, rel))
        model.gate = KNNGate(gate.k, gate.alpha, z.shape[-1], dtype).fit(z)
        model.gate_enabled = True
        self.journal.gate(z.shape[0], float(model.gate.threshold))
        return GateSummary(k=gate.k, alpha=gate.alpha, space=gate.space, bank=int(z.shape[0]),
                           threshold=float(model.gate.threshold))

    def objective(self, model, runs: Sequence[Run], val: WindowSet, w_v, dtype, device,
                  val_origins: WindowOrigins | None = None) -> float:
        """The run's validation loss ``val_loss_multistep`` (`VAL_LOSS_DEFINITION`): L_v of the
        final model (gate included) on validation windows of each of its horizons
        (`objective_horizons`), averaged over the horizons the validation data hold a window
        of; the T-step windows `val` (cut from the logs `val_origins` names) when they hold
        none. The windows are kept per horizon as ``validation_sets_`` (the first as
        ``validation_windows_``), their logs and start times as ``validation_origins_``, the
        model's velocity errors (T, W, 3) on them as ``validation_errors_``."""
        exp, t = self.experiment, self.experiment.training
        sets: dict[float, WindowSet] = {}
        origins: dict[float, WindowOrigins] = {}
        for horizon in objective_horizons(exp):
            # objective_s: that many seconds of steps; an evaluation horizon: windows of as many
            # samples as the test windows (H = h / dt points, first included)
            steps = max(1, int(round(horizon / val.dt)) - (0 if t.objective_s > 0 else 1))
            if not self._validation_runs and int(round(t.block_s / val.dt)) < steps + 1:
                self.journal.horizon_left_out(horizon, t.block_s)
                continue
            try:
                cut = cut_windows(runs, steps, t.stride_s, t.val_fraction, exp.data.exclude_suspect, dtype,
                                  t.block_s, exp.experiment.seed, device, self._validation_runs, self.astern())
            except DataError:   # none that long
                cut = None
            if cut is not None and len(cut.val):
                sets[horizon], origins[horizon] = cut.val, cut.val_origins
            else:
                self.journal.horizon_left_out(horizon, None)
        if not sets:
            sets[round(t.steps * val.dt, 6)] = val
            if val_origins is not None:
                origins[round(t.steps * val.dt, 6)] = val_origins
        self.validation_sets_ = sets
        self.validation_origins_ = origins
        self.validation_windows_ = next(iter(sets.values()))
        # the rollouts' errors, kept per horizon for the verdict's validation scores; the gate's
        # decisions along each rollout from its earlier steps' scans (`RolloutGate`: the same decisions)
        self.validation_errors_ = {horizon: rollout_errors(with_rollout_gate(model), w) for horizon, w in sets.items()}
        return float(np.mean([float(velocity_loss(err, w_v)) for err in self.validation_errors_.values()]))
