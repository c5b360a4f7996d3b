"""Identification: windows, the multi-step loss (Eqs. 13-17), Adam with early stopping.

`Trainer(experiment).fit(runs)` returns self with ``model_``, ``history_``, ``info_``.
Steps, in order:

1. Windows of T+1 samples (T Euler steps) slid by `stride_s` within each file; each file's
   time axis is cut into 30 s blocks, 30 % of them (seeded draw) validation, and a window
   lies wholly in one part, so no validation window overlaps a training window. Exact copies of another file (``turn_cut_...``) and windows
   touching frozen-GNSS segments are left out and reported.
2. Standardisation: FNN input statistics from the training samples (relative wind computed
   from the recorded state and true wind, as the model sees it); output statistics from the
   residual force the data implies: M * (v[k+1] - v[k]) / dt + C(v[k]) - F_MMG(x[k])
   (for NN-only without F_MMG), the force that makes one Euler step land on the record.
3. Optional gradient identification of MMG coefficients (``[identify]``, stage "before").
4. Warm start: the FNN regresses that residual force (one-step fit). With ``[network]
   members`` K > 1, K networks are trained side by side (each on its own loss) and averaged.
5. Multi-step training: Euler rollouts of T steps through torchdiffeq, loss
   lambda_v * L_v + lambda_F * L_F + lambda_L2 * |theta|^2, Adam, early stopping on the
   validation velocity loss, best weights restored.
6. The kNN gate is fitted on the training samples: final features (the paper's) or the
   standardised inputs (``[gate] space``).
"""
from __future__ import annotations

import math
import random
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import torch
from tqdm import tqdm

