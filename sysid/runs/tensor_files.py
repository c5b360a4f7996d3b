"""Files of plain tensors in a run directory (model.pt, knn.pt): written atomically with
``torch.save``, read with ``torch.load(weights_only=True)`` and one clear error line."""
from __future__ import annotations

import warnings
from pathlib import Path

import torch

from sysid.errors import CheckpointError
from sysid.store.files import atomic_path


def save_tensors(obj, path: Path) -> None:
    """`obj` (tensors, numbers, strings in dicts and lists) to `path`, atomically."""
    with atomic_path(path, ".pt") as tmp:
        torch.save(obj, tmp)


def load_tensors(path: Path):
    """What `save_tensors` wrote to `path`; `CheckpointError` naming the file when it is
    missing, truncated, not a torch file or holds other objects than plain data."""
    if not path.is_file():
        raise CheckpointError(f"{path}: missing (the run directory is incomplete)")
    try:
        with warnings.catch_warnings():  # torch's pickle-protocol warnings on a foreign file
            warnings.simplefilter("ignore")
            return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # truncated, not a torch file, unsafe pickle
        reason = (str(exc).strip().splitlines() or [""])[0][:160]
        if "weights_only" in str(exc):  # torch's multi-line advice is not for our users
            reason = "not a checkpoint of plain tensors: truncated, another kind of file, or unsafe objects"
        raise CheckpointError(f"{path}: cannot be loaded safely ({reason})") from None


def check_finite(tensors: dict, path: Path) -> None:
    """Refuse weights holding NaN or inf (a diverged training): they predict nothing; and
    standard deviations (``*_std``, the FNN's scaling) that are not > 0."""
    for key, value in tensors.items():
        if isinstance(value, torch.Tensor) and value.is_floating_point() and not torch.isfinite(value).all():
            raise CheckpointError(f"{path}: {key} holds NaN or inf values (a diverged training); train the run again")
        if key.endswith("_std") and isinstance(value, torch.Tensor) and not bool((value > 0).all()):
            raise CheckpointError(f"{path}: {key} holds a standard deviation <= 0 (the FNN would divide by it); "
                                  "train the run again")
