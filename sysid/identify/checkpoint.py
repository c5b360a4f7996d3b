"""Training checkpoints: the whole training state at the end of an epoch, so that an
interrupted training continues to the same final model as an uninterrupted one.

Written atomically (temporary file, then rename) with plain tensors, numbers and strings
only, so that ``torch.load(..., weights_only=True)`` reads it.
"""
from __future__ import annotations

import enum
import os
from dataclasses import dataclass, fields
from pathlib import Path

import torch

from sysid.errors import CheckpointError
from sysid.store.files import atomic_path

VERSION = 1


def plain(value):
    """`value` with numpy scalars turned into Python numbers and enum members into their
    values (weights_only-safe)."""
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, torch.Tensor):
        return value.item()
    return value


STAGES = ("identify", "train")


@dataclass(frozen=True)
class CheckpointState:
    """The state of a training stage at the end of an epoch, all that a resumed stage needs
    to continue to the model an uninterrupted one gives.

    stage : "identify" | "train"; epoch : the last finished one (from 1);
    model, optimizer : state dicts; scheduler : the learning-rate schedule's ({} without);
    generator : the minibatch order's random state (uint8 tensor);
    best_loss, best_epoch, best_state : the best validation loss so far, its epoch and its
    weights (None before the first epoch improved on inf);
    stage_history : this stage's history rows; history : the rows of earlier stages;
    summary : the trainer's `TrainingSummary.to_dict()` so far.
    """

    stage: str
    epoch: int
    model: dict
    optimizer: dict
    scheduler: dict
    generator: torch.Tensor
    best_loss: float
    best_epoch: int
    best_state: dict | None
    stage_history: list
    history: list
    summary: dict

    def to_state_dict(self) -> dict:
        """The checkpoint's keys after ``version`` and ``config``, in this order."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_state_dict(cls, state: dict, source: str | os.PathLike) -> "CheckpointState":
        """The state in `state` (read from the file `source`); one `CheckpointError` line
        naming the file and the key when one is missing or of the wrong kind."""
        kinds = {"stage": str, "epoch": int, "model": dict, "optimizer": dict, "scheduler": dict,
                 "generator": torch.Tensor, "best_loss": (int, float), "best_epoch": int,
                 "best_state": (dict, type(None)), "stage_history": list, "history": list, "summary": dict}
        for f in fields(cls):
            if f.name not in state:
                raise CheckpointError(f"{source}: training checkpoint has no {f.name!r}; delete it to start afresh")
            if not isinstance(state[f.name], kinds[f.name]) or isinstance(state[f.name], bool):
                raise CheckpointError(f"{source}: training checkpoint's {f.name!r} is a "
                                      f"{type(state[f.name]).__name__}; delete it to start afresh")
        if state["stage"] not in STAGES:
            raise CheckpointError(f"{source}: training checkpoint of unknown stage {state['stage']!r} "
                                  f"(expected one of {', '.join(STAGES)}); delete it to start afresh")
        return cls(**{f.name: state[f.name] for f in fields(cls)})


class TrainingCheckpoint:
    """One file holding the `CheckpointState` of the running training stage, with
    ``version`` and ``config`` (the resolved experiment TOML it belongs to) before it."""

    def __init__(self, path: str | os.PathLike, config: str):
        self.path = Path(path)
        self.config = config

    def save(self, state: CheckpointState) -> None:
        with atomic_path(self.path, ".pt") as tmp:
            torch.save(plain({"version": VERSION, "config": self.config, **state.to_state_dict()}), tmp)

    def load(self) -> CheckpointState | None:
        """The saved state, None when there is none; refuses another config's checkpoint."""
        if not self.path.is_file():
            return None
        try:
            state = torch.load(self.path, map_location="cpu", weights_only=True)
        except Exception as exc:  # truncated or not a checkpoint
            raise CheckpointError(f"{self.path}: not a readable training checkpoint "
                                  f"({type(exc).__name__}); delete it to start afresh") from None
        if not isinstance(state, dict) or state.get("version") != VERSION:
            raise CheckpointError(f"{self.path}: not a sysid training checkpoint (version "
                                  f"{state.get('version') if isinstance(state, dict) else '?'})")
        if state.get("config") != self.config:
            raise CheckpointError(f"{self.path}: made with another config; delete it or train without --resume")
        return CheckpointState.from_state_dict(state, self.path)

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


class Checkpointing:
    """The checkpointing part of training: the state a fit resumes from (read once by
    `start`) and the `CheckpointState` written after every epoch; none of either without
    a file."""

    def __init__(self, path: str | os.PathLike | None, config: str, resume: bool = False):
        self.file = TrainingCheckpoint(path, config) if path else None
        self.resume = resume
        self.resumed: CheckpointState | None = None

    @property
    def path(self) -> Path | None:
        return self.file.path if self.file is not None else None

    def start(self) -> CheckpointState | None:
        """The saved state to resume from (None: none, or not resuming)."""
        self.resumed = self.file.load() if self.file is not None and self.resume else None
        return self.resumed

    def stage(self, label: str) -> CheckpointState | None:
        """The saved state of stage `label`, when the fit resumes inside it."""
        return self.resumed if self.resumed is not None and self.resumed.stage == label else None

    def save(self, state: CheckpointState) -> None:
        if self.file is not None:
            self.file.save(state)