from sysid.correction import ForceCorrection, correction_inputs
from sysid.data import Run, duplicate_runs, sliding_windows, window_touches
from sysid.device import resolve_device
from sysid.dynamics import integrate, required_force
from sysid.errors import DataError
from sysid.experiment import Experiment, ship_overrides
from sysid.mmg.model import MMG
from sysid.models import CorrectedModel
from sysid.ood import KNNGate
from sysid.ship import load_ship
from sysid.state import VELOCITY_INDEX

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
        return WindowSet(self.states[:, index], self.inputs[:, index], self.dt)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def _block_parts(n: int, block: int, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    """(n,) True for samples in validation blocks: the run is cut into blocks of `block`
    samples and a `val_fraction` share of them, drawn at random, is held out."""
    n_blocks = max(2, math.ceil(n / max(block, 1)))
    n_val = min(n_blocks - 1, max(1, int(round(val_fraction * n_blocks))))
    val_blocks = np.zeros(n_blocks, dtype=bool)
    val_blocks[rng.choice(n_blocks, n_val, replace=False)] = True
    return np.repeat(val_blocks, math.ceil(n / n_blocks))[:n]


def split_windows(runs: Sequence[Run], steps: int, stride_s: float, val_fraction: float,
                  exclude_suspect: bool = True, dtype=torch.float64, block_s: float = 30.0, seed: int = 0,
                  device: str | torch.device = "cpu"):
    """Training and validation `WindowSet`s, the training samples (N, 6)/(N, 4), and a report.

    Each file is cut into blocks of `block_s`; a random `val_fraction` of the blocks (seeded)
    is validation. Windows lie wholly inside one part, so none overlaps across the split.
    """
    rng = np.random.default_rng(seed)
    report = {"files": [], "dropped_copies": [], "suspect_windows": 0}
    copies = {copy for copy, _ in duplicate_runs(runs)}
    train, val, samples = ([], []), ([], []), ([], [])
    dt = None
    length = steps + 1
    for run in runs:
        if run.name in copies:
            report["dropped_copies"].append(run.name)
            continue
        dt = run.dt if dt is None else dt
        if abs(run.dt - dt) > 1e-9:
            raise DataError(f"{run.path}: sample period {run.dt} s differs from {dt} s")
        stride = max(1, int(round(stride_s / run.dt)))
        part_of = _block_parts(len(run), int(round(block_s / run.dt)), val_fraction, rng)
        starts = sliding_windows(len(run), length, stride)
        ends = starts + length - 1
        counts = {}
        for part, flag in (("train", False), ("val", True)):
            # a window lies wholly in one part: no validation window overlaps a training one
            inside = np.concatenate([[0], np.cumsum(part_of == flag)])
            mine = starts[inside[ends + 1] - inside[starts] == length]
            if exclude_suspect:
                bad = window_touches(run, mine, length)
                report["suspect_windows"] += int(bad.sum())
                mine = mine[~bad]
            counts[part] = len(mine)
            if not len(mine):
                continue
            idx = mine[None, :] + np.arange(length)[:, None]
            target = train if part == "train" else val
            target[0].append(torch.as_tensor(run.states[idx], dtype=dtype, device=device))
            target[1].append(torch.as_tensor(run.inputs[idx], dtype=dtype, device=device))
        keep = ~part_of
        for a, b in run.suspect if exclude_suspect else []:
            keep &= ~((run.t >= a - 1.0) & (run.t <= b + 1.0))
        samples[0].append(torch.as_tensor(run.states[keep], dtype=dtype, device=device))
        samples[1].append(torch.as_tensor(run.inputs[keep], dtype=dtype, device=device))
        report["files"].append({"file": run.name, "train_windows": counts["train"],
                                "val_windows": counts["val"], "issues": run.issues})
    if not train[0]:
        raise DataError("no training windows: the files are shorter than one window")
    if not val[0]:
        raise DataError("no validation windows: the files are too short for the 70/30 split")
    make = lambda parts: WindowSet(torch.cat(parts[0], 1), torch.cat(parts[1], 1), dt)
    return make(train), make(val), (torch.cat(samples[0]), torch.cat(samples[1])), report


def implied_residual(model: CorrectedModel, windows: WindowSet, pairs: int = 2
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Correction inputs s (N, 9), residual force (N, 3) and F_MMG (N, 3) at step starts."""
    # the first `pairs` steps of each window: with 2-s strides that covers each step once
    states, inputs = windows.states[:pairs + 1], windows.inputs[:pairs + 1]
    x, nxt, inp = states[:-1].reshape(-1, 6), states[1:].reshape(-1, 6), inputs[:-1].reshape(-1, 4)
    with torch.no_grad():
        acc = (nxt[:, VEL] - x[:, VEL]) / windows.dt
        need = required_force(x, acc, model.coefficients)
        forces = model.mmg(x, inp)
        f_mmg = forces.mmg if model.physics else torch.zeros_like(need)
        s = correction_inputs(x, inp, forces.relative_wind)
    return s, need - f_mmg, f_mmg


def output_penalty(f_nn: torch.Tensor, f_mmg: torch.Tensor, w_F: torch.Tensor, band: float = 0.2) -> torch.Tensor:
    """Eq. (17): w_F^T (|F_NN| - band |F_MMG|)^+ per sample, (..., 3) -> (...).

    Zero while every component of F_NN stays within `band` (20 %) of the MMG force's
    magnitude; grows linearly outside. w_F (3,) scales X [1/N], Y [1/N], N [1/(N m)].
    """
    return (torch.relu(f_nn.abs() - band * f_mmg.abs()) * w_F).sum(-1)


class Trainer:
    """Fits an MMG-only (optionally identified), NN-only or hybrid model to processed runs.

    Training runs on ``[training] device`` ("auto": CUDA when present, else CPU); the fitted
    ``model_`` stays there (``model_.cpu()`` for CPU evaluation).

    Parameters
    ----------
    experiment : validated experiment options.
    progress : show tqdm progress bars.
    log : callable receiving one-line messages.
    """

    def __init__(self, experiment: Experiment, progress: bool = True, log: Callable[[str], None] = print):
        self.experiment = experiment
        self.progress = progress
        self.log = log

    # -- building blocks -------------------------------------------------------------
    def _mmg(self, dtype, trainable=()) -> MMG:
        exp = self.experiment
        ship = load_ship(exp.experiment.ship, ship_overrides(exp))
        bounds = {k: tuple(v) for k, v in exp.identify.bounds.items()}
        return MMG(ship, trainable=trainable, bounds={k: v for k, v in bounds.items() if k in trainable} or None,
                   dtype=dtype)

    def _loss(self, model, batch: WindowSet, w_v, w_F, penalty: bool):
        states, inputs = batch.states, batch.inputs
        net = getattr(model, "correction_net", None)
        if net is not None and net.member_axis:  # every member rolls out the same windows
            states = states.unsqueeze(1).expand(states.shape[0], net.members, *states.shape[1:])
            inputs = inputs.unsqueeze(1).expand(inputs.shape[0], net.members, *inputs.shape[1:])
        record: list = []
        pred = integrate(model, states[0], inputs, batch.dt, "euler", record=record)
        err = pred[1:, ..., VEL] - states[1:, ..., VEL]
        loss_v = ((err * err) * w_v).sum(-1).mean()
        if not penalty:
            return loss_v, loss_v.new_zeros(())
        f_nn = torch.stack([r.correction for r in record])
        f_mmg = torch.stack([r.mmg for r in record])
        return loss_v, output_penalty(f_nn, f_mmg, w_F).mean()

    def _l2(self, model) -> torch.Tensor:
        net = getattr(model, "correction_net", None)
        if net is None:
            return torch.zeros(())
        # ||theta||^2 of the weights, per member (the loss is a mean over members)
        return sum((w * w).sum() for w in net.weights) / net.members

    def _optimize(self, model, params, train: WindowSet, val: WindowSet, w_v, w_F, penalty: bool,
                  epochs: int, lr: float, label: str, deadline: float) -> list[dict]:
        """Adam on the multi-step loss with early stopping; restores the best state."""
        t = self.experiment.training
        opt = torch.optim.Adam(params, lr=lr)
        best, best_state, best_epoch, history = math.inf, None, 0, []
        gen = torch.Generator().manual_seed(self.experiment.experiment.seed + 1)
        bar = tqdm(range(1, epochs + 1), desc=label, unit="epoch", disable=not self.progress, leave=False)
        for epoch in bar:
            start = time.perf_counter()
            order = torch.randperm(len(train), generator=gen)
            sums = np.zeros(3)
            for lo in range(0, len(train), t.batch_size):
                batch = train.select(order[lo:lo + t.batch_size])
                loss_v, loss_F = self._loss(model, batch, w_v, w_F, penalty)
                loss = t.lambda_v * loss_v + t.lambda_F * loss_F + t.lambda_L2 * self._l2(model)
                opt.zero_grad()
                loss.backward()
                opt.step()
                n = len(batch)
                sums += n * np.array([loss.item(), loss_v.item(), loss_F.item()])
            with torch.no_grad():
                val_v, _ = self._loss(model, val, w_v, w_F, False)
            sums /= len(train)
            row = {"stage": label, "epoch": epoch, "train_loss": sums[0], "train_velocity": sums[1],
                   "train_penalty": sums[2], "val_loss": float(val_v), "seconds": time.perf_counter() - start}
            history.append(row)
            if float(val_v) < best:
                best, best_epoch = float(val_v), epoch
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            bar.set_postfix(train=f"{sums[1]:.4f}", val=f"{float(val_v):.4f}", best=best_epoch)
            if epoch - best_epoch >= t.patience or time.perf_counter() > deadline:
                break
        bar.close()
        if best_state is not None:
            model.load_state_dict(best_state)
        stopped = "early stop" if history and history[-1]["epoch"] - best_epoch >= t.patience else (
            "time budget" if time.perf_counter() > deadline else "epoch limit")
        self.log(f"{label}: {len(history)} epochs, best validation loss {best:.5f} at epoch {best_epoch} ({stopped})")
        self.best_epoch_ = best_epoch
        return history

    # -- the estimator ---------------------------------------------------------------
    def fit(self, runs: Sequence[Run]) -> "Trainer":
        exp = self.experiment
        t, kind = exp.training, exp.experiment.model
        seed_everything(exp.experiment.seed)
        dtype = torch.float32 if t.dtype == "float32" else torch.float64
        device = resolve_device(t.device)
        started = time.perf_counter()
        deadline = started + 60.0 * t.max_minutes
        train, val, samples, report = split_windows(runs, t.steps, t.stride_s, t.val_fraction,
                                                    exp.data.exclude_suspect, dtype, t.block_s,
                                                    exp.experiment.seed, device)
        for name in report["dropped_copies"]:
            self.log(f"left out {name}: an exact copy of the start of another training file")
        self.log(f"{len(train)} training and {len(val)} validation windows of {t.steps} steps "
                 f"({report['suspect_windows']} touching frozen GNSS left out)")
        # velocity weights w_v: inverse variance of the recorded velocities
        vel = train.states[:, :, VEL].reshape(-1, 3)
        w_v = 1.0 / vel.var(0)
        identify = list(exp.identify.parameters)
        joint = exp.identify.stage == "joint"
        mmg = self._mmg(dtype, trainable=identify).to(device)
        history: list[dict] = []
        info: dict = {"n_train_windows": len(train), "n_val_windows": len(val), "split": report,
                      "device": str(device)}
        if identify:
            info["identified_initial"] = {k: float(getattr(mmg.coefficients, k).detach()) for k in identify}
        if identify and (kind == "mmg" or not joint):
            history += self._optimize(mmg, list(mmg.parameters()), train, val, w_v, None, False,
                                      exp.identify.epochs, exp.identify.learning_rate, "identify", deadline)
            info["identified"] = {k: float(getattr(mmg.coefficients, k).detach()) for k in identify}
            self.log("identified: " + ", ".join(f"{k} = {v:.5g}" for k, v in info["identified"].items()))
            if not joint:
                for p in mmg.parameters():
                    p.requires_grad_(False)
        if kind == "mmg":
            self.model_, self.history_ = mmg, pd.DataFrame(history)
            info["train_seconds"] = time.perf_counter() - started
            self.info_ = info
            return self
        with torch.no_grad():
            info["mmg_val_loss"] = float(self._loss(mmg, val, w_v, None, False)[0])
            info["mmg_train_loss"] = float(self._loss(mmg, train, w_v, None, False)[0])
        self.log(f"MMG-only multi-step loss: training {info['mmg_train_loss']:.5f}, validation {info['mmg_val_loss']:.5f}")
        net = ForceCorrection(exp.network.hidden, dtype, exp.network.members).to(device)
        model = CorrectedModel(mmg, net, None, physics=(kind == "hybrid"), gate_space=exp.gate.space)
        s, residual, f_mmg = implied_residual(model, train, max(1, int(round(t.stride_s / train.dt))))
        net.set_standardization(s.mean(0), s.std(0), residual.mean(0), residual.std(0))
        info["residual_force_mean"] = residual.mean(0).tolist()
        info["residual_force_std"] = residual.std(0).tolist()
        w_F = 1.0 / net.output_std
        # warm start: one-step regression of the standardised residual force
        if t.warm_start_epochs:
            target = (residual - net.output_mean) / net.output_std
            net.member_axis = True
            s_members = s.expand(net.members, *s.shape)
            opt = torch.optim.Adam(net.parameters(), lr=3e-3)
            gen = torch.Generator().manual_seed(exp.experiment.seed + 2)
            for _ in tqdm(range(t.warm_start_epochs), desc="warm start", unit="epoch",
                          disable=not self.progress, leave=False):
                order = torch.randperm(len(s), generator=gen).to(device)
                for lo in range(0, len(s), 256):
                    idx = order[lo:lo + 256]
                    y = net.evaluate(s_members[:, idx], standardized=True)[0]
                    loss = ((y - target[idx]) ** 2).mean() + t.lambda_L2 * self._l2(model)
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
                if time.perf_counter() > deadline:
                    break
        net.member_axis = True
        with torch.no_grad():
            info["warm_val_loss"] = float(self._loss(model, val, w_v, None, False)[0])
        self.log(f"after warm start: validation loss {info['warm_val_loss']:.5f}")
        params = list(net.parameters()) + (list(mmg.parameters()) if identify and joint else [])
        history += self._optimize(model, params, train, val, w_v, w_F, kind == "hybrid",
                                  t.epochs, t.learning_rate, "train", deadline)
        info["best_epoch"] = self.best_epoch_
        net.member_axis = False
        with torch.no_grad():
            info["ensemble_val_loss"] = float(self._loss(model, val, w_v, None, False)[0])
        if net.members > 1:
            self.log(f"mean of {net.members} networks: validation loss {info['ensemble_val_loss']:.5f}")
        if identify and joint:
            info["identified"] = {k: float(getattr(mmg.coefficients, k).detach()) for k in identify}
        # kNN gate on the final features of the training samples
        if exp.gate.enabled:
            with torch.no_grad():
                states, inputs = samples
                rel = model.mmg(states, inputs).relative_wind
                z = model.gate_coordinates(correction_inputs(states, inputs, rel))
            model.gate = KNNGate(exp.gate.k, exp.gate.alpha, z.shape[-1], dtype).fit(z)
            model.gate_enabled = True
            info["gate"] = {"k": exp.gate.k, "alpha": exp.gate.alpha, "space": exp.gate.space,
                            "bank": int(z.shape[0]),
                            "threshold": float(model.gate.threshold)}
            self.log(f"kNN gate: {z.shape[0]} training features, threshold {float(model.gate.threshold):.4f}")
        info["train_seconds"] = time.perf_counter() - started
        self.model_, self.history_, self.info_ = model, pd.DataFrame(history), info
        return self
