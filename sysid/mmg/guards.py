"""Branch-safe elementwise helpers: exact values, finite gradients on every branch.

`torch.where` evaluates both branches, and a NaN gradient in the branch not taken still
poisons the result; these helpers keep every branch finite.
"""
from __future__ import annotations

import torch

from sysid.mmg.capture import captured, transformed

TINY = 2.2e-16  # the simulator's machine-epsilon guards (numpy.finfo(float).eps)
SPEED_GUARD = 1e-5  # m/s, below it the simulator replaces U by 1e-7


def constant(x: torch.Tensor) -> bool:
    """True where no derivative can pass through `x` (no autograd history, not inside a
    `torch.func` transform): the guards' second branch is not needed then. (Compiled
    code keeps the guarded form; Inductor fuses it.)"""
    if captured():
        return False
    return not x.requires_grad and not transformed(x)


def choose(condition: torch.Tensor, a, b, like: torch.Tensor) -> torch.Tensor:
    """a where `condition` holds, else b (coefficients: 0-d tensors), in the dtype and shape
    of `like` (`torch.where` of two 0-d tensors takes their dtype)."""
    if a.dtype == b.dtype == like.dtype and constant(a) and constant(b):
        return torch.where(condition, a, b)
    return torch.where(condition, a + 0.0 * like, b + 0.0 * like)


def safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """sqrt(x) for x > 0 and 0 for x <= 0, with a zero (not infinite) gradient at 0."""
    if constant(x):  # no derivative to guard: the same values in two operations
        return torch.sqrt(torch.clamp(x, min=0.0))
    positive = x > 0
    return torch.where(positive, torch.sqrt(torch.where(positive, x, 1.0)), 0.0)


def safe_div(num: torch.Tensor, den: torch.Tensor, use: torch.Tensor) -> torch.Tensor:
    """num / den where `use` holds, 0 elsewhere (den may be 0 there)."""
    if constant(num) and constant(den):
        return torch.where(use, num / den, 0.0)
    return torch.where(use, num / torch.where(use, den, 1.0), 0.0)


def safe_atan2(y: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """atan2(y, x) with atan2(0, 0) = 0 and a finite gradient there."""
    origin = (x == 0) & (y == 0)
    return torch.atan2(y, torch.where(origin, 1.0, x))
