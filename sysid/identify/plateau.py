"""The learning-rate schedule of a gradient stage: the rate falls by ``factor`` after more
than ``patience`` epochs without a better validation loss (torch's ReduceLROnPlateau with
its defaults: mode "min", relative threshold 1e-4, no cooldown, no floor, eps 1e-8), on
the ``"lr"`` of an optimizer's groups (`sysid.identify.adam.Adam` or torch's).

``state_dict`` holds ReduceLROnPlateau's keys, so a checkpoint written with either resumes
with the other.
"""
from __future__ import annotations

import math


class Plateau:
    """Reduces ``optimizer.param_groups[i]["lr"]`` to ``lr * factor`` when ``step(loss)``
    has seen more than `patience` losses in a row not below best * (1 - threshold)."""

    threshold = 1e-4
    eps = 1e-8

    def __init__(self, optimizer, factor: float, patience: int):
        if not factor < 1.0:
            raise ValueError(f"Plateau: factor must be below 1, got {factor}")
        self.optimizer = optimizer
        self.factor, self.patience = float(factor), int(patience)
        self.best = math.inf
        self.num_bad_epochs = 0
        self.last_epoch = 0

    def step(self, loss: float) -> None:
        """After an epoch with validation loss `loss`."""
        current = float(loss)
        self.last_epoch += 1
        if current < self.best * (1.0 - self.threshold):
            self.best, self.num_bad_epochs = current, 0
        else:
            self.num_bad_epochs += 1
        if self.num_bad_epochs > self.patience:
            for group in self.optimizer.param_groups:
                old = float(group["lr"])
                new = max(old * self.factor, 0.0)
                if old - new > self.eps:
                    group["lr"] = new
            self.num_bad_epochs = 0

    def state_dict(self) -> dict:
        """ReduceLROnPlateau's state_dict for this schedule."""
        lrs = [float(g["lr"]) for g in self.optimizer.param_groups]
        return {"factor": self.factor, "min_lrs": [0] * len(lrs), "default_min_lr": 0, "patience": self.patience,
                "cooldown": 0, "eps": self.eps, "last_epoch": self.last_epoch, "_last_lr": lrs,
                "mode_worse": math.inf, "mode": "min", "threshold": self.threshold, "threshold_mode": "rel",
                "best": self.best, "cooldown_counter": 0, "num_bad_epochs": self.num_bad_epochs}

    def load_state_dict(self, state: dict) -> None:
        """The running record (best, bad epochs, epoch) of `state` (this class's or
        ReduceLROnPlateau's)."""
        self.best = float(state["best"])
        self.num_bad_epochs = int(state["num_bad_epochs"])
        self.last_epoch = int(state.get("last_epoch", 0))
