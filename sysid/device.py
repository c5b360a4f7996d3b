"""Where tensors live (CUDA when present, else the CPU) and how many CPU threads work on them."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

import torch

from sysid.config.checks import cpu_cores
from sysid.errors import ConfigError

__all__ = ["resolve_device", "cpu_cores", "compute_threads"]


def resolve_device(name: str = "auto") -> torch.device:
    """``auto`` -> ``cuda`` when a GPU is visible, else ``cpu``; ``cuda`` without one is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError(f"device {name!r}: CUDA is not available on this machine (use auto or cpu)")
    return device


@contextmanager
def compute_threads(n: int) -> Iterator[int]:
    """Run the block with `n` torch intra-op threads (0: one per core; at most `cpu_cores`,
    `sysid.config.checks.threads`), then restore.

    One thread is the default for training: the multi-step rollout is dispatch-bound, so
    more threads barely help alone and, beside another job, oversubscribe the cores (a
    warm start measured 40x slower with two 2-thread jobs on 2 cores).
    """
    previous = torch.get_num_threads()
    n = n or cpu_cores()
    torch.set_num_threads(n)
    try:
        yield n
    finally:
        torch.set_num_threads(previous)
