"""Branch-safe elementwise helpers: exact values, finite gradients on every branch.

`torch.where` evaluates both branches, and a NaN gradient in the branch not taken still
poisons the result; these helpers keep every branch finite.
"""
from __future__ import annotations

import torch

TINY = 2.2e-16  # the simulator's machine-epsilon guards (numpy.finfo(float).eps)
SPEED_GUARD = 1e-5  # m/s, below it the simulator replaces U by 1e-7


def safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """sqrt(x) for x > 0 and 0 for x <= 0, with a zero (not infinite) gradient at 0."""
    positive = x > 0
    return torch.where(positive, torch.sqrt(torch.where(positive, x, torch.ones_like(x))), torch.zeros_like(x))


def safe_div(num: torch.Tensor, den: torch.Tensor, use: torch.Tensor) -> torch.Tensor:
    """num / den where `use` holds, 0 elsewhere (den may be 0 there)."""
    return torch.where(use, num / torch.where(use, den, torch.ones_like(den)), torch.zeros_like(num))


def safe_atan2(y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """atan2(y, x) with atan2(0, 0) = 0 and a finite gradient there."""
    origin = (x == 0) & (y == 0)
    return torch.atan2(y, torch.where(origin, torch.ones_like(x), x))
