"""Windows of a recording and the velocity errors of rollouts over them: the training loss's
and the validation score's common ground (the trainer and evaluation both use it).

A `WindowSet` holds L = T + 1 samples of W windows; `WindowOrigins` says which log and time
each was cut from; `rollout_errors` integrates T Euler steps from each window's first recorded
state with its recorded inputs; `velocity_loss` is L_v (Eq. 15) of those errors.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
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


@dataclass(frozen=True, eq=False)
class WindowOrigins:
    """Where each of W windows was cut, in the windows' order: logs (W,) the name of its log
    (the file stem, as evaluation names the test logs), start_s (W,) the log's time [s] of
    its first sample."""

    logs: tuple[str, ...]
    start_s: np.ndarray

    def __post_init__(self):
        starts = np.asarray(self.start_s, dtype=float).reshape(-1)
        if starts.size != len(self.logs):
            raise ValueError(f"{len(self.logs)} window logs and {starts.size} start times do not pair")
        object.__setattr__(self, "logs", tuple(str(name) for name in self.logs))
        object.__setattr__(self, "start_s", starts)

    def __len__(self) -> int:
        return len(self.logs)

    def by_log(self) -> dict[str, np.ndarray]:
        """log name -> the indices (W_log,) of its windows, the logs in the order of their
        first window."""
        names = np.asarray(self.logs, dtype=object)
        return {name: np.flatnonzero(names == name) for name in dict.fromkeys(self.logs)}

    def non_overlapping(self, span_s: float) -> dict[str, np.ndarray]:
        """log name -> the indices of its windows that do not overlap, as the test logs'
        consecutive windows: greedy from the log's first window in time order, a window is kept
        when it starts at least `span_s` [s] (one window span, H = h / dt samples of dt) after
        the last one kept (1e-6 relative slack for the logs' float times); the logs in the
        order of `by_log`."""
        slack = 1e-6 * max(1.0, span_s)
        out = {}
        for name, index in self.by_log().items():
            order = index[np.argsort(self.start_s[index], kind="stable")]
            kept, last = [], -math.inf
            for i in order:               # one pass per log; a log holds at most a few thousand windows
                if self.start_s[i] >= last + span_s - slack:
                    kept.append(i)
                    last = self.start_s[i]
            out[name] = np.asarray(kept, dtype=int)
        return out


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
