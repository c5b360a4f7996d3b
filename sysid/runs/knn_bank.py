"""knn.pt of a run directory: the stored bank of the hybrid's kNN gate (`KnnBank`),
checked against its contract when it is read."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import torch

from sysid.errors import CheckpointError
from sysid.hybrid.knn_gate import KNNGate
from sysid.runs.tensor_files import check_finite, load_tensors, save_tensors

AGAIN = "train the run again"


@dataclass(frozen=True)
class KnnBank:
    """The kNN gate's stored state (paper Eqs. 18-21).

    bank : (N, F) the gate's training vectors (FNN features or standardised inputs), N >= 1;
    threshold : () delta_kNN, the alpha-quantile of the training distances;
    k : neighbours averaged, 1 <= k <= N; alpha : 0 < alpha < 1;
    train_distances : (N,) leave-one-out kNN distance of every bank vector (None when the
    file has none: the gate does not need them to predict).
    All finite.
    """

    bank: torch.Tensor
    threshold: torch.Tensor
    k: int
    alpha: float
    train_distances: torch.Tensor | None = None

    @classmethod
    def of(cls, gate: KNNGate) -> "KnnBank":
        """The bank of a fitted gate (CPU tensors)."""
        return cls(gate.bank.detach().cpu(), gate.threshold.detach().cpu(), gate.k, gate.alpha,
                   gate.train_distances.detach().cpu())

    def gate(self, dtype: torch.dtype = torch.float64) -> KNNGate:
        """A `KNNGate` holding this bank, in `dtype`."""
        gate = KNNGate(self.k, self.alpha, self.bank.shape[1], dtype)
        gate.bank, gate.threshold = self.bank.to(dtype), self.threshold.to(dtype)
        if self.train_distances is not None:
            gate.train_distances = self.train_distances.to(dtype)
        return gate

    def to_state_dict(self) -> dict:
        """knn.pt's content: {"bank", "threshold", "train_distances", "k", "alpha"} as tensors."""
        state = {"bank": self.bank, "threshold": self.threshold}
        if self.train_distances is not None:
            state["train_distances"] = self.train_distances
        return {**state, "k": torch.tensor(self.k), "alpha": torch.tensor(self.alpha, dtype=torch.float64)}

    @classmethod
    def from_state_dict(cls, state, source: str | os.PathLike, width: int | None = None) -> "KnnBank":
        """The bank in `state` (read from the file `source`), checked: one `CheckpointError`
        line naming the file, the field and the fix when it breaks the contract. `width`: the
        F of the model's gate vectors, when known (a transposed bank is refused)."""
        where = Path(source)
        if not isinstance(state, dict):
            raise CheckpointError(f"{where}: not a kNN bank (expected a dict of bank, threshold, k, alpha); {AGAIN}")
        for key in ("bank", "threshold", "k", "alpha"):
            if key not in state:
                raise CheckpointError(f"{where}: kNN bank has no {key!r}; {AGAIN}")
        for key in ("bank", "threshold", "train_distances"):
            value = state.get(key)
            if key in state and not (isinstance(value, torch.Tensor) and value.is_floating_point()):
                raise CheckpointError(f"{where}: {key} is not a tensor of real numbers; {AGAIN}")
        bank, threshold, distances = state["bank"], state["threshold"], state.get("train_distances")
        if bank.dim() != 2:
            raise CheckpointError(f"{where}: bank has shape {tuple(bank.shape)}, expected (N, F): one row per "
                                  f"training vector; {AGAIN}")
        n, f = bank.shape
        if n == 0 or f == 0:
            raise CheckpointError(f"{where}: bank is empty ({n} x {f}): the gate has nothing to compare with; {AGAIN}")
        transposed = (width is not None and f != width and n == width) or \
                     (distances is not None and distances.dim() == 1 and len(distances) == f != n)
        if transposed:
            raise CheckpointError(f"{where}: bank has shape ({n}, {f}), transposed: expected one row per training "
                                  f"vector, ({f}, {n}); write it as (N, F) or {AGAIN}")
        if width is not None and f != width:
            raise CheckpointError(f"{where}: bank vectors have {f} coordinates, the model's gate compares {width}; "
                                  f"the bank belongs to another model: {AGAIN}")
        if distances is not None and tuple(distances.shape) != (n,):
            raise CheckpointError(f"{where}: train_distances has shape {tuple(distances.shape)}, expected ({n},) "
                                  f"like the bank's rows; {AGAIN}")
        if threshold.numel() != 1:
            raise CheckpointError(f"{where}: threshold has shape {tuple(threshold.shape)}, expected a scalar; {AGAIN}")
        k, alpha = _scalar(state["k"], where, "k"), _scalar(state["alpha"], where, "alpha")
        if k != int(k) or not 1 <= k <= n:
            raise CheckpointError(f"{where}: k = {k:g} must be a whole number from 1 to the bank's {n} rows; {AGAIN}")
        if not 0.0 < alpha < 1.0:
            raise CheckpointError(f"{where}: alpha = {alpha:g} must lie in (0, 1); {AGAIN}")
        check_finite({"bank": bank, "threshold": threshold, **({"train_distances": distances} if distances is not None
                                                                 else {})}, where)
        return cls(bank, threshold.reshape(()), int(k), alpha, distances)

    def save(self, path: str | os.PathLike) -> None:
        """Write knn.pt atomically."""
        save_tensors(self.to_state_dict(), Path(path))

    @classmethod
    def load(cls, path: str | os.PathLike, width: int | None = None) -> "KnnBank":
        """Read and check knn.pt (``torch.load(weights_only=True)``)."""
        return cls.from_state_dict(load_tensors(Path(path)), path, width)


def _scalar(value, where: Path, key: str) -> float:
    """A number stored as a one-element tensor or a Python number."""
    if isinstance(value, torch.Tensor) and value.numel() == 1 and value.dtype != torch.bool:
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CheckpointError(f"{where}: {key} is not a finite number; {AGAIN}")
    return value
