"""Training checkpoints: the whole training state at the end of an epoch, so that an
interrupted training continues to the same final model as an uninterrupted one.

Written atomically (temporary file, then rename) with plain tensors, numbers and strings
only, so that ``torch.load(..., weights_only=True)`` reads it.
"""
from __future__ import annotations

import enum
import os
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


class TrainingCheckpoint:
    """One file holding the state of the running training stage.

    Keys: ``version``, ``config`` (the resolved experiment TOML it belongs to), ``stage``
    ("identify" | "train"), ``epoch`` (last finished), ``model``, ``optimizer``,
    ``generator`` (minibatch order), ``best_loss``, ``best_epoch``, ``best_state``,
    ``stage_history``, ``history`` (earlier stages), ``summary`` (`TrainingSummary` so far).
    """

    def __init__(self, path: str | os.PathLike, config: str):
        self.path = Path(path)
        self.config = config

    def save(self, **state) -> None:
        with atomic_path(self.path, ".pt") as tmp:
            torch.save(plain({"version": VERSION, "config": self.config, **state}), tmp)

    def load(self) -> dict | None:
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
        return state

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)
