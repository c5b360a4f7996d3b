"""Identification: windows, the multi-step loss (Eqs. 13-17), Adam with early stopping.

`Trainer(experiment).fit(runs)` returns self with ``model_``, ``history_`` and
``summary_`` (a `TrainingSummary`). Stages, in order, one method each:

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

import dataclasses
import logging
import math
import os
import random
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import torch
from tqdm import tqdm

from sysid.hybrid.correction import ForceCorrection, correction_inputs
from sysid.identify.checkpoint import CheckpointState, TrainingCheckpoint
from sysid.data.recordings import Run, duplicate_runs, sliding_windows, stack_windows, window_touches
from sysid.data.splits import HeldOutFiles, hold_out_files
from sysid.device import resolve_device
from sysid.dynamics.equations import integrate, integrate_training, required_force
from sysid.dynamics.rollouts import WindowSet, rollout_errors, velocity_loss  # noqa: F401 (the trainer's names too)
from sysid.errors import ConfigError, DataError, TrainingError
from sysid.config.choices import DType, Method, ModelKind, Solver, Stage, StartStates, Validation
from sysid.config.experiment import PAPER_FORCE_BAND, Experiment
from sysid.identify.levenberg_marquardt import fit_uncertainty, identify_levenberg_marquardt, start_state_check
from sysid.hybrid.force_models import CorrectedModel, PerMember, build_mmg, correction_of
from sysid.hybrid.knn_gate import KNNGate
from sysid.state import VELOCITY_INDEX
from sysid.identify.uncertainty import coefficient_uncertainty
from sysid.records.summary import VAL_LOSS_DEFINITION  # noqa: F401 (its home before: the run's validation loss)

VEL = list(VELOCITY_INDEX)
_LOG = logging.getLogger(__name__)


@dataclass
class SplitReport:
    """How the files were cut: per file its training/validation window counts and quality
    issues; files left out as copies of another; windows left out at frozen GNSS."""

    files: list[dict] = field(default_factory=list)
    dropped_copies: list[str] = field(default_factory=list)
    suspect_windows: int = 0


@dataclass
class StageResult:
    """One optimisation stage: its history rows, best epoch and why it stopped."""

    history: list[dict]
    best_epoch: int
    best_loss: float
    stopped: str  # "early stop" | "epoch limit" | "time limit" (a failure)


@dataclass(frozen=True)
class EpochReport:
    """One finished epoch of an optimisation stage, given to ``Trainer(on_epoch=...)`` after
    the epoch's checkpoint is written. Losses are the multi-step losses of the history."""

    stage: str                     # "identify" | "train"
    epoch: int                     # within the stage, from 1
    epochs: int                    # the stage's epoch limit
    train_loss: float
    val_loss: float                # validation velocity loss L_v of this epoch
    best_loss: float               # best validation loss of the stage so far
    best_epoch: int
    checkpoint: Path | None        # the checkpoint file just written (None: none kept)


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
    identified_uncertainty: dict | None = None  # `CoefficientUncertainty.as_dict()`
    identification: dict | None = None    # the estimator: solver, start_states, iterations, ...
    gate: dict | None = None
    train_seconds: float = 0.0
    failure: str | None = None            # why the run failed (a hit wall-clock limit)

    def to_dict(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}

    @classmethod
    def from_dict(cls, d: dict) -> "TrainingSummary":
        return cls(**{**d, "split": SplitReport(**d["split"])})


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def _block_parts(n: int, block: int, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    """(n,) True for samples in validation blocks: the run is cut into blocks of `block`
    samples and a `val_fraction` share of them, drawn at random, is held out."""
    n_blocks = max(2, math.ceil(n / max(block, 1)))
    n_val = min(n_blocks - 1, max(1, int(round(val_fraction * n_blocks))))
    val_blocks = np.zeros(n_blocks, dtype=bool)
    val_blocks[rng.choice(n_blocks, n_val, replace=False)] = True
    return np.repeat(val_blocks, math.ceil(n / n_blocks))[:n]


def objective_horizons(exp: Experiment) -> tuple[float, ...]:
    """The horizons [s] of ``val_loss_multistep``: ``[training] objective_s`` when set, else
    ``[evaluation] horizons``, the horizons the verdict judges on the test logs (one
    definition of good for validation, sweeps and the verdict)."""
    t = exp.training
    return (float(t.objective_s),) if t.objective_s > 0 else tuple(float(h) for h in exp.evaluation.horizons)


def split_windows(runs: Sequence[Run], steps: int, stride_s: float, val_fraction: float,
                  exclude_suspect: bool = True, dtype=torch.float64, block_s: float = 30.0, seed: int = 0,
                  device: str | torch.device = "cpu", validation_runs: Sequence[Run] = ()):
    """Training and validation `WindowSet`s, the training samples (N, 6)/(N, 4), and a
    `SplitReport`.

    Each file is cut into blocks of `block_s`; a random `val_fraction` of the blocks (seeded)
    is validation. Windows lie wholly inside one part, so none overlaps across the split.
    Given `validation_runs`, those are validation whole and `runs` training whole.
    """
    rng = np.random.default_rng(seed)
    report = SplitReport()
    validation_runs = list(validation_runs)
    copies = {copy for copy, _ in duplicate_runs(list(runs) + validation_runs)}
    parts: dict[str, list] = {"train": [], "val": []}
    samples = ([], [])
    dt = None
    length = steps + 1
    for run in list(runs) + validation_runs:
        if run.name in copies:
            report.dropped_copies.append(run.name)
            continue
        dt = run.dt if dt is None else dt
        if abs(run.dt - dt) > 1e-9:
            raise DataError(f"{run.path}: sample period {run.dt} s differs from {dt} s")
        stride = max(1, int(round(stride_s / run.dt)))
        if validation_runs:
            part_of = np.full(len(run), any(run is v for v in validation_runs))
        else:
            block = int(round(block_s / run.dt))
            if block < length:  # no window would lie wholly in one block: none in either part
                raise ConfigError(f"[training] block_s = {block_s:g} s: a validation block holds {block} of the "
                                  f"data's {run.dt:g}-s samples, fewer than one {length}-sample training window; "
                                  f"set block_s >= {length * run.dt:g} s (default 30)")
            part_of = _block_parts(len(run), block, val_fraction, rng)
        starts = sliding_windows(len(run), length, stride)
        ends = starts + length - 1
        counts = {}
        for part, flag in (("train", False), ("val", True)):
            # a window lies wholly in one part: no validation window overlaps a training one
            inside = np.concatenate([[0], np.cumsum(part_of == flag)])
            mine = starts[inside[ends + 1] - inside[starts] == length]
            if exclude_suspect:
                bad = window_touches(run, mine, length)
                report.suspect_windows += int(bad.sum())
                mine = mine[~bad]
            counts[part] = len(mine)
            if len(mine):
                parts[part].append(stack_windows(run, mine, length, dtype, device))
        keep = ~part_of
        for a, b in run.suspect if exclude_suspect else []:
            keep &= ~((run.t >= a - 1.0) & (run.t <= b + 1.0))
        samples[0].append(torch.as_tensor(run.states[keep], dtype=dtype, device=device))
        samples[1].append(torch.as_tensor(run.inputs[keep], dtype=dtype, device=device))
        report.files.append({"file": run.name, "train_windows": counts["train"],
                             "val_windows": counts["val"], "issues": run.issues})
    if not parts["train"]:
        raise DataError("no training windows: the files are shorter than one window")
    if not parts["val"]:
        raise DataError("no validation windows: the validation logs are shorter than one window"
                        if validation_runs else "no validation windows: the files are too short for the 70/30 split")

    def window_set(chunks) -> WindowSet:
        return WindowSet(torch.cat([c[0] for c in chunks], 1), torch.cat([c[1] for c in chunks], 1), dt)

    return window_set(parts["train"]), window_set(parts["val"]), \
        (torch.cat(samples[0]), torch.cat(samples[1])), report


def implied_residual(model: CorrectedModel, windows: WindowSet, pairs: int = 2
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Correction inputs s (N, 9), residual force (N, 3) and F_MMG (N, 3) at step starts."""
    # the first `pairs` steps of each window: with 2-s strides that covers each step once
    states, inputs = windows.states[:pairs + 1], windows.inputs[:pairs + 1]
    x, nxt, inp = states[:-1].reshape(-1, 6), states[1:].reshape(-1, 6), inputs[:-1].reshape(-1, 4)
    with torch.no_grad():
        acc = (nxt[:, VEL] - x[:, VEL]) / windows.dt
        need = required_force(x, acc, model.coefficients)
        forces = model.mmg(x, inp)
        f_mmg = forces.mmg if model.physics else torch.zeros_like(need)
        s = correction_inputs(x, inp, forces.relative_wind)
    return s, need - f_mmg, f_mmg


def output_penalty(f_nn: torch.Tensor, f_mmg: torch.Tensor, w_F: torch.Tensor,
                   band: float = PAPER_FORCE_BAND) -> torch.Tensor:
    """Eq. (17): w_F^T (|F_NN| - band |F_MMG|)^+ per sample, (..., 3) -> (...).

    Zero while every component of F_NN stays within `band` (20 %) of the MMG force's
    magnitude; grows linearly outside. w_F (3,) scales X [1/N], Y [1/N], N [1/(N m)].
    """
    return (torch.relu(f_nn.abs() - band * f_mmg.abs()) * w_F).sum(-1)


def held_out_validation(exp: Experiment, runs: Sequence[Run]) -> HeldOutFiles | None:
    """With ``[training] validation = "files"``: the training logs `runs` split into training
    and held-out validation logs (`sysid.data.splits.hold_out_files`, ``val_fraction`` of each
    folder's logs, drawn with ``split_seed``); else None."""
    t = exp.training
    return hold_out_files(runs, t.val_fraction, t.split_seed) if t.validation is Validation.FILES else None


def adam(params, lr: float) -> torch.optim.Adam:
    """Adam (the paper's optimiser) updating all parameters in a few multi-tensor
    operations (``foreach``): the same numbers as the per-parameter loop, fewer dispatches."""
    return torch.optim.Adam(params, lr=lr, foreach=True)


def weight_norm(net: ForceCorrection) -> torch.Tensor:
    """||theta||^2 of the FNN weights (Eq. 13), per member (losses are means over members)."""
    return sum((w * w).sum() for w in net.weights) / net.members


def multistep_loss(model, batch: WindowSet, w_v: torch.Tensor, w_F: torch.Tensor | None = None,
                   band: float = PAPER_FORCE_BAND):
    """(L_v, L_F) of Eqs. (15)-(17) as means over windows and steps: Euler rollouts of T steps
    from each window's first recorded state with its recorded inputs.

    `model` is a force model, or `PerMember` of a hybrid (then every FNN member rolls out
    the same windows and the losses are means over members too). L_F is 0 without `w_F`;
    `band` is the output constraint's share of |F_MMG| (Eq. 17).
    """
    states, inputs = batch.states, batch.inputs
    if isinstance(model, PerMember):
        k = model.model.correction_net.members
        states = states.unsqueeze(1).expand(states.shape[0], k, *states.shape[1:])
        inputs = inputs.unsqueeze(1).expand(inputs.shape[0], k, *inputs.shape[1:])
    if w_F is None:
        pred = integrate(model, states[0], inputs, batch.dt, Method.EULER)
    else:
        pred, f_nn, f_mmg = integrate_training(model, states[0], inputs, batch.dt)
    loss_v = velocity_loss(pred[1:, ..., VEL] - states[1:, ..., VEL], w_v)
    if w_F is None:
        return loss_v, loss_v.new_zeros(())
    return loss_v, output_penalty(f_nn, f_mmg, w_F, band).mean()


class Trainer:
    """Fits an MMG-only (optionally identified), NN-only or hybrid model to processed runs.

    Training runs on ``[training] device`` ("auto": CUDA when present, else CPU); the fitted
    ``model_`` stays there (``model_.cpu()`` for CPU evaluation).

    Parameters
    ----------
    experiment : validated experiment options.
    progress : show progress (tqdm bars on a terminal, a line every 10 epochs elsewhere).
    log : callable receiving one-line messages.
    checkpoint : file for the per-epoch training checkpoint (None: none written).
    resume : continue from `checkpoint` when it exists (same config required).
    on_epoch : called with an `EpochReport` after every epoch (and its checkpoint).
    """

    def __init__(self, experiment: Experiment, progress: bool = True, log: Callable[[str], None] = print,
                 checkpoint: str | os.PathLike | None = None, resume: bool = False,
                 on_epoch: Callable[[EpochReport], None] | None = None):
        self.experiment = experiment
        self.progress = progress
        self.log = log
        self.checkpoint = TrainingCheckpoint(checkpoint, experiment.to_toml()) if checkpoint else None
        self.resume = resume
        self.on_epoch = on_epoch
        self._validation_runs: list[Run] = []   # fit's validation logs

    # -- building blocks -------------------------------------------------------------
    def _l2(self, model) -> torch.Tensor:
        net = correction_of(model.model if isinstance(model, PerMember) else model)
        return weight_norm(net) if net is not None else torch.zeros(())

    def _optimize(self, model, params, train: WindowSet, val: WindowSet, w_v, w_F,
                  epochs: int, lr: float, label: str) -> StageResult:
        """Adam on the multi-step loss with early stopping; restores the best state.

        Stops on `patience` epochs without a better validation loss or at `epochs`; a
        checkpoint is written after every epoch, and a resumed stage continues from it.
        """
        t = self.experiment.training
        opt = adam(params, lr)
        # the learning rate falls by lr_factor after lr_patience epochs without a better
        # validation loss (lr_factor = 1: constant, the paper's Adam)
        sched = torch.optim.lr_scheduler.ReduceLROnPlateau(opt, factor=t.lr_factor, patience=t.lr_patience) \
            if t.lr_factor < 1.0 else None
        best, best_state, best_epoch, history = math.inf, None, 0, []
        gen = torch.Generator().manual_seed(self.experiment.experiment.seed + 1)
        first = 1
        resume = self._resume if self._resume and self._resume.stage == label else None
        if resume:
            model.load_state_dict(resume.model)
            opt.load_state_dict(resume.optimizer)
            if sched is not None:
                sched.load_state_dict(resume.scheduler)
            gen.set_state(resume.generator)
            best, best_epoch, best_state = resume.best_loss, resume.best_epoch, resume.best_state
            history, first = list(resume.stage_history), resume.epoch + 1
            self.log(f"{label}: resumed after epoch {resume.epoch} from {self.checkpoint.path}")
        stopped = "epoch limit"
        bar = self._bar(range(first, epochs + 1), label, epochs, first - 1)
        for epoch in bar:
            start = time.perf_counter()
            order = torch.randperm(len(train), generator=gen)
            sums = np.zeros(3)
            for lo in range(0, len(train), t.batch_size):
                batch = train.select(order[lo:lo + t.batch_size])
                loss_v, loss_F = multistep_loss(model, batch, w_v, w_F, t.force_band)
                loss = t.lambda_v * loss_v + t.lambda_F * loss_F + t.lambda_L2 * self._l2(model)
                if not torch.isfinite(loss):
                    raise TrainingError(f"{self.experiment.source}: [training] the {label} loss became "
                                        f"{loss.detach().item()} at epoch {epoch} (learning_rate = {lr:g}?); no run written")
                opt.zero_grad()
                loss.backward()
                opt.step()
                n = len(batch)
                sums += n * np.array([loss.item(), loss_v.item(), loss_F.item()])
            with torch.no_grad():
                val_v, _ = multistep_loss(model, val, w_v)
            sums /= len(train)
            row = {"stage": label, "epoch": epoch, "train_loss": float(sums[0]), "train_velocity": float(sums[1]),
                   "train_penalty": float(sums[2]), "early_stopping_loss": float(val_v), "seconds": time.perf_counter() - start}
            history.append(row)
            if float(val_v) < best:
                best, best_epoch = float(val_v), epoch
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            if sched is not None:
                sched.step(float(val_v))
            self._progress(bar, epoch, epochs, sums[1], float(val_v), best_epoch)
            if epoch - best_epoch >= t.patience:
                stopped = "early stop"
            elif time.perf_counter() > self._deadline:
                stopped = "time limit"
            if self.checkpoint is not None:
                self.checkpoint.save(CheckpointState(
                    stage=label, epoch=epoch, model=model.state_dict(), optimizer=opt.state_dict(),
                    scheduler=sched.state_dict() if sched is not None else {}, generator=gen.get_state(),
                    best_loss=best, best_epoch=best_epoch, best_state=best_state, stage_history=history,
                    history=self._history, summary=self._summary.to_dict()))
            if self.on_epoch is not None:
                self.on_epoch(EpochReport(label, epoch, epochs, float(sums[0]), float(val_v), best, best_epoch,
                                          self.checkpoint.path if self.checkpoint is not None else None))
            if stopped != "epoch limit":
                break
        if hasattr(bar, "close"):
            bar.close()
        return self._end_stage(model, label, StageResult(history, best_epoch, best, stopped), best_state)

    def _end_stage(self, model, label: str, stage: StageResult, best_state: dict | None) -> StageResult:
        """A stage's end: its best state restored into `model`, a hit time limit recorded as
        the run's failure, one log line; returns `stage`."""
        if best_state is not None:
            model.load_state_dict(best_state)
        if stage.stopped == "time limit":
            self._summary.failure = (f"wall-clock limit of {self.experiment.training.max_minutes:g} min "
                                     f"([training] max_minutes) hit in stage {label} at epoch {len(stage.history)}")
            self.log(f"FAILED: {self._summary.failure}")
        self.log(f"{label}: {len(stage.history)} epochs, best early-stopping loss {stage.best_loss:.5f} at epoch "
                 f"{stage.best_epoch} ({stage.stopped}; validation windows, before any kNN gate)")
        return stage

    def _bar(self, epochs, label: str, total: int, done: int):
        """tqdm on a terminal; elsewhere the epochs plain (progress then comes as log lines)."""
        if self.progress and sys.stderr.isatty():
            return tqdm(epochs, desc=label, unit="epoch", leave=False, total=total, initial=done)
        return epochs

    def _progress(self, bar, epoch: int, total: int, train_v: float, val_v: float, best_epoch: int) -> None:
        line = f"  epoch {epoch}/{total}: training {train_v:.5f}, early-stopping {val_v:.5f} (best at {best_epoch})"
        if hasattr(bar, "set_postfix"):
            bar.set_postfix(train=f"{train_v:.4f}", val=f"{val_v:.4f}", best=best_epoch)
        elif self.progress and (epoch % 10 == 0 or epoch == total):
            self.log(line)
        else:
            _LOG.debug(line.strip())  # every epoch with ``sysid -v``

    def disjoint_windows(self, runs: Sequence[Run], dtype, device) -> WindowSet:
        """Windows of T+1 samples of the training part that share no sample (slid by T+1):
        independent clusters for the sandwich sigma, and what least squares identifies on."""
        exp, t = self.experiment, self.experiment.training
        return split_windows(runs, t.steps, float(t.steps + 1) / exp.data.rate, t.val_fraction,
                             exp.data.exclude_suspect, dtype, t.block_s, exp.experiment.seed, device,
                             self._validation_runs)[0]

    def _log_uncertainty(self, result) -> dict:
        self.log("identified ± 2 sigma: " + ", ".join(
            f"{k} = {e:.4g} ± {2 * s:.2g}" + (" (undetermined)" if u else "")
            for k, e, s, u in zip(result.names, result.estimate, result.std_error, result.undetermined)))
        return result.as_dict()

    def uncertainty(self, model, runs: Sequence[Run], dtype, device, w_v) -> dict:
        """Stage 3b: standard errors and correlations of the identified coefficients from
        the multi-step residuals on disjoint windows of the training part, each window from
        its recorded start (`sysid.identify.uncertainty`)."""
        disjoint = self.disjoint_windows(runs, dtype, device)
        return self._log_uncertainty(coefficient_uncertainty(model, disjoint, list(self.experiment.identify.parameters),
                                                             w_v))

    def _gradient_estimator(self, stage: StageResult, joint: bool) -> dict:
        """What identified the coefficients with ``solver = "gradient"`` (for the summary)."""
        return {"solver": Solver.GRADIENT.value, "start_states": StartStates.RECORDED.value, "epochs": len(stage.history),
                "stage": "joint with the FNN" if joint else Stage.BEFORE.value, "integrator": Method.EULER.value,
                "covariance": "sandwich"}

    def _coefficients(self, mmg) -> dict[str, float]:
        return {k: float(getattr(mmg.coefficients, k).detach()) for k in self.experiment.identify.parameters}

    # -- stages ----------------------------------------------------------------------
    def split(self, runs: Sequence[Run], dtype, device) -> tuple[WindowSet, WindowSet, tuple, SplitReport]:
        """Stage 1: training and validation windows, training samples, the split report."""
        exp, t = self.experiment, self.experiment.training
        train, val, samples, report = split_windows(runs, t.steps, t.stride_s, t.val_fraction,
                                                    exp.data.exclude_suspect, dtype, t.block_s,
                                                    exp.experiment.seed, device, self._validation_runs)
        for name in report.dropped_copies:
            self.log(f"left out {name}: an exact copy of the start of another training file")
        self.log(f"{len(train)} training and {len(val)} validation windows of {t.steps} steps "
                 f"({report.suspect_windows} touching frozen GNSS left out)")
        return train, val, samples, report

    def identify(self, mmg, train: WindowSet, val: WindowSet, w_v) -> StageResult:
        """Stage 3 (``[identify]``, stage "before" or MMG-only): gradient identification of
        the MMG coefficients on the multi-step loss."""
        ident = self.experiment.identify
        result = self._optimize(mmg, list(mmg.parameters()), train, val, w_v, None,
                                ident.epochs, ident.learning_rate, "identify")
        self._log_identified(mmg)
        return result

    def _log_identified(self, mmg) -> None:
        self.log("identified: " + ", ".join(f"{k} = {v:.5g}" for k, v in self._coefficients(mmg).items()))

    def identify_least_squares(self, mmg, runs: Sequence[Run], train: WindowSet, val: WindowSet, w_v,
                               device) -> tuple[StageResult, dict, dict]:
        """Stage 3 with ``[identify] solver = "levenberg_marquardt"``: least squares on the
        disjoint windows of the training part in float64, Euler as in training, start states
        and prior as configured (`sysid.identify.levenberg_marquardt`), then the sigma of that
        estimator. Sets the MMG's coefficients; returns the stage (one history row: the
        identified MMG's multi-step loss on the training and validation windows), the sigma
        (`CoefficientUncertainty.as_dict`) and what the estimator was."""
        ident = self.experiment.identify
        names = list(ident.parameters)
        started = time.perf_counter()
        windows = self.disjoint_windows(runs, torch.float64, device)
        model = build_mmg(self.experiment, torch.float64).to(device)   # float64: identification's precision
        prior = self._coefficients(model)
        weights = w_v.to(torch.float64)
        fit = identify_levenberg_marquardt(model, windows, names, weights, Method.EULER, ident.start_states, prior,
                                           ident.prior_weight, ident.iterations)
        model.coefficients.assign(fit.coefficients)
        result = fit_uncertainty(model, windows, names, fit, weights, Method.EULER, prior=prior,
                                 prior_weight=ident.prior_weight)
        check = start_state_check(build_mmg(self.experiment, torch.float64).to(device), windows, names, fit,
                                  result.std_error, weights, Method.EULER, prior, ident.prior_weight, ident.iterations)
        with torch.no_grad():
            mmg.coefficients.assign(check.coefficients)
            check_val = float(multistep_loss(mmg, val, w_v)[0])
            mmg.coefficients.assign(fit.coefficients)
            train_v, val_v = (float(multistep_loss(mmg, w, w_v)[0]) for w in (train, val))
        self.log(f"identify: Levenberg-Marquardt, start states {ident.start_states}, {len(windows)} disjoint "
                 f"windows, {fit.iterations} iterations ({fit.stopped}); multi-step loss training "
                 f"{train_v:.5f}, validation {val_v:.5f}")
        self._log_identified(mmg)
        self._log_start_state_check(check, val_v, check_val)
        row = {"stage": "identify", "epoch": fit.iterations, "train_loss": train_v, "train_velocity": train_v,
               "train_penalty": 0.0, "early_stopping_loss": val_v, "seconds": time.perf_counter() - started}
        estimator = {"solver": Solver.LEVENBERG_MARQUARDT.value, "start_states": ident.start_states.value,
                     "prior_weight": ident.prior_weight, "iterations": fit.iterations, "windows": len(windows),
                     "integrator": Method.EULER.value, "covariance": result.method,
                     "start_state_check": {**check.as_dict(), "val_loss_multistep": check_val}}
        return (StageResult([row], fit.iterations, val_v, fit.stopped), self._log_uncertainty(result), estimator)

    def _log_start_state_check(self, check, val_v: float, check_val: float) -> None:
        said = (f"check: {check.verdict()}; validation loss {check_val:.5f} "
                f"(start states {check.start_states}) against {val_v:.5f}")
        self.log(said if check.agrees else "WARNING " + said)

    def standardize(self, model: CorrectedModel, train: WindowSet) -> torch.Tensor:
        """Stage 2: FNN input statistics and output statistics of the implied residual force;
        returns the correction inputs s and the residual (N, 3) for the warm start."""
        net = model.correction_net
        stride = max(1, int(round(self.experiment.training.stride_s / train.dt)))
        s, residual, _ = implied_residual(model, train, stride)
        net.set_standardization(s.mean(0), s.std(0), residual.mean(0), residual.std(0))
        return s, residual

    def warm_start(self, net: ForceCorrection, s: torch.Tensor, residual: torch.Tensor, device) -> None:
        """Stage 4: every FNN member regresses the standardised residual force (one step)."""
        t = self.experiment.training
        target = (residual - net.output_mean) / net.output_std
        z = net.standardize_inputs(s).expand(net.members, *s.shape)  # (K, N, 9), fixed over the warm start
        opt = adam(net.parameters(), 3e-3)
        gen = torch.Generator().manual_seed(self.experiment.experiment.seed + 2)
        bar = self._bar(range(t.warm_start_epochs), "warm start", t.warm_start_epochs, 0)
        if not hasattr(bar, "set_postfix"):
            self.log(f"warm start: {t.warm_start_epochs} epochs of one-step regression on {len(s)} samples")
        for epoch in bar:
            order = torch.randperm(len(s), generator=gen).to(device)
            for lo in range(0, len(s), 256):
                idx = order[lo:lo + 256]
                y = net.layers(z[:, idx])[0]
                loss = ((y - target[idx]) ** 2).mean() + t.lambda_L2 * weight_norm(net)
                opt.zero_grad()
                loss.backward()
                opt.step()
            if not torch.isfinite(loss):
                raise TrainingError(f"{self.experiment.source}: [training] the warm-start loss became "
                                    f"{loss.detach().item()}; no run written")
            shown = self.progress and ((epoch + 1) % 25 == 0 or epoch + 1 == t.warm_start_epochs)
            if not hasattr(bar, "set_postfix") and (shown or _LOG.isEnabledFor(logging.DEBUG)):
                line = f"  warm start epoch {epoch + 1}/{t.warm_start_epochs}: loss {loss.item():.5f}"
                self.log(line) if shown else _LOG.debug(line.strip())  # every epoch with ``sysid -v``

    def train(self, model: CorrectedModel, params, train: WindowSet, val: WindowSet, w_v, w_F) -> StageResult:
        """Stage 5: multi-step training of every FNN member (and joint MMG coefficients)."""
        t = self.experiment.training
        return self._optimize(PerMember(model), params, train, val, w_v, w_F, t.epochs, t.learning_rate, "train")

    def fit_gate(self, model: CorrectedModel, samples: tuple[torch.Tensor, torch.Tensor], dtype) -> dict:
        """Stage 6: the kNN gate on the training samples' features (or standardised inputs)."""
        gate = self.experiment.gate
        with torch.no_grad():
            states, inputs = samples
            rel = model.mmg(states, inputs).relative_wind
            z = model.gate_coordinates(correction_inputs(states, inputs, rel))
        model.gate = KNNGate(gate.k, gate.alpha, z.shape[-1], dtype).fit(z)
        model.gate_enabled = True
        self.log(f"kNN gate: {z.shape[0]} training features, threshold {float(model.gate.threshold):.4f}")
        return {"k": gate.k, "alpha": gate.alpha, "space": gate.space, "bank": int(z.shape[0]),
                "threshold": float(model.gate.threshold)}

    def objective(self, model, runs: Sequence[Run], val: WindowSet, w_v, dtype, device) -> float:
        """The run's validation loss ``val_loss_multistep`` (`VAL_LOSS_DEFINITION`): L_v of the
        final model (gate included) on validation windows of each of its horizons
        (`objective_horizons`), averaged over the horizons the validation data hold a window
        of; T steps when they hold none. The windows are kept per horizon as
        ``validation_sets_`` (the first as ``validation_windows_``)."""
        exp, t = self.experiment, self.experiment.training
        sets: dict[float, WindowSet] = {}
        for horizon in objective_horizons(exp):
            # objective_s: that many seconds of steps; an evaluation horizon: windows of as many
            # samples as the test windows (H = h / dt points, first included)
            steps = max(1, int(round(horizon / val.dt)) - (0 if t.objective_s > 0 else 1))
            if not self._validation_runs and int(round(t.block_s / val.dt)) < steps + 1:
                self.log(f"val_loss_multistep: no validation window of {horizon:g} s fits a {t.block_s:g}-s "
                         "validation block; that horizon is left out")
                continue
            try:
                windows = split_windows(runs, steps, t.stride_s, t.val_fraction, exp.data.exclude_suspect, dtype,
                                        t.block_s, exp.experiment.seed, device, self._validation_runs)[1]
            except DataError:   # none that long
                windows = None
            if windows is not None and len(windows):
                sets[horizon] = windows
            else:
                self.log(f"val_loss_multistep: no validation window of {horizon:g} s (the validation blocks or "
                         "logs are shorter); that horizon is left out")
        if not sets:
            sets[round(t.steps * val.dt, 6)] = val
        self.validation_sets_ = sets
        self.validation_windows_ = next(iter(sets.values()))
        return float(np.mean([float(velocity_loss(rollout_errors(model, w), w_v)) for w in sets.values()]))

    # -- the estimator ---------------------------------------------------------------
    def fit(self, runs: Sequence[Run], validation: Sequence[Run] = ()) -> "Trainer":
        """Fit to the training logs `runs`; validation windows from `validation` logs when
        given, else from logs of `runs` held out whole (``[training] validation = "files"``,
        `sysid.data.splits.hold_out_files`), else from the validation blocks of `runs`.
        Sets ``model_``, ``history_``,
        ``summary_``, ``validation_windows_`` (the windows of ``val_loss_multistep``) and
        ``velocity_weights_`` (w_v (3,), 1 / variance of u, v_m, r in the training windows)."""
        prepared = self.prepare(runs, validation)
        stage = None
        if prepared.trains:
            stage = self.train(prepared.model, prepared.params, prepared.train, prepared.val, prepared.w_v,
                               prepared.w_F)
        return self.finish(prepared, stage)

    def prepare(self, runs: Sequence[Run], validation: Sequence[Run] = ()) -> "Prepared":
        """Stages 1-4 of `fit` (split, identification before training, standardisation, warm
        start, or their results from a checkpoint of the training stage): what stage 5 and
        `finish` need. `sysid.identify.side_by_side` trains several seeds' stage 5 at once."""
        exp = self.experiment
        if not validation and (held_out := held_out_validation(exp, runs)) is not None:
            runs, validation = held_out.train, held_out.validation
        self._validation_runs = list(validation)
        t, kind = exp.training, exp.experiment.model
        seed_everything(exp.experiment.seed)
        dtype = torch.float32 if t.dtype is DType.FLOAT32 else torch.float64
        device = resolve_device(t.device)
        started = time.perf_counter()
        self._deadline = started + 60.0 * t.max_minutes if t.max_minutes > 0 else math.inf
        self._resume = self.checkpoint.load() if self.checkpoint is not None and self.resume else None
        train, val, samples, report = self.split(runs, dtype, device)
        if kind is not ModelKind.MMG and exp.gate.enabled and exp.gate.k > len(samples[0]):
            raise ConfigError(f"{exp.source or 'experiment'}: [gate] k = {exp.gate.k}: more neighbours than "
                              f"the {len(samples[0])} training samples the gate's bank holds")
        # velocity weights w_v: inverse variance of the recorded velocities
        w_v = 1.0 / train.states[:, :, VEL].reshape(-1, 3).var(0)
        identify = bool(exp.identify.parameters)
        joint = exp.identify.stage is Stage.JOINT
        mmg = build_mmg(exp, dtype).to(device)
        summary = TrainingSummary(len(train), len(val), report, str(device))
        self._summary, self._history = summary, []
        resumed_in = self._resume.stage if self._resume else None
        if resumed_in == "train":  # earlier stages are done: their results come from the checkpoint
            summary = self._summary = TrainingSummary.from_dict(self._resume.summary)
            self._history = list(self._resume.history)
        if identify and not summary.identified_initial:
            summary.identified_initial = self._coefficients(mmg)
        if identify and (kind is ModelKind.MMG or not joint) and resumed_in != "train":
            if exp.identify.solver is Solver.LEVENBERG_MARQUARDT:
                stage, uncertainty, estimator = self.identify_least_squares(mmg, runs, train, val, w_v, device)
            else:
                stage = self.identify(mmg, train, val, w_v)
                uncertainty = self.uncertainty(mmg, runs, dtype, device, w_v)
                estimator = self._gradient_estimator(stage, joint=False)
            self._history += stage.history
            summary.stopped["identify"] = stage.stopped
            summary.best_epoch = stage.best_epoch  # the training stage's, if one follows
            summary.identified = self._coefficients(mmg)
            summary.identified_uncertainty, summary.identification = uncertainty, estimator
        if identify and not joint:
            mmg.requires_grad_(False)
        prepared = Prepared(runs, dtype, device, started, train, val, samples, w_v, mmg)
        if kind is not ModelKind.MMG and summary.failure is None:
            net = ForceCorrection(exp.network.hidden, dtype, exp.network.members).to(device)
            model = CorrectedModel(mmg, net, None, physics=(kind is ModelKind.HYBRID), gate_space=exp.gate.space)
            if resumed_in != "train":
                with torch.no_grad():
                    summary.mmg_val_loss = float(multistep_loss(mmg, val, w_v)[0])
                    summary.mmg_train_loss = float(multistep_loss(mmg, train, w_v)[0])
                self.log(f"MMG-only multi-step loss: training {summary.mmg_train_loss:.5f}, "
                         f"validation {summary.mmg_val_loss:.5f}")
                s, residual = self.standardize(model, train)
                summary.residual_force_mean = residual.mean(0).tolist()
                summary.residual_force_std = residual.std(0).tolist()
                if t.warm_start_epochs:
                    self.warm_start(net, s, residual, device)
                with torch.no_grad():
                    summary.warm_val_loss = float(multistep_loss(PerMember(model), val, w_v)[0])
                self.log(f"after warm start: validation loss {summary.warm_val_loss:.5f}")
            prepared.params = list(net.parameters()) + (list(mmg.parameters()) if identify and joint else [])
            if resumed_in == "train":  # buffers (standardisation) first: w_F depends on them
                PerMember(model).load_state_dict(self._resume.model)
            prepared.model = model
            prepared.w_F = 1.0 / net.output_std if kind is ModelKind.HYBRID else None
        return prepared

    def finish(self, prepared: "Prepared", stage: StageResult | None) -> "Trainer":
        """Stage 6 and the run's validation loss after the training stage `stage` (None: no
        training stage, MMG-only or a failure before it); returns self, fitted."""
        exp, t = self.experiment, self.experiment.training
        model = prepared.model if prepared.model is not None else prepared.mmg
        summary, val, w_v = self._summary, prepared.val, prepared.w_v
        identify, joint = bool(exp.identify.parameters), exp.identify.stage is Stage.JOINT
        stopping_best = None
        if stage is not None and prepared.model is not None:
            net = prepared.model.correction_net
            stopping_best = stage.best_loss if exp.gate.enabled else None
            self._history += stage.history
            summary.stopped["train"] = stage.stopped
            summary.best_epoch = stage.best_epoch
            with torch.no_grad():
                summary.ensemble_val_loss = float(multistep_loss(model, val, w_v)[0])
            if net.members > 1:
                self.log(f"mean of {net.members} networks: validation loss {summary.ensemble_val_loss:.5f}")
            if identify and joint:
                summary.identified = self._coefficients(prepared.mmg)
                summary.identified_uncertainty = self.uncertainty(model, prepared.runs, prepared.dtype,
                                                                  prepared.device, w_v)
                summary.identification = self._gradient_estimator(stage, joint=True)
            if exp.gate.enabled:
                summary.gate = self.fit_gate(model, prepared.samples, prepared.dtype)
        self.velocity_weights_ = w_v
        self.validation_windows_ = val
        self.validation_sets_ = {round(t.steps * val.dt, 6): val}
        if summary.failure is None:
            summary.val_loss_multistep = self.objective(model, prepared.runs, val, w_v, prepared.dtype,
                                                        prepared.device)
            judged = " and ".join(f"{len(w)} of {h:g} s" for h, w in self.validation_sets_.items())
            self.log(f"val_loss_multistep {summary.val_loss_multistep:.5f}: the final model"
                     + (" (kNN gate on)" if summary.gate else "") + f" on validation windows: {judged}"
                     + (f"; the early-stopping loss {stopping_best:.5f} is the network's during training, "
                        "before the gate" if stopping_best is not None else ""))
        self.history_ = pd.DataFrame(self._history)
        summary.epochs = int(self.history_["epoch"].max()) if len(self._history) else 0
        summary.train_seconds = time.perf_counter() - prepared.started
        self.model_, self.summary_ = model, summary
        return self


@dataclass
class Prepared:
    """What `Trainer.prepare` leaves for the training stage and `Trainer.finish`: the training
    logs `runs` (held-out validation logs removed), dtype, device, the start time
    (``time.perf_counter``), the windows, the training samples, w_v (3,), the MMG, and for a
    learned model still to train (``trains``): the model, the trained parameters and w_F (3,)
    (None: NN-only)."""

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

    @property
    def trains(self) -> bool:
        return self.model is not None
