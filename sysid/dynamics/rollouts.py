"""Windows of a recording and the velocity errors of rollouts over them: the training loss's
and the validation score's common ground (the trainer and evaluation both use it).

A `WindowSet` holds L = T + 1 samples of W windows; `rollout_errors` integrates T Euler
steps from each window's first recorded state with its recorded inputs; `velocity_loss` is
L_v (Eq. 15) of those errors.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from sysid.dynamics.equations import integrate
from sysid.channel_names import VELOCITY_INDEX

VEL = list(VELOCITY_INDEX)


@dataclass
class WindowSet:
    """Windows (L, W, 6) states and (L, W, 4) inputs, L = T + 1 samples at dt [s]."""

    states: torch.Tensor
    inputs: torch.Tensor
    dt: float

    def __len__(self) -> int:
        return self.states.shape[1]

    def select(self, index: torch.Tensor) -> "WindowSet":
        index = index.to(self.states.device)
        flat = index.reshape(-1)  # index_select: advanced indexing's values in a quarter of its time

        def rows(x: torch.Tensor) -> torch.Tensor:
            return x.index_select(1, flat).reshape(x.shape[0], *index.shape, x.shape[-1])
        return WindowSet(rows(self.states), rows(self.inputs), self.dt)


def velocity_loss(err: torch.Tensor, w_v: torch.Tensor) -> torch.Tensor:
    """L_v (Eq. 15): the mean over windows and steps of sum_j w_j err_j^2; err (T, ..., 3)
    velocity errors (u, v_m [m/s], r [rad/s]), w_v (3,) their weights."""
    return ((err * err) * w_v).sum(-1).mean()


def rollout_errors(model, batch: WindowSet) -> torch.Tensor:
    """(T, W, 3) velocity errors (u, v_m [m/s], r [rad/s]) of Euler rollouts of T steps from
    each window's first recorded state with its recorded inputs (no gradient)."""
    with torch.no_grad():
        pred = integrate(model, batch.states[0], batch.inputs, batch.dt, "euler")
    return pred[1:, ..., VEL] - batch.states[1:, ..., VEL]
