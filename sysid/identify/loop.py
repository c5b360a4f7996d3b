"""The training loop of a gradient stage: epochs of minibatch steps on the multi-step loss,
early stopping on the validation velocity loss, the learning-rate schedule, the wall-clock
limit and the best weights restored.

The loop is composed of its parts: the minibatch `GradientStep` (Adam on the multi-step
loss; a fused or compiled step takes its place with the same call), the checkpointing part
(`sysid.identify.checkpoint.Checkpointing`, a state after every epoch and the state a stage
resumes from), the logging part (`sysid.identify.journal.TrainingJournal`) and the caller's
``on_epoch``. The loop calls them; the identification strategies and the models do no I/O.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from sysid.config.experiment import Experiment
from sysid.dynamics.rollouts import WindowSet
from sysid.errors import TrainingError
from sysid.identify.adam import Adam
from sysid.identify.checkpoint import CheckpointState, Checkpointing
from sysid.identify.journal import TrainingJournal
from sysid.identify.losses import adam, step_loss, validation_loss
from sysid.identify.plateau import Plateau


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
class RunProgress:
    """The run so far, as a checkpoint saves it: the history rows of finished stages and the
    trainer's summary (a `sysid.identify.trainer.TrainingSummary`)."""

    history: list[dict]
    summary: Any


@dataclass(eq=False)
class StageState:
    """A running stage: its optimizer, schedule (None: a constant rate), minibatch generator,
    last finished epoch, early-stopping record, history rows and why it stopped (None: it
    goes on)."""

    optimizer: Adam
    scheduler: Plateau | None
    generator: torch.Generator
    epoch: int = 0
    best: float = math.inf
    best_epoch: int = 0
    best_state: dict | None = None
    history: list = field(default_factory=list)
    stopped: str | None = None


class GradientStep:
    """One minibatch update of a gradient stage: lambda_v L_v + lambda_F L_F + lambda_L2
    |theta|^2 (Eqs. 13-17), its gradient, the optimizer's step. Returns the three losses;
    a non-finite loss is a `TrainingError` naming the stage and epoch."""

    def __init__(self, experiment: Experiment):
        self.training, self.source = experiment.training, experiment.source

    def __call__(self, model, batch: WindowSet, w_v, w_F, optimizer, label: str, epoch: int, lr: float):
        loss, loss_v, loss_F = step_loss(model, batch, w_v, w_F, self.training)
        if not math.isfinite(loss.item()):
            raise TrainingError(f"{self.source}: [training] the {label} loss became "
                                f"{loss.detach().item()} at epoch {epoch} (learning_rate = {lr:g}?); no run written")
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        return loss, loss_v, loss_F


class TrainingLoop:
    """Adam on the multi-step loss with early stopping, per stage (`run`); `start`,
    `end_epoch` and `end_stage` are its bookkeeping, shared with seeds side by side
    (`sysid.identify.side_by_side`).

    experiment : the options (``[training]``: batch, losses, patience, schedule).
    checkpointing, journal : the checkpointing and logging parts.
    run : the run so far (saved in every checkpoint; a hit time limit is its failure).
    deadline : ``time.perf_counter()`` beyond which a stage stops ("time limit").
    on_epoch : receives an `EpochReport` after every epoch's checkpoint.
    step : the minibatch update (default `GradientStep`).
    """

    def __init__(self, experiment: Experiment, checkpointing: Checkpointing, journal: TrainingJournal,
                 run: RunProgress, deadline: float = math.inf,
                 on_epoch: Callable[[EpochReport], None] | None = None, step: GradientStep | None = None):
        self.experiment, self.checkpointing, self.journal = experiment, checkpointing, journal
        self.run_progress, self.deadline, self.on_epoch = run, deadline, on_epoch
        self.step = step if step is not None else GradientStep(experiment)

    def start(self, model, params, lr: float, label: str) -> StageState:
        """A stage's optimizer, schedule and generator, continued from the checkpoint when
        the fit resumes inside this stage."""
        t = self.experiment.training
        opt = adam(params, lr)
        # the learning rate falls by lr_factor after lr_patience epochs without a better
        # validation loss (lr_factor = 1: constant, the paper's Adam)
        sched = Plateau(opt, t.lr_factor, t.lr_patience) if t.lr_factor < 1.0 else None
        state = StageState(opt, sched, torch.Generator().manual_seed(self.experiment.experiment.seed + 1))
        resume = self.checkpointing.stage(label)
        if resume:
            model.load_state_dict(resume.model)
            opt.load_state_dict(resume.optimizer)
            if sched is not None:
                sched.load_state_dict(resume.scheduler)
            state.generator.set_state(resume.generator)
            state.best, state.best_epoch, state.best_state = resume.best_loss, resume.best_epoch, resume.best_state
            state.history, state.epoch = list(resume.stage_history), resume.epoch
            self.journal.resumed(label, resume.epoch, self.checkpointing.path)
        return state

    def run(self, model, params, train: WindowSet, val: WindowSet, w_v, w_F, epochs: int, lr: float,
            label: str) -> StageResult:
        """Stage `label`: epochs of minibatches of `train` until `patience` epochs without a
        better validation loss, `epochs`, or the deadline; the best state restored."""
        t = self.experiment.training
        state = self.start(model, params, lr, label)
        bar = self.journal.epochs(range(state.epoch + 1, epochs + 1), label, epochs, state.epoch)
        for epoch in bar:
            started = time.perf_counter()
            order = torch.randperm(len(train), generator=state.generator)
            sums = np.zeros(3)
            for lo in range(0, len(train), t.batch_size):
                batch = train.select(order[lo:lo + t.batch_size])
                losses = self.step(model, batch, w_v, w_F, state.optimizer, label, epoch, lr)
                sums += len(batch) * np.array([loss.item() for loss in losses])
            val_v = validation_loss(model, val, w_v)
            state.epoch = epoch
            self.end_epoch(state, model, label, epochs, sums / len(train), float(val_v),
                           time.perf_counter() - started, bar)
            if state.stopped is not None:
                break
        if hasattr(bar, "close"):
            bar.close()
        return self.end_stage(model, label, state)

    def end_epoch(self, state: StageState, model, label: str, epochs: int, sums: np.ndarray, val_v: float,
                  seconds: float, bar=()) -> None:
        """After epoch ``state.epoch``: its history row (mean training losses `sums`: total,
        L_v, L_F), the best state, the schedule, progress, stopping, checkpoint, `EpochReport`."""
        t = self.experiment.training
        epoch = state.epoch
        state.history.append({"stage": label, "epoch": epoch, "train_loss": float(sums[0]),
                              "train_velocity": float(sums[1]), "train_penalty": float(sums[2]),
                              "early_stopping_loss": val_v, "seconds": seconds})
        if val_v < state.best:
            state.best, state.best_epoch = val_v, epoch
            state.best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        if state.scheduler is not None:
            state.scheduler.step(val_v)
        self.journal.epoch(bar, epoch, epochs, sums[1], val_v, state.best_epoch)
        if epoch - state.best_epoch >= t.patience:
            state.stopped = "early stop"
        elif time.perf_counter() > self.deadline:
            state.stopped = "time limit"
        self.checkpointing.save(CheckpointState(
            stage=label, epoch=epoch, model=model.state_dict(), optimizer=state.optimizer.state_dict(),
            scheduler=state.scheduler.state_dict() if state.scheduler is not None else {},
            generator=state.generator.get_state(), best_loss=state.best, best_epoch=state.best_epoch,
            best_state=state.best_state, stage_history=state.history, history=self.run_progress.history,
            summary=self.run_progress.summary.to_dict()))
        if self.on_epoch is not None:
            self.on_epoch(EpochReport(label, epoch, epochs, float(sums[0]), val_v, state.best, state.best_epoch,
                                      self.checkpointing.path))

    def end_stage(self, model, label: str, state: StageState) -> StageResult:
        """A stage's end: its best state restored into `model`, a hit time limit recorded as
        the run's failure, the journal's lines; its `StageResult`."""
        stage = StageResult(state.history, state.best_epoch, state.best, state.stopped or "epoch limit")
        if state.best_state is not None:
            model.load_state_dict(state.best_state)
        failure = None
        if stage.stopped == "time limit":
            failure = (f"wall-clock limit of {self.experiment.training.max_minutes:g} min "
                       f"([training] max_minutes) hit in stage {label} at epoch {len(stage.history)}")
            self.run_progress.summary.failure = failure
        self.journal.stage_end(label, stage, failure)
        return stage
